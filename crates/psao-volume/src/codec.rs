//! Brick codecs: every brick of the shared pool is stored in one format.
//!
//! * `F32`, `F16`: raw values (4 / 2 bytes per voxel).
//! * `Unorm8`: values mapped to 0..=255 between the volume's min and max (1 byte).
//! * `Bc4`: the brick as eight 8×8 z-slices, each four BC4 blocks (4 bits per voxel).
//! * `Bc7`: four consecutive z voxels packed into the RGBA channels of one texel, so a brick is
//!   two 8×8 texel slices of four BC7 blocks each (128 bytes, 2 bits per voxel).
//!
//! Normalised formats store `(v - lo) / (hi - lo)`; decoding maps back to values. BC4 bricks
//! lead with two bytes, their own min and max on that 0..=255 scale, and the blocks use the
//! full code range between them. BC7 pools carry a sparse refinement layer: the 1/64 of the
//! bricks with the largest BC7 error also store their residual as one more BC7 brick over
//! its own range (two `f32`), found by binary search of the sorted refined brick list.

use crate::grid::{voxel_index, BRICK_VOXELS};
use rayon::prelude::*;

/// A brick storage format.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum BrickFormat {
    /// 32-bit float.
    F32,
    /// 16-bit float.
    F16,
    /// 8-bit unsigned normalised (per-volume min-max).
    Unorm8,
    /// BC4 blocks (per-volume min-max).
    Bc4,
    /// BC7 blocks with four z voxels per RGBA texel (per-volume min-max).
    Bc7,
}

impl BrickFormat {
    /// All formats, best quality first.
    pub const ALL: [BrickFormat; 5] = [
        BrickFormat::F32,
        BrickFormat::F16,
        BrickFormat::Unorm8,
        BrickFormat::Bc4,
        BrickFormat::Bc7,
    ];

    /// Bytes of one 8³ brick.
    pub fn brick_bytes(self) -> usize {
        match self {
            BrickFormat::F32 => 2048,
            BrickFormat::F16 => 1024,
            BrickFormat::Unorm8 => 512,
            BrickFormat::Bc4 => 2 + 256,
            BrickFormat::Bc7 => 128,
        }
    }

    /// Lower-case name (as on the command line).
    pub fn name(self) -> &'static str {
        match self {
            BrickFormat::F32 => "f32",
            BrickFormat::F16 => "f16",
            BrickFormat::Unorm8 => "unorm8",
            BrickFormat::Bc4 => "bc4",
            BrickFormat::Bc7 => "bc7",
        }
    }

    /// Parses a name from [`BrickFormat::name`].
    pub fn parse(s: &str) -> Option<BrickFormat> {
        BrickFormat::ALL.into_iter().find(|f| f.name() == s)
    }

    /// Stable numeric code used in `.psv` files.
    pub fn code(self) -> u8 {
        match self {
            BrickFormat::F32 => 0,
            BrickFormat::F16 => 1,
            BrickFormat::Unorm8 => 2,
            BrickFormat::Bc4 => 3,
            BrickFormat::Bc7 => 4,
        }
    }

    /// Inverse of [`BrickFormat::code`].
    pub fn from_code(c: u8) -> Option<BrickFormat> {
        BrickFormat::ALL.into_iter().find(|f| f.code() == c)
    }
}

/// The shared brick pool of all frames.
#[derive(Clone, Debug)]
pub struct BrickPool {
    /// Storage format.
    pub format: BrickFormat,
    /// Minimum of the value range used by normalised formats.
    pub lo: f32,
    /// Maximum of the value range used by normalised formats.
    pub hi: f32,
    /// Encoded bricks, `format.brick_bytes()` each.
    pub data: Vec<u8>,
    /// BC7 only: sorted indices of the refined bricks.
    pub refined: Vec<u32>,
    /// BC7 only: per refined brick, residual min and max (`f32`) and 128 bytes of BC7 blocks.
    pub refinement: Vec<u8>,
}

/// Bytes of one refinement record.
pub const REFINEMENT_BYTES: usize = 8 + 128;
/// One brick in this many gets a BC7 refinement.
const REFINE_EVERY: usize = 64;

/// Bricks per encoder call (one BC surface).
const CHUNK: usize = 64;

/// Offset and step of a BC brick's codes from its two leading range bytes.
#[inline]
fn sub_range(b: &[u8], lo: f32, span: f32) -> (f32, f32) {
    let (q0, q1) = (b[0] as f32, b[1] as f32);
    (lo + q0 * span, (q1 - q0) * span / 255.0)
}

