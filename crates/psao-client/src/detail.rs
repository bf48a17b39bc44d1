//! Screen-space detail below the point spacing: a contact term scaled by the local spacing.
//!
//! The reconstruction interpolates point values over a radius of several point spacings, so
//! occlusion that varies on a smaller scale (a groove, a bar's contact line) comes out
//! blurred. Here the G-buffer supplies that scale: per pixel a horizon-style near-field
//! occlusion `o` within `radius` Poisson radii of the pixel's instance is measured in screen
//! space, and compared with its mean `ō` over the reconstruction footprint (tent weights,
//! same surface). The points' interpolated AO already holds the footprint's mean near-field
//! visibility, so the pixel gets `AO · ((1 − o)/(1 − ō))^strength`: the detail is
//! redistributed within the footprint, and a flat open surface (`o = ō = 0`) is untouched.
//! Every radius follows the point spacing of the pixel's instance, so denser points make
//! the term narrower and it fades out where the spacing falls under a pixel.

use crate::state::ClientState;
use glam::Vec3;
use psao_raster::GBuffer;
use psao_scene::Camera;
use rayon::prelude::*;

/// Screen directions sampled per pixel.
const DIRECTIONS: usize = 8;
/// Samples per direction.
const STEPS: usize = 4;
/// Largest sampling radius in pixels (a surface right in front of the camera).
const MAX_RADIUS_PX: f32 = 32.0;

/// Settings of the detail term.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DetailSettings {
    /// Near-field radius in Poisson radii of the pixel's instance.
    pub radius: f32,
    /// Radius, in Poisson radii, of the footprint whose mean near-field visibility the
    /// interpolated points already contain (the reconstruction radius).
    pub footprint: f32,
    /// Exponent of the visibility ratio (0 disables the term).
    pub strength: f32,
    /// Largest distance from the pixel's tangent plane, in Poisson radii, of a footprint
    /// pixel counted in the mean (as the reconstruction's plane test).
    pub plane_tolerance: f32,
}

impl Default for DetailSettings {
    fn default() -> Self {
        Self {
            radius: 3.0,
            footprint: psao_points::DEFAULT_INTERPOLATION_FACTOR,
            strength: 1.0,
            plane_tolerance: psao_points::DEFAULT_PLANE_TOLERANCE,
        }
    }
}

/// World size of the Poisson radius per instance (`None`: no grid or transform yet).
fn world_radii(state: &ClientState) -> Vec<Option<f32>> {
    (0..state.instance_count())
        .map(|i| {
            let grid = state.grid(i)?;
            let t = state.transform(i)?;
            let scale = t.matrix3.determinant().abs().cbrt();
            let r = grid.layout().poisson_radius * scale;
            (r > 0.0 && r.is_finite()).then_some(r)
        })
        .collect()
}

