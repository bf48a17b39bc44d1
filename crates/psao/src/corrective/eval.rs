//! `psao corrective eval`: corrected frames along a camera path at several sample budgets and
//! orderings, against the reference; a static-view convergence run per ordering.
//!
//! Budgets are samples per frame (not time, so the results are deterministic). The scene is
//! frozen (no animation). Every analysis period the ordering assigns region priorities:
//! `saliency` (bottom-up saliency of the frame as shown blended with task importance),
//! `uniform` (all equal) or `random` (hashed from the seed, frame, object and region).
//! Regions are the objects' parts in the tiles of [`analyze_tiles`].

use super::frame::{frame_images, rgb_image, trace_sample, FrameImages};
use super::metrics::{frame_error, FrameError};
use super::plot::{convergence_plot, Curve};
use crate::args::{FrameRange, Resolution};
use crate::png_io::write_rgb_png;
use crate::progress;
use crate::scene_source::SceneArgs;
use anyhow::{bail, Context, Result};
use clap::Args;
use psao_corrective::attention::{analyze_tiles, ObjectRegion, DEFAULT_SALIENCY_WEIGHT};
use psao_corrective::base::TracedAoShade;
use psao_corrective::cache::CacheConfig;
use psao_corrective::saliency::saliency;
use psao_corrective::schedule::{DEFAULT_DECAY, DEFAULT_JOB_SIZE};
use psao_corrective::session::Corrector;
use psao_corrective::splat::{Sample, SplatTarget};
use psao_corrective::sqrt5::Hierarchy;
use psao_corrective::trace::{CorrectionTracer, TraceSettings};
use psao_trace::ao::hash64;
use psao_trace::{Backend, GeometryMode, Tracer};
use rayon::prelude::*;
use serde::Serialize;
use std::path::PathBuf;
use std::str::FromStr;
use std::time::Instant;

/// How regions are ordered.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Order {
    /// Saliency blended with task importance (the paper).
    Saliency,
    /// Equal priorities.
    Uniform,
    /// Random priorities per analysis.
    Random,
}

impl FromStr for Order {
    type Err = anyhow::Error;
    fn from_str(s: &str) -> Result<Self> {
        match s.trim() {
            "saliency" => Ok(Order::Saliency),
            "uniform" => Ok(Order::Uniform),
            "random" => Ok(Order::Random),
            other => bail!("unknown order '{other}' (saliency, uniform, random)"),
        }
    }
}

impl Order {
    fn name(self) -> &'static str {
        match self {
            Order::Saliency => "saliency",
            Order::Uniform => "uniform",
            Order::Random => "random",
        }
    }
}

/// Arguments of `psao corrective eval`.
#[derive(Args, Debug)]
pub struct EvalArgs {
    #[command(flatten)]
    pub input: SceneArgs,
    /// Image size.
    #[arg(long, default_value = "320x180")]
    pub res: Resolution,
    /// Frames of the path evaluated, `A..B` (default 0..48).
    #[arg(long)]
    pub frames: Option<FrameRange>,
    /// Samples traced per frame, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "150,600")]
    pub budget: Vec<usize>,
    /// Orderings, comma-separated: saliency, uniform, random.
    #[arg(long, value_delimiter = ',', default_value = "saliency,uniform,random")]
    pub order: Vec<Order>,
    /// Priority reduction per finished √5 level, in [0, 1).
    #[arg(long, default_value_t = DEFAULT_DECAY)]
    pub decay: f32,
    /// Frames between analyses (path frames are 1/60 s apart: 18 = 0.3 s, as the split's
    /// clients analyse).
    #[arg(long, default_value_t = psao_net::corrective::DEFAULT_ANALYZE_EVERY)]
    pub analyze_every: u32,
    /// AO rays per point of the base shading.
    #[arg(long, default_value_t = 8)]
    pub ao_spp: u32,
    /// Frames of the static-view convergence run (at the first frame's camera, first budget).
    #[arg(long, default_value_t = 60)]
    pub static_frames: u32,
    /// Seed of every random choice.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output directory.
    #[arg(long)]
    pub out: PathBuf,
}