/// The two range bytes of a brick for BC coding, and the matching (offset, scale) that maps
/// its values onto 0..=1.
fn brick_range(brick: &[f32; BRICK_VOXELS], lo: f32, scale: f32) -> ([u8; 2], f32, f32) {
    let (mn, mx) = brick
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |a, &v| {
            (a.0.min(v), a.1.max(v))
        });
    let q0 = ((mn - lo) * scale * 255.0).floor().clamp(0.0, 254.0);
    let q1 = ((mx - lo) * scale * 255.0).ceil().clamp(q0 + 1.0, 255.0);
    let off = lo + q0 / (255.0 * scale.max(f32::MIN_POSITIVE));
    let sub = if scale > 0.0 {
        scale * 255.0 / (q1 - q0)
    } else {
        0.0
    };
    ([q0 as u8, q1 as u8], off, sub)
}

fn to_unorm(v: f32, lo: f32, scale: f32) -> u8 {
    ((v - lo) * scale * 255.0).round().clamp(0.0, 255.0) as u8
}

impl BrickPool {
    /// Encodes `bricks` (values in [`voxel_index`] layout) in `format` over the range
    /// `lo..=hi` (used by the normalised formats).
    pub fn encode(format: BrickFormat, bricks: &[[f32; BRICK_VOXELS]], lo: f32, hi: f32) -> Self {
        let scale = if hi > lo { 1.0 / (hi - lo) } else { 0.0 };
        let bb = format.brick_bytes();
        let mut data = vec![0u8; bricks.len() * bb];
        data.par_chunks_mut(bb * CHUNK)
            .zip(bricks.par_chunks(CHUNK))
            .for_each(|(out, src)| encode_chunk(format, src, lo, scale, out));
        let mut pool = BrickPool {
            format,
            lo,
            hi,
            data,
            refined: Vec::new(),
            refinement: Vec::new(),
        };
        if format == BrickFormat::Bc7 {
            pool.refine(bricks);
        }
        pool
    }

