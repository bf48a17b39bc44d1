//! √5 hierarchical image-space sampling (paper §4.3), aligned so that every sample is a pixel
//! centre.
//!
//! Pixel `(x, y)` is the Gaussian integer `x + y·i`. The finest level `L` is the pixel grid
//! `ℤ[i]`; level `ℓ` is the sublattice `gᵏ·ℤ[i]` with `k = L − ℓ` and `g = 2 − i`, i.e. each
//! coarser level is the finer one scaled by √5 and turned by arctan ½. A level-`ℓ` position is
//! `(a + b·i)·gᵏ = a·u + b·v` with `u = gᵏ` and `v = i·u`; it also belongs to level `ℓ − 1`
//! exactly when `a + b·i` is divisible by `g`, which (as `i ≡ 2` modulo `g`) is the paper's rule
//! `(a + 2b) mod 5 = 0`. Such positions are omitted on every level but the first, so over all
//! levels every pixel is sampled exactly once. The paper's square splat footprint of level `ℓ`
//! has the side `s_ℓ = max(|u.x|, |u.y|)`, its `√5ᵏ·max(|cos kα|, |sin kα|)` (the tests check
//! the lattice against it; `crate::splat` reaches a level's spacing instead).
//!
//! Iteration is non-recursive: the lattice rows `b` crossing a rectangle, then for each row the
//! range of `a` clipped to the rectangle (parametric line clipping).

use thiserror::Error;

/// Most levels a hierarchy may have: the coarsest spacing is then √5¹¹ ≈ 6 988 pixels.
pub const MAX_LEVELS: u8 = 12;

/// Errors of the sampling hierarchy.
#[derive(Debug, Error, PartialEq, Eq)]
pub enum SamplingError {
    /// The number of levels is outside `1..=MAX_LEVELS`.
    #[error("a √5 hierarchy needs 1..={MAX_LEVELS} levels, got {0}")]
    Levels(u8),
    /// A level outside `1..=levels` was asked for.
    #[error("level {level} is outside 1..={levels}")]
    Level {
        /// The level asked for.
        level: u8,
        /// Levels of the hierarchy.
        levels: u8,
    },
}

/// A half-open pixel rectangle `[x0, x1) × [y0, y1)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct PixelRect {
    /// First column.
    pub x0: i32,
    /// First row.
    pub y0: i32,
    /// One past the last column.
    pub x1: i32,
    /// One past the last row.
    pub y1: i32,
}

impl PixelRect {
    /// True when the rectangle holds no pixel.
    pub fn is_empty(&self) -> bool {
        self.x1 <= self.x0 || self.y1 <= self.y0
    }

    /// True when pixel (`x`, `y`) lies inside.
    pub fn contains(&self, x: i32, y: i32) -> bool {
        x >= self.x0 && x < self.x1 && y >= self.y0 && y < self.y1
    }

    /// Number of pixels inside.
    pub fn area(&self) -> u64 {
        if self.is_empty() {
            0
        } else {
            (self.x1 - self.x0) as u64 * (self.y1 - self.y0) as u64
        }
    }
}

/// The √5 level hierarchy: level 1 is the coarsest, level `levels` the pixel grid.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Hierarchy {
    levels: u8,
}

/// `gᵏ` for `g = 2 − i`, as (real, imaginary).
fn g_power(k: u8) -> (i64, i64) {
    let (mut re, mut im) = (1i64, 0i64);
    for _ in 0..k {
        // (re + im·i)(2 − i) = (2re + im) + (2im − re)·i
        (re, im) = (2 * re + im, 2 * im - re);
    }
    (re, im)
}

impl Hierarchy {
    /// A hierarchy of `levels` levels (1..=[`MAX_LEVELS`]).
    pub fn new(levels: u8) -> Result<Self, SamplingError> {
        if levels == 0 || levels > MAX_LEVELS {
            return Err(SamplingError::Levels(levels));
        }
        Ok(Self { levels })
    }

