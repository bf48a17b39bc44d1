//! Client-side AO reconstruction at a shaded position (DESIGN §3, paper §3.5, Eqs. 2–4).

use glam::Vec3;

use crate::linear_fit::LinearFit;
use crate::lookup::CellLookup;
use crate::pack::{is_valid, normal_code, normal_table, unpack_ao};

/// Default interpolation factor: reconstruction radius r = 2√2 × the Poisson radius r_max.
///
/// The paper sets r to "the average radius computed during the Poisson disk rejection"; its
/// authors' code weighs by squared distance within `sqrt(0.5) · cell = 2√2 · r_max` (their
/// factor 1), and this is the reach we match. Smaller radii leave holes (no point within r,
/// AO falls back to 1): with 2× oversampling the random candidates already contain empty
/// disks of radius ≈ 2.2–2.5 r_max, which elimination cannot fill. Measured on a 4 m² plane
/// at N = 1024 (40k queries, 3 seeds): holes 0.07–0.18 % at factor 2, ≤ 0.005 % at 2.5, none
/// at 2√2. Factor 2 is the largest radius the 2×2×2 lookup covers completely (half a cell of
/// 4·r_max); beyond it points are visited depending on where the position falls in its cell,
/// which only affects weights below (r − 2·r_max)/r ≈ 0.29.
pub const DEFAULT_INTERPOLATION_FACTOR: f32 = 2.0 * std::f32::consts::SQRT_2;
/// Default T_n: points whose normal has cosine ≤ this with the surface normal are ignored.
pub const DEFAULT_NORMAL_THRESHOLD: f32 = 0.1;
/// Default T_d: points whose normal has squared cosine ≥ this with the direction to them are
/// ignored (they lie in front of or behind the surface, not along it).
pub const DEFAULT_DIRECTION_THRESHOLD: f32 = 0.7;

/// Default plane tolerance, in Poisson radii: points farther than this from the shaded
/// position's tangent plane are ignored (our addition to Eq. 3, see [`reconstruct_ao`]).
pub const DEFAULT_PLANE_TOLERANCE: f32 = 0.5;
/// Default exponent of the normal-agreement weight `(n·n_i)^k` (our addition, see
/// [`reconstruct_ao`]).
pub const DEFAULT_NORMAL_EXPONENT: i32 = 8;
/// Ridge of the planar fit, in Poisson radii, when it is chosen
/// ([`ReconstructParams::linear_ridge`]; off by default: on streamed frames whose points hold
/// few samples it tilts with their noise and lowers SSIM, see docs/BENCHMARKS.md).
pub const DEFAULT_LINEAR_RIDGE: f32 = 0.25;

/// Neighbours that set the footprint of [`ReconstructParams::adaptive_radius`]: the radius
/// follows the distance to the third nearest compatible point.
pub const ADAPTIVE_NEIGHBOURS: usize = 3;
/// Default factor of [`ReconstructParams::adaptive_radius`] when it is chosen: on a uniform
/// Poisson set of radius `r_max` the third nearest point of a random position lies about
/// `1.8 r_max` away (3 points expected in a disk of that radius at the density
/// `1 / (2√3 r_max²)`), so 1.8 × it is about 3.3 `r_max`, beyond the default radius of
/// 2√2 `r_max`: the footprint shrinks only where the points are clearly denser than the
/// instance's Poisson radius says (adaptive placement).
pub const DEFAULT_ADAPTIVE_RADIUS: f32 = 1.8;

/// The [`ADAPTIVE_NEIGHBOURS`] smallest squared distances offered to it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NearestK {
    d2: [f32; ADAPTIVE_NEIGHBOURS],
}

impl Default for NearestK {
    fn default() -> Self {
        Self {
            d2: [f32::INFINITY; ADAPTIVE_NEIGHBOURS],
        }
    }
}

impl NearestK {
    /// Offer a squared distance.
    #[inline]
    pub fn offer(&mut self, d2: f32) {
        if d2 < self.d2[ADAPTIVE_NEIGHBOURS - 1] {
            let mut i = ADAPTIVE_NEIGHBOURS - 1;
            while i > 0 && self.d2[i - 1] > d2 {
                self.d2[i] = self.d2[i - 1];
                i -= 1;
            }
            self.d2[i] = d2;
        }
    }

