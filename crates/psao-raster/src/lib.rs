//! CPU G-buffer rasterizer.
//!
//! Pipeline: transform every instance's vertices (in a given pose) to world and clip space;
//! set up triangles (homogeneous near-plane and guard-band clipping, 12-bit sub-pixel
//! fixed-point edge functions with the top-left fill rule); bin them into horizontal bands of
//! rows; then, one rayon task per band, keep the nearest triangle id per pixel centre (a
//! visibility buffer, depth-tested on the exact plane depth a ray cast through the pixel centre
//! would find) and resolve its attributes by intersecting the pixel-centre ray with that
//! triangle. Use a [`Rasterizer`] and one [`GBuffer`] per view in frame loops to reuse memory.
//!
//! Both windings are rasterized unless [`RasterOptions::cull_backfaces`]; fragments beyond the
//! camera's far distance are dropped, and so are fragments of alpha-masked materials where the
//! surface is cut out ([`psao_scene::Material::opaque_at`] at the pixel centre's texture
//! coordinates), so what lies behind shows through.
//!
//! [`ShadowMaps`] renders depth maps of suns and point lights with the same rasterizer and
//! gives the shadowed direct light they cast (the client's share of DESIGN §12).

mod clip;
mod gbuffer;
mod geometry;
mod mask;
mod pose;
mod raster;
mod rasterizer;
mod resolve;
mod setup;
mod shadow;
mod view;

use psao_scene::{Camera, Scene};

pub use gbuffer::GBuffer;
pub use pose::{validate_poses, InstancePose, PoseError};
pub use rasterizer::Rasterizer;
pub use setup::MAX_DIMENSION;
pub use shadow::{ShadowMaps, ShadowSettings};

/// Image size and culling for one rasterization.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RasterOptions {
    /// Image width in pixels (clamped to [`MAX_DIMENSION`]).
    pub width: u32,
    /// Image height in pixels (clamped to [`MAX_DIMENSION`]).
    pub height: u32,
    /// Drop back faces (clockwise as seen) of single-sided materials; double-sided materials
    /// always keep both faces.
    pub cull_backfaces: bool,
}

impl RasterOptions {
    /// Options for a `width`×`height` image rasterizing both faces.
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            cull_backfaces: false,
        }
    }
}

/// Rasterizes `scene` with every instance at its stored transform and undeformed mesh.
/// Triangles with out-of-range indices and instances with a missing mesh are skipped.
pub fn rasterize(scene: &Scene, camera: &Camera, opts: &RasterOptions) -> GBuffer {
    let mut out = GBuffer::empty(0, 0);
    Rasterizer::new().rasterize(scene, camera, opts, &mut out);
    out
}

/// Rasterizes `scene` with instance `i` posed by `poses[i]` (transform and optionally deformed
/// positions/normals, e.g. after animation and skinning).
pub fn rasterize_posed(
    scene: &Scene,
    poses: &[InstancePose<'_>],
    camera: &Camera,
    opts: &RasterOptions,
) -> Result<GBuffer, PoseError> {
    let mut out = GBuffer::empty(0, 0);
    Rasterizer::new().rasterize_posed(scene, poses, camera, opts, &mut out)?;
    Ok(out)
}
