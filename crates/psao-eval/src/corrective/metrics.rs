//! Colour image metrics of corrected frames against the reference, on the 8-bit sRGB images a
//! viewer sees: PSNR and FLIP over all pixels and over the non-diffuse pixels, and FLIP
//! weighted by the saliency model's own map and by a centre-bias fixation prior.

use psao_client::composite_srgb8;
use serde::Serialize;

/// PSNR cap for identical images, so averages stay finite.
pub const PSNR_CAP: f64 = 99.0;

/// Standard deviation of the centre-bias prior as a fraction of the image's width and height.
///
/// Free-viewing fixations cluster around the image centre (Tatler 2007; Judd et al. 2009 fit
/// a centred Gaussian to them); a fixed Gaussian of a quarter of each side gives weights that
/// owe nothing to the saliency model.
pub const CENTRE_SIGMA: f32 = 0.25;

/// PSNR in dB (capped at [`PSNR_CAP`]) of 8-bit RGB `test` against `reference` over the
/// pixels `keep` selects; `None` when it selects none.
pub fn psnr_where(reference: &[u8], test: &[u8], keep: impl Fn(usize) -> bool) -> Option<f64> {
    let (mut se, mut n) = (0.0f64, 0usize);
    for (i, (a, b)) in reference
        .chunks_exact(3)
        .zip(test.chunks_exact(3))
        .enumerate()
    {
        if keep(i) {
            se += a
                .iter()
                .zip(b)
                .map(|(&x, &y)| (x as f64 - y as f64).powi(2))
                .sum::<f64>();
            n += 3;
        }
    }
    (n > 0).then(|| {
        let mse = se / n as f64;
        if mse == 0.0 {
            PSNR_CAP
        } else {
            (10.0 * (255.0f64 * 255.0 / mse).log10()).min(PSNR_CAP)
        }
    })
}

/// The per-pixel FLIP error map of 8-bit sRGB `test` against `reference` (`width × height`).
pub fn flip_map(reference: &[u8], test: &[u8], width: u32, height: u32) -> Vec<f32> {
    let a = nv_flip::FlipImageRgb8::with_data(width, height, reference);
    let b = nv_flip::FlipImageRgb8::with_data(width, height, test);
    nv_flip::flip(a, b, nv_flip::DEFAULT_PIXELS_PER_DEGREE).to_vec()
}

/// The mean of `map` with `weights`; the plain mean when the weights sum to zero.
pub fn weighted_mean(map: &[f32], weights: &[f32]) -> f64 {
    let wsum: f64 = weights.iter().map(|&w| w as f64).sum();
    if wsum > 0.0 {
        map.iter()
            .zip(weights)
            .map(|(&f, &w)| f as f64 * w as f64)
            .sum::<f64>()
            / wsum
    } else {
        map.iter().map(|&v| v as f64).sum::<f64>() / map.len().max(1) as f64
    }
}

/// The centre-bias fixation prior of a `width × height` image: a Gaussian around the image
/// centre with standard deviations [`CENTRE_SIGMA`] × width and × height, 1 at the centre.
pub fn centre_bias(width: u32, height: u32) -> Vec<f32> {
    let (w, h) = (width as f32, height as f32);
    let (sx, sy) = (CENTRE_SIGMA * w, CENTRE_SIGMA * h);
    (0..height)
        .flat_map(|y| {
            (0..width).map(move |x| {
                let dx = (x as f32 + 0.5 - 0.5 * w) / sx;
                let dy = (y as f32 + 0.5 - 0.5 * h) / sy;
                (-0.5 * (dx * dx + dy * dy)).exp()
            })
        })
        .collect()
}

/// The errors of one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct FrameError {
    /// PSNR in dB over all pixels.
    pub psnr: f64,
    /// Mean FLIP over all pixels.
    pub flip: f64,
    /// PSNR over the non-diffuse pixels (object id ≠ 0); `None` when the frame has none.
    pub nd_psnr: Option<f64>,
    /// Mean FLIP over the non-diffuse pixels; `None` when the frame has none.
    pub nd_flip: Option<f64>,
    /// FLIP weighted by the reference's normalised saliency map: the saliency model's own
    /// measure, which favours the ordering built from it.
    pub saliency_flip: f64,
    /// FLIP weighted by the centre-bias prior ([`centre_bias`]).
    pub centre_flip: f64,
}

/// What a frame is compared with: the reference and the weights of the metrics.
pub struct Truth<'a> {
    /// The reference as 8-bit sRGB.
    pub reference_srgb: &'a [u8],
    /// Object id per pixel (0 = diffuse).
    pub ids: &'a [u32],
    /// The reference's normalised saliency map.
    pub saliency: &'a [f32],
    /// The centre-bias prior.
    pub centre: &'a [f32],
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
}

/// The errors of linear-RGB `test` against `truth`.
pub fn frame_error(truth: &Truth<'_>, test: &[[f32; 3]]) -> FrameError {
    let t = composite_srgb8(test);
    let map = flip_map(truth.reference_srgb, &t, truth.width, truth.height);
    let non_diffuse: Vec<f32> = truth.ids.iter().map(|&i| (i != 0) as u32 as f32).collect();
    let any_non_diffuse = truth.ids.iter().any(|&i| i != 0);
    FrameError {
        psnr: psnr_where(truth.reference_srgb, &t, |_| true).unwrap_or(PSNR_CAP),
        flip: weighted_mean(&map, &[]),
        nd_psnr: psnr_where(truth.reference_srgb, &t, |i| truth.ids[i] != 0),
        nd_flip: any_non_diffuse.then(|| weighted_mean(&map, &non_diffuse)),
        saliency_flip: weighted_mean(&map, truth.saliency),
        centre_flip: weighted_mean(&map, truth.centre),
    }
}

