//! CPU volume rendering: level-set first hit (depth shaded), fog optical depth and single
//! scattering from one directional light with delta tracking, plus the dense fixed-step
//! level-set baseline used to measure what HDDA saves.

use crate::grid::{GridClass, BRICK_VOXELS};
use crate::rng::Rng;
use crate::sample::Sampler;
use crate::trace::{delta_track, level_set_hit, optical_depth, step_length, IndexRay};
use crate::tree::Locate;
use crate::volume::Volume;
use crate::{Result, VolumeError};
use glam::{IVec3, Vec3};
use rayon::prelude::*;
use std::sync::Mutex;

/// A pinhole camera in world space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Eye position.
    pub eye: Vec3,
    /// Point looked at.
    pub target: Vec3,
    /// Up vector.
    pub up: Vec3,
    /// Vertical field of view in degrees.
    pub fov_y_deg: f32,
}

impl Camera {
    /// A camera looking at the centre of `bounds` from a fixed oblique direction, far enough
    /// that the bounding sphere fills the view.
    pub fn framing(bounds: (Vec3, Vec3), fov_y_deg: f32) -> Camera {
        let centre = (bounds.0 + bounds.1) * 0.5;
        let radius = ((bounds.1 - bounds.0).length() * 0.5).max(1e-3);
        let dir = Vec3::new(0.55, 0.35, 1.0).normalize();
        let dist = radius / (0.5 * fov_y_deg.to_radians()).sin() * 1.02;
        Camera {
            eye: centre + dir * dist,
            target: centre,
            up: Vec3::Y,
            fov_y_deg,
        }
    }

    /// Unit world direction through pixel (x, y) of a `w`×`h` image (pixel centres).
    pub fn ray_dir(&self, x: u32, y: u32, w: u32, h: u32) -> Vec3 {
        self.pixel_rays(w, h).dir(x, y)
    }

    /// The camera's frame for a `w`×`h` image, computed once for all its pixels.
    pub fn pixel_rays(&self, w: u32, h: u32) -> PixelRays {
        let f = (self.target - self.eye).normalize();
        let r = f.cross(self.up).normalize();
        let u = r.cross(f);
        let th = (0.5 * self.fov_y_deg.to_radians()).tan();
        PixelRays {
            f,
            r,
            u,
            th,
            aspect: w as f32 / h as f32,
            w: w as f32,
            h: h as f32,
        }
    }
}

/// Pixel ray directions of one camera and image size ([`Camera::pixel_rays`]).
#[derive(Clone, Copy, Debug)]
pub struct PixelRays {
    f: Vec3,
    r: Vec3,
    u: Vec3,
    th: f32,
    aspect: f32,
    w: f32,
    h: f32,
}

impl PixelRays {
    /// Unit world direction through the centre of pixel (x, y).
    #[inline]
    pub fn dir(&self, x: u32, y: u32) -> Vec3 {
        let sx = ((x as f32 + 0.5) / self.w * 2.0 - 1.0) * self.th * self.aspect;
        let sy = (1.0 - (y as f32 + 0.5) / self.h * 2.0) * self.th;
        (self.f + self.r * sx + self.u * sy).normalize()
    }
}

/// What to render.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RenderMode {
    /// Level-set first hit, shaded by depth.
    LevelSet,
    /// Accumulated fog density: `1 - exp(-density_scale · τ)`.
    Fog,
    /// Single scattering of one directional light, delta tracking.
    DeltaTrack,
}

/// Render settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderSettings {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Mode.
    pub mode: RenderMode,
    /// Frame of the volume.
    pub frame: usize,
    /// Extinction per world unit at density 1.
    pub density_scale: f32,
    /// Direction towards the light (delta tracking).
    pub light_dir: Vec3,
    /// Samples per pixel (delta tracking).
    pub spp: u32,
    /// Seed (delta tracking).
    pub seed: u64,
}

impl RenderSettings {
    /// Defaults for `vol`: density scale so that density 1 over 8 voxels is one optical depth.
    pub fn new(vol: &Volume, width: u32, height: u32, mode: RenderMode) -> Self {
        RenderSettings {
            width,
            height,
            mode,
            frame: 0,
            density_scale: 1.0 / (8.0 * vol.transform.scale.min_element() as f32),
            light_dir: Vec3::new(0.3, 1.0, 0.4).normalize(),
            spp: 8,
            seed: 1,
        }
    }
}

/// A grey image, row-major, values in 0..=1.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width.
    pub width: u32,
    /// Height.
    pub height: u32,
    /// Pixels.
    pub pixels: Vec<f32>,
}

impl Image {
    /// Mean absolute difference to another image of the same size.
    pub fn mean_abs_diff(&self, other: &Image) -> f32 {
        let n = self.pixels.len().max(1) as f32;
        self.pixels
            .iter()
            .zip(&other.pixels)
            .map(|(a, b)| (a - b).abs())
            .sum::<f32>()
            / n
    }
}