    /// Adds BC7 residual bricks for the bricks with the largest squared error.
    fn refine(&mut self, bricks: &[[f32; BRICK_VOXELS]]) {
        let count = bricks.len() / REFINE_EVERY;
        if count == 0 {
            return;
        }
        let residuals: Vec<[f32; BRICK_VOXELS]> = bricks
            .par_iter()
            .enumerate()
            .map(|(i, b)| {
                let mut out = [0.0; BRICK_VOXELS];
                self.decode(i as u32, &mut out);
                for (o, v) in out.iter_mut().zip(b) {
                    *o = v - *o;
                }
                out
            })
            .collect();
        let se = |r: &[f32; BRICK_VOXELS]| r.iter().map(|e| (e * e) as f64).sum::<f64>();
        let mut order: Vec<u32> = (0..bricks.len() as u32).collect();
        order.sort_by(|&a, &b| se(&residuals[b as usize]).total_cmp(&se(&residuals[a as usize])));
        let mut chosen: Vec<u32> = order[..count]
            .iter()
            .copied()
            .filter(|&i| se(&residuals[i as usize]) > 0.0)
            .collect();
        chosen.sort_unstable();
        let picked: Vec<[f32; BRICK_VOXELS]> =
            chosen.iter().map(|&i| residuals[i as usize]).collect();
        let ranges: Vec<(f32, f32)> = picked
            .iter()
            .map(|r| {
                r.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |a, &v| {
                    (a.0.min(v), a.1.max(v))
                })
            })
            .collect();
        let blocks: Vec<Vec<u8>> = picked
            .par_chunks(CHUNK)
            .zip(ranges.par_chunks(CHUNK))
            .map(|(src, rg)| {
                let per: Vec<(f32, f32)> = rg
                    .iter()
                    .map(|&(a, b)| (a, if b > a { 1.0 / (b - a) } else { 0.0 }))
                    .collect();
                encode_bc7(src, &per)
            })
            .collect();
        let blocks: Vec<u8> = blocks.concat();
        for ((r, b), _) in ranges.iter().zip(blocks.chunks_exact(128)).zip(&chosen) {
            self.refinement.extend_from_slice(&r.0.to_le_bytes());
            self.refinement.extend_from_slice(&r.1.to_le_bytes());
            self.refinement.extend_from_slice(b);
        }
        self.refined = chosen;
    }

    /// All bytes of the pool (bricks, refined list and refinement records).
    pub fn byte_size(&self) -> usize {
        self.data.len() + 4 * self.refined.len() + self.refinement.len()
    }

    /// Number of bricks.
    pub fn len(&self) -> usize {
        self.data.len() / self.format.brick_bytes()
    }

    /// Whether the pool holds no brick.
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    /// The encoded bytes of brick `i`.
    #[inline]
    pub fn brick(&self, i: u32) -> &[u8] {
        let bb = self.format.brick_bytes();
        &self.data[i as usize * bb..(i as usize + 1) * bb]
    }

    /// Decodes brick `i` into `out` ([`voxel_index`] layout).
    pub fn decode(&self, i: u32, out: &mut [f32; BRICK_VOXELS]) {
        let b = self.brick(i);
        let (lo, span) = (self.lo, (self.hi - self.lo) / 255.0);
        match self.format {
            BrickFormat::F32 => {
                for (o, c) in out.iter_mut().zip(b.chunks_exact(4)) {
                    *o = f32::from_le_bytes([c[0], c[1], c[2], c[3]]);
                }
            }
            BrickFormat::F16 => {
                for (o, c) in out.iter_mut().zip(b.chunks_exact(2)) {
                    *o = half::f16::from_le_bytes([c[0], c[1]]).to_f32();
                }
            }
            BrickFormat::Unorm8 => {
                for (o, &c) in out.iter_mut().zip(b) {
                    *o = lo + c as f32 * span;
                }
            }
            BrickFormat::Bc4 => {
                let (lo, span) = sub_range(b, lo, span);
                let mut px = [0u8; 16];
                for (k, block) in b[2..].chunks_exact(8).enumerate() {
                    bcdec_rs::bc4(block, &mut px, 4, false);
                    // Block k: row-of-blocks k / 2 covers slice z = k / 4, rows y0..y0 + 4.
                    let (row, x0) = (k / 2, (k % 2) * 4);
                    let (z, y0) = (row / 2, (row % 2) * 4);
                    for dy in 0..4 {
                        for dx in 0..4 {
                            out[voxel_index(x0 + dx, y0 + dy, z)] =
                                lo + px[dy * 4 + dx] as f32 * span;
                        }
                    }
                }
            }
            BrickFormat::Bc7 => {
                decode_bc7(b, lo, span, out, false);
                if let Ok(k) = self.refined.binary_search(&i) {
                    let r = &self.refinement[k * REFINEMENT_BYTES..(k + 1) * REFINEMENT_BYTES];
                    let r0 = f32::from_le_bytes([r[0], r[1], r[2], r[3]]);
                    let r1 = f32::from_le_bytes([r[4], r[5], r[6], r[7]]);
                    decode_bc7(&r[8..], r0, (r1 - r0) / 255.0, out, true);
                }
            }
        }
    }

    /// Decodes the 4³ block `g` (`x/4 + 2 (y/4) + 4 (z/4)`) of brick `i` into `out`, indexed
    /// `x%4 + 4 (y%4 + 4 (z%4))`: a BC7 block, four BC4 blocks or 64 plain values.
    pub fn decode_block(&self, i: u32, g: usize, out: &mut [f32; 64]) {
        let b = self.brick(i);
        let (lo, span) = (self.lo, (self.hi - self.lo) / 255.0);
        let (x0, y0, z0) = ((g & 1) * 4, ((g >> 1) & 1) * 4, (g >> 2) * 4);
        match self.format {
            BrickFormat::Bc7 => {
                // BC7 block k = (zq * 2 + y / 4) * 2 + x / 4 is exactly group g.
                decode_bc7_block(&b[g * 16..g * 16 + 16], lo, span, out, false);
                if let Ok(k) = self.refined.binary_search(&i) {
                    let r = &self.refinement[k * REFINEMENT_BYTES..(k + 1) * REFINEMENT_BYTES];
                    let r0 = f32::from_le_bytes([r[0], r[1], r[2], r[3]]);
                    let r1 = f32::from_le_bytes([r[4], r[5], r[6], r[7]]);
                    decode_bc7_block(
                        &r[8 + g * 16..8 + g * 16 + 16],
                        r0,
                        (r1 - r0) / 255.0,
                        out,
                        true,
                    );
                }
            }
            BrickFormat::Bc4 => {
                let (lo, span) = sub_range(b, lo, span);
                let mut px = [0u8; 16];
                for dz in 0..4 {
                    let k = ((z0 + dz) * 2 + y0 / 4) * 2 + x0 / 4;
                    bcdec_rs::bc4(&b[2 + k * 8..2 + k * 8 + 8], &mut px, 4, false);
                    for (j, &p) in px.iter().enumerate() {
                        out[j + 16 * dz] = lo + p as f32 * span;
                    }
                }
            }
            _ => {
                for dz in 0..4 {
                    for dy in 0..4 {
                        for dx in 0..4 {
                            let v = voxel_index(x0 + dx, y0 + dy, z0 + dz);
                            out[dx + 4 * (dy + 4 * dz)] = self.raw_value(i, v).unwrap_or(0.0);
                        }
                    }
                }
            }
        }
    }

    /// Reads one voxel of brick `i` directly (the uncompressed formats only).
    #[inline]
    pub fn raw_value(&self, i: u32, voxel: usize) -> Option<f32> {
        let bb = self.format.brick_bytes();
        let at = i as usize * bb;
        match self.format {
            BrickFormat::F32 => {
                let c = &self.data[at + voxel * 4..at + voxel * 4 + 4];
                Some(f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            }
            BrickFormat::F16 => {
                let c = &self.data[at + voxel * 2..at + voxel * 2 + 2];
                Some(half::f16::from_le_bytes([c[0], c[1]]).to_f32())
            }
            BrickFormat::Unorm8 => {
                Some(self.lo + self.data[at + voxel] as f32 * ((self.hi - self.lo) / 255.0))
            }
            BrickFormat::Bc4 | BrickFormat::Bc7 => None,
        }
    }
}

