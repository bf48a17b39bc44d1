//! `psao corrective bench`: the sample cache's per-frame cost, and what the analyzer thread
//! saves the client's frame loop.
//!
//! Cache: samples are taken in √5 order (coarse levels first) at the G-buffer pixels of one
//! path frame, every covered pixel counting as part of an object (id = instance + 1), then
//! aged and reprojected into a later frame of the path and splatted there.
//!
//! Analysis: the client's correction step (composite, splat, object ids) over consecutive path
//! frames, timed per frame, once with the analysis in the frame loop every `--analyze-every`
//! frames (lockstep views, `psao run`) and once handing the frame to the analyzer thread
//! instead (threaded `psao view`: the frame loop only copies what the analysis reads).

use crate::args::Resolution;
use crate::bench_client::median_ms;
use crate::scene_source::SceneArgs;
use anyhow::{bail, Result};
use clap::Args;
use psao_corrective::cache::{CacheConfig, SampleCache};
use psao_corrective::screen::ScreenView;
use psao_corrective::splat::{Sample, SplatTarget};
use psao_corrective::sqrt5::{Hierarchy, PixelRect};
use psao_net::convert::camera_msg;
use psao_net::corrective::{BaseFrame, CorrectiveClient, CorrectiveClientConfig};
use psao_raster::{rasterize, GBuffer, RasterOptions};
use psao_scene::{CameraPath, Scene};
use psao_wire::CameraMsg;
use serde::Serialize;
use std::time::Instant;

/// Arguments of `psao corrective bench`.
#[derive(Args, Debug)]
pub struct BenchArgs {
    #[command(flatten)]
    pub input: SceneArgs,
    /// Image size.
    #[arg(long, default_value = "640x360")]
    pub res: Resolution,
    /// Cached samples.
    #[arg(long, default_value_t = 50_000)]
    pub samples: usize,
    /// Path frame the samples are traced at.
    #[arg(long, default_value_t = 0)]
    pub from: usize,
    /// Path frame they are reprojected to.
    #[arg(long, default_value_t = 1)]
    pub to: usize,
    /// Timed repetitions (the median is reported).
    #[arg(long, default_value_t = 20)]
    pub repeat: u32,
    /// Client frames between analyses in the frame-loop comparison.
    #[arg(long, default_value_t = psao_net::corrective::DEFAULT_ANALYZE_EVERY)]
    pub analyze_every: u32,
    /// Client frames timed in the frame-loop comparison (from path frame `--from`).
    #[arg(long, default_value_t = 72)]
    pub loop_frames: u32,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize)]
struct CacheBench {
    res: String,
    threads: usize,
    samples: usize,
    levels: u8,
    aging_ms: f64,
    splat_ms: f64,
    drawn: usize,
    kept_after_aging: usize,
    frame_loop: FrameLoopBench,
}

/// The client's correction step per frame, with the analysis in the frame loop or handed to
/// the analyzer thread.
#[derive(Serialize)]
struct FrameLoopBench {
    frames: u32,
    analyze_every: u32,
    /// One analysis (saliency and regions), median.
    analysis_ms: f64,
    inline_mean_ms: f64,
    inline_max_ms: f64,
    threaded_mean_ms: f64,
    threaded_max_ms: f64,
}

/// Samples at covered pixels of `g`, level by level, until `count` (fewer when the image runs out).
fn samples_of(g: &GBuffer, view: &ScreenView, hierarchy: &Hierarchy, count: usize) -> Vec<Sample> {
    let rect = PixelRect {
        x0: 0,
        y0: 0,
        x1: g.width as i32,
        y1: g.height as i32,
    };
    let mut out = Vec::with_capacity(count);
    for level in 1..=hierarchy.levels() {
        let positions = hierarchy
            .level_samples(level, rect)
            .expect("level within the hierarchy");
        for (x, y) in positions.iter_from(0) {
            if out.len() == count {
                return out;
            }
            let i = g.index(x as u32, y as u32);
            if !g.covered(i) {
                continue;
            }
            let v = (view.eye - g.position[i]).normalize_or_zero();
            out.push(Sample {
                position: g.position[i],
                normal: g.normal[i],
                ndotv: g.normal[i].dot(v),
                color: (g.normal[i] * 0.5 + 0.5).to_array(),
                object: g.instance[i] + 1,
                level,
                age: 0,
            });
        }
    }
    out
}

