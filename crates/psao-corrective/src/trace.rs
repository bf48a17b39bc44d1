//! The correction ray tracer (paper §4.3) through the `psao-trace` facade (either backend).
//!
//! At a non-diffuse hit the radiance is
//! - the diffuse part, `(1 − metallic)·(1 − transmission)·(1 − F)` times what the client shows
//!   there ([`DiffuseShade`]: base shading × AO), so corrected pixels agree with their
//!   surroundings;
//! - specular reflection with Schlick's Fresnel: one mirror ray below a roughness of
//!   [`MIRROR_ROUGHNESS`], otherwise distributed rays sampling the GGX (Cook–Torrance)
//!   distribution of half vectors, weighted by `F·G·(v·h) / ((n·h)(n·v))`;
//! - glossy highlights of the scene's lights with shadow rays (rectangles sampled uniformly
//!   over their area, converted to solid angle), Cook–Torrance GGX;
//! - refraction for transmissive dielectrics with the exact dielectric Fresnel term and total
//!   internal reflection, tinted by the base colour (the surface's roughness is ignored for
//!   the refracted ray).
//!
//! Rays that reach a diffuse surface, or exceed the depth limit, return the [`DiffuseShade`];
//! misses return the sky colour. Random numbers are hashed from (seed, frame, pixel, path),
//! so a sample is deterministic per (pixel, frame).

use crate::splat::Sample;
use glam::Vec3;
use psao_scene::{Camera, LightShape, Material, Scene, ScenePose};
use psao_trace::ao::{hash64, orthonormal_basis, ray_offset, sample_2d};
use psao_trace::surface::{SurfaceHit, Surfaces};
use psao_trace::{Hit, Ray, Tracer};

/// Roughness below which reflection is a single mirror ray and lights give no highlight.
pub const MIRROR_ROUGHNESS: f32 = 0.05;

/// What the client shows at a diffuse surface point.
pub trait DiffuseShade: Sync {
    /// Linear RGB of the client's shading at `point` (unit `normal` facing the viewer) of an
    /// instance with `material`.
    fn shade(&self, point: Vec3, normal: Vec3, instance: u32, material: &Material) -> Vec3;
}

/// Settings of the correction tracer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TraceSettings {
    /// Bounces after the primary hit (depth limit).
    pub max_depth: u32,
    /// Distributed reflection rays at the first glossy hit of a path (one at later hits).
    pub glossy_rays: u32,
    /// Shadow rays per rectangular light.
    pub area_samples: u32,
    /// Linear RGB returned by rays that hit nothing.
    pub sky: Vec3,
    /// Seed of every random choice.
    pub seed: u64,
    /// Whether a primary hit's radiance includes the diffuse part of its own surface. Off
    /// over a lit base: a sample is then the view-dependent part only (reflection,
    /// refraction, highlights), and the client keeps [`diffuse_weight`] of its own diffuse
    /// light under it ([`crate::splat::SplatTarget::keep`]).
    pub own_diffuse: bool,
}

impl Default for TraceSettings {
    /// Depth 4, 8 glossy rays, 4 area-light samples, a grey sky, seed 1, the own diffuse
    /// part included.
    fn default() -> Self {
        Self {
            max_depth: 4,
            glossy_rays: 8,
            area_samples: 4,
            sky: Vec3::new(0.62, 0.66, 0.72),
            seed: 1,
            own_diffuse: true,
        }
    }
}

/// The weight of the diffuse part of `material`'s radiance seen at `n_v` = n·v:
/// `(1 − metallic)·(1 − transmission)·(1 − F)`, F Schlick's Fresnel term (its largest
/// channel) with the material's F0. 1 for a diffuse dielectric seen head on, less towards
/// grazing angles, 0 for metals and clear glass.
pub fn diffuse_weight(material: &Material, n_v: f32) -> f32 {
    let fv = schlick(f0_of(material), n_v.max(1e-4));
    (1.0 - material.metallic) * (1.0 - material.transmission) * (1.0 - fv.max_element())
}

/// Normal-incidence reflectance of `m`: the dielectric's from its index, the base colour for
/// metals, blended by `metallic`.
fn f0_of(m: &Material) -> Vec3 {
    let dielectric_f0 = ((m.ior - 1.0) / (m.ior + 1.0)).powi(2);
    Vec3::splat(dielectric_f0).lerp(m.base_color.truncate(), m.metallic)
}

/// Traces correction samples of a scene: every instance at its stored transform, or at a
/// pose of its animation ([`CorrectionTracer::posed`]).
pub struct CorrectionTracer<'a> {
    scene: &'a Scene,
    tracer: &'a Tracer,
    shade: &'a dyn DiffuseShade,
    settings: TraceSettings,
    /// Hits to surfaces, in the pose the tracer holds.
    surfaces: Surfaces<'a>,
}

