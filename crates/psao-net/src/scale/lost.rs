//! Noticing a NATS server that lost messages it had acknowledged (docs/SCALE-OUT.md,
//! "Lost messages"). nats-server's file store writes asynchronously: killed hard, it comes
//! back without the last messages it had stored, and hands their sequence numbers to new
//! messages. What it lost is always the newest messages of a stream, so the messages a
//! node remembers that the stream still holds, as they were, are the oldest of them.

use std::collections::VecDeque;

use async_nats::jetstream::message::StreamMessage;
use async_nats::jetstream::stream::{LastRawMessageErrorKind, Stream};

use crate::NetError;

/// Messages an edge remembers (a loss deeper than this is read again from the stream's
/// start); well under [`super::RECORD_FRAMES`], so that none of them is dropped by the
/// stream's limits meanwhile.
pub const RECEIVED_WINDOW: usize = 512;

/// The message stored under `sequence`, `None` when the stream holds none there.
pub(super) async fn stored(
    stream: &Stream,
    sequence: u64,
) -> Result<Option<StreamMessage>, NetError> {
    match stream.get_raw_message(sequence).await {
        Ok(m) => Ok(Some(m)),
        Err(e) if matches!(e.kind(), LastRawMessageErrorKind::NoMessageFound) => Ok(None),
        Err(e) => Err(NetError::Nats(format!(
            "cannot read message {sequence} of the records stream: {e}"
        ))),
    }
}

/// The last messages an edge received: sequence number and the time the stream stored
/// them (which a message stored later under a reused number cannot share).
#[derive(Default)]
pub struct Received {
    window: VecDeque<(u64, i128)>,
}

impl Received {
    /// Remember the message `sequence`, stored at `nanos` (Unix ns).
    pub fn note(&mut self, sequence: u64, nanos: i128) {
        if self.window.len() == RECEIVED_WINDOW {
            self.window.pop_front();
        }
        self.window.push_back((sequence, nanos));
    }

    /// The sequence number of the remembered message before the oldest one that `stream`
    /// no longer holds as it was (the messages after it are to be read again), forgetting
    /// the ones from there on; the newest one when none was lost. `Ok(None)`: the oldest
    /// one was lost (read from the stream's start), or nothing is remembered.
    ///
    /// The messages lost are the newest the server had stored, so those still held come
    /// first; messages received since the server came back are held too, but come after
    /// the lost ones: the window is scanned from its oldest message.
    pub async fn last_held(&mut self, stream: &Stream) -> Result<Option<u64>, NetError> {
        let mut held = 0;
        for &(sequence, nanos) in &self.window {
            let same = stored(stream, sequence)
                .await?
                .is_some_and(|m| m.time.unix_timestamp_nanos() == nanos);
            if !same {
                break;
            }
            held += 1;
        }
        self.window.truncate(held);
        Ok(self.window.back().map(|&(s, _)| s))
    }

    /// Whether nothing is remembered.
    pub fn is_empty(&self) -> bool {
        self.window.is_empty()
    }
}

/// A message a trace node published and the stream acknowledged.
#[derive(Clone)]
pub struct Sent {
    /// Its stream sequence number.
    pub sequence: u64,
    /// Subject, message id and payload, to publish it again.
    pub subject: String,
    pub id: String,
    pub payload: bytes::Bytes,
}

/// The indexes in `sent` of the messages `stream` no longer holds: the message under
/// each one's sequence number is missing or has another message id. Every message is
/// asked: those stored since the server came back are held, but may be newer than lost
/// ones.
pub async fn lost(stream: &Stream, sent: &VecDeque<Sent>) -> Result<Vec<usize>, NetError> {
    let mut lost = Vec::new();
    for (i, s) in sent.iter().enumerate() {
        let same = stored(stream, s.sequence).await?.is_some_and(|m| {
            m.headers
                .get(async_nats::header::NATS_MESSAGE_ID)
                .is_some_and(|id| id.as_str() == s.id)
        });
        if !same {
            lost.push(i);
        }
    }
    Ok(lost)
}
