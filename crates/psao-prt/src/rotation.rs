//! Rotation of order-4 SH vectors by any 3-D rotation.
//!
//! Method: rotations keep each band's space, and a band-l function is fixed by its values at
//! any 2l+1 directions where the band's basis is independent. With a fixed set of
//! [`SAMPLES`] directions `p_k` and the band's precomputed pseudo-inverse `P_l` of
//! `Y_l[k][m] = y_lm(p_k)`, the rotated function `g(s) = f(Rᵀs)` has band coefficients
//! `c'_l = P_l · Y_l(Rᵀp) · c_l`: evaluating the basis at the [`SAMPLES`] rotated directions
//! is all a rotation costs, and the result is exact (up to rounding) for any rotation, with
//! no Euler-angle singularities. (This replaces the Ivanic–Ruedenberg recurrence: same
//! result, a third of the code, and no sign-convention pitfalls between real bases.)

use std::sync::OnceLock;

use glam::{DVec3, Mat3, Vec3};

use crate::sh::{self, ShVec, BANDS, COEFFS};
use crate::small::pseudo_inverse;

/// Number of fixed sample directions (more than 2·3+1 = 7 for good conditioning).
pub const SAMPLES: usize = 10;

/// Per band: the pseudo-inverse (2l+1)×SAMPLES, row-major.
struct Tables {
    dirs: [Vec3; SAMPLES],
    pinv: [Vec<f32>; BANDS],
}

fn tables() -> &'static Tables {
    static T: OnceLock<Tables> = OnceLock::new();
    T.get_or_init(|| {
        // Spherical Fibonacci directions: spread out and not antipodally symmetric.
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        let dirs64: Vec<DVec3> = (0..SAMPLES)
            .map(|k| {
                let z = 1.0 - (2.0 * k as f64 + 1.0) / SAMPLES as f64;
                let r = (1.0 - z * z).sqrt();
                let phi = golden * k as f64;
                DVec3::new(r * phi.cos(), r * phi.sin(), z)
            })
            .collect();
        let values: Vec<[f64; COEFFS]> = dirs64.iter().map(|&d| sh::eval_f64(d)).collect();
        let pinv = std::array::from_fn(|l| {
            let width = 2 * l + 1;
            let first = l * l;
            let y: Vec<f64> = values
                .iter()
                .flat_map(|v| v[first..first + width].iter().copied())
                .collect();
            pseudo_inverse(&y, SAMPLES, width)
                .expect("the fixed sample directions span every band")
                .into_iter()
                .map(|x| x as f32)
                .collect()
        });
        Tables {
            dirs: std::array::from_fn(|k| dirs64[k].as_vec3()),
            pinv,
        }
    })
}

/// A rotation prepared for applying to SH vectors: the basis at the rotated sample directions.
#[derive(Clone, Debug)]
pub struct ShRotation {
    rotated: [ShVec; SAMPLES],
}

impl ShRotation {
    /// Prepares rotation by `r` (a proper rotation matrix): [`Self::apply`] maps the
    /// coefficients of `f` to those of `s ↦ f(rᵀ s)`, so a lobe around `a` ends up around `r·a`.
    pub fn new(r: Mat3) -> Self {
        let t = tables();
        let inv = r.transpose();
        Self {
            rotated: std::array::from_fn(|k| sh::eval(inv * t.dirs[k])),
        }
    }

    /// The rotated coefficients of `v`.
    pub fn apply(&self, v: &ShVec) -> ShVec {
        let t = tables();
        let mut out = [0.0; COEFFS];
        out[0] = v[0];
        for l in 1..BANDS {
            let first = l * l;
            let width = 2 * l + 1;
            let mut samples = [0.0f32; SAMPLES];
            for (s, y) in samples.iter_mut().zip(&self.rotated) {
                *s = (0..width).map(|m| y[first + m] * v[first + m]).sum();
            }
            let p = &t.pinv[l];
            for m in 0..width {
                out[first + m] = (0..SAMPLES).map(|k| p[m * SAMPLES + k] * samples[k]).sum();
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::zonal::ZhLobe;
    use glam::Quat;

    fn sample_vec(seed: u32) -> ShVec {
        std::array::from_fn(|i| (((i as u32 * 7919 + seed * 104_729) % 1000) as f32 / 500.0) - 1.0)
    }

    fn rotations() -> Vec<Mat3> {
        vec![
            Mat3::from_quat(Quat::from_axis_angle(
                Vec3::new(1.0, 2.0, 3.0).normalize(),
                0.7,
            )),
            Mat3::from_quat(Quat::from_axis_angle(Vec3::X, std::f32::consts::PI)),
            Mat3::from_quat(Quat::from_euler(glam::EulerRot::ZYX, 2.0, -1.1, 0.4)),
        ]
    }

    #[test]
    fn rotation_then_inverse_is_identity() {
        for r in rotations() {
            let v = sample_vec(3);
            let back = ShRotation::new(r.transpose()).apply(&ShRotation::new(r).apply(&v));
            for i in 0..COEFFS {
                assert!(
                    (back[i] - v[i]).abs() < 1e-4,
                    "coefficient {i}: {} vs {}",
                    back[i],
                    v[i]
                );
            }
        }
    }

    #[test]
    fn rotation_keeps_band_energy() {
        for r in rotations() {
            let v = sample_vec(5);
            let e0 = sh::band_energy(&v);
            let e1 = sh::band_energy(&ShRotation::new(r).apply(&v));
            for l in 0..BANDS {
                assert!((e0[l] - e1[l]).abs() < 1e-4 * e0[l].max(1.0), "band {l}");
            }
        }
    }

    #[test]
    fn rotated_function_values_follow_the_rotation() {
        // g(s) = f(rᵀ s) at arbitrary directions.
        let v = sample_vec(11);
        for r in rotations() {
            let g = ShRotation::new(r).apply(&v);
            for d in [Vec3::new(0.2, 0.9, -0.3), Vec3::new(-0.6, -0.1, 0.7)] {
                let d = d.normalize();
                let a = sh::value(&g, d);
                let b = sh::value(&v, r.transpose() * d);
                assert!((a - b).abs() < 1e-4, "{a} vs {b}");
            }
        }
    }

    #[test]
    fn rotating_a_lobe_axis_equals_rotating_its_expansion() {
        let lobe = ZhLobe {
            axis: Vec3::new(0.3, -0.4, 0.866).normalize(),
            coeffs: [0.9, 0.6, -0.3, 0.2],
        };
        for r in rotations() {
            let a = ShRotation::new(r).apply(&lobe.to_sh());
            let b = ZhLobe {
                axis: r * lobe.axis,
                ..lobe
            }
            .to_sh();
            for i in 0..COEFFS {
                assert!((a[i] - b[i]).abs() < 1e-4, "coefficient {i}");
            }
        }
    }
}