/// Schlick's Fresnel approximation.
fn schlick(f0: Vec3, cos: f32) -> Vec3 {
    f0 + (Vec3::ONE - f0) * (1.0 - cos.clamp(0.0, 1.0)).powi(5)
}

/// Exact Fresnel reflectance of an unpolarised dielectric interface (`eta` = n_in / n_out).
fn fresnel_dielectric(cos_in: f32, eta: f32) -> f32 {
    let sin2_t = eta * eta * (1.0 - cos_in * cos_in);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let rs = (eta * cos_in - cos_t) / (eta * cos_in + cos_t);
    let rp = (cos_in - eta * cos_t) / (cos_in + eta * cos_t);
    0.5 * (rs * rs + rp * rp)
}

/// GGX normal distribution for `alpha` = roughness².
fn ggx_d(n_h: f32, alpha: f32) -> f32 {
    let a2 = alpha * alpha;
    let d = n_h * n_h * (a2 - 1.0) + 1.0;
    a2 / (std::f32::consts::PI * d * d)
}

/// Smith–Schlick shadowing-masking for GGX.
fn smith_g(n_v: f32, n_l: f32, alpha: f32) -> f32 {
    let k = alpha * 0.5;
    (n_v / (n_v * (1.0 - k) + k)) * (n_l / (n_l * (1.0 - k) + k))
}

impl<'a> CorrectionTracer<'a> {
    /// A tracer over `scene`; `tracer` must hold its triangles in [`psao_trace::GeometryMode::Primary`].
    pub fn new(
        scene: &'a Scene,
        tracer: &'a Tracer,
        shade: &'a dyn DiffuseShade,
        settings: TraceSettings,
    ) -> Self {
        Self {
            scene,
            tracer,
            shade,
            settings,
            surfaces: Surfaces::new(scene),
        }
    }

    /// The same tracer for the scene in `pose`, which its `tracer` must hold (see
    /// [`Tracer::apply_pose`]): surfaces take the posed transforms and skinned vertices.
    pub fn posed(mut self, pose: &'a ScenePose) -> Self {
        self.surfaces = self.surfaces.posed(pose);
        self
    }

    fn hit(&self, ray: &Ray) -> Option<Hit> {
        let mut out = [None];
        self.tracer.intersect(std::slice::from_ref(ray), &mut out);
        out[0]
    }

    fn occluded(&self, ray: &Ray) -> bool {
        let mut out = [false];
        self.tracer.occluded(std::slice::from_ref(ray), &mut out);
        out[0]
    }

    fn surface(&self, ray: &Ray, hit: &Hit) -> Option<SurfaceHit> {
        self.surfaces.surface(ray, hit)
    }

    /// The radiance arriving along the primary ray from `eye` through direction `dir`, with
    /// the hit it found (`None` on a miss). `frame` and `pixel` pick the random numbers.
    pub fn primary(
        &self,
        eye: Vec3,
        dir: Vec3,
        frame: u64,
        pixel: u64,
    ) -> (Vec3, Option<(Vec3, Vec3)>) {
        let key = self.key(frame, pixel);
        let ray = Ray::new(eye, dir.normalize(), f32::INFINITY);
        let Some(hit) = self.hit(&ray) else {
            return (self.settings.sky, None);
        };
        let Some(s) = self.surface(&ray, &hit) else {
            return (self.settings.sky, None);
        };
        let l = self.shade_surface(&ray, &s, 0, key, true);
        (l, Some((s.point, s.normal)))
    }

    /// The object id (instance + 1 on a non-diffuse material, else 0) the primary ray of
    /// pixel (`x`, `y`) of a `width × height` image of `camera` hits.
    pub fn object_at(&self, camera: &Camera, width: u32, height: u32, x: i32, y: i32) -> u32 {
        let ray = pixel_ray(camera, width, height, x, y);
        self.hit(&ray)
            .and_then(|hit| self.surface(&ray, &hit))
            .map_or(0, |s| self.object_of(&s))
    }

    fn object_of(&self, s: &SurfaceHit) -> u32 {
        let non_diffuse = self
            .scene
            .materials
            .get(s.material)
            .is_some_and(Material::is_non_diffuse);
        if non_diffuse {
            s.instance + 1
        } else {
            0
        }
    }

