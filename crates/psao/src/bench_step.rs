//! `psao bench step`: the server alone, in this process. N clients' cameras follow a path
//! (client k starts k/N of the way along it), server frames run back to back, and each
//! frame's updates are encoded for the clients during the next step's publishing phase
//! ([`psao_server::Server::step_beside`]), as `psao serve` does.
//! Reports wall ms per frame with the step's phases, and the process's CPU ms per frame.
//! Without a network or client processes beside it, this is a quieter measure of the
//! server's part of `psao bench serve`. It also itemises the process's whole resident size
//! ([`crate::memory_account`]): server structures, scene, tracer, the clients' codec
//! references, the first client's mirror, other heap, executable, allocator slack.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use psao_delta::{Codec, Update};
use psao_server::{ClientId, View};
use rayon::prelude::*;
use serde::Serialize;

use crate::args::Resolution;
use crate::bench_serve::LoadArgs;
use crate::memory_account::{itemise, scene_heap_bytes, Item};
use crate::run::{write_json, ServerTuning};
use crate::scene_source::SceneInput;
use psao_net::cpu_time::cpu_seconds;
use psao_net::pipeline::CLIENT_HZ;
use psao_net::process_memory::{
    malloc_stats, map_large_blocks_apart, release_free_memory, resident, SlackTrimmer,
};
use psao_net::serve::{code, coding_plan, mean, percentile};

/// Rays in the set `bench trace`'s reference rate is measured on.
const TRACE_RATE_RAYS: usize = 1_000_000;

