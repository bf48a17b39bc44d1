//! `psao bench serve`: one `psao serve` (or, with `--edge-nats`, one `psao edge`) and N
//! headless viewers on loopback for a fixed number of client frames — N `psao view`
//! processes, or with `--one-client-process` one `psao view --viewers N` process that loads
//! the scene once — and reports per-client Mbit/s, server ms per frame and the updates
//! coalesced because a client had no room.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

use anyhow::{bail, Context, Result};
use serde::Serialize;

use crate::run::write_json;

/// Default ray budget per server frame of the load benchmark (see `--ray-budget`).
const BENCH_RAY_BUDGET: u64 = 48_000;

/// What the load benchmarks (`psao bench serve`, `psao bench step`) serve: N clients on a
/// scene's camera path.
#[derive(clap::Args, Debug)]
pub struct LoadArgs {
    /// Number of clients.
    #[arg(long, default_value_t = 8)]
    pub clients: u32,
    /// Scene: `default` (built in) or a .gltf/.glb/.obj/.toml file.
    #[arg(long, default_value = crate::scene_source::BUILTIN_SCENE)]
    pub scene: String,
    /// Camera path file (default: the scene's first path); client k starts k/N of the way
    /// along it.
    #[arg(long)]
    pub path: Option<PathBuf>,
    /// Server frames per second of scene time.
    #[arg(long, default_value_t = 30)]
    pub hz: u32,
    /// Points per unit area.
    #[arg(long, default_value_t = 1024.0)]
    pub points: f32,
}

/// Arguments of `psao bench serve`.
#[derive(clap::Args, Debug)]
pub struct BenchServeArgs {
    #[command(flatten)]
    pub load: LoadArgs,
    /// Client frames per client (60 per second of scene time).
    #[arg(long, default_value_t = 300)]
    pub frames: u32,
    /// Update codec.
    #[arg(long, default_value = "compact")]
    pub codec: String,
    /// Rays per server frame at most. The default leaves the 30 Hz frame room on 2 cores:
    /// at ~13 M closest-hit AO rays/s on 2 threads (Embree, Sponza, docs/BENCHMARKS.md)
    /// 48 000 rays (3000 points × 16 rays) take ~4 ms of the 33 ms frame, because culling
    /// the visible points, publishing, encoding one update per client and (here) the
    /// clients themselves need the rest; measured on Sponza with 8 clients, 144 000 rays
    /// already need more than 2 cores (docs/BENCHMARKS.md).
    #[arg(long, default_value_t = BENCH_RAY_BUDGET)]
    pub ray_budget: u64,
    /// Clients' image size (their aspect shapes the culling frusta).
    #[arg(long, default_value = "640x360")]
    pub res: String,
    /// Clients check their state against the server's hash after every update (costs a hash
    /// of the whole state per update on both ends).
    #[arg(long)]
    pub verify: bool,
    /// Run the clients at this `nice` level (1–19, lower priority than the server), so
    /// the server gets the two cores first, as it would with the clients on other machines.
    /// Needs the `nice` program.
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..=19))]
    pub client_nice: Option<u8>,
    /// Run the clients under the `SCHED_IDLE` policy (`chrt --idle 0`): they run only when
    /// the server leaves a core idle, and a waking server thread takes the core from them
    /// at once (under `nice` it may wait for a client's time slice to end). Closest to
    /// clients on other machines; the clients fall behind sooner. Needs the `chrt` program.
    #[arg(long, conflicts_with = "client_nice")]
    pub client_idle: bool,
    /// Measure a `psao edge` reading this NATS server instead of a `psao serve` (start
    /// `nats-server -js` and `psao trace-node --nats URL` with the same scene and settings
    /// first; docs/SCALE-OUT.md).
    #[arg(long)]
    pub edge_nats: Option<String>,
    /// Run the N viewers as threads of one `psao view --viewers N` process (one scene load,
    /// decode and apply only) instead of N processes that each load the scene: many viewers
    /// of a large scene then fit beside the server on one machine. Per-client `cores` is
    /// that process's share divided by N.
    #[arg(long)]
    pub one_client_process: bool,
    /// Write the report as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// One client's numbers.