fn encode_chunk(
    format: BrickFormat,
    src: &[[f32; BRICK_VOXELS]],
    lo: f32,
    scale: f32,
    out: &mut [u8],
) {
    match format {
        BrickFormat::F32 => {
            for (o, v) in out.chunks_exact_mut(4).zip(src.iter().flatten()) {
                o.copy_from_slice(&v.to_le_bytes());
            }
        }
        BrickFormat::F16 => {
            for (o, v) in out.chunks_exact_mut(2).zip(src.iter().flatten()) {
                o.copy_from_slice(&half::f16::from_f32(*v).to_le_bytes());
            }
        }
        BrickFormat::Unorm8 => {
            for (o, v) in out.iter_mut().zip(src.iter().flatten()) {
                *o = to_unorm(*v, lo, scale);
            }
        }
        BrickFormat::Bc4 => {
            // Surface: 8 texels wide, 64 rows per brick (row = 8 z + y).
            let mut px = vec![0u8; src.len() * BRICK_VOXELS];
            let mut ranges = Vec::with_capacity(src.len());
            for (b, brick) in src.iter().enumerate() {
                let (r, lo, scale) = brick_range(brick, lo, scale);
                ranges.push(r);
                for z in 0..8 {
                    for y in 0..8 {
                        for x in 0..8 {
                            px[b * 512 + (z * 8 + y) * 8 + x] =
                                to_unorm(brick[voxel_index(x, y, z)], lo, scale);
                        }
                    }
                }
            }
            let surface = intel_tex_2::RSurface {
                data: &px,
                width: 8,
                height: (src.len() * 64) as u32,
                stride: 8,
            };
            interleave(&ranges, &intel_tex_2::bc4::compress_blocks(&surface), out);
        }
        BrickFormat::Bc7 => {
            let per = vec![(lo, scale); src.len()];
            out.copy_from_slice(&encode_bc7(src, &per));
        }
    }
}

/// BC7-encodes bricks, four z voxels per RGBA texel: the surface is 8 texels wide with 16
/// rows per brick (row = 8 zq + y, channel c = z - 4 zq). Brick `b` maps `v` to
/// `(v - per[b].0) * per[b].1` on 0..=1.
fn encode_bc7(src: &[[f32; BRICK_VOXELS]], per: &[(f32, f32)]) -> Vec<u8> {
    let mut px = vec![0u8; src.len() * BRICK_VOXELS];
    for (b, (brick, &(lo, scale))) in src.iter().zip(per).enumerate() {
        for zq in 0..2 {
            for y in 0..8 {
                for x in 0..8 {
                    for c in 0..4 {
                        px[b * 512 + ((zq * 8 + y) * 8 + x) * 4 + c] =
                            to_unorm(brick[voxel_index(x, y, zq * 4 + c)], lo, scale);
                    }
                }
            }
        }
    }
    let surface = intel_tex_2::RgbaSurface {
        data: &px,
        width: 8,
        height: (src.len() * 16) as u32,
        stride: 32,
    };
    intel_tex_2::bc7::compress_blocks(&intel_tex_2::bc7::alpha_basic_settings(), &surface)
}