/// Averages of [`FrameError`]s over frames (the non-diffuse parts over the frames that have
/// non-diffuse pixels).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct MeanError {
    /// Mean PSNR (dB).
    pub psnr: f64,
    /// Mean FLIP.
    pub flip: f64,
    /// Mean non-diffuse PSNR.
    pub nd_psnr: Option<f64>,
    /// Mean non-diffuse FLIP.
    pub nd_flip: Option<f64>,
    /// Mean saliency-weighted FLIP (the model's own measure).
    pub saliency_flip: f64,
    /// Mean centre-bias-weighted FLIP.
    pub centre_flip: f64,
}

/// Running sums of [`FrameError`]s.
#[derive(Clone, Copy, Debug, Default)]
pub struct ErrorSums {
    frames: usize,
    nd_frames: usize,
    sum: MeanError,
}

impl ErrorSums {
    /// Adds one frame.
    pub fn add(&mut self, e: &FrameError) {
        self.frames += 1;
        let s = &mut self.sum;
        s.psnr += e.psnr;
        s.flip += e.flip;
        s.saliency_flip += e.saliency_flip;
        s.centre_flip += e.centre_flip;
        if let (Some(p), Some(f)) = (e.nd_psnr, e.nd_flip) {
            self.nd_frames += 1;
            s.nd_psnr = Some(s.nd_psnr.unwrap_or(0.0) + p);
            s.nd_flip = Some(s.nd_flip.unwrap_or(0.0) + f);
        }
    }

    /// The averages.
    pub fn mean(&self) -> MeanError {
        let n = self.frames.max(1) as f64;
        let m = self.nd_frames.max(1) as f64;
        let s = &self.sum;
        MeanError {
            psnr: s.psnr / n,
            flip: s.flip / n,
            nd_psnr: s.nd_psnr.map(|v| v / m),
            nd_flip: s.nd_flip.map(|v| v / m),
            saliency_flip: s.saliency_flip / n,
            centre_flip: s.centre_flip / n,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn truth<'a>(srgb: &'a [u8], ids: &'a [u32], sal: &'a [f32], centre: &'a [f32]) -> Truth<'a> {
        Truth {
            reference_srgb: srgb,
            ids,
            saliency: sal,
            centre,
            width: 32,
            height: 32,
        }
    }

    #[test]
    fn identical_images_have_no_error_and_weights_focus_it() {
        let n = 32 * 32;
        let img = vec![[0.4f32, 0.5, 0.6]; n];
        let srgb = composite_srgb8(&img);
        let ids = vec![0u32; n];
        let ones = vec![1.0; n];
        let centre = centre_bias(32, 32);
        let e = frame_error(&truth(&srgb, &ids, &ones, &centre), &img);
        assert_eq!((e.psnr, e.flip, e.saliency_flip), (PSNR_CAP, 0.0, 0.0));
        assert_eq!((e.nd_psnr, e.nd_flip), (None, None));
        let mut bad = img.clone();
        for p in &mut bad[..32 * 4] {
            *p = [1.0, 0.0, 0.0];
        }
        // Saliency weights on the damaged rows raise the weighted error above the plain mean;
        // the centre prior, small at the top rows, lowers it.
        let mut weights = vec![0.0; n];
        weights[..32 * 4].fill(1.0);
        let mut ids = ids;
        ids[..32 * 4].fill(1);
        let e = frame_error(&truth(&srgb, &ids, &weights, &centre), &bad);
        assert!(e.psnr < 30.0 && e.flip > 0.0);
        assert!(e.saliency_flip > 2.0 * e.flip);
        assert!(e.centre_flip < e.flip);
        // Only damaged pixels are non-diffuse: their FLIP is the weighted one, their PSNR lower.
        assert!((e.nd_flip.unwrap() - e.saliency_flip).abs() < 1e-12);
        assert!(e.nd_psnr.unwrap() < e.psnr);
    }

    #[test]
    fn the_centre_prior_peaks_at_the_centre_and_is_symmetric() {
        let c = centre_bias(40, 20);
        let at = |x: usize, y: usize| c[y * 40 + x];
        // The corner is about two standard deviations out along each axis: exp(−3.7).
        assert!(at(19, 9) > 0.99 && (at(0, 0) - (-3.705f32).exp()).abs() < 1e-3);
        assert_eq!(at(3, 5), at(36, 14));
        assert!(at(10, 10) < at(15, 10));
    }

    #[test]
    fn sums_average_non_diffuse_parts_over_frames_that_have_them() {
        let mut s = ErrorSums::default();
        let with = FrameError {
            psnr: 30.0,
            nd_psnr: Some(20.0),
            nd_flip: Some(0.2),
            ..FrameError::default()
        };
        let without = FrameError {
            psnr: 40.0,
            ..FrameError::default()
        };
        s.add(&with);
        s.add(&without);
        let m = s.mean();
        assert_eq!(
            (m.psnr, m.nd_psnr, m.nd_flip),
            (35.0, Some(20.0), Some(0.2))
        );
    }
}
