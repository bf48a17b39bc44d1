//! The PSAO point representation (DESIGN §3; paper "PSAO: Point-Based Split Rendering for
//! Ambient Occlusion", §3): evenly spread surface points per mesh instance, a per-instance
//! virtual grid addressed through hash buckets, 32-bit packed points, and the client's AO
//! reconstruction. Pure computation: no file or network I/O.
//!
//! Typical use:
//! 1. [`generate_instance_points`] (or [`generate_scene_points`]) → [`InstancePoints`];
//! 2. [`InstanceGrid::from_points`] → buckets + cells (server state, sent to clients);
//! 3. the server writes AO with [`InstanceGrid::update`]; clients mirror buckets and cells
//!    ([`MirrorGrid::set_bucket`], [`MirrorGrid::set_cell`]) and call [`reconstruct_ao`]
//!    (on either, through [`CellLookup`]).

#[cfg(feature = "generate")]
mod elimination;
mod error;
#[cfg(feature = "generate")]
mod generate;
mod grid;
pub mod irradiance;
mod key_map;
mod layout;
mod linear_fit;
mod lookup;
mod mirror;
pub mod pack;
mod paged;
mod reconstruct;
mod rng;

#[cfg(feature = "generate")]
pub use elimination::{eliminate, eliminate_scaled, max_poisson_radius};
pub use error::PointsError;
#[cfg(feature = "generate")]
pub use generate::{
    generate_instance_points, generate_instance_points_adaptive, generate_scene_points,
    generate_scene_points_adaptive, instance_seed, Adaptive, AlphaTest, DensitySignal,
    GenerateParams, InstancePoints, SceneAlphaTest, SurfacePoint, DEFAULT_DENSITY, MAX_SPAWNED,
};
pub use grid::{Bucket, BucketEntry, Cell, GridMemory, InstanceGrid, PointLoc};
pub use key_map::{KeyHasher, KeyMap};
pub use layout::{
    DecodedPoint, GridLayout, BUCKET_ENTRIES, CELLS_PER_AREA, CELL_POINTS, CELL_RADIUS_FACTOR,
    MAX_DIM, TABLE_OVERSIZE,
};
pub use linear_fit::LinearFit;
pub use lookup::CellLookup;
pub use mirror::{MirrorGrid, MirrorMemory, PagedRuns, MAX_RUN};
pub use paged::Paged;
pub use reconstruct::{
    reconstruct_ao, NearestK, ReconstructParams, ADAPTIVE_NEIGHBOURS, DEFAULT_ADAPTIVE_RADIUS,
    DEFAULT_DIRECTION_THRESHOLD, DEFAULT_INTERPOLATION_FACTOR, DEFAULT_LINEAR_RIDGE,
    DEFAULT_NORMAL_EXPONENT, DEFAULT_NORMAL_THRESHOLD, DEFAULT_PLANE_TOLERANCE,
};

/// Heap bytes a vector holds: its allocated capacity times the element size.
pub fn vec_bytes<T>(v: &Vec<T>) -> u64 {
    (v.capacity() * std::mem::size_of::<T>()) as u64
}