#[derive(Debug, Serialize)]
pub struct BenchClient {
    /// Received Mbit per second of scene time.
    pub mbit_s: f64,
    /// Updates applied.
    pub updates: u64,
    /// Server frames coalesced into a later update for this client.
    pub coalesced: u64,
    /// Final state equal to the server's at the client's last update (only with `--verify`).
    pub exact: Option<bool>,
    /// The client process's CPU time over its wall time: cores it kept busy on average.
    pub cores: f64,
}

/// What `psao bench serve` reports.
#[derive(Debug, Serialize)]
pub struct BenchServeReport {
    /// Scene.
    pub scene: String,
    /// Clients.
    pub clients: u32,
    /// Server rate.
    pub hz: u32,
    /// Client frames each.
    pub frames: u32,
    /// Ray budget per server frame.
    pub ray_budget: u64,
    /// Mean rays traced per server frame.
    pub rays_per_frame: f64,
    /// Server frames stepped.
    pub server_frames: u64,
    /// Mean server ms per frame (step + per-client deltas + encode).
    pub server_mean_ms: f64,
    /// 95th percentile of it.
    pub server_p95_ms: f64,
    /// Median of it (robust to the start: the snapshots and the frames before the clients'
    /// cameras arrived).
    pub server_median_ms: f64,
    /// Mean server ms per frame over the frame period (1000 / hz): below 1 keeps up.
    pub server_load: f64,
    /// Server process CPU ms (all threads) per frame.
    pub server_cpu_ms: f64,
    /// That over the CPU time of 2 cores in one frame period: the server's share of a
    /// 2-core machine, independent of other load.
    pub server_cpu_share_2_cores: f64,
    /// Mean of the step alone.
    pub server_step_ms: f64,
    /// Mean of the step's culling.
    pub server_cull_ms: f64,
    /// Mean of the step's selection, tracing and accumulation.
    pub server_trace_ms: f64,
    /// Mean of the step's publishing.
    pub server_publish_ms: f64,
    /// Mean of collecting the clients' updates per frame (all clients).
    pub server_update_ms: f64,
    /// Mean of encoding them per frame (all clients).
    pub server_encode_ms: f64,
    /// Server frames started late (the previous one overran the period).
    pub late_frames: u64,
    /// Per client.
    pub per_client: Vec<BenchClient>,
}

struct Guard(Child);

impl Drop for Guard {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn read_json(path: &Path) -> Result<serde_json::Value> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    Ok(serde_json::from_str(&text)?)
}

