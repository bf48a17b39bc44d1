//! A table of values over the unit sphere, in an octahedral map, linearly interpolated.
//!
//! The run-time relighter ([`crate::runtime`]) shades a vertex as the dot product of its
//! visibility (SH, world space) with a vector that depends only on the BRDF axis and the
//! frame's lighting (see [`crate::shade::Shader::axis_transfer`]); that vector is smooth in
//! the axis, so it is tabulated once per lighting and looked up per vertex.
//!
//! The octahedral map folds the sphere onto the square `[−1, 1]²`: `p = (x, y) / (|x| + |y| +
//! |z|)` for the upper hemisphere, the lower one folded over the diagonals. Grid points are
//! placed on the square's corners and edges (`res + 1` per side); a point on an edge and its
//! mirror image across the edge's midpoint are the same direction, so the interpolated
//! function is continuous over the whole sphere.

use glam::{Vec2, Vec3};
use rayon::prelude::*;

/// A vector-valued function over the sphere, tabulated on an octahedral grid.
#[derive(Clone, Debug)]
pub struct SphereTable {
    /// Cells per side of the square.
    res: usize,
    /// Values per grid point.
    width: usize,
    /// Row-major `(res + 1)² × width`.
    values: Vec<f32>,
}

impl SphereTable {
    /// Tabulates `f(direction, out)` (`width` values) at the grid points, on all rayon
    /// threads. `res` is clamped to at least 2 (and made even, so that the grid is symmetric).
    pub fn new(res: usize, width: usize, f: impl Fn(Vec3, &mut [f32]) + Sync) -> Self {
        let res = res.max(2).next_multiple_of(2);
        let side = res + 1;
        let mut values = vec![0.0f32; side * side * width];
        values
            .par_chunks_mut(width.max(1))
            .enumerate()
            .for_each(|(k, out)| {
                let (i, j) = (k % side, k / side);
                let uv = Vec2::new(i as f32, j as f32) / res as f32 * 2.0 - Vec2::ONE;
                f(decode(uv), out);
            });
        Self { res, width, values }
    }

    /// Values per direction.
    pub fn width(&self) -> usize {
        self.width
    }

    /// The interpolated values at the unit direction `d` into `out` (`width` values).
    pub fn lookup(&self, d: Vec3, out: &mut [f32]) {
        let (offsets, weights) = self.corners(d);
        let out = &mut out[..self.width];
        out.fill(0.0);
        for (offset, weight) in offsets.into_iter().zip(weights) {
            for (o, v) in out.iter_mut().zip(self.point(offset)) {
                *o += weight * v;
            }
        }
    }

    /// The grid points whose values are interpolated at the unit direction `d`: the
    /// offsets of their values (for [`Self::point`]) and their weights (summing to 1).
    /// Branch-free, so that a loop over directions vectorises.
    #[inline(always)]
    pub fn corners(&self, d: Vec3) -> ([u32; 3], [f32; 3]) {
        let res = self.res as f32;
        let uv = (encode(d) + Vec2::ONE) * (0.5 * res);
        let last = self.res as f32 - 1.0;
        let (fi, fj) = (
            uv.x.max(0.0).floor().min(last),
            uv.y.max(0.0).floor().min(last),
        );
        let (fx, fy) = (uv.x - fi, uv.y - fj);
        // Through i32 (the cells are within 0..res): a conversion that vectorises.
        let (i, j) = (fi as i32 as u32, fj as i32 as u32);
        // The cell's triangle: split along the diagonal parallel to the fold of its
        // quadrant (|u| + |v| = 1), so that the map's kink lies on triangle edges. Corners
        // as (di, dj, weight).
        let half = (self.res / 2) as u32;
        let corners = if (i < half) == (j < half) {
            let low = fx + fy <= 1.0;
            [
                (
                    if low { 0 } else { 1 },
                    if low { 0 } else { 1 },
                    if low { 1.0 - fx - fy } else { fx + fy - 1.0 },
                ),
                (1, 0, if low { fx } else { 1.0 - fy }),
                (0, 1, if low { fy } else { 1.0 - fx }),
            ]
        } else {
            let right = fx >= fy;
            [
                (0, 0, if right { 1.0 - fx } else { 1.0 - fy }),
                (
                    if right { 1 } else { 0 },
                    if right { 0 } else { 1 },
                    if right { fx - fy } else { fy - fx },
                ),
                (1, 1, if right { fy } else { fx }),
            ]
        };
        let side = self.res as u32 + 1;
        let w = self.width as u32;
        (
            corners.map(|(di, dj, _)| ((j + dj) * side + i + di) * w),
            corners.map(|(_, _, weight)| weight),
        )
    }

