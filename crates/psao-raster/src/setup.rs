//! Triangle setup: clip, project to fixed-point screen coordinates, and build edge functions
//! with the top-left fill rule.

use glam::{Vec3, Vec4};

use crate::clip::{ClipVolume, MAX_VERTS};
use crate::view::View;

/// Sub-pixel precision in bits (vertices snap to 1/4096 pixel, so coverage differs from exact
/// ray casting only for pixel centres within that distance of an edge).
const SUBPIXEL_BITS: u32 = 12;
/// One pixel in fixed point.
const ONE: i64 = 1 << SUBPIXEL_BITS;
/// Half a pixel in fixed point (pixel centres sit at half-integers).
const HALF: i64 = ONE / 2;
/// Largest supported image side; larger requests are clamped.
pub const MAX_DIMENSION: u32 = 1 << 14;
/// Guard band around the image in pixels. Snapped coordinates are clamped to
/// ±(2·guard + MAX_DIMENSION) < 2^16.4 pixels, i.e. < 2^28.4 in fixed point, so their
/// differences fit in i32 and edge-function products (< 2^59) in i64; pixel indices
/// (< MAX_DIMENSION) fit in u16.
const GUARD_PIXELS: f32 = (1 << 15) as f32;

/// A screen-space triangle ready for scan conversion (kept small: binning reads many).
#[derive(Clone, Copy, Debug)]
pub(crate) struct SetupTri {
    /// Biased edge functions at the centre of pixel (`min_x`, `min_y`); a pixel is covered when
    /// all three are ≥ 0.
    pub edge: [i64; 3],
    /// 1/depth = a·x + b·y + c at the centre of pixel (x, y).
    pub inv_depth: [f64; 3],
    /// Edge-function increments per pixel step in x, in units of one pixel (see
    /// [`SetupTri::steps`]).
    step_x: [i32; 3],
    /// Edge-function increments per pixel step in y, in units of one pixel.
    step_y: [i32; 3],
    /// Pixel bounding box (inclusive), clamped to the image.
    pub min_x: u16,
    /// See `min_x`.
    pub min_y: u16,
    /// See `min_x`.
    pub max_x: u16,
    /// See `min_x`.
    pub max_y: u16,
    /// Global triangle id.
    pub id: u32,
    /// Whether its fragments pass an alpha test (see [`crate::mask`]).
    pub masked: bool,
}

impl SetupTri {
    /// Edge-function increments per pixel step in x and in y.
    pub fn steps(&self) -> ([i64; 3], [i64; 3]) {
        (
            self.step_x.map(|s| i64::from(s) * ONE),
            self.step_y.map(|s| i64::from(s) * ONE),
        )
    }
}

/// Converts world-space triangles into [`SetupTri`]s for one view.
pub(crate) struct TriangleSetup<'a> {
    view: &'a View,
    volume: ClipVolume,
    cull_backfaces: bool,
}

impl<'a> TriangleSetup<'a> {
    /// Setup for `view`, culling back faces (counter-clockwise = front) when asked.
    pub fn new(view: &'a View, cull_backfaces: bool) -> Self {
        let volume = ClipVolume {
            near: view.near,
            gx: 1.0 + 2.0 * GUARD_PIXELS / view.width as f32,
            gy: 1.0 + 2.0 * GUARD_PIXELS / view.height as f32,
        };
        Self {
            view,
            volume,
            cull_backfaces,
        }
    }

