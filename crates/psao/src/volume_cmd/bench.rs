//! `psao volume bench`: speed ratios of the fast paths on several volumes (files and generated
//! ones), one row per volume and mode, the worst ratio of each mode last.

use anyhow::{Context, Result};
use psao_net::cpu_time::fine_cpu_seconds;
use psao_volume::render::{self, DenseGrid};
use psao_volume::{
    BrickFormat, Camera, GridClass, Image, Procedural, RenderMode, RenderSettings, SparseGrid,
    Volume,
};
use std::time::Instant;

/// Target of fog through the BC7 pool: at least this fraction of the f32 pool's speed.
const FOG_TARGET: f64 = 0.8;
/// Target of the HDDA level set: at least this speed-up over the dense march.
const HDDA_TARGET: f64 = 3.0;

/// One measured row.
struct Row {
    volume: String,
    mode: &'static str,
    bricks: usize,
    names: [&'static str; 2],
    wall: [f64; 2],
    cpu: [f64; 2],
    /// Speed of the fast path over the reference (wall, CPU).
    ratio: (f64, f64),
    target: f64,
    diff: f32,
}

/// Best wall and CPU time of two renderers run alternately `reps` times each, with the first
/// images.
struct Pair {
    wall: [f64; 2],
    cpu: [f64; 2],
    images: Vec<Image>,
}

type Job<'a> = Box<dyn Fn() -> Result<Image> + 'a>;

fn race(reps: u32, jobs: [Job; 2]) -> Result<Pair> {
    let mut p = Pair {
        wall: [f64::INFINITY; 2],
        cpu: [f64::INFINITY; 2],
        images: Vec::new(),
    };
    for rep in 0..reps {
        // Alternate which renderer goes first, so a load change hits both alike.
        let order = if rep % 2 == 0 { [0, 1] } else { [1, 0] };
        for k in order {
            let (t, c) = (Instant::now(), fine_cpu_seconds());
            let img = jobs[k]()?;
            p.wall[k] = p.wall[k].min(t.elapsed().as_secs_f64());
            // A thread that ended meanwhile takes its time along: no figure then.
            if let (Some(a), Some(b)) = (c, fine_cpu_seconds()) {
                if b >= a {
                    p.cpu[k] = p.cpu[k].min(b - a);
                }
            }
            if rep == 0 {
                p.images.push(img);
            }
        }
    }
    Ok(p)
}

/// Measures the fog and (for level sets) the HDDA rows of one volume.
fn bench_volume(label: &str, grid: &SparseGrid, w: u32, h: u32, reps: u32) -> Result<Vec<Row>> {
    let frames = std::slice::from_ref(grid);
    let (f32v, _) = Volume::build(frames, BrickFormat::F32, None)
        .with_context(|| format!("cannot build {label}"))?;
    let (bc7v, _) = Volume::build(frames, BrickFormat::Bc7, None)
        .with_context(|| format!("cannot build {label}"))?;
    let cam = Camera::framing(f32v.world_bounds(0), 40.0);
    let bricks = f32v.pool.len();
    let mut rows = Vec::new();
    let fog = RenderSettings::new(&f32v, w, h, RenderMode::Fog);
    let p = race(
        reps,
        [
            Box::new(|| Ok(render::render(&f32v, &cam, &fog)?)),
            Box::new(|| Ok(render::render(&bc7v, &cam, &fog)?)),
        ],
    )?;
    rows.push(Row {
        volume: label.to_string(),
        mode: "fog bc7/f32",
        bricks,
        names: ["f32", "bc7"],
        wall: p.wall,
        cpu: p.cpu,
        ratio: (p.wall[0] / p.wall[1], p.cpu[0] / p.cpu[1]),
        target: FOG_TARGET,
        diff: p.images[0].mean_abs_diff(&p.images[1]),
    });
    if f32v.class == GridClass::LevelSet {
        let ls = RenderSettings::new(&f32v, w, h, RenderMode::LevelSet);
        let dense = DenseGrid::from_volume(&f32v, 0);
        let p = race(
            reps,
            [
                Box::new(|| Ok(render::render(&f32v, &cam, &ls)?)),
                Box::new(|| Ok(render::render_dense_level_set(&f32v, &dense, &cam, &ls)?)),
            ],
        )?;
        rows.push(Row {
            volume: label.to_string(),
            mode: "level set HDDA/dense",
            bricks,
            names: ["HDDA", "dense"],
            wall: p.wall,
            cpu: p.cpu,
            ratio: (p.wall[1] / p.wall[0], p.cpu[1] / p.cpu[0]),
            target: HDDA_TARGET,
            diff: p.images[0].mean_abs_diff(&p.images[1]),
        });
    }
    Ok(rows)
}

/// Volumes to measure: files (read as they come, one at a time) or generated kinds.
pub enum Input {
    /// An OpenVDB file.
    File(std::path::PathBuf),
    /// A generated volume of this kind, size and seed.
    Generated(Procedural, u32, u64),
}

/// Runs the benchmark over `inputs` and prints the table.
pub fn run(inputs: &[Input], w: u32, h: u32, reps: u32) -> Result<()> {
    let mut rows = Vec::new();
    println!("| volume | mode | bricks | A | A ms | A CPU ms | B | B ms | B CPU ms | speed wall | speed CPU | target | image mean abs diff |");
    println!("|---|---|---:|---|---:|---:|---|---:|---:|---:|---:|---:|---:|");
    for input in inputs {
        let (label, grid) = match input {
            Input::File(f) => (
                f.file_name()
                    .map_or_else(|| f.display().to_string(), |n| n.to_string_lossy().into()),
                super::read_frames(std::slice::from_ref(f), None)?.remove(0),
            ),
            Input::Generated(kind, size, seed) => (
                format!("{} (generated {size}³, seed {seed})", kind.name()),
                kind.generate(*size, *seed)
                    .with_context(|| format!("cannot generate {}", kind.name()))?,
            ),
        };
        for r in bench_volume(&label, &grid, w, h, reps)? {
            println!(
                "| {} | {} | {} | {} | {:.1} | {:.1} | {} | {:.1} | {:.1} | {:.2}x | {:.2}x | {:.1}x | {:.4} |",
                r.volume,
                r.mode,
                r.bricks,
                r.names[0],
                r.wall[0] * 1e3,
                r.cpu[0] * 1e3,
                r.names[1],
                r.wall[1] * 1e3,
                r.cpu[1] * 1e3,
                r.ratio.0,
                r.ratio.1,
                r.target,
                r.diff
            );
            rows.push(r);
        }
    }
    for mode in ["fog bc7/f32", "level set HDDA/dense"] {
        let of_mode = || rows.iter().filter(|r| r.mode == mode);
        let wall = of_mode().min_by(|a, b| a.ratio.0.total_cmp(&b.ratio.0));
        let cpu = of_mode().min_by(|a, b| a.ratio.1.total_cmp(&b.ratio.1));
        if let (Some(r), Some(c)) = (wall, cpu) {
            println!(
                "worst {mode}: {:.2}x wall on {} (target {:.1}x: {}); {:.2}x CPU on {}",
                r.ratio.0,
                r.volume,
                r.target,
                if r.ratio.0 >= r.target {
                    "met"
                } else {
                    "missed"
                },
                c.ratio.1,
                c.volume
            );
        }
    }
    Ok(())
}
