//! `psao bench trace`: ray-tracing throughput of every compiled backend on one AO ray set;
//! with `--dynamic`, the cost of animating the scene's structure ([`dynamic`]).

mod dynamic;

use crate::args::Resolution;
use crate::scene_source::{SceneArgs, SceneInput};
use anyhow::{bail, Context, Result};
use clap::Args;
use psao_raster::{rasterize, RasterOptions};
use psao_trace::{ao, sort_rays_spatially, Backend, GeometryMode, Ray, Tracer};
use rayon::prelude::*;
use serde::Serialize;
use std::time::Instant;

/// Rays handed to one backend call; large enough to amortise the call, small enough to balance threads.
const RAYS_PER_CALL: usize = 4096;
/// Camera-path frames whose visible surfaces seed the ray origins.
const SEED_FRAMES: usize = 4;
/// Largest accepted ray count.
const MAX_RAYS: usize = 200_000_000;

/// Arguments of `psao bench trace`.
#[derive(Args, Debug)]
pub struct BenchTraceArgs {
    #[command(flatten)]
    pub input: SceneArgs,
    /// Number of AO rays in the set.
    #[arg(long, default_value_t = 4_000_000)]
    pub rays: usize,
    /// Resolution of the views that pick ray origins.
    #[arg(long, default_value = "320x180")]
    pub res: Resolution,
    /// Timed repetitions per case (the best is reported).
    #[arg(long, default_value_t = 3)]
    pub repeat: u32,
    /// Print JSON (a list of `{backend, sorted, threads, query, mrays_per_s}`, or with
    /// `--dynamic` one record per backend).
    #[arg(long)]
    pub json: bool,
    /// Measure dynamic updates instead: per-frame top-level updates of the moving instances,
    /// refit and rebuild times of skinned meshes, AO throughput after refits vs rebuilds.
    #[arg(long)]
    pub dynamic: bool,
    /// Server frames (1/15 s apart) animated by `--dynamic`.
    #[arg(long, default_value_t = 30)]
    pub frames: usize,
    /// `--dynamic`: rebuild a skinned mesh once refits raised its SAH cost by this factor.
    #[arg(long, default_value_t = psao_trace::DEFAULT_MAX_COST_RATIO)]
    pub max_cost_ratio: f32,
}

/// One measured case.
#[derive(Serialize, Debug)]
struct Case {
    backend: &'static str,
    sorted: bool,
    threads: usize,
    query: &'static str,
    mrays_per_s: f64,
}

/// Runs `psao bench trace`.
pub fn run(args: &BenchTraceArgs) -> Result<()> {
    if args.rays == 0 || args.rays > MAX_RAYS {
        bail!("--rays must be in 1..={MAX_RAYS}, got {}", args.rays);
    }
    let (input, path) = args.input.load()?;
    if args.dynamic {
        return dynamic::run(args, &input, &path);
    }
    let unsorted = ao_ray_set(&input, &path, args.res, args.rays)?;
    let order = sort_rays_spatially(&unsorted);
    let sorted: Vec<Ray> = order.iter().map(|&i| unsorted[i as usize]).collect();
    tracing::info!(
        "{} AO rays (R = {}) from visible surfaces of {}",
        unsorted.len(),
        input.scene.ao_radius,
        input.name
    );
    let mut cases = Vec::new();
    for backend in Backend::compiled() {
        let tracer = Tracer::new(backend, &input.scene, GeometryMode::Occlusion)
            .with_context(|| format!("cannot build the {} backend", backend.name()))?;
        for (is_sorted, rays) in [(false, &unsorted), (true, &sorted)] {
            for threads in [1, 2] {
                for query in ["occluded", "closest"] {
                    let secs = time_case(&tracer, rays, threads, query, args.repeat.max(1))?;
                    let case = Case {
                        backend: backend.name(),
                        sorted: is_sorted,
                        threads,
                        query,
                        mrays_per_s: rays.len() as f64 / secs / 1e6,
                    };
                    tracing::info!("{case:?}");
                    cases.push(case);
                }
            }
        }
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&cases)?);
    } else {
        println!("| backend | rays | threads | query | Mrays/s |");
        println!("|---|---|---|---|---:|");
        for c in &cases {
            let order = if c.sorted { "sorted" } else { "unsorted" };
            println!(
                "| {} | {order} | {} | {} | {:.2} |",
                c.backend, c.threads, c.query, c.mrays_per_s
            );
        }
    }
    Ok(())
}