    /// The correction sample of pixel (`x`, `y`) of a `width × height` image of `camera` at
    /// camera age `age`: its surface from the primary ray (not a G-buffer), so a server can
    /// trace it from the camera alone. `None` when the pixel does not show `object`. Its
    /// colour equals [`Self::primary`]'s for the same pixel and age.
    #[allow(clippy::too_many_arguments)]
    pub fn camera_sample(
        &self,
        camera: &Camera,
        width: u32,
        height: u32,
        x: i32,
        y: i32,
        object: u32,
        level: u8,
        age: u32,
    ) -> Option<Sample> {
        if x < 0 || y < 0 || x as u32 >= width || y as u32 >= height {
            return None;
        }
        let ray = pixel_ray(camera, width, height, x, y);
        let s = self.surface(&ray, &self.hit(&ray)?)?;
        if self.object_of(&s) != object {
            return None;
        }
        let pixel = y as u64 * width as u64 + x as u64;
        let color = self.shade_surface(&ray, &s, 0, self.key(age as u64, pixel), true);
        let v = (camera.position - s.point).normalize_or_zero();
        Some(Sample {
            position: s.point,
            normal: s.normal,
            ndotv: s.normal.dot(v).clamp(-1.0, 1.0),
            color: color.max(Vec3::ZERO).to_array(),
            object,
            level,
            age,
        })
    }

    fn key(&self, frame: u64, pixel: u64) -> u64 {
        hash64(self.settings.seed ^ hash64(frame.wrapping_mul(0x9e37_79b9) ^ hash64(pixel)))
    }

    fn radiance(&self, ray: &Ray, depth: u32, key: u64) -> Vec3 {
        let Some(hit) = self.hit(ray) else {
            return self.settings.sky;
        };
        match self.surface(ray, &hit) {
            Some(s) => self.shade_surface(ray, &s, depth, key, false),
            None => self.settings.sky,
        }
    }

    fn shade_surface(&self, ray: &Ray, s: &SurfaceHit, depth: u32, key: u64, branch: bool) -> Vec3 {
        let fallback = Material::default();
        let m = self.scene.materials.get(s.material).unwrap_or(&fallback);
        if !m.is_non_diffuse() || depth >= self.settings.max_depth {
            return self.shade.shade(s.point, s.normal, s.instance, m);
        }
        let v = -ray.dir;
        let n = s.normal;
        let n_v = n.dot(v).max(1e-4);
        let base = m.base_color.truncate();
        let f0 = f0_of(m);
        let fv = schlick(f0, n_v);
        let opaque = 1.0 - m.transmission;
        let dielectric = 1.0 - m.metallic;
        let mut out = Vec3::ZERO;
        // The diffuse part, as the client shows it (left to the client at a primary hit
        // over a lit base).
        let kd = diffuse_weight(m, n_v);
        if kd > 0.0 && (depth > 0 || self.settings.own_diffuse) {
            out += kd * self.shade.shade(s.point, n, s.instance, m);
        }
        let alpha = (m.roughness * m.roughness).max(1e-3);
        let next = |salt: u64| hash64(key ^ salt.wrapping_mul(0xd6e8_feb8_6659_fd93));
        // Specular reflection (metals fully, dielectrics by Fresnel).
        let spec_weight = if m.transmission > 0.0 {
            dielectric * opaque
        } else {
            1.0
        };
        if spec_weight > 0.0 {
            let origin = ray_offset(s.point, s.face);
            if m.roughness < MIRROR_ROUGHNESS {
                let r = ray.dir - 2.0 * ray.dir.dot(n) * n;
                if r.dot(s.face) > 0.0 {
                    let l = self.radiance(&Ray::new(origin, r, f32::INFINITY), depth + 1, next(1));
                    out += spec_weight * fv * l;
                }
            } else {
                let count = if branch {
                    self.settings.glossy_rays.max(1)
                } else {
                    1
                };
                let (t, b) = orthonormal_basis(n);
                let mut sum = Vec3::ZERO;
                for i in 0..count {
                    let (u1, u2) = sample_2d(self.settings.seed, key, i);
                    let tan2 = alpha * alpha * u1 / (1.0 - u1).max(1e-6);
                    let cos_t = 1.0 / (1.0 + tan2).sqrt();
                    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
                    let phi = std::f32::consts::TAU * u2;
                    let h =
                        (t * (sin_t * phi.cos()) + b * (sin_t * phi.sin()) + n * cos_t).normalize();
                    let v_h = v.dot(h);
                    if v_h <= 0.0 {
                        continue;
                    }
                    let l = 2.0 * v_h * h - v;
                    let n_l = n.dot(l);
                    if n_l <= 0.0 || l.dot(s.face) <= 0.0 {
                        continue;
                    }
                    let weight = schlick(f0, v_h) * smith_g(n_v, n_l, alpha) * v_h
                        / (h.dot(n).max(1e-4) * n_v);
                    let li = self.radiance(
                        &Ray::new(origin, l, f32::INFINITY),
                        depth + 1,
                        next(2 + i as u64),
                    );
                    sum += weight * li;
                }
                out += spec_weight * sum / count as f32;
                out += spec_weight * self.highlights(s, v, n_v, f0, alpha, key);
            }
        }
        // Refraction through transmissive dielectrics.
        if m.transmission > 0.0 && dielectric > 0.0 {
            let eta = if s.front { 1.0 / m.ior } else { m.ior };
            let cos_in = n_v;
            let f = fresnel_dielectric(cos_in, eta);
            let reflected = ray.dir - 2.0 * ray.dir.dot(n) * n;
            let weight = dielectric * m.transmission;
            if f > 0.0 && reflected.dot(s.face) > 0.0 {
                let origin = ray_offset(s.point, s.face);
                let l = self.radiance(
                    &Ray::new(origin, reflected, f32::INFINITY),
                    depth + 1,
                    next(101),
                );
                out += weight * f * l;
            }
            if f < 1.0 {
                let sin2_t = eta * eta * (1.0 - cos_in * cos_in);
                let refracted =
                    (eta * ray.dir + (eta * cos_in - (1.0 - sin2_t).sqrt()) * n).normalize();
                if refracted.dot(s.face) < 0.0 {
                    let origin = ray_offset(s.point, -s.face);
                    let l = self.radiance(
                        &Ray::new(origin, refracted, f32::INFINITY),
                        depth + 1,
                        next(102),
                    );
                    out += weight * (1.0 - f) * base * l;
                }
            }
        }
        out
    }

