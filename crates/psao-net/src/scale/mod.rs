//! Scale-out on NATS JetStream (docs/SCALE-OUT.md): trace nodes ([`trace_node`]) share the
//! tracing of a scene's points and publish point records per server frame; edges
//! ([`edge`]) rebuild the whole published state from them and serve viewers with the serve
//! code of `psao serve` ([`crate::serve`]).

pub mod auth;
pub mod edge;
pub mod fanout;
pub mod join;
mod lost;
mod names;
pub mod parts;
pub mod trace_node;
pub mod wire;

pub use auth::NatsAuth;
pub use names::{scene_id, Names};

use std::sync::atomic::{AtomicBool, Ordering::SeqCst};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

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

/// The latest error the NATS server sent on a connection (`-ERR`) and when it arrived. A
/// publish the server refuses (too large, not permitted) is answered only by such an error
/// (and, when too large, a closed connection), never by an acknowledgement.
#[derive(Clone, Default)]
pub(crate) struct ServerErrors(Arc<Mutex<Option<(Instant, String)>>>);

impl ServerErrors {
    fn note(&self, error: String) {
        if let Ok(mut latest) = self.0.lock() {
            *latest = Some((Instant::now(), error));
        }
    }

    /// The latest error that arrived since `since` when it says a publish was refused.
    pub(crate) fn refusal_since(&self, since: Instant) -> Option<String> {
        let latest = self.0.lock().ok()?.clone();
        latest
            .filter(|(at, e)| *at >= since && is_refusal(e))
            .map(|(_, e)| e)
    }
}

/// Whether a NATS server error says it refused a publish (nats-server's wording: "Maximum
/// Payload Violation", "Permissions Violation for Publish to ...").
fn is_refusal(error: &str) -> bool {
    let error = error.to_lowercase();
    error.contains("maximum payload") || error.contains("permissions violation")
}

/// Connects to the NATS server at `url` with `auth`. Clients reconnect by themselves after a restart;
/// `connected` is notified at every reconnection (not the first connection), for what the
/// NATS server may have forgotten meanwhile (consumers); `errors` keeps the server's latest
/// error.
async fn connect(
    url: &str,
    auth: &NatsAuth,
    connected: Arc<Notify>,
    errors: ServerErrors,
) -> Result<async_nats::Client, NetError> {
    let first = Arc::new(AtomicBool::new(true));
    auth.options()
        .await?
        .connection_timeout(Duration::from_secs(5))
        // Reconnect within RECONNECT_DELAY_MAX of the server's return (the client's default
        // backoff grows to 4 s): a node that lags behind the others' reconnection by more than
        // LEASE_TTL would have its partitions adopted although it is alive.
        .reconnect_delay_callback(|attempts| {
            (RECONNECT_DELAY_STEP * attempts.min(10) as u32).min(RECONNECT_DELAY_MAX)
        })
        .event_callback(move |event| {
            let (connected, first, errors) = (connected.clone(), first.clone(), errors.clone());
            async move {
                tracing::info!("NATS: {event}");
                if let async_nats::Event::ServerError(e) = &event {
                    errors.note(e.to_string());
                }
                if matches!(event, async_nats::Event::Connected) && !first.swap(false, SeqCst) {
                    connected.notify_one();
                }
            }
        })
        .connect(url)
        .await
        .map_err(|e| NetError::Nats(format!("cannot connect to {url}: {e}")))
}

/// The NATS server's `max_payload` on `client`'s connection, checked to leave room for
/// every message a node publishes.
fn max_payload(client: &async_nats::Client) -> Result<usize, NetError> {
    let max = client.server_info().max_payload;
    let snapshot = wire::Snapshot::encoded_len(wire::CHUNK_POINTS) + parts::NATS_HEADROOM;
    let need = parts::MIN_MAX_PAYLOAD.max(snapshot);
    if max < need {
        return Err(NetError::Nats(format!(
            "the NATS server's max_payload of {max} bytes is too small: a snapshot chunk needs {need}"
        )));
    }
    Ok(max)
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refusals_are_told_from_other_server_errors() {
        let errors = ServerErrors::default();
        let before = Instant::now();
        assert_eq!(errors.refusal_since(before), None);
        errors.note("Stale Connection".into());
        assert_eq!(errors.refusal_since(before), None, "not a refusal");
        errors.note("Maximum Payload Violation".into());
        assert_eq!(
            errors.refusal_since(before).as_deref(),
            Some("Maximum Payload Violation")
        );
        errors.note("Permissions Violation for Publish to \"psao.s.rec.0\"".into());
        assert!(errors
            .refusal_since(before)
            .unwrap()
            .contains("psao.s.rec.0"));
        assert_eq!(
            errors.refusal_since(Instant::now() + Duration::from_secs(1)),
            None,
            "older than the publish"
        );
    }
}
