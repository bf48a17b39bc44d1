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

use glam::Vec3;
use psao_scene::{Light, LightShape, Scene, ScenePose};

use crate::ao::{cosine_hemisphere, hash64, ray_offset, sample_2d};
use crate::surface::Surfaces;
use crate::{Ray, Tracer};

/// Fraction of the distance to a point on a light left out of its shadow ray, so the light
/// itself (when it lies on geometry) does not shadow.
const SHADOW_SHORTEN: f32 = 1e-4;

/// The diffuse lighting of a scene at one scene time: its lights at that time, its
/// environment and the surfaces' base colours, with `bounces` indirect bounces.
pub struct DiffuseLighting<'a> {
    surfaces: Surfaces<'a>,
    lights: Vec<Light>,
    bounces: u32,
    /// Whether the direct light of suns and point lights at the path's first vertex is left
    /// out ([`Self::without_sharp_direct`]).
    skip_sharp_direct: bool,
    /// Whether a rectangle's sample is capped at `π × its radiance`
    /// ([`Self::with_clamped_rect_samples`]).
    clamp_rect_samples: bool,
}

impl<'a> DiffuseLighting<'a> {
    /// The lighting of `scene` at scene time `time` seconds (lights as
    /// [`Scene::lights_at`]), every instance at its stored transform.
    pub fn new(scene: &'a Scene, time: f32, bounces: u32) -> Self {
        Self::with_lights(scene, scene.lights_at(time), bounces)
    }

    /// The lighting of `scene` with `lights` in place of its own (e.g. the lights at some
    /// scene time, computed once), every instance at its stored transform.
    pub fn with_lights(scene: &'a Scene, lights: Vec<Light>, bounces: u32) -> Self {
        Self {
            surfaces: Surfaces::new(scene),
            lights,
            bounces,
            skip_sharp_direct: false,
            clamp_rect_samples: false,
        }
    }

    /// The same lighting without the direct light of suns and point lights at the point
    /// itself (their bounces stay): what a client that renders those lights with shadow maps
    /// takes from the points (DESIGN §12, as CloudLight leaves direct light to the client).
    /// Rectangles and the environment, whose shadows are soft, stay whole.
    pub fn without_sharp_direct(mut self) -> Self {
        self.skip_sharp_direct = true;
        self
    }

    /// The same lighting with each rectangle light's sample (its radiance × the sampled
    /// point's `cos θ · cos θ' · area / d²`) capped at `π ×` its radiance: the irradiance of
    /// an emitter filling the whole hemisphere, which no true value exceeds. Only samples
    /// at vertices close to a rectangle, where `1/d²` makes single paths orders of magnitude
    /// brighter than their mean, are capped, so the estimate loses those rare spikes (a
    /// small bias, towards darker, next to the panels) for much less variance: what the
    /// server's few paths per point need (docs/LIGHTING.md "Noise"). The per-pixel reference
    /// keeps the unbiased samples.
    pub fn with_clamped_rect_samples(mut self) -> Self {
        self.clamp_rect_samples = true;
        self
    }

    /// The same lighting with the scene in `pose`, which the tracer given to the queries must
    /// hold: surfaces take the posed transforms and skinned vertices.
    pub fn posed(mut self, pose: &'a ScenePose) -> Self {
        self.surfaces = self.surfaces.posed(pose);
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
        self.sample_counted(tracer, x, n, face, seed, key, index).0
    }

    /// [`Self::sample`] with the number of rays the path traced: per vertex (at most
    /// `bounces + 1`) one closest-hit ray and at most one shadow ray per light.
    #[allow(clippy::too_many_arguments)]
    pub fn sample_counted(
        &self,
        tracer: &Tracer,
        x: Vec3,
        n: Vec3,
        face: Vec3,
        seed: u64,
        key: u64,
        index: u32,
    ) -> (Vec3, u32) {
        let (mut x, mut n, mut face) = (x, n.normalize_or(Vec3::Y), face.normalize_or(n));
        let mut weight = Vec3::ONE;
        let mut total = Vec3::ZERO;
        let mut rays = 0;
        for depth in 0..=self.bounces {
            let origin = ray_offset(x, face);
            let sharp = depth > 0 || !self.skip_sharp_direct;
            let (direct, shadow_rays) =
                self.direct(tracer, origin, n, face, (seed, key, depth, index), sharp);
            total += weight * direct;
            rays += shadow_rays + 1;
            let (u1, u2) = sample_2d(seed, stream(key, depth, 0), index);
            let ray = Ray::new(origin, cosine_hemisphere(n, u1, u2), f32::INFINITY);
            let mut hit = [None];
            tracer.intersect(std::slice::from_ref(&ray), &mut hit);
            let Some(hit) = hit[0] else {
                let sky = self.surfaces.scene().environment.radiance(ray.dir);
                total += weight * std::f32::consts::PI * sky;
                break;
            };
            if depth == self.bounces {
                break;
            }
            let Some(s) = self.surfaces.surface(&ray, &hit) else {
                break;
            };
            weight *= self.albedo(s.material);
            if weight == Vec3::ZERO {
                break;
            }
            (x, n, face) = (s.point, s.normal, s.face);
        }
        (total, rays)
    }

    /// The diffuse albedo of material `material` (its base colour; 0.8 grey when missing).
    fn albedo(&self, material: usize) -> Vec3 {
        (self.surfaces.scene().materials)
            .get(material)
            .map_or(Vec3::splat(0.8), |m| m.base_color.truncate())
    }

    /// Direct irradiance of every light (suns and point lights only when `sharp`) at `origin`
    /// (already offset off the surface) on a surface with shading normal `n` and face normal
    /// `face`, with at most one shadow ray each; `(seed, key, depth, index)` pick the random
    /// numbers. Returns it with the number of shadow rays traced.
    fn direct(
        &self,
        tracer: &Tracer,
        origin: Vec3,
        n: Vec3,
        face: Vec3,
        (seed, key, depth, index): (u64, u64, u32, u32),
        sharp: bool,
    ) -> (Vec3, u32) {
        let traced = std::cell::Cell::new(0);
        let visible = |l: Vec3, tmax: f32| {
            if n.dot(l) <= 0.0 || face.dot(l) <= 0.0 {
                return false;
            }
            traced.set(traced.get() + 1);
            let mut out = [false];
            tracer.occluded(&[Ray::new(origin, l, tmax)], &mut out);
            !out[0]
        };
        let mut e = Vec3::ZERO;
        for (li, light) in self.lights.iter().enumerate() {
            let strength = light.color * light.power;
            match light.shape {
                LightShape::Sun { .. } | LightShape::Point { .. } if !sharp => {}
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
                        if self.clamp_rect_samples {
                            let geometry = n.dot(l) * cos_area / dist2;
                            e += strength * geometry.min(std::f32::consts::PI);
                        } else {
                            e += strength * n.dot(l) * cos_area / dist2;
                        }
                    }
                }
            }
        }
        (e, traced.get())
    }
}

/// The random stream of one purpose (0: the bounce direction, 1 + i: light i) at one depth
/// of point `key`'s paths.
fn stream(key: u64, depth: u32, purpose: u32) -> u64 {
    hash64(key ^ hash64((u64::from(depth) << 32 | u64::from(purpose)) ^ 0x6769_5f70_6174_6873))
}
