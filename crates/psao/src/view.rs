//! `psao view`: arguments, scene loading, image writing and printing around
//! [`psao_net::view`].

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use psao_net::view::{view, ViewConfig};
use psao_net::Resolution;

use crate::access_args::TokenArgs;
use crate::run::{write_frame_images, write_json};
use crate::scene_source::SceneArgs;

/// Arguments of `psao view`.
#[derive(clap::Args, Debug, Clone)]
pub struct ViewArgs {
    /// Server address: `HOST:PORT` (TCP), `ws://HOST:PORT[/PATH]` (WebSocket, path `/ws` by
    /// default) or `wss://HOST:PORT[/PATH]` (WebSocket over TLS). Several, comma separated
    /// (e.g. the edges of docs/SCALE-OUT.md), are tried in turn on each reconnect.
    #[arg(long, default_value = "127.0.0.1:7878")]
    pub connect: String,
    /// PEM file of the certificates to trust for `wss://` (default: the Mozilla roots).
    #[arg(long)]
    pub tls_ca: Option<PathBuf>,
    #[command(flatten)]
    pub token: TokenArgs,
    #[command(flatten)]
    pub input: SceneArgs,
    /// Client frames to run (default: the whole camera path).
    #[arg(long)]
    pub frames: Option<u32>,
    /// Image size, `WxH`.
    #[arg(long, default_value = "640x360")]
    pub res: Resolution,
    /// Output folder for `frame_NNNNN.png` / `ao_NNNNN.png`; without it nothing is rendered
    /// (updates are still received and applied).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write the summary as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Simulated one-way latency of received frames, ms.
    #[arg(long, default_value_t = 0)]
    pub latency_ms: u64,
    /// Simulated link capacity for received frames, Mbit/s (0 = unlimited).
    #[arg(long, default_value_t = 0.0)]
    pub max_mbit: f64,
    /// Give up after this many seconds without a connection.
    #[arg(long, default_value_t = 30.0)]
    pub retry_secs: f64,
    /// Do not ask for the server's state hash with every update (saves hashing the whole
    /// state on both ends each update; for load tests).
    #[arg(long)]
    pub no_verify: bool,
    /// Start this many frames into the camera path (wrapping around at its end).
    #[arg(long, default_value_t = 0)]
    pub path_offset: u32,
    /// Fault injection: drop the connection once, at this client frame.
    #[arg(long, hide = true)]
    pub drop_at: Option<u32>,
    /// Write the first received frames (≤ 64 KiB each) and their update payloads to this
    /// folder (seed corpus for the fuzz targets).
    #[arg(long, hide = true)]
    pub record: Option<PathBuf>,
    #[command(flatten)]
    pub corrective: crate::corrective::split_args::CorrectiveArgs,
    /// Run this many headless viewers in this one process, for load tests (`psao bench serve
    /// --one-client-process`): one scene load, a thread each, viewer k starting k/N of the way
    /// along the path (after `--path-offset`); `--json` then writes a list of their summaries.
    /// Not with `--out`, `--record` or `--corrective`.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub viewers: Option<u32>,
}

/// Runs `psao view`.
pub fn run(args: &ViewArgs) -> Result<()> {
    if let Some(n) = args.viewers {
        return run_viewers(args, n);
    }
    let (input, path) = args.input.load()?;
    if let Some(out) = &args.out {
        std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    }
    let config = view_config(args)?;
    let stats = view(&input.scene, &path, &config, &mut |frame, img| {
        if let Some(out) = &args.out {
            write_frame_images(out, frame, &input.scene, img)?;
        }
        Ok(())
    })?;
    println!(
        "{} frames, {:.2} Mbit/s, {} reconnects, state {}",
        stats.frames, stats.mbit_s, stats.reconnects, stats.state_hash
    );
    if let Some(h) = &stats.corrective_state_hash {
        println!("{} correction samples, corrective state {h}", stats.samples);
    }
    if let Some(json) = &args.json {
        write_json(json, &stats)?;
    }
    if stats.hash_mismatches > 0 {
        bail!(
            "{} updates left the client's state different from the server's",
            stats.hash_mismatches
        );
    }
    Ok(())
}

/// `psao view --viewers n`: n headless viewers on threads of this process.
fn run_viewers(args: &ViewArgs, n: u32) -> Result<()> {
    if args.out.is_some() || args.record.is_some() || args.corrective.config()?.is_some() {
        bail!("--viewers runs headless viewers without --out, --record or --corrective");
    }
    let (input, path) = args.input.load()?;
    let total = path.frame_count() as u32;
    let config = view_config(args)?;
    let stats: Vec<_> = std::thread::scope(|scope| {
        let viewers: Vec<_> = (0..n)
            .map(|k| {
                let config = ViewConfig {
                    path_offset: args.path_offset + k * total / n,
                    ..config.clone()
                };
                let scene = &input.scene;
                let path = &path;
                scope.spawn(move || view(scene, path, &config, &mut |_, _| Ok(())))
            })
            .collect();
        viewers
            .into_iter()
            .enumerate()
            .map(|(k, v)| match v.join() {
                Ok(stats) => stats.with_context(|| format!("viewer {k}")),
                Err(_) => Err(anyhow::anyhow!("viewer {k} panicked")),
            })
            .collect::<Result<_>>()
    })?;
    let updates: u64 = stats.iter().map(|s| u64::from(s.updates)).sum();
    println!("{n} viewers, {updates} updates applied in all");
    if let Some(json) = &args.json {
        write_json(json, &stats)?;
    }
    let mismatches: u32 = stats.iter().map(|s| s.hash_mismatches).sum();
    if mismatches > 0 {
        bail!("{mismatches} updates left a viewer's state different from the server's");
    }
    Ok(())
}

/// The viewer settings of `args`.
fn view_config(args: &ViewArgs) -> Result<ViewConfig> {
    Ok(ViewConfig {
        connect: args.connect.clone(),
        tls_ca: args.tls_ca.clone(),
        token: args.token.token()?,
        frames: args.frames,
        res: args.res,
        render: args.out.is_some(),
        latency_ms: args.latency_ms,
        max_mbit: args.max_mbit,
        retry_secs: args.retry_secs,
        no_verify: args.no_verify,
        path_offset: args.path_offset,
        drop_at: args.drop_at,
        record: args.record.clone(),
        corrective: args.corrective.config()?.map(|c| c.client),
    })
}
