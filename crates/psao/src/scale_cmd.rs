//! `psao trace-node` and `psao edge`: arguments, scene loading and printing around
//! [`psao_net::scale`] (docs/SCALE-OUT.md).

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Duration;

use anyhow::Result;
use psao_net::scale::edge::{EdgeConfig, EdgeStats, EdgeStepper};
use psao_net::scale::trace_node::{self, TraceNodeConfig};
use psao_net::scale::NatsAuth;
use psao_net::serve::{Serve, ServeConfig, ServeStats};
use psao_server::{Partition, Server};
use serde::Serialize;

use crate::access_args::ExposureArgs;
use crate::run::{write_json, ServerTuning};
use crate::scene_source::SceneInput;

/// Default NATS server.
const NATS: &str = "nats://127.0.0.1:4222";

/// What both roles need to build the same server.
#[derive(clap::Args, Debug, Clone)]
pub struct SceneArgs {
    /// NATS server URL (with JetStream: `nats-server -js`).
    #[arg(long, default_value = NATS)]
    pub nats: String,
    #[command(flatten)]
    pub nats_auth: NatsAuthArgs,
    /// Scene: `default` (built in) or a .gltf/.glb/.obj/.toml file. Every node of a
    /// session must load the same scene with the same settings.
    #[arg(long, default_value = crate::scene_source::BUILTIN_SCENE)]
    pub scene: String,
    /// Points per unit area (after sample elimination).
    #[arg(long, default_value_t = 1024.0)]
    pub points: f32,
    /// Server frames per second of scene time.
    #[arg(long, default_value_t = 30)]
    pub hz: u32,
    #[command(flatten)]
    pub tuning: ServerTuning,
}

/// Credentials and TLS for the NATS connection (docs/SECURITY.md); secrets come from files.
#[derive(clap::Args, Debug, Clone)]
pub struct NatsAuthArgs {
    /// NATS `.creds` file (user JWT and NKey seed).
    #[arg(long, value_name = "FILE")]
    pub nats_creds: Option<PathBuf>,
    /// NATS user name (needs --nats-password-file).
    #[arg(long, requires = "nats_password_file")]
    pub nats_user: Option<String>,
    /// File whose first line is the NATS user's password.
    #[arg(long, value_name = "FILE", requires = "nats_user")]
    pub nats_password_file: Option<PathBuf>,
    /// File whose first line is a NATS token.
    #[arg(long, value_name = "FILE")]
    pub nats_token_file: Option<PathBuf>,
    /// File whose first line is a NATS NKey seed.
    #[arg(long, value_name = "FILE")]
    pub nats_nkey_seed_file: Option<PathBuf>,
    /// PEM certificates to trust for the NATS server (TLS).
    #[arg(long, value_name = "FILE")]
    pub nats_tls_ca: Option<PathBuf>,
    /// PEM client certificate for the NATS server (needs --nats-tls-key).
    #[arg(long, value_name = "FILE", requires = "nats_tls_key")]
    pub nats_tls_cert: Option<PathBuf>,
    /// PEM private key of --nats-tls-cert.
    #[arg(long, value_name = "FILE", requires = "nats_tls_cert")]
    pub nats_tls_key: Option<PathBuf>,
}

impl NatsAuthArgs {
    fn auth(&self) -> NatsAuth {
        NatsAuth {
            creds_file: self.nats_creds.clone(),
            user: self.nats_user.clone(),
            password_file: self.nats_password_file.clone(),
            token_file: self.nats_token_file.clone(),
            nkey_seed_file: self.nats_nkey_seed_file.clone(),
            tls_ca: self.nats_tls_ca.clone(),
            tls_cert: self.nats_tls_cert.clone(),
            tls_key: self.nats_tls_key.clone(),
        }
    }
}

impl SceneArgs {
    /// The scene's name, its server, and the scene as binary glTF (for browsers).
    fn server(&self) -> Result<(String, Server, Vec<u8>)> {
        let input = SceneInput::load(&self.scene)?;
        let server = crate::serve::scene_server(&input, &self.tuning, None, self.points, self.hz)?;
        let glb = psao_net::glb::scene_glb(&input.scene, &input.paths)?;
        Ok((input.name, server, glb))
    }
}

/// Arguments of `psao trace-node`.
#[derive(clap::Args, Debug, Clone)]
pub struct TraceNodeArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// The partition this node starts with, `k/n` (0 <= k < n).
    #[arg(long, default_value = "0/1")]
    pub partition: Partition,
    /// Lockstep with this many `psao edge --lockstep`: frame f is stepped once each sent its
    /// viewers' views for it.
    #[arg(long)]
    pub lockstep_edges: Option<usize>,
    /// Stop after this many server frames (default: until Ctrl-C).
    #[arg(long)]
    pub frames: Option<u64>,
    /// This node's name in the partition leases (default: trace-PID).
    #[arg(long)]
    pub node_id: Option<String>,
    /// Publish a snapshot of the held partitions every this many frames (0: never); a
    /// joining edge starts from the latest one instead of the whole history.
    #[arg(long, default_value_t = 64)]
    pub snapshot_every: u64,
    /// Write the node's statistics as JSON to this file on exit.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// Runs `psao trace-node`.