    /// The smallest hierarchy whose coarsest spacing (√5^(levels−1)) reaches `spacing` pixels.
    pub fn for_spacing(spacing: f32) -> Self {
        let mut levels = 1u8;
        while levels < MAX_LEVELS && 5f32.sqrt().powi(levels as i32 - 1) < spacing {
            levels += 1;
        }
        Self { levels }
    }

    /// Number of levels.
    pub fn levels(&self) -> u8 {
        self.levels
    }

    fn check(&self, level: u8) -> Result<u8, SamplingError> {
        if level == 0 || level > self.levels {
            Err(SamplingError::Level {
                level,
                levels: self.levels,
            })
        } else {
            Ok(self.levels - level)
        }
    }

    /// The lattice vector `u` of a level (the other is `u` turned by 90°).
    pub fn basis(&self, level: u8) -> Result<(i64, i64), SamplingError> {
        Ok(g_power(self.check(level)?))
    }

    /// The level at which pixel (`x`, `y`) is sampled.
    pub fn level_of(&self, x: i32, y: i32) -> u8 {
        let (mut a, mut b) = (x as i64, y as i64);
        let mut level = self.levels;
        // Divide by g while possible: (a + b·i)/(2 − i) = ((2a − b) + (a + 2b)·i)/5.
        while level > 1 && (a + 2 * b).rem_euclid(5) == 0 {
            (a, b) = ((2 * a - b) / 5, (a + 2 * b) / 5);
            level -= 1;
        }
        level
    }

    /// The positions of one level inside a rectangle, in iteration order.
    pub fn level_samples(&self, level: u8, rect: PixelRect) -> Result<LevelSamples, SamplingError> {
        let k = self.check(level)?;
        let (ux, uy) = g_power(k);
        Ok(LevelSamples::new(ux, uy, level > 1, rect))
    }
}

/// The positions of one level inside a rectangle: rows `b`, each with its column range of `a`.
#[derive(Clone, Debug)]
pub struct LevelSamples {
    u: (i64, i64),
    omit_coarser: bool,
    rect: PixelRect,
    /// First and last lattice row crossing the rectangle (none when first > last).
    rows: (i64, i64),
}

/// `ceil(n / d)` for `d > 0`.
fn div_ceil(n: i64, d: i64) -> i64 {
    -((-n).div_euclid(d))
}

/// Clip `lo ≤ c + a·s ≤ hi` to a range of `a` (empty when `lo_a > hi_a`).
fn clip(c: i64, s: i64, lo: i64, hi: i64) -> (i64, i64) {
    match s.signum() {
        1 => (div_ceil(lo - c, s), (hi - c).div_euclid(s)),
        -1 => (div_ceil(c - hi, -s), (c - lo).div_euclid(-s)),
        _ if c >= lo && c <= hi => (i64::MIN / 4, i64::MAX / 4),
        _ => (1, 0),
    }
}

impl LevelSamples {
    fn new(ux: i64, uy: i64, omit_coarser: bool, rect: PixelRect) -> Self {
        let norm = ux * ux + uy * uy;
        let (vx, vy) = (-uy, ux);
        let rows = if rect.is_empty() {
            (1, 0)
        } else {
            let corners = [
                (rect.x0 as i64, rect.y0 as i64),
                (rect.x1 as i64 - 1, rect.y0 as i64),
                (rect.x0 as i64, rect.y1 as i64 - 1),
                (rect.x1 as i64 - 1, rect.y1 as i64 - 1),
            ];
            let dots = corners.map(|(x, y)| x * vx + y * vy);
            let lo = *dots.iter().min().expect("four corners");
            let hi = *dots.iter().max().expect("four corners");
            (div_ceil(lo, norm), hi.div_euclid(norm))
        };
        Self {
            u: (ux, uy),
            omit_coarser,
            rect,
            rows,
        }
    }

