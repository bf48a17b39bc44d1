//! Image quality metrics on AO images: PSNR, SSIM (`image-compare`) and FLIP (`nv-flip`).

use crate::AoImage;
use serde::{Deserialize, Serialize};

/// PSNR reported for identical images (an infinite PSNR cannot be written to JSON).
pub const PSNR_IDENTICAL_DB: f64 = 100.0;

/// Quality of a test image against a reference.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// Peak signal-to-noise ratio in dB, peak 1.0, capped at [`PSNR_IDENTICAL_DB`].
    pub psnr: f64,
    /// Mean structural similarity over 8×8 windows, on 8-bit values (1 = identical).
    pub ssim: f64,
    /// Mean FLIP error on 8-bit values (0 = identical).
    pub flip: f64,
}

/// Why two images could not be compared.
#[derive(Debug, thiserror::Error)]
pub enum MetricsError {
    /// The images differ in size.
    #[error("image sizes differ: {0}x{1} vs {2}x{3}")]
    SizeMismatch(u32, u32, u32, u32),
    /// An image has no pixels or its data does not match its size.
    #[error("image is empty or its data length does not match {0}x{1}")]
    BadImage(u32, u32),
    /// SSIM failed inside `image-compare`.
    #[error("SSIM failed: {0}")]
    Ssim(String),
}

/// Peak signal-to-noise ratio of `test` against `reference` (values in [0, 1]).
pub fn psnr(reference: &AoImage, test: &AoImage) -> f64 {
    let n = reference.data.len().max(1) as f64;
    let mse: f64 = reference
        .data
        .iter()
        .zip(&test.data)
        .map(|(&a, &b)| {
            let d = a.clamp(0.0, 1.0) as f64 - b.clamp(0.0, 1.0) as f64;
            d * d
        })
        .sum::<f64>()
        / n;
    if mse <= 0.0 {
        PSNR_IDENTICAL_DB
    } else {
        (-10.0 * mse.log10()).min(PSNR_IDENTICAL_DB)
    }
}

/// Mean SSIM of `test` against `reference` on their 8-bit values.
pub fn ssim(reference: &AoImage, test: &AoImage) -> Result<f64, MetricsError> {
    let a = gray8(reference);
    let b = gray8(test);
    image_compare::gray_similarity_structure(&image_compare::Algorithm::MSSIMSimple, &a, &b)
        .map(|s| s.score)
        .map_err(|e| MetricsError::Ssim(e.to_string()))
}

/// Mean FLIP error of `test` against `reference`, both shown as 8-bit gray on an sRGB display,
/// at FLIP's default viewing distance.
pub fn flip(reference: &AoImage, test: &AoImage) -> f64 {
    let a = rgb8(reference);
    let b = rgb8(test);
    let map = nv_flip::flip(a, b, nv_flip::DEFAULT_PIXELS_PER_DEGREE);
    nv_flip::FlipPool::from_image(&map).mean() as f64
}

/// All metrics of `test` against `reference`.
pub fn compare(reference: &AoImage, test: &AoImage) -> Result<Metrics, MetricsError> {
    for img in [reference, test] {
        if img.width == 0
            || img.height == 0
            || img.data.len() != img.width as usize * img.height as usize
        {
            return Err(MetricsError::BadImage(img.width, img.height));
        }
    }
    if (reference.width, reference.height) != (test.width, test.height) {
        return Err(MetricsError::SizeMismatch(
            reference.width,
            reference.height,
            test.width,
            test.height,
        ));
    }
    Ok(Metrics {
        psnr: psnr(reference, test),
        ssim: ssim(reference, test)?,
        flip: flip(reference, test),
    })
}

fn gray8(img: &AoImage) -> image::GrayImage {
    image::GrayImage::from_raw(img.width, img.height, img.to_u8())
        .expect("length checked by compare")
}

fn rgb8(img: &AoImage) -> nv_flip::FlipImageRgb8 {
    let rgb: Vec<u8> = img.to_u8().iter().flat_map(|&v| [v, v, v]).collect();
    nv_flip::FlipImageRgb8::with_data(img.width, img.height, &rgb)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gradient(w: u32, h: u32) -> AoImage {
        let data = (0..w * h)
            .map(|i| (i % w) as f32 / w as f32 * 0.8 + (i / w) as f32 / h as f32 * 0.2)
            .collect();
        AoImage {
            width: w,
            height: h,
            data,
        }
    }

    #[test]
    fn identical_images_are_perfect() {
        let a = gradient(64, 48);
        let m = compare(&a, &a).unwrap();
        assert_eq!(m.psnr, PSNR_IDENTICAL_DB);
        assert!((m.ssim - 1.0).abs() < 1e-9, "ssim {}", m.ssim);
        assert!(m.flip < 1e-6, "flip {}", m.flip);
    }

    #[test]
    fn psnr_matches_known_mse() {
        let a = AoImage::filled(10, 10, 0.5);
        let b = AoImage::filled(10, 10, 0.6);
        // MSE = 0.01 -> 20 dB.
        assert!((psnr(&a, &b) - 20.0).abs() < 1e-4);
    }

    #[test]
    fn more_noise_scores_worse_on_every_metric() {
        let a = gradient(96, 64);
        let noisy = |amp: f32| {
            let mut b = a.clone();
            for (i, v) in b.data.iter_mut().enumerate() {
                let h = (i as u32).wrapping_mul(2654435761) >> 16;
                *v = (*v + amp * ((h & 0xff) as f32 / 255.0 - 0.5)).clamp(0.0, 1.0);
            }
            b
        };
        let low = compare(&a, &noisy(0.05)).unwrap();
        let high = compare(&a, &noisy(0.3)).unwrap();
        assert!(low.psnr > high.psnr);
        assert!(low.ssim > high.ssim);
        assert!(low.flip < high.flip);
    }

    #[test]
    fn size_mismatch_is_an_error() {
        let a = AoImage::filled(4, 4, 1.0);
        let b = AoImage::filled(4, 5, 1.0);
        assert!(matches!(
            compare(&a, &b),
            Err(MetricsError::SizeMismatch(..))
        ));
        let bad = AoImage {
            width: 3,
            height: 3,
            data: vec![0.0; 2],
        };
        assert!(matches!(
            compare(&bad, &bad),
            Err(MetricsError::BadImage(..))
        ));
    }
}
