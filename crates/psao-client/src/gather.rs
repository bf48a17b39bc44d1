//! [`psao_points::reconstruct_ao`] with the neighbourhood lookup shared between pixels, and
//! with lighting the points' irradiance interpolated with the same weights.
//!
//! Neighbouring pixels of one surface usually fall into the same 2×2×2 block of cells (a cell
//! spans several pixels at typical distances), so a [`Neighbourhood`] keeps the decoded points
//! of the last block it gathered and only repeats the hash lookups and unpacking when the
//! instance or the block changes. The weighting performs the same floating-point operations
//! on the same points in the same order as `reconstruct_ao`, so results are bit-identical
//! (tested).
//!
//! Irradiance (DESIGN §12) uses the AO kernel: the same points and weights give
//! `Σ w·E_i / Σ w` per channel (the weighted mean also where AO uses a planar fit), the same
//! nearest-point fallbacks give the fallback point's irradiance, and a pixel with no
//! compatible point at all gets zero here ([`Found::Nothing`]; `crate::fill` then fills its
//! irradiance from neighbouring pixels).

use glam::{IVec3, Vec3};
use psao_points::irradiance::unpack_rgb9e5;
use psao_points::pack::{is_valid, normal_code, normal_table, unpack_ao};
use psao_points::{
    CellLookup, LinearFit, MirrorGrid, NearestK, Paged, ReconstructParams, CELL_POINTS,
};

use crate::state::CellLights;

/// An instance's irradiance records by cell slot.
pub(crate) type Lights<'a> = Option<&'a Paged<CellLights>>;

/// Where [`Neighbourhood::sample`] found the pixel's value.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Found {
    /// In the 2×2×2 block: the kernel's weighted points or the block's nearest compatible
    /// point (with the nearest-point fallback on).
    Block,
    /// The nearest compatible point of the ring of cells around the block.
    Ring,
    /// No compatible point: AO 1, irradiance zero.
    Nothing,
}

/// Most points a 2×2×2 block can hold.
const MAX_POINTS: usize = 8 * CELL_POINTS;

/// The decoded points of one instance's 2×2×2 cell block, reused across pixels.
pub(crate) struct Neighbourhood {
    /// (instance, block base) the points belong to; `None` before the first gather.
    key: Option<(u32, IVec3)>,
    count: usize,
    /// Positions and normals, one array per coordinate so the weighting loop vectorises.
    position: [[f32; MAX_POINTS]; 3],
    normal: [[f32; MAX_POINTS]; 3],
    ao: [f32; MAX_POINTS],
    /// Irradiance per point, one array per channel (decoded only with records).
    irradiance: [[f32; MAX_POINTS]; 3],
    /// Whether the gathered points came with irradiance records.
    lit: bool,
}

impl Neighbourhood {
    /// An empty cache.
    pub(crate) fn new() -> Self {
        Self {
            key: None,
            count: 0,
            position: [[0.0; MAX_POINTS]; 3],
            normal: [[0.0; MAX_POINTS]; 3],
            ao: [0.0; MAX_POINTS],
            irradiance: [[0.0; MAX_POINTS]; 3],
            lit: false,
        }
    }