    /// Appends the screen triangles of world triangle `world` (clip coordinates `clip`) to `out`.
    /// Back faces are culled when the setup culls and the triangle is `single_sided`; `masked`
    /// marks triangles whose fragments pass an alpha test.
    pub fn push(
        &self,
        id: u32,
        world: [Vec3; 3],
        clip: [Vec4; 3],
        (single_sided, masked): (bool, bool),
        out: &mut Vec<SetupTri>,
    ) {
        if !clip.iter().all(|v| v.is_finite()) {
            return;
        }
        let Some(poly) = self.volume.clip(clip) else {
            return;
        };
        let Some(inv_depth) = self.view.inverse_depth_plane(world) else {
            return;
        };
        let verts = poly.verts();
        let mut fixed = [[0i64; 2]; MAX_VERTS];
        for (f, &v) in fixed.iter_mut().zip(verts) {
            let Some(p) = self.to_fixed(v) else {
                return;
            };
            *f = p;
        }
        for i in 1..verts.len() - 1 {
            let tri = [fixed[0], fixed[i], fixed[i + 1]];
            if let Some(t) = self.edges(tri, inv_depth, id, single_sided && self.cull_backfaces) {
                out.push(SetupTri { masked, ..t });
            }
        }
    }

    /// Perspective divide and viewport transform to fixed-point pixels (y down).
    /// `None` when the result is not finite.
    fn to_fixed(&self, v: Vec4) -> Option<[i64; 2]> {
        let limit = 2.0 * GUARD_PIXELS + MAX_DIMENSION as f32;
        let x = (v.x / v.w * 0.5 + 0.5) * self.view.width as f32;
        let y = (0.5 - v.y / v.w * 0.5) * self.view.height as f32;
        if !(x.is_finite() && y.is_finite()) {
            return None;
        }
        // Round half away from zero (in f64, exact at these magnitudes) without a libm call.
        let snap = |p: f32| {
            let v = f64::from(p.clamp(-limit, limit)) * ONE as f64;
            (v + 0.5f64.copysign(v)) as i64
        };
        Some([snap(x), snap(y)])
    }

    /// Edge functions and bounds of one screen triangle, `None` when it covers no pixel centre.
    fn edges(
        &self,
        mut t: [[i64; 2]; 3],
        inv_depth: [f64; 3],
        id: u32,
        cull: bool,
    ) -> Option<SetupTri> {
        let area =
            (t[1][0] - t[0][0]) * (t[2][1] - t[0][1]) - (t[1][1] - t[0][1]) * (t[2][0] - t[0][0]);
        // With y pointing down, a front-facing (counter-clockwise) triangle has negative area.
        if area == 0 || (cull && area > 0) {
            return None;
        }
        if area < 0 {
            t.swap(1, 2);
        }
        let lo = |k: usize| t.iter().map(|p| p[k]).min().unwrap_or(0);
        let hi = |k: usize| t.iter().map(|p| p[k]).max().unwrap_or(0);
        // Pixel x is sampled at x·ONE + HALF.
        let first = |v: i64| -(-(v - HALF)).div_euclid(ONE);
        let last = |v: i64| (v - HALF).div_euclid(ONE);
        let min_x = first(lo(0)).max(0);
        let min_y = first(lo(1)).max(0);
        let max_x = last(hi(0)).min(self.view.width as i64 - 1);
        let max_y = last(hi(1)).min(self.view.height as i64 - 1);
        if min_x > max_x || min_y > max_y {
            return None;
        }
        let (px, py) = (min_x * ONE + HALF, min_y * ONE + HALF);
        let mut edge = [0i64; 3];
        let mut step_x = [0i32; 3];
        let mut step_y = [0i32; 3];
        for i in 0..3 {
            let (a, b) = (t[i], t[(i + 1) % 3]);
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            // Inside is where the edge function is positive; pixels exactly on an edge belong to
            // the triangle only for top edges (horizontal, interior below) and left edges.
            let top_left = dy < 0 || (dy == 0 && dx > 0);
            edge[i] = dx * (py - a[1]) - dy * (px - a[0]) - i64::from(!top_left);
            // See GUARD_PIXELS for why these fit.
            step_x[i] = -dy as i32;
            step_y[i] = dx as i32;
        }
        Some(SetupTri {
            edge,
            inv_depth,
            step_x,
            step_y,
            min_x: min_x as u16,
            min_y: min_y as u16,
            max_x: max_x as u16,
            max_y: max_y as u16,
            id,
            masked: false,
        })
    }
}