#[derive(Serialize, Clone)]
struct Row {
    order: String,
    budget: usize,
    psnr: f64,
    flip: f64,
    saliency_flip: f64,
}

#[derive(Serialize)]
struct FrameRow {
    frame: u32,
    order: String,
    budget: usize,
    #[serde(flatten)]
    error: FrameError,
    cache_size: usize,
}

#[derive(Serialize)]
struct Convergence {
    order: String,
    budget: usize,
    non_diffuse_pixels: usize,
    samples_traced: usize,
    /// Whether every non-diffuse pixel equals the reference bit for bit at the end.
    bit_identical: bool,
    /// (samples so far, FLIP, saliency-weighted FLIP) after each frame.
    curve: Vec<(usize, f64, f64)>,
}

#[derive(Serialize)]
struct Timing {
    worker_samples_per_s: f64,
    threads: usize,
    aging_ms: f64,
    splat_ms: f64,
    analysis_ms: f64,
    mean_cache_size: f64,
    max_cache_size: usize,
}

#[derive(Serialize)]
struct Report {
    scene: String,
    res: String,
    frames: String,
    levels: u8,
    rows: Vec<Row>,
    per_frame: Vec<FrameRow>,
    convergence: Vec<Convergence>,
    timing: Timing,
}

/// One simulated viewer.
struct Sim {
    order: Order,
    budget: usize,
    corrector: Corrector,
    sums: FrameError,
}

