//! `psao corrective eval`: parses the arguments, runs the evaluation of
//! [`psao_eval::corrective`] and writes its reports and images.

use super::plot::{convergence_plot, Curve};
use crate::args::{FrameRange, Resolution};
use crate::png_io::write_rgb_png;
use crate::progress;
use crate::reference::Lighting;
use crate::scene_source::SceneArgs;
use anyhow::{Context, Result};
use clap::Args;
use psao_corrective::schedule::DEFAULT_DECAY;
use psao_eval::corrective::report::{path_markdown, rows_table, seeds_markdown, summary_table};
use psao_eval::corrective::seeds::{evaluate_seeds, Paths};
use psao_eval::corrective::{Budget, EvalConfig, GiEval, Order, PathEval, Tracers};
use psao_scene::{PathGenConfig, PATH_HZ};
use serde::Serialize;
use std::path::{Path, PathBuf};

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
    #[arg(long, value_delimiter = ',', default_value = "150,600", value_parser = positive_count)]
    pub budget: Vec<usize>,
    /// Milliseconds of tracing per frame, comma-separated (the paper's 1/f; timing-dependent),
    /// evaluated next to the sample budgets.
    #[arg(long, value_delimiter = ',')]
    pub budget_ms: Vec<f64>,
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
    /// Frames of the static-view convergence run (at the first frame's camera, first
    /// budget; 0: none).
    #[arg(long, default_value_t = 60)]
    pub static_frames: u32,
    /// Seed of every random choice.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Largest turn in degrees of a mirror sample's view direction before the cache drops
    /// it (the GGX lobe width roughness² is added for glossy surfaces; `inf`: the paper's
    /// aging only).
    #[arg(long, default_value_t = 1.0)]
    pub mirror_turn: f32,
    /// The session's lighting: `ao` (the base is the AO composite, the reference shades
    /// diffuse pixels the same way) or `gi` (the base is the lit composite, the reference is
    /// the path-traced diffuse lighting plus the reflected and refracted paths).
    #[arg(long, value_enum, default_value_t = Lighting::Ao)]
    pub lighting: Lighting,
    /// Indirect diffuse bounces with `--lighting gi`.
    #[arg(long, default_value_t = 1)]
    pub bounces: u32,
    /// Paths per point of the lit base frame and of the samples' diffuse shading.
    #[arg(long, default_value_t = 16)]
    pub base_paths: u32,
    /// Paths per point of the lit reference.
    #[arg(long, default_value_t = 64)]
    pub reference_paths: u32,
    /// What samples carry: `full` radiance (their own surface's diffuse light included), a
    /// correction relative to the base at the pixel they land on, or the `view-dependent`
    /// part only, added over the base's diffuse share. Default: `full` with `--lighting
    /// ao`, `view-dependent` with `--lighting gi` (as the split); the other to compare.
    #[arg(long, value_enum)]
    pub samples: Option<SampleKind>,
    /// Seeds, comma-separated: one run per seed (replaces `--seed`), reported as mean and
    /// spread over the seeds.
    #[arg(long, value_delimiter = ',')]
    pub seeds: Vec<u64>,
    /// Evaluate on this many camera paths generated per seed through the scene's free
    /// space instead of `--path`.
    #[arg(long)]
    pub random_paths: Option<usize>,
    /// Path frames to dump per ordering and budget (`dump/` of `--out`: every non-diffuse
    /// pixel's base, corrected and reference values and every cached sample), comma-separated.
    #[arg(long, value_delimiter = ',')]
    pub dump_frames: Vec<u32>,
    /// Output directory.
    #[arg(long)]
    pub out: PathBuf,
}

/// What correction samples carry (`--samples`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum SampleKind {
    /// The full radiance.
    Full,
    /// The view-dependent part.
    ViewDependent,
}

/// A positive count.
fn positive_count(s: &str) -> Result<usize> {
    match s.trim().parse::<usize>() {
        Ok(0) => anyhow::bail!("must be positive"),
        Ok(n) => Ok(n),
        Err(e) => Err(e).context("not a count"),
    }
}

/// The report of runs over seeds, with what they ran on.
#[derive(Serialize)]
struct SeedsFile<'a> {
    scene: &'a str,
    res: String,
    paths: String,
    #[serde(flatten)]
    report: &'a psao_eval::corrective::seeds::SeedsReport,
}

/// The report of one run along one path.
#[derive(Serialize)]
struct PathFile<'a> {
    scene: &'a str,
    res: String,
    #[serde(flatten)]
    eval: &'a PathEval,
}

