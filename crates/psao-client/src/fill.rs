//! Irradiance for the pixels whose reconstruction found no compatible point (DESIGN §12,
//! docs/LIGHTING.md "Pixels without a compatible point"): thin geometry the points do not
//! resolve, silhouettes, and at a session's start the surfaces whose cells have not arrived
//! yet. Such a pixel takes, instead of black, the normal-weighted mean irradiance of the
//! nearest pixels around it that found points in their own 2×2×2 block.
//!
//! The search visits rings at pixel distances [`FILL_RINGS`] (nearest first), eight
//! directions each (the four axes and the four diagonals). A donor `j` of a hole with normal
//! `n` weighs `s⁸` with `s = (1 + n·nⱼ) / 2` (1 for the same normal, 1/256 at a right
//! angle, 0 facing the opposite way: an edge-aware weight that prefers the same surface
//! orientation but still fills a rod or a corner from what surrounds it); the search stops
//! after the first ring whose accumulated weight reaches [`FILL_ENOUGH`], and the pixel
//! gets `Σ w·Eⱼ / Σ w` over every donor visited so far (zero when none was found). Donors
//! are pixels whose reconstruction used the kernel or the block's nearest point, never a
//! pixel that was itself filled or that took the ring fallback, so the result does not
//! depend on the order pixels are processed in. The browser's shader (web/src/aoshader.ts)
//! performs the same search with the same weights.

use glam::Vec3;
use psao_raster::GBuffer;
use rayon::prelude::*;

use crate::gather::Found;

/// Pixel distances of the rings searched around a pixel without a compatible point,
/// nearest first (up to 128 pixels: a sixth of a 720p frame's width).
pub(crate) const FILL_RINGS: [i32; 8] = [1, 2, 4, 8, 16, 32, 64, 128];

/// Accumulated donor weight after which the search stops: one donor of the same orientation.
pub(crate) const FILL_ENOUGH: f32 = 1.0;

/// The eight directions of a ring, in the order the shader visits them.
const DIRECTIONS: [(i32, i32); 8] = [
    (1, 0),
    (1, 1),
    (0, 1),
    (-1, 1),
    (-1, 0),
    (-1, -1),
    (0, -1),
    (1, -1),
];

/// Weight of a donor with unit normal `nj` for a hole with unit normal `n`: `((1 + n·nⱼ)/2)⁸`
/// by repeated squaring (the shader computes it alike).
#[inline]
pub(crate) fn donor_weight(n: Vec3, nj: Vec3) -> f32 {
    let s = (0.5 * (1.0 + n.dot(nj))).max(0.0);
    let s2 = s * s;
    let s4 = s2 * s2;
    s4 * s4
}

/// Fill `irradiance` (row-major over `gbuffer`) at every covered pixel whose reconstruction
/// found nothing (`found[i] == Found::Nothing`), as the module documentation says. Pixels
/// missing from `found`, `irradiance` or the G-buffer's arrays are left alone.
pub(crate) fn fill_holes(gbuffer: &GBuffer, found: &[Found], irradiance: &mut [Vec3]) {
    let (width, height) = (gbuffer.width as i32, gbuffer.height as i32);
    let pixels = found
        .len()
        .min(irradiance.len())
        .min(gbuffer.normal.len())
        .min(gbuffer.instance.len());
    let donor = |x: i32, y: i32| -> Option<usize> {
        let j = (x >= 0 && y >= 0 && x < width && y < height).then(|| (y * width + x) as usize)?;
        (j < pixels && found[j] == Found::Block).then_some(j)
    };
    let shared: &[Vec3] = irradiance;
    let filled: Vec<(usize, Vec3)> = (0..pixels)
        .into_par_iter()
        .filter(|&i| found[i] == Found::Nothing && gbuffer.covered(i))
        .filter_map(|i| {
            let n = gbuffer.normal[i];
            let (x, y) = ((i as i32) % width.max(1), (i as i32) / width.max(1));
            let (mut w_sum, mut e_sum) = (0.0f32, Vec3::ZERO);
            for d in FILL_RINGS {
                for (dx, dy) in DIRECTIONS {
                    if let Some(j) = donor(x + dx * d, y + dy * d) {
                        let w = donor_weight(n, gbuffer.normal[j]);
                        w_sum += w;
                        e_sum += w * shared[j];
                    }
                }
                if w_sum >= FILL_ENOUGH {
                    break;
                }
            }
            (w_sum > 0.0).then(|| (i, e_sum / w_sum))
        })
        .collect();
    for (i, e) in filled {
        irradiance[i] = e;
    }
}
