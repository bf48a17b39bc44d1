//! Light from far away: a latitude–longitude radiance map read from a Radiance `.hdr` file
//! (scene-file `environment`, with an intensity and a rotation about +Y), or a constant sky.
//!
//! Map convention: +Y is up (glTF). Pixel row `y` (0 at the top) has polar angle
//! `θ = π (y + ½) / h` from +Y, column `x` azimuth `φ = 2π (x + ½) / w`, and the direction
//! is `(sin θ cos φ, cos θ, sin θ sin φ)`.

use std::io::BufReader;
use std::path::Path;
use std::sync::Arc;

use glam::{Quat, Vec3};
use image::codecs::hdr::HdrDecoder;

use crate::error::SceneError;

/// Radiance of the constant sky of a scene without an environment map: a neutral grey of
/// 0.6, so an unoccluded white surface facing up receives irradiance `0.6·π` and reflects
/// radiance 0.6, the client's ambient term.
pub const DEFAULT_SKY: Vec3 = Vec3::splat(0.6);

/// Largest map width read, in pixels (an 16K latitude–longitude map).
pub const MAX_MAP_WIDTH: u32 = 16384;
/// Largest pixel count read: an 8K map (8192 × 4096, 384 MB as linear RGB floats).
pub const MAX_MAP_PIXELS: u64 = 8192 * 4096;

/// A linear-radiance latitude–longitude map (row-major from the top).
#[derive(Clone, Debug, PartialEq)]
pub struct LatLongMap {
    width: usize,
    height: usize,
    pixels: Vec<[f32; 3]>,
}

impl LatLongMap {
    /// A map of `width × height` RGB pixels, row-major from the top; an empty map, a pixel
    /// count that does not match, or a negative or non-finite value is refused (the message
    /// names which).
    pub fn new(width: usize, height: usize, pixels: Vec<[f32; 3]>) -> Result<Self, String> {
        if width == 0 || height == 0 || pixels.len() != width * height {
            return Err(format!(
                "environment map {width}x{height} with {} pixels",
                pixels.len()
            ));
        }
        if pixels.iter().flatten().any(|v| !v.is_finite() || *v < 0.0) {
            return Err("environment map has negative or non-finite radiance".into());
        }
        Ok(Self {
            width,
            height,
            pixels,
        })
    }

    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// The pixels, row-major from the top.
    pub fn pixels(&self) -> &[[f32; 3]] {
        &self.pixels
    }

    /// The direction at the centre of pixel (x, y).
    pub fn direction(&self, x: usize, y: usize) -> Vec3 {
        let theta = std::f32::consts::PI * (y as f32 + 0.5) / self.height as f32;
        let phi = std::f32::consts::TAU * (x as f32 + 0.5) / self.width as f32;
        Vec3::new(
            theta.sin() * phi.cos(),
            theta.cos(),
            theta.sin() * phi.sin(),
        )
    }

    /// Radiance in direction `d` (unit), nearest pixel.
    pub fn radiance(&self, d: Vec3) -> [f32; 3] {
        let theta = d.y.clamp(-1.0, 1.0).acos();
        let phi = d.z.atan2(d.x).rem_euclid(std::f32::consts::TAU);
        let y = ((theta / std::f32::consts::PI) * self.height as f32) as usize;
        let x = ((phi / std::f32::consts::TAU) * self.width as f32) as usize;
        self.pixels[y.min(self.height - 1) * self.width + x.min(self.width - 1)]
    }
}

/// Checks the size a map's header declares before any pixel is allocated.
fn check_map_size(path: &Path, width: u32, height: u32) -> Result<(), SceneError> {
    if width == 0 || height == 0 {
        return Err(SceneError::parse(
            path,
            "Radiance HDR",
            format!("empty image ({width}x{height})"),
        ));
    }
    if width > MAX_MAP_WIDTH {
        return Err(SceneError::too_large(
            path,
            "environment map width",
            width.into(),
            MAX_MAP_WIDTH.into(),
        ));
    }
    let pixels = u64::from(width) * u64::from(height);
    if pixels > MAX_MAP_PIXELS {
        return Err(SceneError::too_large(
            path,
            "environment map pixel count",
            pixels,
            MAX_MAP_PIXELS,
        ));
    }
    Ok(())
}

/// Reads a Radiance `.hdr` (RGBE) latitude–longitude map. The size in its header is checked
/// against [`MAX_MAP_WIDTH`] and [`MAX_MAP_PIXELS`] before the pixels are read.
pub fn read_hdr(path: &Path) -> Result<LatLongMap, SceneError> {
    let bad = |m: String| SceneError::parse(path, "Radiance HDR", m);
    let file = std::fs::File::open(path).map_err(|e| SceneError::io(path, e))?;
    let decoder = HdrDecoder::new(BufReader::new(file)).map_err(|e| {
        bad(format!(
            "not a Radiance HDR image (expected a file starting with #?RADIANCE or #?RGBE): {e}"
        ))
    })?;
    let meta = decoder.metadata();
    check_map_size(path, meta.width, meta.height)?;
    let image = image::DynamicImage::from_decoder(decoder)
        .map_err(|e| bad(format!("corrupt pixel data: {e}")))?
        .into_rgb32f();
    let (w, h) = image.dimensions();
    let pixels = image.pixels().map(|p| p.0).collect();
    LatLongMap::new(w as usize, h as usize, pixels).map_err(bad)
}

