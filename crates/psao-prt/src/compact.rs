//! A pose model compacted for synthesis at run time (paper §4.3).
//!
//! The model's prediction is `Wᵀ·[1; x]` for the limited pose features `x`. A limited pose
//! is the training mean plus a combination of the training poses' principal axes `aᵢ` (see
//! [`crate::limits`]), so with `k` axes the outputs are `base + Σᵢ cᵢ·Cᵢ`: `base` the
//! prediction at the mean, `Cᵢ = W_xᵀ·aᵢ`, `cᵢ` the limited coordinates, `k + 1` rows instead
//! of the pose vector's `1 + 3·active` (a model without limits keeps its pose features as
//! coordinates). Each coordinate stays within the box `|cᵢ| ≤ bᵢ`, so the columns scaled
//! to the change they can make, `Dᵢ = bᵢ·Cᵢ`, are decomposed by a thin SVD (through their
//! `k × k` Gram matrix): `D = Σⱼ σⱼ·qⱼ·rⱼᵀ`, and component j moves an output by at most
//! `σⱼ·√k·max|qⱼ|`. The smallest components are dropped while the sum of these bounds stays
//! within a tolerance (a model without limits has no box and keeps every component).
//!
//! The rows left (base and components) are stored as 16-bit integers with one factor per
//! row, in blocks of [`LANES`] vertices: per block, per row, per output number, the block's
//! vertices side by side. A frame synthesises a block's lobes ([`CompactModel::synthesise_block`])
//! by reading its numbers once, in order, into one array per output number (a structure of
//! arrays that the shading's lane loops read directly), right before shading it.

use crate::model::{PoseModel, LOBE_DIM};
use crate::PrtError;
use glam::Vec3;
use rayon::prelude::*;

/// Default largest change (in the model's output units: axis components and zonal
/// coefficients) that the dropped components can make to any output of a pose within the
/// training poses' box.
pub const DEFAULT_TOLERANCE: f32 = 1e-3;

/// Largest stored integer.
const I16_MAX: f32 = i16::MAX as f32;

/// Vertices per block of the stored rows (and lanes of the run time's structure of arrays).
pub const LANES: usize = 64;

/// One output number of a block of vertices, one lane per vertex.
pub type Lanes = [f32; LANES];

/// A pose model re-expressed for fast synthesis (see the module's doc).
#[derive(Clone, Debug)]
pub struct CompactModel {
    /// The model (for its pose features and limits).
    model_shape: PoseModel,
    /// Outputs per vertex (`lobes·7`).
    per_vertex: usize,
    /// Stored rows: the base, then one per kept component.
    rows: usize,
    /// Per kept component: coefficients on the coordinates (`σⱼ·rⱼ / b`, `k` numbers).
    projection: Vec<f32>,
    /// Per row: the factor of its stored integers.
    scale: Vec<f32>,
    /// Block-major `blocks × rows × per_vertex × LANES` integers (the last block padded with
    /// zeros).
    values: Vec<i16>,
    /// Largest change the dropped components and the rounding to integers can make to an
    /// output, for poses within the box.
    bound: f32,
}

