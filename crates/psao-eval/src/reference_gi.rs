//! The per-pixel reference of the diffuse lighting (`psao reference --lighting gi`): at every
//! covered G-buffer pixel, the irradiance E of [`psao_trace::gi`] (direct light of the
//! scene's lights with shadow rays, the environment, and a fixed number of indirect diffuse
//! bounces against the base colours; see that module for the estimator and why the depth is
//! fixed) path-traced from the pixel's surface point, shown as the Lambertian radiance
//! `ρ/π · E` with ρ the pixel's base colour. It uses nothing of the point method: no points,
//! no reconstruction, no client shading.

use glam::Vec3;
use psao_raster::GBuffer;
use psao_scene::{Material, Scene};
use psao_trace::gi::DiffuseLighting;
use psao_trace::Tracer;
use rayon::prelude::*;

/// Settings of a reference lighting image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GiSettings {
    /// Paths per pixel.
    pub spp: u32,
    /// Seed of the sample pattern (vary it per frame for independent noise).
    pub seed: u64,
    /// Linear RGB of pixels that no surface covers.
    pub background: Vec3,
}

/// A linear RGB image, row-major from the top-left pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct RgbImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Linear RGB per pixel.
    pub data: Vec<[f32; 3]>,
}

/// Pixels per parallel work item; also the granularity of progress reports.
const PIXELS_PER_BLOCK: usize = 256;

/// The reference radiance of every pixel of `gbuffer` under `lighting` (whose pose `tracer`
/// holds), `settings.background` where nothing is covered. Pixel i's paths are keyed by i,
/// so the result does not depend on the number of threads. `progress` is called with the
/// number of pixels finished since its previous call.
pub fn reference_gi(
    gbuffer: &GBuffer,
    scene: &Scene,
    lighting: &DiffuseLighting,
    tracer: &Tracer,
    settings: &GiSettings,
    progress: &(dyn Fn(u64) + Sync),
) -> RgbImage {
    let pixels = gbuffer.width as usize * gbuffer.height as usize;
    let fallback = Material::default().base_color.truncate();
    let spp = settings.spp.max(1);
    let mut data = vec![settings.background.to_array(); pixels];
    data.par_chunks_mut(PIXELS_PER_BLOCK)
        .enumerate()
        .for_each(|(block, out)| {
            for (j, o) in out.iter_mut().enumerate() {
                let i = block * PIXELS_PER_BLOCK + j;
                if !gbuffer.covered(i) {
                    continue;
                }
                let base = gbuffer
                    .material(scene, i)
                    .and_then(|m| scene.materials.get(m))
                    .map_or(fallback, |m| m.base_color.truncate());
                let (x, n, face) = (
                    gbuffer.position[i],
                    gbuffer.normal[i],
                    gbuffer.geometric_normal[i],
                );
                let e =
                    lighting.irradiance_sum(tracer, x, n, face, 0, spp, settings.seed, i as u64)
                        / spp as f32;
                *o = (base * e / std::f32::consts::PI).to_array();
            }
            progress(out.len() as u64);
        });
    RgbImage {
        width: gbuffer.width,
        height: gbuffer.height,
        data,
    }
}
