//! Scale-out on NATS JetStream (docs/SCALE-OUT.md): trace nodes ([`trace_node`]) share the
//! tracing of a scene's points and publish point records per server frame; edges
//! ([`edge`]) rebuild the whole published state from them and serve viewers with the serve
//! code of `psao serve` ([`crate::serve`]).

pub mod edge;
mod names;
pub mod trace_node;
pub mod wire;

pub use names::{scene_id, Names};

use std::time::Duration;

use crate::NetError;

/// How long a partition's lease lives without being refreshed.
pub const LEASE_TTL: Duration = Duration::from_secs(3);
/// How often a trace node refreshes its leases and looks for partitions without one.
pub const LEASE_CHECK: Duration = Duration::from_millis(500);

/// Connects to the NATS server at `url` (clients reconnect by themselves after a restart).
async fn connect(url: &str) -> Result<async_nats::Client, NetError> {
    async_nats::ConnectOptions::new()
        .connection_timeout(Duration::from_secs(5))
        .connect(url)
        .await
        .map_err(|e| NetError::Nats(format!("cannot connect to {url}: {e}")))
}

/// The records stream of `names`, created when missing.
async fn records_stream(
    js: &async_nats::jetstream::Context,
    names: &Names,
) -> Result<async_nats::jetstream::stream::Stream, NetError> {
    js.get_or_create_stream(async_nats::jetstream::stream::Config {
        name: names.stream(),
        subjects: vec![names.records_wildcard()],
        storage: async_nats::jetstream::stream::StorageType::File,
        ..Default::default()
    })
    .await
    .map_err(|e| NetError::Nats(format!("cannot open stream {}: {e}", names.stream())))
}
