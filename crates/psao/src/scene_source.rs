//! Resolving `--scene` and `--path` arguments into a loaded scene and a camera path.

use anyhow::{bail, Context, Result};
use clap::Args;
use psao_scene::path::CameraPath;
use psao_scene::Scene;
use psao_trace::ao::Medium;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The name that selects the built-in default scene.
pub const BUILTIN_SCENE: &str = "default";

/// Camera paths of the built-in scene, embedded so that it works from any directory.
const BUILTIN_PATHS: [(&str, &str); 2] = [
    ("default_a", include_str!("../../../paths/default_a.toml")),
    ("default_b", include_str!("../../../paths/default_b.toml")),
];

/// The `--scene` and `--path` arguments.
#[derive(Args, Debug, Clone)]
pub struct SceneArgs {
    /// Scene: `default` (built in) or a .gltf/.glb/.obj/.toml file.
    #[arg(long, default_value = BUILTIN_SCENE)]
    pub scene: String,
    /// Camera path file (default: the scene's first path, else a 20 s orbit that frames
    /// the scene's bounds, looking at their lower half).
    #[arg(long)]
    pub path: Option<PathBuf>,
    /// Play none of the scene's animations: the geometry stays in its rest pose.
    #[arg(long = "static")]
    pub frozen: bool,
}

impl SceneArgs {
    /// Loads the scene (frozen when `--static` is given) and picks the camera path.
    pub fn load(&self) -> Result<(SceneInput, CameraPath)> {
        let mut input = SceneInput::load(&self.scene)?;
        if self.frozen {
            input.scene.freeze();
        }
        let path = input.camera_path(self.path.as_ref())?;
        Ok((input, path))
    }
}

/// A scene with the camera paths it names and the volume it places.
pub struct SceneInput {
    /// Display name (file name or `default`).
    pub name: String,
    /// The scene.
    pub scene: Scene,
    /// Camera paths that come with the scene (first = default).
    pub paths: Vec<CameraPath>,
    /// The volume the scene file places, as a medium for AO rays.
    pub volume: Option<crate::scene_volume::SceneMedium>,
}

impl SceneInput {
    /// Loads `arg` (`default`, `builtin:default`, or a .gltf/.glb/.obj/.toml file).
    pub fn load(arg: &str) -> Result<Self> {
        if arg == BUILTIN_SCENE || arg == "builtin:default" {
            let paths = BUILTIN_PATHS
                .iter()
                .map(|(name, text)| {
                    CameraPath::parse(text)
                        .with_context(|| format!("built-in camera path {name} is invalid"))
                })
                .collect::<Result<_>>()?;
            return Ok(Self {
                name: BUILTIN_SCENE.into(),
                scene: psao_scene::builtin::default_scene(),
                paths,
                volume: None,
            });
        }
        let file = Path::new(arg);
        let loaded = psao_scene::load(file)
            .with_context(|| format!("cannot load scene {}", file.display()))?;
        let paths = loaded
            .camera_paths
            .iter()
            .map(|p| {
                CameraPath::load(p).with_context(|| format!("scene {arg} names a bad camera path"))
            })
            .collect::<Result<_>>()?;
        let volume = loaded
            .volumes
            .first()
            .map(crate::scene_volume::load)
            .transpose()?;
        Ok(Self {
            volume,
            name: file
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| arg.to_string()),
            scene: loaded.scene,
            paths,
        })
    }

    /// The medium AO rays pass through (the scene's volume), if any.
    pub fn medium(&self) -> Option<Arc<dyn Medium>> {
        self.volume
            .as_ref()
            .map(|v| v.volume.clone() as Arc<dyn Medium>)
    }

    /// The camera path named by `--path` (a file), else the scene's first path, else the
    /// default orbit around the scene's bounds ([`psao_scene::orbit_path`]).
    pub fn camera_path(&self, path_arg: Option<&PathBuf>) -> Result<CameraPath> {
        if let Some(p) = path_arg {
            return CameraPath::load(p)
                .with_context(|| format!("cannot load camera path {}", p.display()));
        }
        if let Some(p) = self.paths.first() {
            return Ok(p.clone());
        }
        let (lo, hi) = self.scene.bounds();
        let Some(orbit) = psao_scene::orbit_path(lo, hi) else {
            bail!(
                "scene '{}' names no camera path and has no geometry to orbit: give one with --path FILE",
                self.name
            );
        };
        tracing::info!(
            "scene '{}' names no camera path: orbiting its bounds {lo}..{hi} once in {} s \
             ({} frames), looking at their lower half (give one with --path FILE)",
            self.name,
            orbit.duration(),
            orbit.frame_count()
        );
        Ok(orbit)
    }
}
