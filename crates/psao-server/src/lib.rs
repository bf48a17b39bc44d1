//! The PSAO server (DESIGN §3 "Server update" and "CPU server"): the authoritative point
//! state of a scene, AO (and optionally diffuse irradiance, DESIGN §12) accumulated over
//! server frames within a ray budget, thresholded
//! publishing into per-instance hash grids, and per-client deltas of what changed.
//!
//! Typical loop: [`Server::new`] → [`Server::instance_table`] (sent once per client) →
//! each server frame [`Server::step_at`] with the clients' views and the scene time → [`Server::update_for`] per
//! client, encoded with a [`psao_delta::Codec`]. Pure computation: no file or network I/O.

mod alloc;
mod blocks;
mod bury;
mod changes;
mod clients;
mod config;
mod dynamics;
mod error;
mod frustum;
mod instance;
mod light;
mod memory;
mod near_field;
pub mod partition;
mod publish;
mod server;
mod start_points;
mod summary;
mod trace;

pub use blocks::morton_order;
pub use bury::{BURIAL_MIN_INSIDE, BURIAL_RAYS};
pub use clients::ClientId;
pub use config::{LightingConfig, ServerConfig, Thresholds, MAX_BOUNCES, MAX_SAMPLES_LIMIT};
pub use dynamics::{Invalidation, MotionStats};
pub use error::ServerError;
pub use frustum::{Frustum, View};
pub use light::{POOL_COS, POOL_MAX_REACH, POOL_PLANE, SUN_TOLERANCE_DEG};
pub use memory::MemoryPart;
pub use near_field::{NEAR_FIELD_RAYS, NEAR_FIELD_SPACINGS};
pub use partition::{Owners, Partition};
pub use server::{PointInfo, PointRecord, PointState, Server, StepStats};
pub use start_points::StartPoints;
