//! Scene-file `[[volume]]` entries: a sparse volume (OpenVDB or `.psv` files, loaded at the
//! edge by the caller) placed in the scene as a participating medium for AO rays.

use std::path::{Path, PathBuf};

use glam::{Quat, Vec3};
use serde::Deserialize;

use super::motion::euler_deg;
use super::Scale;

/// `[[volume]]`: `file` (one path or a list = flip-book frames), placement, density scale,
/// brick format, frame.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct VolumeEntry {
    file: Files,
    translation: Option<[f32; 3]>,
    #[serde(default)]
    rotation_deg: [f32; 3],
    scale: Option<Scale>,
    #[serde(default = "one")]
    density_scale: f32,
    format: Option<String>,
    #[serde(default)]
    frame: usize,
}

fn one() -> f32 {
    1.0
}

#[derive(Deserialize)]
#[serde(untagged)]
enum Files {
    One(String),
    Frames(Vec<String>),
}

/// A volume placed in a scene (from a scene file's `[[volume]]` entry). A point `v` of the
/// volume's own world space (its file transform) is placed at
/// `translation + rotation · (scale ⊙ v)`.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneVolume {
    /// The scene file that placed it (for messages).
    pub scene_file: PathBuf,
    /// Frame files in order (`.vdb` files, or one `.psv`), resolved against the scene file's
    /// folder and checked to exist.
    pub files: Vec<PathBuf>,
    /// Offset after rotation (metres).
    pub translation: Vec3,
    /// Rotation after scaling (`rotation_deg`: about X, then Y, then Z, fixed axes).
    pub rotation: Quat,
    /// Per-axis scale (positive).
    pub scale: Vec3,
    /// Extinction per metre at the volume's densest voxel (density normalised to 0..=1).
    pub density_scale: f32,
    /// In-memory brick format name for `.vdb` files (`None`: the loader's default).
    pub format: Option<String>,
    /// The flip-book frame that occludes AO (static: the scene clock does not pick frames).
    pub frame: usize,
}

/// Validates entry `i` of the scene file in folder `dir`; the message names the field.
pub(super) fn scene_volume(
    scene_file: &Path,
    dir: &Path,
    e: &VolumeEntry,
) -> Result<SceneVolume, String> {
    let names = match &e.file {
        Files::One(f) => vec![f.clone()],
        Files::Frames(f) => f.clone(),
    };
    if names.is_empty() {
        return Err("file: the list of frames is empty".into());
    }
    let mut files = Vec::with_capacity(names.len());
    for n in &names {
        let p = dir.join(n);
        if !p.is_file() {
            return Err(format!("file: '{}' not found", p.display()));
        }
        files.push(p);
    }
    let translation = Vec3::from_array(e.translation.unwrap_or_default());
    let rotation = euler_deg(e.rotation_deg);
    let scale = match e.scale {
        None => Vec3::ONE,
        Some(Scale::Uniform(s)) => Vec3::splat(s),
        Some(Scale::PerAxis(s)) => Vec3::from_array(s),
    };
    if !translation.is_finite() {
        return Err("translation: non-finite value".into());
    }
    if !rotation.is_finite() {
        return Err("rotation_deg: non-finite value".into());
    }
    if !(scale.is_finite() && scale.cmpgt(Vec3::ZERO).all()) {
        return Err(format!("scale: must be positive and finite, got {scale}"));
    }
    if !(e.density_scale.is_finite() && e.density_scale >= 0.0) {
        return Err(format!(
            "density_scale: must be finite and >= 0 (extinction per metre), got {}",
            e.density_scale
        ));
    }
    if e.frame >= files.len() {
        return Err(format!(
            "frame: {} but only {} file(s) given",
            e.frame,
            files.len()
        ));
    }
    Ok(SceneVolume {
        scene_file: scene_file.to_path_buf(),
        files,
        translation,
        rotation,
        scale,
        density_scale: e.density_scale,
        format: e.format.clone(),
        frame: e.frame,
    })
}