    /// AO and irradiance at local position `p` with local unit normal `n` on instance
    /// `instance` (whose grid is `grid` and irradiance records `lights`): the AO is the result
    /// of `reconstruct_ao(grid, p, n, params)`, the irradiance interpolated as the module
    /// documentation says (zero without records), and where they were found.
    #[inline]
    pub(crate) fn sample(
        &mut self,
        instance: u32,
        (grid, lights): (&MirrorGrid, Lights<'_>),
        p: Vec3,
        n: Vec3,
        params: &ReconstructParams,
    ) -> (f32, Vec3, Found) {
        let layout = grid.layout();
        let mut r = layout.poisson_radius * params.interpolation_factor;
        if !(r > 0.0 && r.is_finite() && p.is_finite()) {
            return (1.0, Vec3::ZERO, Found::Nothing);
        }
        let base = layout.nearest_base(p);
        if self.key != Some((instance, base)) {
            self.gather(grid, lights, base);
            self.key = Some((instance, base));
        }
        let plane = params.plane_tolerance * layout.poisson_radius;
        let [px, py, pz] = &self.position;
        let [nx, ny, nz] = &self.normal;
        if let Some(factor) = params.adaptive_radius {
            let mut near = NearestK::default();
            for i in 0..self.count {
                let delta = Vec3::new(px[i], py[i], pz[i]) - p;
                let ni = Vec3::new(nx[i], ny[i], nz[i]);
                let d2 = delta.length_squared();
                if d2 < r * r && compatible(ni, n, delta, d2, plane, params) {
                    near.offer(d2);
                }
            }
            r = near.radius(r, factor);
        }
        let (r2, inv_r) = (r * r, 1.0 / r);
        // Branch-free: a rejected point gets weight +0, which leaves both sums unchanged, so
        // the result equals the early-continue formulation bit for bit.
        let mut weight = [0.0f32; MAX_POINTS];
        for i in 0..self.count {
            // Same operations as glam's `Vec3` arithmetic in `reconstruct_ao`.
            let delta = Vec3::new(px[i], py[i], pz[i]) - p;
            let ni = Vec3::new(nx[i], ny[i], nz[i]);
            let d2 = delta.length_squared();
            let keep = d2 < r2 && compatible(ni, n, delta, d2, plane, params);
            weight[i] = if keep {
                (r - d2.sqrt()) * inv_r * ni.dot(n).powi(params.normal_exponent)
            } else {
                0.0
            };
        }
        let (mut w_sum, mut ao_sum) = (0.0f32, 0.0f32);
        for (w, ao) in weight.iter().zip(&self.ao).take(self.count) {
            w_sum += w;
            ao_sum += w * ao;
        }
        if w_sum > 0.0 {
            let ao = match params.linear_ridge {
                Some(ridge) => {
                    // The same points, in the same order, as `reconstruct_ao` adds.
                    let mut fit = LinearFit::new(n);
                    for i in (0..self.count).filter(|&i| weight[i] > 0.0) {
                        let delta = Vec3::new(px[i], py[i], pz[i]) - p;
                        fit.add(weight[i], delta, self.ao[i]);
                    }
                    fit.solve(ridge * layout.poisson_radius)
                        .unwrap_or(ao_sum / w_sum)
                }
                None => ao_sum / w_sum,
            };
            (ao, self.weighted_irradiance(&weight, w_sum), Found::Block)
        } else if params.nearest_fallback {
            match self.nearest(p, n, plane, params) {
                Some(i) => (self.ao[i], self.irradiance_of(i), Found::Block),
                None => ring_nearest((grid, lights), base, p, n, plane, params)
                    .map_or((1.0, Vec3::ZERO, Found::Nothing), |(ao, e)| {
                        (ao, e, Found::Ring)
                    }),
            }
        } else {
            (1.0, Vec3::ZERO, Found::Nothing)
        }
    }

    /// `Σ w·E_i / w_sum` over the gathered points (zero without records).
    fn weighted_irradiance(&self, weight: &[f32; MAX_POINTS], w_sum: f32) -> Vec3 {
        if !self.lit {
            return Vec3::ZERO;
        }
        let mut sum = [0.0f32; 3];
        for (channel, values) in sum.iter_mut().zip(&self.irradiance) {
            for (w, e) in weight.iter().zip(values).take(self.count) {
                *channel += w * e;
            }
        }
        Vec3::from(sum) / w_sum
    }

    /// The irradiance of gathered point `i` (zero without records).
    fn irradiance_of(&self, i: usize) -> Vec3 {
        let [r, g, b] = &self.irradiance;
        if self.lit {
            Vec3::new(r[i], g[i], b[i])
        } else {
            Vec3::ZERO
        }
    }

    /// The fallback of `reconstruct_ao` when no point lies within the radius: the index of
    /// the block's nearest point passing the normal, plane and direction tests (first one on
    /// ties), if any.
    fn nearest(&self, p: Vec3, n: Vec3, plane: f32, params: &ReconstructParams) -> Option<usize> {
        let [px, py, pz] = &self.position;
        let [nx, ny, nz] = &self.normal;
        let (mut nearest_d2, mut nearest) = (f32::INFINITY, None);
        for i in 0..self.count {
            let delta = Vec3::new(px[i], py[i], pz[i]) - p;
            let ni = Vec3::new(nx[i], ny[i], nz[i]);
            let d2 = delta.length_squared();
            if compatible(ni, n, delta, d2, plane, params) && d2 < nearest_d2 {
                (nearest_d2, nearest) = (d2, Some(i));
            }
        }
        nearest
    }

    /// Decode the valid points of the allocated cells of the block at `base`, in the order
    /// `reconstruct_ao` visits them, with their irradiance when `lights` has records.
    fn gather(&mut self, grid: &MirrorGrid, lights: Lights<'_>, base: IVec3) {
        let layout = grid.layout();
        let normals = normal_table();
        self.count = 0;
        self.lit = lights.is_some();
        for (coord, slot, words) in grid.block_cells(base) {
            let records = lights.map(|l| l.value(slot as usize));
            for (k, &bits) in words.iter().enumerate().filter(|(_, &b)| is_valid(b)) {
                let i = self.count;
                if let Some(records) = &records {
                    let e = unpack_rgb9e5(records[k]);
                    for (channel, value) in self.irradiance.iter_mut().zip(e.to_array()) {
                        channel[i] = value;
                    }
                }
                let position = layout.unpack_position(coord, bits);
                let normal = normals[normal_code(bits) as usize];
                for axis in 0..3 {
                    self.position[axis][i] = position[axis];
                    self.normal[axis][i] = normal[axis];
                }
                self.ao[i] = unpack_ao(bits);
                self.count += 1;
            }
        }
    }
}

/// The second fallback of `reconstruct_ao`, when the block has no compatible point: the AO
/// (and irradiance, zero without records) of the nearest compatible point of the cells
/// around it ([`CellLookup::ring_cells`]), decoded straight from the grid (this path is
/// rare, so nothing is cached).
fn ring_nearest(
    (grid, lights): (&MirrorGrid, Lights<'_>),
    base: IVec3,
    p: Vec3,
    n: Vec3,
    plane: f32,
    params: &ReconstructParams,
) -> Option<(f32, Vec3)> {
    let layout = grid.layout();
    let normals = normal_table();
    let (mut nearest_d2, mut nearest) = (f32::INFINITY, None);
    for (coord, slot, words) in grid.ring_cells(base) {
        for (k, &bits) in words.iter().enumerate().filter(|(_, &b)| is_valid(b)) {
            let delta = layout.unpack_position(coord, bits) - p;
            let d2 = delta.length_squared();
            let ni = normals[normal_code(bits) as usize];
            if compatible(ni, n, delta, d2, plane, params) && d2 < nearest_d2 {
                (nearest_d2, nearest) = (d2, Some((slot, k, unpack_ao(bits))));
            }
        }
    }
    let (slot, k, ao) = nearest?;
    let e = lights.map_or(Vec3::ZERO, |l| unpack_rgb9e5(l.value(slot as usize)[k]));
    Some((ao, e))
}

/// The normal, tangent-plane and direction tests of `reconstruct_ao` for a point with normal
/// `ni` at `delta` (`d2 = |delta|²`) from the shaded position with normal `n`.
#[inline(always)]
fn compatible(
    ni: Vec3,
    n: Vec3,
    delta: Vec3,
    d2: f32,
    plane: f32,
    params: &ReconstructParams,
) -> bool {
    let c = ni.dot(delta) / d2.sqrt();
    ni.dot(n) > params.normal_threshold
        && n.dot(delta).abs() <= plane
        && (d2 == 0.0 || c * c < params.direction_threshold)
}
