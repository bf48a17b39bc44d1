//! The images of one evaluated frame that every ordering and budget shares: the G-buffer,
//! object ids, the base frame (the client's shading: with traced AO, or lit), the reference
//! (on diffuse pixels the base frame, or with lighting the path-traced diffuse lighting; the
//! reference's correction tracer on every non-diffuse pixel) and the reference's saliency map.

use glam::Vec3;
use psao_corrective::base::object_ids;
use psao_corrective::saliency::{saliency, Map, RgbImage};
use psao_corrective::screen::ScreenView;
use psao_corrective::session::Planned;
use psao_corrective::splat::Sample;
use psao_corrective::trace::{CorrectionTracer, DiffuseShade};
use psao_raster::{rasterize, GBuffer, RasterOptions};
use psao_scene::{Camera, Material, Scene};
use rayon::prelude::*;

/// Shared images of one frame.
pub struct FrameImages {
    /// The camera.
    pub camera: Camera,
    /// The camera as the splatting sees it.
    pub view: ScreenView,
    /// The rasterized G-buffer.
    pub gbuffer: GBuffer,
    /// Object id per pixel (0 = diffuse).
    pub ids: Vec<u32>,
    /// The base frame (linear RGB).
    pub base: Vec<[f32; 3]>,
    /// The reference (linear RGB).
    pub reference: Vec<[f32; 3]>,
    /// The reference as 8-bit sRGB.
    pub reference_srgb: Vec<u8>,
    /// Saliency of the reference, normalised (metric weights).
    pub reference_saliency: Map,
    /// Camera age (number of camera changes so far): the key of this frame's samples.
    pub camera_age: u32,
    /// With view-dependent samples over a lit base: the share of the base each pixel keeps
    /// under a correction ([`psao_corrective::splat::SplatTarget::keep`]).
    pub keep: Option<Vec<f32>>,
}

/// The linear image as the saliency model's input.
pub fn rgb_image(pixels: &[[f32; 3]], width: u32, height: u32) -> RgbImage {
    RgbImage {
        width: width as usize,
        height: height as usize,
        pixels: pixels.to_vec(),
    }
}

/// One correction sample at pixel (x, y): the tracer's colour, the G-buffer's surface.
pub fn trace_sample(tracer: &CorrectionTracer<'_>, f: &FrameImages, p: &Planned) -> Sample {
    let (w, h) = (f.gbuffer.width, f.gbuffer.height);
    let i = f.gbuffer.index(p.x as u32, p.y as u32);
    let dir = f
        .camera
        .ray_direction(p.x as f32 + 0.5, p.y as f32 + 0.5, w, h);
    let (color, _) = tracer.primary(f.camera.position, dir, f.camera_age as u64, i as u64);
    let position = f.gbuffer.position[i];
    let normal = f.gbuffer.normal[i];
    let v = (f.camera.position - position).normalize_or_zero();
    Sample {
        position,
        normal,
        ndotv: normal.dot(v),
        color: color.to_array(),
        object: p.object,
        level: p.level,
        age: f.camera_age,
    }
}

/// How the reference of a frame is rendered.
pub struct ReferenceShading<'a> {
    /// The correction tracer of the non-diffuse pixels.
    pub tracer: &'a CorrectionTracer<'a>,
    /// The shading of the diffuse pixels; `None`: the base frame's.
    pub diffuse: Option<&'a dyn DiffuseShade>,
}

/// Renders the shared images of a frame: the base frame with `base` at every covered pixel,
/// the reference with `reference`.
pub fn frame_images(
    scene: &Scene,
    camera: Camera,
    camera_age: u32,
    (width, height): (u32, u32),
    base: &dyn DiffuseShade,
    reference: &ReferenceShading<'_>,
) -> FrameImages {
    let gbuffer = rasterize(scene, &camera, &RasterOptions::new(width, height));
    let ids = object_ids(scene, &gbuffer);
    let fallback = Material::default();
    let sky = psao_client::SKY_GREY;
    let shade = |shade: &dyn DiffuseShade, i: usize| {
        if !gbuffer.covered(i) {
            return sky;
        }
        let m = gbuffer
            .material(scene, i)
            .and_then(|m| scene.materials.get(m))
            .unwrap_or(&fallback);
        let (p, n) = (gbuffer.position[i], gbuffer.normal[i]);
        shade.shade(p, n, gbuffer.instance[i], m).to_array()
    };
    let base_frame: Vec<[f32; 3]> = (0..gbuffer.len())
        .into_par_iter()
        .map(|i| shade(base, i))
        .collect();
    let tracer = reference.tracer;
    let reference: Vec<[f32; 3]> = (0..gbuffer.len())
        .into_par_iter()
        .map(|i| {
            if ids[i] == 0 {
                return reference.diffuse.map_or(base_frame[i], |d| shade(d, i));
            }
            let (x, y) = (i as u32 % width, i as u32 / width);
            let dir = camera.ray_direction(x as f32 + 0.5, y as f32 + 0.5, width, height);
            let (c, _): (Vec3, _) =
                tracer.primary(camera.position, dir, camera_age as u64, i as u64);
            c.to_array()
        })
        .collect();
    let reference_srgb = psao_client::composite_srgb8(&reference);
    let reference_saliency = saliency(&rgb_image(&reference, width, height));
    FrameImages {
        view: ScreenView::new(&camera, width, height),
        camera,
        gbuffer,
        ids,
        base: base_frame,
        reference,
        reference_srgb,
        reference_saliency,
        camera_age,
        keep: None,
    }
}
