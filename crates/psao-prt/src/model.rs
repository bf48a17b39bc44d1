//! The linear pose model: joint rotations → zonal lobes per vertex (paper §3.1).
//!
//! Pose vector `a` = the rotation vectors (axis × angle) of the active joints' local
//! rotations relative to the bind pose, 3 numbers per joint, plus a constant. Per vertex and
//! lobe the model predicts 7 numbers: the axis as a 3-vector (normalised after prediction)
//! and the 4 zonal coefficients. Why a 3-vector and not the paper's 2 angles: angles wrap
//! (φ jumps by 2π) and are singular at the poles, so a lobe moving smoothly can have
//! angles that jump, which no linear model fits; the 3 components vary as smoothly as the
//! lobe. Training solves `A·X = B` in least squares with faer (thin SVD of the centred
//! pose matrix, so every ridge value costs one product), the ridge chosen by blocked
//! cross-validation: the time-ordered training frames are cut into contiguous blocks, each
//! block is predicted by a model trained on the others, and the ridge with the lowest SH
//! visibility error over all blocks is kept. A held-out block is a stretch of poses the
//! model never saw, as in use; frames between training frames would reward a model that
//! interpolates well and extrapolates wildly (no ridge). The same blocks then choose, per
//! vertex, how much of the pose-dependent part to keep ([`crate::shrink`]), and the model
//! keeps poses within the training poses' limits ([`crate::limits`]).

use glam::Vec3;
use rayon::prelude::*;

use crate::fit::{fit_lobes, fit_sequence, rms_difference};
pub use crate::limits::PoseLimits;
use crate::sh::ShVec;
use crate::shrink::{shrink_towards_mean, ShrinkErrors};
use crate::zonal::ZhLobe;
use crate::PrtError;

/// Numbers per lobe in the model's output: axis (3) + zonal coefficients (4).
pub const LOBE_DIM: usize = 7;

/// Joints whose rotation varies less than this (radians, std over training) are left out.
const ACTIVE_JOINT_STD: f32 = 1e-4;

/// Ridge candidates, relative to the largest squared singular value of the pose matrix.
const RIDGE_GRID: [f64; 9] = [0.0, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 3e-2, 1e-1, 1.0];

/// Rounds at most of refitting the lobes from the model's own prediction (see [`train`]).
const REFIT_ROUNDS: usize = 1;

/// Contiguous blocks of the training frames in the ridge's cross-validation.
const FOLDS: usize = 4;

/// One posed frame of training or validation data.
#[derive(Clone, Debug)]
pub struct Sample {
    /// Rotation vector of every skin joint (relative to the bind pose).
    pub joint_rotations: Vec<Vec3>,
    /// SH visibility per vertex in its local frame.
    pub visibility: Vec<ShVec>,
}

/// What training measured.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainReport {
    /// Mean and standard deviation over training vertices×frames of the direct lobe fit's
    /// RMS error over the sphere.
    pub lobe_fit_error: (f32, f32),
    /// Per ridge candidate (relative to the largest squared singular value of the pose
    /// matrix): mean RMS SH error on the held-out blocks of the cross-validation.
    pub ridge_errors: Vec<(f64, f32)>,
    /// The chosen ridge (relative, as in `ridge_errors`).
    pub ridge: f64,
    /// Mean RMS SH error of the model on the validation frames (0 without them).
    pub validation_error: f32,
    /// Per vertex: the factor of the pose-dependent part chosen by cross-validation (see
    /// [`crate::shrink`]), folded into the returned model.
    pub vertex_shrink: Vec<f32>,
    /// The returned model before the per-vertex shrink (to measure what it does).
    pub unshrunk: PoseModel,
}

/// A trained linear pose model for one character.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseModel {
    /// Name of the character it was trained on.
    pub character: String,
    /// Vertex count of that character.
    pub vertices: usize,
    /// Skin joint count of that character.
    pub joints: usize,
    /// Lobes per vertex.
    pub lobes: usize,
    /// Skin joint indices whose rotations form the pose vector.
    pub active: Vec<u32>,
    /// Row-major `(1 + 3·active) × (vertices·lobes·7)`: row 0 is the constant.
    pub weights: Vec<f32>,
    /// Where training's poses lie (empty: poses are not limited).
    pub limits: PoseLimits,
}