/// The light arriving from directions where rays leave the scene.
#[derive(Clone, Debug, PartialEq)]
pub enum Environment {
    /// The same linear RGB radiance from every direction.
    Constant(Vec3),
    /// A map, scaled and turned.
    Map {
        /// The radiance map.
        map: Arc<LatLongMap>,
        /// Factor on every pixel (≥ 0).
        intensity: f32,
        /// Turn of the map about +Y, radians (counter-clockwise seen from above).
        rotation: f32,
    },
}

impl Default for Environment {
    /// The constant [`DEFAULT_SKY`].
    fn default() -> Self {
        Environment::Constant(DEFAULT_SKY)
    }
}

impl Environment {
    /// Linear RGB radiance arriving from unit world direction `d`.
    pub fn radiance(&self, d: Vec3) -> Vec3 {
        match self {
            Environment::Constant(c) => *c,
            Environment::Map {
                map,
                intensity,
                rotation,
            } => {
                let local = Quat::from_rotation_y(-rotation) * d;
                Vec3::from_array(map.radiance(local)) * *intensity
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    fn write_hdr(path: &Path, w: u32, h: u32, rgb: impl Fn(u32, u32) -> [f32; 3]) {
        let pixels: Vec<image::Rgb<f32>> =
            (0..w * h).map(|i| image::Rgb(rgb(i % w, i / w))).collect();
        let file = std::fs::File::create(path).unwrap();
        image::codecs::hdr::HdrEncoder::new(file)
            .encode(&pixels, w as usize, h as usize)
            .unwrap();
    }

    #[test]
    fn reads_a_map_and_looks_up_its_pixels() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sky.hdr");
        write_hdr(&path, 16, 8, |x, y| [x as f32, y as f32, 0.5]);
        let map = read_hdr(&path).unwrap();
        assert_eq!((map.width(), map.height()), (16, 8));
        for (x, y) in [(0, 0), (5, 3), (15, 7)] {
            let v = map.radiance(map.direction(x, y));
            // RGBE keeps 8 mantissa bits.
            assert!((v[0] - x as f32).abs() <= 0.07 && (v[1] - y as f32).abs() <= 0.07);
            assert!((v[2] - 0.5).abs() < 0.01);
        }
    }

    #[test]
    fn rotation_turns_the_map_about_up() {
        let map = LatLongMap::new(4, 1, vec![[1.0; 3], [2.0; 3], [3.0; 3], [4.0; 3]]).unwrap();
        let env = |rotation| Environment::Map {
            map: Arc::new(map.clone()),
            intensity: 2.0,
            rotation,
        };
        let d = map.direction(1, 0);
        assert_eq!(env(0.0).radiance(d), Vec3::splat(4.0));
        // Turned by a quarter (90° counter-clockwise seen from above, +X towards −Z), the
        // pixel that was at d's azimuth minus 90° arrives from d.
        let turned = Quat::from_rotation_y(std::f32::consts::FRAC_PI_2) * map.direction(0, 0);
        assert_eq!(
            env(std::f32::consts::FRAC_PI_2).radiance(turned),
            Vec3::splat(2.0)
        );
        assert_eq!(Environment::default().radiance(d), DEFAULT_SKY);
    }

    #[test]
    fn bad_files_and_sizes_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.hdr");
        std::fs::write(&path, b"P6\n2 2\n255\n").unwrap();
        let e = read_hdr(&path).unwrap_err().to_string();
        assert!(e.contains("not a Radiance HDR"), "{e}");
        // A header claiming a huge image is refused before anything is allocated.
        let mut f = std::fs::File::create(&path).unwrap();
        f.write_all(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 100000 +X 200000\n")
            .unwrap();
        drop(f);
        let e = read_hdr(&path).unwrap_err();
        assert!(matches!(e, SceneError::TooLarge { .. }), "{e}");
        // Truncated pixel data is an error, not a panic.
        write_hdr(&path, 8, 4, |_, _| [1.0; 3]);
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() - 20]).unwrap();
        assert!(read_hdr(&path).is_err());
        assert!(matches!(
            read_hdr(&dir.path().join("none.hdr")),
            Err(SceneError::Io { .. })
        ));
    }

    #[test]
    fn the_largest_documented_map_passes_the_size_check() {
        let p = Path::new("x.hdr");
        assert!(check_map_size(p, 8192, 4096).is_ok());
        assert!(check_map_size(p, MAX_MAP_WIDTH, 2048).is_ok());
        assert!(check_map_size(p, 8192, 4097).is_err());
        assert!(check_map_size(p, MAX_MAP_WIDTH + 1, 1).is_err());
        assert!(check_map_size(p, 0, 1).is_err());
    }

    #[test]
    fn bad_maps_are_refused() {
        assert!(LatLongMap::new(2, 2, vec![[0.0; 3]; 3]).is_err());
        assert!(LatLongMap::new(1, 1, vec![[f32::NAN, 0.0, 0.0]]).is_err());
        assert!(LatLongMap::new(1, 1, vec![[-1.0, 0.0, 0.0]]).is_err());
    }
}
