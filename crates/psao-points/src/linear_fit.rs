//! A first-order (planar) weighted least-squares fit of AO over the tangent plane, the
//! optional interpolant of [`crate::reconstruct_ao`].
//!
//! The weighted mean of Eq. 2 flattens any variation within the reconstruction radius, e.g.
//! the steep fall of AO towards the foot of a wall a few centimetres tall. Fitting
//! `AO ≈ a + b·u + c·v` over the same weighted points (u, v: tangent-plane offsets) and taking
//! `a` keeps such gradients. Written here because it is a 3×3 solve on nine running sums;
//! a linear-algebra crate would add nothing.

use glam::Vec3;

/// Running weighted moments of the points used at one shaded position.
#[derive(Clone, Copy, Debug)]
pub struct LinearFit {
    t1: Vec3,
    t2: Vec3,
    s: [f32; 9],
    lo: f32,
    hi: f32,
}

impl LinearFit {
    /// An empty fit in the tangent plane of unit normal `n`.
    #[inline(always)]
    pub fn new(n: Vec3) -> Self {
        let (t1, t2) = n.any_orthonormal_pair();
        Self {
            t1,
            t2,
            s: [0.0; 9],
            lo: f32::INFINITY,
            hi: f32::NEG_INFINITY,
        }
    }

    /// Adds a point at offset `delta` from the shaded position with weight `w` and AO `ao`.
    #[inline(always)]
    pub fn add(&mut self, w: f32, delta: Vec3, ao: f32) {
        let (u, v) = (self.t1.dot(delta), self.t2.dot(delta));
        let (wu, wv) = (w * u, w * v);
        let s = &mut self.s;
        s[0] += w;
        s[1] += wu;
        s[2] += wv;
        s[3] += wu * u;
        s[4] += wu * v;
        s[5] += wv * v;
        s[6] += w * ao;
        s[7] += wu * ao;
        s[8] += wv * ao;
        self.lo = self.lo.min(ao);
        self.hi = self.hi.max(ao);
    }

    /// The fitted AO at the shaded position, kept within the range of the added values;
    /// `ridge` (a length: the fit's gradient is damped as if every point had that much
    /// extra spread in each tangent direction) keeps thin or one-sided point sets from
    /// extrapolating. The weighted mean when the system is singular; `None` without weight.
    #[inline(always)]
    pub fn solve(&self, ridge: f32) -> Option<f32> {
        let s = &self.s;
        if s[0].is_nan() || s[0] <= 0.0 {
            return None;
        }
        let mean = s[6] / s[0];
        let lambda = s[0] * ridge * ridge;
        let (a00, a01, a02) = (s[0], s[1], s[2]);
        let (a11, a12, a22) = (s[3] + lambda, s[4], s[5] + lambda);
        // Cramer's rule on the symmetric 3×3 system.
        let c00 = a11 * a22 - a12 * a12;
        let c01 = a02 * a12 - a01 * a22;
        let c02 = a01 * a12 - a02 * a11;
        let det = a00 * c00 + a01 * c01 + a02 * c02;
        let singular = det.abs() <= f32::EPSILON * a00 * c00.abs();
        if singular || !det.is_finite() {
            return Some(mean);
        }
        let a = (s[6] * c00 + s[7] * c01 + s[8] * c02) / det;
        Some(if a.is_finite() {
            a.clamp(self.lo, self.hi)
        } else {
            mean
        })
    }
}