impl CompactModel {
    /// Compacts `model`, dropping components whose summed largest change to an output stays
    /// within `tolerance` (≥ 0). Errors when the decomposition fails.
    pub fn new(model: &PoseModel, tolerance: f32) -> Result<Self, PrtError> {
        if tolerance.is_nan() || tolerance < 0.0 {
            return Err(PrtError::Parameter(format!(
                "compaction tolerance {tolerance} (must be ≥ 0)"
            )));
        }
        let m = model.output_len();
        let p = 3 * model.active.len();
        let weights = |row: usize| &model.weights[row * m..(row + 1) * m];
        // The coordinate axes (rows of p numbers) and the mean pose features.
        let limited = !model.limits.range.is_empty() && model.limits.mean.len() == p;
        let (axes, mean, bounds): (Vec<f32>, Vec<f32>, Option<Vec<f32>>) = if limited {
            let l = &model.limits;
            let b = l
                .range
                .iter()
                .map(|[lo, hi]| lo.abs().max(hi.abs()))
                .collect();
            (l.axes.clone(), l.mean.clone(), Some(b))
        } else {
            let identity = (0..p * p)
                .map(|i| if i / p == i % p { 1.0 } else { 0.0 })
                .collect();
            (identity, vec![0.0; p], None)
        };
        let k = axes.len().checked_div(p).unwrap_or(0);
        // base = W₀ + Σ mean·W_x; Cᵢ = Σ aᵢ·W_x, scaled by the bound.
        let combine = |first: Option<&[f32]>, coef: &[f32]| -> Vec<f32> {
            let mut out = first.map_or_else(|| vec![0.0; m], <[f32]>::to_vec);
            out.par_chunks_mut(4096).enumerate().for_each(|(c, chunk)| {
                let base = c * 4096;
                for (j, &a) in coef.iter().enumerate() {
                    if a != 0.0 {
                        let row = &weights(1 + j)[base..base + chunk.len()];
                        for (o, w) in chunk.iter_mut().zip(row) {
                            *o += a * w;
                        }
                    }
                }
            });
            out
        };
        let base = combine(Some(weights(0)), &mean);
        let scale_of = |i: usize| bounds.as_ref().map_or(1.0, |b| b[i].max(1e-30));
        let columns: Vec<Vec<f32>> = (0..k)
            .map(|i| {
                let b = scale_of(i);
                combine(None, &axes[i * p..(i + 1) * p])
                    .into_iter()
                    .map(|x| x * b)
                    .collect()
            })
            .collect();
        let gram = faer::Mat::<f64>::from_fn(k.max(1), k.max(1), |i, j| {
            if k == 0 {
                return 0.0;
            }
            columns[i]
                .par_chunks(8192)
                .zip(columns[j].par_chunks(8192))
                .map(|(a, b)| {
                    a.iter()
                        .zip(b)
                        .map(|(x, y)| *x as f64 * *y as f64)
                        .sum::<f64>()
                })
                .sum()
        });
        let svd = gram
            .thin_svd()
            .map_err(|e| PrtError::Solve(format!("SVD did not converge: {e:?}")))?;
        let (s, r) = (svd.S().column_vector(), svd.U());
        // Per component: σⱼ, qⱼ = D·rⱼ / σⱼ and its bound σⱼ·√k·max|qⱼ|.
        let smax = if k == 0 { 0.0 } else { s[0].max(0.0).sqrt() };
        let mut components: Vec<(f64, Vec<f32>, f32)> = Vec::new();
        for j in 0..k {
            let sigma = s[j].max(0.0).sqrt();
            if sigma <= 1e-7 * smax {
                break;
            }
            let q: Vec<f32> = (0..m)
                .into_par_iter()
                .map(|o| {
                    let dot: f64 = (0..k).map(|i| columns[i][o] as f64 * r[(i, j)]).sum();
                    (dot / sigma) as f32
                })
                .collect();
            let reach = (sigma * (k as f64).sqrt()) as f32 * max_abs(&q);
            components.push((sigma, q, reach));
        }
        // Drop from the smallest while the summed bound stays within the tolerance (only
        // with a box: without one a coordinate is unbounded).
        let mut dropped = 0.0f32;
        if bounds.is_some() {
            while let Some(&(_, _, reach)) = components.last() {
                if dropped + reach > tolerance {
                    break;
                }
                dropped += reach;
                components.pop();
            }
        }
        let projection = components
            .iter()
            .enumerate()
            .flat_map(|(j, (sigma, _, _))| {
                (0..k).map(move |i| (sigma * r[(i, j)] / scale_of(i) as f64) as f32)
            })
            .collect();
        let rows_data: Vec<&[f32]> = std::iter::once(base.as_slice())
            .chain(components.iter().map(|(_, q, _)| q.as_slice()))
            .collect();
        let per_vertex = model.lobes * LOBE_DIM;
        let stride = per_vertex.max(1);
        let rows = rows_data.len();
        let scale: Vec<f32> = rows_data.iter().map(|r| max_abs(r) / I16_MAX).collect();
        let blocks = model.vertices.div_ceil(LANES);
        let block_len = rows * stride * LANES;
        let mut values = vec![0i16; blocks * block_len];
        values
            .par_chunks_mut(block_len)
            .enumerate()
            .for_each(|(b, out)| {
                for (row, (data, &s)) in rows_data.iter().zip(&scale).enumerate() {
                    let out = &mut out[row * stride * LANES..(row + 1) * stride * LANES];
                    for lane in 0..LANES.min(model.vertices - b * LANES) {
                        let v = b * LANES + lane;
                        let src = &data[v * per_vertex..(v + 1) * per_vertex];
                        for (k, x) in src.iter().enumerate() {
                            out[k * LANES + lane] =
                                if s > 0.0 { (x / s).round() as i16 } else { 0 };
                        }
                    }
                }
            });
        // Rounding: half a step per row, times the row's largest factor (1 for the base,
        // σⱼ·√k for a component).
        let rounding: f32 = 0.5 * scale[0]
            + components
                .iter()
                .zip(&scale[1..])
                .map(|((sigma, _, _), s)| 0.5 * s * (*sigma * (k as f64).sqrt()) as f32)
                .sum::<f32>();
        Ok(Self {
            model_shape: PoseModel {
                weights: Vec::new(),
                ..model.clone()
            },
            per_vertex,
            rows,
            projection,
            scale,
            values,
            bound: dropped + rounding,
        })
    }

