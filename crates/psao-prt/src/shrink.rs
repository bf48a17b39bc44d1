//! Per-vertex shrinkage of a pose model towards the training frames' average lobes.
//!
//! Some vertices change visibility with the pose in ways a linear model does not follow;
//! for them the model's pose-dependent part does more harm than good on poses it did not
//! see, and the training average (the prediction at the training poses' mean) is the
//! better guess. Per vertex a factor `s` from [`SHRINK_GRID`] scales the pose-dependent
//! part: `lobes(a) = mean + s·(model(a) − mean)` in the model's 7 numbers per lobe. The
//! factor is chosen by the same blocked cross-validation as the ridge (see
//! [`crate::model`]): the one with the least error on held-out blocks, summed over them.
//! The model being linear, the factor folds into the weights ([`shrink_towards_mean`]):
//! run time is unchanged.

use rayon::prelude::*;

use crate::fit::rms_difference;
use crate::model::{unpack_lobe, PoseModel, LOBE_DIM};
use crate::sh::ShVec;
use crate::zonal::ZhLobe;
use crate::PrtError;

/// The factors tried, from the full model (1) to the average alone (0). On a tie the
/// earlier (larger) one is kept.
pub const SHRINK_GRID: [f32; 5] = [1.0, 0.75, 0.5, 0.25, 0.0];

/// Per vertex and factor of [`SHRINK_GRID`]: the summed RMS-over-the-sphere error of the
/// shrunk prediction on held-out frames.
#[derive(Clone, Debug)]
pub struct ShrinkErrors {
    lobes: usize,
    sums: Vec<[f64; SHRINK_GRID.len()]>,
}

impl ShrinkErrors {
    /// No errors yet for `vertices` vertices of `lobes` lobes.
    pub fn new(vertices: usize, lobes: usize) -> Self {
        Self {
            lobes,
            sums: vec![[0.0; SHRINK_GRID.len()]; vertices],
        }
    }

    /// Adds one held-out frame: the model's raw outputs `raw` at its pose, `mean` at the
    /// training poses' mean (both `vertices·lobes·7`), and the frame's visibility.
    pub fn add(&mut self, mean: &[f32], raw: &[f32], visibility: &[ShVec]) {
        let dim = self.lobes * LOBE_DIM;
        self.sums
            .par_iter_mut()
            .zip(visibility)
            .enumerate()
            .for_each_init(
                || (Vec::new(), Vec::new()),
                |(blend, lobes): &mut (Vec<f32>, Vec<ZhLobe>), (v, (sums, vis))| {
                    let m = &mean[v * dim..(v + 1) * dim];
                    let r = &raw[v * dim..(v + 1) * dim];
                    for (sum, &s) in sums.iter_mut().zip(&SHRINK_GRID) {
                        blend.clear();
                        blend.extend(m.iter().zip(r).map(|(m, r)| m + s * (r - m)));
                        lobes.clear();
                        lobes.extend(blend.chunks_exact(LOBE_DIM).map(unpack_lobe));
                        *sum += rms_difference(&crate::zonal::lobes_to_sh(lobes), vis) as f64;
                    }
                },
            );
    }

    /// Per vertex the factor with the least summed error.
    pub fn choose(&self) -> Vec<f32> {
        self.sums
            .iter()
            .map(|sums| {
                let best = sums
                    .iter()
                    .enumerate()
                    .fold(0, |b, (k, &e)| if e < sums[b] { k } else { b });
                SHRINK_GRID[best]
            })
            .collect()
    }
}

