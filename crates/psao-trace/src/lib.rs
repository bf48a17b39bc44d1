//! psao-trace: one [`Tracer`] facade over a two-level ray-tracing structure (a BVH per mesh in
//! mesh-local space, a top level over the instances), with the pure-Rust `obvhs` backend and
//! Embree 3 behind the cargo feature `embree`; spatial ray sorting; the [`ao`] and [`gi`]
//! modules that define ambient occlusion and diffuse lighting for all of psao; and the one
//! hit-to-surface lookup ([`surface`]).

pub mod ao;
#[cfg(feature = "embree")]
mod embree_backend;
mod geometry;
pub mod gi;
mod obvhs_backend;
mod sort;
pub mod surface;
mod tracer;
mod types;

pub use sort::sort_rays_spatially;
pub use tracer::{MeshUpdate, Tracer, DEFAULT_MAX_COST_RATIO};
pub use types::{Backend, GeometryMode, Hit, Ray, TraceError};
