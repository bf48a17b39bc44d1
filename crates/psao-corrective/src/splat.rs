//! Splatting samples into a frame, respecting what each sample knows.
//!
//! A sample is a correction of the base frame: its traced radiance minus the base's diffuse
//! value at its own pixel (the paper's additive blend), added to the pixels around it. Each
//! sample is projected to its pixel; it is drawn only when that pixel shows its object at
//! about its depth (occluded samples and samples that left their object are not drawn).
//! Around that pixel it reaches the pixels within its level's lattice spacing, but only those
//! that lie on its surface: same object id, within [`PLANE_TOLERANCE`] of its tangent plane
//! and with a normal within [`NORMAL_COS`] of its own, so a footprint stops at depth, normal
//! and object edges.
//!
//! At each pixel:
//! - a pixel that is some drawn sample's own pixel shows the radiance of the samples of its
//!   finest such level: the samples know it. When one of them was traced for the current
//!   camera age it shows that one (it knows the current view); otherwise, when several
//!   traces of other camera ages the cache still holds as valid have it as their own pixel,
//!   it shows their mean, so one stale trace's noise (e.g. a rare spike of a glossy
//!   highlight's area-light estimate) does not stand alone there;
//! - otherwise only the finest level whose samples reach the pixel counts (a coarse sample
//!   fills only pixels no finer sample covers), and its samples' corrections are blended
//!   with weights `(1 − d²/R²)²` falling with the distance `d` from each sample over its
//!   level's spacing `R` (1 at a sample's own pixel), accumulated and normalised by the
//!   larger of their sum and 1: where the samples' total weight is below that of one sample
//!   at its own pixel (the rim of a lone sample's reach) the correction fades towards the
//!   base in proportion, so a sample's confidence falls with the distance from it in units of
//!   its level's coarseness;
//! - a pixel no sample reaches keeps the base;
//! - a highlight ([`is_highlight`]) reaches its own pixel only.
//!
//! Over a lit base (diffuse light from the points and shadow maps, DESIGN §12) the samples
//! carry only the view-dependent part of their radiance (reflection, refraction,
//! highlights: the paper's additive corrections over a diffuse global-illumination base),
//! and each pixel they reach keeps the share of its base that its material's diffuse weight
//! leaves ([`SplatTarget::keep`]): the client's own diffuse light stays under the
//! corrections instead of the server's estimate of it.
//!
//! The frame is cut into bands of rows written in parallel; every band visits the samples in
//! the same order, so the result does not depend on the number of threads.

use crate::screen::ScreenView;
use crate::sqrt5::Hierarchy;
use glam::Vec3;
use psao_raster::GBuffer;
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

/// The frame splatting corrects, and what it reads to place samples.
pub struct SplatTarget<'a> {
    /// Linear RGB per pixel, row-major: the base frame as shown, corrected in place.
    pub color: &'a mut [[f32; 3]],
    /// The base's diffuse value per pixel that the samples' radiance is relative to (the
    /// client's diffuse shading the tracer reproduces on diffuse surfaces); the same as
    /// `color` when the frame shows that shading. Not read when `keep` is given.
    pub diffuse: &'a [[f32; 3]],
    /// `Some` when the samples carry only the view-dependent part of their radiance (a lit
    /// base, traced without the diffuse part of their own surface,
    /// [`crate::trace::TraceSettings::own_diffuse`]): per pixel, the share of the base that
    /// stays under a correction (the diffuse weight of its material at its view angle,
    /// [`crate::base::diffuse_keep`]). A pixel a sample reaches then shows
    /// `keep × base + the samples' radiance`, blended with the base by confidence as below.
    pub keep: Option<&'a [f32]>,
    /// Object id per pixel (0 = diffuse), the stencil.
    pub ids: &'a [u32],
    /// The frame's G-buffer: depth, world positions and normals.
    pub gbuffer: &'a GBuffer,
}