/// Runs `psao corrective eval`.
pub fn run(args: &EvalArgs) -> Result<()> {
    anyhow::ensure!(
        args.bounces <= psao_server::MAX_BOUNCES,
        "--bounces must be at most {}, got {}",
        psao_server::MAX_BOUNCES,
        args.bounces
    );
    let (mut input, path) = args.input.load()?;
    input.scene.freeze();
    let scene = &input.scene;
    let config = EvalConfig {
        width: args.res.width,
        height: args.res.height,
        frames: args.frames.map(|r| r.start..r.end),
        budgets: (args.budget.iter().map(|&n| Budget::Samples(n)))
            .chain(args.budget_ms.iter().map(|&ms| Budget::Ms(ms)))
            .collect(),
        orders: args.order.clone(),
        decay: args.decay,
        analyze_every: args.analyze_every,
        ao_spp: args.ao_spp,
        static_frames: args.static_frames,
        seed: args.seed,
        mirror_turn: args.mirror_turn.to_radians(),
        lighting: (args.lighting == Lighting::Gi).then_some(GiEval {
            bounces: args.bounces,
            base_paths: args.base_paths,
            reference_paths: args.reference_paths,
        }),
        dump_frames: args.dump_frames.clone(),
        full_samples: match args.samples {
            Some(kind) => kind == SampleKind::Full,
            None => args.lighting == Lighting::Ao,
        },
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let tracers = Tracers::new(scene)?;
    let seeds = if args.seeds.is_empty() {
        vec![args.seed]
    } else {
        args.seeds.clone()
    };
    let (paths, described) = match args.random_paths {
        Some(count) => {
            // Long enough for the frames asked for (at least 4 s, so a walk turns).
            let frames_end = config.frames.as_ref().map_or(48, |r| r.end);
            let duration_s = (frames_end as f32 / PATH_HZ).max(4.0);
            let paths = Paths::Generated {
                count,
                config: PathGenConfig {
                    duration_s,
                    ..PathGenConfig::default()
                },
            };
            (
                paths,
                format!("{count} generated paths per seed ({duration_s} s each)"),
            )
        }
        None => (Paths::Fixed(&path), format!("path `{}`", path.name)),
    };
    let per_path = config.frames.as_ref().map_or(48, |r| r.len());
    let paths_per_seed = args.random_paths.unwrap_or(1);
    let bar = progress::bar(
        (seeds.len() * paths_per_seed * per_path) as u64,
        "corrective eval",
        "frames",
    );
    let report = evaluate_seeds(scene, &tracers, &paths, &seeds, &config, &mut || bar.inc(1))?;
    bar.finish_and_clear();
    let first = report
        .runs
        .first()
        .and_then(|r| r.paths.first())
        .context("the evaluation ran no path")?;
    write_path_outputs(&args.out, &input.name, args, &config, first)?;
    write_dumps(&args.out, &report)?;
    if seeds.len() > 1 || paths_per_seed > 1 {
        let file = SeedsFile {
            scene: &input.name,
            res: args.res.to_string(),
            paths: described.clone(),
            report: &report,
        };
        write_text(
            &args.out.join("seeds.json"),
            &serde_json::to_string_pretty(&file)?,
        )?;
        write_text(
            &args.out.join("seeds.md"),
            &seeds_markdown(&input.name, &config, &described, &report),
        )?;
        println!("{}", summary_table(&report));
    } else {
        println!("{}", rows_table(&first.rows));
    }
    Ok(())
}

/// The frame dumps of every run, as `dump/s{seed}_{path}_{order}_{budget}_f{frame}.json`.
fn write_dumps(out: &Path, report: &psao_eval::corrective::seeds::SeedsReport) -> Result<()> {
    let dumps = report.runs.iter().flat_map(|r| {
        r.paths
            .iter()
            .flat_map(move |p| p.dumps.iter().map(move |d| (r.seed, d)))
    });
    for (i, (seed, d)) in dumps.enumerate() {
        if i == 0 {
            std::fs::create_dir_all(out.join("dump"))?;
        }
        let budget = d.budget.to_string().replace(' ', "");
        let name = format!("s{seed}_{}_{}_{budget}_f{}.json", d.path, d.order, d.frame);
        write_text(&out.join("dump").join(name), &serde_json::to_string(d)?)?;
    }
    Ok(())
}

fn write_text(file: &Path, text: &str) -> Result<()> {
    std::fs::write(file, text).with_context(|| format!("cannot write {}", file.display()))
}

/// `report.json`, `report.md`, `convergence.svg` and the middle frame's PNGs of one run.
fn write_path_outputs(
    out: &Path,
    scene: &str,
    args: &EvalArgs,
    config: &EvalConfig,
    eval: &PathEval,
) -> Result<()> {
    let (w, h) = (args.res.width, args.res.height);
    if let Some(m) = &eval.middle {
        write_rgb_png(&out.join("base.png"), w, h, m.base.clone())?;
        write_rgb_png(&out.join("corrected.png"), w, h, m.corrected.clone())?;
        write_rgb_png(&out.join("reference.png"), w, h, m.reference.clone())?;
    }
    if !eval.convergence.is_empty() {
        let curves: Vec<Curve> = eval
            .convergence
            .iter()
            .map(|c| Curve {
                label: c.order.clone(),
                points: c.curve.iter().map(|&(s, f, _)| (s as f64, f)).collect(),
            })
            .collect();
        convergence_plot(&out.join("convergence.svg"), &curves)?;
    }
    let file = PathFile {
        scene,
        res: args.res.to_string(),
        eval,
    };
    write_text(
        &out.join("report.json"),
        &serde_json::to_string_pretty(&file)?,
    )?;
    let config = EvalConfig {
        seed: eval_seed(args),
        ..config.clone()
    };
    write_text(&out.join("report.md"), &path_markdown(scene, &config, eval))
}

/// The seed of the first run.
fn eval_seed(args: &EvalArgs) -> u64 {
    args.seeds.first().copied().unwrap_or(args.seed)
}
