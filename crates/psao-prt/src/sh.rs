//! Real spherical harmonics of order 4 (bands l = 0..3, 16 coefficients).
//!
//! Convention: index `i = l² + l + m` for `m = -l..=l`; the real basis without the
//! Condon–Shortley phase, so that band 1 is `(y, z, x)` times a positive constant:
//! `y_{l,m} = K · P(z) · sin(|m|φ)` for `m < 0`, `K · P(z)` for `m = 0` and `K · P(z) · cos(mφ)`
//! for `m > 0` (φ measured from +x towards +y), orthonormal over the unit sphere.

use glam::{DVec3, Vec3};

/// Number of bands (SH order).
pub const BANDS: usize = 4;
/// Number of coefficients of an order-4 SH vector.
pub const COEFFS: usize = BANDS * BANDS;

/// An order-4 SH coefficient vector.
pub type ShVec = [f32; COEFFS];

/// Index of coefficient (l, m) in an SH vector.
pub const fn index(l: usize, m: i32) -> usize {
    (l * l + l) as i32 as usize + m as usize
}

/// Band of coefficient `i`.
pub const fn band_of(i: usize) -> usize {
    match i {
        0 => 0,
        1..=3 => 1,
        4..=8 => 2,
        _ => 3,
    }
}

/// Order `m` of coefficient `i` (−l..=l).
pub const fn order_of(i: usize) -> i32 {
    let l = band_of(i);
    i as i32 - (l * l + l) as i32
}

/// The normalisation constants written as `sqrt(num / (den · π))`, per coefficient, of the
/// Cartesian polynomials in [`eval_f64`].
mod k {
    use std::f64::consts::PI;
    pub fn c(num: f64, den: f64) -> f64 {
        (num / (den * PI)).sqrt()
    }
}

/// All 16 basis functions at the unit direction `d` (double precision).
pub fn eval_f64(d: DVec3) -> [f64; COEFFS] {
    let (x, y, z) = (d.x, d.y, d.z);
    let c = k::c;
    [
        c(1.0, 4.0),
        c(3.0, 4.0) * y,
        c(3.0, 4.0) * z,
        c(3.0, 4.0) * x,
        c(15.0, 4.0) * x * y,
        c(15.0, 4.0) * y * z,
        c(5.0, 16.0) * (3.0 * z * z - 1.0),
        c(15.0, 4.0) * x * z,
        c(15.0, 16.0) * (x * x - y * y),
        c(35.0, 32.0) * y * (3.0 * x * x - y * y),
        c(105.0, 4.0) * x * y * z,
        c(21.0, 32.0) * y * (5.0 * z * z - 1.0),
        c(7.0, 16.0) * z * (5.0 * z * z - 3.0),
        c(21.0, 32.0) * x * (5.0 * z * z - 1.0),
        c(105.0, 16.0) * z * (x * x - y * y),
        c(35.0, 32.0) * x * (x * x - 3.0 * y * y),
    ]
}

/// Single-precision constants of [`eval`], equal to those of [`eval_f64`].
const C0: f32 = 0.282_094_8;
const C1: f32 = 0.488_602_5;
const C2A: f32 = 1.092_548_4;
const C2B: f32 = 0.315_391_57;
const C2C: f32 = 0.546_274_2;
const C3A: f32 = 0.590_043_6;
const C3B: f32 = 2.890_611_4;
const C3C: f32 = 0.457_045_8;
const C3D: f32 = 0.373_176_33;
const C3E: f32 = 1.445_305_7;

/// All 16 basis functions at the unit direction `d` (single precision, the run-time path).
#[inline]
pub fn eval(d: Vec3) -> ShVec {
    let (x, y, z) = (d.x, d.y, d.z);
    let (z2, x2, y2) = (z * z, x * x, y * y);
    [
        C0,
        C1 * y,
        C1 * z,
        C1 * x,
        C2A * x * y,
        C2A * y * z,
        C2B * (3.0 * z2 - 1.0),
        C2A * x * z,
        C2C * (x2 - y2),
        C3A * y * (3.0 * x2 - y2),
        C3B * x * y * z,
        C3C * y * (5.0 * z2 - 1.0),
        C3D * z * (5.0 * z2 - 3.0),
        C3C * x * (5.0 * z2 - 1.0),
        C3E * z * (x2 - y2),
        C3A * x * (x2 - 3.0 * y2),
    ]
}

/// Dot product of two SH vectors (the integral of the product of the two functions).
#[inline]
pub fn dot(a: &ShVec, b: &ShVec) -> f32 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Value of the function with coefficients `v` in direction `d`.
pub fn value(v: &ShVec, d: Vec3) -> f32 {
    dot(v, &eval(d))
}

/// Energy of each band (sum of squared coefficients), kept by rotations.
pub fn band_energy(v: &ShVec) -> [f32; BANDS] {
    let mut e = [0.0; BANDS];
    for (i, c) in v.iter().enumerate() {
        e[band_of(i)] += c * c;
    }
    e
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn single_precision_basis_matches_double() {
        for d in [
            Vec3::new(0.3, -0.5, 0.81),
            Vec3::new(-0.9, 0.1, -0.2),
            Vec3::Z,
        ] {
            let d = d.normalize();
            let a = eval(d);
            let b = eval_f64(d.as_dvec3());
            for i in 0..COEFFS {
                assert!((a[i] as f64 - b[i]).abs() < 1e-6, "coefficient {i}");
            }
        }
    }

    #[test]
    fn indices_round_trip() {
        for l in 0..BANDS {
            for m in -(l as i32)..=(l as i32) {
                let i = index(l, m);
                assert_eq!((band_of(i), order_of(i)), (l, m));
            }
        }
    }
}
