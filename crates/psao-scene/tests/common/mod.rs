//! Shared helpers for the integration tests.

use std::path::PathBuf;

/// The shared real-data folder, or `None` (with a note) when it is not present.
pub fn data_dir() -> Option<PathBuf> {
    let dir = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data"));
    if dir.is_dir() {
        Some(dir)
    } else {
        eprintln!("note: {} missing, test skipped", dir.display());
        None
    }
}
