//! Where the training poses lie, and how a pose is kept there before prediction.
//!
//! A linear pose model is only trustworthy near the poses it was trained on. Two limits,
//! both taken from the training set (no parameter):
//!
//! * the **box**: per principal axis of the training poses, the least and greatest
//!   coordinate of a training pose; a pose's coordinates are clamped into it;
//! * the **ball**: the pose's distance from the training mean, with each principal axis
//!   measured in units of the training poses' RMS coordinate on it regularised by the
//!   model's ridge (a Mahalanobis distance that does not blow up along axes the training
//!   poses barely span), at most that of the farthest training pose; a pose beyond it is
//!   moved towards the mean until it is on the ball.
//!
//! A training pose is inside both and is left as it is. The box alone lets a pose that is
//! extreme on many axes at once sit in a corner that no training pose comes near; the ball
//! bounds that. The model being linear, moving a pose towards the mean along a line is
//! blending its prediction towards the prediction at the training mean (the training
//! frames' average lobes) by the same factor.

/// The training poses' box and ball in their principal axes (see the module's doc).
/// Directions in which training poses did not vary carry no weight in the model and are
/// dropped.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PoseLimits {
    /// Mean of the training pose vectors (without the constant), `3·active` numbers.
    pub mean: Vec<f32>,
    /// Orthonormal principal axes, row-major `axes × 3·active`.
    pub axes: Vec<f32>,
    /// Per axis: the least and greatest coordinate of a training pose.
    pub range: Vec<[f32; 2]>,
    /// Per axis: the ball's unit on that axis, `√((s² + λ) / frames)` for the axis's
    /// singular value `s` of the centred training pose matrix and the model's ridge `λ`
    /// (without the ridge, the training poses' RMS coordinate; along an axis whose `s²` is
    /// far below `λ`, which the ridge keeps the model from following, a pose's coordinate
    /// counts little); empty: no ball.
    pub scale: Vec<f32>,
    /// The ball's radius: the largest scaled distance of a training pose from the mean.
    pub radius: f32,
}

impl PoseLimits {
    /// Moves the pose features `x` (`3·active` numbers) into the box, then into the ball;
    /// no-op when empty or of another length.
    pub fn apply(&self, x: &mut [f32]) {
        let p = self.mean.len();
        let Some(coords) = self.limited_coords(x) else {
            return;
        };
        x.copy_from_slice(&self.mean);
        for (axis, c) in self.axes.chunks_exact(p).zip(&coords) {
            for (o, a) in x.iter_mut().zip(axis) {
                *o += *c * a;
            }
        }
    }

    /// The principal coordinates of the pose features `x` (`3·active` numbers) moved into
    /// the box, then into the ball: the limited pose is the mean plus these times the
    /// axes. `None` when the limits are empty or `x` has another length.
    pub fn limited_coords(&self, x: &[f32]) -> Option<Vec<f32>> {
        if self.range.is_empty() || x.len() != self.mean.len() {
            return None;
        }
        let mut coords = self.coords(x);
        for (c, &[lo, hi]) in coords.iter_mut().zip(&self.range) {
            *c = c.clamp(lo, hi);
        }
        let factor = self.ball_factor(&coords);
        for c in &mut coords {
            *c *= factor;
        }
        Some(coords)
    }

    /// How far the pose features `x` are from the training mean, as a multiple of the
    /// ball's radius (the farthest training pose's distance): at most 1 for a training pose.
    /// Measured before any limit is applied; `None` without a ball or for another length.
    pub fn reach(&self, x: &[f32]) -> Option<f32> {
        (self.radius > 0.0 && self.scale.len() == self.range.len() && x.len() == self.mean.len())
            .then(|| self.distance(&self.coords(x)) / self.radius)
    }

    /// The share of the pose's departure from the training mean that the box keeps: the
    /// length of the box-limited departure over the length of the pose's own (Euclidean, in
    /// the pose features' radians, so it does not depend on the ridge; the axes are
    /// orthonormal, so a direction the training poses did not vary in is not kept at all).
    /// 1 for a pose inside the box (every training pose), towards 0 for a pose far outside
    /// it or off the training poses' span. 1 without limits or for another length.
    pub fn coverage(&self, x: &[f32]) -> f32 {
        if self.range.is_empty() || x.len() != self.mean.len() {
            return 1.0;
        }
        let departure: f32 = x
            .iter()
            .zip(&self.mean)
            .map(|(a, m)| (a - m) * (a - m))
            .sum();
        if departure <= 0.0 {
            return 1.0;
        }
        let kept: f32 = self
            .coords(x)
            .iter()
            .zip(&self.range)
            .map(|(c, &[lo, hi])| c.clamp(lo, hi).powi(2))
            .sum();
        (kept / departure).sqrt().min(1.0)
    }

    /// The principal coordinates of the pose features `x` (of the right length).
    fn coords(&self, x: &[f32]) -> Vec<f32> {
        let d: Vec<f32> = x.iter().zip(&self.mean).map(|(a, m)| a - m).collect();
        self.axes
            .chunks_exact(self.mean.len())
            .map(|axis| axis.iter().zip(&d).map(|(a, b)| a * b).sum())
            .collect()
    }

