//! Reading and writing AO images as grayscale PNG files.

use anyhow::{bail, Context, Result};
use psao_eval::AoImage;
use std::path::Path;

/// Writes `image` as a 16-bit grayscale PNG.
pub fn write_ao_png(path: &Path, image: &AoImage) -> Result<()> {
    let samples = image.to_u16();
    let buffer: image::ImageBuffer<image::Luma<u16>, Vec<u16>> =
        image::ImageBuffer::from_raw(image.width, image.height, samples)
            .context("image data does not match its size")?;
    buffer
        .save(path)
        .with_context(|| format!("cannot write {}", path.display()))
}

/// Writes 8-bit sRGB RGB pixels as a PNG.
pub fn write_rgb_png(path: &Path, width: u32, height: u32, rgb: Vec<u8>) -> Result<()> {
    let buffer = image::RgbImage::from_raw(width, height, rgb)
        .context("image data does not match its size")?;
    buffer
        .save(path)
        .with_context(|| format!("cannot write {}", path.display()))
}

/// Writes a linear RGB image as a Radiance `.hdr` file.
pub fn write_rgb_hdr(path: &Path, image: &psao_eval::RgbImage) -> Result<()> {
    let pixels: Vec<image::Rgb<f32>> = image.data.iter().map(|&p| image::Rgb(p)).collect();
    let file =
        std::fs::File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    image::codecs::hdr::HdrEncoder::new(std::io::BufWriter::new(file))
        .encode(&pixels, image.width as usize, image.height as usize)
        .with_context(|| format!("cannot write {}", path.display()))
}

/// Reads a PNG (8 or 16 bit, gray or colour: colour is converted to luma) as an AO image.
pub fn read_ao_png(path: &Path) -> Result<AoImage> {
    let decoded = image::ImageReader::open(path)
        .with_context(|| format!("cannot open {}", path.display()))?
        .with_guessed_format()
        .with_context(|| format!("cannot read {}", path.display()))?
        .decode()
        .with_context(|| format!("{} is not a readable image", path.display()))?;
    let gray = decoded.to_luma16();
    if gray.width() == 0 || gray.height() == 0 {
        bail!("{} has no pixels", path.display());
    }
    Ok(AoImage::from_u16(
        gray.width(),
        gray.height(),
        gray.as_raw(),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_within_16_bit_precision() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.png");
        let img = AoImage {
            width: 3,
            height: 2,
            data: vec![0.0, 0.25, 0.5, 0.75, 1.0, 0.123],
        };
        write_ao_png(&path, &img).unwrap();
        let back = read_ao_png(&path).unwrap();
        assert_eq!((back.width, back.height), (3, 2));
        for (a, b) in img.data.iter().zip(&back.data) {
            assert!((a - b).abs() <= 0.5 / 65535.0 + 1e-7);
        }
    }

    #[test]
    fn garbage_file_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.png");
        std::fs::write(&path, b"\x89PNG\r\n\x1a\nnot really").unwrap();
        let err = read_ao_png(&path).unwrap_err();
        assert!(format!("{err:#}").contains("bad.png"));
    }
}
