//! Colour image metrics of corrected frames against the reference: PSNR and FLIP on the 8-bit
//! sRGB images a viewer sees, and FLIP averaged with saliency weights.

use psao_client::composite_srgb8;

/// PSNR in dB of 8-bit `test` against `reference` (∞ when identical, as `f64::INFINITY`).
pub fn psnr(reference: &[u8], test: &[u8]) -> f64 {
    let se: f64 = reference
        .iter()
        .zip(test)
        .map(|(&a, &b)| {
            let d = a as f64 - b as f64;
            d * d
        })
        .sum();
    let mse = se / reference.len().max(1) as f64;
    if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (255.0f64 * 255.0 / mse).log10()
    }
}

/// The per-pixel FLIP error map of 8-bit sRGB `test` against `reference` (`width × height`).
pub fn flip_map(reference: &[u8], test: &[u8], width: u32, height: u32) -> Vec<f32> {
    let a = nv_flip::FlipImageRgb8::with_data(width, height, reference);
    let b = nv_flip::FlipImageRgb8::with_data(width, height, test);
    nv_flip::flip(a, b, nv_flip::DEFAULT_PIXELS_PER_DEGREE).to_vec()
}

/// PSNR, mean FLIP and saliency-weighted FLIP of one frame.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct FrameError {
    /// PSNR in dB (capped at 99 for identical images so averages stay finite).
    pub psnr: f64,
    /// Mean FLIP.
    pub flip: f64,
    /// FLIP averaged with the reference's normalised saliency as weights.
    pub saliency_flip: f64,
}

/// PSNR cap for identical images.
pub const PSNR_CAP: f64 = 99.0;

/// The errors of linear-RGB `test` against `reference_srgb` with saliency `weights`.
pub fn frame_error(
    reference_srgb: &[u8],
    test: &[[f32; 3]],
    weights: &[f32],
    width: u32,
    height: u32,
) -> FrameError {
    let t = composite_srgb8(test);
    let map = flip_map(reference_srgb, &t, width, height);
    let flip = map.iter().map(|&v| v as f64).sum::<f64>() / map.len().max(1) as f64;
    let wsum: f64 = weights.iter().map(|&w| w as f64).sum();
    let saliency_flip = if wsum > 0.0 {
        map.iter()
            .zip(weights)
            .map(|(&f, &w)| f as f64 * w as f64)
            .sum::<f64>()
            / wsum
    } else {
        flip
    };
    FrameError {
        psnr: psnr(reference_srgb, &t).min(PSNR_CAP),
        flip,
        saliency_flip,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identical_images_have_no_error_and_weights_focus_it() {
        let (w, h) = (32u32, 32u32);
        let img = vec![[0.4f32, 0.5, 0.6]; (w * h) as usize];
        let srgb = composite_srgb8(&img);
        let e = frame_error(&srgb, &img, &vec![1.0; img.len()], w, h);
        assert_eq!((e.psnr, e.flip, e.saliency_flip), (PSNR_CAP, 0.0, 0.0));
        let mut bad = img.clone();
        for p in &mut bad[..(w as usize * 4)] {
            *p = [1.0, 0.0, 0.0];
        }
        // Weights on the damaged rows raise the weighted error above the plain mean.
        let mut weights = vec![0.0; img.len()];
        weights[..(w as usize * 4)].fill(1.0);
        let e = frame_error(&srgb, &bad, &weights, w, h);
        assert!(e.psnr < 30.0 && e.flip > 0.0);
        assert!(e.saliency_flip > 2.0 * e.flip);
    }
}
