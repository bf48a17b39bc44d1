//! The client's final image, and its 8-bit sRGB encoding. Without lighting (AO only):
//! base colour × (ambient × AO + direct sun light) ([`composite`]). With lighting (DESIGN
//! §12): the Lambertian radiance `base colour / π × (direct + irradiance)`
//! ([`composite_lit`]), where the irradiance reconstructed from the points carries the
//! environment, area lights and all bounced light, already occluded by the scene (so AO does
//! not scale it again), and `direct` is the shadow-mapped light of suns and point lights
//! ([`direct_light`]).

use glam::Vec3;
use psao_raster::{GBuffer, ShadowMaps};
use psao_scene::{Material, Scene};
use rayon::prelude::*;

/// Linear RGB of pixels that no surface covers: a constant sky grey.
pub const SKY_GREY: [f32; 3] = [0.62, 0.66, 0.72];

/// A simple lighting model for compositing AO.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shading {
    /// Direction towards the light, world space (normalised when used).
    pub light_dir: Vec3,
    /// Intensity of the directional light.
    pub light: f32,
    /// Intensity of the ambient term that AO attenuates.
    pub ambient: f32,
}

impl Default for Shading {
    /// A sun from above and in front (+y up, +z front), ambient 0.6, light 0.5.
    fn default() -> Self {
        Self {
            light_dir: Vec3::new(0.35, 1.0, 0.6).normalize(),
            light: 0.5,
            ambient: 0.6,
        }
    }
}

/// Linear RGB per pixel: `base_colour × (ambient × AO + light × max(0, n·l))` with the
/// material's base colour and the G-buffer's camera-facing shading normal; [`SKY_GREY`]
/// where nothing is covered. A pixel whose material is unknown uses the default material's
/// colour; a pixel without an AO value (short `ao`) uses AO 1, one missing from the G-buffer's
/// attribute arrays counts as uncovered.
pub fn composite(scene: &Scene, gbuffer: &GBuffer, ao: &[f32], shading: &Shading) -> Vec<[f32; 3]> {
    composite_tinted(scene, gbuffer, ao, &[], shading)
}

/// [`composite`] with the ambient term of each pixel scaled per channel by `tint`:
/// `base_colour × (ambient × AO × tint + light × max(0, n·l))` (relit characters' pixels
/// carry their self-shadowing there, docs/RELIGHTING.md "Served characters"). A pixel
/// missing from `tint` uses 1.
pub fn composite_tinted(
    scene: &Scene,
    gbuffer: &GBuffer,
    ao: &[f32],
    tint: &[Vec3],
    shading: &Shading,
) -> Vec<[f32; 3]> {
    let light_dir = shading.light_dir.normalize_or_zero();
    shade(scene, gbuffer, |i, base, normal| {
        let occlusion = ao.get(i).copied().unwrap_or(1.0);
        let tint = tint.get(i).copied().unwrap_or(Vec3::ONE);
        let direct = shading.light * normal.dot(light_dir).max(0.0);
        base * (shading.ambient * occlusion * tint + direct)
    })
}

/// Linear RGB radiance per pixel with lighting: `base_colour / π × (direct + irradiance)`
/// (the convention of the per-pixel reference, `psao_eval::reference_gi`), with the
/// material's base colour as in [`composite`]; [`SKY_GREY`] where nothing is covered. A pixel
/// missing from `irradiance` or `direct` counts as receiving none of it.
pub fn composite_lit(
    scene: &Scene,
    gbuffer: &GBuffer,
    irradiance: &[Vec3],
    direct: &[Vec3],
) -> Vec<[f32; 3]> {
    shade(scene, gbuffer, |i, base, _| {
        let e = irradiance.get(i).copied().unwrap_or(Vec3::ZERO)
            + direct.get(i).copied().unwrap_or(Vec3::ZERO);
        base * e / std::f32::consts::PI
    })
}

/// The shadow-mapped direct irradiance of `shadows` ([`ShadowMaps::direct`]) at every covered
/// pixel of `gbuffer` (its position and shading normal); zero elsewhere.
pub fn direct_light(shadows: &ShadowMaps, gbuffer: &GBuffer) -> Vec<Vec3> {
    let pixels = gbuffer.width as usize * gbuffer.height as usize;
    (0..pixels)
        .into_par_iter()
        .map(|i| match (gbuffer.position.get(i), gbuffer.normal.get(i)) {
            (Some(&p), Some(&n)) if gbuffer.covered(i) => shadows.direct(p, n),
            _ => Vec3::ZERO,
        })
        .collect()
}

/// `colour(pixel, base colour, shading normal)` at every covered pixel, [`SKY_GREY`] where
/// nothing is covered (or the G-buffer's attribute arrays miss the pixel). An unknown
/// material uses the default material's colour.
fn shade<F>(scene: &Scene, gbuffer: &GBuffer, colour: F) -> Vec<[f32; 3]>
where
    F: Fn(usize, Vec3, Vec3) -> Vec3 + Sync,
{
    let fallback = Material::default().base_color.truncate();
    let pixels = gbuffer.width as usize * gbuffer.height as usize;
    (0..pixels)
        .into_par_iter()
        .map(|i| {
            let (Some(&instance), Some(&normal)) = (gbuffer.instance.get(i), gbuffer.normal.get(i))
            else {
                return SKY_GREY;
            };
            if instance == GBuffer::NONE {
                return SKY_GREY;
            }
            let base = gbuffer
                .material(scene, i)
                .and_then(|m| scene.materials.get(m))
                .map_or(fallback, |m| m.base_color.truncate());
            colour(i, base, normal).to_array()
        })
        .collect()
}

/// 8-bit sRGB-encoded RGB triples (3 bytes per pixel, ready for PNG) of linear RGB values,
/// clamped to [0, 1].
pub fn composite_srgb8(linear: &[[f32; 3]]) -> Vec<u8> {
    linear
        .par_iter()
        .flat_map_iter(|rgb| rgb.map(encode_srgb))
        .collect()
}

/// The sRGB transfer function of one linear value, quantised to 8 bits.
pub fn encode_srgb(linear: f32) -> u8 {
    let c = linear.clamp(0.0, 1.0);
    let s = if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0).round() as u8
}
