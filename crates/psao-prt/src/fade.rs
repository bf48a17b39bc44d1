//! Trusting a model's shadows less as the pose leaves the training poses.
//!
//! The pose limits ([`crate::limits`]) predict an unseen pose from the nearest training-like
//! pose; what the pose does beyond the training poses' box (or in directions they never
//! moved in) the model cannot know, and the shadows it predicts there may be wrong in any
//! direction. A glossy lobe reads visibility in a narrow cone, where such an error costs
//! more than no shadowing at all. So the predicted visibility is blended towards
//! unoccluded visibility (the constant 1) by the pose's *coverage*
//! ([`crate::limits::PoseLimits::coverage`]): the share of its departure from the training
//! mean that the box keeps, measured in the pose features' own radians (it does not
//! shrink with the ridge, as the ball's units do). A training pose, or any pose inside the
//! box, keeps its predicted shadows; a pose with half of its departure outside the box
//! gets half of them.
//!
//! The blend is `w·V + (1 − w)·1` with `w` the coverage raised to the [`FadeRule`]'s
//! power, and since shading is linear in visibility it is the shade's blend
//! `w·S + (1 − w)·U` between shadowed and unshadowed shading. On a lobe model it scales every
//! lobe's zonal coefficients by `w` and adds `(1 − w)·2√π` (the constant 1's band-0
//! coefficient) to the first lobe's ([`fade_outputs`]); axes are unchanged.

use glam::Vec3;

use crate::model::{PoseModel, LOBE_DIM};
use crate::shade::Mode;

/// The band-0 zonal coefficient of the constant 1 (`2√π`).
const UNIT0: f32 = 3.544_907_7;

/// How much of a model's predicted shadowing a pose keeps, by its coverage.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FadeRule {
    /// The power of the coverage (0: shadows are kept whatever the pose).
    pub power: f32,
}

impl FadeRule {
    /// Shadows kept whatever the pose.
    pub const NONE: Self = Self { power: 0.0 };

    /// The rule shading in `mode` follows by default.
    pub fn of_mode(mode: Mode) -> Self {
        match mode {
            Mode::Phong { .. } => Self { power: 1.0 },
            Mode::Diffuse | Mode::Translucent { .. } => Self::NONE,
        }
    }

    /// The share of the predicted shadowing kept at the pose of these joint rotations
    /// (every skin joint's rotation vector relative to the bind pose), in [0, 1].
    pub fn weight(&self, model: &PoseModel, joint_rotations: &[Vec3]) -> f32 {
        if self.power == 0.0 {
            return 1.0;
        }
        let raw = model.raw_pose_vector(joint_rotations);
        model.limits.coverage(&raw[1..]).powf(self.power)
    }
}

/// The raw outputs of `model` (`vertices·lobes·7`) at the pose of these joint rotations:
/// the pose limited ([`PoseModel::pose_vector`]), predicted ([`PoseModel::predict_raw`]) and
/// faded by `rule` ([`fade_outputs`]), into `out`.
pub fn predict(model: &PoseModel, rule: FadeRule, joint_rotations: &[Vec3], out: &mut Vec<f32>) {
    model.predict_raw(&model.pose_vector(joint_rotations), out);
    fade_outputs(out, model.lobes, rule.weight(model, joint_rotations));
}

/// Blends the raw outputs of a model of `lobes` lobes per vertex (`vertices·lobes·7`, as
/// [`PoseModel::predict_raw`] gives them) towards unoccluded visibility: `w·V + (1 − w)·1`
/// per vertex (module doc).
pub fn fade_outputs(raw: &mut [f32], lobes: usize, w: f32) {
    if w == 1.0 || lobes == 0 {
        return;
    }
    for vertex in raw.chunks_exact_mut(lobes * LOBE_DIM) {
        for lobe in vertex.chunks_exact_mut(LOBE_DIM) {
            for c in &mut lobe[3..] {
                *c *= w;
            }
        }
        vertex[3] += (1.0 - w) * UNIT0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::unpack_lobe;
    use crate::sh::ShVec;
    use crate::shade::unit_visibility;

    fn sh_of(vertex: &[f32]) -> ShVec {
        let lobes: Vec<_> = vertex.chunks_exact(LOBE_DIM).map(unpack_lobe).collect();
        crate::zonal::lobes_to_sh(&lobes)
    }

    #[test]
    fn fading_blends_each_vertexs_visibility_towards_one() {
        // Two vertices of two lobes.
        let mut raw = vec![
            0.0, 0.6, 0.8, 1.2, -0.4, 0.3, 0.1, 1.0, 0.0, 0.0, 0.9, 0.5, -0.2, 0.05, //
            0.0, 0.0, 1.0, 3.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, -0.5, 0.2, 0.1, 0.0,
        ];
        let before: Vec<ShVec> = raw.chunks_exact(14).map(sh_of).collect();
        fade_outputs(&mut raw, 2, 0.25);
        let one = unit_visibility();
        for (v, b) in raw.chunks_exact(14).zip(&before) {
            let after = sh_of(v);
            for k in 0..16 {
                let want = 0.25 * b[k] + 0.75 * one[k];
                assert!(
                    (after[k] - want).abs() < 1e-5,
                    "{k}: {} vs {want}",
                    after[k]
                );
            }
        }
        // w = 0: visibility 1 exactly; w = 1: unchanged.
        let mut zero = raw.clone();
        fade_outputs(&mut zero, 2, 0.0);
        for v in zero.chunks_exact(14) {
            let s = sh_of(v);
            assert!(
                s.iter().zip(&one).all(|(a, b)| (a - b).abs() < 1e-5),
                "{s:?}"
            );
        }
        let mut same = raw.clone();
        fade_outputs(&mut same, 2, 1.0);
        assert_eq!(same, raw);
    }
}
