//! Sparse volumes (DESIGN §6): OpenVDB ingest, a flat 5-4-3 tree over one shared pool of 8³
//! voxel bricks (f32, f16, unorm8, BC4 or BC7-packed), k-means brick clustering, HDDA
//! traversal, rendering (level-set hit, fog density, delta tracking) and a deterministic
//! transmittance query for occluding AO rays.

pub mod cluster;
pub mod codec;
pub mod error;
pub mod grid;
pub mod mask;
pub mod medium;
pub mod procedural;
pub mod psv;
pub mod render;
pub mod rng;
pub mod sample;
pub mod trace;
pub mod tree;
pub mod vdb;
pub mod volume;

pub use cluster::ClusterParams;
pub use codec::{BrickFormat, BrickPool};
pub use error::{Result, VolumeError};
pub use grid::{GridClass, Leaf, SparseGrid, Tile, Transform, BRICK, BRICK_VOXELS};
pub use medium::{PlacedVolume, Placement};
pub use procedural::Procedural;
pub use render::{Camera, Image, PixelRays, RenderMode, RenderSettings};
pub use sample::Sampler;
pub use trace::transmittance_with;
pub use volume::{BuildStats, ErrorStats, SizeStats, Volume};