    /// Glossy highlights of the scene's lights at `s`, with shadow rays.
    fn highlights(
        &self,
        s: &SurfaceHit,
        v: Vec3,
        n_v: f32,
        f0: Vec3,
        alpha: f32,
        key: u64,
    ) -> Vec3 {
        let n = s.normal;
        let origin = ray_offset(s.point, s.face);
        let brdf = |l: Vec3| -> Option<(Vec3, f32)> {
            let n_l = n.dot(l);
            if n_l <= 0.0 || l.dot(s.face) <= 0.0 {
                return None;
            }
            let h = (l + v).normalize();
            let spec =
                schlick(f0, v.dot(h)) * ggx_d(n.dot(h).max(0.0), alpha) * smith_g(n_v, n_l, alpha)
                    / (4.0 * n_v * n_l);
            Some((spec, n_l))
        };
        let mut out = Vec3::ZERO;
        for (li, light) in self.scene.lights.iter().enumerate() {
            let e = light.color * light.power;
            match light.shape {
                LightShape::Sun { direction } => {
                    let l = direction.normalize();
                    if let Some((f, n_l)) = brdf(l) {
                        if !self.occluded(&Ray::new(origin, l, f32::INFINITY)) {
                            out += f * e * n_l;
                        }
                    }
                }
                LightShape::Point { position } => {
                    let d = position - origin;
                    let dist = d.length();
                    let l = d / dist;
                    if let Some((f, n_l)) = brdf(l) {
                        if !self.occluded(&Ray::new(origin, l, dist * (1.0 - 1e-4))) {
                            out += f * e * n_l / (dist * dist);
                        }
                    }
                }
                LightShape::Rect {
                    centre,
                    half_u,
                    half_v,
                } => {
                    let area = 4.0 * half_u.cross(half_v).length();
                    let light_n = half_u.cross(half_v).normalize();
                    let count = self.settings.area_samples.max(1);
                    let mut sum = Vec3::ZERO;
                    for i in 0..count {
                        let (a, b) =
                            sample_2d(self.settings.seed, hash64(key ^ (li as u64 + 1)), i);
                        let q = centre + (2.0 * a - 1.0) * half_u + (2.0 * b - 1.0) * half_v;
                        let d = q - origin;
                        let dist2 = d.length_squared();
                        let dist = dist2.sqrt();
                        let l = d / dist;
                        let cos_light = (-l).dot(light_n);
                        if cos_light <= 0.0 {
                            continue;
                        }
                        if let Some((f, n_l)) = brdf(l) {
                            if !self.occluded(&Ray::new(origin, l, dist * (1.0 - 1e-4))) {
                                sum += f * e * n_l * cos_light * area / dist2;
                            }
                        }
                    }
                    out += sum / count as f32;
                }
            }
        }
        out
    }
}

/// The primary ray through the centre of pixel (`x`, `y`).
fn pixel_ray(camera: &Camera, width: u32, height: u32, x: i32, y: i32) -> Ray {
    let dir = camera.ray_direction(x as f32 + 0.5, y as f32 + 0.5, width, height);
    Ray::new(camera.position, dir.normalize(), f32::INFINITY)
}
