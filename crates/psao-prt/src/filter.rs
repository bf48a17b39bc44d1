//! Deringing of reconstructed visibility before shading.
//!
//! Order-4 SH visibility (projected, or the sum of a model's lobes) rings: a binary
//! function truncated to 4 bands overshoots above 1 and undershoots below 0 around its
//! edges, and the model's extrapolated lobes can be far outside [0, 1] too. Under bright
//! light from the open side that negative ringing darkens a vertex that nothing occludes
//! there. Two remedies, applied in this order:
//!
//! * a **window**: band `l` scaled by `w_l` (Hanning `(1 + cos(π l / 4)) / 2`, or Lanczos
//!   σ-factors `sinc(l / 4)`), which smooths the function and so its ringing; band 0 is
//!   kept, so unoccluded visibility (the constant 1) is unchanged;
//! * a **clamp**: the function evaluated at the nodes of a product quadrature over the
//!   sphere, clamped to [0, 1], and the change projected back onto the 16 coefficients
//!   (the rule integrates products of two order-4 functions exactly, so a function within
//!   [0, 1] everywhere is returned unchanged).

use std::str::FromStr;

use crate::quadrature::SphereQuadrature;
use crate::sh::{self, ShVec, BANDS, COEFFS};
use crate::PrtError;

/// Gauss–Legendre nodes in z of the clamp's quadrature (twice as many in φ: 72 nodes,
/// exact to degree 11).
const CLAMP_NODES: usize = 6;

/// A per-band window on SH coefficients.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Window {
    /// No window.
    #[default]
    None,
    /// Hanning: `(1 + cos(π l / 4)) / 2`.
    Hanning,
    /// Lanczos σ-factors: `sin(π l / 4) / (π l / 4)`.
    Lanczos,
}

impl Window {
    /// The factor of every band.
    pub fn factors(self) -> [f32; BANDS] {
        let x = |l: usize| std::f32::consts::PI * l as f32 / BANDS as f32;
        std::array::from_fn(|l| match self {
            Window::None => 1.0,
            Window::Hanning => 0.5 * (1.0 + x(l).cos()),
            Window::Lanczos if l == 0 => 1.0,
            Window::Lanczos => x(l).sin() / x(l),
        })
    }
}

/// What is done to reconstructed visibility before it is shaded.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Filter {
    /// The window.
    pub window: Window,
    /// Whether visibility is clamped to [0, 1] over the sphere.
    pub clamp: bool,
}

impl FromStr for Filter {
    type Err = PrtError;

    /// `none`, or `+`-joined parts among `hanning`, `lanczos` and `clamp`
    /// (e.g. `clamp`, `hanning+clamp`).
    fn from_str(s: &str) -> Result<Self, PrtError> {
        let mut f = Filter::default();
        for part in s.split('+').map(str::trim) {
            match part {
                "none" => {}
                "clamp" => f.clamp = true,
                "hanning" => f.window = Window::Hanning,
                "lanczos" => f.window = Window::Lanczos,
                other => {
                    return Err(PrtError::Parameter(format!(
                        "visibility filter `{other}` (known: none, clamp, hanning, lanczos, \
                         joined by +)"
                    )))
                }
            }
        }
        Ok(f)
    }
}

impl std::fmt::Display for Filter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let window = match self.window {
            Window::None => None,
            Window::Hanning => Some("hanning"),
            Window::Lanczos => Some("lanczos"),
        };
        let parts: Vec<&str> = window
            .into_iter()
            .chain(self.clamp.then_some("clamp"))
            .collect();
        if parts.is_empty() {
            write!(f, "none")
        } else {
            write!(f, "{}", parts.join("+"))
        }
    }
}

/// A [`Filter`] ready to apply (the window's factors per coefficient, the clamp's nodes).
#[derive(Clone, Debug)]
pub struct Prepared {
    filter: Filter,
    factors: ShVec,
    /// Basis values at each quadrature node, and the node's weight.
    nodes: Vec<(ShVec, f32)>,
}