impl PoseModel {
    /// Length of the pose vector (constant included).
    pub fn pose_len(&self) -> usize {
        1 + 3 * self.active.len()
    }

    /// Outputs per frame.
    pub fn output_len(&self) -> usize {
        self.vertices * self.lobes * LOBE_DIM
    }

    /// The pose vector for all skin joints' rotation vectors, moved within the training
    /// poses' limits (see [`PoseLimits`]).
    pub fn pose_vector(&self, joint_rotations: &[Vec3]) -> Vec<f32> {
        let mut a = self.raw_pose_vector(joint_rotations);
        self.limits.apply(&mut a[1..]);
        a
    }

    /// The pose vector as the rotations give it, not limited.
    pub fn raw_pose_vector(&self, joint_rotations: &[Vec3]) -> Vec<f32> {
        features(&self.active, joint_rotations)
    }

    /// Raw predicted outputs (`vertices·lobes·7` numbers) for `pose` (from
    /// [`Self::pose_vector`]) into `out`: one matrix-vector product on all threads.
    pub fn predict_raw(&self, pose: &[f32], out: &mut Vec<f32>) {
        let n = self.output_len();
        out.resize(n, 0.0);
        const CHUNK: usize = 4096;
        out.par_chunks_mut(CHUNK)
            .enumerate()
            .for_each(|(c, chunk)| {
                let base = c * CHUNK;
                chunk.fill(0.0);
                for (k, &a) in pose.iter().enumerate() {
                    let row = &self.weights[k * n + base..k * n + base + chunk.len()];
                    for (o, w) in chunk.iter_mut().zip(row) {
                        *o += a * w;
                    }
                }
            });
    }

    /// The lobes of vertex `v` from raw outputs (axes normalised; a vanishing axis becomes +z).
    pub fn lobes_of(&self, raw: &[f32], v: usize, out: &mut Vec<ZhLobe>) {
        out.clear();
        let base = v * self.lobes * LOBE_DIM;
        for x in 0..self.lobes {
            let p = &raw[base + x * LOBE_DIM..base + (x + 1) * LOBE_DIM];
            out.push(unpack_lobe(p));
        }
    }

    /// Size of the weights in megabytes (10⁶ bytes).
    pub fn megabytes(&self) -> f64 {
        self.weights.len() as f64 * 4.0 / 1e6
    }
}

/// A lobe from its 7 model numbers.
pub fn unpack_lobe(p: &[f32]) -> ZhLobe {
    ZhLobe {
        axis: Vec3::new(p[0], p[1], p[2]).normalize_or(Vec3::Z),
        coeffs: [p[3], p[4], p[5], p[6]],
    }
}

fn pack_lobe(l: &ZhLobe, out: &mut [f32]) {
    out[..3].copy_from_slice(&l.axis.to_array());
    out[3..7].copy_from_slice(&l.coeffs);
}

/// Mean and standard deviation.
pub fn mean_std(values: impl Iterator<Item = f32>) -> (f32, f32) {
    let (mut n, mut s, mut s2) = (0.0f64, 0.0f64, 0.0f64);
    for v in values {
        n += 1.0;
        s += v as f64;
        s2 += (v as f64) * (v as f64);
    }
    if n == 0.0 {
        return (0.0, 0.0);
    }
    let mean = s / n;
    (
        (mean) as f32,
        ((s2 / n - mean * mean).max(0.0)).sqrt() as f32,
    )
}

