//! Noticing a NATS server that lost messages it had acknowledged (docs/SCALE-OUT.md,
//! "Lost messages"). nats-server's file store writes asynchronously: killed hard, it comes
//! back without the last messages it had stored, and hands their sequence numbers to new
//! messages. What it lost is always the newest messages of a stream, so the messages a
//! node remembers that the stream still holds, as they were, are the oldest of them.

use std::collections::VecDeque;
use std::future::Future;

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
        self.last_held_by(|sequence, nanos| async move {
            let m = stored(stream, sequence).await?;
            Ok(m.is_some_and(|m| m.time.unix_timestamp_nanos() == nanos))
        })
        .await
    }

    /// [`Received::last_held`] with `held(sequence, nanos)` saying whether the stream
    /// still holds that message as it was.
    async fn last_held_by<F, Fut>(&mut self, mut held: F) -> Result<Option<u64>, NetError>
    where
        F: FnMut(u64, i128) -> Fut,
        Fut: Future<Output = Result<bool, NetError>>,
    {
        let mut kept = 0;
        for &(sequence, nanos) in &self.window {
            if !held(sequence, nanos).await? {
                break;
            }
            kept += 1;
        }
        self.window.truncate(kept);
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
    lost_by(sent, |s| async move {
        let m = stored(stream, s.sequence).await?;
        Ok(m.is_some_and(|m| {
            m.headers
                .get(async_nats::header::NATS_MESSAGE_ID)
                .is_some_and(|id| id.as_str() == s.id)
        }))
    })
    .await
}

/// [`lost`] with `held(s)` saying whether the stream still holds `s`.
async fn lost_by<'a, F, Fut>(sent: &'a VecDeque<Sent>, mut held: F) -> Result<Vec<usize>, NetError>
where
    F: FnMut(&'a Sent) -> Fut,
    Fut: Future<Output = Result<bool, NetError>>,
{
    let mut lost = Vec::new();
    for (i, s) in sent.iter().enumerate() {
        if !held(s).await? {
            lost.push(i);
        }
    }
    Ok(lost)
}

#[cfg(test)]
mod tests {
    use super::*;
    use futures_util::FutureExt;

    #[test]
    fn an_edge_reads_again_after_the_last_message_before_the_first_lost() {
        // Stored as received: 1 to 3. Lost: 4 (missing) and 5 (its number reused by a
        // later message). 6 was received from the server after it came back.
        let stream = |seq: u64, nanos: i128| match seq {
            1..=3 | 6 => nanos == seq as i128 * 10,
            5 => nanos == 999,
            _ => false,
        };
        let ask = |seq, nanos| futures_util::future::ready(Ok(stream(seq, nanos)));
        let mut r = Received::default();
        assert_eq!(r.last_held_by(ask).now_or_never().unwrap().unwrap(), None);
        for seq in 1..=6 {
            r.note(seq, seq as i128 * 10);
        }
        let got = r.last_held_by(ask).now_or_never().unwrap().unwrap();
        assert_eq!(got, Some(3), "6 is held, but 4 and 5 before it are not");
        assert_eq!(r.window.len(), 3);
        assert_eq!(
            r.last_held_by(ask).now_or_never().unwrap().unwrap(),
            Some(3)
        );

        let mut gone = Received::default();
        gone.note(4, 40);
        let got = gone.last_held_by(ask).now_or_never().unwrap().unwrap();
        assert_eq!(got, None, "nothing remembered is held: from the start");
        assert!(gone.is_empty());

        let mut full = Received::default();
        for seq in 0..RECEIVED_WINDOW as u64 + 10 {
            full.note(seq, 0);
        }
        assert_eq!(full.window.len(), RECEIVED_WINDOW);
        assert_eq!(full.window[0].0, 10, "the oldest are forgotten");
    }

    #[test]
    fn a_trace_node_republishes_every_lost_batch_also_before_newer_held_ones() {
        let sent: VecDeque<Sent> = (1..=6)
            .map(|sequence| Sent {
                sequence,
                subject: "psao.s.rec.0".into(),
                id: format!("n.0.{sequence}"),
                payload: bytes::Bytes::new(),
            })
            .collect();
        // 4 and 5 lost; 6 stored after the server came back.
        let held = |s: &Sent| futures_util::future::ready(Ok(![4, 5].contains(&s.sequence)));
        let got = lost_by(&sent, held).now_or_never().unwrap().unwrap();
        assert_eq!(got, [3, 4], "indexes of sequences 4 and 5");
    }
}
