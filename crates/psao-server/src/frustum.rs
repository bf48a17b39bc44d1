//! Views and the extended view frustum used to cull points (paper §3.3).

use glam::{Vec3, Vec4};
use psao_scene::Camera;

/// One client's view: its camera and image aspect (width / height).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    /// The client's camera.
    pub camera: Camera,
    /// Width / height of the client's image.
    pub aspect: f32,
}

/// A view frustum widened by a margin, without near clipping (it starts at the eye).
/// Planes are stored as (unit normal, offset) with `n·p + d ≥ 0` inside.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frustum {
    planes: [Vec4; 6],
}

impl Frustum {
    /// The frustum of `view` with both half-angle tangents scaled by `1 + margin`, reaching
    /// from the eye to the camera's far distance. Degenerate cameras give a frustum that
    /// contains nothing (NaN planes).
    pub fn new(view: &View, margin: f32) -> Self {
        let c = &view.camera;
        let eye = c.position;
        let f = (c.target - eye).normalize();
        let r = f.cross(c.up).normalize();
        let u = r.cross(f);
        let ty = (c.fov_y * 0.5).tan() * (1.0 + margin);
        let tx = ty * view.aspect;
        let through_eye = |n: Vec3| {
            let n = n.normalize();
            n.extend(-n.dot(eye))
        };
        Self {
            planes: [
                through_eye(f),
                (-f).extend(f.dot(eye) + c.far),
                through_eye(tx * f - r),
                through_eye(tx * f + r),
                through_eye(ty * f - u),
                through_eye(ty * f + u),
            ],
        }
    }

    /// The six planes (unit normal, offset), `n·p + d ≥ 0` inside.
    pub(crate) fn planes(&self) -> &[Vec4; 6] {
        &self.planes
    }

    /// Whether `p` lies inside or within distance `slack` of the frustum (conservatively:
    /// against each plane separately).
    #[inline]
    pub fn contains(&self, p: Vec3, slack: f32) -> bool {
        let p = p.extend(1.0);
        self.planes.iter().all(|pl| pl.dot(p) >= -slack)
    }

    /// Whether the box `(lo, hi)` may intersect the frustum grown by `slack` (false only when
    /// the box lies entirely outside one plane).
    pub fn may_intersect(&self, (lo, hi): (Vec3, Vec3), slack: f32) -> bool {
        self.planes.iter().all(|pl| {
            let n = pl.truncate();
            let far_corner = Vec3::select(n.cmpgt(Vec3::ZERO), hi, lo);
            n.dot(far_corner) + pl.w >= -slack
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn view() -> View {
        View {
            camera: Camera::look_at(Vec3::ZERO, -Vec3::Z, 90.0),
            aspect: 2.0,
        }
    }

    #[test]
    fn contains_respects_angles_margin_and_slack() {
        let f = Frustum::new(&view(), 0.0);
        // Vertical half-angle 45°: at depth 1 the edge is y = ±1; horizontal x = ±2.
        assert!(f.contains(Vec3::new(0.0, 0.99, -1.0), 0.0));
        assert!(!f.contains(Vec3::new(0.0, 1.01, -1.0), 0.0));
        assert!(f.contains(Vec3::new(1.99, 0.0, -1.0), 0.0));
        assert!(!f.contains(Vec3::new(2.01, 0.0, -1.0), 0.0));
        assert!(!f.contains(Vec3::new(0.0, 0.0, 0.5), 0.0), "behind the eye");
        assert!(
            f.contains(Vec3::new(0.0, 0.0, 0.05), 0.1),
            "within slack behind"
        );
        assert!(!f.contains(Vec3::new(0.0, 0.0, -1001.0), 0.0), "beyond far");
        let wide = Frustum::new(&view(), 0.2);
        assert!(wide.contains(Vec3::new(0.0, 1.19, -1.0), 0.0));
        assert!(!wide.contains(Vec3::new(0.0, 1.21, -1.0), 0.0));
        // Slack is a distance from the plane y = z (normal length √2 in (y, z)).
        let p = Vec3::new(0.0, 1.1, -1.0);
        assert!(!f.contains(p, 0.07) && f.contains(p, 0.071));
    }

    #[test]
    fn boxes_and_degenerate_views() {
        let f = Frustum::new(&view(), 0.0);
        assert!(f.may_intersect(
            (Vec3::new(-5.0, -5.0, -3.0), Vec3::new(5.0, 5.0, -2.0)),
            0.0
        ));
        assert!(!f.may_intersect((Vec3::new(-1.0, -1.0, 1.0), Vec3::new(1.0, 1.0, 2.0)), 0.0));
        assert!(!f.may_intersect((Vec3::new(5.0, 0.0, -1.0), Vec3::new(6.0, 1.0, -0.5)), 0.0));
        let mut v = view();
        v.camera.target = v.camera.position;
        let d = Frustum::new(&v, 0.2);
        assert!(!d.contains(Vec3::new(0.0, 0.0, -1.0), 1.0));
    }
}