/// Mrays/s of `backend` on `count` sorted AO rays from the surfaces visible along `path`
/// (closest-hit queries, the rayon pool's threads, best of three): the rate `psao bench step`
/// compares the tracing inside a server step against.
pub fn sorted_closest_rate(
    input: &SceneInput,
    path: &psao_scene::path::CameraPath,
    backend: Backend,
    count: usize,
) -> Result<f64> {
    let views = Resolution {
        width: 320,
        height: 180,
    };
    let rays = ao_ray_set(input, path, views, count)?;
    let order = sort_rays_spatially(&rays);
    let sorted: Vec<Ray> = order.iter().map(|&i| rays[i as usize]).collect();
    let tracer = Tracer::new(backend, &input.scene, GeometryMode::Occlusion)
        .with_context(|| format!("cannot build the {} backend", backend.name()))?;
    let secs = time_case(&tracer, &sorted, rayon::current_num_threads(), "closest", 3)?;
    Ok(sorted.len() as f64 / secs / 1e6)
}

/// `count` AO rays from the surfaces visible along the path in views of size `res`, in a
/// seeded random order.
fn ao_ray_set(
    input: &SceneInput,
    path: &psao_scene::path::CameraPath,
    res: Resolution,
    count: usize,
) -> Result<Vec<Ray>> {
    let opts = RasterOptions::new(res.width, res.height);
    let frames = path.frame_count();
    let mut points = Vec::new();
    for k in 0..SEED_FRAMES {
        let camera = path.camera_at_frame(k * (frames - 1) / (SEED_FRAMES - 1).max(1));
        let g = rasterize(&input.scene, &camera, &opts);
        points.extend(
            (0..g.depth.len())
                .filter(|&i| g.covered(i))
                .map(|i| (g.position[i], g.normal[i])),
        );
    }
    if points.is_empty() {
        bail!("the camera path sees no geometry: cannot place AO rays");
    }
    let spp = count.div_ceil(points.len()) as u32;
    let mut rays = Vec::with_capacity(points.len() * spp as usize);
    for (i, &(x, n)) in points.iter().enumerate() {
        ao::ao_rays(x, n, input.scene.ao_radius, spp, 7, i as u64, &mut rays);
    }
    rays.truncate(count);
    // A seeded shuffle: sort by a hash of the index, so "unsorted" means incoherent.
    let mut keyed: Vec<(u64, Ray)> = rays
        .into_iter()
        .enumerate()
        .map(|(i, r)| {
            (
                (i as u64 ^ 0x9e37_79b9_7f4a_7c15)
                    .wrapping_mul(0xbf58_476d_1ce4_e5b9)
                    .rotate_left(31),
                r,
            )
        })
        .collect();
    keyed.sort_unstable_by_key(|(k, _)| *k);
    Ok(keyed.into_iter().map(|(_, r)| r).collect())
}

/// Best wall time of `repeat` runs of one case.
fn time_case(
    tracer: &Tracer,
    rays: &[Ray],
    threads: usize,
    query: &str,
    repeat: u32,
) -> Result<f64> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .context("cannot start the thread pool")?;
    let mut best = f64::INFINITY;
    pool.install(|| {
        for _ in 0..repeat {
            let start = Instant::now();
            if query == "occluded" {
                let mut out = vec![false; rays.len()];
                rays.par_chunks(RAYS_PER_CALL)
                    .zip(out.par_chunks_mut(RAYS_PER_CALL))
                    .for_each(|(r, o)| tracer.occluded(r, o));
                std::hint::black_box(&out);
            } else {
                let mut out = vec![None; rays.len()];
                rays.par_chunks(RAYS_PER_CALL)
                    .zip(out.par_chunks_mut(RAYS_PER_CALL))
                    .for_each(|(r, o)| tracer.intersect(r, o));
                std::hint::black_box(&out);
            }
            best = best.min(start.elapsed().as_secs_f64());
        }
    });
    Ok(best)
}
