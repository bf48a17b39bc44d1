//! Errors of the relighting crate.

use psao_scene::AnimationError;
use psao_trace::TraceError;

/// Why relighting data could not be built, loaded or used.
#[derive(Debug, thiserror::Error)]
pub enum PrtError {
    /// The scene has no skinned mesh to relight.
    #[error("no skinned mesh: the file has no instance with a skin and skinning weights")]
    NoSkin,
    /// The requested clip does not exist.
    #[error("no animation clip `{requested}` (the file has: {available})")]
    UnknownClip {
        /// What was asked for.
        requested: String,
        /// The clips there are, listed for the message.
        available: String,
    },
    /// The scene's animation data cannot be played.
    #[error("animation: {0}")]
    Animation(#[from] AnimationError),
    /// The ray tracer rejected the geometry.
    #[error("ray tracing: {0}")]
    Trace(#[from] TraceError),
    /// A model file is not usable.
    #[error("model file: {0}")]
    Model(String),
    /// The model belongs to another character.
    #[error("the model was trained on `{model}` ({model_vertices} vertices, {model_joints} joints), not on `{character}` ({vertices} vertices, {joints} joints)")]
    WrongCharacter {
        /// Character named in the model.
        model: String,
        /// Its vertex count.
        model_vertices: usize,
        /// Its joint count.
        model_joints: usize,
        /// The character given.
        character: String,
        /// Its vertex count.
        vertices: usize,
        /// Its joint count.
        joints: usize,
    },
    /// A parameter is out of range.
    #[error("{0}")]
    Parameter(String),
    /// The least-squares solve failed.
    #[error("least squares: {0}")]
    Solve(String),
}