/// `model` with each vertex's pose-dependent part scaled by its factor (one per vertex, in
/// [0, 1]) about the prediction at the training poses' mean (`model.limits.mean`), folded
/// into the weights: `W'ₖ = s·Wₖ` for the pose rows, `W'₀ = W₀ + (1 − s)·Σₖ Wₖ·meanₖ`.
/// Errors when the factors do not match the vertices or the model has no pose mean.
pub fn shrink_towards_mean(model: &PoseModel, factors: &[f32]) -> Result<PoseModel, PrtError> {
    let p = model.pose_len() - 1;
    if factors.len() != model.vertices {
        return Err(PrtError::Parameter(format!(
            "{} shrink factors for {} vertices",
            factors.len(),
            model.vertices
        )));
    }
    if model.limits.mean.len() != p {
        return Err(PrtError::Parameter(
            "the model has no training pose mean to shrink towards".into(),
        ));
    }
    if let Some(s) = factors.iter().find(|s| !(0.0..=1.0).contains(*s)) {
        return Err(PrtError::Parameter(format!(
            "shrink factor {s} (must be in 0..1)"
        )));
    }
    let n = model.output_len();
    let dim = model.lobes * LOBE_DIM;
    let mut weights = model.weights.clone();
    let (bias, rows) = weights.split_at_mut(n);
    for (c, b) in bias.iter_mut().enumerate() {
        let s = factors[c / dim];
        let mut at_mean = 0.0f64;
        for (k, &m) in model.limits.mean.iter().enumerate() {
            let w = &mut rows[k * n + c];
            at_mean += *w as f64 * m as f64;
            *w *= s;
        }
        *b += ((1.0 - s) as f64 * at_mean) as f32;
    }
    Ok(PoseModel {
        weights,
        ..model.clone()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::limits::PoseLimits;
    use glam::Vec3;

    /// 2 vertices, 1 lobe, 1 active joint (3 pose numbers), arbitrary weights.
    fn model() -> PoseModel {
        PoseModel {
            character: "t".into(),
            vertices: 2,
            joints: 1,
            lobes: 1,
            active: vec![0],
            weights: (0..4 * 14)
                .map(|i| ((i * 7) % 11) as f32 * 0.1 - 0.4)
                .collect(),
            limits: PoseLimits {
                mean: vec![0.2, -0.1, 0.3],
                ..PoseLimits::default()
            },
        }
    }

    fn predict(m: &PoseModel, rot: Vec3) -> Vec<f32> {
        let mut raw = Vec::new();
        m.predict_raw(&m.pose_vector(&[rot]), &mut raw);
        raw
    }

    #[test]
    fn folded_factors_blend_each_vertex_towards_its_prediction_at_the_mean() {
        let m = model();
        let shrunk = shrink_towards_mean(&m, &[1.0, 0.25]).unwrap();
        let mean = predict(&m, Vec3::new(0.2, -0.1, 0.3));
        for rot in [Vec3::new(1.0, 0.5, -0.7), Vec3::ZERO] {
            let (full, s) = (predict(&m, rot), predict(&shrunk, rot));
            for c in 0..14 {
                let f = if c < 7 { 1.0 } else { 0.25 };
                let expected = mean[c] + f * (full[c] - mean[c]);
                assert!(
                    (s[c] - expected).abs() < 1e-5,
                    "{c}: {} vs {expected}",
                    s[c]
                );
            }
        }
        // At the mean nothing changes.
        let at_mean = predict(&shrunk, Vec3::new(0.2, -0.1, 0.3));
        assert!(at_mean.iter().zip(&mean).all(|(a, b)| (a - b).abs() < 1e-5));
    }

    #[test]
    fn bad_factors_are_refused() {
        let m = model();
        assert!(shrink_towards_mean(&m, &[1.0]).is_err());
        assert!(shrink_towards_mean(&m, &[1.0, 1.5]).is_err());
        let mut no_mean = model();
        no_mean.limits = PoseLimits::default();
        assert!(shrink_towards_mean(&no_mean, &[1.0, 1.0]).is_err());
    }

    #[test]
    fn each_vertex_gets_the_factor_that_predicts_its_held_out_frames_best() {
        // Vertex 0: the truth is the model's prediction (factor 1). Vertex 1: the truth is
        // the mean (the model's pose-dependent part is noise; factor 0). Vertex 2: halfway.
        let lobe = |axis: Vec3, c0: f32| [axis.x, axis.y, axis.z, c0, 0.8, 0.3, 0.1];
        let mean: Vec<f32> = [lobe(Vec3::Z, 2.0); 3].concat();
        let raw: Vec<f32> = [
            lobe(Vec3::new(0.6, 0.0, 0.8), 2.6),
            lobe(Vec3::new(0.0, 0.6, 0.8), 1.2),
            lobe(Vec3::new(0.8, 0.0, 0.6), 3.0),
        ]
        .concat();
        let truth = |blend: &[f32]| unpack_lobe(blend).to_sh();
        let halfway: Vec<f32> = mean[14..21]
            .iter()
            .zip(&raw[14..21])
            .map(|(m, r)| 0.5 * (m + r))
            .collect();
        let vis = [truth(&raw[0..7]), truth(&mean[7..14]), truth(&halfway)];
        let mut errors = ShrinkErrors::new(3, 1);
        errors.add(&mean, &raw, &vis);
        assert_eq!(errors.choose(), [1.0, 0.0, 0.5]);
    }
}
