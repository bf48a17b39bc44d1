//! Per-pixel AO reconstruction from the mirrored point grids (DESIGN §3 "Client
//! reconstruction", paper §3.5), and with lighting the irradiance with the same kernel
//! (DESIGN §12).

use glam::{Affine3A, Mat3A, Vec3, Vec3A};
use psao_points::{
    MirrorGrid, ReconstructParams, DEFAULT_INTERPOLATION_FACTOR, DEFAULT_NORMAL_EXPONENT,
    DEFAULT_PLANE_TOLERANCE,
};
use psao_raster::GBuffer;
use rayon::prelude::*;

use crate::fill::fill_holes;
use crate::gather::{Found, Lights, Neighbourhood};
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
    grid: &'a MirrorGrid,
    /// The instance's irradiance records, when they are wanted and the state has some.
    lights: Lights<'a>,
    /// World → instance-local.
    to_local: Affine3A,
    /// World normal → (unnormalised) local normal: the transpose of the forward linear part,
    /// i.e. the inverse of the normal matrix.
    normal_to_local: Mat3A,
}

impl<'a> InstanceView<'a> {
    fn new(state: &'a ClientState, instance: usize, with_lights: bool) -> Option<Self> {
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
            lights: with_lights.then(|| state.light_cells(instance)).flatten(),
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
    run(state, gbuffer, settings, out, None);
}

/// [`reconstruct_into`] that also interpolates the points' irradiance (linear RGB, DESIGN
/// §12) per pixel into `irradiance` with the same kernel (see the `gather` module: the same
/// points and weights, the same nearest-point fallbacks). A covered pixel where no point is
/// compatible (or whose instance has no grid or transform) takes the normal-weighted mean
/// irradiance of the nearest pixels around it that found points (the `fill` module), zero
/// when there are none; pixels that are not covered get zero, and every pixel does when the
/// state has no irradiance records. The AO is exactly [`reconstruct_into`]'s.
pub fn reconstruct_lit_into(
    state: &ClientState,
    gbuffer: &GBuffer,
    settings: &ReconstructSettings,
    ao: &mut Vec<f32>,
    irradiance: &mut Vec<Vec3>,
) {
    run(state, gbuffer, settings, ao, Some(irradiance));
}

/// AO per pixel into `ao`, and irradiance into `irradiance` when given.
fn run(
    state: &ClientState,
    gbuffer: &GBuffer,
    settings: &ReconstructSettings,
    ao: &mut Vec<f32>,
    irradiance: Option<&mut Vec<Vec3>>,
) {
    let width = gbuffer.width as usize;
    let pixels = width * gbuffer.height as usize;
    ao.clear();
    ao.resize(pixels, 1.0);
    let with_lights = irradiance.is_some() && state.has_lights();
    // With records: where each pixel found its value, for the hole filling below.
    let mut found = vec![Found::Nothing; if with_lights { pixels } else { 0 }];
    let mut irradiance = irradiance;
    let irradiance_rows: Vec<Option<(&mut [Vec3], &mut [Found])>> = match irradiance.as_mut() {
        Some(e) => {
            e.clear();
            e.resize(pixels, Vec3::ZERO);
            let found_rows = found.chunks_mut(width.max(1)).map(Some);
            let found_rows = found_rows.chain(std::iter::repeat_with(|| None));
            e.chunks_mut(width.max(1))
                .zip(found_rows)
                .map(|(e, f)| Some((e, f.unwrap_or_default())))
                .collect()
        }
        None => (0..gbuffer.height).map(|_| None).collect(),
    };
    if pixels == 0 {
        return;
    }
    let views: Vec<Option<InstanceView<'_>>> = (0..state.instance_count())
        .map(|i| InstanceView::new(state, i, with_lights))
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
    ao.par_chunks_mut(width)
        .zip(irradiance_rows)
        .zip(gbuffer.instance.par_chunks(width))
        .zip(gbuffer.position.par_chunks(width))
        .zip(gbuffer.normal.par_chunks(width))
        .for_each_init(
            Neighbourhood::new,
            |cache, ((((row, mut e_row), instances), positions), normals)| {
                let pixels = row.iter_mut().zip(instances).zip(positions).zip(normals);
                for (x, (((ao, &instance), &position), &normal)) in pixels.enumerate() {
                    let Some(Some(view)) = views.get(instance as usize) else {
                        continue;
                    };
                    let p = view.to_local.transform_point3a(Vec3A::from(position));
                    let n = (view.normal_to_local * Vec3A::from(normal)).normalize_or_zero();
                    let grid = (view.grid, view.lights);
                    let (a, e, how) = cache.sample(instance, grid, p.into(), n.into(), &params);
                    *ao = a;
                    if let Some((e_row, found_row)) = e_row.as_mut() {
                        if let Some(slot) = e_row.get_mut(x) {
                            *slot = e;
                        }
                        if let Some(slot) = found_row.get_mut(x) {
                            *slot = how;
                        }
                    }
                }
            },
        );
    if let (true, Some(e)) = (with_lights, irradiance) {
        fill_holes(gbuffer, &found, e);
    }
}
