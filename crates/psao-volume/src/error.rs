//! Typed errors of the volume library.

use std::path::PathBuf;

/// Everything that can go wrong while reading, building, encoding or storing a volume.
#[derive(Debug, thiserror::Error)]
pub enum VolumeError {
    /// An I/O error on a named file.
    #[error("cannot read {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The bytes are not an OpenVDB file or are damaged.
    #[error("{0}: not a valid OpenVDB file: {1}")]
    InvalidVdb(String, String),
    /// The file holds no grid this library can use.
    #[error("{0}: unsupported grid: {1}")]
    UnsupportedGrid(String, String),
    /// The grid's index-to-world transform is not a scale + translation.
    #[error("{0}: unsupported transform `{1}` (only scale and translation maps are supported)")]
    UnsupportedTransform(String, String),
    /// The frames of an animation disagree (class or transform).
    #[error("animation frames disagree: {0}")]
    FrameMismatch(String),
    /// The volume does not fit the fixed 4096³ span of one flat-tree top node.
    #[error("volume too large for one top node: extent {0:?} voxels (at most 4096 per axis)")]
    TooLarge([i32; 3]),
    /// A file holds more nodes, leaves or voxels than the reader accepts (checked before any
    /// of them is expanded; `count` may be a lower bound, counted up to the first excess).
    #[error("{label}: too many {what}: {count} (the limit is {limit})")]
    LimitExceeded {
        /// The file.
        label: String,
        /// What was counted.
        what: &'static str,
        /// How many the file holds.
        count: u64,
        /// The most accepted.
        limit: u64,
    },
    /// The volume has no active voxels.
    #[error("the volume has no voxel data")]
    Empty,
    /// A `.psv` file is damaged, truncated or of another version.
    #[error("not a valid .psv file: {0}")]
    InvalidPsv(String),
    /// An argument is out of range.
    #[error("invalid parameter: {0}")]
    InvalidParameter(String),
}

/// Result alias of this crate.
pub type Result<T> = std::result::Result<T, VolumeError>;
