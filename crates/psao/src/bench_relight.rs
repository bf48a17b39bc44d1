//! `psao bench relight`: synthesis + shading time per frame of a trained relighting model.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Args;
use serde::Serialize;

use psao_net::cpu_time::fine_cpu_seconds;
use psao_prt::shade::{ShadingGeometry, Visibility};

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
    threads: usize,
    runs: usize,
    /// Median wall-clock milliseconds for pose → lobes → shaded vertices (RGB).
    ms_per_frame: f64,
    /// Median CPU milliseconds of the same work, summed over all threads of the process
    /// (`null` where the scheduler statistics are not available). Unlike wall time it does
    /// not grow when other processes take the cores; on an otherwise idle machine with both
    /// cores busy it is up to 2 × `ms_per_frame`.
    cpu_ms_per_frame: Option<f64>,
    /// Median milliseconds of the model's matrix product alone.
    synthesis_ms: f64,
    model_mb: f64,
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
    let shader = args.shading.shader()?;
    let c = &loaded.character;
    let frames = clip_frames(c);
    let poses: Vec<_> = (0..frames.min(args.runs as u32))
        .map(|i| c.pose(i as f32 / FPS))
        .collect();
    let camera = framing_camera(&poses[0], 640, 480);
    let mut raw = Vec::new();
    let mut total = Vec::with_capacity(args.runs);
    let mut synth = Vec::with_capacity(args.runs);
    let mut cpu = Vec::with_capacity(args.runs);
    // One warm-up frame, then the timed runs.
    for run in 0..=args.runs {
        let pose = &poses[run % poses.len()];
        let cpu_start = fine_cpu_seconds();
        let start = Instant::now();
        model.predict_raw(&model.pose_vector(&pose.joint_rotations), &mut raw);
        let mid = Instant::now();
        let v = shader.shade(
            Visibility::Model(&model, &raw),
            ShadingGeometry {
                positions: &pose.positions,
                frames: &pose.frames,
                transform: pose.transform,
            },
            &lights,
            camera.position,
        )?;
        std::hint::black_box(v);
        let wall = start.elapsed();
        let cpu_end = fine_cpu_seconds();
        if run > 0 {
            total.push(wall.as_secs_f64() * 1e3);
            synth.push((mid - start).as_secs_f64() * 1e3);
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
        vertices: model.vertices,
        lobes: model.lobes,
        mode: format!("{mode:?}"),
        threads: rayon::current_num_threads(),
        runs: args.runs,
        ms_per_frame: median(&mut total),
        // Every run has a figure or none has (the statistics exist or they do not).
        cpu_ms_per_frame: (cpu.len() == total.len()).then(|| median(&mut cpu)),
        synthesis_ms: median(&mut synth),
        model_mb: model.megabytes(),
    };
    let cpu_text = result
        .cpu_ms_per_frame
        .map_or("not available".to_string(), |c| format!("{c:.3} ms"));
    println!(
        "{}: {} vertices, {} lobes, {} on {} threads: {:.3} ms per frame (synthesis {:.3} ms), CPU {cpu_text} per frame, model {:.2} MB",
        result.character,
        result.vertices,
        result.lobes,
        result.mode,
        result.threads,
        result.ms_per_frame,
        result.synthesis_ms,
        result.model_mb
    );
    if let Some(path) = &args.json {
        std::fs::write(path, serde_json::to_string_pretty(&result)?)
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}