/// Runs `psao corrective bench`.
pub fn run(args: &BenchArgs) -> Result<()> {
    if args.repeat == 0 {
        bail!("--repeat must be at least 1");
    }
    if args.analyze_every == 0 || args.loop_frames == 0 {
        bail!("--analyze-every and --loop-frames must be at least 1");
    }
    let (input, path) = args.input.load()?;
    let frames = path.frame_count();
    if args.from >= frames || args.to >= frames {
        bail!(
            "--from {} / --to {} outside the path's {frames} frames",
            args.from,
            args.to
        );
    }
    let (w, h) = (args.res.width, args.res.height);
    let opts = RasterOptions::new(w, h);
    let cam_a = path.camera_at_frame(args.from);
    let cam_b = path.camera_at_frame(args.to);
    let g_a = rasterize(&input.scene, &cam_a, &opts);
    let g_b = rasterize(&input.scene, &cam_b, &opts);
    let hierarchy = Hierarchy::for_spacing(w.min(h) as f32 / 4.0);
    let samples = samples_of(
        &g_a,
        &ScreenView::new(&cam_a, w, h),
        &hierarchy,
        args.samples,
    );
    if samples.len() < args.samples {
        bail!(
            "frame {} covers only {} pixels, fewer than --samples {}",
            args.from,
            samples.len(),
            args.samples
        );
    }
    let mut cache = SampleCache::new(CacheConfig::default(), hierarchy)?;
    cache.insert(&samples)?;
    let view_b = ScreenView::new(&cam_b, w, h);
    // Aging changes the cache, so each timed run ages a fresh copy (copied untimed).
    let mut aging_times: Vec<f64> = (0..args.repeat)
        .map(|_| {
            let mut c = cache.clone();
            let t = Instant::now();
            c.camera_changed(&view_b);
            let ms = t.elapsed().as_secs_f64() * 1e3;
            std::hint::black_box(c);
            ms
        })
        .collect();
    aging_times.sort_by(f64::total_cmp);
    let aging_ms = aging_times[aging_times.len() / 2];
    let mut aged = cache.clone();
    aged.camera_changed(&view_b);
    let ids: Vec<u32> = g_b
        .instance
        .iter()
        .map(|&i| if i == GBuffer::NONE { 0 } else { i + 1 })
        .collect();
    let n = (w * h) as usize;
    let black = vec![[0.0f32; 3]; n];
    let mut color = black.clone();
    let mut drawn = 0;
    let splat_ms = median_ms(args.repeat, || {
        drawn = cache.splat(
            &view_b,
            &mut SplatTarget {
                color: &mut color,
                diffuse: &black,
                keep: None,
                ids: &ids,
                gbuffer: &g_b,
            },
        );
    });
    let frame_loop = frame_loop(args, &input.scene, &path)?;
    let result = CacheBench {
        res: args.res.to_string(),
        threads: rayon::current_num_threads(),
        samples: samples.len(),
        levels: hierarchy.levels(),
        aging_ms,
        splat_ms,
        drawn,
        kept_after_aging: aged.len(),
        frame_loop,
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&result)?);
    } else {
        println!(
            "{} samples, {} levels, {} on {} threads: aging {:.2} ms ({} kept), reprojection + splatting {:.2} ms ({} drawn)",
            result.samples,
            result.levels,
            result.res,
            result.threads,
            result.aging_ms,
            result.kept_after_aging,
            result.splat_ms,
            result.drawn
        );
        let f = &result.frame_loop;
        println!(
            "client correction step over {} frames, analysis ({:.2} ms) every {}: in the frame loop {:.2} ms mean / {:.2} ms max per frame, on the analyzer thread {:.2} / {:.2} ms",
            f.frames,
            f.analysis_ms,
            f.analyze_every,
            f.inline_mean_ms,
            f.inline_max_ms,
            f.threaded_mean_ms,
            f.threaded_max_ms
        );
    }
    Ok(())
}

/// Times the client's correction step over `--loop-frames` path frames from `--from` (G-buffers
/// rasterized beforehand, AO 1), with the analysis inline and handed off.
fn frame_loop(args: &BenchArgs, scene: &Scene, path: &CameraPath) -> Result<FrameLoopBench> {
    let (w, h) = (args.res.width, args.res.height);
    let opts = RasterOptions::new(w, h);
    let ao = vec![1.0f32; (w * h) as usize];
    let frames: Vec<(CameraMsg, GBuffer)> = (0..args.loop_frames)
        .map(|f| {
            let camera = path.camera_at_frame((args.from + f as usize) % path.frame_count());
            let msg = camera_msg(f, &camera, w as f32 / h as f32);
            (msg, rasterize(scene, &camera, &opts))
        })
        .collect();
    let config = CorrectiveClientConfig {
        analyze_every: args.analyze_every,
        ..CorrectiveClientConfig::default()
    };
    // Per-frame milliseconds of `step` over every frame, on a fresh client.
    let timed = |step: &dyn Fn(&mut CorrectiveClient, u32, &GBuffer)| -> Result<Vec<f64>> {
        let mut client = CorrectiveClient::new(w, h, config)?;
        Ok(frames
            .iter()
            .zip(0..)
            .map(|((msg, g), f)| {
                client.camera(msg);
                let t = Instant::now();
                step(&mut client, f, g);
                t.elapsed().as_secs_f64() * 1e3
            })
            .collect())
    };
    let inline = timed(&|c, f, g| {
        std::hint::black_box(c.frame(scene, f, g, BaseFrame::Ao(&ao)));
    })?;
    let threaded = timed(&|c, f, g| {
        let corrected = c.correct(scene, f, g, BaseFrame::Ao(&ao));
        if f.is_multiple_of(args.analyze_every) {
            std::hint::black_box(corrected.analysis());
        }
    })?;
    let mut client = CorrectiveClient::new(w, h, config)?;
    let shown = client
        .correct(scene, 0, &frames[0].1, BaseFrame::Ao(&ao))
        .analysis();
    let analysis_ms = median_ms(args.repeat, || {
        std::hint::black_box(shown.regions());
    });
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let max = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
    Ok(FrameLoopBench {
        frames: args.loop_frames,
        analyze_every: args.analyze_every,
        analysis_ms,
        inline_mean_ms: mean(&inline),
        inline_max_ms: max(&inline),
        threaded_mean_ms: mean(&threaded),
        threaded_max_ms: max(&threaded),
    })
}
