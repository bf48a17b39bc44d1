//! Scene-file `environment`, `environment_intensity`, `environment_rotation_deg` and `sky`.

use std::path::Path;
use std::sync::Arc;

use glam::Vec3;

use crate::environment::{read_hdr, Environment, DEFAULT_SKY};
use crate::error::SceneError;

/// The top-level entries that set a scene's environment.
pub(super) struct SkyEntries<'a> {
    pub environment: Option<&'a str>,
    pub intensity: Option<f32>,
    pub rotation_deg: Option<f32>,
    pub sky: Option<[f32; 3]>,
}

/// The environment the entries describe (a map relative to `dir`), checked; `bad` wraps a
/// message into the scene file's error.
pub(super) fn environment(
    e: &SkyEntries,
    dir: &Path,
    bad: impl Fn(String) -> SceneError,
) -> Result<Environment, SceneError> {
    let Some(file) = e.environment else {
        if e.intensity.is_some() || e.rotation_deg.is_some() {
            return Err(bad(
                "environment_intensity and environment_rotation_deg need `environment`".into(),
            ));
        }
        let sky = e.sky.map_or(DEFAULT_SKY, Vec3::from_array);
        if !sky.is_finite() || sky.min_element() < 0.0 {
            return Err(bad(format!(
                "sky must be a non-negative radiance [r, g, b], got {sky}"
            )));
        }
        return Ok(Environment::Constant(sky));
    };
    if e.sky.is_some() {
        return Err(bad("`sky` and `environment` exclude each other".into()));
    }
    let intensity = e.intensity.unwrap_or(1.0);
    if !(intensity.is_finite() && intensity >= 0.0) {
        return Err(bad(format!(
            "environment_intensity must be a non-negative number, got {intensity}"
        )));
    }
    let rotation_deg = e.rotation_deg.unwrap_or(0.0);
    if !rotation_deg.is_finite() {
        return Err(bad(format!(
            "environment_rotation_deg must be finite, got {rotation_deg}"
        )));
    }
    let map = read_hdr(&dir.join(file))?;
    Ok(Environment::Map {
        map: Arc::new(map),
        intensity,
        rotation: rotation_deg.to_radians(),
    })
}
