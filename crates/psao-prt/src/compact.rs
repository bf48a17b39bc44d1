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
//! `σⱼ·√k·max|qⱼ|` (a model without limits has no box: it keeps every component, at 16 bits).
//!
//! The rows (base and components) are stored in blocks of [`LANES`] vertices, and each block
//! keeps only what its own vertices need: component j changes an output of block b by at
//! most `c_bj = σⱼ·√k·max_b|qⱼ|` (the maximum over the block's vertices), so per block the
//! components are sorted by `c_bj` and the smallest dropped, the next stored as 8-bit and the
//! rest as 16-bit integers (one factor per block and row; the base always 16-bit), choosing
//! how many of each to store the fewest bytes while the block's summed bound, dropped
//! changes plus rounding (half a step times the row's largest factor), stays within the
//! tolerance (with tolerance 0 only rows that change nothing in the block are dropped, and
//! nothing is 8-bit). Much of a character barely moves with the pose; its blocks keep few
//! rows. A frame synthesises a block's lobes ([`CompactModel::synthesise_block`]) by reading
//! its stored rows once, in order, into one array per output number (a structure of arrays
//! that the shading's lane loops read directly), right before shading it.

use crate::model::{PoseModel, LOBE_DIM};
use crate::PrtError;
use glam::Vec3;
use rayon::prelude::*;

/// Default largest change (in the model's output units: axis components and zonal
/// coefficients) that the dropped components and the rounding can make to any output of a
/// pose within the training poses' box.
pub const DEFAULT_TOLERANCE: f32 = 1e-3;

/// Largest stored 16-bit integer.
const I16_MAX: f32 = i16::MAX as f32;

/// Largest stored 8-bit integer.
const I8_MAX: f32 = i8::MAX as f32;

/// Vertices per block of the stored rows (and lanes of the run time's structure of arrays).
pub const LANES: usize = 64;

/// One output number of a block of vertices, one lane per vertex.
pub type Lanes = [f32; LANES];

/// How a block stores one of its rows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Width {
    /// 16-bit integers.
    Wide,
    /// 8-bit integers.
    Narrow,
}

/// One row stored for one block: `outputs per vertex × LANES` integers.
#[derive(Clone, Copy, Debug)]
struct Stored {
    /// The row: 0 the base, j + 1 component j.
    row: u32,
    width: Width,
    /// Where its integers start in `wide` or `narrow`.
    offset: u32,
    /// The factor of its integers.
    scale: f32,
}

/// A pose model re-expressed for fast synthesis (see the module's doc).
#[derive(Clone, Debug)]
pub struct CompactModel {
    /// The model (for its pose features and limits).
    model_shape: PoseModel,
    /// Outputs per vertex (`lobes·7`).
    per_vertex: usize,
    /// Rows: the base, then one per component.
    rows: usize,
    /// Per component: coefficients on the coordinates (`σⱼ·rⱼ / b`, `k` numbers).
    projection: Vec<f32>,
    /// Per block, the rows it stores (from `block_start[b]` to `block_start[b + 1]`).
    stored: Vec<Stored>,
    block_start: Vec<u32>,
    /// The 16-bit and the 8-bit rows' integers, block-major, each row `per_vertex × LANES`
    /// (lanes past the last vertex are 0).
    wide: Vec<i16>,
    narrow: Vec<i8>,
    /// Largest change the dropped rows and the rounding to integers can make to an output,
    /// for poses within the box.
    bound: f32,
}

/// One block's rows before they are laid out: per stored row its number, factor and
/// integers (16-bit or 8-bit), and the block's bound.
struct BlockRows {
    wide: Vec<(u32, f32, Vec<i16>)>,
    narrow: Vec<(u32, f32, Vec<i8>)>,
    bound: f32,
}

/// Appends a block's rows of one width to that width's `values`, each row's place in
/// `stored`.
fn lay_out<T>(
    rows: Vec<(u32, f32, Vec<T>)>,
    width: Width,
    values: &mut Vec<T>,
    stored: &mut Vec<Stored>,
) {
    for (row, scale, data) in rows {
        stored.push(Stored {
            row,
            width,
            offset: values.len() as u32,
            scale,
        });
        values.extend(data);
    }
}

