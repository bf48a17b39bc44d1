//! Scale-out on NATS JetStream (docs/SCALE-OUT.md): trace nodes ([`trace_node`]) share the
//! tracing of a scene's points and publish point records per server frame; edges
//! ([`edge`]) rebuild the whole published state from them and serve viewers with the serve
//! code of `psao serve` ([`crate::serve`]).

pub mod edge;
pub mod join;
mod lost;
mod names;
pub mod trace_node;
pub mod wire;

pub use names::{scene_id, Names};

use std::sync::atomic::{AtomicBool, Ordering::SeqCst};
use std::sync::Arc;
use std::time::Duration;

use tokio::sync::Notify;

use crate::NetError;

/// How long a partition's lease lives without being refreshed.
pub const LEASE_TTL: Duration = Duration::from_secs(3);
/// Frames of batches the records stream keeps per partition; older ones are dropped (a
/// joining edge starts from the snapshots, which are much more recent).
pub const RECORD_FRAMES: i64 = 1024;
/// Messages kept per snapshot subject: a chunk's latest message is its points' current
/// state, and a partition's latest mark says as of which frame (docs/SCALE-OUT.md).
const SNAPSHOT_FRAMES: i64 = 1;
/// How often a trace node refreshes its leases and looks for partitions without one.
pub const LEASE_CHECK: Duration = Duration::from_millis(500);
/// Growth of the delay between attempts to reconnect to the NATS server, per attempt.
const RECONNECT_DELAY_STEP: Duration = Duration::from_millis(25);
/// Longest delay between attempts to reconnect (well under [`LEASE_TTL`]).
const RECONNECT_DELAY_MAX: Duration = Duration::from_millis(250);

/// Connects to the NATS server at `url`. Clients reconnect by themselves after a restart;
/// `connected` is notified at every reconnection (not the first connection), for what the
/// NATS server may have forgotten meanwhile (consumers).
async fn connect(url: &str, connected: Arc<Notify>) -> Result<async_nats::Client, NetError> {
    let first = Arc::new(AtomicBool::new(true));
    async_nats::ConnectOptions::new()
        .connection_timeout(Duration::from_secs(5))
        // Reconnect within RECONNECT_DELAY_MAX of the server's return (the client's default
        // backoff grows to 4 s): a node that lags behind the others' reconnection by more than
        // LEASE_TTL would have its partitions adopted although it is alive.
        .reconnect_delay_callback(|attempts| {
            (RECONNECT_DELAY_STEP * attempts.min(10) as u32).min(RECONNECT_DELAY_MAX)
        })
        .event_callback(move |event| {
            let (connected, first) = (connected.clone(), first.clone());
            async move {
                tracing::info!("NATS: {event}");
                if matches!(event, async_nats::Event::Connected) && !first.swap(false, SeqCst) {
                    connected.notify_one();
                }
            }
        })
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
        max_messages_per_subject: RECORD_FRAMES,
        storage: async_nats::jetstream::stream::StorageType::File,
        ..Default::default()
    })
    .await
    .map_err(|e| NetError::Nats(format!("cannot open stream {}: {e}", names.stream())))
}

/// The snapshots stream of `names` (the last [`SNAPSHOT_FRAMES`] messages of each subject),
/// created when missing.
async fn snapshot_stream(
    js: &async_nats::jetstream::Context,
    names: &Names,
) -> Result<async_nats::jetstream::stream::Stream, NetError> {
    let name = names.snapshot_stream();
    js.get_or_create_stream(async_nats::jetstream::stream::Config {
        name: name.clone(),
        subjects: vec![names.snapshots_wildcard()],
        max_messages_per_subject: SNAPSHOT_FRAMES,
        storage: async_nats::jetstream::stream::StorageType::File,
        ..Default::default()
    })
    .await
    .map_err(|e| NetError::Nats(format!("cannot open stream {name}: {e}")))
}
