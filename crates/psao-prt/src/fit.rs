//! Fitting c zonal lobes to an SH vector (least-squares in L2 over the sphere).
//!
//! For fixed axes the zonal coefficients are linear least squares; bands are orthogonal, so
//! it splits into one c×c system per band. Band 0 is the same for every axis, so those
//! systems are singular for c > 1: a small ridge picks the minimum-norm solution (the band-0
//! value shared evenly), which also keeps the coefficients from blowing up when two axes
//! come close. The axes are refined by Levenberg–Marquardt on the residual with the
//! coefficients re-solved at every step (variable projection), each axis moving in its own
//! tangent plane. Starts are deterministic: the first lobe along the band-1 direction, each
//! further lobe at the direction (of a fixed spherical-Fibonacci set) where the residual
//! function is largest in magnitude; or the previous frame's axes ([`fit_sequence`]), which
//! keeps lobes in correspondence from frame to frame.

use glam::{DVec3, Vec3};
use psao_trace::ao::orthonormal_basis;

use crate::sh::{self, ShVec, BANDS, COEFFS};
use crate::small::solve_spd;
use crate::zonal::{ZhLobe, ZH_SCALE};

/// Ridge on each band's normal equations, relative to their mean diagonal. Two lobes whose
/// axes are δ apart span, in band l, a difference mode whose Gram eigenvalue is about
/// `l(l+1)δ²/4` of the diagonal; a ridge λ damps that mode below `δ ≈ 2√(λ/(l(l+1)))`
/// (0.14 rad in band 1 for λ = 10⁻²), so close lobes cannot form a "dipole" of large opposite
/// coefficients, whose sum a tiny axis error changes a lot: the linear pose model predicts
/// each lobe separately and could not follow it. With 10⁻⁴ such pairs carried most of the
/// 2-lobe model's error on the shared characters (docs/RELIGHTING.md).
const RIDGE: f64 = 1e-2;
/// Levenberg–Marquardt iterations at most.
const ITERATIONS: usize = 25;
/// Finite-difference step (radians) for the Jacobian.
const STEP: f64 = 1e-5;
/// Weight of the pull towards the previous frame's axes, relative to the target's squared
/// norm: lobes whose axis barely changes the fit (weak lobes) stay put instead of wandering,
/// which a linear pose model could not follow.
const SMOOTHNESS: f64 = 1e-3;
/// Candidate start directions for added lobes.
const CANDIDATES: usize = 64;

/// Coefficients for fixed `axes` and the squared residual norm.
fn solve_coefficients(
    target: &[f64; COEFFS],
    axes: &[DVec3],
) -> (Vec<[f64; BANDS]>, [f64; COEFFS]) {
    let c = axes.len();
    let ys: Vec<[f64; COEFFS]> = axes.iter().map(|&a| sh::eval_f64(a)).collect();
    let mut coeffs = vec![[0.0; BANDS]; c];
    let mut residual = *target;
    for l in 0..BANDS {
        let (first, width) = (l * l, 2 * l + 1);
        let s = ZH_SCALE[l] as f64;
        let col = |x: usize, m: usize| s * ys[x][first + m];
        let mut gram = vec![0.0; c * c];
        let mut rhs = vec![0.0; c];
        for i in 0..c {
            for j in 0..c {
                gram[i * c + j] = (0..width).map(|m| col(i, m) * col(j, m)).sum();
            }
            rhs[i] = (0..width).map(|m| col(i, m) * target[first + m]).sum();
        }
        let trace: f64 = (0..c).map(|i| gram[i * c + i]).sum::<f64>() / c as f64;
        // One lobe has nothing to pair with: no ridge, no shrinkage.
        let ridge = if c > 1 { RIDGE * trace } else { 0.0 };
        if solve_spd(&mut gram, &mut rhs, c, ridge + 1e-12).is_none() {
            continue;
        }
        for (x, z) in rhs.iter().enumerate() {
            coeffs[x][l] = *z;
            for m in 0..width {
                residual[first + m] -= z * col(x, m);
            }
        }
    }
    (coeffs, residual)
}