    /// The values of the grid point at `offset` (from [`Self::corners`]).
    #[inline(always)]
    pub fn point(&self, offset: u32) -> &[f32] {
        &self.values[offset as usize..offset as usize + self.width]
    }
}

/// The octahedral map of a unit direction onto `[−1, 1]²`.
#[inline]
fn encode(d: Vec3) -> Vec2 {
    let p = Vec2::new(d.x, d.y) / (d.x.abs() + d.y.abs() + d.z.abs()).max(1e-30);
    if d.z >= 0.0 {
        p
    } else {
        (Vec2::ONE - Vec2::new(p.y.abs(), p.x.abs())) * sign(p)
    }
}

/// The unit direction of a point of `[−1, 1]²` (inverse of [`encode`]).
fn decode(uv: Vec2) -> Vec3 {
    let z = 1.0 - uv.x.abs() - uv.y.abs();
    let p = if z >= 0.0 {
        uv
    } else {
        (Vec2::ONE - Vec2::new(uv.y.abs(), uv.x.abs())) * sign(uv)
    };
    Vec3::new(p.x, p.y, z).normalize()
}

/// Per component: 1 for ≥ 0, else −1.
#[inline]
fn sign(p: Vec2) -> Vec2 {
    Vec2::new(
        if p.x >= 0.0 { 1.0 } else { -1.0 },
        if p.y >= 0.0 { 1.0 } else { -1.0 },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_map_round_trips() {
        for k in 0..200 {
            let (u1, u2) = psao_trace::ao::sample_2d(3, 0, k);
            let z = 1.0 - 2.0 * u1;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let (s, c) = (std::f32::consts::TAU * u2).sin_cos();
            let d = Vec3::new(r * c, r * s, z);
            assert!((decode(encode(d)) - d).length() < 1e-5, "{d}");
        }
    }

    #[test]
    fn smooth_functions_are_interpolated_closely_and_continuously() {
        // A band-2 function of the direction, two values per point.
        let f = |d: Vec3, out: &mut [f32]| {
            out[0] = 1.0 + d.x * d.y + 0.5 * d.z;
            out[1] = d.z * d.z - d.x;
        };
        let table = SphereTable::new(64, 2, f);
        assert_eq!(table.width(), 2);
        let mut worst = 0.0f32;
        for k in 0..2000 {
            let (u1, u2) = psao_trace::ao::sample_2d(9, 0, k);
            let z = 1.0 - 2.0 * u1;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let (s, c) = (std::f32::consts::TAU * u2).sin_cos();
            let d = Vec3::new(r * c, r * s, z);
            let (mut got, mut want) = ([0.0; 2], [0.0; 2]);
            table.lookup(d, &mut got);
            f(d, &mut want);
            worst = worst.max((got[0] - want[0]).abs().max((got[1] - want[1]).abs()));
        }
        assert!(worst < 2e-3, "worst interpolation error {worst}");
        // Grid points are exact, among them the poles and a folded edge point.
        for d in [Vec3::Z, -Vec3::Z, Vec3::X, Vec3::new(0.0, -1.0, 0.0)] {
            let (mut got, mut want) = ([0.0; 2], [0.0; 2]);
            table.lookup(d, &mut got);
            f(d, &mut want);
            assert!((got[0] - want[0]).abs() < 1e-5 && (got[1] - want[1]).abs() < 1e-5);
        }
    }
}