/// Runs `psao bench serve`.
pub fn run(args: &BenchServeArgs) -> Result<()> {
    if args.load.clients == 0 || args.frames == 0 {
        bail!("--clients and --frames must be at least 1");
    }
    let exe = std::env::current_exe().context("cannot find the psao executable")?;
    let dir = tempfile_dir()?;
    let serve_json = dir.join("serve.json");
    let mut serve = Command::new(&exe);
    match &args.edge_nats {
        Some(url) => serve.args(["--log", "warn", "edge", "--nats", url]),
        None => serve.args(["--log", "warn", "serve"]),
    };
    serve
        .args(["--scene", &args.load.scene, "--listen", "127.0.0.1:0"])
        .args([
            "--hz",
            &args.load.hz.to_string(),
            "--points",
            &args.load.points.to_string(),
        ])
        .args(["--codec", &args.codec, "--once"])
        .args(["--wait-clients", &args.load.clients.to_string()])
        .arg("--json")
        .arg(&serve_json)
        .stdout(Stdio::piped());
    serve.args(["--ray-budget", &args.ray_budget.to_string()]);
    let mut server = Guard(serve.spawn().context("cannot start the server")?);
    let mut line = String::new();
    let stdout = server.0.stdout.take().context("no server stdout")?;
    BufReader::new(stdout).read_line(&mut line)?;
    let addr = line
        .trim()
        .strip_prefix("listening on ")
        .with_context(|| format!("psao serve did not start: {line:?}"))?
        .to_string();
    tracing::info!("server at {addr}; starting {} clients", args.load.clients);
    let (input, path) = crate::scene_source::SceneArgs {
        scene: args.load.scene.clone(),
        path: args.load.path.clone(),
        frozen: false,
    }
    .load()?;
    drop(input);
    let total = path.frame_count() as u32;
    let mut views = Vec::new();
    let processes = if args.one_client_process {
        1
    } else {
        args.load.clients
    };
    for k in 0..processes {
        let (mut c, through) = match (args.client_nice, args.client_idle) {
            (Some(n), _) => {
                let mut c = Command::new("nice");
                c.arg(format!("-n{n}")).arg(&exe);
                (c, " through `nice`")
            }
            (None, true) => {
                let mut c = Command::new("chrt");
                c.args(["--idle", "0"]).arg(&exe);
                (c, " through `chrt`")
            }
            (None, false) => (Command::new(&exe), ""),
        };
        c.args([
            "--log",
            "warn",
            "view",
            "--connect",
            &addr,
            "--scene",
            &args.load.scene,
        ])
        .args(["--frames", &args.frames.to_string(), "--res", &args.res])
        .args([
            "--path-offset",
            &(k * total / args.load.clients).to_string(),
        ])
        .arg("--json")
        .arg(dir.join(format!("view_{k}.json")))
        .stdout(Stdio::null());
        if args.one_client_process {
            c.args(["--viewers", &args.load.clients.to_string()]);
        }
        if !args.verify {
            c.arg("--no-verify");
        }
        if let Some(p) = &args.load.path {
            c.arg("--path").arg(p);
        }
        views
            .push(Guard(c.spawn().with_context(|| {
                format!("cannot start psao view{through}")
            })?));
    }
    for (k, v) in views.iter_mut().enumerate() {
        let status = v.0.wait()?;
        if !status.success() {
            bail!("client {k} failed ({status})");
        }
    }
    let status = server.0.wait()?;
    if !status.success() {
        bail!("the server failed ({status})");
    }
    let s = read_json(&serve_json)?;
    let server_clients = s["clients"].as_array().cloned().unwrap_or_default();
    let coalesced_of = |id: &serde_json::Value| {
        server_clients
            .iter()
            .filter(|c| c["id"] == *id)
            .filter_map(|c| c["coalesced"].as_u64())
            .sum::<u64>()
    };
    let summaries: Vec<serde_json::Value> = if args.one_client_process {
        match read_json(&dir.join("view_0.json"))? {
            serde_json::Value::Array(list) => list,
            other => bail!("psao view --viewers wrote no list: {other}"),
        }
    } else {
        (0..processes)
            .map(|k| read_json(&dir.join(format!("view_{k}.json"))))
            .collect::<Result<_>>()?
    };
    if summaries.len() != args.load.clients as usize {
        bail!(
            "{} viewer summaries for {} clients",
            summaries.len(),
            args.load.clients
        );
    }
    // Viewers sharing one process share its CPU time.
    let sharing = if args.one_client_process {
        f64::from(args.load.clients)
    } else {
        1.0
    };
    let mut per_client = Vec::new();
    for v in &summaries {
        per_client.push(BenchClient {
            mbit_s: v["mbit_s"].as_f64().unwrap_or(0.0),
            updates: v["updates"].as_u64().unwrap_or(0),
            coalesced: v["client_ids"]
                .as_array()
                .map_or(0, |ids| ids.iter().map(coalesced_of).sum()),
            exact: args
                .verify
                .then(|| v["state_hash"] == v["server_state_hash"]),
            cores: v["cpu_seconds"].as_f64().unwrap_or(0.0)
                / v["seconds"].as_f64().unwrap_or(0.0).max(1e-9)
                / sharing,
        });
    }
    let report = BenchServeReport {
        scene: args.load.scene.clone(),
        clients: args.load.clients,
        hz: args.load.hz,
        frames: args.frames,
        ray_budget: args.ray_budget,
        rays_per_frame: s["mean_rays"].as_f64().unwrap_or(0.0),
        server_frames: s["frames"].as_u64().unwrap_or(0),
        server_mean_ms: s["mean_ms"].as_f64().unwrap_or(0.0),
        server_p95_ms: s["p95_ms"].as_f64().unwrap_or(0.0),
        server_median_ms: s["median_ms"].as_f64().unwrap_or(0.0),
        server_load: s["mean_ms"].as_f64().unwrap_or(0.0) * f64::from(args.load.hz) / 1000.0,
        server_cpu_ms: s["cpu_ms"].as_f64().unwrap_or(0.0),
        server_cpu_share_2_cores: s["cpu_ms"].as_f64().unwrap_or(0.0) * f64::from(args.load.hz)
            / 2000.0,
        server_step_ms: s["mean_step_ms"].as_f64().unwrap_or(0.0),
        server_cull_ms: s["mean_cull_ms"].as_f64().unwrap_or(0.0),
        server_trace_ms: s["mean_trace_ms"].as_f64().unwrap_or(0.0),
        server_publish_ms: s["mean_publish_ms"].as_f64().unwrap_or(0.0),
        server_update_ms: s["mean_update_ms"].as_f64().unwrap_or(0.0),
        server_encode_ms: s["mean_encode_ms"].as_f64().unwrap_or(0.0),
        late_frames: s["late_frames"].as_u64().unwrap_or(0),
        per_client,
    };
    println!(
        "{} clients at {} Hz on {}: {} server frames, {:.0} rays per frame (budget {}), \
         {:.1} ms mean ({:.2} of the {:.1} ms period) / {:.1} ms median / {:.1} ms p95 per frame \
         ({:.1} ms step: cull {:.1}, trace {:.1}, publish {:.1}; {:.1} ms updates, {:.1} ms \
         encoding beside the next step), {} late; \
         server CPU {:.1} ms per frame = {:.2} of 2 cores",
        report.clients,
        report.hz,
        report.scene,
        report.server_frames,
        report.rays_per_frame,
        report.ray_budget,
        report.server_mean_ms,
        report.server_load,
        1000.0 / f64::from(report.hz),
        report.server_median_ms,
        report.server_p95_ms,
        report.server_step_ms,
        report.server_cull_ms,
        report.server_trace_ms,
        report.server_publish_ms,
        report.server_update_ms,
        report.server_encode_ms,
        report.late_frames,
        report.server_cpu_ms,
        report.server_cpu_share_2_cores
    );
    println!(
        "clients: {:.2} cores busy in all",
        report.per_client.iter().map(|c| c.cores).sum::<f64>()
    );
    println!("client  Mbit/s  updates  coalesced  cores  exact");
    for (k, c) in report.per_client.iter().enumerate() {
        println!(
            "{k:>6}  {:>6.2}  {:>7}  {:>9}  {:>5.2}  {}",
            c.mbit_s,
            c.updates,
            c.coalesced,
            c.cores,
            c.exact.map_or("-".to_string(), |e| e.to_string())
        );
    }
    if let Some(json) = &args.json {
        write_json(json, &report)?;
    }
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}

/// A fresh scratch folder for the children's JSON files.
fn tempfile_dir() -> Result<PathBuf> {
    let dir = std::env::temp_dir().join(format!("psao-bench-serve-{}", std::process::id()));
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    Ok(dir)
}