/// Edge of the pixel tiles (neighbouring rays reuse decoded bricks).
const TILE: u32 = 16;

fn check(vol: &Volume, cam: &Camera, st: &RenderSettings) -> Result<()> {
    if st.width == 0 || st.height == 0 || st.frame >= vol.frames() {
        return Err(VolumeError::InvalidParameter(format!(
            "image {}x{} / frame {} of {}",
            st.width,
            st.height,
            st.frame,
            vol.frames()
        )));
    }
    if st.mode == RenderMode::LevelSet && vol.class != GridClass::LevelSet {
        return Err(VolumeError::InvalidParameter(
            "level-set rendering needs a level-set volume".into(),
        ));
    }
    if (cam.target - cam.eye).length() <= 0.0 {
        return Err(VolumeError::InvalidParameter(
            "camera eye equals target".into(),
        ));
    }
    Ok(())
}

/// Depth shading range: distances from the eye to the nearest and farthest bounds corners.
fn depth_range(vol: &Volume, frame: usize, eye: Vec3) -> (f32, f32) {
    let (lo, hi) = vol.world_bounds(frame);
    let mut near = f32::INFINITY;
    let mut far: f32 = 0.0;
    for c in psao_scene::affine::box_corners(lo, hi) {
        near = near.min((c - eye).length());
        far = far.max((c - eye).length());
    }
    let centre = ((lo + hi) * 0.5 - eye).length();
    (near.min(centre * 0.5), far.max(near + 1e-3))
}

fn shade_depth(t: Option<f32>, range: (f32, f32)) -> f32 {
    t.map_or(0.0, |t| {
        (1.0 - (t - range.0) / (range.1 - range.0)).clamp(0.05, 1.0)
    })
}

/// Renders `vol` with HDDA through the flat tree.
pub fn render(vol: &Volume, cam: &Camera, st: &RenderSettings) -> Result<Image> {
    check(vol, cam, st)?;
    let (w, h) = (st.width, st.height);
    let range = depth_range(vol, st.frame, cam.eye);
    let rays = cam.pixel_rays(w, h);
    // The eye and the world-to-index direction scale, mapped once for all pixels.
    let eye = vol.transform.world_to_index(cam.eye);
    let to_index = (1.0 / vol.transform.scale).as_vec3();
    let tiles_x = w.div_ceil(TILE);
    let tiles = tiles_x * h.div_ceil(TILE);
    // Runs of consecutive tiles, each rendered by one sampler taken from a shared stack and
    // put back after, so decoded bricks stay warm across runs (rayon may split work into
    // many more jobs than threads; a fresh cache per job would decode everything again).
    let runs = (16 * rayon::current_num_threads() as u32).clamp(1, tiles);
    let free: Mutex<Vec<Sampler>> = Mutex::new(Vec::new());
    let tile_pixels: Vec<Vec<(u32, f32)>> = (0..runs)
        .into_par_iter()
        .map(|run| {
            let mut s = free
                .lock()
                .map(|mut f| f.pop())
                .unwrap_or(None)
                .unwrap_or_else(|| Sampler::new(vol, st.frame));
            let mut out = Vec::new();
            for tile in tiles * run / runs..tiles * (run + 1) / runs {
                let (x0, y0) = ((tile % tiles_x) * TILE, (tile / tiles_x) * TILE);
                for y in y0..(y0 + TILE).min(h) {
                    for x in x0..(x0 + TILE).min(w) {
                        let ray = IndexRay::new(eye, rays.dir(x, y) * to_index);
                        let v = match st.mode {
                            RenderMode::LevelSet => {
                                shade_depth(level_set_hit(&mut s, &ray, f32::INFINITY), range)
                            }
                            RenderMode::Fog => {
                                1.0 - (-st.density_scale
                                    * optical_depth(&mut s, &ray, f32::INFINITY))
                                .exp()
                            }
                            RenderMode::DeltaTrack => {
                                let pixel = (y as u64) * w as u64 + x as u64;
                                let mut rng = Rng::new(st.seed, pixel);
                                single_scatter(&mut s, &ray, st, &mut rng)
                            }
                        };
                        out.push((y * w + x, v));
                    }
                }
            }
            if let Ok(mut f) = free.lock() {
                f.push(s);
            }
            out
        })
        .collect();
    let mut pixels = vec![0.0f32; (w * h) as usize];
    for (i, v) in tile_pixels.into_iter().flatten() {
        pixels[i as usize] = v;
    }
    Ok(Image {
        width: w,
        height: h,
        pixels,
    })
}

