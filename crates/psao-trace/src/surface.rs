//! The surface a ray found: position, shading and face normals turned towards the ray, the
//! side it came from and the material, for the scene at its stored transforms or in a pose.
//! The one hit-to-surface lookup of psao (diffuse lighting, correction samples, the server's
//! light paths).

use glam::{Affine3A, Mat3A, Vec3};
use psao_scene::{Scene, ScenePose};

use crate::{Hit, Ray};

/// A surface point a ray found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceHit {
    /// World position.
    pub point: Vec3,
    /// Interpolated unit shading normal, on the side the ray came from (the face normal when
    /// the mesh has no normals).
    pub normal: Vec3,
    /// Unit face normal, on the side the ray came from.
    pub face: Vec3,
    /// Whether the ray came from the front side of the triangle (counter-clockwise winding).
    pub front: bool,
    /// Instance hit.
    pub instance: u32,
    /// Index of the mesh's material in [`Scene::materials`].
    pub material: usize,
}

/// Turns hits into [`SurfaceHit`]s for the scene in one pose: the normal matrices of the
/// instances' transforms and, for skinned instances, the posed vertices.
#[derive(Clone, Debug)]
pub struct Surfaces<'a> {
    scene: &'a Scene,
    pose: Option<&'a ScenePose>,
    normal_matrices: Vec<Mat3A>,
}

impl<'a> Surfaces<'a> {
    /// Surfaces of `scene` with every instance at its stored transform.
    pub fn new(scene: &'a Scene) -> Self {
        let normal_matrices = scene
            .instances
            .iter()
            .map(|i| normal_matrix(&i.transform))
            .collect();
        Self {
            scene,
            pose: None,
            normal_matrices,
        }
    }

    /// The same surfaces with the scene in `pose` (the pose the tracer holds): the posed
    /// transforms and skinned vertices.
    pub fn posed(mut self, pose: &'a ScenePose) -> Self {
        self.normal_matrices = (self.scene.instances.iter().enumerate())
            .map(|(i, inst)| normal_matrix(pose.transforms.get(i).unwrap_or(&inst.transform)))
            .collect();
        self.pose = Some(pose);
        self
    }

    /// The scene.
    pub fn scene(&self) -> &'a Scene {
        self.scene
    }

    /// The surface `hit` found on `ray`; `None` for a hit on a degenerate triangle or one
    /// the scene does not hold.
    pub fn surface(&self, ray: &Ray, hit: &Hit) -> Option<SurfaceHit> {
        let inst = self.scene.instances.get(hit.instance as usize)?;
        let mesh = self.scene.meshes.get(inst.mesh)?;
        let [a, b, c] = *mesh.indices.get(hit.triangle as usize)?;
        let skinned = (self.pose)
            .and_then(|p| p.skinned.get(hit.instance as usize))
            .and_then(Option::as_ref);
        let positions = skinned.map_or(&mesh.positions, |g| &g.positions);
        let normals = skinned.map_or(&mesh.normals, |g| &g.normals);
        let p = |i: u32| positions.get(i as usize).copied();
        let (p0, p1, p2) = (p(a)?, p(b)?, p(c)?);
        let m = *self.normal_matrices.get(hit.instance as usize)?;
        let face = (m * (p1 - p0).cross(p2 - p0)).normalize_or_zero();
        if face == Vec3::ZERO {
            return None;
        }
        let front = face.dot(ray.dir) < 0.0;
        let face = if front { face } else { -face };
        let w = 1.0 - hit.u - hit.v;
        let interpolated = match (
            normals.get(a as usize),
            normals.get(b as usize),
            normals.get(c as usize),
        ) {
            (Some(na), Some(nb), Some(nc)) => {
                (m * (*na * w + *nb * hit.u + *nc * hit.v)).normalize_or_zero()
            }
            _ => Vec3::ZERO,
        };
        let normal = match interpolated {
            v if v == Vec3::ZERO => face,
            v if v.dot(face) < 0.0 => -v,
            v => v,
        };
        Some(SurfaceHit {
            point: ray.origin + ray.dir * hit.t,
            normal,
            face,
            front,
            instance: hit.instance,
            material: mesh.material,
        })
    }
}

/// The inverse transpose of a transform's linear part (for normals); the linear part itself
/// when it is singular.
fn normal_matrix(t: &Affine3A) -> Mat3A {
    let m = t.matrix3;
    if m.determinant().abs() > 1e-20 {
        m.inverse().transpose()
    } else {
        m
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use psao_scene::{Instance, Mesh};

    /// One triangle in the z = 0 plane, counter-clockwise seen from +z, instanced scaled
    /// by 2 along x and moved up by 1 along z.
    fn scene() -> Scene {
        let mesh = Mesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            indices: vec![[0, 1, 2]],
            ..Default::default()
        };
        let mut scene = Scene::of_meshes(vec![mesh]);
        scene.instances[0] = Instance {
            transform: Affine3A::from_scale_rotation_translation(
                Vec3::new(2.0, 1.0, 1.0),
                glam::Quat::IDENTITY,
                Vec3::Z,
            ),
            ..scene.instances[0].clone()
        };
        scene
    }

    #[test]
    fn normals_face_the_ray_and_the_side_is_reported() {
        let scene = scene();
        let surfaces = Surfaces::new(&scene);
        let hit = Hit {
            t: 2.0,
            u: 0.25,
            v: 0.25,
            instance: 0,
            triangle: 0,
        };
        let down = Ray::new(Vec3::new(0.5, 0.25, 3.0), Vec3::NEG_Z, 10.0);
        let s = surfaces.surface(&down, &hit).unwrap();
        assert_eq!((s.front, s.face, s.normal), (true, Vec3::Z, Vec3::Z));
        assert_eq!(s.point, Vec3::new(0.5, 0.25, 1.0));
        let up = Ray::new(Vec3::new(0.5, 0.25, -1.0), Vec3::Z, 10.0);
        let s = surfaces.surface(&up, &hit).unwrap();
        assert_eq!(
            (s.front, s.face, s.normal),
            (false, Vec3::NEG_Z, Vec3::NEG_Z)
        );
        let missing = Hit { triangle: 1, ..hit };
        assert!(surfaces.surface(&down, &missing).is_none());
    }
}
