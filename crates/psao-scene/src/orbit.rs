//! The default camera path of a scene that names none: a slow orbit that frames its bounds.

use glam::Vec3;

use crate::path::{CameraKey, CameraPath, DEFAULT_FOV_Y_DEG};

/// Seconds per revolution of the default orbit (18° per second).
pub const ORBIT_PERIOD_S: f32 = 20.0;

/// Keys per revolution: with 16 the spline stays within 0.1 % of the circle.
const ORBIT_KEYS: usize = 16;

/// Camera elevation above the horizontal plane through the target, in degrees.
const ORBIT_ELEVATION_DEG: f32 = 25.0;

/// Where the orbit looks, as a fraction of the bounds' height from the bottom: the middle
/// of the lower half, where objects meet the ground and contact shadows are.
const TARGET_HEIGHT_FRACTION: f32 = 0.25;

/// Distance factor over the tightest fit, covering the spline's deviation from the circle.
const FIT_MARGIN: f32 = 1.1;

/// A one-revolution orbit around the box `lo`..`hi` named `orbit`: the camera circles the
/// box at a fixed elevation, looking at the middle of its lower half, far enough that the
/// whole box stays inside the view of any image at least as wide as it is high.
/// `None` when the bounds are empty or not finite (a scene without geometry).
pub fn orbit_path(lo: Vec3, hi: Vec3) -> Option<CameraPath> {
    if !(lo.is_finite() && hi.is_finite() && lo.cmple(hi).all()) {
        return None;
    }
    let target = Vec3::new(
        0.5 * (lo.x + hi.x),
        lo.y + TARGET_HEIGHT_FRACTION * (hi.y - lo.y),
        0.5 * (lo.z + hi.z),
    );
    // Radius of the sphere about the target that holds every corner of the box.
    let radius = (0..8)
        .map(|i| {
            let corner = Vec3::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            );
            corner.distance(target)
        })
        .fold(0.0f32, f32::max)
        .max(1e-3);
    // A sphere of radius r seen from distance d fills a cone of half-angle asin(r / d); with
    // the vertical half-FOV as that angle it fits the view whenever width ≥ height.
    let half_fov = (0.5 * DEFAULT_FOV_Y_DEG).to_radians();
    let distance = FIT_MARGIN * radius / half_fov.sin();
    let elevation = ORBIT_ELEVATION_DEG.to_radians();
    let keys = (0..=ORBIT_KEYS)
        .map(|k| {
            let angle = std::f32::consts::TAU * k as f32 / ORBIT_KEYS as f32;
            let offset = Vec3::new(
                elevation.cos() * angle.cos(),
                elevation.sin(),
                elevation.cos() * angle.sin(),
            );
            CameraKey {
                time: ORBIT_PERIOD_S * k as f32 / ORBIT_KEYS as f32,
                position: target + distance * offset,
                look_at: target,
                fov_y_deg: DEFAULT_FOV_Y_DEG,
            }
        })
        .collect();
    Some(CameraPath {
        name: "orbit".into(),
        keys,
    })
}