fn norm2(r: &[f64; COEFFS]) -> f64 {
    r.iter().map(|x| x * x).sum()
}

/// Axes moved by tangent-plane offsets `delta` (two per axis).
fn moved(axes: &[DVec3], delta: &[f64]) -> Vec<DVec3> {
    axes.iter()
        .enumerate()
        .map(|(x, &a)| {
            let (t, b) = tangents(a);
            (a + t * delta[2 * x] + b * delta[2 * x + 1]).normalize()
        })
        .collect()
}

fn tangents(a: DVec3) -> (DVec3, DVec3) {
    let (t, b) = orthonormal_basis(a.as_vec3());
    (t.as_dvec3(), b.as_dvec3())
}

/// The residual minimised by [`refine`]: the SH residual for `axes`, then, with a `prior`,
/// `√w · (axis − prior axis)` per lobe.
fn residual(target: &[f64; COEFFS], axes: &[DVec3], prior: Option<(&[DVec3], f64)>) -> Vec<f64> {
    let (_, r) = solve_coefficients(target, axes);
    let mut out = r.to_vec();
    if let Some((p, w)) = prior {
        let s = w.sqrt();
        for (a, b) in axes.iter().zip(p) {
            out.extend_from_slice(&((*a - *b) * s).to_array());
        }
    }
    out
}

fn sum_sq(r: &[f64]) -> f64 {
    r.iter().map(|x| x * x).sum()
}

/// Levenberg–Marquardt refinement of `axes` (variable projection), optionally pulled
/// towards `prior` axes with weight `w`.
fn refine(target: &[f64; COEFFS], axes: &mut Vec<DVec3>, prior: Option<(&[DVec3], f64)>) {
    let p = 2 * axes.len();
    let mut r = residual(target, axes, prior);
    let n = r.len();
    let mut err = sum_sq(&r);
    let mut mu = 1e-3;
    for _ in 0..ITERATIONS {
        // Jacobian of the residual by forward differences.
        let mut jac = vec![vec![0.0f64; n]; p];
        for (k, col) in jac.iter_mut().enumerate() {
            let mut d = vec![0.0; p];
            d[k] = STEP;
            let rk = residual(target, &moved(axes, &d), prior);
            for i in 0..n {
                col[i] = (rk[i] - r[i]) / STEP;
            }
        }
        let mut improved = false;
        for _ in 0..8 {
            let mut jtj = vec![0.0; p * p];
            let mut g = vec![0.0; p];
            for a in 0..p {
                for b in 0..p {
                    jtj[a * p + b] = (0..n).map(|i| jac[a][i] * jac[b][i]).sum();
                }
                jtj[a * p + a] *= 1.0 + mu;
                g[a] = -(0..n).map(|i| jac[a][i] * r[i]).sum::<f64>();
            }
            if solve_spd(&mut jtj, &mut g, p, 1e-12).is_none() {
                mu *= 10.0;
                continue;
            }
            let trial = moved(axes, &g);
            let rt = residual(target, &trial, prior);
            let et = sum_sq(&rt);
            if et < err {
                let gain = err - et;
                *axes = trial;
                r = rt;
                err = et;
                mu = (mu * 0.3).max(1e-9);
                improved = gain > 1e-12 * (1.0 + err);
                break;
            }
            mu *= 10.0;
        }
        if !improved {
            break;
        }
    }
}