/// Multiplies `ao` (one value per pixel of `gbuffer`, as [`crate::reconstruct`] returns it)
/// by the detail term for the view of `camera`. Deterministic; rows run in parallel.
pub fn apply_detail(
    state: &ClientState,
    gbuffer: &GBuffer,
    camera: &Camera,
    settings: &DetailSettings,
    ao: &mut [f32],
) {
    let (w, h) = (gbuffer.width as usize, gbuffer.height as usize);
    if settings.strength == 0.0 || w == 0 || h == 0 || ao.len() != w * h {
        return;
    }
    if gbuffer.position.len() != w * h
        || gbuffer.normal.len() != w * h
        || gbuffer.depth.len() != w * h
        || gbuffer.instance.len() != w * h
    {
        return;
    }
    // World size of one pixel at unit depth.
    let pixel = 2.0 * (camera.fov_y * 0.5).tan() / h as f32;
    if !(pixel > 0.0 && pixel.is_finite()) {
        return;
    }
    let radii = world_radii(state);
    let dirs: [(f32, f32); DIRECTIONS] = std::array::from_fn(|k| {
        let a = (k as f32 + 0.5) * std::f32::consts::TAU / DIRECTIONS as f32;
        (a.cos(), a.sin())
    });
    let spacing = |i: usize| -> Option<f32> {
        let inst = gbuffer.instance[i];
        let r = (*radii.get(inst as usize)?)?;
        let z = gbuffer.depth[i];
        (z > 0.0 && z.is_finite()).then_some(r)
    };
    // Visits the pixels on DIRECTIONS × STEPS samples within `radius_px` of (x, y).
    let taps = |x: usize, y: usize, radius_px: f32, f: &mut dyn FnMut(usize)| {
        for &(dx, dy) in &dirs {
            for s in 1..=STEPS {
                let t = radius_px * s as f32 / STEPS as f32;
                let qx = (x as f32 + 0.5 + dx * t).floor();
                let qy = (y as f32 + 0.5 + dy * t).floor();
                if qx < 0.0 || qy < 0.0 || qx >= w as f32 || qy >= h as f32 {
                    break;
                }
                f(qy as usize * w + qx as usize);
            }
        }
    };
    // Pass 1: near-field visibility 1 − o per pixel.
    let mut vis = vec![1.0f32; w * h];
    vis.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, v) in row.iter_mut().enumerate() {
            let i = y * w + x;
            let Some(r) = spacing(i) else { continue };
            let rho = settings.radius * r;
            let radius_px = (rho / (gbuffer.depth[i] * pixel)).min(MAX_RADIUS_PX);
            if radius_px < 1.0 {
                continue;
            }
            let (p, n) = (gbuffer.position[i], gbuffer.normal[i]);
            let mut occlusion = 0.0f32;
            for &(dx, dy) in &dirs {
                let mut horizon = 0.0f32;
                for s in 1..=STEPS {
                    let t = radius_px * s as f32 / STEPS as f32;
                    let qx = (x as f32 + 0.5 + dx * t).floor();
                    let qy = (y as f32 + 0.5 + dy * t).floor();
                    if qx < 0.0 || qy < 0.0 || qx >= w as f32 || qy >= h as f32 {
                        break;
                    }
                    let q = qy as usize * w + qx as usize;
                    if gbuffer.instance[q] == GBuffer::NONE {
                        continue;
                    }
                    let d: Vec3 = gbuffer.position[q] - p;
                    let l = d.length();
                    if l >= rho || l <= 0.0 {
                        continue;
                    }
                    let sin_elevation = n.dot(d) / l;
                    horizon = horizon.max(sin_elevation * (1.0 - l / rho));
                }
                occlusion += horizon;
            }
            *v = 1.0 - occlusion / DIRECTIONS as f32;
        }
    });
    // Pass 2: the footprint's mean visibility, and the ratio applied to the AO.
    ao.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, a) in row.iter_mut().enumerate() {
            let i = y * w + x;
            let Some(r) = spacing(i) else { continue };
            let reach = settings.footprint * r;
            let radius_px = (reach / (gbuffer.depth[i] * pixel)).min(MAX_RADIUS_PX);
            let (p, n, inst) = (gbuffer.position[i], gbuffer.normal[i], gbuffer.instance[i]);
            let plane = settings.plane_tolerance * r;
            let (mut w_sum, mut v_sum) = (1.0f32, vis[i]);
            if radius_px >= 1.0 {
                taps(x, y, radius_px, &mut |q| {
                    if gbuffer.instance[q] != inst || gbuffer.normal[q].dot(n) <= 0.5 {
                        return;
                    }
                    let d: Vec3 = gbuffer.position[q] - p;
                    let l = d.length();
                    if l >= reach || n.dot(d).abs() > plane {
                        return;
                    }
                    let wt = 1.0 - l / reach;
                    w_sum += wt;
                    v_sum += wt * vis[q];
                });
            }
            let mean = (v_sum / w_sum).max(1e-3);
            let ratio = (vis[i] / mean).powf(settings.strength);
            *a = (*a * ratio).clamp(0.0, 1.0);
        }
    });
}
