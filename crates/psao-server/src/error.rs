//! Typed errors of the server.

/// Everything that can go wrong when building a [`crate::Server`].
#[derive(Debug, thiserror::Error)]
pub enum ServerError {
    /// A configuration value is out of range.
    #[error("invalid server configuration: {0}")]
    InvalidConfig(String),
    /// The scene has more instances than update records can address.
    #[error("scene has {0} instances; at most 2^32 are supported")]
    TooManyInstances(usize),
    /// Point generation or grid building failed.
    #[error(transparent)]
    Points(#[from] psao_points::PointsError),
    /// The scene's animation data cannot be played.
    #[error(transparent)]
    Animation(#[from] psao_scene::AnimationError),
    /// The ray tracer could not be built or updated.
    #[error(transparent)]
    Trace(#[from] psao_trace::TraceError),
    /// Stored start points cannot be used.
    #[error("stored start points: {0}")]
    StartPoints(String),
    /// Published point records from another node cannot be applied.
    #[error("point records: {0}")]
    Records(String),
}