impl CompactModel {
    /// Compacts `model`, storing per block the fewest bytes whose summed largest change to
    /// an output (dropped rows and rounding) stays within `tolerance` (≥ 0; module doc).
    /// Errors when the decomposition fails.
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
        // Per component: σⱼ and qⱼ = D·rⱼ / σⱼ.
        let smax = if k == 0 { 0.0 } else { s[0].max(0.0).sqrt() };
        let mut components: Vec<(f64, Vec<f32>)> = Vec::new();
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
            components.push((sigma, q));
        }
        let projection = components
            .iter()
            .enumerate()
            .flat_map(|(j, (sigma, _))| {
                (0..k).map(move |i| (sigma * r[(i, j)] / scale_of(i) as f64) as f32)
            })
            .collect();
        // Each component's largest factor: σⱼ·√k within the box (|cᵢ| ≤ bᵢ); without a
        // box a coordinate is unbounded (the bound is then for unit pose features) and
        // every row is kept at 16 bits.
        let factor_bound: Vec<f32> = components
            .iter()
            .map(|(sigma, _)| (sigma * (k as f64).sqrt()) as f32)
            .collect();
        let reducible = bounds.is_some();
        let rows_data: Vec<&[f32]> = std::iter::once(base.as_slice())
            .chain(components.iter().map(|(_, q)| q.as_slice()))
            .collect();
        let per_vertex = model.lobes * LOBE_DIM;
        let blocks = model.vertices.div_ceil(LANES);
        let block_rows: Vec<BlockRows> = (0..blocks)
            .into_par_iter()
            .map(|b| {
                let lanes = LANES.min(model.vertices - b * LANES);
                let data =
                    |row: usize| &rows_data[row][b * LANES * per_vertex..][..lanes * per_vertex];
                let bound = reducible.then_some(tolerance);
                compact_block(data, rows_data.len(), &factor_bound, bound, per_vertex)
            })
            .collect();
        // Lay the blocks out one after the other.
        let (mut stored, mut block_start) = (Vec::new(), vec![0u32]);
        let (mut wide, mut narrow) = (Vec::new(), Vec::new());
        let mut bound = 0.0f32;
        for block in block_rows {
            lay_out(block.wide, Width::Wide, &mut wide, &mut stored);
            lay_out(block.narrow, Width::Narrow, &mut narrow, &mut stored);
            block_start.push(stored.len() as u32);
            bound = bound.max(block.bound);
        }
        Ok(Self {
            model_shape: PoseModel {
                weights: Vec::new(),
                ..model.clone()
            },
            per_vertex,
            rows: rows_data.len(),
            projection,
            stored,
            block_start,
            wide,
            narrow,
            bound,
        })
    }

    /// Vertices.
    pub fn vertices(&self) -> usize {
        self.model_shape.vertices
    }

    /// Rows: the base and one per component of the pose's change.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// The rows stored per block, on average (16- and 8-bit).
    pub fn stored_rows(&self) -> f64 {
        self.stored.len() as f64 / self.blocks().max(1) as f64
    }

    /// The largest change that the dropped rows and the rounding to integers can make to
    /// any output, for a pose within the training poses' box (without limits: the
    /// rounding's, for unit pose features).
    pub fn bound(&self) -> f32 {
        self.bound
    }

    /// Size of the stored rows in megabytes (10⁶ bytes): their integers and, per stored
    /// row of a block, its factor.
    pub fn megabytes(&self) -> f64 {
        (self.wide.len() * 2 + self.narrow.len() + self.stored.len() * 4) as f64 / 1e6
    }

    /// Per row, the factor of its values for the pose of these joint rotations (every skin
    /// joint's rotation vector relative to the bind pose): 1 for the base, then the
    /// components' coordinates.
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
            .collect()
    }

    /// The rows block `block` stores.
    fn stored_of(&self, block: usize) -> &[Stored] {
        &self.stored[self.block_start[block] as usize..self.block_start[block + 1] as usize]
    }

    /// The outputs (`lobes·7` numbers) of vertex `v` for the factors of
    /// [`Self::row_factors`] into `out` (at least that long).
    pub fn vertex_outputs(&self, factors: &[f32], v: usize, out: &mut [f32]) {
        let out = &mut out[..self.per_vertex];
        out.fill(0.0);
        let (block, lane) = (v / LANES, v % LANES);
        for s in self.stored_of(block) {
            let f = factors[s.row as usize] * s.scale;
            let at = s.offset as usize + lane;
            for (k, o) in out.iter_mut().enumerate() {
                let x = match s.width {
                    Width::Wide => self.wide[at + k * LANES] as f32,
                    Width::Narrow => self.narrow[at + k * LANES] as f32,
                };
                *o += f * x;
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
        let stored = self.stored_of(block);
        if stored.is_empty() {
            out.fill(0.0);
        }
        // The first stored row is written, the others added (no clearing pass).
        for (r, s) in stored.iter().enumerate() {
            let f = factors[s.row as usize] * s.scale;
            let at = s.offset as usize;
            match s.width {
                Width::Wide => scale_row_into(out, &self.wide[at..at + len], f, r == 0),
                Width::Narrow => scale_row_into(out, &self.narrow[at..at + len], f, r == 0),
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

/// One block's rows (`data(row)`: its vertices' outputs of that row, `per_vertex` each;
/// `rows` rows, the base first): which to drop, store as 8-bit or as 16-bit (module doc),
/// given each component's largest factor and the tolerance (`None`: coordinates are
/// unbounded, every row is stored at 16 bits).
fn compact_block<'a>(
    data: impl Fn(usize) -> &'a [f32],
    rows: usize,
    factor_bound: &[f32],
    tolerance: Option<f32>,
    per_vertex: usize,
) -> BlockRows {
    let base_max = max_abs(data(0));
    let base_rounding = 0.5 * base_max / I16_MAX;
    // Components by their largest change to this block's outputs, smallest first.
    let mut changes: Vec<(usize, f32)> = (1..rows)
        .map(|row| (row, factor_bound[row - 1] * max_abs(data(row))))
        .collect();
    changes.sort_by(|a, b| a.1.total_cmp(&b.1));
    let n = changes.len();
    // Prefix sums of the changes (f64: the totals are compared with the tolerance).
    let mut prefix = vec![0.0f64; n + 1];
    for (i, (_, c)) in changes.iter().enumerate() {
        prefix[i + 1] = prefix[i] + *c as f64;
    }
    let rounding =
        |bits_max: f32, from: usize, to: usize| (prefix[to] - prefix[from]) * 0.5 / bits_max as f64;
    // The d smallest dropped, the next e 8-bit, the rest 16-bit.
    let bound_of = |d: usize, e: usize| {
        base_rounding as f64 + prefix[d] + rounding(I8_MAX, d, d + e) + rounding(I16_MAX, d + e, n)
    };
    // Rows that change nothing here are dropped whatever the tolerance.
    let zeros = changes.iter().take_while(|(_, c)| *c == 0.0).count();
    let mut best = (zeros, 0usize);
    if let Some(tolerance) = tolerance {
        let limit = (tolerance as f64).max(bound_of(zeros, 0));
        // Dropping more than fits stops the search (the dropped changes only grow).
        let droppable = (zeros..=n).take_while(|&d| prefix[d] + (base_rounding as f64) <= limit);
        for d in droppable {
            // The most 8-bit rows that fit after dropping d.
            let e = (0..=n - d)
                .rev()
                .find(|&e| bound_of(d, e) <= limit)
                .unwrap_or(0);
            let saved = |(d, e): (usize, usize)| 2 * d + e;
            if saved((d, e)) > saved(best) && bound_of(d, e) <= limit {
                best = (d, e);
            }
        }
    }
    let (d, e) = best;
    let quantise = |row: usize, top: f32| -> (f32, Vec<f32>) {
        let values = data(row);
        let scale = max_abs(values) / top;
        let mut out = vec![0.0f32; per_vertex * LANES];
        for (lane, v) in values.chunks_exact(per_vertex.max(1)).enumerate() {
            for (k, x) in v.iter().enumerate() {
                out[k * LANES + lane] = if scale > 0.0 {
                    (x / scale).round()
                } else {
                    0.0
                };
            }
        }
        (scale, out)
    };
    let mut block = BlockRows {
        wide: Vec::new(),
        narrow: Vec::new(),
        bound: bound_of(d, e) as f32,
    };
    let (scale, values) = quantise(0, I16_MAX);
    block
        .wide
        .push((0, scale, values.iter().map(|&x| x as i16).collect()));
    for (i, &(row, _)) in changes.iter().enumerate().skip(d) {
        if i < d + e {
            let (scale, values) = quantise(row, I8_MAX);
            block
                .narrow
                .push((row as u32, scale, values.iter().map(|&x| x as i8).collect()));
        } else {
            let (scale, values) = quantise(row, I16_MAX);
            block.wide.push((
                row as u32,
                scale,
                values.iter().map(|&x| x as i16).collect(),
            ));
        }
    }
    block
}

/// The largest absolute value (0 when empty).
fn max_abs(v: &[f32]) -> f32 {
    v.iter().fold(0.0f32, |a, x| a.max(x.abs()))
}

/// `out = f · row` when `first`, else `out += f · row`, element by element (a stored row of
/// either width into a block's outputs).
#[inline(always)]
fn scale_row_into<T: Copy + Into<f32>>(out: &mut [f32], row: &[T], f: f32, first: bool) {
    if first {
        for (o, &x) in out.iter_mut().zip(row) {
            *o = f * x.into();
        }
    } else {
        for (o, &x) in out.iter_mut().zip(row) {
            *o += f * x.into();
        }
    }
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
        assert_eq!(cut.rows(), 3);
        assert_eq!(full.stored_rows(), 3.0);
        assert_eq!(
            cut.stored_rows(),
            1.0,
            "everything fits in a tolerance of 10"
        );
        let rot = [Vec3::new(0.1, -0.3, 0.2), Vec3::new(0.0, 0.05, 0.4)];
        let worst = outputs(&full, &rot)
            .iter()
            .zip(outputs(&cut, &rot))
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        assert!(worst <= cut.bound() + 1e-6, "{worst} > {}", cut.bound());
        assert!(CompactModel::new(&m, -1.0).is_err());
    }

    #[test]
    fn each_block_keeps_what_its_vertices_need_within_the_tolerance() {
        // 130 vertices in 3 blocks; the pose moves only the first block's vertices, and the
        // second component barely.
        let vertices = 130;
        let out = vertices * LOBE_DIM;
        let mut weights = vec![0.0f32; 7 * out];
        for (i, w) in weights.iter_mut().enumerate() {
            let (row, col) = (i / out, i % out);
            let hash = ((i * 2_654_435_761usize) % 1000) as f32 / 1000.0 - 0.5;
            *w = match row {
                0 => hash + 1.0,
                _ if col >= LANES * LOBE_DIM => 0.0,
                4 => 1e-3 * hash,
                _ => hash,
            };
        }
        let m = PoseModel {
            vertices,
            weights,
            ..model(true)
        };
        let exact = CompactModel::new(&m, 0.0).unwrap();
        let loose = CompactModel::new(&m, 1e-2).unwrap();
        // Blocks 1 and 2 store the base alone, whatever the tolerance.
        assert_eq!(exact.stored_of(1).len(), 1);
        assert_eq!(exact.stored_of(2).len(), 1);
        assert!(exact.stored_of(0).iter().all(|s| s.width == Width::Wide));
        assert!(loose.megabytes() < exact.megabytes());
        assert!(
            loose.bound() <= 1e-2 && exact.bound() < 1e-4,
            "{} {}",
            loose.bound(),
            exact.bound()
        );
        for rot in [
            [Vec3::new(0.1, -0.3, 0.2), Vec3::new(0.0, 0.05, 0.4)],
            [Vec3::new(-0.4, 0.1, 0.0), Vec3::new(0.3, 0.2, -0.1)],
        ] {
            let mut want = Vec::new();
            m.predict_raw(&m.pose_vector(&rot), &mut want);
            for c in [&exact, &loose] {
                let got = outputs(c, &rot);
                let worst = got
                    .iter()
                    .zip(&want)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0f32, f32::max);
                assert!(worst <= c.bound() + 1e-6, "{worst} > bound {}", c.bound());
                // One vertex at a time gives the same.
                let factors = c.row_factors(&rot);
                let mut one = [0.0f32; LOBE_DIM];
                c.vertex_outputs(&factors, 65, &mut one);
                assert_eq!(one.as_slice(), &got[65 * LOBE_DIM..66 * LOBE_DIM]);
            }
        }
    }
}