    /// The footprint radius: `min(r, factor · d_k)` with `d_k` the distance of the k-th
    /// nearest offered point, or `r` when fewer than k were offered.
    #[inline]
    pub fn radius(&self, r: f32, factor: f32) -> f32 {
        let dk = self.d2[ADAPTIVE_NEIGHBOURS - 1];
        if dk.is_finite() {
            r.min(factor * dk.sqrt())
        } else {
            r
        }
    }
}

/// Parameters of the reconstruction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReconstructParams {
    /// Radius r = layout Poisson radius × this.
    pub interpolation_factor: f32,
    /// T_n of Eq. 3.
    pub normal_threshold: f32,
    /// T_d of Eq. 3.
    pub direction_threshold: f32,
    /// Largest distance `|n·(p_i − p)|` of a used point from the tangent plane at `p`, in
    /// units of the layout's Poisson radius (`f32::INFINITY` disables the test).
    pub plane_tolerance: f32,
    /// Exponent `k` of the extra weight `(n·n_i)^k` (0 disables it).
    pub normal_exponent: i32,
    /// When no point lies within `r`, use the AO of the nearest point of the visited cells
    /// that passes every other test instead of 1 (see [`reconstruct_ao`]).
    pub nearest_fallback: bool,
    /// `Some(ridge)`: fit a plane through the weighted AO values ([`LinearFit`]) instead of
    /// taking their weighted mean; `ridge` is in Poisson radii.
    pub linear_ridge: Option<f32>,
    /// `Some(c)`: a footprint that follows the local point spacing (for adaptive placement,
    /// where the points are denser than the instance's Poisson radius says): the radius is
    /// `min(r, c · d_k)`, with `d_k` the distance to the k-th nearest point within `r` that
    /// passes every other test ([`ADAPTIVE_NEIGHBOURS`], [`NearestK`]). `None` (the default):
    /// always `r`.
    pub adaptive_radius: Option<f32>,
}

impl Default for ReconstructParams {
    fn default() -> Self {
        Self {
            interpolation_factor: DEFAULT_INTERPOLATION_FACTOR,
            normal_threshold: DEFAULT_NORMAL_THRESHOLD,
            direction_threshold: DEFAULT_DIRECTION_THRESHOLD,
            plane_tolerance: DEFAULT_PLANE_TOLERANCE,
            normal_exponent: DEFAULT_NORMAL_EXPONENT,
            nearest_fallback: true,
            linear_ridge: None,
            adaptive_radius: None,
        }
    }
}