    /// Vertices.
    pub fn vertices(&self) -> usize {
        self.model_shape.vertices
    }

    /// Stored rows: the base and one per kept component.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// The largest change that the dropped components and the rounding to 16-bit integers
    /// can make to any output, for a pose within the training poses' box (without limits:
    /// the rounding's, for unit pose features).
    pub fn bound(&self) -> f32 {
        self.bound
    }

    /// Size of the stored rows in megabytes (10⁶ bytes).
    pub fn megabytes(&self) -> f64 {
        self.values.len() as f64 * 2.0 / 1e6
    }

    /// Per row, the factor of its stored integers for the pose of these joint rotations
    /// (every skin joint's rotation vector relative to the bind pose).
    pub fn row_factors(&self, joint_rotations: &[Vec3]) -> Vec<f32> {
        let raw = self.model_shape.raw_pose_vector(joint_rotations);
        let features = &raw[1..];
        let coords = self
            .model_shape
            .limits
            .limited_coords(features)
            .unwrap_or_else(|| features.to_vec());
        let k = coords.len();
        std::iter::once(1.0)
            .chain(
                self.projection
                    .chunks_exact(k.max(1))
                    .map(|p| p.iter().zip(&coords).map(|(a, c)| a * c).sum()),
            )
            .zip(&self.scale)
            .map(|(f, s): (f32, &f32)| f * s)
            .collect()
    }

    /// The outputs (`lobes·7` numbers) of vertex `v` for the factors of
    /// [`Self::row_factors`] into `out` (at least that long).
    pub fn vertex_outputs(&self, factors: &[f32], v: usize, out: &mut [f32]) {
        let stride = self.per_vertex.max(1);
        let out = &mut out[..self.per_vertex];
        out.fill(0.0);
        let (block, lane) = (v / LANES, v % LANES);
        let rows = &self.values[block * self.rows * stride * LANES..][..self.rows * stride * LANES];
        for (row, &f) in rows.chunks_exact(stride * LANES).zip(factors) {
            for (k, o) in out.iter_mut().enumerate() {
                *o += f * row[k * LANES + lane] as f32;
            }
        }
    }

    /// Blocks of [`LANES`] vertices (the last one possibly partial).
    pub fn blocks(&self) -> usize {
        self.vertices().div_ceil(LANES)
    }

    /// The outputs of the vertices of block `block` for the factors of
    /// [`Self::row_factors`] into `out` (`lobes·7` arrays, one per output number, one lane per
    /// vertex; lanes past the last vertex are 0).
    #[inline(always)]
    pub fn synthesise_block(&self, factors: &[f32], block: usize, out: &mut [Lanes]) {
        let len = self.per_vertex * LANES;
        let out = &mut out.as_flattened_mut()[..len];
        out.fill(0.0);
        let stride = self.per_vertex.max(1) * LANES;
        let rows = &self.values[block * self.rows * stride..][..self.rows * stride];
        for (row, &f) in rows.chunks_exact(stride).zip(factors) {
            for (o, &x) in out.iter_mut().zip(&row[..len]) {
                *o += f * x as f32;
            }
        }
    }