pub fn run_trace_node(args: &TraceNodeArgs) -> Result<()> {
    let (scene, server, _) = args.scene.server()?;
    let config = TraceNodeConfig {
        nats: args.scene.nats.clone(),
        auth: args.scene.nats_auth.auth(),
        scene,
        partition: args.partition,
        hz: args.scene.hz,
        lockstep_edges: args.lockstep_edges,
        frames: args.frames,
        node_id: args
            .node_id
            .clone()
            .unwrap_or_else(|| format!("trace-{}", std::process::id())),
        snapshot_every: args.snapshot_every,
    };
    println!("trace node {} ready", args.partition);
    let stop = Arc::new(AtomicBool::new(false));
    let stats = trace_node::run(server, config, stop)?;
    tracing::info!(
        "{} frames, {} rays ({:.0}/s of step time), partitions {:?}",
        stats.frames,
        stats.rays,
        stats.rays_per_s,
        stats.partitions
    );
    if let Some(json) = &args.json {
        write_json(json, &stats)?;
    }
    Ok(())
}

/// Arguments of `psao edge`.
#[derive(clap::Args, Debug, Clone)]
pub struct EdgeArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Address to listen on (TCP and WebSocket on the same port); port 0 picks a free one.
    #[arg(long, default_value = "127.0.0.1:7878")]
    pub listen: SocketAddr,
    #[command(flatten)]
    pub exposure: ExposureArgs,
    /// The session's number of partitions: the N of the trace nodes' `--partition k/N`.
    /// Batches and snapshots claiming another count are dropped (the bus never sets it).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub partitions: u32,
    /// Step once per round of client camera messages, waiting for every partition's batch
    /// of each frame (deterministic; the trace nodes need --lockstep-edges).
    #[arg(long)]
    pub lockstep: bool,
    /// Wait for this many clients before the first server frame.
    #[arg(long, default_value_t = 1)]
    pub wait_clients: usize,
    /// Most clients at once; later ones are refused with a `Server` error.
    #[arg(long, default_value_t = 64)]
    pub max_clients: usize,
    /// Exit once every client has left (after at least one joined).
    #[arg(long)]
    pub once: bool,
    /// This edge's name on its views subject (default: edge-PID).
    #[arg(long)]
    pub edge_id: Option<String>,
    /// Longest wait in lockstep for a frame's batches, seconds.
    #[arg(long, default_value_t = 30.0)]
    pub frame_timeout: f64,
    /// Write the serve and edge statistics as JSON to this file on exit.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// What `psao edge --json` writes: `psao serve`'s figures and the edge's counts.
#[derive(Serialize)]
struct EdgeReport {
    #[serde(flatten)]
    serve: ServeStats,
    edge: EdgeStats,
}

/// Runs `psao edge`.
pub fn run_edge(args: &EdgeArgs) -> Result<()> {
    let (scene, mut server, scene_glb) = args.scene.server()?;
    anyhow::ensure!(
        args.frame_timeout.is_finite() && args.frame_timeout > 0.0,
        "--frame-timeout must be a positive number of seconds"
    );
    let mut stepper = EdgeStepper::connect(
        EdgeConfig {
            nats: args.scene.nats.clone(),
            auth: args.scene.nats_auth.auth(),
            scene: scene.clone(),
            edge_id: args
                .edge_id
                .clone()
                .unwrap_or_else(|| format!("edge-{}", std::process::id())),
            partitions: args.partitions,
            lockstep: args.lockstep,
            frame_timeout: Duration::from_secs_f64(args.frame_timeout),
        },
        &mut server,
    )?;
    if !args.lockstep {
        let frames = stepper.catch_up(&mut server, Duration::from_secs(1))?;
        tracing::info!("caught up {frames} frames from the records stream");
    }
    let counters = stepper.counters();
    let config = ServeConfig {
        listen: args.listen,
        token: args.exposure.token.token()?,
        allow_origins: args.exposure.allow_origins.clone(),
        max_per_source: args.exposure.max_per_source,
        scene_name: scene,
        codec: args.scene.tuning.codec.clone(),
        hz: args.scene.hz,
        lockstep: args.lockstep,
        wait_clients: args.wait_clients,
        max_clients: args.max_clients,
        once: args.once,
        stop_on_ctrl_c: true,
        scene_glb,
        characters: Default::default(),
        tls: args.exposure.tls()?,
    };
    let serve = Serve::bind(server, config)?;
    stepper.report_to(serve.health());
    let serve = serve.with_stepper(Box::new(stepper));
    println!("listening on {}", serve.local_addr());
    let serve = serve.run();
    if let Some(json) = &args.json {
        let report = EdgeReport {
            serve,
            edge: counters.snapshot(),
        };
        write_json(json, &report)?;
    }
    Ok(())
}
