//! `psao bench relight`: synthesis + shading time per frame of a trained relighting model.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Args;
use serde::Serialize;

use psao_net::cpu_time::fine_cpu_seconds;
use psao_prt::compact::CompactModel;
use psao_prt::filter::Filter;
use psao_prt::model::PoseModel;
use psao_prt::runtime::{FramePose, Relighter, Rig};
use psao_prt::served::ServedRelighter;
use psao_prt::sh::ShVec;

use crate::relight_cmd::{
    character_and_model, frame_range, gather, split, train_model, ShadingArgs,
};
use crate::relight_io::{clip_frames, framing_camera, load_character, load_env, FPS};

/// Arguments of `psao bench relight`.
#[derive(Args, Debug)]
pub struct BenchRelightArgs {
    /// The skinned character (glTF/GLB).
    #[arg(long)]
    pub character: PathBuf,
    /// Clip name or index (default: the first clip).
    #[arg(long)]
    pub clip: Option<String>,
    /// A trained model (default: train a 2-lobe model on every 2nd frame with 64 rays).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Radiance `.hdr` environment map (default: a fixed synthetic SH sky).
    #[arg(long)]
    pub env: Option<PathBuf>,
    #[command(flatten)]
    pub shading: ShadingArgs,
    /// Timed runs (one per frame of the clip, cycling).
    #[arg(long, default_value_t = 60)]
    pub runs: usize,
    /// Relight this many vertices: the character's vertices, model columns and skinned
    /// geometry repeated (or cut) to that count (the cost depends on the sizes, not on the
    /// values); default: the character's own.
    #[arg(long)]
    pub vertices: Option<usize>,
    /// Threads of the pool the frames run on (default: one per core).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Time a relit character's whole per-frame work in `psao run --relight`, `psao view`
    /// and the browser (`psao_prt::served::ServedRelighter::relight`): shading under the
    /// lighting and a white sky, with and without shadowing, and the per-vertex
    /// self-shadowing and self-visibility, instead of the RGB shading alone (no visibility
    /// filter: the clients have none).
    #[arg(long)]
    pub client: bool,
    /// Write the result as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

#[derive(Serialize)]
struct BenchResult {
    character: String,
    vertices: usize,
    lobes: usize,
    mode: String,
    client: bool,
    threads: usize,
    runs: usize,
    /// Median wall-clock milliseconds for pose → lobes → shaded vertices (RGB; with
    /// `client`, as a client of a relighting server: 4 channels and per-vertex values).
    ms_per_frame: f64,
    /// Median CPU milliseconds of the same work, summed over all threads of the process
    /// (`null` where the scheduler statistics are not available). Unlike wall time it does
    /// not grow when other processes take the cores; on an otherwise idle machine with both
    /// cores busy it is up to 2 × `ms_per_frame`.
    cpu_ms_per_frame: Option<f64>,
    /// Median milliseconds of the compacted model's synthesis alone (every vertex's lobes).
    synthesis_ms: f64,
    model_mb: f64,
    /// Size of the compacted model's stored rows (16- and 8-bit integers and their
    /// factors).
    compact_mb: f64,
    /// Rows of the compacted model: its base and one per component.
    compact_rows: usize,
    /// Rows stored per block of vertices, on average (each block keeps what its vertices
    /// need).
    compact_stored_rows: f64,
    /// Largest change the compaction can make to a lobe number (pose within the box).
    compact_bound: f32,
}

/// What the bench times per frame.
enum Frames {
    /// [`Relighter::shade_into`] under these lights.
    Plain(Relighter, Vec<ShVec>),
    /// [`ServedRelighter::relight`].
    Served(ServedRelighter),
}

impl Frames {
    fn compact(&self) -> &CompactModel {
        match self {
            Frames::Plain(r, _) => r.compact(),
            Frames::Served(r) => r.relighter().compact(),
        }
    }
}

/// Runs `psao bench relight`.
pub fn run(args: &BenchRelightArgs) -> Result<()> {
    if args.runs == 0 {
        bail!("--runs must be at least 1");
    }
    let (loaded, model) = match &args.model {
        Some(m) => character_and_model(&args.character, args.clip.as_deref(), m)?,
        None => {
            let loaded = load_character(&args.character, args.clip.as_deref())?;
            let c = &loaded.character;
            let s = split(frame_range(c, None)?, 2, None)?;
            let train_set = gather(c, &s.train, 64, 1, "tracing training frames")?;
            let validate = gather(c, &s.validate, 64, 1, "tracing validation frames")?;
            let (model, _) = train_model(&loaded.name, &train_set, &validate, 2)?;
            (loaded, model)
        }
    };
    let lights = match &args.env {
        Some(e) => load_env(e)?.project().rgb,
        None => {
            let mut l = psao_prt::shade::unit_visibility();
            l[1] = 1.0;
            l[5] = 0.3;
            [l; 3]
        }
    };
    let mode = args.shading.mode()?;
    let c = &loaded.character;
    let frames = clip_frames(c);
    let mut poses: Vec<_> = (0..frames.min(args.runs as u32))
        .map(|i| c.pose(i as f32 / FPS))
        .collect();
    let camera = framing_camera(&poses[0], 640, 480);
    let (model, rig) = match args.vertices {
        Some(n) => {
            if n == 0 {
                bail!("--vertices must be at least 1");
            }
            for pose in &mut poses {
                pose.positions = repeat(&pose.positions, 1, n);
                pose.normals = repeat(&pose.normals, 1, n);
            }
            repeat_vertices(&model, c.rig(), n)
        }
        None => (model, c.rig()),
    };
    let vertices = model.vertices;
    let (lobes, model_mb) = (model.lobes, model.megabytes());
    let mut relighter = if args.client {
        if args.shading.filter != Filter::default() {
            bail!("--client shades as the clients do, without a visibility filter");
        }
        Frames::Served(ServedRelighter::new(
            model,
            rig,
            mode,
            lights.as_flattened(),
        )?)
    } else {
        Frames::Plain(
            Relighter::new(model, args.shading.shader()?, rig)?,
            lights.to_vec(),
        )
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads.unwrap_or(0))
        .build()
        .context("cannot start the thread pool")?;
    let (mut raw, mut shaded, mut values) = (Vec::new(), Vec::new(), Vec::new());
    let mut total = Vec::with_capacity(args.runs);
    let mut synth = Vec::with_capacity(args.runs);
    let mut cpu = Vec::with_capacity(args.runs);
    // One warm-up frame, then the timed runs. The clocks are read on this thread, outside
    // the pool: a thread's scheduler statistics are only brought up to date when it stops
    // running, so the pool's threads are read while they wait between frames.
    for run in 0..=args.runs {
        let pose = &poses[run % poses.len()];
        let frame = FramePose {
            joint_local: &pose.joint_local,
            positions: &pose.positions,
            normals: &pose.normals,
            transform: pose.transform,
        };
        let cpu_start = fine_cpu_seconds();
        let start = Instant::now();
        pool.install(|| match &mut relighter {
            Frames::Plain(r, lights) => r.shade_into(&frame, lights, camera.position, &mut shaded),
            Frames::Served(r) => r.relight(&frame, camera.position, &mut values),
        })?;
        std::hint::black_box(&values);
        let wall = start.elapsed();
        let cpu_end = fine_cpu_seconds();
        std::hint::black_box(&shaded);
        // The synthesis alone (the compacted model's product), timed apart.
        let compact = relighter.compact();
        let start = Instant::now();
        pool.install(|| compact.predict(&pose.joint_rotations, &mut raw));
        let synthesis = start.elapsed();
        if run > 0 {
            total.push(wall.as_secs_f64() * 1e3);
            synth.push(synthesis.as_secs_f64() * 1e3);
            if let (Some(a), Some(b)) = (cpu_start, cpu_end) {
                cpu.push((b - a).max(0.0) * 1e3);
            }
        }
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let result = BenchResult {
        character: loaded.name.clone(),
        vertices,
        lobes,
        mode: format!("{mode:?}"),
        client: args.client,
        threads: pool.current_num_threads(),
        runs: args.runs,
        ms_per_frame: median(&mut total),
        // Every run has a figure or none has (the statistics exist or they do not).
        cpu_ms_per_frame: (cpu.len() == total.len()).then(|| median(&mut cpu)),
        synthesis_ms: median(&mut synth),
        model_mb,
        compact_mb: relighter.compact().megabytes(),
        compact_rows: relighter.compact().rows(),
        compact_stored_rows: relighter.compact().stored_rows(),
        compact_bound: relighter.compact().bound(),
    };
    let cpu_text = result
        .cpu_ms_per_frame
        .map_or("not available".to_string(), |c| format!("{c:.3} ms"));
    println!(
        "{}: {} vertices, {} lobes, {} on {} threads: {:.3} ms per frame (synthesis {:.3} ms), CPU {cpu_text} per frame, model {:.2} MB (compacted {} rows, {:.1} stored per block, {:.2} MB, bound {:.1e})",
        result.character,
        result.vertices,
        result.lobes,
        result.mode,
        result.threads,
        result.ms_per_frame,
        result.synthesis_ms,
        result.model_mb,
        result.compact_rows,
        result.compact_stored_rows,
        result.compact_mb,
        result.compact_bound
    );
    if let Some(path) = &args.json {
        std::fs::write(path, serde_json::to_string_pretty(&result)?)
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}

/// `values` (`per` entries per vertex) repeated vertex by vertex to `n` vertices (vertex
/// `v` takes the values of vertex `v mod len`).
fn repeat<T: Copy>(values: &[T], per: usize, n: usize) -> Vec<T> {
    let len = values.len() / per;
    (0..n)
        .flat_map(|v| &values[(v % len) * per..(v % len + 1) * per])
        .copied()
        .collect()
}

/// The model and rig of a character of `n` vertices made by repeating these: every row of
/// weights repeated per vertex, each copy's tangent neighbours within the same copy (or
/// the original's where the last copy is cut short).
fn repeat_vertices(model: &PoseModel, rig: Rig, n: usize) -> (PoseModel, Rig) {
    let per = model.lobes * psao_prt::model::LOBE_DIM;
    let out = model.output_len();
    let weights = model
        .weights
        .chunks_exact(out)
        .flat_map(|row| repeat(row, per, n))
        .collect();
    let len = model.vertices;
    let neighbours = (0..n)
        .map(|v| {
            let copied = (v - v % len) as u32 + rig.neighbours[v % len];
            if (copied as usize) < n {
                copied
            } else {
                rig.neighbours[v % len]
            }
        })
        .collect();
    (
        PoseModel {
            vertices: n,
            weights,
            ..model.clone()
        },
        Rig {
            rest: rig.rest,
            neighbours,
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn repeated_vertices_take_their_originals_columns_and_neighbours() {
        let model = PoseModel {
            character: "t".into(),
            vertices: 2,
            joints: 0,
            lobes: 1,
            active: vec![],
            weights: (0..14).map(|i| i as f32).collect(),
            limits: Default::default(),
        };
        let rig = Rig {
            rest: vec![],
            neighbours: vec![1, 0],
        };
        let (m, r) = repeat_vertices(&model, rig, 5);
        assert_eq!(m.vertices, 5);
        assert_eq!(m.weights.len(), 35);
        assert_eq!(m.weights[14..21], model.weights[0..7]);
        assert_eq!(m.weights[21..28], model.weights[7..14]);
        // Vertex 4 is the first of a cut copy: its neighbour 5 does not exist.
        assert_eq!(r.neighbours, [1, 0, 3, 2, 1]);
        assert_eq!(repeat(&[1, 2, 3, 4], 2, 3), [1, 2, 3, 4, 1, 2]);
    }
}