    /// All outputs (`vertices·lobes·7`, as [`PoseModel::predict_raw`] gives them) for the
    /// pose of these joint rotations into `out`, on the calling rayon pool.
    pub fn predict(&self, joint_rotations: &[Vec3], out: &mut Vec<f32>) {
        let factors = self.row_factors(joint_rotations);
        let per = self.per_vertex;
        out.resize(self.vertices() * per, 0.0);
        if per == 0 {
            return;
        }
        out.par_chunks_mut(per * LANES).enumerate().for_each_init(
            || vec![[0.0f32; LANES]; per],
            |lanes, (b, chunk)| {
                self.synthesise_block(&factors, b, lanes);
                for (lane, o) in chunk.chunks_mut(per).enumerate() {
                    for (k, o) in o.iter_mut().enumerate() {
                        *o = lanes[k][lane];
                    }
                }
            },
        );
    }

    /// Outputs per vertex (`lobes·7`).
    pub fn outputs_per_vertex(&self) -> usize {
        self.per_vertex
    }

    /// The model without its weights (counts, joints, limits).
    pub fn shape(&self) -> &PoseModel {
        &self.model_shape
    }
}

/// The largest absolute value (0 when empty).
fn max_abs(v: &[f32]) -> f32 {
    v.iter().fold(0.0f32, |a, x| a.max(x.abs()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::limits::PoseLimits;

    /// Two vertices, one lobe, two active joints; limits with two axes in the 6 features.
    fn model(limited: bool) -> PoseModel {
        let out = 2 * LOBE_DIM;
        let weights = (0..7 * out)
            .map(|i| ((i * 2_654_435_761usize) % 1000) as f32 / 1000.0 - 0.5)
            .collect();
        let limits = if limited {
            let s = 0.5f32.sqrt();
            PoseLimits {
                mean: vec![0.1, 0.0, -0.2, 0.0, 0.3, 0.0],
                axes: vec![
                    s, s, 0.0, 0.0, 0.0, 0.0, //
                    0.0, 0.0, 0.0, 1.0, 0.0, 0.0,
                ],
                range: vec![[-0.5, 0.4], [-0.1, 0.2]],
                scale: vec![0.3, 0.1],
                radius: 3.0,
            }
        } else {
            PoseLimits::default()
        };
        PoseModel {
            character: "t".into(),
            vertices: 2,
            joints: 2,
            lobes: 1,
            active: vec![0, 1],
            weights,
            limits,
        }
    }

    fn outputs(c: &CompactModel, rotations: &[Vec3]) -> Vec<f32> {
        let mut out = Vec::new();
        c.predict(rotations, &mut out);
        out
    }

    #[test]
    fn the_compact_model_predicts_what_the_model_predicts() {
        for limited in [false, true] {
            let m = model(limited);
            let c = CompactModel::new(&m, 0.0).unwrap();
            assert_eq!(c.rows(), 1 + if limited { 2 } else { 6 });
            for rot in [
                [Vec3::new(0.1, -0.3, 0.2), Vec3::new(0.0, 0.05, 0.4)],
                [Vec3::new(2.0, 1.0, -1.0), Vec3::ZERO],
            ] {
                let mut want = Vec::new();
                m.predict_raw(&m.pose_vector(&rot), &mut want);
                let got = outputs(&c, &rot);
                let worst = got
                    .iter()
                    .zip(&want)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0f32, f32::max);
                assert!(worst < 1e-3, "limited {limited}: {worst}");
                if limited {
                    assert!(worst <= c.bound() + 1e-6, "{worst} > bound {}", c.bound());
                }
            }
        }
    }

    #[test]
    fn a_tolerance_drops_components_within_their_bound() {
        let m = model(true);
        let full = CompactModel::new(&m, 0.0).unwrap();
        let cut = CompactModel::new(&m, 10.0).unwrap();
        assert_eq!(cut.rows(), 1, "everything fits in a tolerance of 10");
        let rot = [Vec3::new(0.1, -0.3, 0.2), Vec3::new(0.0, 0.05, 0.4)];
        let worst = outputs(&full, &rot)
            .iter()
            .zip(outputs(&cut, &rot))
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        assert!(worst <= cut.bound() + 1e-6, "{worst} > {}", cut.bound());
        assert!(CompactModel::new(&m, -1.0).is_err());
    }
}
