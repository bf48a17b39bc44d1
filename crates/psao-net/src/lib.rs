//! psao networking: a server streaming AO updates to many clients over TCP and WebSocket
//! ([`serve`]), a headless client following a camera path ([`view`]), the frame transports
//! and wire conversions they share, the in-process split pipeline ([`pipeline`]), and the
//! start points kept on disk between runs ([`start_cache`]).
//!
//! Everything here is a library: the `psao` binary only parses arguments, loads scenes and
//! prints; another program can embed a server or a client the same way.

pub mod convert;
pub mod cpu_time;
mod error;
pub mod pipeline;
mod resolution;
pub mod serve;
pub mod start_cache;
pub mod transport;
pub mod view;

pub use error::NetError;
pub use resolution::{Resolution, ResolutionError, MAX_IMAGE_SIDE};