/// Fits `lobes` lobes per vertex to the time-ordered `train` frames (in correspondence) and
/// solves the linear model, choosing the ridge by blocked cross-validation over `train`
/// (see the module's doc); `validate` frames are only measured. `progress(done, total)` is
/// called as vertices finish fitting.
pub fn train(
    character: &str,
    train: &[Sample],
    validate: &[Sample],
    lobes: usize,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<(PoseModel, TrainReport), PrtError> {
    let frames = train.len();
    if frames < 2 {
        return Err(PrtError::Parameter(format!(
            "need at least 2 training frames, got {frames}"
        )));
    }
    if !(1..=3).contains(&lobes) {
        return Err(PrtError::Parameter(format!(
            "lobes must be 1, 2 or 3, got {lobes}"
        )));
    }
    let vertices = train[0].visibility.len();
    let joints = train[0].joint_rotations.len();
    if train
        .iter()
        .chain(validate)
        .any(|s| s.visibility.len() != vertices || s.joint_rotations.len() != joints)
    {
        return Err(PrtError::Parameter(
            "frames differ in vertex or joint count".into(),
        ));
    }
    let active = active_joints(train);

    // Lobes per vertex over the training frames, in correspondence.
    let out_dim = lobes * LOBE_DIM;
    let done = std::sync::atomic::AtomicUsize::new(0);
    let mut fits: Vec<VertexFits> = (0..vertices)
        .into_par_iter()
        .map(|v| {
            let seq: Vec<ShVec> = train.iter().map(|s| s.visibility[v]).collect();
            let fits = VertexFits::pack(&fit_sequence(&seq, lobes), out_dim);
            let d = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            if d % 64 == 0 || d == vertices {
                progress(d, vertices);
            }
            fits
        })
        .collect();
    let shape = Shape {
        character,
        vertices,
        joints,
        lobes,
        active: &active,
    };
    let mut best = solve(train, &shape, &fits)?;
    let mut lobe_fit_error = mean_std(fits.iter().flat_map(|f| f.errors.iter().copied()));
    // Refit rounds: each frame's lobes again, started from (and pulled towards) the model's
    // own prediction at that frame's pose instead of the previous frame's lobes, then the
    // model solved again. A lobe that the frame-to-frame fit let jump or swap roles with
    // another is moved back to what a linear function of the pose can follow (block
    // coordinate descent on fit error + closeness to a linear model). A round is kept only
    // if it lowers the cross-validated error.
    if lobes > 1 {
        for _ in 0..REFIT_ROUNDS {
            let predictions: Vec<Vec<f32>> = train
                .iter()
                .map(|s| {
                    let mut raw = Vec::new();
                    best.model
                        .predict_raw(&best.model.pose_vector(&s.joint_rotations), &mut raw);
                    raw
                })
                .collect();
            let refits: Vec<VertexFits> = (0..vertices)
                .into_par_iter()
                .map_init(Vec::new, |predicted, v| {
                    let per_frame: Vec<(Vec<ZhLobe>, f32)> = train
                        .iter()
                        .zip(&predictions)
                        .map(|(s, raw)| {
                            best.model.lobes_of(raw, v, predicted);
                            let axes: Vec<Vec3> = predicted.iter().map(|l| l.axis).collect();
                            fit_lobes(&s.visibility[v], lobes, Some(&axes))
                        })
                        .collect();
                    VertexFits::pack(&per_frame, out_dim)
                })
                .collect();
            let candidate = solve(train, &shape, &refits)?;
            if candidate.cv_error >= best.cv_error {
                break;
            }
            best = candidate;
            fits = refits;
            lobe_fit_error = mean_std(fits.iter().flat_map(|f| f.errors.iter().copied()));
        }
    }
    let vertex_shrink = cross_validate_shrink(train, &shape, &fits, best.ridge)?;
    let model = shrink_towards_mean(&best.model, &vertex_shrink)?;
    let validation_error = if validate.is_empty() {
        0.0
    } else {
        model_error(&model, validate).0
    };
    Ok((
        model,
        TrainReport {
            lobe_fit_error,
            ridge_errors: best.ridge_errors,
            ridge: best.ridge,
            validation_error,
            vertex_shrink,
            unshrunk: best.model,
        },
    ))
}

/// Per vertex, the factor of [`crate::shrink::SHRINK_GRID`] whose shrunk prediction has the least error
/// on the blocks of the same blocked cross-validation as the ridge's, with ridge
/// `relative`.
fn cross_validate_shrink(
    train: &[Sample],
    shape: &Shape,
    fits: &[VertexFits],
    relative: f64,
) -> Result<Vec<f32>, PrtError> {
    let mut errors = ShrinkErrors::new(shape.vertices, shape.lobes);
    let (mut raw, mut mean) = (Vec::new(), Vec::new());
    for (held, rest) in folds(train.len()) {
        let solver = Solver::new(train, shape.active, &rest)?;
        let model = solver.model(shape, fits, relative);
        let at_mean: Vec<f32> = std::iter::once(1.0)
            .chain(solver.mean_a.iter().map(|&m| m as f32))
            .collect();
        model.predict_raw(&at_mean, &mut mean);
        for s in &train[held] {
            model.predict_raw(&model.pose_vector(&s.joint_rotations), &mut raw);
            errors.add(&mean, &raw, &s.visibility);
        }
    }
    Ok(errors.choose())
}

/// The blocks of the blocked cross-validation over `frames` time-ordered frames: each
/// held-out block with the frames left to train on ([`FOLDS`] blocks, fewer when there are
/// under `2·FOLDS` frames; at least 2, each leaving at least 2 to train on).
fn folds(frames: usize) -> Vec<(std::ops::Range<usize>, Vec<usize>)> {
    let folds = FOLDS.min(frames / 2).max(2).min(frames);
    (0..folds)
        .map(|k| k * frames / folds..(k + 1) * frames / folds)
        .filter(|held| !held.is_empty())
        .map(|held| {
            let rest: Vec<usize> = (0..frames).filter(|f| !held.contains(f)).collect();
            (held, rest)
        })
        .filter(|(_, rest)| rest.len() >= 2)
        .collect()
}

/// The model of `fits` over all of `train` with the ridge that cross-validates best.
fn solve(train: &[Sample], shape: &Shape, fits: &[VertexFits]) -> Result<Solved, PrtError> {
    let ridge_errors = cross_validate(train, shape, fits)?;
    let (ridge, cv_error) = ridge_errors
        .iter()
        .copied()
        .fold(None, |b: Option<(f64, f32)>, (r, e)| match b {
            Some((_, be)) if be <= e => b,
            _ => Some((r, e)),
        })
        .expect("the ridge grid is not empty");
    let all: Vec<usize> = (0..train.len()).collect();
    let solver = Solver::new(train, shape.active, &all)?;
    let model = solver.model(shape, fits, ridge);
    Ok(Solved {
        model,
        ridge_errors,
        ridge,
        cv_error,
    })
}

/// Per ridge of [`RIDGE_GRID`]: the mean RMS SH error over the frames of every contiguous
/// block of `train` predicted by the model trained on the other blocks ([`FOLDS`] blocks,
/// fewer when there are under `2·FOLDS` frames; at least 2).
fn cross_validate(
    train: &[Sample],
    shape: &Shape,
    fits: &[VertexFits],
) -> Result<Vec<(f64, f32)>, PrtError> {
    let mut sums = vec![0.0f64; RIDGE_GRID.len()];
    let mut count = 0usize;
    for (held, rest) in folds(train.len()) {
        let solver = Solver::new(train, shape.active, &rest)?;
        let prepared = solver.prepare_lobes(shape, fits);
        for (sum, &rel) in sums.iter_mut().zip(&RIDGE_GRID) {
            let model = solver.lobe_model(shape, &prepared, rel);
            *sum += model_errors(&model, &train[held.clone()])
                .iter()
                .map(|&e| e as f64)
                .sum::<f64>();
        }
        count += held.len() * shape.vertices;
    }
    Ok(RIDGE_GRID
        .iter()
        .zip(sums)
        .map(|(&r, s)| (r, (s / count.max(1) as f64) as f32))
        .collect())
}

/// One vertex's fitted lobes over the training frames, packed `frames × (lobes·7)`, and
/// the fit's RMS error over the sphere per frame.
struct VertexFits {
    packed: Vec<f32>,
    errors: Vec<f32>,
}

impl VertexFits {
    fn pack(fits: &[(Vec<ZhLobe>, f32)], out_dim: usize) -> Self {
        let mut packed = vec![0.0f32; fits.len() * out_dim];
        for (f, (ls, _)) in fits.iter().enumerate() {
            for (x, l) in ls.iter().enumerate() {
                pack_lobe(l, &mut packed[f * out_dim + x * LOBE_DIM..]);
            }
        }
        let errors = fits
            .iter()
            .map(|(_, e)| e / (4.0 * std::f32::consts::PI).sqrt())
            .collect();
        Self { packed, errors }
    }
}

/// What every model of one training run shares.
struct Shape<'a> {
    character: &'a str,
    vertices: usize,
    joints: usize,
    lobes: usize,
    active: &'a [u32],
}

