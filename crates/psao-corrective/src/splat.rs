//! Splatting samples into a frame: each sample is projected to its pixel and written as a
//! square of its level's footprint, only onto pixels of its own object (the paper's stencil
//! test), coarse levels first. The centre pixel must show the sample's object at about the
//! sample's depth, so samples that became occluded or left their object are not drawn.
//!
//! The frame is cut into bands of rows written in parallel; every band visits the samples in
//! the same order, so the result does not depend on the number of threads.

use crate::screen::ScreenView;
use crate::sqrt5::{footprint_rect, Hierarchy};
use glam::Vec3;
use rayon::prelude::*;

/// One ray-traced correction sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// World-space hit position of the primary ray.
    pub position: Vec3,
    /// Unit shading normal at the hit, facing the camera it was traced from.
    pub normal: Vec3,
    /// `normal · v` at creation, `v` the unit direction from the hit to the eye.
    pub ndotv: f32,
    /// Linear RGB radiance of the pixel.
    pub color: [f32; 3],
    /// Object id (non-zero: instance × non-diffuse material).
    pub object: u32,
    /// √5 level (1 = coarsest).
    pub level: u8,
    /// Camera age when the sample was traced.
    pub age: u32,
}

/// The pixels splatting writes to, and what it reads to test them.
pub struct SplatTarget<'a> {
    /// Linear RGB per pixel, row-major.
    pub color: &'a mut [[f32; 3]],
    /// Set for every pixel a splat wrote.
    pub written: &'a mut [bool],
    /// Object id per pixel (0 = diffuse), the stencil.
    pub ids: &'a [u32],
    /// Depth along the viewing axis per pixel (the rasterizer's G-buffer depth).
    pub depth: &'a [f32],
}

/// Relative depth difference up to which a sample's centre pixel counts as showing it.
pub const DEPTH_TOLERANCE: f32 = 0.02;

/// A sample placed on screen.
#[derive(Clone, Copy)]
struct Placed {
    x0: i32,
    y0: i32,
    x1: i32,
    y1: i32,
    object: u32,
    color: [f32; 3],
}

/// Where a sample lands on screen, or `None` when it is off screen, occluded or on another object.
fn place(
    s: &Sample,
    view: &ScreenView,
    hierarchy: &Hierarchy,
    ids: &[u32],
    depth: &[f32],
) -> Option<Placed> {
    let (x, y, z) = view.project(s.position)?;
    let i = y as usize * view.width as usize + x as usize;
    if ids[i] != s.object || (depth[i] - z).abs() > DEPTH_TOLERANCE * z {
        return None;
    }
    let side = hierarchy.footprint(s.level).ok()?;
    let r = footprint_rect(x, y, side);
    Some(Placed {
        x0: r.x0.max(0),
        y0: r.y0.max(0),
        x1: r.x1.min(view.width as i32),
        y1: r.y1.min(view.height as i32),
        object: s.object,
        color: s.color,
    })
}

/// Splat `batches` in order (each batch in its order) into `target`; returns how many samples
/// were drawn.
///
/// # Panics
/// When the target's buffers are not `view.width × view.height` (a caller bug).
pub fn splat(
    batches: &[&[Sample]],
    hierarchy: &Hierarchy,
    view: &ScreenView,
    target: &mut SplatTarget<'_>,
) -> usize {
    let (w, h) = (view.width as usize, view.height as usize);
    let n = w * h;
    assert!(
        target.color.len() == n
            && target.written.len() == n
            && target.ids.len() == n
            && target.depth.len() == n,
        "splat target buffers must be {w}×{h}"
    );
    if n == 0 {
        return 0;
    }
    let (ids, depth) = (target.ids, target.depth);
    let mut placed: Vec<Placed> = Vec::new();
    for batch in batches {
        placed.par_extend(
            batch
                .par_iter()
                .filter_map(|s| place(s, view, hierarchy, ids, depth)),
        );
    }
    // Enough bands to balance the threads; each is a few rows high.
    let band_rows = h.div_ceil(rayon::current_num_threads() * 8).max(4);
    target
        .color
        .par_chunks_mut(band_rows * w)
        .zip(target.written.par_chunks_mut(band_rows * w))
        .enumerate()
        .for_each(|(band, (color, written))| {
            let by0 = (band * band_rows) as i32;
            let by1 = by0 + (color.len() / w) as i32;
            for p in &placed {
                if p.y1 <= by0 || p.y0 >= by1 {
                    continue;
                }
                for y in p.y0.max(by0)..p.y1.min(by1) {
                    let row = y as usize * w;
                    let local = (y - by0) as usize * w;
                    for x in p.x0 as usize..p.x1 as usize {
                        if ids[row + x] == p.object {
                            color[local + x] = p.color;
                            written[local + x] = true;
                        }
                    }
                }
            }
        });
    placed.len()
}
