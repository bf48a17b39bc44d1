//! Start points kept on disk between runs: a server restarted with the same scene and
//! settings reads its generated, burial-tested points back instead of making them again.
//! One file per [`StartPoints::key`] and build of the running program (another build may
//! generate points differently, so its files count as stale); a stale, foreign or damaged
//! file is reported and replaced, never trusted. [`read_stored`] and [`keep_stored`] keep
//! other derived data (the relit characters' models, `.prt`) the same way, keyed by the
//! caller.

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

/// The file in `dir` holding the start points of `key` made by the build `build`.
pub fn file_for(dir: &Path, key: u64, build: u64) -> PathBuf {
    stored_file(dir, key, build, POINTS)
}

/// Extension of the start-point files.
const POINTS: &str = "points";

/// The file in `dir` holding the data of `key` with extension `ext` made by `build`.
fn stored_file(dir: &Path, key: u64, build: u64, ext: &str) -> PathBuf {
    dir.join(format!("{key:016x}-{build:016x}.{ext}"))
}

/// The bytes this build stored in `dir` for `key` with extension `ext`, with their file,
/// when present and `size_ok` accepts their length (a refused or unreadable file is logged
/// and ignored; the caller validates the content).
pub fn read_stored(
    dir: &Path,
    key: u64,
    ext: &str,
    size_ok: impl Fn(u64) -> bool,
) -> Option<(PathBuf, Vec<u8>)> {
    let build = build_id();
    if build == 0 {
        return None;
    }
    let file = stored_file(dir, key, build, ext);
    let read = std::fs::metadata(&file).and_then(|m| {
        if size_ok(m.len()) {
            std::fs::read(&file).map(Some)
        } else {
            Ok(None)
        }
    });
    match read {
        Ok(Some(bytes)) => Some((file, bytes)),
        Ok(None) => {
            tracing::warn!("{}: not of a usable size; ignored", file.display());
            None
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
        Err(e) => {
            tracing::warn!("cannot read {}: {e}", file.display());
            None
        }
    }
}

/// Stores `bytes` in `dir` for `key` with extension `ext` (atomically, removing what other
/// builds stored for that key); the file, or `None` when nothing was stored (logged).
pub fn keep_stored(dir: &Path, key: u64, ext: &str, bytes: &[u8]) -> Option<PathBuf> {
    let build = build_id();
    if build == 0 {
        return None;
    }
    let file = stored_file(dir, key, build, ext);
    match store(dir, &file, bytes) {
        Ok(()) => {
            forget_other_builds(dir, key, ext, &file);
            Some(file)
        }
        Err(e) => {
            tracing::warn!("cannot store {}: {e}", file.display());
            None
        }
    }
}

/// An identity of the running program's build: a hash of its executable's path, size and
/// modification time (0 when they cannot be read, so nothing stored is ever reused).
pub fn build_id() -> u64 {
    use std::hash::{Hash, Hasher};
    let exe = std::env::current_exe().ok();
    let meta = exe.as_ref().and_then(|e| std::fs::metadata(e).ok());
    let modified = meta.as_ref().and_then(|m| m.modified().ok());
    match (exe, meta, modified) {
        (Some(exe), Some(meta), Some(modified)) => {
            let mut h = std::hash::DefaultHasher::new();
            (exe, meta.len(), modified).hash(&mut h);
            h.finish() | 1
        }
        _ => 0,
    }
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
    let build = build_id();
    let file = file_for(dir, key, build);
    if build != 0 {
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
    }
    let start = StartPoints::generate(scene, &config)?;
    if build != 0 {
        match store(dir, &file, &start.to_bytes()) {
            Ok(()) => forget_other_builds(dir, key, POINTS, &file),
            Err(e) => tracing::warn!("cannot store the start points in {}: {e}", file.display()),
        }
    }
    Ok(Server::with_start_points(scene, config, medium, start)?)
}

/// Remove the files of `key` with extension `ext` that other builds stored in `dir` (they
/// are never read again).
fn forget_other_builds(dir: &Path, key: u64, ext: &str, kept: &Path) {
    let prefix = format!("{key:016x}-");
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        let ours = path
            .file_name()
            .and_then(|n| n.to_str())
            .is_some_and(|n| n.starts_with(&prefix) && n.ends_with(&format!(".{ext}")));
        if ours && path != kept {
            let _ = std::fs::remove_file(&path);
        }
    }
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
