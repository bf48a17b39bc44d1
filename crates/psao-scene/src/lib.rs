//! Scene data model and import: glTF 2.0, OBJ, scene files, the built-in default scene and camera paths.

pub mod affine;
pub mod alpha;
pub mod anim;
pub mod builtin;
pub mod camera;
pub mod environment;
mod error;
mod geometry;
pub mod gltf;
pub mod light;
mod load;
pub mod model;
pub mod obj;
pub mod orbit;
pub mod path;
pub mod path_gen;
pub mod scene_file;

pub use alpha::{AlphaImage, AlphaTexture, Wrap};
pub use anim::{AnimationError, Animator, Motion, PosedInstance, ScenePose, SkinnedGeometry};
pub use camera::Camera;
pub use environment::{Environment, LatLongMap};
pub use error::{SceneError, MAX_ELEMENTS};
pub use light::{Light, LightShape, SunKeys};
pub use load::{load, load_scene, LoadedScene};
pub use model::*;
pub use orbit::orbit_path;
pub use path::{CameraKey, CameraPath, PATH_HZ};
pub use path_gen::{generate_paths, CastHit, PathGenConfig, PathGenError, RayCaster};
