//! Walkers: a root node carried along a polyline at constant speed, facing its direction
//! of travel (the heading turns smoothly through corners), optionally rolling.

use glam::{Quat, Vec3};

use crate::model::Walker;

/// Half the length of the chord whose direction is the heading: corners are rounded over
/// about twice this distance.
const TURN_HALF_LENGTH: f32 = 0.3;

/// A walker's path with its arc-length table.
#[derive(Clone, Debug)]
pub(crate) struct WalkPath {
    walker: Walker,
    /// Arc length at each corner; with a closed path one more entry (back at the start).
    cumulative: Vec<f32>,
}

impl WalkPath {
    /// Precomputes the arc lengths of a validated walker.
    pub(crate) fn new(walker: &Walker) -> Self {
        let mut cumulative = vec![0.0];
        let mut corners = walker.points.clone();
        if walker.closed && corners.len() > 1 {
            corners.push(corners[0]);
        }
        for pair in corners.windows(2) {
            let last = *cumulative.last().unwrap_or(&0.0);
            cumulative.push(last + pair[0].distance(pair[1]));
        }
        Self {
            walker: walker.clone(),
            cumulative,
        }
    }

    /// The moved node.
    pub(crate) fn node(&self) -> usize {
        self.walker.node
    }

    fn total(&self) -> f32 {
        *self.cumulative.last().unwrap_or(&0.0)
    }

    /// Corner `k` of the (closed: wrapped) path.
    fn corner(&self, k: usize) -> Vec3 {
        self.walker.points[k % self.walker.points.len()]
    }

    /// The point at arc length `s`, wrapped for closed paths and clamped for open ones.
    fn point_at(&self, s: f32) -> Vec3 {
        let total = self.total();
        if total <= 0.0 {
            return self.walker.points[0];
        }
        let s = if self.walker.closed {
            s.rem_euclid(total)
        } else {
            s.clamp(0.0, total)
        };
        let next = self
            .cumulative
            .partition_point(|&c| c <= s)
            .clamp(1, self.cumulative.len() - 1);
        let k = next - 1;
        let length = self.cumulative[next] - self.cumulative[k];
        let f = if length > 0.0 {
            (s - self.cumulative[k]) / length
        } else {
            0.0
        };
        self.corner(k).lerp(self.corner(k + 1), f)
    }

    /// Where the walker is at `time`: (path point, unit horizontal heading, distance walked).
    pub(crate) fn state_at(&self, time: f32) -> (Vec3, Vec3, f32) {
        let walked = self.walker.speed * time;
        let total = self.total();
        if total <= 0.0 {
            return (self.walker.points[0], Vec3::Z, walked);
        }
        let (s, sign) = if self.walker.closed {
            (walked.rem_euclid(total), 1.0)
        } else {
            let u = walked.rem_euclid(2.0 * total);
            if u <= total {
                (u, 1.0)
            } else {
                (2.0 * total - u, -1.0)
            }
        };
        let h = TURN_HALF_LENGTH.min(0.5 * total);
        let chord = self.point_at(s + sign * h) - self.point_at(s - sign * h);
        let heading = Vec3::new(chord.x, 0.0, chord.z)
            .try_normalize()
            .unwrap_or(Vec3::Z);
        (self.point_at(s), heading, walked)
    }

    /// The node's local translation and rotation at `time`, for a node of rest `scale`.
    pub(crate) fn local_at(&self, time: f32, scale: Vec3) -> (Vec3, Quat) {
        let (point, heading, walked) = self.state_at(time);
        let w = &self.walker;
        let yaw = Quat::from_rotation_y(heading.x.atan2(heading.z));
        let roll = match w.roll_radius {
            Some(r) => Quat::from_rotation_x(walked / r),
            None => Quat::IDENTITY,
        };
        let rotation = (yaw * roll * w.rotation).normalize();
        let translation = point + Vec3::Y * w.lift - rotation * (scale * w.centre);
        (translation, rotation)
    }
}

/// Why a walker is unusable (`None` when fine); `node_count` bounds its node index.
pub(crate) fn check(walker: &Walker, node_count: usize) -> Option<String> {
    if walker.node >= node_count {
        return Some(format!(
            "node {} out of range ({node_count} nodes)",
            walker.node
        ));
    }
    if walker.points.is_empty() {
        return Some("path has no points".into());
    }
    let finite = walker.points.iter().all(|p| p.is_finite())
        && walker.centre.is_finite()
        && walker.lift.is_finite()
        && walker.rotation.is_finite();
    if !finite {
        return Some("non-finite path point, centre, lift or rotation".into());
    }
    if !(walker.speed.is_finite() && walker.speed >= 0.0) {
        return Some(format!(
            "speed must be finite and not negative, got {}",
            walker.speed
        ));
    }
    if let Some(r) = walker.roll_radius {
        if !(r.is_finite() && r > 0.0) {
            return Some(format!("roll radius must be positive, got {r}"));
        }
    }
    None
}
