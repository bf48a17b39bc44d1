//! `psao bench nats`: how much one NATS server carries for scale-out
//! (docs/SCALE-OUT.md "Bandwidth at scale"): messages of a record batch's size stored in a
//! records stream and taken by 1, 2, 4, … consumers, as trace nodes publish and edges read.

use std::path::PathBuf;

use anyhow::{bail, Result};
use clap::Args;
use psao_net::scale::fanout::{measure, FanoutConfig, FanoutResult};
use psao_net::scale::NatsAuth;
use serde::Serialize;

use crate::bench_scale::{start_nats, Scratch};
use crate::run::write_json;

/// `psao bench nats` arguments.
#[derive(Args, Debug)]
pub struct BenchNatsArgs {
    /// Bytes per message (the compressed record batch of a frame, or one part of it).
    #[arg(long, default_value_t = 65_536)]
    pub message_bytes: usize,
    /// Messages stored per measurement.
    #[arg(long, default_value_t = 2000)]
    pub messages: u64,
    /// Consumer counts to measure, each taking every message.
    #[arg(long, default_value = "1,2,4,8", value_delimiter = ',')]
    pub subscribers: Vec<u32>,
    /// Measure this NATS server (with JetStream) instead of one started for the run.
    #[arg(long)]
    pub nats: Option<String>,
    /// The NATS server program started for the run.
    #[arg(long, default_value = "nats-server")]
    pub nats_server: PathBuf,
    /// Write the report as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// What `psao bench nats` reports.
#[derive(Serialize)]
struct NatsReport {
    runs: Vec<FanoutResult>,
}

/// Runs `psao bench nats`.
pub fn run(args: &BenchNatsArgs) -> Result<()> {
    if args.messages == 0 || args.message_bytes == 0 || args.subscribers.contains(&0) {
        bail!("--messages, --message-bytes and every --subscribers count must be at least 1");
    }
    let mut runs = Vec::new();
    for &subscribers in &args.subscribers {
        // A fresh server per count (when started here): no stored messages carried over.
        let scratch = Scratch::new(&format!("nats{subscribers}"))?;
        let (_server, url) = match &args.nats {
            Some(url) => (None, url.clone()),
            None => {
                let (server, url) = start_nats(&args.nats_server, scratch.path())?;
                (Some(server), url)
            }
        };
        let result = measure(&FanoutConfig {
            nats: url,
            auth: NatsAuth::default(),
            message_bytes: args.message_bytes,
            messages: args.messages,
            subscribers,
        })?;
        tracing::info!(
            "{subscribers} consumers: {:.0} messages/s stored, {:.1} MB/s in, {:.1} MB/s out",
            result.stored_per_s,
            result.stored_mb_per_s,
            result.delivered_mb_per_s
        );
        runs.push(result);
    }
    let report = NatsReport { runs };
    println!("{}", serde_json::to_string_pretty(&report)?);
    if let Some(json) = &args.json {
        write_json(json, &report)?;
    }
    Ok(())
}
