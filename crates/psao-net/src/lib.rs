//! psao networking: a server streaming AO updates to many clients over TCP, HTTP/WebSocket
//! and TLS ([`serve`], [`http`], [`tls`]), a headless client following a camera path
//! ([`view`]), the frame transports and wire conversions they share, the in-process split
//! pipeline ([`pipeline`]), relit characters on a client ([`relit`]), the served scene as binary glTF ([`glb`]), and the start points
//! kept on disk between runs ([`start_cache`]).
//!
//! Everything here is a library: the `psao` binary only parses arguments, loads scenes and
//! prints; another program can embed a server or a client the same way.

pub mod access;
pub mod admission;
pub mod characters;
pub mod convert;
pub mod corrective;
pub mod cpu_time;
pub mod deadline;
mod error;
pub mod glb;
mod hash_pacing;
pub mod http;
pub mod io;
pub mod pipeline;
pub mod priority;
pub mod process_memory;
pub mod relit;
mod resolution;
pub mod scale;
pub mod secret;
pub mod serve;
pub mod start_cache;
pub mod tls;
pub mod transport;
pub mod view;
mod view_analyzer;

pub use error::NetError;
pub use resolution::{Resolution, ResolutionError, MAX_IMAGE_SIDE};
