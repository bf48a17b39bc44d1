//! `psao bench client`: cost of the client's AO reconstruction against SSAO on one G-buffer.

use crate::args::Resolution;
use crate::run::ServerTuning;
use crate::scene_source::SceneArgs;
use anyhow::{bail, Result};
use clap::Args;
use psao_client::{reconstruct, ReconstructSettings};
use psao_eval::{ssao, SsaoSettings};
use psao_net::pipeline::Pipeline;
use serde::Serialize;
use std::time::Instant;

/// Server frames run before timing, so that the visible points carry AO.
const WARMUP_SERVER_FRAMES: u32 = 30;

/// Arguments of `psao bench client`.
#[derive(Args, Debug)]
pub struct BenchClientArgs {
    #[command(flatten)]
    pub input: SceneArgs,
    /// Image size.
    #[arg(long, default_value = "1280x720")]
    pub res: Resolution,
    /// Points per unit area.
    #[arg(long, default_value_t = 1024.0)]
    pub points: f32,
    /// Timed repetitions (the median is reported).
    #[arg(long, default_value_t = 10)]
    pub repeat: u32,
    #[command(flatten)]
    pub tuning: ServerTuning,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize)]
struct ClientBench {
    res: String,
    threads: usize,
    reconstruct_ms: f64,
    ssao_ms: f64,
    ratio: f64,
}

/// Runs `psao bench client`.
pub fn run(args: &BenchClientArgs) -> Result<()> {
    if args.repeat == 0 {
        bail!("--repeat must be at least 1");
    }
    let (input, path) = args.input.load()?;
    let camera = path.camera_at_frame(0);
    let config = args.tuning.config(args.points, 60, args.res)?;
    let mut pipeline = Pipeline::new(&input.scene, &config)?;
    let mut frame = None;
    for i in 0..WARMUP_SERVER_FRAMES {
        let last = i + 1 == WARMUP_SERVER_FRAMES;
        frame = pipeline.frame(i, &camera, last)?.1;
    }
    let Some(frame) = frame else {
        bail!("the pipeline rendered no frame");
    };
    let g = &frame.gbuffer;
    let settings = ReconstructSettings::default();
    let reconstruct_ms = median_ms(args.repeat, || {
        std::hint::black_box(reconstruct(pipeline.client(), g, &settings));
    });
    let ssao_settings = SsaoSettings::new(input.scene.ao_radius);
    let ssao_ms = median_ms(args.repeat, || {
        std::hint::black_box(ssao(g, &camera, &ssao_settings));
    });
    let result = ClientBench {
        res: args.res.to_string(),
        threads: rayon::current_num_threads(),
        reconstruct_ms,
        ssao_ms,
        ratio: reconstruct_ms / ssao_ms,
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&result)?);
    } else {
        println!(
            "{} on {} threads: reconstruction {:.2} ms, SSAO {:.2} ms, ratio {:.2}",
            result.res, result.threads, result.reconstruct_ms, result.ssao_ms, result.ratio
        );
    }
    Ok(())
}

/// Median wall time of `repeat` calls of `f` (after one untimed call), in ms.
pub fn median_ms(repeat: u32, mut f: impl FnMut()) -> f64 {
    f();
    let mut times: Vec<f64> = (0..repeat)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[times.len() / 2]
}
