//! Diffuse lighting as defined once for all of psao (DESIGN §12): the linear RGB irradiance
//! at a surface point x with unit normal n,
//!
//! ```text
//! E(x) = Σ_lights E_l(x) + ∫_Ω(n) L_in(x, ω) cos θ dω
//! ```
//!
//! the direct light of the scene's suns, point lights and rectangles ([`psao_scene::Light`])
//! with shadow rays, plus the light arriving from the hemisphere: the scene's
//! [`psao_scene::Environment`] where a ray leaves the scene, and where it hits a surface y
//! that surface's diffuse radiance `ρ(y)/π · E(y)` (ρ = the material's base colour, every
//! surface treated as Lambertian, hits on either face), recursively for `bounces` levels
//! (0: the direct light and the environment only; 1: also their first bounce, the bounce of
//! the sun included). A surface shown with it has radiance `ρ/π · E`.
//!
//! One sample ([`DiffuseLighting::sample`]) is a path: at each vertex one shadow ray per
//! light (a rectangle at one uniform point of its area, the area measure turned into solid
//! angle) and one cosine-distributed ray (pdf cos θ / π, so a miss adds `π·L_env` and a hit
//! multiplies the path's weight by ρ). Lights are not geometry, so rays never hit them and
//! their light is counted once, by the shadow rays.
//!
//! **Fixed depth, not Russian roulette.** `bounces` names exactly which truncated sum is
//! computed, so the points, the per-pixel reference and the baselines estimate the same
//! quantity and their differences are the method's, not a different truncation; a path
//! costs at most `bounces + 1` closest-hit rays and `(bounces + 1) · lights` shadow rays,
//! a bound the server's ray budget needs. (Roulette would estimate the infinite sum, with
//! variance where interiors are brightest and an unbounded path length.)
//!
//! Random numbers are hashed from (seed, key, sample index, depth, purpose), so a sample is
//! the same whichever thread traces it and a point can resume at any index.

use glam::{Affine3A, Mat3A, Vec3};
use psao_scene::{Light, LightShape, Scene, ScenePose};

use crate::ao::{cosine_hemisphere, hash64, ray_offset, sample_2d};
use crate::{Hit, Ray, Tracer};

/// Fraction of the distance to a point on a light left out of its shadow ray, so the light
/// itself (when it lies on geometry) does not shadow.
const SHADOW_SHORTEN: f32 = 1e-4;

/// The diffuse lighting of a scene at one scene time: its lights at that time, its
/// environment and the surfaces' base colours, with `bounces` indirect bounces.
pub struct DiffuseLighting<'a> {
    scene: &'a Scene,
    lights: Vec<Light>,
    bounces: u32,
    pose: Option<&'a ScenePose>,
    normal_matrices: Vec<Mat3A>,
}

/// A surface point a ray found.
struct Surface {
    point: Vec3,
    /// Interpolated unit normal, on the side the ray came from.
    normal: Vec3,
    /// Unit face normal, on the side the ray came from.
    face: Vec3,
    albedo: Vec3,
}

impl<'a> DiffuseLighting<'a> {
    /// The lighting of `scene` at scene time `time` seconds (lights as
    /// [`Scene::lights_at`]), every instance at its stored transform.
    pub fn new(scene: &'a Scene, time: f32, bounces: u32) -> Self {
        let normal_matrices = scene
            .instances
            .iter()
            .map(|i| normal_matrix(&i.transform))
            .collect();
        Self {
            scene,
            lights: scene.lights_at(time),
            bounces,
            pose: None,
            normal_matrices,
        }
    }

    /// The same lighting with the scene in `pose`, which the tracer given to the queries must
    /// hold: surfaces take the posed transforms and skinned vertices.
    pub fn posed(mut self, pose: &'a ScenePose) -> Self {
        self.normal_matrices = (self.scene.instances.iter().enumerate())
            .map(|(i, inst)| normal_matrix(pose.transforms.get(i).unwrap_or(&inst.transform)))
            .collect();
        self.pose = Some(pose);
        self
    }

    /// Indirect bounces per path.
    pub fn bounces(&self) -> u32 {
        self.bounces
    }

    /// The lights in use.
    pub fn lights(&self) -> &[Light] {
        &self.lights
    }

    /// The sum of samples `first..first + count` of the irradiance at surface point `x` with
    /// unit shading normal `n` and unit face normal `face` (both on the lit side; pass `n`
    /// for both when the face is unknown), point `key`. Divide by the sample count for the
    /// estimate.
    #[allow(clippy::too_many_arguments)]
    pub fn irradiance_sum(
        &self,
        tracer: &Tracer,
        x: Vec3,
        n: Vec3,
        face: Vec3,
        first: u32,
        count: u32,
        seed: u64,
        key: u64,
    ) -> Vec3 {
        (first..first.saturating_add(count))
            .map(|i| self.sample(tracer, x, n, face, seed, key, i))
            .sum()
    }