/// Accumulated timings.
#[derive(Default)]
struct Clock {
    traced: usize,
    trace_s: f64,
    aging_ms: Vec<f64>,
    splat_ms: Vec<f64>,
    analysis_ms: Vec<f64>,
    cache_sizes: Vec<usize>,
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// Region priorities for `order`; the saliency ordering analyses `shown`, the frame as the
/// viewer sees it now (base frame with the cached corrections splatted, as the paper's
/// analyzer reads the frame buffer).
fn priorities(
    order: Order,
    f: &FrameImages,
    shown: &[[f32; 3]],
    seed: u64,
    frame: u32,
    clock: &mut Clock,
) -> Vec<ObjectRegion> {
    let (w, h) = (f.gbuffer.width as usize, f.gbuffer.height as usize);
    let t = Instant::now();
    let sal = match order {
        Order::Saliency => saliency(&rgb_image(shown, w as u32, h as u32)),
        _ => psao_corrective::saliency::Map {
            width: w,
            height: h,
            values: vec![0.0; w * h],
        },
    };
    let mut regions = analyze_tiles(&f.ids, w, h, &sal, DEFAULT_SALIENCY_WEIGHT, usize::MAX);
    if order == Order::Saliency {
        clock.analysis_ms.push(t.elapsed().as_secs_f64() * 1e3);
    }
    for r in &mut regions {
        r.priority = match order {
            Order::Saliency => r.priority,
            Order::Uniform => 1.0,
            Order::Random => {
                let place = (r.rect.x0 as u64) << 32 | r.rect.y0 as u64;
                (hash64(seed ^ hash64(frame as u64 ^ hash64(r.id as u64 ^ hash64(place)))) >> 40)
                    as f32
                    / (1u64 << 24) as f32
            }
        };
    }
    regions
}

/// One frame of one simulated viewer: plan, trace, cache, splat; returns the corrected frame.
fn step(
    sim: &mut Sim,
    f: &FrameImages,
    tracer: &CorrectionTracer<'_>,
    clock: &mut Clock,
) -> Result<Vec<[f32; 3]>> {
    let w = f.gbuffer.width as usize;
    let planned = sim.corrector.plan(&f.ids, w, sim.budget);
    let t = Instant::now();
    let samples: Vec<Sample> = planned
        .par_iter()
        .map(|p| trace_sample(tracer, f, p))
        .collect();
    clock.trace_s += t.elapsed().as_secs_f64();
    clock.traced += samples.len();
    sim.corrector.add(&samples)?;
    let mut color = f.base.clone();
    let mut written = vec![false; color.len()];
    let t = Instant::now();
    sim.corrector.splat(
        &f.view,
        &mut SplatTarget {
            color: &mut color,
            written: &mut written,
            ids: &f.ids,
            depth: &f.gbuffer.depth,
        },
    );
    clock.splat_ms.push(t.elapsed().as_secs_f64() * 1e3);
    clock.cache_sizes.push(sim.corrector.cache().len());
    Ok(color)
}

/// The frame as `corrector`'s viewer sees it before this frame's new samples: the base frame
/// with the cache splatted.
fn shown(corrector: &Corrector, f: &FrameImages) -> Vec<[f32; 3]> {
    let mut color = f.base.clone();
    let mut written = vec![false; color.len()];
    corrector.splat(
        &f.view,
        &mut SplatTarget {
            color: &mut color,
            written: &mut written,
            ids: &f.ids,
            depth: &f.gbuffer.depth,
        },
    );
    color
}

fn new_corrector(hierarchy: Hierarchy, decay: f32) -> Result<Corrector> {
    Ok(Corrector::new(
        hierarchy,
        CacheConfig::default(),
        DEFAULT_JOB_SIZE,
        decay,
    )?)
}

/// Runs `psao corrective eval`.
pub fn run(args: &EvalArgs) -> Result<()> {
    if args.budget.is_empty() || args.budget.contains(&0) {
        bail!("--budget needs positive sample counts");
    }
    if args.order.is_empty() {
        bail!("--order needs at least one ordering");
    }
    if args.analyze_every == 0 {
        bail!("--analyze-every must be at least 1");
    }
    if !(0.0..1.0).contains(&args.decay) {
        bail!("--decay must be in [0, 1), got {}", args.decay);
    }
    let (mut input, path) = args.input.load()?;
    input.scene.freeze();
    let scene = &input.scene;
    let count = path.frame_count() as u32;
    let range = FrameRange::within_path(
        Some(args.frames.unwrap_or(FrameRange {
            start: 0,
            end: 48.min(count),
        })),
        count,
    )?;
    let (w, h) = (args.res.width, args.res.height);
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let backend = Backend::compiled()[0];
    let primary = Tracer::new(backend, scene, GeometryMode::Primary)?;
    let occlusion = Tracer::new(backend, scene, GeometryMode::Occlusion)?;
    let shade = TracedAoShade {
        tracer: &occlusion,
        shading: psao_client::Shading::default(),
        radius: scene.ao_radius,
        spp: args.ao_spp,
        seed: args.seed,
    };
    let settings = TraceSettings {
        sky: glam::Vec3::from_array(psao_client::SKY_GREY),
        seed: args.seed,
        ..TraceSettings::default()
    };
    let tracer = CorrectionTracer::new(scene, &primary, &shade, settings);
    let hierarchy = Hierarchy::for_spacing(w.min(h) as f32 / 4.0);

    let mut sims: Vec<Sim> = Vec::new();
    for &order in &args.order {
        for &budget in &args.budget {
            sims.push(Sim {
                order,
                budget,
                corrector: new_corrector(hierarchy, args.decay)?,
                sums: FrameError::default(),
            });
        }
    }
    let mut base_sum = FrameError::default();
    let mut per_frame = Vec::new();
    let mut clock = Clock::default();
    let mut camera_age = 0u32;
    let mut previous = None;
    let frames = range.end - range.start;
    let bar = progress::bar(frames as u64, "corrective eval", "frames");
    let show = range.start + frames / 2;
    for frame in range.start..range.end {
        let camera = path.camera_at_frame(frame as usize);
        let moved = previous.is_some_and(|p| p != camera);
        if moved {
            camera_age += 1;
        }
        previous = Some(camera);
        let f = frame_images(scene, camera, camera_age, w, h, &shade, &tracer);
        let base_err = frame_error(
            &f.reference_srgb,
            &f.base,
            &f.reference_saliency.values,
            w,
            h,
        );
        accumulate(&mut base_sum, &base_err);
        per_frame.push(FrameRow {
            frame,
            order: "base".into(),
            budget: 0,
            error: base_err,
            cache_size: 0,
        });
        let analyze_now = (frame - range.start) % args.analyze_every == 0;
        for sim in &mut sims {
            if moved {
                let t = Instant::now();
                sim.corrector.camera_changed(&f.view);
                clock.aging_ms.push(t.elapsed().as_secs_f64() * 1e3);
            }
            if analyze_now {
                let now = shown(&sim.corrector, &f);
                let regions = priorities(sim.order, &f, &now, args.seed, frame, &mut clock);
                sim.corrector.analyze(&regions);
            }
            let corrected = step(sim, &f, &tracer, &mut clock)?;
            let e = frame_error(
                &f.reference_srgb,
                &corrected,
                &f.reference_saliency.values,
                w,
                h,
            );
            accumulate(&mut sim.sums, &e);
            per_frame.push(FrameRow {
                frame,
                order: sim.order.name().into(),
                budget: sim.budget,
                error: e,
                cache_size: sim.corrector.cache().len(),
            });
            let largest = args.budget.iter().max().copied().unwrap_or(0);
            if frame == show && sim.budget == largest && sim.order == args.order[0] {
                write_rgb_png(
                    &args.out.join("corrected.png"),
                    w,
                    h,
                    psao_client::composite_srgb8(&corrected),
                )?;
            }
        }
        if frame == show {
            write_rgb_png(
                &args.out.join("base.png"),
                w,
                h,
                psao_client::composite_srgb8(&f.base),
            )?;
            write_rgb_png(
                &args.out.join("reference.png"),
                w,
                h,
                f.reference_srgb.clone(),
            )?;
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    let n = frames as f64;
    let mut rows = vec![Row {
        order: "base".into(),
        budget: 0,
        psnr: base_sum.psnr / n,
        flip: base_sum.flip / n,
        saliency_flip: base_sum.saliency_flip / n,
    }];
    rows.extend(sims.iter().map(|s| Row {
        order: s.order.name().into(),
        budget: s.budget,
        psnr: s.sums.psnr / n,
        flip: s.sums.flip / n,
        saliency_flip: s.sums.saliency_flip / n,
    }));

    let convergence =
        static_convergence(args, scene, &path, hierarchy, &shade, &tracer, &mut clock)?;
    let curves: Vec<Curve> = convergence
        .iter()
        .map(|c| Curve {
            label: c.order.clone(),
            points: c.curve.iter().map(|&(s, f, _)| (s as f64, f)).collect(),
        })
        .collect();
    convergence_plot(&args.out.join("convergence.svg"), &curves)?;

    let timing = Timing {
        worker_samples_per_s: clock.traced as f64 / clock.trace_s.max(1e-9),
        threads: rayon::current_num_threads(),
        aging_ms: mean(&clock.aging_ms),
        splat_ms: mean(&clock.splat_ms),
        analysis_ms: mean(&clock.analysis_ms),
        mean_cache_size: clock.cache_sizes.iter().sum::<usize>() as f64
            / clock.cache_sizes.len().max(1) as f64,
        max_cache_size: clock.cache_sizes.iter().copied().max().unwrap_or(0),
    };
    let report = Report {
        scene: input.name.clone(),
        res: args.res.to_string(),
        frames: format!("{}..{}", range.start, range.end),
        levels: hierarchy.levels(),
        rows,
        per_frame,
        convergence,
        timing,
    };
    let json = serde_json::to_string_pretty(&report)?;
    std::fs::write(args.out.join("report.json"), json)
        .with_context(|| format!("cannot write {}", args.out.join("report.json").display()))?;
    std::fs::write(args.out.join("report.md"), markdown(&report, args))
        .with_context(|| format!("cannot write {}", args.out.join("report.md").display()))?;
    println!("{}", table(&report.rows));
    Ok(())
}

fn accumulate(sum: &mut FrameError, e: &FrameError) {
    sum.psnr += e.psnr;
    sum.flip += e.flip;
    sum.saliency_flip += e.saliency_flip;
}

/// The static-view run: the first frame's camera, the first budget, per ordering.
fn static_convergence(
    args: &EvalArgs,
    scene: &psao_scene::Scene,
    path: &psao_scene::CameraPath,
    hierarchy: Hierarchy,
    shade: &TracedAoShade<'_>,
    tracer: &CorrectionTracer<'_>,
    clock: &mut Clock,
) -> Result<Vec<Convergence>> {
    let (w, h) = (args.res.width, args.res.height);
    let start = args.frames.map_or(0, |r| r.start);
    let camera = path.camera_at_frame(start as usize);
    let f = frame_images(scene, camera, 0, w, h, shade, tracer);
    let non_diffuse = f.ids.iter().filter(|&&i| i != 0).count();
    let budget = args.budget[0];
    let mut out = Vec::new();
    for &order in &args.order {
        let mut sim = Sim {
            order,
            budget,
            corrector: new_corrector(hierarchy, args.decay)?,
            sums: FrameError::default(),
        };
        let mut curve = Vec::new();
        let mut traced = 0;
        let mut last = f.base.clone();
        for i in 0..args.static_frames {
            if i % args.analyze_every == 0 {
                let now = shown(&sim.corrector, &f);
                let regions = priorities(order, &f, &now, args.seed, i, clock);
                sim.corrector.analyze(&regions);
            }
            let before = sim.corrector.cache().len();
            last = step(&mut sim, &f, tracer, clock)?;
            traced += sim.corrector.cache().len() - before;
            let e = frame_error(&f.reference_srgb, &last, &f.reference_saliency.values, w, h);
            curve.push((traced, e.flip, e.saliency_flip));
        }
        let bit_identical = (0..f.ids.len())
            .filter(|&i| f.ids[i] != 0)
            .all(|i| last[i] == f.reference[i]);
        out.push(Convergence {
            order: order.name().into(),
            budget,
            non_diffuse_pixels: non_diffuse,
            samples_traced: traced,
            bit_identical,
            curve,
        });
    }
    Ok(out)
}

fn table(rows: &[Row]) -> String {
    let mut s = String::from("| order | samples / frame | PSNR (dB) | FLIP | saliency-weighted FLIP |\n|---|---|---|---|---|\n");
    for r in rows {
        s += &format!(
            "| {} | {} | {:.2} | {:.4} | {:.4} |\n",
            r.order, r.budget, r.psnr, r.flip, r.saliency_flip
        );
    }
    s
}

fn markdown(r: &Report, args: &EvalArgs) -> String {
    let mut s = format!(
        "# Corrective splatting evaluation\n\nScene `{}`, {}, frames {}, {} √5 levels, analysis every {} frames, {} AO rays per point of the base shading, seed {}.\n\n",
        r.scene, r.res, r.frames, r.levels, args.analyze_every, args.ao_spp, args.seed
    );
    s += "## Averages over the frames (against the reference)\n\n";
    s += &table(&r.rows);
    s += "\n## Static view (first frame's camera)\n\n| order | samples / frame | non-diffuse pixels | samples traced | bit-identical at the end |\n|---|---|---|---|---|\n";
    for c in &r.convergence {
        s += &format!(
            "| {} | {} | {} | {} | {} |\n",
            c.order, c.budget, c.non_diffuse_pixels, c.samples_traced, c.bit_identical
        );
    }
    s += "\n![FLIP against samples](convergence.svg)\n\n## Timing\n\n";
    let t = &r.timing;
    s += &format!(
        "| worker samples/s | threads | aging ms | reprojection + splatting ms | analysis ms | mean cache size | max cache size |\n|---|---|---|---|---|---|---|\n| {:.0} | {} | {:.3} | {:.3} | {:.1} | {:.0} | {} |\n",
        t.worker_samples_per_s, t.threads, t.aging_ms, t.splat_ms, t.analysis_ms, t.mean_cache_size, t.max_cache_size
    );
    s += "\nImages of the middle frame: `base.png`, `corrected.png` (first ordering, largest budget), `reference.png`.\n";
    s
}