/// A solved model with its ridge choice.
struct Solved {
    model: PoseModel,
    ridge_errors: Vec<(f64, f32)>,
    ridge: f64,
    /// Its ridge's cross-validated error.
    cv_error: f32,
}

/// A right-hand side's part shared by every ridge (see [`Solver::prepare`]).
struct Prepared {
    utb: faer::Mat<f64>,
    mean_b: Vec<f64>,
}

/// The least-squares side of training on some of the frames: the thin SVD of their centred
/// pose matrix, shared by every right-hand side and ridge value.
struct Solver {
    /// The training frames used (indices).
    rows: Vec<usize>,
    mean_a: Vec<f64>,
    u: faer::Mat<f64>,
    s: Vec<f64>,
    v: faer::Mat<f64>,
}

impl Solver {
    fn new(train: &[Sample], active: &[u32], rows: &[usize]) -> Result<Self, PrtError> {
        let frames = rows.len();
        let p = 3 * active.len();
        let feats: Vec<Vec<f64>> = rows
            .iter()
            .map(|&f| &train[f])
            .map(|s| {
                active
                    .iter()
                    .flat_map(|&j| s.joint_rotations[j as usize].to_array())
                    .map(f64::from)
                    .collect()
            })
            .collect();
        let mean_a: Vec<f64> = (0..p)
            .map(|k| feats.iter().map(|r| r[k]).sum::<f64>() / frames as f64)
            .collect();
        let a = faer::Mat::<f64>::from_fn(frames, p.max(1), |f, k| {
            if p == 0 {
                0.0
            } else {
                feats[f][k] - mean_a[k]
            }
        });
        let svd = a
            .thin_svd()
            .map_err(|e| PrtError::Solve(format!("SVD did not converge: {e:?}")))?;
        let s = svd.S().column_vector();
        Ok(Self {
            rows: rows.to_vec(),
            mean_a,
            u: svd.U().to_owned(),
            s: (0..s.nrows()).map(|i| s[i]).collect(),
            v: svd.V().to_owned(),
        })
    }

