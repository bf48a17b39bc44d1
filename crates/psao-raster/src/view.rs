//! Camera quantities shared by triangle setup and attribute resolve.

use glam::{Mat4, Vec3};
use psao_scene::Camera;

/// Smallest near distance used; smaller (or invalid) camera near distances are raised to it.
const MIN_NEAR: f32 = 1e-6;

/// A camera prepared for one image size.
pub(crate) struct View {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// World to clip (depth in [0, 1]).
    pub view_proj: Mat4,
    /// Eye position.
    pub origin: Vec3,
    /// Unit viewing direction.
    pub forward: Vec3,
    /// Near clip distance.
    pub near: f32,
    /// 1 / far distance (0 when the far plane is at infinity or invalid).
    pub inv_far: f64,
    /// Ray direction through the centre of pixel (0, 0); see [`View::pixel_ray`].
    ray00: Vec3,
    /// Ray direction change per pixel step in x.
    ray_dx: Vec3,
    /// Ray direction change per pixel step in y.
    ray_dy: Vec3,
}

impl View {
    /// Prepares `camera` for a `width`×`height` image (both non-zero). The rays match
    /// [`Camera::ray_direction`] up to scale.
    pub fn new(camera: &Camera, width: u32, height: u32) -> Self {
        let aspect = width as f32 / height as f32;
        let forward = (camera.target - camera.position).normalize();
        let right = forward.cross(camera.up).normalize();
        let up = right.cross(forward);
        let tan_y = (camera.fov_y * 0.5).tan();
        let tan_x = tan_y * aspect;
        let ray_dx = right * (2.0 * tan_x / width as f32);
        let ray_dy = up * (-2.0 * tan_y / height as f32);
        let ray00 = forward - tan_x * right + tan_y * up + 0.5 * (ray_dx + ray_dy);
        let inv_far = 1.0 / camera.far as f64;
        Self {
            width,
            height,
            view_proj: camera.projection(aspect) * camera.view(),
            origin: camera.position,
            forward,
            // A clearly positive near distance keeps clip-space w well above 0 after clipping.
            near: camera.near.max(MIN_NEAR),
            inv_far: if inv_far.is_finite() && inv_far > 0.0 {
                inv_far
            } else {
                0.0
            },
            ray00,
            ray_dx,
            ray_dy,
        }
    }

    /// World-space primary ray direction through the centre of pixel (`x`, `y`), scaled so
    /// that its component along [`View::forward`] is 1 (ray parameter = view depth).
    pub fn pixel_ray(&self, x: u32, y: u32) -> Vec3 {
        self.ray00 + x as f32 * self.ray_dx + y as f32 * self.ray_dy
    }

    /// Coefficients (c, a, b) with `pixel_ray(x, y)·v = c + a·x + b·y`.
    pub fn pixel_affine(&self, v: Vec3) -> Vec3 {
        Vec3::new(self.ray00.dot(v), self.ray_dx.dot(v), self.ray_dy.dot(v))
    }

    /// Coefficients (a, b, c) with 1/depth = a·x + b·y + c at the centre of pixel (x, y) for the
    /// plane through the world-space triangle `tri`, or `None` when the plane contains the eye.
    pub fn inverse_depth_plane(&self, tri: [Vec3; 3]) -> Option<[f64; 3]> {
        let o = self.origin.as_dvec3();
        let [p0, p1, p2] = tri.map(|p| p.as_dvec3() - o);
        let n = (p1 - p0).cross(p2 - p0);
        let c = n.dot(p0);
        if c == 0.0 || !c.is_finite() {
            return None;
        }
        // The eye ray o + t·d meets the plane n·(p − o) = c at t = c / n·d, and d is affine in
        // the pixel coordinates, so 1/t is too.
        let dot = |v: Vec3| n.dot(v.as_dvec3()) / c;
        Some([dot(self.ray_dx), dot(self.ray_dy), dot(self.ray00)])
    }
}
