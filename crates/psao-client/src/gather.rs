//! [`psao_points::reconstruct_ao`] with the neighbourhood lookup shared between pixels.
//!
//! Neighbouring pixels of one surface usually fall into the same 2×2×2 block of cells (a cell
//! spans several pixels at typical distances), so a [`Neighbourhood`] keeps the decoded points
//! of the last block it gathered and only repeats the hash lookups and unpacking when the
//! instance or the block changes. The weighting performs the same floating-point operations
//! on the same points in the same order as `reconstruct_ao`, so results are bit-identical
//! (tested).

use glam::{IVec3, Vec3};
use psao_points::pack::{is_valid, normal_code, normal_table, unpack_ao};
use psao_points::{InstanceGrid, LinearFit, NearestK, ReconstructParams, CELL_POINTS};

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
        }
    }

    /// AO at local position `p` with local unit normal `n` on instance `instance` (whose grid
    /// is `grid`): the result of `reconstruct_ao(grid, p, n, params)`.
    #[inline]
    pub(crate) fn ao(
        &mut self,
        instance: u32,
        grid: &InstanceGrid,
        p: Vec3,
        n: Vec3,
        params: &ReconstructParams,
    ) -> f32 {
        let layout = grid.layout();
        let mut r = layout.poisson_radius * params.interpolation_factor;
        if !(r > 0.0 && r.is_finite() && p.is_finite()) {
            return 1.0;
        }
        let base = layout.nearest_base(p);
        if self.key != Some((instance, base)) {
            self.gather(grid, base);
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
            match params.linear_ridge {
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
            }
        } else if params.nearest_fallback {
            self.nearest(p, n, plane, params)
                .or_else(|| ring_nearest(grid, base, p, n, plane, params))
                .unwrap_or(1.0)
        } else {
            1.0
        }
    }

    /// The fallback of `reconstruct_ao` when no point lies within the radius: the AO of the
    /// block's nearest point passing the normal, plane and direction tests (first one on
    /// ties), if any.
    fn nearest(&self, p: Vec3, n: Vec3, plane: f32, params: &ReconstructParams) -> Option<f32> {
        let [px, py, pz] = &self.position;
        let [nx, ny, nz] = &self.normal;
        let (mut nearest_d2, mut nearest_ao) = (f32::INFINITY, None);
        for i in 0..self.count {
            let delta = Vec3::new(px[i], py[i], pz[i]) - p;
            let ni = Vec3::new(nx[i], ny[i], nz[i]);
            let d2 = delta.length_squared();
            if compatible(ni, n, delta, d2, plane, params) && d2 < nearest_d2 {
                (nearest_d2, nearest_ao) = (d2, Some(self.ao[i]));
            }
        }
        nearest_ao
    }

    /// Decode the valid points of the allocated cells of the block at `base`, in the order
    /// `reconstruct_ao` visits them.
    fn gather(&mut self, grid: &InstanceGrid, base: IVec3) {
        let layout = grid.layout();
        let normals = normal_table();
        self.count = 0;
        for (coord, cell) in grid.block_cells(base) {
            for &bits in cell.points.iter().filter(|&&b| is_valid(b)) {
                let i = self.count;
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
/// of the nearest compatible point of the cells around it ([`InstanceGrid::ring_cells`]),
/// decoded straight from the grid (this path is rare, so nothing is cached).
fn ring_nearest(
    grid: &InstanceGrid,
    base: IVec3,
    p: Vec3,
    n: Vec3,
    plane: f32,
    params: &ReconstructParams,
) -> Option<f32> {
    let layout = grid.layout();
    let normals = normal_table();
    let (mut nearest_d2, mut nearest_ao) = (f32::INFINITY, None);
    for (coord, cell) in grid.ring_cells(base) {
        for &bits in cell.points.iter().filter(|&&b| is_valid(b)) {
            let delta = layout.unpack_position(coord, bits) - p;
            let d2 = delta.length_squared();
            let ni = normals[normal_code(bits) as usize];
            if compatible(ni, n, delta, d2, plane, params) && d2 < nearest_d2 {
                (nearest_d2, nearest_ao) = (d2, Some(unpack_ao(bits)));
            }
        }
    }
    nearest_ao
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