/// Arguments of `psao bench step`.
#[derive(clap::Args, Debug)]
pub struct BenchStepArgs {
    // Clients, scene, path, server rate (which sets each frame's scene time and the
    // clients' cameras; frames still run back to back) and point density.
    #[command(flatten)]
    pub load: LoadArgs,
    /// Server frames to run.
    #[arg(long, default_value_t = 300)]
    pub frames: u32,
    /// Clients' image size (their aspect shapes the culling frusta).
    #[arg(long, default_value = "640x360")]
    pub res: Resolution,
    #[command(flatten)]
    pub tuning: ServerTuning,
    /// Write the report as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// What `psao bench step` measured (ms are means per server frame).
#[derive(Debug, Default, Serialize)]
pub struct BenchStepReport {
    /// The `--scene` argument.
    pub scene: String,
    /// Clients (views and codecs).
    pub clients: u32,
    /// Server frames run.
    pub frames: u32,
    /// Rays per server frame at most.
    pub ray_budget: u64,
    /// Rays traced per server frame.
    pub rays_per_frame: f64,
    /// Wall time per frame: step, update collection and the previous frame's encoding beside
    /// the step.
    pub frame_ms: f64,
    /// Median of it.
    pub frame_median_ms: f64,
    /// 95th percentile of it.
    pub frame_p95_ms: f64,
    /// The step alone.
    pub step_ms: f64,
    /// The step's posing and invalidation.
    pub animate_ms: f64,
    /// The step's culling.
    pub cull_ms: f64,
    /// The step's selection, tracing and accumulation.
    pub trace_ms: f64,
    /// The step's publishing.
    pub publish_ms: f64,
    /// Collecting the clients' updates after the step.
    pub update_ms: f64,
    /// Encoding all clients' updates (beside the next step's publishing).
    pub encode_ms: f64,
    /// This process's CPU time per frame (all threads).
    pub cpu_ms: f64,
    /// `cpu_ms / frame_ms`: cores kept busy on average.
    pub cores_busy: f64,
    /// Payload Mbit per second of scene time, averaged over the clients.
    pub mbit_s: f64,
    /// Seconds from the loaded scene to a server ready to step (point generation and burial
    /// test, or reading the stored start points; grids; tracer).
    pub startup_s: f64,
    /// Points the server stores.
    pub points: usize,
    /// The process's resident memory after the last frame, per stored point (everything:
    /// server structures, tracer, scene, the clients' codec references, allocator slack).
    pub bytes_per_point: f64,
    /// The process's peak resident memory per stored point.
    pub peak_bytes_per_point: f64,
    /// Resident bytes per stored point once the server is started.
    pub started_bytes_per_point: f64,
    /// The same once the free memory start-up left behind is given back
    /// ([`release_free_memory`], as `psao serve` does).
    pub started_released_bytes_per_point: f64,
    /// The resident memory after the last frame item by item, adding up to
    /// `bytes_per_point` ([`crate::memory_account::itemise`]).
    pub resident: Vec<MemoryRow>,
    /// Free bytes the C allocator holds after the last frame, per stored point (resident or
    /// not; part of the slack row when resident).
    pub malloc_free_bytes_per_point: f64,
    /// Heap bytes per stored point of each server structure after the last frame.
    pub memory: Vec<MemoryRow>,
    /// Points in the first client's mirror after the last frame (what its views reached).
    pub client_points: usize,
    /// Heap bytes of the first client's mirror (`psao-client`'s grids, fed the same updates
    /// its codec encodes) per point it holds.
    pub client_bytes_per_point: f64,
    /// The first client's mirror by part, in heap bytes per point it holds
    /// (`psao_points::GridMemory`).
    pub client_memory: Vec<MemoryRow>,
    /// Rays per second of the step's tracing phase (selection, tracing, accumulation), Mrays/s.
    pub step_trace_mrays_s: f64,
    /// `psao bench trace`'s sorted closest-hit rate on this scene and backend, measured in this
    /// run on the same threads, Mrays/s.
    pub bench_trace_mrays_s: f64,
    /// `step_trace_mrays_s / bench_trace_mrays_s`.
    pub trace_ratio: f64,
}

/// One structure's memory in the report.
#[derive(Debug, Default, Serialize)]
pub struct MemoryRow {
    /// What it holds.
    pub name: String,
    /// Heap bytes.
    pub bytes: u64,
    /// Heap bytes per stored point.
    pub bytes_per_point: f64,
}

/// Run `psao bench step`.
pub fn run(args: &BenchStepArgs) -> Result<()> {
    if args.load.clients == 0 || args.frames == 0 || args.load.hz == 0 || args.load.hz > CLIENT_HZ {
        bail!(
            "--clients and --frames must be at least 1 and --hz in 1..={CLIENT_HZ} (got {}, {}, {})",
            args.load.clients,
            args.frames,
            args.load.hz
        );
    }
    map_large_blocks_apart();
    let input = SceneInput::load(&args.load.scene)?;
    let path = input.camera_path(args.load.path.as_ref())?;
    let config = args
        .tuning
        .config(args.load.points, args.load.hz, args.res)?;
    let started = Instant::now();
    let backend = config.server.backend;
    let mut server = psao_net::start_cache::start_server(
        &input.scene,
        config.server,
        input.medium(),
        config.points_cache.as_deref(),
    )
    .context("cannot start the server (point generation or tracer)")?;
    let startup_s = started.elapsed().as_secs_f64();
    let started_rss = resident().map_or(0, |r| r.bytes);
    release_free_memory();
    let released_rss = resident().map_or(0, |r| r.bytes);
    let ids: Vec<ClientId> = (0..args.load.clients)
        .map(|_| server.add_client())
        .collect();
    let mut mirror = psao_client::ClientState::new(&server.instance_table());
    let mut codecs = ids
        .iter()
        .map(|_| psao_delta::codec_by_name(&args.tuning.codec))
        .collect::<Result<Vec<_>, _>>()?;
    let total = path.frame_count() as u64;
    let aspect = args.res.width as f32 / args.res.height as f32;
    let bar = crate::progress::bar(u64::from(args.frames), "server frames", "frames");
    let (mut frame_ms, mut sums) = (Vec::new(), BenchStepReport::default());
    let (mut rays, mut bytes) = (0u64, 0u64);
    let mut pending: Option<Vec<(Vec<ClientId>, Update)>> = None;
    let cpu_start = cpu_seconds();
    let mut trimmer = SlackTrimmer::default();
    for f in 0..u64::from(args.frames) {
        let t = Instant::now();
        let client_frame = f * u64::from(CLIENT_HZ) / u64::from(args.load.hz);
        let mut views: Vec<View> = Vec::new();
        for k in 0..u64::from(args.load.clients) {
            let at = (client_frame + k * total / u64::from(args.load.clients)) % total;
            let view = View {
                camera: path.camera_at_frame(at as usize),
                aspect,
            };
            if !views.contains(&view) {
                views.push(view);
            }
        }
        let seconds = (server.frame() + 1) as f32 / args.load.hz as f32;
        let previous = pending.take();
        let (step, encoded) = server.step_beside(&views, seconds, || {
            previous.map(|groups| encode(&mut codecs, &ids, &groups))
        });
        let step = step.context("server frame failed")?;
        if let Some((n, ms)) = encoded {
            bytes += n;
            sums.encode_ms += ms;
        }
        rays += step.rays;
        sums.step_ms += step.ms;
        sums.animate_ms += step.animate_ms;
        sums.cull_ms += step.cull_ms;
        sums.trace_ms += step.trace_ms;
        sums.publish_ms += step.publish_ms;
        let tu = Instant::now();
        let updates = server.updates_for(&ids);
        if let Some((_, update)) = updates.iter().find(|(group, _)| group.contains(&ids[0])) {
            mirror
                .apply(update)
                .context("the first client's mirror refused an update")?;
        }
        pending = Some(updates);
        sums.update_ms += tu.elapsed().as_secs_f64() * 1e3;
        // As `psao serve` does after each frame.
        trimmer.after_frame();
        frame_ms.push(t.elapsed().as_secs_f64() * 1e3);
        bar.inc(1);
    }
    bar.finish_and_clear();
    let n = f64::from(args.frames);
    let frame_mean = mean(&frame_ms);
    let cpu_ms = match (cpu_start, cpu_seconds()) {
        (Some(a), Some(b)) => (b - a) * 1e3 / n,
        _ => 0.0,
    };
    let process = resident().unwrap_or_default();
    let malloc = malloc_stats();
    let points = server.point_count();
    let per_point = |bytes: u64| bytes as f64 / points.max(1) as f64;
    let row = |name: String, bytes: u64| MemoryRow {
        name,
        bytes,
        bytes_per_point: per_point(bytes),
    };
    let server_parts = server.memory_use();
    let memory = server_parts
        .iter()
        .map(|p| row(p.name.to_string(), p.bytes))
        .collect();
    let mut heap: Vec<Item> = server_parts
        .iter()
        .map(|p| Item {
            name: format!("server: {}", p.name),
            bytes: p.bytes,
        })
        .collect();
    heap.extend([
        Item {
            name: "scene (meshes, textures, animation)".into(),
            bytes: scene_heap_bytes(&input.scene),
        },
        Item {
            name: format!("codec references ({} clients)", ids.len()),
            bytes: codecs.iter().map(|c| c.heap_bytes()).sum(),
        },
        Item {
            name: "first client's mirror".into(),
            bytes: mirror.heap_bytes(),
        },
    ]);
    let tracer = server
        .tracer()
        .structure_bytes()
        .map(|bytes| (bytes, tracer_buffer_bytes(&input.scene)));
    let resident_items = itemise(process, malloc, heap, tracer)
        .into_iter()
        .map(|i| row(i.name, i.bytes))
        .collect();
    let step_trace_mrays_s = rays as f64 / (sums.trace_ms * 1e-3).max(1e-9) / 1e6;
    let bench_trace_mrays_s =
        crate::bench_trace::sorted_closest_rate(&input, &path, backend, TRACE_RATE_RAYS)?;
    let report = BenchStepReport {
        scene: args.load.scene.clone(),
        clients: args.load.clients,
        frames: args.frames,
        ray_budget: args.tuning.ray_budget,
        rays_per_frame: rays as f64 / n,
        frame_ms: frame_mean,
        frame_median_ms: percentile(&frame_ms, 0.5),
        frame_p95_ms: percentile(&frame_ms, 0.95),
        step_ms: sums.step_ms / n,
        animate_ms: sums.animate_ms / n,
        cull_ms: sums.cull_ms / n,
        trace_ms: sums.trace_ms / n,
        publish_ms: sums.publish_ms / n,
        update_ms: sums.update_ms / n,
        encode_ms: sums.encode_ms / n,
        cpu_ms,
        cores_busy: cpu_ms / frame_mean,
        // Encoded frames: all but the last, each 1/hz s of scene time.
        mbit_s: bytes as f64 * 8e-6 * f64::from(args.load.hz)
            / ((n - 1.0).max(1.0) * f64::from(args.load.clients)),
        startup_s,
        points,
        bytes_per_point: per_point(process.bytes),
        peak_bytes_per_point: per_point(process.peak),
        started_bytes_per_point: per_point(started_rss),
        started_released_bytes_per_point: per_point(released_rss),
        resident: resident_items,
        malloc_free_bytes_per_point: malloc.map_or(0.0, |m| per_point(m.free)),
        memory,
        client_points: mirror.point_count(),
        client_bytes_per_point: mirror.heap_bytes() as f64 / mirror.point_count().max(1) as f64,
        client_memory: mirror
            .memory_parts()
            .named()
            .into_iter()
            .map(|(name, bytes)| MemoryRow {
                name: name.to_string(),
                bytes,
                bytes_per_point: bytes as f64 / mirror.point_count().max(1) as f64,
            })
            .collect(),
        step_trace_mrays_s,
        bench_trace_mrays_s,
        trace_ratio: step_trace_mrays_s / bench_trace_mrays_s,
    };
    println!(
        "{} clients on {}: {} server frames, {:.0} rays per frame; {:.1} ms per frame \
         (median {:.1}, p95 {:.1}): step {:.1} (animate {:.1}, cull {:.1}, trace {:.1}, \
         publish {:.1}), updates {:.1}, encoding beside publishing {:.1}; CPU {:.1} ms per \
         frame = {:.2} cores busy; {:.2} Mbit/s per client",
        report.clients,
        report.scene,
        report.frames,
        report.rays_per_frame,
        report.frame_ms,
        report.frame_median_ms,
        report.frame_p95_ms,
        report.step_ms,
        report.animate_ms,
        report.cull_ms,
        report.trace_ms,
        report.publish_ms,
        report.update_ms,
        report.encode_ms,
        report.cpu_ms,
        report.cores_busy,
        report.mbit_s
    );
    println!(
        "start-up {:.1} s; {} points, {:.0} bytes per point resident (peak {:.0}); tracing \
         in the step {:.2} Mrays/s = {:.2} of bench trace's sorted closest-hit {:.2}",
        report.startup_s,
        report.points,
        report.bytes_per_point,
        report.peak_bytes_per_point,
        report.step_trace_mrays_s,
        report.trace_ratio,
        report.bench_trace_mrays_s
    );
    println!(
        "resident after start-up {:.1} bytes per point, {:.1} once its free memory was given \
         back; after the last frame, item by item:",
        report.started_bytes_per_point, report.started_released_bytes_per_point
    );
    for m in &report.resident {
        println!(
            "  {:<62} {:>8.1} bytes per point",
            m.name, m.bytes_per_point
        );
    }
    println!(
        "first client's mirror: {} points, {:.1} bytes per point",
        report.client_points, report.client_bytes_per_point
    );
    for m in &report.client_memory {
        println!(
            "  {:<32} {:>8.2} bytes per point",
            m.name, m.bytes_per_point
        );
    }
    if let Some(json) = &args.json {
        write_json(json, &report)?;
    }
    Ok(())
}

/// Bytes of the vertex and index buffers Embree copies the AO geometry into (allocated
/// through malloc, unlike its BVH nodes): 12 per vertex and per triangle of the meshes AO rays
/// hit.
fn tracer_buffer_bytes(scene: &psao_scene::Scene) -> u64 {
    scene
        .meshes
        .iter()
        .filter(|m| {
            !scene
                .materials
                .get(m.material)
                .is_some_and(|mat| mat.skipped_by_rays())
        })
        .map(|m| 12 * (m.positions.len() + m.indices.len()) as u64)
        .sum()
}

/// Encode each group's update with one client's codec and advance the others' (as
/// `psao serve` does: [`coding_plan`]), in parallel over the clients `ids` (whose codecs
/// `codecs` are); returns the payload bytes of all clients and the ms taken.
fn encode(
    codecs: &mut [Box<dyn Codec>],
    ids: &[ClientId],
    groups: &[(Vec<ClientId>, Update)],
) -> (u64, f64) {
    let t = Instant::now();
    let plan = coding_plan(ids.iter().copied(), groups);
    let sizes: Vec<u64> = codecs
        .par_iter_mut()
        .zip(&plan)
        .filter_map(|(codec, job)| {
            let (g, encodes) = (*job)?;
            let payload = code(codec.as_mut(), &groups[g].1, encodes);
            Some(payload.map_or(0, |p| p.len() as u64 * groups[g].0.len() as u64))
        })
        .collect();
    (sizes.iter().sum(), t.elapsed().as_secs_f64() * 1e3)
}
