//! Scene validation and small geometric helpers shared by the backends.

use glam::{Affine3A, Vec3};
use psao_scene::Scene;

use crate::{GeometryMode, TraceError};

/// Checks every mesh and instance of `scene` and returns, per mesh, whether it goes into the
/// acceleration structure under `mode` (it must have triangles and, in occlusion mode, a
/// material that rays do not skip).
pub(crate) fn included_meshes(scene: &Scene, mode: GeometryMode) -> Result<Vec<bool>, TraceError> {
    for (instance, inst) in scene.instances.iter().enumerate() {
        if inst.mesh >= scene.meshes.len() {
            return Err(TraceError::InstanceMesh {
                instance,
                mesh: inst.mesh,
                meshes: scene.meshes.len(),
            });
        }
    }
    scene
        .meshes
        .iter()
        .enumerate()
        .map(|(m, mesh)| {
            check_positions(m, &mesh.positions)?;
            for (triangle, tri) in mesh.indices.iter().enumerate() {
                if let Some(&vertex) = tri.iter().find(|&&i| i as usize >= mesh.positions.len()) {
                    return Err(TraceError::VertexIndex {
                        mesh: m,
                        triangle,
                        vertex,
                        vertices: mesh.positions.len(),
                    });
                }
            }
            let skipped = match mode {
                GeometryMode::Primary => false,
                GeometryMode::Occlusion => scene
                    .materials
                    .get(mesh.material)
                    .ok_or(TraceError::MeshMaterial {
                        mesh: m,
                        material: mesh.material,
                        materials: scene.materials.len(),
                    })?
                    .skipped_by_rays(),
            };
            Ok(!skipped && !mesh.indices.is_empty())
        })
        .collect()
}

/// Errors when a position is NaN or infinite.
pub(crate) fn check_positions(mesh: usize, positions: &[Vec3]) -> Result<(), TraceError> {
    match positions.iter().position(|p| !p.is_finite()) {
        Some(vertex) => Err(TraceError::NonFinitePosition { mesh, vertex }),
        None => Ok(()),
    }
}

/// The inverse of `transform` when it is finite and invertible; instances without one are
/// left out of the top level (they cannot be hit).
pub(crate) fn usable_inverse(transform: &Affine3A) -> Option<Affine3A> {
    let det = transform.matrix3.determinant();
    if !transform.is_finite() || !det.is_normal() {
        return None;
    }
    let inverse = transform.inverse();
    inverse.is_finite().then_some(inverse)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Quat;

    #[test]
    fn singular_transform_has_no_inverse() {
        assert!(usable_inverse(&Affine3A::from_scale(Vec3::new(1.0, 0.0, 1.0))).is_none());
        assert!(usable_inverse(&Affine3A::from_translation(Vec3::splat(f32::NAN))).is_none());
        let t = Affine3A::from_rotation_translation(Quat::from_rotation_y(0.3), Vec3::ONE);
        let inv = usable_inverse(&t).unwrap();
        let p = Vec3::new(0.2, -3.0, 5.0);
        assert!((inv.transform_point3(t.transform_point3(p)) - p).length() < 1e-5);
    }
}
