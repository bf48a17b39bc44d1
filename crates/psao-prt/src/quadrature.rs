//! Projection of spherical functions onto SH by quadrature.
//!
//! A product rule: Gauss–Legendre in `z = cos θ` times equally spaced φ. With `n` nodes in z
//! and `2n` in φ it integrates every polynomial of degree < 2n in (x, y, z) exactly, so a
//! band-limited product such as `y_i · y_j` (degree ≤ 6) is exact from n = 4 on.
//! Written here because the nodes are a dozen lines of Newton iteration, not worth a crate.

use glam::DVec3;
use std::f64::consts::PI;

use crate::sh::{self, COEFFS};

/// Gauss–Legendre nodes and weights on [a, b] with `n` points (Newton on P_n, f64).
pub fn gauss_legendre(n: usize, a: f64, b: f64) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        // Chebyshev-like start, then Newton on P_n.
        let mut x = (PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        let mut dp = 1.0;
        for _ in 0..100 {
            let (mut p0, mut p1) = (1.0, x);
            for k in 2..=n {
                let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                p0 = p1;
                p1 = p2;
            }
            let pn = if n == 0 { 1.0 } else { p1 };
            let pn1 = if n == 0 { 0.0 } else { p0 };
            dp = n as f64 * (x * pn - pn1) / (x * x - 1.0);
            let dx = pn / dp;
            x -= dx;
            if dx.abs() < 1e-15 {
                break;
            }
        }
        let w = 2.0 / ((1.0 - x * x) * dp * dp);
        out.push((0.5 * (b - a) * x + 0.5 * (b + a), 0.5 * (b - a) * w));
    }
    out
}

/// Directions and weights of a product quadrature over a band of the sphere.
#[derive(Clone, Debug)]
pub struct SphereQuadrature {
    /// Unit directions with their solid-angle weights.
    pub nodes: Vec<(DVec3, f64)>,
}

impl SphereQuadrature {
    /// Rule over the whole sphere: `n` Gauss–Legendre nodes in z, `2n` angles in φ.
    pub fn sphere(n: usize) -> Self {
        Self::zone(n, -1.0, 1.0)
    }

    /// Rule over the upper hemisphere (z ≥ 0).
    pub fn upper_hemisphere(n: usize) -> Self {
        Self::zone(n, 0.0, 1.0)
    }

    /// Rule over the zone z ∈ [z0, z1].
    fn zone(n: usize, z0: f64, z1: f64) -> Self {
        let phis = 2 * n;
        let dphi = 2.0 * PI / phis as f64;
        let mut nodes = Vec::with_capacity(n * phis);
        for (z, w) in gauss_legendre(n, z0, z1) {
            let r = (1.0 - z * z).max(0.0).sqrt();
            for k in 0..phis {
                let phi = (k as f64 + 0.5) * dphi;
                nodes.push((DVec3::new(r * phi.cos(), r * phi.sin(), z), w * dphi));
            }
        }
        Self { nodes }
    }

    /// The integral of `f` under this rule.
    pub fn integrate(&self, f: impl Fn(DVec3) -> f64) -> f64 {
        self.nodes.iter().map(|&(d, w)| w * f(d)).sum()
    }

    /// SH coefficients of `f`: ∫ f(s) y_i(s) ds under this rule.
    pub fn project(&self, f: impl Fn(DVec3) -> f64) -> [f64; COEFFS] {
        let mut out = [0.0; COEFFS];
        for &(d, w) in &self.nodes {
            let v = w * f(d);
            if v != 0.0 {
                for (o, y) in out.iter_mut().zip(sh::eval_f64(d)) {
                    *o += v * y;
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gauss_legendre_is_exact_for_polynomials() {
        let rule = gauss_legendre(5, 0.0, 1.0);
        for k in 0..10 {
            let s: f64 = rule.iter().map(|(x, w)| w * x.powi(k)).sum();
            assert!((s - 1.0 / (k as f64 + 1.0)).abs() < 1e-13, "x^{k}");
        }
    }

    #[test]
    fn basis_is_orthonormal_under_the_rule() {
        let q = SphereQuadrature::sphere(6);
        for i in 0..COEFFS {
            let row = q.project(|d| sh::eval_f64(d)[i]);
            for (j, v) in row.iter().enumerate() {
                let expect = if i == j { 1.0 } else { 0.0 };
                assert!((v - expect).abs() < 1e-12, "<y{i}, y{j}> = {v}");
            }
        }
    }

    #[test]
    fn constant_projects_to_band_zero() {
        // f = 1: c_0 = 2√π, everything else 0.
        let c = SphereQuadrature::sphere(8).project(|_| 1.0);
        assert!((c[0] - 2.0 * PI.sqrt()).abs() < 1e-12);
        assert!(c[1..].iter().all(|v| v.abs() < 1e-12));
    }

    #[test]
    fn clamped_cosine_projects_to_its_closed_form() {
        // max(0, z): zonal, c_{l0} = 2π ∫_0^1 z · y_l0(z) dz:
        // l=0: √π/2, l=1: √(π/3), l=2: √(5π)/8, l=3: 0.
        let c = SphereQuadrature::upper_hemisphere(16).project(|d| d.z);
        let expect = [
            (0, PI.sqrt() / 2.0),
            (2, (PI / 3.0).sqrt()),
            (6, (5.0 * PI).sqrt() / 8.0),
            (12, 0.0),
        ];
        for (i, e) in expect {
            assert!((c[i] - e).abs() < 1e-12, "c{i} = {} vs {e}", c[i]);
        }
        for (i, v) in c.iter().enumerate() {
            if ![0, 2, 6, 12].contains(&i) {
                assert!(v.abs() < 1e-12, "c{i} = {v}");
            }
        }
    }
}