/// Relative depth difference up to which a sample's pixel counts as showing it.
pub const DEPTH_TOLERANCE: f32 = 0.02;
/// Distance from a sample's tangent plane, relative to the pixel's depth, up to which a pixel
/// counts as lying on the sample's surface.
pub const PLANE_TOLERANCE: f32 = 0.01;
/// Smallest cosine between a pixel's normal and a sample's normal for the sample to reach it.
pub const NORMAL_COS: f32 = 0.9;

/// Radiance above which a sample channel is a highlight: brighter than the display's white.
pub const HIGHLIGHT: f32 = 1.0;

/// Whether `s` is a highlight: some channel brighter than [`HIGHLIGHT`], a light (or a
/// bright reflection of one) seen in a glossy or mirror surface. Such a peak is narrower
/// than a pixel's neighbours and moves with the eye, so it is splatted to its own pixel only
/// and kept for its own view only ([`crate::cache`]).
pub fn is_highlight(s: &Sample) -> bool {
    s.color.iter().any(|&c| c > HIGHLIGHT)
}

/// A sample placed on screen.
#[derive(Clone, Copy)]
struct Placed {
    x: i32,
    y: i32,
    /// Reach in pixels (the level's lattice spacing).
    reach: f32,
    x0: i32,
    y0: i32,
    x1: i32,
    y1: i32,
    level: u8,
    /// Whether it was traced for the current camera age.
    fresh: bool,
    object: u32,
    position: Vec3,
    normal: Vec3,
    /// Traced radiance.
    color: [f32; 3],
    /// Traced radiance minus the base's diffuse value at the sample's pixel (the radiance
    /// itself when it is the view-dependent part only).
    correction: [f32; 3],
}

impl Placed {
    /// Whether pixel `i` lies on this sample's surface.
    fn reaches(&self, i: usize, ids: &[u32], g: &GBuffer) -> bool {
        ids[i] == self.object
            && g.normal[i].dot(self.normal) >= NORMAL_COS
            && (g.position[i] - self.position).dot(self.normal).abs()
                <= PLANE_TOLERANCE * g.depth[i]
    }
}

/// Where a sample lands on screen, or `None` when it is off screen, occluded or on another object.
fn place(
    s: &Sample,
    now: u32,
    view: &ScreenView,
    hierarchy: &Hierarchy,
    ids: &[u32],
    diffuse: Option<&[[f32; 3]]>,
    g: &GBuffer,
) -> Option<Placed> {
    let (x, y, z) = view.project(s.position)?;
    let i = y as usize * view.width as usize + x as usize;
    // The pixel must show the sample's surface: its object, at its depth, facing as it does
    // (a sample reprojected onto another face of its object, e.g. around a corner of a box
    // the eye walked past, corrects light it did not trace).
    if ids[i] != s.object
        || (g.depth[i] - z).abs() > DEPTH_TOLERANCE * z
        || g.normal[i].dot(s.normal) < NORMAL_COS
    {
        return None;
    }
    let (ux, uy) = hierarchy.basis(s.level).ok()?;
    let spacing = ((ux * ux + uy * uy) as f32).sqrt();
    // A highlight is narrower than any footprint: only its own pixel shows it.
    let reach = if is_highlight(s) { 1.0 } else { spacing };
    // Pixels strictly closer than `reach`: |dx|, |dy| ≤ ⌈reach⌉ − 1.
    let r = reach.ceil() as i32 - 1;
    let base = diffuse.map_or([0.0; 3], |d| d[i]);
    Some(Placed {
        x,
        y,
        reach,
        x0: (x - r).max(0),
        y0: (y - r).max(0),
        x1: (x + r + 1).min(view.width as i32),
        y1: (y + r + 1).min(view.height as i32),
        level: s.level,
        fresh: s.age == now,
        object: s.object,
        position: s.position,
        normal: s.normal,
        color: s.color,
        correction: std::array::from_fn(|c| s.color[c] - base[c]),
    })
}

