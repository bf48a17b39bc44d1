//! Per-pixel AO reconstruction from the mirrored point grids (DESIGN §3 "Client
//! reconstruction", paper §3.5).

use glam::{Affine3A, Mat3A, Vec3A};
use psao_points::{
    InstanceGrid, ReconstructParams, DEFAULT_INTERPOLATION_FACTOR, DEFAULT_NORMAL_EXPONENT,
    DEFAULT_PLANE_TOLERANCE,
};
use psao_raster::GBuffer;
use rayon::prelude::*;

use crate::gather::Neighbourhood;
use crate::state::ClientState;

/// Smallest |det| of an instance transform's linear part that is still inverted; flatter
/// instances (e.g. scaled to zero to hide them) reconstruct as unoccluded.
const MIN_DETERMINANT: f32 = 1e-12;

/// Client-side reconstruction settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReconstructSettings {
    /// Reconstruction radius in units of the instance's Poisson radius.
    pub interpolation_factor: f32,
    /// Tangent-plane tolerance in Poisson radii ([`ReconstructParams::plane_tolerance`]).
    pub plane_tolerance: f32,
    /// Exponent of the normal-agreement weight ([`ReconstructParams::normal_exponent`]).
    pub normal_exponent: i32,
    /// Nearest-point fallback for holes ([`ReconstructParams::nearest_fallback`]).
    pub nearest_fallback: bool,
    /// Planar fit instead of the weighted mean ([`ReconstructParams::linear_ridge`]).
    pub linear_ridge: Option<f32>,
    /// Footprint following the local point spacing ([`ReconstructParams::adaptive_radius`]).
    pub adaptive_radius: Option<f32>,
}

impl Default for ReconstructSettings {
    fn default() -> Self {
        Self {
            interpolation_factor: DEFAULT_INTERPOLATION_FACTOR,
            plane_tolerance: DEFAULT_PLANE_TOLERANCE,
            normal_exponent: DEFAULT_NORMAL_EXPONENT,
            nearest_fallback: true,
            linear_ridge: None,
            adaptive_radius: None,
        }
    }
}

/// What one instance needs per pixel, computed once per frame.
struct InstanceView<'a> {
    grid: &'a InstanceGrid,
    /// World → instance-local.
    to_local: Affine3A,
    /// World normal → (unnormalised) local normal: the transpose of the forward linear part,
    /// i.e. the inverse of the normal matrix.
    normal_to_local: Mat3A,
}

impl<'a> InstanceView<'a> {
    fn new(state: &'a ClientState, instance: usize) -> Option<Self> {
        let grid = state.grid(instance)?;
        let transform = state.transform(instance)?;
        if transform.matrix3.determinant().abs() <= MIN_DETERMINANT {
            return None;
        }
        let to_local = transform.inverse();
        let finite = [
            to_local.matrix3.x_axis,
            to_local.matrix3.y_axis,
            to_local.matrix3.z_axis,
            to_local.translation,
        ]
        .iter()
        .all(|c| c.is_finite());
        finite.then(|| Self {
            grid,
            to_local,
            normal_to_local: transform.matrix3.transpose(),
        })
    }
}

/// AO per pixel of `gbuffer` (row-major, `width × height`): each covered pixel's world
/// position and camera-facing normal are taken into its instance's local space with the
/// instance transform of the last applied update, and the instance's points are interpolated
/// there exactly as [`psao_points::reconstruct_ao`] does (bit-identical; neighbouring pixels
/// share the decoded cell block). Pixels that are not covered, or whose instance has no grid or no
/// (invertible) transform yet, get 1. Rows run in parallel; the result does not depend on the
/// thread count.
pub fn reconstruct(
    state: &ClientState,
    gbuffer: &GBuffer,
    settings: &ReconstructSettings,
) -> Vec<f32> {
    let mut out = Vec::new();
    reconstruct_into(state, gbuffer, settings, &mut out);
    out
}

/// [`reconstruct`] into a reused buffer (resized to the pixel count).
pub fn reconstruct_into(
    state: &ClientState,
    gbuffer: &GBuffer,
    settings: &ReconstructSettings,
    out: &mut Vec<f32>,
) {
    let width = gbuffer.width as usize;
    let pixels = width * gbuffer.height as usize;
    out.clear();
    out.resize(pixels, 1.0);
    if pixels == 0 {
        return;
    }
    let views: Vec<Option<InstanceView<'_>>> = (0..state.instance_count())
        .map(|i| InstanceView::new(state, i))
        .collect();
    let params = ReconstructParams {
        interpolation_factor: settings.interpolation_factor,
        plane_tolerance: settings.plane_tolerance,
        normal_exponent: settings.normal_exponent,
        nearest_fallback: settings.nearest_fallback,
        linear_ridge: settings.linear_ridge,
        adaptive_radius: settings.adaptive_radius,
        ..ReconstructParams::default()
    };
    // Zipping row slices tolerates inconsistent attribute lengths: missing pixels stay 1.
    // The neighbourhood cache only saves work; results do not depend on how rows are split.
    out.par_chunks_mut(width)
        .zip(gbuffer.instance.par_chunks(width))
        .zip(gbuffer.position.par_chunks(width))
        .zip(gbuffer.normal.par_chunks(width))
        .for_each_init(
            Neighbourhood::new,
            |cache, (((row, instances), positions), normals)| {
                let pixels = row.iter_mut().zip(instances).zip(positions).zip(normals);
                for (((ao, &instance), &position), &normal) in pixels {
                    let Some(Some(view)) = views.get(instance as usize) else {
                        continue;
                    };
                    let p = view.to_local.transform_point3a(Vec3A::from(position));
                    let n = (view.normal_to_local * Vec3A::from(normal)).normalize_or_zero();
                    *ao = cache.ao(instance, view.grid, p.into(), n.into(), &params);
                }
            },
        );
}
