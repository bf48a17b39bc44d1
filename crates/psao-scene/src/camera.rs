//! A pinhole camera: the view every rasterized or ray-cast image is made from.

use glam::{Mat4, Vec3};

/// A perspective pinhole camera in world space (right-handed, y up by default).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Eye position.
    pub position: Vec3,
    /// Point looked at.
    pub target: Vec3,
    /// Up hint.
    pub up: Vec3,
    /// Vertical field of view in radians.
    pub fov_y: f32,
    /// Near clip distance (> 0).
    pub near: f32,
    /// Far clip distance.
    pub far: f32,
}

impl Camera {
    /// A camera at `position` looking at `target` with y up and the given vertical FOV in degrees.
    pub fn look_at(position: Vec3, target: Vec3, fov_y_deg: f32) -> Self {
        Self {
            position,
            target,
            up: Vec3::Y,
            fov_y: fov_y_deg.to_radians(),
            near: 0.05,
            far: 1000.0,
        }
    }

    /// World-to-view matrix (right-handed, camera looks down −z).
    pub fn view(&self) -> Mat4 {
        glam::camera::rh::view::look_at_mat4(self.position, self.target, self.up)
    }

    /// View-to-clip matrix for an image of the given aspect (width / height), depth in [0, 1].
    pub fn projection(&self, aspect: f32) -> Mat4 {
        glam::camera::rh::proj::directx::perspective(self.fov_y, aspect, self.near, self.far)
    }

    /// World-space direction of the primary ray through pixel coordinates (`px`, `py`)
    /// (continuous, origin at the image's top-left corner) of a `width`×`height` image.
    pub fn ray_direction(&self, px: f32, py: f32, width: u32, height: u32) -> Vec3 {
        let forward = (self.target - self.position).normalize();
        let right = forward.cross(self.up).normalize();
        let up = right.cross(forward);
        let tan = (self.fov_y * 0.5).tan();
        let aspect = width as f32 / height as f32;
        let x = (2.0 * px / width as f32 - 1.0) * tan * aspect;
        let y = (1.0 - 2.0 * py / height as f32) * tan;
        (forward + x * right + y * up).normalize()
    }
}
