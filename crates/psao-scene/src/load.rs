//! Entry points: load any supported scene or asset file by its extension.

use std::path::{Path, PathBuf};

use crate::error::SceneError;
use crate::model::Scene;

/// A loaded scene plus the camera paths its scene file lists.
#[derive(Clone, Debug)]
pub struct LoadedScene {
    /// The composed scene.
    pub scene: Scene,
    /// Camera path files, resolved against the scene file's folder (empty for plain assets).
    pub camera_paths: Vec<PathBuf>,
    /// Volumes placed by the scene file (at most one; files checked to exist, not read).
    pub volumes: Vec<crate::scene_file::SceneVolume>,
}

/// Loads `.gltf`, `.glb`, `.obj` or a `.toml` scene file (extension, case-insensitive).
pub fn load(path: &Path) -> Result<LoadedScene, SceneError> {
    if extension(path).as_deref() == Some("toml") {
        return crate::scene_file::load(path);
    }
    Ok(LoadedScene {
        scene: load_asset(path)?,
        camera_paths: Vec::new(),
        volumes: Vec::new(),
    })
}

/// [`load`] without the camera paths.
pub fn load_scene(path: &Path) -> Result<Scene, SceneError> {
    load(path).map(|l| l.scene)
}

/// Loads a single asset file (glTF, GLB or OBJ).
pub(crate) fn load_asset(path: &Path) -> Result<Scene, SceneError> {
    match extension(path).as_deref() {
        Some("gltf" | "glb") => crate::gltf::load(path),
        Some("obj") => crate::obj::load(path),
        other => Err(SceneError::unsupported(
            path,
            format!(
                "unknown file extension {:?} (expected .gltf, .glb, .obj or .toml)",
                other.unwrap_or("")
            ),
        )),
    }
}

fn extension(path: &Path) -> Option<String> {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
}