    /// The column range `a` of row `b` (empty when start > end).
    fn columns(&self, b: i64) -> (i64, i64) {
        let (ux, uy) = self.u;
        let (cx, cy) = (-uy * b, ux * b);
        let r = &self.rect;
        let (ax0, ax1) = clip(cx, ux, r.x0 as i64, r.x1 as i64 - 1);
        let (ay0, ay1) = clip(cy, uy, r.y0 as i64, r.y1 as i64 - 1);
        (ax0.max(ay0), ax1.min(ay1))
    }

    /// Positions of row `b` with `a` in `[a0, a1]` that this level keeps.
    fn kept_in(&self, b: i64, a0: i64, a1: i64) -> u64 {
        if a0 > a1 {
            return 0;
        }
        let total = (a1 - a0 + 1) as u64;
        if !self.omit_coarser {
            return total;
        }
        // Omitted: a ≡ −2b (mod 5).
        let r = (-2 * b).rem_euclid(5);
        let first = a0 + (r - a0).rem_euclid(5);
        let omitted = if first > a1 {
            0
        } else {
            ((a1 - first) / 5 + 1) as u64
        };
        total - omitted
    }

    /// Number of positions of this level inside the rectangle.
    pub fn count(&self) -> u64 {
        (self.rows.0..=self.rows.1)
            .map(|b| {
                let (a0, a1) = self.columns(b);
                self.kept_in(b, a0, a1)
            })
            .sum()
    }

    /// Iterate the positions from the `start`-th one on (0 = the first), as pixel (x, y).
    pub fn iter_from(&self, start: u64) -> LevelIter<'_> {
        let mut skip = start;
        let (mut b, end) = self.rows;
        while b <= end {
            let (a0, a1) = self.columns(b);
            let n = self.kept_in(b, a0, a1);
            if skip < n {
                break;
            }
            skip -= n;
            b += 1;
        }
        let mut it = LevelIter {
            samples: self,
            b,
            a: 0,
            a_end: -1,
        };
        if b <= end {
            let (a0, a1) = self.columns(b);
            it.a = a0;
            it.a_end = a1;
            // Skip within the row, counting only kept positions.
            while skip > 0 {
                if it.kept(it.a) {
                    skip -= 1;
                }
                it.a += 1;
            }
        }
        it
    }
}

/// Non-recursive iterator over one level's positions in a rectangle.
#[derive(Clone, Debug)]
pub struct LevelIter<'a> {
    samples: &'a LevelSamples,
    b: i64,
    a: i64,
    a_end: i64,
}

impl LevelIter<'_> {
    fn kept(&self, a: i64) -> bool {
        !self.samples.omit_coarser || (a + 2 * self.b).rem_euclid(5) != 0
    }
}

