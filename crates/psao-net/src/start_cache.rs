//! Start points kept on disk between runs: a server restarted with the same scene and
//! settings reads its generated, burial-tested points back instead of making them again.
//! One file per [`StartPoints::key`]; a stale, foreign or damaged file is reported and
//! replaced, never trusted.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use psao_server::{Server, ServerConfig, StartPoints};
use psao_trace::ao::Medium;

use crate::NetError;

/// The default folder for stored start points: `$PSAO_CACHE_DIR/points`, else
/// `$XDG_CACHE_HOME/psao/points`, else `$HOME/.cache/psao/points` (`None` when none is set).
pub fn default_dir() -> Option<PathBuf> {
    let var = |k: &str| {
        std::env::var_os(k)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
    };
    var("PSAO_CACHE_DIR")
        .or_else(|| var("XDG_CACHE_HOME").map(|d| d.join("psao")))
        .or_else(|| var("HOME").map(|d| d.join(".cache").join("psao")))
        .map(|d| d.join("points"))
}

/// The file in `dir` holding the start points of `key`.
pub fn file_for(dir: &Path, key: u64) -> PathBuf {
    dir.join(format!("{key:016x}.points"))
}

/// A server for `scene` with `config`; with a `cache` folder, from the start points stored
/// there for this scene and settings when they are present and sound, and otherwise from
/// points generated now and then stored there (a failure to store is logged, not fatal).
pub fn start_server(
    scene: &psao_scene::Scene,
    config: ServerConfig,
    medium: Option<Arc<dyn Medium>>,
    cache: Option<&Path>,
) -> Result<Server, NetError> {
    let Some(dir) = cache else {
        return Ok(Server::with_medium(scene, config, medium)?);
    };
    let key = StartPoints::key(scene, &config);
    let file = file_for(dir, key);
    match std::fs::read(&file) {
        Ok(bytes) => match StartPoints::from_bytes(&bytes, key) {
            Ok(start) => {
                tracing::info!("start points read from {}", file.display());
                return Ok(Server::with_start_points(scene, config, medium, start)?);
            }
            Err(e) => tracing::warn!("{}: {e}; generating the points again", file.display()),
        },
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => tracing::warn!("cannot read {}: {e}", file.display()),
    }
    let start = StartPoints::generate(scene, &config)?;
    if let Err(e) = store(dir, &file, &start.to_bytes()) {
        tracing::warn!("cannot store the start points in {}: {e}", file.display());
    }
    Ok(Server::with_start_points(scene, config, medium, start)?)
}

/// Write `bytes` to `file` atomically (a temporary file in `dir`, then a rename), so that
/// concurrent runs never read a half-written file.
fn store(dir: &Path, file: &Path, bytes: &[u8]) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    let tmp = dir.join(format!(
        ".{}.{}.tmp",
        file.file_name()
            .and_then(|n| n.to_str())
            .unwrap_or("points"),
        std::process::id()
    ));
    std::fs::write(&tmp, bytes)?;
    std::fs::rename(&tmp, file)
}