    /// The right-hand side's part shared by every ridge, for `B` with `cols` columns whose
    /// entry at training frame `f` and column `c` is `value(f, c)`: `Uᵀ·B` (B centred)
    /// and B's column means.
    fn prepare(&self, cols: usize, value: impl Fn(usize, usize) -> f64 + Sync) -> Prepared {
        let frames = self.rows.len();
        let mean_b: Vec<f64> = (0..cols)
            .map(|c| self.rows.iter().map(|&f| value(f, c)).sum::<f64>() / frames as f64)
            .collect();
        let bc = faer::Mat::<f64>::from_fn(frames, cols, |i, c| value(self.rows[i], c) - mean_b[c]);
        Prepared {
            utb: self.u.transpose() * &bc,
            mean_b,
        }
    }

    /// The weights (row-major `(1 + p) × cols`, row 0 the constant) solving `A·X = B`
    /// (prepared by [`Self::prepare`]) with the ridge `relative` times the largest squared
    /// singular value.
    fn weights(&self, prepared: &Prepared, relative: f64) -> Vec<f32> {
        let Prepared { utb, mean_b } = prepared;
        let cols = utb.ncols();
        let p = self.mean_a.len();
        let s = &self.s;
        let rank = s.len();
        let smax2 = s.iter().map(|x| x * x).fold(0.0f64, f64::max).max(1e-300);
        let lambda = relative * smax2;
        // X = V diag(s / (s² + λ)) Uᵀ Bc, then the constant row folded in.
        let scaled = faer::Mat::<f64>::from_fn(rank, cols, |i, c| {
            let si = s[i];
            let g = if si * si > 1e-12 * smax2 {
                si / (si * si + lambda)
            } else {
                0.0
            };
            g * utb[(i, c)]
        });
        let x = &self.v * &scaled; // p × cols
        let mut w = vec![0.0f32; (1 + p) * cols];
        for c in 0..cols {
            let mut bias = mean_b[c];
            for k in 0..p {
                bias -= self.mean_a[k] * x[(k, c)];
                w[(1 + k) * cols + c] = x[(k, c)] as f32;
            }
            w[c] = bias as f32;
        }
        w
    }

