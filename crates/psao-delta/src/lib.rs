//! The PSAO update data model and its codecs (DESIGN §3 "Server update", §4 "The wire").
//!
//! A server frame produces, per client, an [`Update`]: the instance transforms plus the hash
//! buckets and cells that changed since the client's previous update ([`InstanceDelta`]). A
//! client that applied every update in order (or a snapshot and then every later update) holds
//! exactly the server's published grids. [`Codec`]s turn updates into bytes and back; decoding
//! is hardened against malformed or hostile input (typed [`DeltaError`]s, bounded memory).
//! Pure computation: no file or network I/O.

mod codec;
mod compact;
mod error;
mod limits;
mod model;
mod paper;
mod words;
pub mod zstd_io;

pub use codec::{codec_by_name, Codec, CODEC_NAMES};
pub use compact::{CompactCodec, COMPACT_LEVEL};
pub use error::DeltaError;
pub use limits::{decode_limit, total_buckets, MAX_TOTAL_BUCKETS};
pub use model::{compact_bucket, compact_cell, InstanceDelta, InstanceInfo, Update};
pub use paper::{PaperCodec, MAX_DECODED_BYTES, MAX_DECODE_LIMIT, PAPER_LEVEL};
/// The grid layout type of [`InstanceInfo`], re-exported for building instance tables.
pub use psao_points::GridLayout;