/// What has reached one pixel so far.
#[derive(Clone, Copy, Default)]
struct Acc {
    /// Finest level blended here (0: none).
    level: u8,
    /// Sum of weights of that level.
    weight: f32,
    /// Weighted sum of corrections of that level.
    sum: [f32; 3],
    /// Finest level of a sample whose own pixel this is (0: none).
    own_level: u8,
    /// The summed radiance of that level's samples whose own pixel this is.
    own: [f32; 3],
    /// How many they are.
    own_count: u16,
    /// The summed radiance of those traced for the current camera age.
    fresh: [f32; 3],
    /// How many they are.
    fresh_count: u16,
}

impl Acc {
    fn add(&mut self, p: &Placed, x: i32, y: i32) {
        if x == p.x && y == p.y {
            if p.level > self.own_level {
                *self = Acc {
                    own_level: p.level,
                    own: [0.0; 3],
                    own_count: 0,
                    fresh: [0.0; 3],
                    fresh_count: 0,
                    ..*self
                };
            }
            if p.level == self.own_level && self.own_count < u16::MAX {
                self.own_count += 1;
                for c in 0..3 {
                    self.own[c] += p.color[c];
                }
                if p.fresh {
                    self.fresh_count += 1;
                    for c in 0..3 {
                        self.fresh[c] += p.color[c];
                    }
                }
            }
            return;
        }
        if p.level < self.level {
            return;
        }
        let (dx, dy) = ((x - p.x) as f32, (y - p.y) as f32);
        let q = 1.0 - (dx * dx + dy * dy) / (p.reach * p.reach);
        if q <= 0.0 {
            return;
        }
        if p.level > self.level {
            (self.level, self.weight, self.sum) = (p.level, 0.0, [0.0; 3]);
        }
        let w = q * q;
        self.weight += w;
        for c in 0..3 {
            self.sum[c] += w * p.correction[c];
        }
    }

    /// The radiance of the finest level's samples whose own pixel this is: those traced for
    /// the current view when there are any (they know it), else the mean of all (each an
    /// estimate of a nearby view, none better than the others).
    fn own_mean(&self) -> [f32; 3] {
        let (sum, n) = if self.fresh_count > 0 {
            (self.fresh, self.fresh_count)
        } else {
            (self.own, self.own_count.max(1))
        };
        sum.map(|v| v / f32::from(n))
    }

    /// The corrected pixel: `base` plus the correction, with `diffuse` the base's diffuse
    /// value there. A sample's own pixel gets the sample's radiance plus what the base adds to
    /// its diffuse value there: exactly the radiance when `base` is `diffuse`.
    fn resolve(&self, base: [f32; 3], diffuse: [f32; 3]) -> [f32; 3] {
        if self.own_level > 0 {
            let own = self.own_mean();
            std::array::from_fn(|c| own[c] + (base[c] - diffuse[c]))
        } else if self.weight > 0.0 {
            let norm = self.weight.max(1.0);
            std::array::from_fn(|c| base[c] + self.sum[c] / norm)
        } else {
            base
        }
    }

    /// The corrected pixel when the samples carry view-dependent radiance only and `keep`
    /// of `base` stays under it: a sample's own pixel is `keep × base` plus its radiance;
    /// elsewhere the blend `keep × base + Σ w·radiance / Σ w` is mixed with `base` by the
    /// confidence `min(Σ w, 1)`, so the rim of a lone sample fades towards the base.
    fn resolve_view_dependent(&self, base: [f32; 3], keep: f32) -> [f32; 3] {
        if self.own_level > 0 {
            let own = self.own_mean();
            std::array::from_fn(|c| keep * base[c] + own[c])
        } else if self.weight > 0.0 {
            let norm = self.weight.max(1.0);
            let confidence = self.weight.min(1.0);
            std::array::from_fn(|c| {
                base[c] + self.sum[c] / norm - confidence * (1.0 - keep) * base[c]
            })
        } else {
            base
        }
    }
}

