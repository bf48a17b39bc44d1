//! The analytic normalised-Phong convolution operator (paper eq. 2 and Appendix A).
//!
//! Derivation (ours; the printed matrix of the paper is partly garbled). Write each real
//! basis function as `y_i(s) = Q_i(z) · (1 − z²)^{|m|/2} · t_m(φ)` with `z = cos θ`, a
//! polynomial `Q_i`, and `t_m = sin(|m|φ)`, `1` or `cos(mφ)` for m < 0, = 0, > 0. The
//! hemispherical integral of eq. 2 then separates:
//!
//! `M^α[i][j] = ∫_{H²} z^α y_i y_j ds = [m_i = m_j] · Φ_m · ∫_0^1 z^α Q_i Q_j (1 − z²)^{|m|} dz`
//!
//! with `Φ_0 = 2π` and `Φ_m = π` otherwise (products of different `t_m` integrate to 0 over
//! φ). The z-integrand is `z^α` times a polynomial `Σ_k c_k z^k` of degree ≤ 6, so
//! `∫_0^1 = Σ_k c_k / (α + k + 1)`: a closed form for every real α ≥ 0, with 44 non-zero
//! entries (17.2 %), symmetric. The normalised operator of eq. 2 is `(α+1)/(2π) · M^α`;
//! α = 1 is the Lambertian (clamped cosine / π) convolution.

use crate::sh::{order_of, ShVec, COEFFS};

/// `c_k` of `K_i · Q_i(z)` (z-polynomial, lowest degree first) for every coefficient.
fn q_poly(i: usize) -> (f64, &'static [f64]) {
    let c = |num: f64, den: f64| (num / (den * std::f64::consts::PI)).sqrt();
    match i {
        0 => (c(1.0, 4.0), &[1.0]),
        1 | 3 => (c(3.0, 4.0), &[1.0]),
        2 => (c(3.0, 4.0), &[0.0, 1.0]),
        4 | 8 => (c(15.0, 16.0), &[1.0]),
        5 | 7 => (c(15.0, 4.0), &[0.0, 1.0]),
        6 => (c(5.0, 16.0), &[-1.0, 0.0, 3.0]),
        9 | 15 => (c(35.0, 32.0), &[1.0]),
        10 | 14 => (c(105.0, 16.0), &[0.0, 1.0]),
        11 | 13 => (c(21.0, 32.0), &[-1.0, 0.0, 5.0]),
        _ => (c(7.0, 16.0), &[0.0, -3.0, 0.0, 5.0]),
    }
}

/// Product of two polynomials (lowest degree first).
fn mul(a: &[f64], b: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; a.len() + b.len() - 1];
    for (i, x) in a.iter().enumerate() {
        for (j, y) in b.iter().enumerate() {
            out[i + j] += x * y;
        }
    }
    out
}

/// The paper's `M^α[i][j] = ∫_{H²} cos^α θ · y_i · y_j ds` (without the Phong normalisation).
pub fn hemisphere_entry(alpha: f64, i: usize, j: usize) -> f64 {
    let m = order_of(i);
    if m != order_of(j) {
        return 0.0;
    }
    let (ki, qi) = q_poly(i);
    let (kj, qj) = q_poly(j);
    let mut poly = mul(qi, qj);
    for _ in 0..m.unsigned_abs() {
        poly = mul(&poly, &[1.0, 0.0, -1.0]);
    }
    let phi = if m == 0 {
        2.0 * std::f64::consts::PI
    } else {
        std::f64::consts::PI
    };
    let z_integral: f64 = poly
        .iter()
        .enumerate()
        .map(|(k, c)| c / (alpha + k as f64 + 1.0))
        .sum();
    phi * ki * kj * z_integral
}

/// The normalised Phong operator `(α+1)/(2π) · M^α` for one exponent, stored sparsely.
#[derive(Clone, Debug, PartialEq)]
pub struct PhongOperator {
    /// The Phong exponent (1 = diffuse).
    pub alpha: f32,
    /// Non-zero entries (row, column, value).
    entries: Vec<(u8, u8, f32)>,
}

impl PhongOperator {
    /// The operator for exponent `alpha` (≥ 0; finite).
    pub fn new(alpha: f32) -> Self {
        let a = alpha as f64;
        let norm = (a + 1.0) / (2.0 * std::f64::consts::PI);
        let mut entries = Vec::with_capacity(44);
        for i in 0..COEFFS {
            for j in 0..COEFFS {
                let v = hemisphere_entry(a, i, j);
                if order_of(i) == order_of(j) {
                    entries.push((i as u8, j as u8, (norm * v) as f32));
                }
            }
        }
        Self { alpha, entries }
    }

    /// The diffuse (α = 1) operator: `(1/π) ∫_{H²} cos θ · f`.
    pub fn diffuse() -> Self {
        Self::new(1.0)
    }

    /// Number of stored (structurally non-zero) entries.
    pub fn nonzeros(&self) -> usize {
        self.entries.len()
    }

