//! Zonal-harmonic lobes: a function symmetric about an axis, four coefficients (one per band).
//!
//! A lobe with axis `s` and zonal coefficients `z_l` (its SH coefficients `v_l0` when `s` is
//! +z) has SH coefficients `v_lm = sqrt(4π / (2l+1)) · z_l · y_lm(s)` (paper eq. 1): the
//! rotation of a zonal function is a scaled evaluation of the basis at its axis.

use glam::Vec3;

use crate::sh::{self, ShVec, BANDS, COEFFS};

/// `sqrt(4π / (2l+1))` per band.
pub const ZH_SCALE: [f32; BANDS] = [3.544_907_7, 2.046_653_4, 1.585_330_9, 1.339_849_2];

/// One zonal lobe.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ZhLobe {
    /// Unit axis of symmetry.
    pub axis: Vec3,
    /// Zonal coefficients, bands 0..3.
    pub coeffs: [f32; BANDS],
}

impl ZhLobe {
    /// The lobe's SH vector (eq. 1).
    pub fn to_sh(&self) -> ShVec {
        let mut out = [0.0; COEFFS];
        self.add_to(&mut out);
        out
    }

    /// Adds the lobe's SH vector to `out`.
    #[inline]
    pub fn add_to(&self, out: &mut ShVec) {
        let y = sh::eval(self.axis);
        let scale: [f32; BANDS] = std::array::from_fn(|l| ZH_SCALE[l] * self.coeffs[l]);
        for (i, (o, y)) in out.iter_mut().zip(y).enumerate() {
            *o += scale[sh::band_of(i)] * y;
        }
    }
}

/// The SH vector of a sum of lobes.
pub fn lobes_to_sh(lobes: &[ZhLobe]) -> ShVec {
    let mut out = [0.0; COEFFS];
    for lobe in lobes {
        lobe.add_to(&mut out);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scale_constants_are_right() {
        for (l, s) in ZH_SCALE.iter().enumerate() {
            let exact = (4.0 * std::f64::consts::PI / (2 * l + 1) as f64).sqrt();
            assert!((*s as f64 - exact).abs() < 1e-6);
        }
    }

    #[test]
    fn lobe_on_z_has_only_zonal_coefficients() {
        let v = ZhLobe {
            axis: Vec3::Z,
            coeffs: [1.0, 2.0, 3.0, 4.0],
        }
        .to_sh();
        for (i, c) in v.iter().enumerate() {
            let expect = match i {
                0 => 1.0,
                2 => 2.0,
                6 => 3.0,
                12 => 4.0,
                _ => 0.0,
            };
            assert!((c - expect).abs() < 1e-5, "coefficient {i}: {c}");
        }
    }
}