/// Start axes for `lobes` lobes on `target`, greedily.
fn initial_axes(target: &[f64; COEFFS], lobes: usize) -> Vec<DVec3> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let candidates: Vec<DVec3> = (0..CANDIDATES)
        .map(|k| {
            let z = 1.0 - (2.0 * k as f64 + 1.0) / CANDIDATES as f64;
            let r = (1.0 - z * z).sqrt();
            DVec3::new(
                r * (golden * k as f64).cos(),
                r * (golden * k as f64).sin(),
                z,
            )
        })
        .collect();
    let band1 = DVec3::new(target[3], target[1], target[2]);
    let mut axes = vec![band1.try_normalize().unwrap_or(DVec3::Z)];
    refine(target, &mut axes, None);
    while axes.len() < lobes {
        let (_, r) = solve_coefficients(target, &axes);
        let value = |d: DVec3| -> f64 {
            sh::eval_f64(d)
                .iter()
                .zip(&r)
                .map(|(y, c)| y * c)
                .sum::<f64>()
                .abs()
        };
        let best = candidates
            .iter()
            .copied()
            .fold((DVec3::Z, -1.0), |(bd, bv), d| {
                let v = value(d);
                if v > bv {
                    (d, v)
                } else {
                    (bd, bv)
                }
            })
            .0;
        axes.push(best);
        refine(target, &mut axes, None);
    }
    axes
}

/// The fitted lobes for `target` from `start` axes (refined), or from the greedy start when
/// `start` is `None`. Returns the lobes and the L2 error over the sphere.
pub fn fit_lobes(target: &ShVec, lobes: usize, start: Option<&[Vec3]>) -> (Vec<ZhLobe>, f32) {
    let t: [f64; COEFFS] = target.map(f64::from);
    let axes = match start {
        Some(s) if s.len() == lobes => {
            let prior: Vec<DVec3> = s
                .iter()
                .map(|a| a.as_dvec3().try_normalize().unwrap_or(DVec3::Z))
                .collect();
            let mut axes = prior.clone();
            refine(&t, &mut axes, Some((&prior, SMOOTHNESS * norm2(&t))));
            axes
        }
        _ => initial_axes(&t, lobes),
    };
    let (coeffs, residual) = solve_coefficients(&t, &axes);
    let out = axes
        .iter()
        .zip(&coeffs)
        .map(|(a, c)| ZhLobe {
            axis: a.as_vec3(),
            coeffs: c.map(|x| x as f32),
        })
        .collect();
    (out, norm2(&residual).sqrt() as f32)
}

/// Fits `lobes` lobes to each vector of a time-ordered sequence (one vertex over training
/// frames), each frame starting from the previous frame's axes so lobes stay in
/// correspondence. Returns per frame the lobes and the L2 error.
pub fn fit_sequence(targets: &[ShVec], lobes: usize) -> Vec<(Vec<ZhLobe>, f32)> {
    let mut out: Vec<(Vec<ZhLobe>, f32)> = Vec::with_capacity(targets.len());
    for t in targets {
        let start: Option<Vec<Vec3>> = out.last().map(|(l, _)| l.iter().map(|l| l.axis).collect());
        out.push(fit_lobes(t, lobes, start.as_deref()));
    }
    out
}

