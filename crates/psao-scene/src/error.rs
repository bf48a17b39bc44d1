//! The one error type of scene import: every variant names the file it is about.

use std::path::{Path, PathBuf};

/// Largest element count accepted for any vertex/index/key array (2^28).
pub const MAX_ELEMENTS: usize = 1 << 28;

/// Why a scene, asset or camera path could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file could not be read.
    #[error("{}: cannot read file: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O failure.
        #[source]
        source: std::io::Error,
    },
    /// The file is not valid for its format (glTF, OBJ, TOML, …) or its content is inconsistent.
    #[error("{}: invalid {format}: {message}", path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// Which format was expected ("glTF", "OBJ", "TOML", "camera path", "scene file").
        format: &'static str,
        /// What is wrong.
        message: String,
    },
    /// An index in the file points outside the array it refers to.
    #[error("{}: {what} index {index} out of range (only {count})", path.display())]
    IndexOutOfRange {
        /// The file.
        path: PathBuf,
        /// What kind of index (e.g. "vertex", "joint").
        what: String,
        /// The offending index.
        index: usize,
        /// Number of valid entries.
        count: usize,
    },
    /// Binary data the file refers to is missing or shorter than declared.
    #[error("{}: missing buffer data: {message}", path.display())]
    MissingBuffer {
        /// The file.
        path: PathBuf,
        /// Which buffer and how much is missing.
        message: String,
    },
    /// A NaN or infinite number where a finite one is required.
    #[error("{}: non-finite value in {what}", path.display())]
    NonFinite {
        /// The file.
        path: PathBuf,
        /// Where the value was found.
        what: String,
    },
    /// A count or size far beyond anything plausible.
    #[error("{}: {what} too large: {size} (limit {limit})", path.display())]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// What is too large.
        what: String,
        /// The size found.
        size: u64,
        /// The limit.
        limit: u64,
    },
    /// A valid but unsupported feature, or an unknown file kind.
    #[error("{}: unsupported: {message}", path.display())]
    Unsupported {
        /// The file.
        path: PathBuf,
        /// What is unsupported.
        message: String,
    },
    /// An image the scene needs (an alpha mask) is missing, corrupt or in an unsupported format.
    #[error("{}: {image}: {message}", path.display())]
    Image {
        /// The scene file that refers to the image.
        path: PathBuf,
        /// Which image and what uses it.
        image: String,
        /// What is wrong.
        message: String,
    },
    /// An asset listed in a scene file failed to load.
    #[error("{}: asset failed to load: {source}", scene.display())]
    Asset {
        /// The scene file.
        scene: PathBuf,
        /// The asset's own error (names the asset file).
        #[source]
        source: Box<SceneError>,
    },
}

impl SceneError {
    /// The file the error is about (for an asset failure: the scene file listing it).
    pub fn path(&self) -> &Path {
        match self {
            Self::Io { path, .. }
            | Self::Parse { path, .. }
            | Self::IndexOutOfRange { path, .. }
            | Self::MissingBuffer { path, .. }
            | Self::NonFinite { path, .. }
            | Self::TooLarge { path, .. }
            | Self::Unsupported { path, .. }
            | Self::Image { path, .. } => path,
            Self::Asset { scene, .. } => scene,
        }
    }

    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        Self::Io {
            path: path.to_path_buf(),
            source,
        }
    }

    pub(crate) fn parse(path: &Path, format: &'static str, message: impl Into<String>) -> Self {
        Self::Parse {
            path: path.to_path_buf(),
            format,
            message: message.into(),
        }
    }

    pub(crate) fn index(path: &Path, what: impl Into<String>, index: usize, count: usize) -> Self {
        Self::IndexOutOfRange {
            path: path.to_path_buf(),
            what: what.into(),
            index,
            count,
        }
    }

    pub(crate) fn non_finite(path: &Path, what: impl Into<String>) -> Self {
        Self::NonFinite {
            path: path.to_path_buf(),
            what: what.into(),
        }
    }

    pub(crate) fn too_large(path: &Path, what: impl Into<String>, size: u64, limit: u64) -> Self {
        Self::TooLarge {
            path: path.to_path_buf(),
            what: what.into(),
            size,
            limit,
        }
    }

    pub(crate) fn image(path: &Path, image: &str, message: impl Into<String>) -> Self {
        Self::Image {
            path: path.to_path_buf(),
            image: image.to_owned(),
            message: message.into(),
        }
    }

    pub(crate) fn unsupported(path: &Path, message: impl Into<String>) -> Self {
        Self::Unsupported {
            path: path.to_path_buf(),
            message: message.into(),
        }
    }
}

/// Reads a whole file, mapping failures to [`SceneError::Io`].
pub(crate) fn read_file(path: &Path) -> Result<Vec<u8>, SceneError> {
    std::fs::read(path).map_err(|e| SceneError::io(path, e))
}

/// A TOML error as "line N: message".
pub(crate) fn toml_message(text: &str, e: &toml::de::Error) -> String {
    match e.span() {
        Some(span) => {
            let line = text.as_bytes()[..span.start.min(text.len())]
                .iter()
                .filter(|&&b| b == b'\n')
                .count()
                + 1;
            format!("line {line}: {}", e.message())
        }
        None => e.message().to_owned(),
    }
}
