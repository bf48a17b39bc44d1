//! `psao bench scale`: trace nodes (`psao trace-node` child processes) over a
//! `nats-server -js` started here, and an edge in this process following a camera path in
//! lockstep (docs/SCALE-OUT.md). Reports each node's rays per second of step time against
//! the one-process server's, the bytes through NATS per server frame against the bytes one
//! viewer receives, the bytes a late edge reads to join against the whole history's, and
//! the time a dead node's partition takes to be adopted.

use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use psao_net::pipeline::CLIENT_HZ;
use psao_net::scale::edge::{EdgeConfig, EdgeStepper};
use psao_net::scale::trace_node::TraceNodeStats;
use psao_net::scale::NatsAuth;
use psao_net::serve::Stepper;
use psao_net::Resolution;
use psao_scene::CameraPath;
use psao_server::{Server, View};
use serde::Serialize;

use psao_eval::{spread, Spread};

use crate::paths_cmd::generated_paths;
use crate::run::{write_json, ServerTuning};
use crate::scene_source::SceneInput;

/// Arguments of `psao bench scale`.
#[derive(clap::Args, Debug)]
pub struct BenchScaleArgs {
    /// Scene: `default` (built in) or a .gltf/.glb/.obj/.toml file.
    #[arg(long, default_value = crate::scene_source::BUILTIN_SCENE)]
    pub scene: String,
    /// Camera path file (default: the scene's first path).
    #[arg(long)]
    pub path: Option<PathBuf>,
    /// Seeds of generated camera paths, comma separated (as `psao paths` makes them): each
    /// seed's path (as long as the run) is followed by every topology, and the report gives
    /// the spread over the seeds. Without, the run follows `--path`.
    #[arg(long, value_delimiter = ',', conflicts_with = "path")]
    pub path_seeds: Vec<u64>,
    /// Points per unit area.
    #[arg(long, default_value_t = 1024.0)]
    pub points: f32,
    /// Server frames per second of scene time.
    #[arg(long, default_value_t = 30)]
    pub hz: u32,
    /// Server frames per run.
    #[arg(long, default_value_t = 60)]
    pub frames: u64,
    /// The trace nodes publish a snapshot every this many frames.
    #[arg(long, default_value_t = 64)]
    pub snapshot_every: u64,
    /// Trace-node counts to run, comma separated.
    #[arg(long, default_value = "1,2,4", value_delimiter = ',')]
    pub nodes: Vec<u32>,
    #[command(flatten)]
    pub tuning: ServerTuning,
    /// The NATS server program.
    #[arg(long, default_value = "nats-server")]
    pub nats_server: PathBuf,
    /// Write the report as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// One run of `nodes` trace nodes.
#[derive(Debug, Serialize)]
pub struct ScaleRow {
    /// Trace nodes.
    pub nodes: u32,
    /// Rays per second of step time of each node, and their sum.
    pub rays_per_s: Vec<f64>,
    pub sum_rays_per_s: f64,
    /// The first node's rate over the one-process server's.
    pub node_over_serve: f64,
    /// Mean step ms of each node.
    pub step_ms: Vec<f64>,
    /// Bytes of record batches through NATS per server frame (all partitions), as
    /// published (compressed, in parts), and what they would have been uncompressed.
    pub nats_bytes_per_frame: f64,
    pub nats_raw_bytes_per_frame: f64,
    /// Record batch messages per server frame (all partitions: more than one per batch
    /// when one would not fit the NATS server's max_payload).
    pub nats_messages_per_frame: f64,
    /// Bytes one viewer receives per server frame (the update encoded with the codec).
    pub viewer_bytes_per_frame: f64,
    /// Bytes of snapshot chunks and marks the nodes published per server frame, and the
    /// chunks published (only those whose points changed since their previous message).
    pub snapshot_bytes_per_frame: f64,
    pub snapshot_chunks: u64,
    /// Bytes per server frame had every round published every chunk (full snapshots).
    pub full_snapshot_bytes_per_frame: f64,
    /// Of `snapshot_bytes_per_frame`: chunks published only because sample counts changed.
    pub samples_only_snapshot_bytes_per_frame: f64,
    /// Whether the edge's final grids hash like the one-process server's.
    pub same_state: bool,
    /// Bytes of every batch in the records stream at the end (the history).
    pub history_bytes: u64,
    /// Bytes a late edge read to join after the run (snapshots and the batches after
    /// them), the frame it started from, and whether it ended with the same grids.
    pub late_join_bytes: u64,
    pub late_join_frame: u64,
    pub late_same_state: bool,
}

/// What `psao bench scale` reports.
#[derive(Debug, Serialize)]
pub struct ScaleReport {
    /// Scene and settings.
    pub scene: String,
    pub frames: u64,
    pub ray_budget: u64,
    /// The one-process server's rays per second of step time.
    pub serve_rays_per_s: f64,
    /// Its final state hash.
    pub serve_state_hash: String,
    /// One row per trace-node count.
    pub runs: Vec<ScaleRow>,
    /// Two nodes, the second killed a third of the way: seconds from its last batch to the
    /// adoption of its partition by the first.
    pub takeover_s: Option<f64>,
}

/// One generated path's run of `psao bench scale --path-seeds`.
#[derive(Debug, Serialize)]
pub struct SeedScale {
    /// The path's seed and name.
    pub seed: u64,
    pub path: String,
    /// Its report.
    pub report: ScaleReport,
}

/// One trace-node count over the seeds.
#[derive(Debug, Serialize)]
pub struct NodesOverSeeds {
    /// Trace nodes.
    pub nodes: u32,
    /// Seeds whose edge (and late edge) ended with the one-process server's grids.
    pub same_state: usize,
    pub late_same_state: usize,
    /// The rows' figures over the seeds.
    pub nats_bytes_per_frame: Spread,
    pub nats_raw_bytes_per_frame: Spread,
    pub viewer_bytes_per_frame: Spread,
    pub node_over_serve: Spread,
    /// The nodes' summed rays per second over the one-process server's.
    pub sum_over_serve: Spread,
}

/// What `psao bench scale --path-seeds` reports.
#[derive(Debug, Serialize)]
pub struct SeedsScaleReport {
    /// Scene, frames per run, ray budget.
    pub scene: String,
    pub frames: u64,
    pub ray_budget: u64,
    /// Seeds run.
    pub seeds: usize,
    /// Per trace-node count, over the seeds.
    pub summary: Vec<NodesOverSeeds>,
    /// Adoption seconds over the seeds (those where the partition was adopted).
    pub takeover_s: Option<Spread>,
    /// Each seed's run.
    pub runs: Vec<SeedScale>,
}

/// A child process killed on drop.
pub(crate) struct Proc(Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A scratch folder for one nats-server's store, removed on drop.
pub(crate) struct Scratch(PathBuf);

impl Scratch {
    pub(crate) fn new(name: &str) -> Result<Self> {
        let dir =
            std::env::temp_dir().join(format!("psao-bench-scale-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create {}", dir.display()))?;
        Ok(Self(dir))
    }

    pub(crate) fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Runs `psao bench scale`.
pub fn run(args: &BenchScaleArgs) -> Result<()> {
    if args.frames == 0 || args.nodes.contains(&0) || args.hz == 0 || args.hz > CLIENT_HZ {
        bail!("--frames and every --nodes count must be at least 1, --hz in 1..={CLIENT_HZ}");
    }
    let input = SceneInput::load(&args.scene)?;
    if args.path_seeds.is_empty() {
        let path = input.camera_path(args.path.as_ref())?;
        let report = measure(args, &input, &path)?;
        return print_and_write(args, &report);
    }
    // Long enough that the run never wraps around (at least 4 s, so a walk turns).
    let duration_s = (args.frames as f32 / args.hz as f32).max(4.0);
    let mut runs = Vec::new();
    for &seed in &args.path_seeds {
        let [path] = <[CameraPath; 1]>::try_from(generated_paths(
            &input,
            args.tuning.backend,
            1,
            seed,
            duration_s,
        )?)
        .map_err(|_| anyhow::anyhow!("the generator made no path for seed {seed}"))?;
        tracing::info!("seed {seed}: path {}", path.name);
        let report = measure(args, &input, &path)?;
        runs.push(SeedScale {
            seed,
            path: path.name,
            report,
        });
    }
    print_and_write(args, &over_seeds(runs))
}

/// Prints `report` as JSON and writes it to `--json`.
fn print_and_write(args: &BenchScaleArgs, report: &impl Serialize) -> Result<()> {
    println!("{}", serde_json::to_string_pretty(report)?);
    if let Some(json) = &args.json {
        write_json(json, report)?;
    }
    Ok(())
}

/// The runs' summary per trace-node count.
fn over_seeds(runs: Vec<SeedScale>) -> SeedsScaleReport {
    let first = &runs[0].report;
    let over = |n: u32, value: &dyn Fn(&ScaleRow, &ScaleReport) -> f64| {
        let values: Vec<f64> = runs
            .iter()
            .filter_map(|r| {
                let row = r.report.runs.iter().find(|row| row.nodes == n)?;
                Some(value(row, &r.report))
            })
            .collect();
        spread(&values).expect("every seed runs every node count")
    };
    let count = |n: u32, test: &dyn Fn(&ScaleRow) -> bool| {
        runs.iter()
            .filter(|r| r.report.runs.iter().any(|row| row.nodes == n && test(row)))
            .count()
    };
    let summary = first
        .runs
        .iter()
        .map(|row| {
            let n = row.nodes;
            NodesOverSeeds {
                nodes: n,
                same_state: count(n, &|r| r.same_state),
                late_same_state: count(n, &|r| r.late_same_state),
                nats_bytes_per_frame: over(n, &|r, _| r.nats_bytes_per_frame),
                nats_raw_bytes_per_frame: over(n, &|r, _| r.nats_raw_bytes_per_frame),
                viewer_bytes_per_frame: over(n, &|r, _| r.viewer_bytes_per_frame),
                node_over_serve: over(n, &|r, _| r.node_over_serve),
                sum_over_serve: over(n, &|r, rep| {
                    r.sum_rays_per_s / rep.serve_rays_per_s.max(1e-9)
                }),
            }
        })
        .collect();
    let takeovers: Vec<f64> = runs.iter().filter_map(|r| r.report.takeover_s).collect();
    SeedsScaleReport {
        scene: first.scene.clone(),
        frames: first.frames,
        ray_budget: first.ray_budget,
        seeds: runs.len(),
        summary,
        takeover_s: spread(&takeovers),
        runs,
    }
}

/// Every topology of `args` on `path`, against the one-process server on the same path.
fn measure(args: &BenchScaleArgs, input: &SceneInput, path: &CameraPath) -> Result<ScaleReport> {
    let config = args.tuning.config(
        args.points,
        args.hz,
        Resolution {
            width: 1,
            height: 1,
        },
    )?;
    let make = || crate::serve::scene_server(input, &args.tuning, None, args.points, args.hz);
    let (serve_rays_per_s, serve_hash) = {
        let mut server = make()?;
        let (mut rays, mut ms) = (0u64, 0.0);
        for f in 1..=args.frames {
            let step = server.step_at(&[view_at(path, f, args.hz)], seconds(f, args.hz))?;
            rays += step.rays;
            ms += step.ms;
        }
        (rays as f64 / (ms / 1e3).max(1e-9), state_hash(&server))
    };
    tracing::info!("one process: {serve_rays_per_s:.0} rays/s");
    let mut runs = Vec::new();
    for &n in &args.nodes {
        let dir = Scratch::new(&format!("n{n}"))?;
        let (_nats, url) = start_nats(&args.nats_server, dir.path())?;
        let mut nodes: Vec<Proc> = (0..n)
            .map(|k| trace_node(args, &url, k, n, &dir.path().join(format!("t{k}.json"))))
            .collect::<Result<_>>()?;
        let mut replica = make()?;
        let (viewer_bytes, nats_bytes) =
            follow(args, &url, &input.name, path, n, &mut replica, None)?;
        let stats: Vec<TraceNodeStats> = (0..n)
            .map(|k| {
                wait_stats(
                    &mut nodes[k as usize],
                    &dir.path().join(format!("t{k}.json")),
                )
            })
            .collect::<Result<_>>()?;
        let rays_per_s: Vec<f64> = stats.iter().map(|s| s.rays_per_s).collect();
        let frames = args.frames as f64;
        let mut late = make()?;
        let (late_join_bytes, late_join_frame) = late_join(&url, &input.name, n, &mut late)?;
        let row = ScaleRow {
            nodes: n,
            sum_rays_per_s: rays_per_s.iter().sum(),
            node_over_serve: rays_per_s[0] / serve_rays_per_s.max(1e-9),
            rays_per_s,
            step_ms: stats.iter().map(|s| s.mean_step_ms).collect(),
            nats_bytes_per_frame: nats_bytes as f64 / frames,
            nats_raw_bytes_per_frame: stats.iter().map(|s| s.batch_raw_bytes).sum::<u64>() as f64
                / frames,
            nats_messages_per_frame: stats.iter().map(|s| s.batch_messages).sum::<u64>() as f64
                / frames,
            viewer_bytes_per_frame: viewer_bytes as f64 / frames,
            snapshot_bytes_per_frame: stats.iter().map(|s| s.snapshot_bytes).sum::<u64>() as f64
                / frames,
            snapshot_chunks: stats.iter().map(|s| s.snapshot_chunks).sum(),
            samples_only_snapshot_bytes_per_frame: stats
                .iter()
                .map(|s| s.snapshot_samples_only_bytes)
                .sum::<u64>() as f64
                / frames,
            full_snapshot_bytes_per_frame: stats.iter().map(|s| s.snapshot_full_bytes).sum::<u64>()
                as f64
                / frames,
            same_state: state_hash(&replica) == serve_hash,
            history_bytes: nats_bytes,
            late_join_bytes,
            late_join_frame,
            late_same_state: state_hash(&late) == state_hash(&replica),
        };
        tracing::info!("{n} nodes: {row:?}");
        runs.push(row);
    }
    let takeover_s = takeover(args, &input.name, path, make()?)?;
    Ok(ScaleReport {
        scene: input.name.clone(),
        frames: args.frames,
        ray_budget: config.server.ray_budget,
        serve_rays_per_s,
        serve_state_hash: serve_hash,
        runs,
        takeover_s,
    })
}

/// Two nodes; the second is killed a third of the way; the first's adoption time.
fn takeover(
    args: &BenchScaleArgs,
    scene: &str,
    path: &CameraPath,
    mut replica: Server,
) -> Result<Option<f64>> {
    let dir = Scratch::new("takeover")?;
    let (_nats, url) = start_nats(&args.nats_server, dir.path())?;
    let first = dir.path().join("t0.json");
    let mut survivor = trace_node(args, &url, 0, 2, &first)?;
    let victim = trace_node(args, &url, 1, 2, &dir.path().join("t1.json"))?;
    follow(
        args,
        &url,
        scene,
        path,
        2,
        &mut replica,
        Some((args.frames / 3, victim)),
    )?;
    let stats = wait_stats(&mut survivor, &first)?;
    Ok(stats.adopted.first().map(|a| a.after_s))
}

/// Follow the path for `args.frames` server frames as an edge in lockstep of a session of
/// `partitions` partitions; returns the bytes one viewer would receive and the bytes of
/// batches received. `kill`: at that frame, kill that node.
fn follow(
    args: &BenchScaleArgs,
    url: &str,
    scene: &str,
    path: &CameraPath,
    partitions: u32,
    replica: &mut Server,
    mut kill: Option<(u64, Proc)>,
) -> Result<(u64, u64)> {
    let config = EdgeConfig {
        nats: url.to_string(),
        auth: NatsAuth::default(),
        scene: scene.to_string(),
        edge_id: "bench".into(),
        partitions,
        lockstep: true,
        frame_timeout: Duration::from_secs(300),
    };
    let mut edge = EdgeStepper::connect(config, replica)?;
    let client = replica.add_client();
    let mut codec = psao_delta::codec_by_name(&args.tuning.codec)?;
    let mut viewer_bytes = 0u64;
    for f in 1..=args.frames {
        if kill.as_ref().is_some_and(|(at, _)| *at == f) {
            drop(kill.take());
        }
        edge.step(replica, &[view_at(path, f, args.hz)], seconds(f, args.hz))?;
        viewer_bytes += codec.encode(&replica.update_for(client)).len() as u64;
    }
    Ok((viewer_bytes, edge.counters().snapshot().batch_bytes))
}

/// A clocked edge joining a session of `partitions` partitions after the run: the bytes it
/// read to catch up (snapshots and batches) and the frame it started from.
fn late_join(url: &str, scene: &str, partitions: u32, replica: &mut Server) -> Result<(u64, u64)> {
    let config = EdgeConfig {
        nats: url.to_string(),
        auth: NatsAuth::default(),
        scene: scene.to_string(),
        edge_id: "late".into(),
        partitions,
        lockstep: false,
        frame_timeout: Duration::from_secs(30),
    };
    let mut edge = EdgeStepper::connect(config, replica)?;
    edge.catch_up(replica, Duration::from_secs(2))?;
    let c = edge.counters().snapshot();
    Ok((c.snapshot_bytes + c.batch_bytes, c.snapshot_frame))
}

fn seconds(frame: u64, hz: u32) -> f32 {
    frame as f32 / hz as f32
}

/// The path's view at server frame `frame`.
fn view_at(path: &CameraPath, frame: u64, hz: u32) -> View {
    let total = path.frame_count() as u64;
    let at = (frame * u64::from(CLIENT_HZ) / u64::from(hz)) % total;
    View {
        camera: path.camera_at_frame(at as usize),
        aspect: 16.0 / 9.0,
    }
}

fn state_hash(server: &Server) -> String {
    let h = psao_client::state_hash_of((0..server.instance_count()).map(|i| server.grid(i)));
    format!("{h:016x}")
}

/// A `nats-server -js` on a free loopback port storing into `dir`.
pub(crate) fn start_nats(program: &Path, dir: &Path) -> Result<(Proc, String)> {
    let port = TcpListener::bind("127.0.0.1:0")?.local_addr()?.port();
    let child = Command::new(program)
        .args(["-js", "-a", "127.0.0.1", "-p", &port.to_string(), "-sd"])
        .arg(dir.join("js"))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .with_context(|| {
            format!(
                "cannot start {} (apt-get install nats-server)",
                program.display()
            )
        })?;
    let proc = Proc(child);
    let end = Instant::now() + Duration::from_secs(10);
    while TcpStream::connect(("127.0.0.1", port)).is_err() {
        if Instant::now() > end {
            bail!("nats-server did not listen on port {port} within 10 s");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    Ok((proc, format!("nats://127.0.0.1:{port}")))
}

/// A `psao trace-node` child for partition `k/n`, lockstep with one edge.
fn trace_node(args: &BenchScaleArgs, url: &str, k: u32, n: u32, json: &Path) -> Result<Proc> {
    let exe = std::env::current_exe()?;
    let mut c = Command::new(exe);
    c.args([
        "--log",
        "warn",
        "trace-node",
        "--scene",
        &args.scene,
        "--nats",
        url,
    ]);
    c.args(["--partition", &format!("{k}/{n}"), "--lockstep-edges", "1"]);
    c.args([
        "--frames",
        &args.frames.to_string(),
        "--hz",
        &args.hz.to_string(),
    ]);
    c.args(["--points", &args.points.to_string()]);
    c.args(["--ray-budget", &args.tuning.ray_budget.to_string()]);
    c.args(["--rays-per-point", &args.tuning.rays_per_point.to_string()]);
    c.args(["--max-samples", &args.tuning.max_samples.to_string()]);
    c.args(["--seed", &args.tuning.seed.to_string()]);
    c.args(["--snapshot-every", &args.snapshot_every.to_string()]);
    if let Some(b) = &args.tuning.backend {
        c.args(["--backend", &format!("{b:?}").to_lowercase()]);
    }
    c.arg("--json").arg(json);
    c.stdout(Stdio::null()).stderr(Stdio::inherit());
    Ok(Proc(c.spawn().context("cannot start psao trace-node")?))
}

/// Wait for a node to exit and read its statistics.
fn wait_stats(node: &mut Proc, json: &Path) -> Result<TraceNodeStats> {
    let status = node.0.wait()?;
    if !status.success() {
        bail!("psao trace-node exited with {status}");
    }
    let text =
        std::fs::read_to_string(json).with_context(|| format!("cannot read {}", json.display()))?;
    Ok(serde_json::from_str(&text)?)
}