/// Decodes one BC7 block (a 4³ group, indexed `x + 4 (y + 4 z)`) as `lo + code · span`,
/// added to `out` if `add`.
fn decode_bc7_block(b: &[u8], lo: f32, span: f32, out: &mut [f32; 64], add: bool) {
    let mut px = [0u8; 64];
    bcdec_rs::bc7(b, &mut px, 16);
    for dy in 0..4 {
        for dx in 0..4 {
            for c in 0..4 {
                let v = lo + px[(dy * 4 + dx) * 4 + c] as f32 * span;
                let o = &mut out[dx + 4 * (dy + 4 * c)];
                *o = if add { *o + v } else { v };
            }
        }
    }
}

/// Decodes one BC7 brick (128 bytes) as `lo + code · span`, added to `out` if `add`.
fn decode_bc7(b: &[u8], lo: f32, span: f32, out: &mut [f32; BRICK_VOXELS], add: bool) {
    let mut px = [0u8; 64];
    for (k, block) in b.chunks_exact(16).enumerate() {
        bcdec_rs::bc7(block, &mut px, 16);
        let (row, x0) = (k / 2, (k % 2) * 4);
        let (zq, y0) = (row / 2, (row % 2) * 4);
        for dy in 0..4 {
            for dx in 0..4 {
                for c in 0..4 {
                    let v = lo + px[(dy * 4 + dx) * 4 + c] as f32 * span;
                    let o = &mut out[voxel_index(x0 + dx, y0 + dy, zq * 4 + c)];
                    *o = if add { *o + v } else { v };
                }
            }
        }
    }
}

/// Writes each brick as its two range bytes followed by its blocks.
fn interleave(ranges: &[[u8; 2]], blocks: &[u8], out: &mut [u8]) {
    let per = blocks.len() / ranges.len();
    for ((o, r), b) in out
        .chunks_exact_mut(per + 2)
        .zip(ranges)
        .zip(blocks.chunks_exact(per))
    {
        o[..2].copy_from_slice(r);
        o[2..].copy_from_slice(b);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn smooth_bricks(n: usize) -> Vec<[f32; BRICK_VOXELS]> {
        (0..n)
            .map(|b| {
                let mut a = [0.0; BRICK_VOXELS];
                for z in 0..8 {
                    for y in 0..8 {
                        for x in 0..8 {
                            a[voxel_index(x, y, z)] =
                                ((x + 2 * y + 3 * z + b) as f32 * 0.02).sin() * 0.5 + 0.5;
                        }
                    }
                }
                a
            })
            .collect()
    }

    #[test]
    fn every_format_round_trips_within_its_precision() {
        let bricks = smooth_bricks(70);
        for (format, tol) in [
            (BrickFormat::F32, 0.0),
            (BrickFormat::F16, 1e-3),
            (BrickFormat::Unorm8, 0.5 / 255.0 + 1e-6),
            (BrickFormat::Bc4, 0.02),
            (BrickFormat::Bc7, 0.03),
        ] {
            let pool = BrickPool::encode(format, &bricks, 0.0, 1.0);
            assert_eq!(pool.len(), bricks.len());
            assert_eq!(pool.data.len(), bricks.len() * format.brick_bytes());
            let mut out = [0.0; BRICK_VOXELS];
            for (i, b) in bricks.iter().enumerate() {
                pool.decode(i as u32, &mut out);
                let err = b
                    .iter()
                    .zip(&out)
                    .map(|(a, c)| (a - c).abs())
                    .fold(0.0, f32::max);
                assert!(err <= tol, "{format:?} brick {i}: error {err}");
                if let Some(v) = pool.raw_value(i as u32, 77) {
                    assert_eq!(v, out[77]);
                }
                let mut block = [0.0; 64];
                for g in 0..8 {
                    pool.decode_block(i as u32, g, &mut block);
                    let (x0, y0, z0) = ((g & 1) * 4, ((g >> 1) & 1) * 4, (g >> 2) * 4);
                    for (j, v) in block.iter().enumerate() {
                        let (x, y, z) = (x0 + j % 4, y0 + (j / 4) % 4, z0 + j / 16);
                        assert_eq!(*v, out[voxel_index(x, y, z)], "{format:?} block {g}");
                    }
                }
            }
        }
    }

    #[test]
    fn bc7_keeps_the_z_channels_apart() {
        let mut brick = [0.0f32; BRICK_VOXELS];
        for z in 0..8 {
            for y in 0..8 {
                for x in 0..8 {
                    brick[voxel_index(x, y, z)] = z as f32 / 7.0;
                }
            }
        }
        let pool = BrickPool::encode(BrickFormat::Bc7, &[brick], 0.0, 1.0);
        let mut out = [0.0; BRICK_VOXELS];
        pool.decode(0, &mut out);
        for z in 0..8 {
            assert!((out[voxel_index(3, 5, z)] - z as f32 / 7.0).abs() < 0.02);
        }
    }
}
