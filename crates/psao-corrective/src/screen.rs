//! Projection of world points to the pixels of a camera image, matching the rasterizer's
//! conventions (pixel centres at half-integers, depth = distance along the viewing axis).

use glam::Vec3;
use psao_scene::Camera;

/// A camera prepared for one image size.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScreenView {
    /// Eye position.
    pub eye: Vec3,
    forward: Vec3,
    /// Right vector scaled by `1 / tan_x` so that `x_ndc = (p−eye)·right / depth`.
    right: Vec3,
    /// Up vector scaled by `1 / tan_y`.
    up: Vec3,
    near: f32,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
}

impl ScreenView {
    /// Prepares `camera` for a `width × height` image (both non-zero).
    pub fn new(camera: &Camera, width: u32, height: u32) -> Self {
        let forward = (camera.target - camera.position).normalize();
        let right = forward.cross(camera.up).normalize();
        let up = right.cross(forward);
        let tan_y = (camera.fov_y * 0.5).tan();
        let tan_x = tan_y * width as f32 / height.max(1) as f32;
        Self {
            eye: camera.position,
            forward,
            right: right / tan_x,
            up: up / tan_y,
            near: camera.near.max(1e-6),
            width,
            height,
        }
    }

    /// The pixel (x, y) whose area holds `p` and `p`'s depth along the viewing axis, or `None`
    /// when `p` is behind the near plane or outside the image.
    #[inline]
    pub fn project(&self, p: Vec3) -> Option<(i32, i32, f32)> {
        let d = p - self.eye;
        let depth = d.dot(self.forward);
        if depth < self.near || !depth.is_finite() {
            return None;
        }
        let x = (d.dot(self.right) / depth + 1.0) * 0.5 * self.width as f32;
        let y = (1.0 - d.dot(self.up) / depth) * 0.5 * self.height as f32;
        if !(x >= 0.0 && y >= 0.0 && x < self.width as f32 && y < self.height as f32) {
            return None;
        }
        Some((x as i32, y as i32, depth))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn projection_inverts_the_camera_rays() {
        let cam = Camera::look_at(Vec3::new(1.0, 2.0, 5.0), Vec3::new(0.0, 0.5, 0.0), 50.0);
        let (w, h) = (64, 36);
        let view = ScreenView::new(&cam, w, h);
        for (x, y) in [(0u32, 0u32), (63, 35), (10, 20), (32, 18)] {
            let dir = cam.ray_direction(x as f32 + 0.5, y as f32 + 0.5, w, h);
            let p = cam.position + dir * 3.0;
            let (px, py, depth) = view.project(p).unwrap();
            assert_eq!((px, py), (x as i32, y as i32));
            let forward = (cam.target - cam.position).normalize();
            assert!((depth - 3.0 * dir.dot(forward)).abs() < 1e-4);
        }
        let forward = (cam.target - cam.position).normalize();
        assert!(view.project(cam.position - forward * 3.0).is_none());
        assert!(view
            .project(cam.position + forward * 3.0 + Vec3::X * 100.0)
            .is_none());
    }
}