    /// The factor that brings principal coordinates `coords` onto the ball (1 inside it or
    /// without a ball).
    fn ball_factor(&self, coords: &[f32]) -> f32 {
        if self.scale.len() != coords.len() || self.radius <= 0.0 {
            return 1.0;
        }
        let dist = self.distance(coords);
        if dist > self.radius {
            self.radius / dist
        } else {
            1.0
        }
    }

    /// The scaled (Mahalanobis) length of principal coordinates `coords`.
    pub fn distance(&self, coords: &[f32]) -> f32 {
        coords
            .iter()
            .zip(&self.scale)
            .map(|(c, s)| if *s > 0.0 { (c / s).powi(2) } else { 0.0 })
            .sum::<f32>()
            .sqrt()
    }

    /// The same limits without the ball (the box alone).
    pub fn box_only(&self) -> Self {
        Self {
            scale: Vec::new(),
            radius: 0.0,
            ..self.clone()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two axes in a 3-number pose space: x with coordinates in [−1, 2], y in [−0.5, 0.5],
    /// unit RMS 1 and 0.25, radius 2.
    fn limits() -> PoseLimits {
        PoseLimits {
            mean: vec![1.0, 0.0, 0.0],
            axes: vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0],
            range: vec![[-1.0, 2.0], [-0.5, 0.5]],
            scale: vec![1.0, 0.25],
            radius: 2.0,
        }
    }

    #[test]
    fn a_pose_inside_box_and_ball_is_unchanged() {
        let mut x = [2.5, 0.2, 0.0];
        limits().apply(&mut x);
        assert_eq!(x, [2.5, 0.2, 0.0]);
    }

    #[test]
    fn the_box_clamps_each_axis_and_drops_unvaried_directions() {
        let l = limits().box_only();
        let mut x = [5.0, -3.0, 7.0];
        l.apply(&mut x);
        assert_eq!(x, [3.0, -0.5, 0.0]);
    }

    #[test]
    fn the_ball_moves_a_box_corner_towards_the_mean() {
        let l = limits();
        // The corner (2, 0.5) has scaled length √(4 + 4) = 2√2 > 2.
        let mut x = [5.0, 3.0, 0.0];
        l.apply(&mut x);
        let coords = [x[0] - 1.0, x[1]];
        assert!((l.distance(&coords) - 2.0).abs() < 1e-5, "{x:?}");
        // Along the line from the mean to the box-limited pose.
        assert!((coords[1] / coords[0] - 0.25).abs() < 1e-6, "{x:?}");
        // The corner lies √2 radii out, a pose beyond it farther; the mean at none.
        assert!((l.reach(&[3.0, 0.5, 0.0]).unwrap() - 2f32.sqrt()).abs() < 1e-5);
        assert!((l.reach(&[5.0, 3.0, 0.0]).unwrap() - 160f32.sqrt() / 2.0).abs() < 1e-4);
        assert_eq!(l.reach(&[1.0, 0.0, 0.0]), Some(0.0));
        assert_eq!(l.box_only().reach(&[5.0, 3.0, 0.0]), None);
        // Without the ball the corner stays.
        let mut y = [5.0, 3.0, 0.0];
        l.box_only().apply(&mut y);
        assert_eq!(y, [3.0, 0.5, 0.0]);
    }

    #[test]
    fn coverage_is_the_share_of_the_departure_the_box_keeps() {
        let l = limits();
        // Inside the box (and the mean itself): all of it.
        assert_eq!(l.coverage(&[2.5, 0.2, 0.0]), 1.0);
        assert_eq!(l.coverage(&[1.0, 0.0, 0.0]), 1.0);
        // x clamped from 4 to 2: half of a departure along x.
        assert!((l.coverage(&[5.0, 0.0, 0.0]) - 0.5).abs() < 1e-6);
        // Along z (not an axis): nothing kept; (1.5, 0, 2) from the mean keeps x: 1.5 / 2.5.
        assert_eq!(l.coverage(&[1.0, 0.0, 2.0]), 0.0);
        assert!((l.coverage(&[2.5, 0.0, 2.0]) - 0.6).abs() < 1e-6);
        // The ball and the ridge play no part.
        assert_eq!(
            l.coverage(&[5.0, 3.0, 0.0]),
            l.box_only().coverage(&[5.0, 3.0, 0.0])
        );
        assert_eq!(PoseLimits::default().coverage(&[9.0, 9.0, 9.0]), 1.0);
    }

    #[test]
    fn empty_limits_or_another_length_do_nothing() {
        let mut x = [9.0, 9.0, 9.0];
        PoseLimits::default().apply(&mut x);
        let mut short = [9.0, 9.0];
        limits().apply(&mut short);
        assert_eq!((x, short), ([9.0; 3], [9.0; 2]));
    }
}