    /// The pose model of the packed lobes `fits` with ridge `relative`.
    fn model(&self, shape: &Shape, fits: &[VertexFits], relative: f64) -> PoseModel {
        let prepared = self.prepare_lobes(shape, fits);
        self.lobe_model(shape, &prepared, relative)
    }

    /// [`Self::prepare`] for packed lobes.
    fn prepare_lobes(&self, shape: &Shape, fits: &[VertexFits]) -> Prepared {
        let out_dim = shape.lobes * LOBE_DIM;
        self.prepare(shape.vertices * out_dim, |f, c| {
            fits[c / out_dim].packed[f * out_dim + c % out_dim] as f64
        })
    }

    /// The pose model of prepared lobes with ridge `relative`.
    fn lobe_model(&self, shape: &Shape, prepared: &Prepared, relative: f64) -> PoseModel {
        PoseModel {
            character: shape.character.to_string(),
            vertices: shape.vertices,
            joints: shape.joints,
            lobes: shape.lobes,
            active: shape.active.to_vec(),
            weights: self.weights(prepared, relative),
            limits: self.limits(relative),
        }
    }

    /// The box and ball of this solver's poses in their principal axes (those with
    /// weight), the ball's units regularised by the ridge `relative` (see
    /// [`PoseLimits::scale`]).
    fn limits(&self, relative: f64) -> PoseLimits {
        let p = self.mean_a.len();
        let smax2 = self
            .s
            .iter()
            .map(|x| x * x)
            .fold(0.0f64, f64::max)
            .max(1e-300);
        let mut limits = PoseLimits {
            mean: self.mean_a.iter().map(|&m| m as f32).collect(),
            ..PoseLimits::default()
        };
        if p == 0 {
            return limits;
        }
        let frames = self.u.nrows();
        let lambda = relative * smax2;
        // Per training pose: its squared scaled distance from the mean.
        let mut dist2 = vec![0.0f64; frames];
        for (i, &si) in self.s.iter().enumerate() {
            if si * si <= 1e-12 * smax2 {
                continue;
            }
            limits.axes.extend((0..p).map(|k| self.v[(k, i)] as f32));
            // Coordinates of the training poses on axis i: U[f, i] · s_i; their RMS is
            // s_i / √frames, the unit regularised to √((s_i² + λ) / frames).
            let (lo, hi) = (0..frames)
                .map(|f| self.u[(f, i)] * si)
                .fold((f64::MAX, f64::MIN), |(lo, hi), c| (lo.min(c), hi.max(c)));
            limits.range.push([lo as f32, hi as f32]);
            let unit = ((si * si + lambda) / frames as f64).sqrt();
            limits.scale.push(unit as f32);
            for (f, d) in dist2.iter_mut().enumerate() {
                *d += (self.u[(f, i)] * si / unit).powi(2);
            }
        }
        limits.radius = dist2.iter().copied().fold(0.0f64, f64::max).sqrt() as f32;
        limits
    }
}

/// Mean and standard deviation over vertices×frames of the RMS error over the sphere between
/// the model's predicted visibility and the projected visibility of `frames`.
pub fn model_error(model: &PoseModel, frames: &[Sample]) -> (f32, f32) {
    mean_std(model_errors(model, frames).into_iter())
}

/// The RMS error over the sphere between the model's predicted visibility and the projected
/// visibility of `frames`, per vertex, frame after frame.
pub fn model_errors(model: &PoseModel, frames: &[Sample]) -> Vec<f32> {
    let mut raw = Vec::new();
    let mut errors = Vec::with_capacity(frames.len() * model.vertices);
    for s in frames {
        model.predict_raw(&model.pose_vector(&s.joint_rotations), &mut raw);
        let e: Vec<f32> = (0..model.vertices)
            .into_par_iter()
            .map_init(Vec::new, |lobes, v| {
                model.lobes_of(&raw, v, lobes);
                rms_difference(&crate::zonal::lobes_to_sh(lobes), &s.visibility[v])
            })
            .collect();
        errors.extend(e);
    }
    errors
}

