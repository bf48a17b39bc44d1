//! Scene data model and import: glTF 2.0, OBJ, scene files, the built-in default scene and camera paths.

pub mod camera;
pub mod model;

pub use camera::Camera;
pub use model::*;