    /// Sample `index` of the irradiance at `x` (see [`Self::irradiance_sum`]): one path.
    #[allow(clippy::too_many_arguments)]
    pub fn sample(
        &self,
        tracer: &Tracer,
        x: Vec3,
        n: Vec3,
        face: Vec3,
        seed: u64,
        key: u64,
        index: u32,
    ) -> Vec3 {
        let (mut x, mut n, mut face) = (x, n.normalize_or(Vec3::Y), face.normalize_or(n));
        let mut weight = Vec3::ONE;
        let mut total = Vec3::ZERO;
        for depth in 0..=self.bounces {
            let origin = ray_offset(x, face);
            total += weight * self.direct(tracer, origin, n, face, seed, key, depth, index);
            let (u1, u2) = sample_2d(seed, stream(key, depth, 0), index);
            let ray = Ray::new(origin, cosine_hemisphere(n, u1, u2), f32::INFINITY);
            let mut hit = [None];
            tracer.intersect(std::slice::from_ref(&ray), &mut hit);
            let Some(hit) = hit[0] else {
                let sky = self.scene.environment.radiance(ray.dir);
                total += weight * std::f32::consts::PI * sky;
                break;
            };
            if depth == self.bounces {
                break;
            }
            let Some(s) = self.surface(&ray, &hit) else {
                break;
            };
            weight *= s.albedo;
            if weight == Vec3::ZERO {
                break;
            }
            (x, n, face) = (s.point, s.normal, s.face);
        }
        total
    }

    /// Direct irradiance of every light at `origin` (already offset off the surface) on a
    /// surface with shading normal `n` and face normal `face`, with one shadow ray each.
    #[allow(clippy::too_many_arguments)]
    fn direct(
        &self,
        tracer: &Tracer,
        origin: Vec3,
        n: Vec3,
        face: Vec3,
        seed: u64,
        key: u64,
        depth: u32,
        index: u32,
    ) -> Vec3 {
        let visible = |l: Vec3, tmax: f32| {
            if n.dot(l) <= 0.0 || face.dot(l) <= 0.0 {
                return false;
            }
            let mut out = [false];
            tracer.occluded(&[Ray::new(origin, l, tmax)], &mut out);
            !out[0]
        };
        let mut e = Vec3::ZERO;
        for (li, light) in self.lights.iter().enumerate() {
            let strength = light.color * light.power;
            match light.shape {
                LightShape::Sun { direction } => {
                    let l = direction.normalize_or_zero();
                    if visible(l, f32::INFINITY) {
                        e += strength * n.dot(l);
                    }
                }
                LightShape::Point { position } => {
                    let d = position - origin;
                    let dist = d.length();
                    let l = d / dist;
                    if dist > 0.0 && visible(l, dist * (1.0 - SHADOW_SHORTEN)) {
                        e += strength * n.dot(l) / (dist * dist);
                    }
                }
                LightShape::Rect {
                    centre,
                    half_u,
                    half_v,
                } => {
                    let (a, b) = sample_2d(seed, stream(key, depth, li as u32 + 1), index);
                    let q = centre + (2.0 * a - 1.0) * half_u + (2.0 * b - 1.0) * half_v;
                    let normal_area = 4.0 * half_u.cross(half_v);
                    let d = q - origin;
                    let dist2 = d.length_squared();
                    let dist = dist2.sqrt();
                    let l = d / dist;
                    // The area's cosine times its area: −l · (normal · area).
                    let cos_area = -l.dot(normal_area);
                    if dist > 0.0 && cos_area > 0.0 && visible(l, dist * (1.0 - SHADOW_SHORTEN)) {
                        e += strength * n.dot(l) * cos_area / dist2;
                    }
                }
            }
        }
        e
    }

    /// The surface `hit` found on `ray`, in the pose the lighting holds.
    fn surface(&self, ray: &Ray, hit: &Hit) -> Option<Surface> {
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
        let toward_ray = |v: Vec3| if v.dot(ray.dir) > 0.0 { -v } else { v };
        let face = toward_ray((m * (p1 - p0).cross(p2 - p0)).normalize_or_zero());
        if face == Vec3::ZERO {
            return None;
        }
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
        let albedo = self
            .scene
            .materials
            .get(mesh.material)
            .map_or(Vec3::splat(0.8), |m| m.base_color.truncate());
        Some(Surface {
            point: ray.origin + ray.dir * hit.t,
            normal,
            face,
            albedo,
        })
    }
}

/// The random stream of one purpose (0: the bounce direction, 1 + i: light i) at one depth
/// of point `key`'s paths.
fn stream(key: u64, depth: u32, purpose: u32) -> u64 {
    hash64(key ^ hash64((u64::from(depth) << 32 | u64::from(purpose)) ^ 0x6769_5f70_6174_6873))
}

/// The inverse transpose of a transform's linear part (for normals).
fn normal_matrix(t: &Affine3A) -> Mat3A {
    let m = t.matrix3;
    if m.determinant().abs() > 1e-20 {
        m.inverse().transpose()
    } else {
        m
    }
}