/// AO at local position `p` with local unit normal `n` from the points of the 2×2×2 cells
/// nearest `p`: weights `w = max(0, (r − |p_i − p|) / r)`, zeroed when `n_i·n ≤ T_n` or
/// `(n_i·(p_i − p)/|p_i − p|)² ≥ T_d`; returns `Σ w·AO_i / Σ w`, or the fallback when
/// `Σ w = 0` (1 in DESIGN; see (3) below).
/// Allocation-free; at most 8 bucket scans and 56 points, 64 and 448 on the ring fallback.
///
/// Two additions to DESIGN §3 / the paper's Eq. 3 (whose criteria stay as they are) fight
/// the leaking the paper names as a limitation: detail finer than the point spacing (a
/// groove, a step, a thin bar) puts points of a parallel surface a few millimetres away
/// inside the radius, where the direction test `(n_i·d̂)² ≥ T_d` does not reject them because
/// they lie mostly sideways. (1) A point farther than `plane_tolerance × r_max` from the
/// tangent plane at `p` (`|n·(p_i − p)| >`, with the pixel's normal `n`) is ignored: on a
/// flat or gently curved surface its own points lie within a fraction of `r_max` of the
/// plane (quantisation: `r_max / 16` at most; curvature radius ≥ 8 `r_max` keeps every
/// point within the radius), points of a surface offset by more do not. (2) `w` is
/// multiplied by `(n·n_i)^normal_exponent`, so on creases points of the other face (tilted
/// normals) count less than points of the pixel's own face. Both only ever zero or shrink
/// weights. (3) When no point passes within `r` (a hole: detail narrower than the spacing,
/// such as a groove bottom, holds too few points of its own), the AO of the nearest point of
/// the visited cells that passes every test but the radius is used; when the 2×2×2 block has
/// none, the nearest such point of the ring of cells around it
/// ([`CellLookup::ring_cells`]); and 1 only when there is none: DESIGN's fallback 1 draws
/// such detail as white gaps (a dark groove breaks into dashes), while the nearest point on
/// the same surface carries nearly the same occlusion. (4) With
/// [`ReconstructParams::linear_ridge`] set (off by default) the result is not `Σ w·AO_i / Σ w` but
/// the value at `p` of the plane fitted through the same weighted points ([`LinearFit`]),
/// which keeps AO gradients steeper than the radius (the foot of a low wall).
pub fn reconstruct_ao<G: CellLookup + ?Sized>(
    grid: &G,
    p: Vec3,
    n: Vec3,
    params: &ReconstructParams,
) -> f32 {
    let layout = grid.layout();
    let mut r = layout.poisson_radius * params.interpolation_factor;
    if !(r > 0.0 && r.is_finite() && p.is_finite()) {
        return 1.0;
    }
    let plane = params.plane_tolerance * layout.poisson_radius;
    let base = layout.nearest_base(p);
    let normals = normal_table();
    // Every test but the radius: normal agreement, tangent plane, direction.
    let passes = |ni: Vec3, delta: Vec3, d2: f32| {
        if ni.dot(n) <= params.normal_threshold || n.dot(delta).abs() > plane {
            return false;
        }
        let d = d2.sqrt();
        if d > 0.0 {
            let c = ni.dot(delta) / d;
            if c * c >= params.direction_threshold {
                return false;
            }
        }
        true
    };
    if let Some(factor) = params.adaptive_radius {
        let mut near = NearestK::default();
        for (coord, _, words) in grid.block_cells(base) {
            for &bits in words.iter().filter(|&&b| is_valid(b)) {
                let delta = layout.unpack_position(coord, bits) - p;
                let d2 = delta.length_squared();
                if d2 < r * r && passes(normals[normal_code(bits) as usize], delta, d2) {
                    near.offer(d2);
                }
            }
        }
        r = near.radius(r, factor);
    }
    let (r2, inv_r) = (r * r, 1.0 / r);
    let (mut w_sum, mut ao_sum) = (0.0f32, 0.0f32);
    let mut fit = LinearFit::new(n);
    let (mut nearest_d2, mut nearest_ao) = (f32::INFINITY, 1.0f32);
    for (coord, _, words) in grid.block_cells(base) {
        for &bits in words {
            if !is_valid(bits) {
                continue;
            }
            let delta = layout.unpack_position(coord, bits) - p;
            let d2 = delta.length_squared();
            let ni = normals[normal_code(bits) as usize];
            if !passes(ni, delta, d2) {
                continue;
            }
            if d2 >= r2 {
                if d2 < nearest_d2 {
                    (nearest_d2, nearest_ao) = (d2, unpack_ao(bits));
                }
                continue;
            }
            let w = (r - d2.sqrt()) * inv_r * ni.dot(n).powi(params.normal_exponent);
            w_sum += w;
            ao_sum += w * unpack_ao(bits);
            if params.linear_ridge.is_some() {
                fit.add(w, delta, unpack_ao(bits));
            }
        }
    }
    if w_sum == 0.0 && params.nearest_fallback && nearest_d2 == f32::INFINITY {
        for (coord, _, words) in grid.ring_cells(base) {
            for &bits in words.iter().filter(|&&b| is_valid(b)) {
                let delta = layout.unpack_position(coord, bits) - p;
                let d2 = delta.length_squared();
                if passes(normals[normal_code(bits) as usize], delta, d2) && d2 < nearest_d2 {
                    (nearest_d2, nearest_ao) = (d2, unpack_ao(bits));
                }
            }
        }
    }
    if w_sum > 0.0 {
        match params.linear_ridge {
            Some(ridge) => fit
                .solve(ridge * layout.poisson_radius)
                .unwrap_or(ao_sum / w_sum),
            None => ao_sum / w_sum,
        }
    } else if params.nearest_fallback {
        nearest_ao
    } else {
        1.0
    }
}