/// Splat `batches` (samples of one level are averaged where they meet, up to rounding in
/// any order) into `target`, `now` being the current camera age (samples of that age know
/// their own pixel in this view); returns how many samples were drawn.
///
/// # Panics
/// When the target's buffers are not `view.width × view.height` (a caller bug).
pub fn splat(
    batches: &[&[Sample]],
    hierarchy: &Hierarchy,
    view: &ScreenView,
    now: u32,
    target: &mut SplatTarget<'_>,
) -> usize {
    let (w, h) = (view.width as usize, view.height as usize);
    let n = w * h;
    let g = target.gbuffer;
    assert!(
        target.color.len() == n
            && target.keep.map_or(target.diffuse.len(), <[f32]>::len) == n
            && target.ids.len() == n
            && g.depth.len() == n
            && g.position.len() == n
            && g.normal.len() == n,
        "splat target buffers must be {w}×{h}"
    );
    if n == 0 {
        return 0;
    }
    let (ids, diffuse, keep) = (target.ids, target.diffuse, target.keep);
    // View-dependent samples are corrections as they are.
    let relative_to = keep.is_none().then_some(diffuse);
    let mut placed: Vec<Placed> = Vec::new();
    for batch in batches {
        placed.par_extend(
            batch
                .par_iter()
                .filter_map(|s| place(s, now, view, hierarchy, ids, relative_to, g)),
        );
    }
    // Enough bands to balance the threads; each is a few rows high.
    let band_rows = h.div_ceil(rayon::current_num_threads() * 8).max(4);
    target
        .color
        .par_chunks_mut(band_rows * w)
        .enumerate()
        .for_each(|(band, color)| {
            let by0 = (band * band_rows) as i32;
            let by1 = by0 + (color.len() / w) as i32;
            let mut acc = vec![Acc::default(); color.len()];
            for p in &placed {
                if p.y1 <= by0 || p.y0 >= by1 {
                    continue;
                }
                for y in p.y0.max(by0)..p.y1.min(by1) {
                    let row = y as usize * w;
                    let local = (y - by0) as usize * w;
                    for x in p.x0..p.x1 {
                        if p.reaches(row + x as usize, ids, g) {
                            acc[local + x as usize].add(p, x, y);
                        }
                    }
                }
            }
            let offset = by0 as usize * w;
            for (i, (c, a)) in color.iter_mut().zip(&acc).enumerate() {
                *c = match keep {
                    Some(k) => a.resolve_view_dependent(*c, k[offset + i]),
                    None => a.resolve(*c, diffuse[offset + i]),
                };
            }
        });
    placed.len()
}

#[cfg(test)]
mod tests {
    use super::*;
    use psao_scene::Camera;

    const W: u32 = 40;
    const H: u32 = 30;

    /// A camera looking straight down at the plane z = 0 from `height`; pixels with `x <
    /// step_x` show a raised part of the same object at z = `step` (a depth edge), pixels
    /// with `x ≥ tilt_x` a part tilted about the y axis (a normal edge). Object 1 everywhere.
    struct Frame {
        view: ScreenView,
        g: GBuffer,
        ids: Vec<u32>,
    }

