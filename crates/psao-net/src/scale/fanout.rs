//! How much one NATS server carries (`psao bench nats`, docs/SCALE-OUT.md "Bandwidth at
//! scale"): messages of a record batch's size are stored in a records stream (file storage,
//! acknowledged, as trace nodes publish them) while `subscribers` ordered consumers (as edges
//! and trace nodes read them) take every message. The result is the rate the server took
//! messages in and gave them out, from which the number of trace nodes and edges one server
//! serves at a given frame rate follows.

use std::collections::VecDeque;
use std::sync::Arc;
use std::time::{Duration, Instant};

use async_nats::jetstream::consumer::DeliverPolicy;
use futures_util::StreamExt;
use serde::Serialize;
use tokio::sync::Notify;

use super::join::ordered;
use super::{connect, records_stream, Names, NatsAuth, ServerErrors};
use crate::NetError;

/// Scene name of the measurement's stream (its subjects and stream name follow [`Names`]).
const FANOUT_SCENE: &str = "psao-bench-fanout";
/// Most stores awaiting their acknowledgement at once.
const ACK_WINDOW: usize = 64;
/// Longest wait for any one message or acknowledgement.
const STALL: Duration = Duration::from_secs(30);

/// One measurement.
#[derive(Clone, Debug)]
pub struct FanoutConfig {
    /// NATS server URL, and its credentials.
    pub nats: String,
    pub auth: NatsAuth,
    /// Bytes per message (a compressed record batch part: at most the server's
    /// `max_payload`).
    pub message_bytes: usize,
    /// Messages stored.
    pub messages: u64,
    /// Consumers that each take every message.
    pub subscribers: u32,
}

/// What one measurement found.
#[derive(Clone, Debug, Serialize)]
pub struct FanoutResult {
    pub subscribers: u32,
    pub message_bytes: usize,
    pub messages: u64,
    /// From the first store to the last message at the slowest consumer.
    pub seconds: f64,
    /// Messages stored per second, and their megabytes (10⁶ bytes) per second.
    pub stored_per_s: f64,
    pub stored_mb_per_s: f64,
    /// Megabytes per second given out to all consumers together.
    pub delivered_mb_per_s: f64,
}

/// Runs one measurement against the NATS server of `config` (which must have JetStream);
/// the stream it uses is deleted afterwards.
pub fn measure(config: &FanoutConfig) -> Result<FanoutResult, NetError> {
    if config.message_bytes == 0 || config.messages == 0 {
        return Err(NetError::Nats(
            "a fan-out measurement needs messages of at least one byte".into(),
        ));
    }
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .map_err(NetError::io("cannot start the async runtime"))?;
    rt.block_on(run(config))
}

async fn run(config: &FanoutConfig) -> Result<FanoutResult, NetError> {
    let failed = |e: &dyn std::fmt::Display| NetError::Nats(format!("fan-out measurement: {e}"));
    let (js, max) = jetstream(config).await?;
    if config.message_bytes > max {
        return Err(NetError::Nats(format!(
            "messages of {} bytes exceed the server's max_payload of {max}",
            config.message_bytes
        )));
    }
    let names = Names::new(FANOUT_SCENE);
    // A stream left by an interrupted run would be counted: start from an empty one.
    let _ = js.delete_stream(names.stream()).await;
    records_stream(&js, &names).await?;
    let mut readers = Vec::new();
    for _ in 0..config.subscribers {
        // A connection per consumer, as every edge and trace node is a process of its own.
        let stream = records_stream(&jetstream(config).await?.0, &names).await?;
        let mut messages = ordered(&stream, DeliverPolicy::All, names.records_wildcard())
            .await
            .map_err(|e| failed(&e))?;
        let want = config.messages;
        readers.push(tokio::spawn(async move {
            let mut got = 0u64;
            loop {
                match tokio::time::timeout(STALL, messages.next()).await {
                    Ok(Some(Ok(m))) => {
                        got += 1;
                        // The stream is new: the last store has sequence `want`.
                        if m.info().is_ok_and(|i| i.stream_sequence >= want) {
                            break;
                        }
                    }
                    Ok(Some(Err(e))) => return Err(e.to_string()),
                    Ok(None) => return Err("the consumer ended".to_string()),
                    Err(_) => return Err(format!("no message for {STALL:?} after {got}")),
                }
            }
            if got < want {
                // The stream keeps RECORD_FRAMES messages per subject: a consumer that fell
                // further behind lost some, and the rate would not be the server's.
                return Err(format!(
                    "a consumer fell behind and lost {} messages",
                    want - got
                ));
            }
            Ok(Instant::now())
        }));
    }
    let payload = bytes::Bytes::from(vec![0x5a; config.message_bytes]);
    let subject = names.records(0);
    let start = Instant::now();
    let mut acks = VecDeque::new();
    for _ in 0..config.messages {
        if acks.len() == ACK_WINDOW {
            await_ack(acks.pop_front()).await?;
        }
        let ack = js
            .publish(subject.clone(), payload.clone())
            .await
            .map_err(|e| failed(&e))?;
        acks.push_back(ack);
    }
    while let Some(ack) = acks.pop_front() {
        await_ack(Some(ack)).await?;
    }
    let stored = start.elapsed().as_secs_f64();
    let mut last = start;
    for reader in readers {
        let done = reader
            .await
            .map_err(|e| failed(&e))?
            .map_err(|e| failed(&e))?;
        last = last.max(done);
    }
    let _ = js.delete_stream(names.stream()).await;
    let seconds = (last - start).as_secs_f64().max(stored);
    let bytes = config.message_bytes as f64 * config.messages as f64;
    Ok(FanoutResult {
        subscribers: config.subscribers,
        message_bytes: config.message_bytes,
        messages: config.messages,
        seconds,
        stored_per_s: config.messages as f64 / stored,
        stored_mb_per_s: bytes / stored / 1e6,
        delivered_mb_per_s: bytes * f64::from(config.subscribers) / seconds / 1e6,
    })
}

/// A JetStream context on a connection of its own, and the server's `max_payload`.
async fn jetstream(
    config: &FanoutConfig,
) -> Result<(async_nats::jetstream::Context, usize), NetError> {
    let client = connect(
        &config.nats,
        &config.auth,
        Arc::new(Notify::new()),
        ServerErrors::default(),
    )
    .await?;
    let max_payload = client.server_info().max_payload;
    let mut js = async_nats::jetstream::new(client);
    // The default acknowledgement timeout (5 s) is shorter than a busy server's file writes
    // can take with many consumers: the measurement waits as long as for any message.
    js.set_timeout(STALL);
    Ok((js, max_payload))
}

/// Waits for one store's acknowledgement.
async fn await_ack(
    ack: Option<async_nats::jetstream::context::PublishAckFuture>,
) -> Result<(), NetError> {
    let Some(ack) = ack else { return Ok(()) };
    match tokio::time::timeout(STALL, ack).await {
        Ok(Ok(_)) => Ok(()),
        Ok(Err(e)) => Err(NetError::Nats(format!("fan-out measurement: store: {e}"))),
        Err(_) => Err(NetError::Nats(format!(
            "fan-out measurement: no acknowledgement within {STALL:?}"
        ))),
    }
}