    /// Entry (i, j) of the normalised operator.
    pub fn entry(&self, i: usize, j: usize) -> f32 {
        self.entries
            .iter()
            .find(|e| e.0 as usize == i && e.1 as usize == j)
            .map_or(0.0, |e| e.2)
    }

    /// `t = N · v`: the visibility (in a frame whose z is the BRDF axis) convolved with the
    /// normalised Phong kernel.
    #[inline]
    pub fn apply(&self, v: &ShVec) -> ShVec {
        let mut out = [0.0; COEFFS];
        for &(i, j, m) in &self.entries {
            out[i as usize] += m * v[j as usize];
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::quadrature::SphereQuadrature;
    use crate::sh;

    /// Eq. 2 by numerical integration: Gauss–Legendre in cos θ over the upper hemisphere
    /// times equally spaced φ, on the Cartesian basis formulas (not the factored form the
    /// operator uses). For integer α the integrand is a polynomial of degree ≤ α + 6 in z
    /// times trigonometric terms of degree ≤ 6 in φ, which 64 nodes in z (exact to degree
    /// 127) and 128 in φ integrate exactly: the only error left is f64 rounding, so the
    /// tolerance is 1e-9 relative to the largest entry (the f32 storage of the operator is
    /// checked separately at 1e-6).
    #[test]
    fn operator_matches_numerical_integration_of_eq_2() {
        let q = SphereQuadrature::upper_hemisphere(64);
        for alpha in [1.0, 2.0, 8.0, 32.0, 100.0] {
            let mut numeric = [[0.0f64; COEFFS]; COEFFS];
            for &(d, w) in &q.nodes {
                let y = sh::eval_f64(d);
                let k = w * d.z.powf(alpha);
                for (row, yi) in numeric.iter_mut().zip(y) {
                    for (cell, yj) in row.iter_mut().zip(y) {
                        *cell += k * yi * yj;
                    }
                }
            }
            let scale = numeric.iter().flatten().fold(0.0f64, |a, b| a.max(b.abs()));
            let op = PhongOperator::new(alpha as f32);
            let norm = (alpha + 1.0) / (2.0 * std::f64::consts::PI);
            for (i, row) in numeric.iter().enumerate() {
                for (j, &num) in row.iter().enumerate() {
                    let exact = hemisphere_entry(alpha, i, j);
                    assert!(
                        (exact - num).abs() < 1e-9 * scale,
                        "α={alpha} M[{i}][{j}] = {exact} vs numeric {num}"
                    );
                    let stored = op.entry(i, j) as f64;
                    assert!((stored - norm * exact).abs() < 1e-6 * (norm * scale).max(1.0));
                }
            }
        }
    }

    #[test]
    fn operator_is_sparse_and_symmetric() {
        let op = PhongOperator::new(7.5);
        assert_eq!(op.nonzeros(), 44);
        for i in 0..COEFFS {
            for j in 0..COEFFS {
                assert_eq!(op.entry(i, j), op.entry(j, i));
            }
        }
    }

    #[test]
    fn entries_match_the_legible_closed_forms_of_appendix_a() {
        // The entries printed legibly in the paper: M00 = 1/(2(α+1)),
        // M(0,2) = √3/(2(α+2)), M(1,1) = 1.5/((α+1)(α+3)), M(2,2) = 1.5/(α+3).
        for alpha in [1.0f64, 4.0, 20.0] {
            let cases = [
                (0, 0, 0.5 / (alpha + 1.0)),
                (0, 2, 3f64.sqrt() / (2.0 * (alpha + 2.0))),
                (1, 1, 1.5 / ((alpha + 1.0) * (alpha + 3.0))),
                (2, 2, 1.5 / (alpha + 3.0)),
            ];
            for (i, j, expect) in cases {
                let got = hemisphere_entry(alpha, i, j);
                assert!(
                    (got - expect).abs() < 1e-12,
                    "α={alpha} ({i},{j}): {got} vs {expect}"
                );
            }
        }
    }

    #[test]
    fn diffuse_operator_on_full_visibility_gives_the_clamped_cosine() {
        // v = 1 everywhere (c0 = 2√π): N¹ v = projection of max(0, z)/π.
        let mut v = [0.0; COEFFS];
        v[0] = 2.0 * std::f32::consts::PI.sqrt();
        let t = PhongOperator::diffuse().apply(&v);
        let pi = std::f32::consts::PI;
        let expect = [
            (0, pi.sqrt() / 2.0 / pi),
            (2, (pi / 3.0).sqrt() / pi),
            (6, (5.0 * pi).sqrt() / 8.0 / pi),
            (12, 0.0),
        ];
        for (i, e) in expect {
            assert!((t[i] - e).abs() < 1e-6, "t{i} = {} vs {e}", t[i]);
        }
        // Irradiance/π of a constant unit sky over the hemisphere is 1: t · (unit light) = 1.
        assert!((sh::dot(&t, &v) - 1.0).abs() < 1e-5);
    }
}
