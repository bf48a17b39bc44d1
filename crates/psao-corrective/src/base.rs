//! The base (uncorrected) image's shading and the object ids of a frame.
//!
//! The base image is what the client shows: `base colour × (ambient × AO + light × n·l)`
//! (`psao_client::composite`), or when the session is lit `base colour / π × (direct +
//! irradiance)` ([`GiShade`]). [`TracedAoShade`] evaluates that shading at any surface point
//! with AO traced by the one estimator of DESIGN §2 (the one the server's points carry), so
//! rays of the correction tracer that reach diffuse surfaces return what the client shows there.

use crate::cache::view_tolerance;
use crate::trace::{diffuse_weight, DiffuseShade};
use glam::Vec3;
use psao_client::Shading;
use psao_raster::GBuffer;
use psao_scene::{Material, Scene};
use psao_trace::ao::{ambient_occlusion, hash64};
use psao_trace::gi::DiffuseLighting;
use psao_trace::Tracer;
use std::collections::HashMap;

/// Client shading with AO traced at the shaded point.
pub struct TracedAoShade<'a> {
    /// Tracer in [`psao_trace::GeometryMode::Occlusion`] (alpha-masked geometry left out).
    pub tracer: &'a Tracer,
    /// The client's lighting.
    pub shading: Shading,
    /// AO ray length.
    pub radius: f32,
    /// AO rays per point.
    pub spp: u32,
    /// Seed of the AO rays.
    pub seed: u64,
}

impl TracedAoShade<'_> {
    /// AO at `point` with `normal`; the sampling key is hashed from the position, so the same
    /// point always gets the same value.
    pub fn ao(&self, point: Vec3, normal: Vec3) -> f32 {
        let key = point_key(point);
        ambient_occlusion(
            self.tracer,
            point,
            normal,
            self.radius,
            self.spp,
            self.seed,
            key,
        )
    }

    /// The client's shading for a known AO value.
    pub fn shade_with_ao(&self, normal: Vec3, material: &Material, ao: f32) -> Vec3 {
        let base = material.base_color.truncate();
        let direct = self.shading.light
            * normal
                .dot(self.shading.light_dir.normalize_or_zero())
                .max(0.0);
        base * (self.shading.ambient * ao + direct)
    }
}

impl DiffuseShade for TracedAoShade<'_> {
    fn shade(&self, point: Vec3, normal: Vec3, _instance: u32, material: &Material) -> Vec3 {
        self.shade_with_ao(normal, material, self.ao(point, normal))
    }
}

/// The lit client's shading (DESIGN §12): a Lambertian surface under the diffuse lighting of
/// [`psao_trace::gi`], `base colour / π × E` with the irradiance E path-traced at the shaded
/// point with a fixed number of paths. The paths are keyed by the point's position, so the
/// same point always gets the same value (as [`TracedAoShade`]'s AO).
pub struct GiShade<'a> {
    /// Tracer in [`psao_trace::GeometryMode::Occlusion`], in the pose `lighting` has.
    pub tracer: &'a Tracer,
    /// The scene's lights, environment and bounces.
    pub lighting: DiffuseLighting<'a>,
    /// Paths per point.
    pub paths: u32,
    /// Seed of the paths.
    pub seed: u64,
}

impl GiShade<'_> {
    /// The irradiance E at `point` with unit `normal` (the mean of the paths).
    pub fn irradiance(&self, point: Vec3, normal: Vec3) -> Vec3 {
        let paths = self.paths.max(1);
        let sum = self.lighting.irradiance_sum(
            self.tracer,
            point,
            normal,
            normal,
            0,
            paths,
            self.seed,
            point_key(point),
        );
        sum / paths as f32
    }
}

impl DiffuseShade for GiShade<'_> {
    fn shade(&self, point: Vec3, normal: Vec3, _instance: u32, material: &Material) -> Vec3 {
        material.base_color.truncate() * self.irradiance(point, normal) / std::f32::consts::PI
    }
}

/// A sampling key hashed from a position's bits.
fn point_key(point: Vec3) -> u64 {
    let [x, y, z] = point.to_array().map(f32::to_bits);
    hash64(x as u64 ^ hash64((y as u64) << 32 | z as u64))
}

/// Whether a pixel can show `object` (see [`object_ids`]): it is `instance + 1` of an instance
/// of `scene` whose mesh has a non-diffuse material.
pub fn is_object(scene: &Scene, object: u32) -> bool {
    let Some(instance) = object.checked_sub(1) else {
        return false;
    };
    (scene.instances.get(instance as usize))
        .and_then(|i| scene.meshes.get(i.mesh))
        .and_then(|m| scene.materials.get(m.material))
        .is_some_and(Material::is_non_diffuse)
}

/// Per object id of `scene` (see [`object_ids`]), the largest turn of its samples' view
/// direction: [`crate::cache::view_tolerance`] of its material's roughness.
pub fn view_tolerances(scene: &Scene, mirror_turn: f32) -> HashMap<u32, f32> {
    (0..scene.instances.len() as u32)
        .filter_map(|i| {
            let object = i + 1;
            let m = scene.meshes.get(scene.instances[i as usize].mesh)?;
            let material = scene.materials.get(m.material)?;
            is_object(scene, object)
                .then(|| (object, view_tolerance(mirror_turn, material.roughness)))
        })
        .collect()
}

/// Per pixel of `g` seen from `eye`, the share of a lit base that stays under a
/// view-dependent correction ([`crate::splat::SplatTarget::keep`]): the diffuse weight of the
/// pixel's material at its view angle ([`diffuse_weight`], as the correction tracer weighs
/// the diffuse part of a non-diffuse hit); 1 where nothing is covered.
pub fn diffuse_keep(scene: &Scene, g: &GBuffer, eye: Vec3) -> Vec<f32> {
    (0..g.len())
        .map(|i| {
            let Some(m) = g.material(scene, i).and_then(|m| scene.materials.get(m)) else {
                return 1.0;
            };
            let v = (eye - g.position[i]).normalize_or_zero();
            diffuse_weight(m, g.normal[i].dot(v).abs())
        })
        .collect()
}

/// Object id per pixel: `instance + 1` where the pixel shows a non-diffuse material (each
/// instance has one mesh with one material, so this is instance × non-diffuse material), 0
/// elsewhere.
pub fn object_ids(scene: &Scene, g: &GBuffer) -> Vec<u32> {
    (0..g.len())
        .map(|i| {
            let non_diffuse = g
                .material(scene, i)
                .and_then(|m| scene.materials.get(m))
                .is_some_and(Material::is_non_diffuse);
            if non_diffuse {
                g.instance[i] + 1
            } else {
                0
            }
        })
        .collect()
}
