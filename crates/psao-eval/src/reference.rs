//! The per-pixel reference AO: DESIGN §2's definition evaluated at every covered G-buffer pixel.

use crate::AoImage;
use psao_raster::GBuffer;
use psao_trace::ao::{self, Medium};
use psao_trace::Tracer;

/// Settings of a reference AO image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReferenceSettings {
    /// Rays per pixel.
    pub spp: u32,
    /// AO radius in scene units.
    pub radius: f32,
    /// Seed of the sample pattern (vary it per frame for independent noise).
    pub seed: u64,
}

/// Pixels handed to the tracer at once; also the granularity of progress reports.
const PIXELS_PER_BLOCK: usize = 2048;

/// AO at every pixel of `gbuffer` (1 where nothing is covered), traced with `tracer`, the
/// rays passing through a participating `medium` if any (the same transmittance-weighted
/// estimator as the server's points, [`ao::sample_value`]).
///
/// `progress` is called with the number of pixels finished since its previous call.
/// The result does not depend on the number of threads.
pub fn reference_ao_in(
    gbuffer: &GBuffer,
    tracer: &Tracer,
    medium: Option<&dyn Medium>,
    settings: &ReferenceSettings,
    progress: &(dyn Fn(u64) + Sync),
) -> AoImage {
    let mut image = AoImage::filled(gbuffer.width, gbuffer.height, 1.0);
    let covered: Vec<usize> = (0..image.data.len())
        .filter(|&i| gbuffer.covered(i))
        .collect();
    progress((image.data.len() - covered.len()) as u64);
    for block in covered.chunks(PIXELS_PER_BLOCK) {
        let points: Vec<_> = block
            .iter()
            .map(|&i| (gbuffer.position[i], gbuffer.normal[i]))
            .collect();
        let values = ao::ambient_occlusion_batch_in(
            tracer,
            medium,
            &points,
            settings.radius,
            settings.spp,
            settings.seed,
            |k| block[k] as u64,
        );
        for (&i, v) in block.iter().zip(values) {
            image.data[i] = v;
        }
        progress(block.len() as u64);
    }
    image
}