/// One pixel of single scattering: mean over `spp` delta-tracked collisions of the light
/// transmittance (albedo 1, isotropic phase normalised so a fully lit collision gives 1).
fn single_scatter(s: &mut Sampler, ray: &IndexRay, st: &RenderSettings, rng: &mut Rng) -> f32 {
    let vol = s.volume();
    let mut sum = 0.0;
    for _ in 0..st.spp {
        if let Some(t) = delta_track(s, ray, f32::INFINITY, st.density_scale, rng) {
            let p = vol.transform.index_to_world(ray.at(t));
            let to_light = IndexRay::from_world(vol, p, st.light_dir);
            sum += (-st.density_scale * optical_depth(s, &to_light, f32::INFINITY)).exp();
        }
    }
    sum / st.spp as f32
}

/// A dense copy of one frame over its index bounds (background outside the leaves).
pub struct DenseGrid {
    origin: IVec3,
    dims: IVec3,
    values: Vec<f32>,
}

impl DenseGrid {
    /// Decodes every brick of `frame` into a dense array.
    pub fn from_volume(vol: &Volume, frame: usize) -> DenseGrid {
        let (lo, hi) = vol.index_bounds(frame);
        let dims = hi - lo;
        let mut values = vec![vol.background; (dims.x * dims.y * dims.z) as usize];
        let mut b = [0.0; BRICK_VOXELS];
        for (f, i, o) in vol.tree.leaves() {
            if f != frame {
                continue;
            }
            vol.pool.decode(vol.tree.l3[i as usize].brick(), &mut b);
            for z in 0..8 {
                for y in 0..8 {
                    for x in 0..8 {
                        let p = o - lo + IVec3::new(x, y, z);
                        values[(p.x + dims.x * (p.y + dims.y * p.z)) as usize] =
                            b[crate::grid::voxel_index(x as usize, y as usize, z as usize)];
                    }
                }
            }
        }
        DenseGrid {
            origin: lo,
            dims,
            values,
        }
    }

    #[inline]
    fn at(&self, p: IVec3, background: f32) -> f32 {
        let l = p - self.origin;
        if l.min_element() < 0 || l.x >= self.dims.x || l.y >= self.dims.y || l.z >= self.dims.z {
            return background;
        }
        self.values[(l.x + self.dims.x * (l.y + self.dims.y * l.z)) as usize]
    }

    fn trilinear(&self, p: Vec3, background: f32) -> f32 {
        let b = crate::grid::floor_ivec(p);
        let f = p - b.as_vec3();
        let c = |dx, dy, dz| self.at(b + IVec3::new(dx, dy, dz), background);
        let x0 = c(0, 0, 0) + (c(1, 0, 0) - c(0, 0, 0)) * f.x;
        let x1 = c(0, 1, 0) + (c(1, 1, 0) - c(0, 1, 0)) * f.x;
        let x2 = c(0, 0, 1) + (c(1, 0, 1) - c(0, 0, 1)) * f.x;
        let x3 = c(0, 1, 1) + (c(1, 1, 1) - c(0, 1, 1)) * f.x;
        let y0 = x0 + (x1 - x0) * f.y;
        let y1 = x2 + (x3 - x2) * f.y;
        y0 + (y1 - y0) * f.z
    }
}

/// Level-set first hit by marching the dense grid at the same fixed step as HDDA rendering,
/// from where the ray enters the bounds (the baseline HDDA is measured against).
pub fn render_dense_level_set(
    vol: &Volume,
    dense: &DenseGrid,
    cam: &Camera,
    st: &RenderSettings,
) -> Result<Image> {
    check(vol, cam, st)?;
    let (w, h) = (st.width, st.height);
    let range = depth_range(vol, st.frame, cam.eye);
    let dt = step_length(vol);
    let (lo, hi) = vol.index_bounds(st.frame);
    let rays = cam.pixel_rays(w, h);
    let mut pixels = vec![0.0f32; (w * h) as usize];
    pixels.par_iter_mut().enumerate().for_each(|(k, px)| {
        let (x, y) = ((k % w as usize) as u32, (k / w as usize) as u32);
        let ray = IndexRay::from_world(vol, cam.eye, rays.dir(x, y));
        let mut hit = None;
        if let Some((a, b)) = ray.clip(lo.as_vec3(), hi.as_vec3()) {
            let mut t = a.max(0.0) + 0.5 * dt;
            let mut prev: Option<(f32, f32)> = None;
            while t < b {
                let v = dense.trilinear(ray.at(t), vol.background);
                if let Some((tp, vp)) = prev {
                    if vp > 0.0 && v <= 0.0 {
                        hit = Some(tp + (t - tp) * vp / (vp - v));
                        break;
                    }
                }
                prev = Some((t, v));
                t += dt;
            }
        }
        *px = shade_depth(hit, range);
    });
    Ok(Image {
        width: w,
        height: h,
        pixels,
    })
}

/// Whether index-space voxel `p` of `frame` lies in an L3 node (for tests and tools).
pub fn in_leaf(vol: &Volume, frame: usize, p: IVec3) -> bool {
    matches!(vol.tree.locate(frame, p), Locate::Leaf(..))
}