/// RMS over the sphere of the difference of two SH functions: `‖a − b‖ / √(4π)`.
pub fn rms_difference(a: &ShVec, b: &ShVec) -> f32 {
    let d: f32 = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum();
    (d / (4.0 * std::f32::consts::PI)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::zonal::lobes_to_sh;

    #[test]
    fn one_lobe_recovers_a_zonal_function() {
        let lobe = ZhLobe {
            axis: Vec3::new(0.4, -0.2, 0.9).normalize(),
            coeffs: [1.5, 1.0, 0.4, 0.1],
        };
        let (fit, err) = fit_lobes(&lobe.to_sh(), 1, None);
        assert!(err < 1e-3, "error {err}");
        assert!(fit[0].axis.dot(lobe.axis).abs() > 0.999);
    }

    #[test]
    fn two_lobes_recover_a_two_lobe_function_better_than_one() {
        let truth = [
            ZhLobe {
                axis: Vec3::new(0.0, 0.3, 1.0).normalize(),
                coeffs: [1.2, 0.9, 0.4, 0.1],
            },
            ZhLobe {
                axis: Vec3::new(1.0, -0.5, -0.2).normalize(),
                coeffs: [0.5, 0.6, 0.5, 0.3],
            },
        ];
        let v = lobes_to_sh(&truth);
        let (_, e1) = fit_lobes(&v, 1, None);
        let (_, e2) = fit_lobes(&v, 2, None);
        assert!(e2 < 0.05 * e1, "one lobe {e1}, two lobes {e2}");
    }

    /// Two lobes whose axes drift with `t`.
    fn two_drifting_lobes(t: f32) -> ShVec {
        lobes_to_sh(&[
            ZhLobe {
                axis: Vec3::new(t, 0.2, 1.0).normalize(),
                coeffs: [1.0, 0.8, 0.3, 0.1],
            },
            ZhLobe {
                axis: Vec3::new(-1.0, t, 0.1).normalize(),
                coeffs: [0.6, 0.5, 0.4, 0.2],
            },
        ])
    }

    #[test]
    fn sequences_keep_lobes_in_correspondence() {
        // Two lobes drifting slowly: each fitted lobe follows its own.
        let frames: Vec<ShVec> = (0..10)
            .map(|f| two_drifting_lobes(f as f32 * 0.05))
            .collect();
        let fits = fit_sequence(&frames, 2);
        for w in fits.windows(2) {
            for k in 0..2 {
                assert!(w[0].0[k].axis.dot(w[1].0[k].axis) > 0.99, "lobe {k} jumped");
            }
        }
        assert!(fits.iter().all(|(_, e)| *e < 0.05));
    }

    #[test]
    fn a_superfluous_lobe_stays_put_from_frame_to_frame() {
        // Two true lobes drifting, fitted with three: the third has little to explain and
        // must not wander (the linear model could not follow it).
        let frames: Vec<ShVec> = (0..12)
            .map(|f| two_drifting_lobes(f as f32 * 0.04))
            .enumerate()
            .map(|(f, v)| {
                // Deterministic noise like that of a few hundred visibility rays.
                std::array::from_fn(|i| {
                    let h = ((f * 16 + i) as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15) >> 40;
                    v[i] + 0.03 * ((h as f32 / (1u64 << 24) as f32) - 0.5)
                })
            })
            .collect();
        let fits = fit_sequence(&frames, 3);
        for w in fits.windows(2) {
            for k in 0..3 {
                let d = w[0].0[k].axis.dot(w[1].0[k].axis);
                assert!(
                    d > 0.95,
                    "lobe {k} turned by {} rad",
                    d.clamp(-1.0, 1.0).acos()
                );
            }
        }
        assert!(fits.iter().all(|(_, e)| *e < 0.1));
    }

    #[test]
    fn close_lobes_do_not_form_a_large_opposite_pair() {
        // The difference of two strong lobes 5° apart (a "dipole") over a constant, fitted
        // from those very axes: the fit must not rebuild the dipole with large opposite
        // coefficients (a ridge of 1e-4 does, with ±2.1), while staying closer than one lobe.
        let a = Vec3::new(0.2, 0.1, 1.0).normalize();
        let b = (a + Vec3::new(0.09, 0.0, 0.0)).normalize();
        let strong = [0.0, 3.0, 2.0, 1.0];
        let mut target = [0.0; COEFFS];
        target[0] = 2.0 * std::f32::consts::PI.sqrt();
        ZhLobe {
            axis: a,
            coeffs: strong,
        }
        .add_to(&mut target);
        ZhLobe {
            axis: b,
            coeffs: strong.map(|c| -c),
        }
        .add_to(&mut target);
        let (_, e1) = fit_lobes(&target, 1, None);
        let (two, e2) = fit_lobes(&target, 2, Some(&[a, b]));
        assert!(e2 < e1, "two lobes {e2} vs one {e1}");
        let largest = two
            .iter()
            .flat_map(|l| l.coeffs[1..].iter().map(|c| c.abs()))
            .fold(0.0f32, f32::max);
        assert!(
            largest < 1.5,
            "coefficients {:?}",
            two.iter().map(|l| l.coeffs).collect::<Vec<_>>()
        );
    }

    #[test]
    fn fitting_is_deterministic() {
        let v: ShVec = std::array::from_fn(|i| ((i * 37 % 11) as f32 - 5.0) / 7.0);
        assert_eq!(fit_lobes(&v, 3, None), fit_lobes(&v, 3, None));
    }
}