/// Joints whose rotation varies over the training frames.
fn active_joints(train: &[Sample]) -> Vec<u32> {
    let joints = train[0].joint_rotations.len();
    (0..joints)
        .filter(|&j| {
            (0..3).any(|k| {
                let (_, std) = mean_std(train.iter().map(|s| s.joint_rotations[j][k]));
                std > ACTIVE_JOINT_STD
            })
        })
        .map(|j| j as u32)
        .collect()
}

/// The paper's Fig. 3 (§3.2) measured: the error of `lobes` zonal lobes fitted to plain
/// SH visibility, of lobes fitted to cosine-weighted visibility (the diffuse transfer
/// vector: the clamped-cosine operator applied to visibility), and of the plain fit
/// convolved with the clamped cosine afterwards, the last two against the traced
/// cosine-weighted visibility. Mean and standard deviation over vertices×frames of the RMS
/// over the sphere.
#[derive(Clone, Debug, PartialEq)]
pub struct ShFitErrors {
    /// Lobes fitted to plain visibility vs the visibility.
    pub plain: (f32, f32),
    /// Lobes fitted to cosine-weighted visibility vs that.
    pub cosine: (f32, f32),
    /// The plain fit convolved with the clamped cosine vs cosine-weighted visibility.
    pub plain_convolved: (f32, f32),
}

/// [`ShFitErrors`] of `lobes` lobes per vertex over `frames` (each vertex and frame fitted
/// on its own, greedily started).
pub fn cosine_fit_errors(frames: &[Sample], lobes: usize) -> ShFitErrors {
    let op = crate::phong::PhongOperator::diffuse();
    let errors: Vec<[f32; 3]> = frames
        .iter()
        .flat_map(|s| &s.visibility)
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|v| {
            let cosine = op.apply(v);
            let (plain_fit, _) = fit_lobes(v, lobes, None);
            let plain_sh = crate::zonal::lobes_to_sh(&plain_fit);
            let (cosine_fit, _) = fit_lobes(&cosine, lobes, None);
            [
                rms_difference(&plain_sh, v),
                rms_difference(&crate::zonal::lobes_to_sh(&cosine_fit), &cosine),
                rms_difference(&op.apply(&plain_sh), &cosine),
            ]
        })
        .collect();
    let column = |k: usize| mean_std(errors.iter().map(|e| e[k]));
    ShFitErrors {
        plain: column(0),
        cosine: column(1),
        plain_convolved: column(2),
    }
}

/// `[1, rotation vectors of the active joints…]`.
fn features(active: &[u32], joint_rotations: &[Vec3]) -> Vec<f32> {
    let mut a = Vec::with_capacity(1 + 3 * active.len());
    a.push(1.0);
    for &j in active {
        let r = joint_rotations
            .get(j as usize)
            .copied()
            .unwrap_or(Vec3::ZERO);
        a.extend_from_slice(&r.to_array());
    }
    a
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folds_are_contiguous_blocks_that_cover_the_frames_once() {
        for frames in [4, 5, 7, 8, 45, 103] {
            let folds = folds(frames);
            assert!(folds.len() >= 2, "{frames}");
            let mut seen = vec![0; frames];
            for (held, rest) in &folds {
                for f in held.clone() {
                    seen[f] += 1;
                }
                assert_eq!(rest.len() + held.len(), frames);
                assert!(rest.iter().all(|f| !held.contains(f)));
            }
            assert!(seen.iter().all(|&n| n == 1), "{frames}: {seen:?}");
        }
        assert_eq!(folds(45).len(), FOLDS);
        // Too few frames to hold any out and train on 2: no blocks (every ridge ties, the
        // first is kept, and no vertex is shrunk).
        assert!(folds(2).is_empty());
        assert_eq!(folds(3).len(), 1);
    }
}