impl Iterator for LevelIter<'_> {
    type Item = (i32, i32);

    fn next(&mut self) -> Option<(i32, i32)> {
        let end = self.samples.rows.1;
        while self.b <= end {
            while self.a <= self.a_end {
                let a = self.a;
                self.a += 1;
                if self.kept(a) {
                    let (ux, uy) = self.samples.u;
                    let x = a * ux - self.b * uy;
                    let y = a * uy + self.b * ux;
                    return Some((x as i32, y as i32));
                }
            }
            self.b += 1;
            if self.b <= end {
                (self.a, self.a_end) = self.samples.columns(self.b);
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Side in pixels of the paper's square splat footprint of a level (1 on the finest
    /// level): the larger component of the level's lattice vector.
    fn footprint(h: &Hierarchy, level: u8) -> Result<u32, SamplingError> {
        let (ux, uy) = h.basis(level)?;
        Ok(ux.unsigned_abs().max(uy.unsigned_abs()) as u32)
    }

    /// The pixels a splat of side `side` centred on pixel (`x`, `y`) covers, as a rectangle
    /// (for an even side the extra column and row are on the low side).
    fn footprint_rect(x: i32, y: i32, side: u32) -> PixelRect {
        let side = side.max(1) as i32;
        let lo = side / 2;
        let hi = side - lo;
        PixelRect {
            x0: x - lo,
            y0: y - lo,
            x1: x + hi,
            y1: y + hi,
        }
    }

    fn disc_mask(w: i32, h: i32) -> Vec<bool> {
        let (cx, cy, r) = (w as f32 * 0.45, h as f32 * 0.55, h as f32 * 0.4);
        (0..h)
            .flat_map(|y| {
                (0..w).map(move |x| {
                    let (dx, dy) = (x as f32 - cx, y as f32 - cy);
                    dx * dx + dy * dy < r * r
                })
            })
            .collect()
    }

    #[test]
    fn rejects_bad_levels() {
        assert_eq!(Hierarchy::new(0), Err(SamplingError::Levels(0)));
        assert_eq!(Hierarchy::new(13), Err(SamplingError::Levels(13)));
        let h = Hierarchy::new(5).unwrap();
        assert!(footprint(&h, 6).is_err());
        assert!(h
            .level_samples(
                0,
                PixelRect {
                    x0: 0,
                    y0: 0,
                    x1: 1,
                    y1: 1
                }
            )
            .is_err());
    }

    #[test]
    fn footprints_follow_the_paper() {
        let h = Hierarchy::new(7).unwrap();
        let alpha = 0.5f64.atan();
        for level in 1..=7u8 {
            let k = (7 - level) as i32;
            let s = 5f64.sqrt().powi(k)
                * (k as f64 * alpha)
                    .cos()
                    .abs()
                    .max((k as f64 * alpha).sin().abs());
            assert!(
                (footprint(&h, level).unwrap() as f64 - s).abs() < 1e-6,
                "level {level}"
            );
        }
        assert_eq!(footprint(&h, 7).unwrap(), 1);
    }

    #[test]
    fn every_pixel_of_a_region_is_sampled_exactly_once() {
        for levels in [1u8, 3, 6] {
            let h = Hierarchy::new(levels).unwrap();
            // An offset rectangle (negative and positive coordinates) and an odd size.
            let rect = PixelRect {
                x0: -7,
                y0: 3,
                x1: 61,
                y1: 50,
            };
            let (w, hgt) = (rect.x1 - rect.x0, rect.y1 - rect.y0);
            let mut hits = vec![0u32; (w * hgt) as usize];
            for level in 1..=levels {
                let s = h.level_samples(level, rect).unwrap();
                let mut n = 0u64;
                for (x, y) in s.iter_from(0) {
                    assert!(rect.contains(x, y), "({x}, {y}) outside");
                    assert_eq!(h.level_of(x, y), level);
                    hits[((y - rect.y0) * w + x - rect.x0) as usize] += 1;
                    n += 1;
                }
                assert_eq!(n, s.count(), "count of level {level}");
            }
            assert!(hits.iter().all(|&c| c == 1), "levels {levels}");
        }
    }

    #[test]
    fn resuming_at_an_iterator_position_continues_the_sequence() {
        let h = Hierarchy::new(5).unwrap();
        let rect = PixelRect {
            x0: 0,
            y0: 0,
            x1: 40,
            y1: 33,
        };
        for level in 1..=5 {
            let s = h.level_samples(level, rect).unwrap();
            let all: Vec<_> = s.iter_from(0).collect();
            for start in [0usize, 1, 7, all.len() / 2, all.len()] {
                let start = start.min(all.len());
                let rest: Vec<_> = s.iter_from(start as u64).collect();
                assert_eq!(rest, all[start..], "level {level} from {start}");
            }
        }
    }

    /// Splat level by level, writing only pixels inside the region (the stencil test).
    fn splat_levels(h: &Hierarchy, mask: &[bool], w: i32, hgt: i32, reference: &[u32]) -> Vec<u32> {
        let rect = PixelRect {
            x0: 0,
            y0: 0,
            x1: w,
            y1: hgt,
        };
        let mut image = vec![0u32; (w * hgt) as usize];
        for level in 1..=h.levels() {
            let side = footprint(h, level).unwrap();
            for (x, y) in h.level_samples(level, rect).unwrap().iter_from(0) {
                if !mask[(y * w + x) as usize] {
                    continue;
                }
                let value = reference[(y * w + x) as usize];
                let f = footprint_rect(x, y, side);
                for py in f.y0.max(0)..f.y1.min(hgt) {
                    for px in f.x0.max(0)..f.x1.min(w) {
                        if mask[(py * w + px) as usize] {
                            image[(py * w + px) as usize] = value;
                        }
                    }
                }
            }
        }
        image
    }

    #[test]
    fn splatting_level_by_level_ends_identical_to_the_reference() {
        let (w, hgt) = (90, 70);
        let mask = disc_mask(w, hgt);
        let reference: Vec<u32> = (0..(w * hgt) as u32)
            .map(|i| i.wrapping_mul(2_654_435_761))
            .collect();
        for levels in [4u8, 6] {
            let h = Hierarchy::new(levels).unwrap();
            let image = splat_levels(&h, &mask, w, hgt, &reference);
            for i in 0..(w * hgt) as usize {
                if mask[i] {
                    assert_eq!(image[i], reference[i], "pixel {i}");
                } else {
                    assert_eq!(image[i], 0);
                }
            }
        }
    }

    #[test]
    fn a_sample_centre_is_never_covered_by_a_later_level() {
        let h = Hierarchy::new(6).unwrap();
        let rect = PixelRect {
            x0: -20,
            y0: -20,
            x1: 80,
            y1: 80,
        };
        let inner = PixelRect {
            x0: 0,
            y0: 0,
            x1: 60,
            y1: 60,
        };
        let mut level_at = std::collections::HashMap::new();
        for level in 1..=6u8 {
            for p in h.level_samples(level, rect).unwrap().iter_from(0) {
                level_at.insert(p, level);
            }
        }
        for level in 1..=6u8 {
            let side = footprint(&h, level).unwrap();
            for (x, y) in h.level_samples(level, inner).unwrap().iter_from(0) {
                let f = footprint_rect(x, y, side);
                for py in f.y0..f.y1 {
                    for px in f.x0..f.x1 {
                        if (px, py) == (x, y) {
                            continue;
                        }
                        let covered = level_at[&(px, py)];
                        assert!(
                            covered > level,
                            "level-{level} splat at ({x}, {y}) covers a level-{covered} centre ({px}, {py})"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn coarse_levels_cover_most_pixels() {
        // The coarse splats leave few holes, so early frames are already mostly corrected.
        let h = Hierarchy::new(5).unwrap();
        let (w, hgt) = (100, 100);
        for level in 1..=5u8 {
            let mut covered = vec![false; (w * hgt) as usize];
            for l in 1..=level {
                let side = footprint(&h, l).unwrap();
                let grow = PixelRect {
                    x0: -200,
                    y0: -200,
                    x1: w + 200,
                    y1: hgt + 200,
                };
                for (x, y) in h.level_samples(l, grow).unwrap().iter_from(0) {
                    let f = footprint_rect(x, y, side);
                    for py in f.y0.max(0)..f.y1.min(hgt) {
                        for px in f.x0.max(0)..f.x1.min(w) {
                            covered[(py * w + px) as usize] = true;
                        }
                    }
                }
            }
            let frac = covered.iter().filter(|&&c| c).count() as f64 / covered.len() as f64;
            // Measured: 0.92 after level 1, above 0.99 from level 2 on.
            assert!(frac > 0.9, "level {level}: {frac}");
        }
    }

    #[test]
    fn for_spacing_reaches_the_spacing() {
        assert_eq!(Hierarchy::for_spacing(1.0).levels(), 1);
        let h = Hierarchy::for_spacing(100.0);
        assert!(5f32.sqrt().powi(h.levels() as i32 - 1) >= 100.0);
        assert!(5f32.sqrt().powi(h.levels() as i32 - 2) < 100.0);
    }
}