    fn frame(step_x: u32, step: f32, tilt_x: u32) -> Frame {
        let cam = Camera::look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO, 60.0);
        let view = ScreenView::new(&cam, W, H);
        let mut g = GBuffer::empty(W, H);
        let tilted = Vec3::new(0.6, 0.0, 0.8);
        for y in 0..H {
            for x in 0..W {
                let i = (y * W + x) as usize;
                let d = cam.ray_direction(x as f32 + 0.5, y as f32 + 0.5, W, H);
                let (z, n) = if x < step_x {
                    (step, Vec3::Z)
                } else {
                    (0.0, if x >= tilt_x { tilted } else { Vec3::Z })
                };
                let p = cam.position + d * ((z - cam.position.z) / d.z);
                g.position[i] = p;
                g.normal[i] = n;
                g.depth[i] = cam.position.z - p.z;
            }
        }
        Frame {
            view,
            g,
            ids: vec![1; (W * H) as usize],
        }
    }

    /// A sample traced at pixel (x, y) of `f` with `color`.
    fn sample_at(f: &Frame, x: u32, y: u32, level: u8, color: [f32; 3]) -> Sample {
        let i = (y * W + x) as usize;
        Sample {
            position: f.g.position[i],
            normal: f.g.normal[i],
            ndotv: 1.0,
            color,
            object: 1,
            level,
            age: 0,
        }
    }

    /// `batches` splatted over `base` (also the diffuse value) at camera age 0.
    fn run(f: &Frame, h: &Hierarchy, base: &[[f32; 3]], batches: &[&[Sample]]) -> Vec<[f32; 3]> {
        run_at(f, h, base, batches, 0)
    }

    /// `batches` splatted over `base` at camera age `now`.
    fn run_at(
        f: &Frame,
        h: &Hierarchy,
        base: &[[f32; 3]],
        batches: &[&[Sample]],
        now: u32,
    ) -> Vec<[f32; 3]> {
        let mut color = base.to_vec();
        splat(
            batches,
            h,
            &f.view,
            now,
            &mut SplatTarget {
                color: &mut color,
                diffuse: base,
                keep: None,
                ids: &f.ids,
                gbuffer: &f.g,
            },
        );
        color
    }

    fn grey(v: f32) -> Vec<[f32; 3]> {
        vec![[v; 3]; (W * H) as usize]
    }

    fn at(img: &[[f32; 3]], x: u32, y: u32) -> f32 {
        img[(y * W + x) as usize][0]
    }

    /// The weight of a sample at squared distance `d2` with reach² `r2`.
    fn weight(d2: f32, r2: f32) -> f32 {
        (1.0 - d2 / r2).powi(2)
    }

    #[test]
    fn a_coarse_sample_never_overwrites_a_pixel_a_finer_one_covers() {
        let f = frame(0, 0.0, W);
        let h = Hierarchy::new(4).unwrap();
        let base = grey(0.5);
        // Level 1 (reach 11.2 px) at (20, 15) says +0.4; level 3 (reach 2.2 px) at (24, 15)
        // says −0.2. Pixels the fine one reaches take its correction alone, whichever order.
        let coarse = [sample_at(&f, 20, 15, 1, [0.9; 3])];
        let fine = [sample_at(&f, 24, 15, 3, [0.3; 3])];
        for batches in [[&coarse[..], &fine[..]], [&fine[..], &coarse[..]]] {
            let img = run(&f, &h, &base, &batches);
            for (x, y) in [(23, 15), (25, 15), (24, 14), (25, 16), (24, 17)] {
                let d2 = ((x - 24) * (x - 24) + (y - 15) * (y - 15)) as f32;
                let fine_alone = 0.5 - 0.2 * weight(d2, 5.0);
                assert!(
                    (at(&img, x as u32, y as u32) - fine_alone).abs() < 1e-6,
                    "({x}, {y})"
                );
            }
            assert_eq!(at(&img, 24, 15), 0.3);
            // Beyond the fine reach the coarse one fills, thinner with distance.
            let coarse_at = |d2: f32| 0.5 + 0.4 * (1.0 - d2 / 125.0).powi(2);
            assert!((at(&img, 21, 15) - coarse_at(1.0)).abs() < 1e-6);
            assert_eq!(at(&img, 20, 15), 0.9);
            assert!((at(&img, 20, 24) - coarse_at(81.0)).abs() < 1e-6);
            // Outside every reach: the base.
            assert_eq!(at(&img, 20, 29), 0.5);
        }
    }

    #[test]
    fn samples_of_one_level_blend_by_distance() {
        let f = frame(0, 0.0, W);
        let h = Hierarchy::new(2).unwrap();
        let base = grey(0.0);
        // Level 1 of 2: reach √5. Two samples 2 px apart: the pixel between (weight 0.64
        // from each, 1.28 in all) gets their mean; a pixel only one reaches, with weight 0.64
        // below one sample's, gets 0.64 of its correction.
        let s = [
            sample_at(&f, 10, 10, 1, [0.25; 3]),
            sample_at(&f, 12, 10, 1, [0.75; 3]),
        ];
        let img = run(&f, &h, &base, &[&s]);
        assert!((at(&img, 11, 10) - 0.5).abs() < 1e-6);
        assert_eq!(at(&img, 10, 10), 0.25);
        assert_eq!(at(&img, 12, 10), 0.75);
        assert!((at(&img, 9, 10) - 0.25 * 0.64).abs() < 1e-6);
        assert!((at(&img, 13, 10) - 0.75 * 0.64).abs() < 1e-6);
    }

    #[test]
    fn a_pixel_shows_its_fresh_sample_or_else_the_mean_of_its_stale_ones() {
        let f = frame(0, 0.0, W);
        let h = Hierarchy::new(2).unwrap();
        let base = grey(0.2);
        let traced = |age: u32, v: f32| Sample {
            age,
            ..sample_at(&f, 10, 10, 2, [v; 3])
        };
        // Three traces of pixel (10, 10) at level 2 at camera ages 1–3, one a noise spike:
        // at age 5 none knows the current view, and the pixel shows their mean, whatever
        // their order; a coarser sample there does not count.
        let mut stale = [traced(1, 0.3), traced(2, 0.9), traced(3, 0.3)];
        let coarse = [Sample {
            age: 5,
            ..sample_at(&f, 10, 10, 1, [0.0; 3])
        }];
        for _ in 0..3 {
            let img = run_at(&f, &h, &base, &[&coarse, &stale], 5);
            assert!((at(&img, 10, 10) - 0.5).abs() < 1e-6);
            stale.rotate_left(1);
        }
        // A trace for the current view knows the pixel: it shows that one exactly.
        let fresh = [traced(5, 0.7)];
        for batches in [[&stale[..], &fresh[..]], [&fresh[..], &stale[..]]] {
            assert_eq!(at(&run_at(&f, &h, &base, &batches, 5), 10, 10), 0.7);
        }
        // A lone stale sample shows itself exactly.
        assert_eq!(at(&run_at(&f, &h, &base, &[&stale[..1]], 5), 10, 10), 0.3);
    }

    #[test]
    fn a_highlight_reaches_its_own_pixel_only() {
        let f = frame(0, 0.0, W);
        let h = Hierarchy::new(3).unwrap();
        let base = grey(0.5);
        // Level 1 of 3 reaches 5 px; brighter than white it reaches none of them.
        let dim = sample_at(&f, 20, 15, 1, [0.9; 3]);
        let bright = sample_at(&f, 20, 15, 1, [0.9, 4.0, 0.9]);
        assert!(!is_highlight(&dim) && is_highlight(&bright));
        assert!(at(&run(&f, &h, &base, &[&[dim]]), 21, 15) > 0.5);
        let img = run(&f, &h, &base, &[&[bright]]);
        assert_eq!(img[(15 * W + 20) as usize], [0.9, 4.0, 0.9]);
        for (x, y) in [(21, 15), (19, 15), (20, 16), (22, 17)] {
            assert_eq!(at(&img, x, y), 0.5, "({x}, {y})");
        }
    }

    #[test]
    fn a_sample_whose_pixel_faces_another_way_is_not_drawn() {
        // Columns ≥ 20 are tilted; the sample claims the flat part's normal at a tilted pixel
        // (the object's other face at its position and depth, as after a walk around a corner).
        let f = frame(0, 0.0, 20);
        let h = Hierarchy::new(3).unwrap();
        let base = grey(0.5);
        let mut s = sample_at(&f, 25, 15, 3, [0.9; 3]);
        s.normal = Vec3::Z;
        let mut color = base.clone();
        let drawn = splat(
            &[&[s]],
            &h,
            &f.view,
            0,
            &mut SplatTarget {
                color: &mut color,
                diffuse: &base,
                keep: None,
                ids: &f.ids,
                gbuffer: &f.g,
            },
        );
        assert_eq!(drawn, 0);
        assert_eq!(color, base);
        // Where the pixel faces as the sample does, it is drawn.
        let flat = sample_at(&f, 10, 15, 3, [0.9; 3]);
        assert_eq!(at(&run(&f, &h, &base, &[&[flat]]), 10, 15), 0.9);
    }

    #[test]
    fn a_footprint_stops_at_depth_and_normal_edges() {
        // Columns < 18 are raised by 0.5 (a depth edge at x = 18); columns ≥ 23 are tilted
        // (a normal edge at x = 23); all one object.
        let f = frame(18, 0.5, 23);
        let h = Hierarchy::new(3).unwrap();
        let base = grey(0.5);
        let s = [sample_at(&f, 20, 15, 1, [0.9; 3])];
        let img = run(&f, &h, &base, &[&s]);
        // Level 1 of 3: reach 5.
        let near = 0.5 + 0.4 * weight(4.0, 25.0);
        for y in 10..20 {
            for x in 14..18 {
                assert_eq!(
                    at(&img, x, y),
                    0.5,
                    "bled across the depth edge at ({x}, {y})"
                );
            }
            for x in 23..27 {
                assert_eq!(
                    at(&img, x, y),
                    0.5,
                    "bled across the normal edge at ({x}, {y})"
                );
            }
        }
        assert!((at(&img, 18, 15) - near).abs() < 1e-6);
        assert!((at(&img, 22, 15) - near).abs() < 1e-6);
        // Without the edges the same sample reaches those columns.
        let flat = frame(0, 0.0, W);
        let s = [sample_at(&flat, 20, 15, 1, [0.9; 3])];
        let img = run(&flat, &h, &base, &[&s]);
        let beyond = 0.5 + 0.4 * weight(9.0, 25.0);
        assert!((at(&img, 17, 15) - beyond).abs() < 1e-6);
        assert!((at(&img, 23, 15) - beyond).abs() < 1e-6);
    }

    #[test]
    fn a_footprint_stops_at_object_edges() {
        let mut f = frame(0, 0.0, W);
        for (i, id) in f.ids.iter_mut().enumerate() {
            if i as u32 % W < 18 {
                *id = 2;
            }
        }
        let h = Hierarchy::new(3).unwrap();
        let img = run(&f, &h, &grey(0.5), &[&[sample_at(&f, 20, 15, 1, [0.9; 3])]]);
        assert!((0..H).all(|y| (0..18).all(|x| at(&img, x, y) == 0.5)));
        assert!((at(&img, 18, 15) - 0.5 - 0.4 * weight(4.0, 25.0)).abs() < 1e-6);
    }

    #[test]
    fn corrections_add_to_the_base_and_an_exact_base_is_unchanged() {
        let f = frame(0, 0.0, W);
        let h = Hierarchy::new(3).unwrap();
        // A textured diffuse value: the base shows it, and samples of it change nothing.
        let diffuse: Vec<[f32; 3]> = (0..W * H)
            .map(|i| [0.1 + 0.003 * (i % 97) as f32, 0.2, 0.05 * (i % 7) as f32])
            .collect();
        let samples: Vec<Sample> = (0..6)
            .map(|k| {
                let (x, y) = (5 + 6 * k, 8 + 3 * k);
                let level = 1 + (k % 3) as u8;
                sample_at(&f, x, y, level, diffuse[(y * W + x) as usize])
            })
            .collect();
        assert_eq!(run(&f, &h, &diffuse, &[&samples]), diffuse);
        // A sample 0.25 brighter than the diffuse value at its pixel adds (up to) 0.25 to the
        // texture around it, keeping it, rather than copying its pixel's colour.
        let (x, y) = (20, 15);
        let mut bright = sample_at(&f, x, y, 1, diffuse[(y * W + x) as usize]);
        bright.color = bright.color.map(|c| c + 0.25);
        let img = run(&f, &h, &diffuse, &[&[bright]]);
        for (px, py) in [(21, 15), (19, 14), (22, 17)] {
            let i = (py * W + px) as usize;
            let d2 = ((px as i32 - x as i32).pow(2) + (py as i32 - y as i32).pow(2)) as f32;
            for c in 0..3 {
                let added = img[i][c] - diffuse[i][c];
                assert!(
                    (added - 0.25 * weight(d2, 25.0)).abs() < 1e-5,
                    "({px}, {py})"
                );
            }
        }
        // A lit frame shown over the diffuse value: the correction adds to what is shown.
        let lit: Vec<[f32; 3]> = diffuse.iter().map(|d| d.map(|c| 2.0 * c)).collect();
        let mut color = lit.clone();
        splat(
            &[&[bright]],
            &h,
            &f.view,
            0,
            &mut SplatTarget {
                color: &mut color,
                diffuse: &diffuse,
                keep: None,
                ids: &f.ids,
                gbuffer: &f.g,
            },
        );
        let i = (y * W + x + 1) as usize;
        assert!((color[i][0] - lit[i][0] - 0.25 * weight(1.0, 25.0)).abs() < 1e-5);
    }

    #[test]
    fn view_dependent_samples_keep_the_diffuse_share_of_the_base_they_reach() {
        let f = frame(0, 0.0, W);
        let h = Hierarchy::new(2).unwrap();
        // A textured lit base; 60 % of it stays under a correction (the material's diffuse
        // weight). Level 1 of 2: reach √5, weight 0.64 at 1 px.
        let base: Vec<[f32; 3]> = (0..W * H)
            .map(|i| [0.2 + 0.004 * (i % 53) as f32, 0.3, 0.1])
            .collect();
        let keep = vec![0.6; (W * H) as usize];
        let view_dependent = |samples: &[Sample]| {
            let mut color = base.clone();
            splat(
                &[samples],
                &h,
                &f.view,
                0,
                &mut SplatTarget {
                    color: &mut color,
                    diffuse: &[],
                    keep: Some(&keep),
                    ids: &f.ids,
                    gbuffer: &f.g,
                },
            );
            color
        };
        let px = |x: u32, y: u32| base[(y * W + x) as usize];
        let s = [
            sample_at(&f, 10, 10, 1, [0.25; 3]),
            sample_at(&f, 12, 10, 1, [0.05; 3]),
        ];
        let img = view_dependent(&s);
        let close = |a: [f32; 3], b: [f32; 3]| a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-6);
        // Own pixels: the kept share of the base under them plus their radiance.
        let own: [f32; 3] = std::array::from_fn(|c| 0.6 * px(10, 10)[c] + 0.25);
        assert!(close(img[(10 * W + 10) as usize], own));
        // Between them (total weight 1.28): the kept base plus their mean radiance.
        let mid: [f32; 3] = std::array::from_fn(|c| 0.6 * px(11, 10)[c] + 0.15);
        assert!(close(img[(10 * W + 11) as usize], mid));
        // The rim of one (weight 0.64): mixed with the base by that confidence.
        let rim: [f32; 3] =
            std::array::from_fn(|c| px(9, 10)[c] + 0.64 * (0.25 - 0.4 * px(9, 10)[c]));
        assert!(close(img[(10 * W + 9) as usize], rim));
        // A pixel no sample reaches keeps the whole base, and no sample changes nothing.
        assert_eq!(img[(20 * W + 30) as usize], px(30, 20));
        assert_eq!(view_dependent(&[]), base);
    }
}