impl Prepared {
    /// Prepares `filter`.
    pub fn new(filter: Filter) -> Self {
        let bands = filter.window.factors();
        let nodes = if filter.clamp {
            SphereQuadrature::sphere(CLAMP_NODES)
                .nodes
                .iter()
                .map(|&(d, w)| (sh::eval_f64(d).map(|y| y as f32), w as f32))
                .collect()
        } else {
            Vec::new()
        };
        Self {
            filter,
            factors: std::array::from_fn(|i| bands[sh::band_of(i)]),
            nodes,
        }
    }

    /// The filter.
    pub fn filter(&self) -> Filter {
        self.filter
    }

    /// Filters `v` in place (a function on the sphere: the result does not depend on the
    /// frame `v` is expressed in).
    pub fn apply(&self, v: &mut ShVec) {
        if self.filter.window != Window::None {
            for (c, w) in v.iter_mut().zip(&self.factors) {
                *c *= w;
            }
        }
        if self.nodes.is_empty() {
            return;
        }
        let mut change = [0.0f32; COEFFS];
        for (y, w) in &self.nodes {
            let value = sh::dot(v, y);
            let d = value.clamp(0.0, 1.0) - value;
            if d != 0.0 {
                for (c, yi) in change.iter_mut().zip(y) {
                    *c += w * d * yi;
                }
            }
        }
        for (c, d) in v.iter_mut().zip(change) {
            *c += d;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shade::unit_visibility;
    use glam::Vec3;

    #[test]
    fn windows_keep_band_zero_and_fall_with_the_band() {
        for w in [Window::Hanning, Window::Lanczos] {
            let f = w.factors();
            assert_eq!(f[0], 1.0);
            assert!(f.windows(2).all(|p| p[1] < p[0]), "{w:?}: {f:?}");
        }
        assert!((Window::Hanning.factors()[2] - 0.5).abs() < 1e-6);
        assert!((Window::Lanczos.factors()[2] - 2.0 / std::f32::consts::PI).abs() < 1e-6);
    }

    #[test]
    fn unit_visibility_passes_unchanged_and_ringing_is_reduced() {
        let all = Prepared::new("hanning+clamp".parse().unwrap());
        let mut one = unit_visibility();
        all.apply(&mut one);
        for (a, b) in one.iter().zip(unit_visibility()) {
            assert!((a - b).abs() < 1e-5, "{one:?}");
        }
        // A cap of half-angle 60° blocked about +z, projected to order 4: it rings below 0
        // and above 1. Clamping brings its range much closer to [0, 1].
        let q = SphereQuadrature::sphere(32);
        let cap = q.project(|d| if d.z > 0.5 { 0.0 } else { 1.0 });
        let v: ShVec = cap.map(|c| c as f32);
        let range = |v: &ShVec| {
            q.nodes
                .iter()
                .fold((f32::MAX, f32::MIN), |(lo, hi), &(d, _)| {
                    let x = sh::value(v, Vec3::new(d.x as f32, d.y as f32, d.z as f32));
                    (lo.min(x), hi.max(x))
                })
        };
        let (lo, hi) = range(&v);
        assert!(lo < -0.05 && hi > 1.05, "{lo} {hi}");
        let mut clamped = v;
        Prepared::new("clamp".parse().unwrap()).apply(&mut clamped);
        let (clo, chi) = range(&clamped);
        assert!(
            clo > lo / 2.0 && chi - 1.0 < (hi - 1.0) / 2.0,
            "{clo} {chi}"
        );
        // The mean (band 0) barely moves.
        assert!((clamped[0] - v[0]).abs() < 0.05 * v[0]);
    }

    #[test]
    fn filters_parse_and_print() {
        for s in ["none", "clamp", "hanning", "lanczos+clamp"] {
            assert_eq!(s.parse::<Filter>().unwrap().to_string(), s);
        }
        assert!("median".parse::<Filter>().is_err());
    }
}
