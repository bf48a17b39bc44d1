//! Alpha-mask textures: the decoded alpha channel of an alpha-masked material's base-colour
//! texture and its nearest-texel sampling (DESIGN §3: points on masked-out texels are rejected).

use std::fmt;
use std::sync::Arc;

use glam::Vec2;

/// A decoded 8-bit alpha channel, row-major from the top-left texel (glTF UV (0, 0)).
#[derive(Clone, PartialEq, Eq)]
pub struct AlphaImage {
    width: u32,
    height: u32,
    alpha: Vec<u8>,
}

impl AlphaImage {
    /// An image of `width`×`height` texels; `None` when a side is 0 or `alpha` does not hold
    /// exactly `width · height` values.
    pub fn new(width: u32, height: u32, alpha: Vec<u8>) -> Option<Self> {
        let ok =
            width > 0 && height > 0 && alpha.len() as u64 == u64::from(width) * u64::from(height);
        ok.then_some(Self {
            width,
            height,
            alpha,
        })
    }

    /// Width in texels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in texels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Alpha of texel (`x`, `y`); both must be in range.
    pub fn texel(&self, x: u32, y: u32) -> u8 {
        self.alpha[y as usize * self.width as usize + x as usize]
    }
}

impl fmt::Debug for AlphaImage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "AlphaImage({}×{})", self.width, self.height)
    }
}

/// How texture coordinates outside [0, 1) map to texels (glTF sampler `wrapS` / `wrapT`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Wrap {
    /// Tile the image (glTF's default).
    #[default]
    Repeat,
    /// Use the nearest edge texel.
    ClampToEdge,
    /// Tile, mirroring every other copy.
    MirroredRepeat,
}

impl Wrap {
    /// The texel index (in `0..size`, `size` ≥ 1) that nearest sampling reads at coordinate `t`
    /// (0 and 1 are the image's edges). Non-finite coordinates read texel 0.
    pub fn texel(self, t: f32, size: u32) -> u32 {
        if !t.is_finite() {
            return 0;
        }
        let size = i64::from(size.max(1));
        // Saturating float-to-int conversion: huge coordinates stay in range below.
        let i = (f64::from(t) * size as f64).floor() as i64;
        let wrapped = match self {
            Self::Repeat => i.rem_euclid(size),
            Self::ClampToEdge => i.clamp(0, size - 1),
            Self::MirroredRepeat => {
                let m = i.rem_euclid(2 * size);
                if m < size {
                    m
                } else {
                    2 * size - 1 - m
                }
            }
        };
        wrapped as u32
    }
}

/// An alpha-masked material's alpha texture: the shared image, which UV set addresses it and
/// how it wraps. Sampling is always nearest-texel (the glTF filters are not used).
#[derive(Clone, Debug, PartialEq)]
pub struct AlphaTexture {
    /// The decoded alpha channel (shared by every material that uses the image).
    pub image: Arc<AlphaImage>,
    /// The mesh texture-coordinate set (`TEXCOORD_n`) the texture is addressed with; the
    /// loader puts that set into [`crate::Mesh::uvs`].
    pub tex_coord: u32,
    /// Wrapping along u.
    pub wrap_s: Wrap,
    /// Wrapping along v.
    pub wrap_t: Wrap,
}

impl AlphaTexture {
    /// Alpha in [0, 1] of the texel nearest to `uv`.
    pub fn sample(&self, uv: Vec2) -> f32 {
        let x = self.wrap_s.texel(uv.x, self.image.width);
        let y = self.wrap_t.texel(uv.y, self.image.height);
        f32::from(self.image.texel(x, y)) / 255.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_modes_map_coordinates_to_texels() {
        // Four texels: [0, 0.25) → 0, …, [0.75, 1) → 3.
        let cases = [
            (0.0, [0, 0, 0]),
            (0.3, [1, 1, 1]),
            (0.999, [3, 3, 3]),
            (1.0, [0, 3, 3]),
            (1.3, [1, 3, 2]),
            (-0.1, [3, 0, 0]),
            (-0.3, [2, 0, 1]),
            (2.1, [0, 3, 0]),
        ];
        for (t, [repeat, clamp, mirror]) in cases {
            assert_eq!(Wrap::Repeat.texel(t, 4), repeat, "repeat {t}");
            assert_eq!(Wrap::ClampToEdge.texel(t, 4), clamp, "clamp {t}");
            assert_eq!(Wrap::MirroredRepeat.texel(t, 4), mirror, "mirror {t}");
        }
        for w in [Wrap::Repeat, Wrap::ClampToEdge, Wrap::MirroredRepeat] {
            for t in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 1e30, -1e30] {
                assert!(w.texel(t, 7) < 7, "{w:?} {t}");
            }
        }
    }

    #[test]
    fn sampling_reads_the_nearest_texel() {
        // 2×2: top row opaque/clear, bottom row clear/opaque.
        let image = AlphaImage::new(2, 2, vec![255, 0, 0, 255]).unwrap();
        let tex = AlphaTexture {
            image: Arc::new(image),
            tex_coord: 0,
            wrap_s: Wrap::Repeat,
            wrap_t: Wrap::ClampToEdge,
        };
        assert_eq!(tex.sample(Vec2::new(0.25, 0.25)), 1.0);
        assert_eq!(tex.sample(Vec2::new(0.75, 0.25)), 0.0);
        assert_eq!(tex.sample(Vec2::new(0.25, 0.75)), 0.0);
        assert_eq!(tex.sample(Vec2::new(1.75, 0.75)), 1.0);
        assert_eq!(tex.sample(Vec2::new(0.75, 5.0)), 1.0);
    }

    #[test]
    fn images_need_matching_sizes() {
        assert!(AlphaImage::new(2, 2, vec![0; 4]).is_some());
        assert!(AlphaImage::new(2, 2, vec![0; 3]).is_none());
        assert!(AlphaImage::new(0, 0, vec![]).is_none());
    }
}
