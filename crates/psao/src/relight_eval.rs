//! `psao relight eval`: fit errors and image quality of shadowed relighting against a Monte
//! Carlo reference on poses that training never saw (by default the clip's last quarter,
//! or another clip of the character), their visibility traced with rays independent of
//! training's; writes `report.json`, `report.md` and side-by-side pictures.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use psao_eval::{AoImage, Metrics};
use psao_prt::character::Character;
use psao_prt::fade::{self, FadeRule};
use psao_prt::filter::Filter;
use psao_prt::lighting::{EnvMap, Radiance, LUMINANCE};
use psao_prt::model::{cosine_fit_errors, mean_std, model_errors, PoseLimits, PoseModel, Sample};
use psao_prt::reference::{reference_shading, ReferenceSettings};
use psao_prt::shade::{Mode, Shader, ShadingGeometry, Visibility};
use psao_prt::visibility::SelfTracer;
use serde::Serialize;

use crate::args::{FrameRange, Resolution};
use crate::png_io::write_rgb_png;
use crate::relight_cmd::{
    frame_range, gather, gather_split, split, train_model, ModeArg, ShadingArgs,
};
use crate::relight_io::{
    clip_frames, display, exposure_for, framing_camera, load_character, load_env, VertexImage, FPS,
};

/// Arguments of `psao relight eval`.
#[derive(Args, Debug)]
pub struct EvalArgs {
    /// The skinned character (glTF/GLB).
    #[arg(long)]
    pub character: PathBuf,
    /// Clip name or index (default: the first clip).
    #[arg(long)]
    pub clip: Option<String>,
    /// Frames `A..B` (30 fps) to train on (default: the whole clip); frames of the test
    /// block are left out.
    #[arg(long)]
    pub train: Option<FrameRange>,
    /// Train on every K-th frame.
    #[arg(long, default_value_t = 1)]
    pub every: u32,
    /// Test frames `A..B` (30 fps), held out of training and validation (default: the
    /// last quarter of the clip, a contiguous block of poses training never saw; with
    /// `--test-clip`, the whole test clip).
    #[arg(long)]
    pub test: Option<FrameRange>,
    /// Test on another clip of the same character (name or index): train on `--clip`,
    /// test on this one.
    #[arg(long)]
    pub test_clip: Option<String>,
    /// Number of test frames evaluated, evenly spread over the test block.
    #[arg(long, default_value_t = 8)]
    pub tests: usize,
    /// Radiance `.hdr` environment map.
    #[arg(long)]
    pub env: PathBuf,
    #[command(flatten)]
    pub shading: ShadingArgs,
    /// Evaluate each of these modes with the same models and test frames (reports in
    /// `OUT/MODE/`); default: `--mode` alone (report in `OUT`).
    #[arg(long, value_enum, value_delimiter = ',')]
    pub modes: Vec<ModeArg>,
    /// Compare these visibility filters (each shadowed method is shaded with each, named
    /// `method:filter`); default: `--filter` alone.
    #[arg(long, value_delimiter = ',')]
    pub filters: Vec<Filter>,
    /// Also shade each model with parts of its protection against unseen poses switched
    /// off (methods `lobesN-VARIANT`): `unlimited` (poses not moved into the training
    /// poses' limits), `box` (the limits' box without their ball), `noshrink` (no
    /// per-vertex shrink towards the average lobes), `plain` (box only, no shrink),
    /// `nofade` (shadows not blended towards unoccluded as the pose leaves the training
    /// poses' box; `fade`, `fade2`: blended in every mode, by the pose's coverage or its
    /// square).
    #[arg(long, value_enum, value_delimiter = ',')]
    pub variants: Vec<Variant>,
    /// Lobe counts to train and compare.
    #[arg(long, value_delimiter = ',', default_value = "1,2,3")]
    pub lobes: Vec<usize>,
    /// Visibility rays per vertex and frame.
    #[arg(long, default_value_t = 512)]
    pub rays: u32,
    /// Reference samples per vertex.
    #[arg(long, default_value_t = 2048)]
    pub ref_samples: u32,
    /// Lighting the reference integrates: the full-resolution map, or its order-4 SH
    /// projection (the run time's lighting, which leaves visibility as the only difference).
    #[arg(long, value_enum, default_value_t = RefLighting::Full)]
    pub ref_lighting: RefLighting,
    /// Image size.
    #[arg(long, default_value = "480x480")]
    pub res: Resolution,
    /// Seed of all sampling.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output folder.
    #[arg(long)]
    pub out: PathBuf,
}

/// A model with parts of its protection against unseen poses switched off.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Variant {
    /// No pose limits (shrink kept).
    Unlimited,
    /// The limits' box without their ball (shrink kept).
    Box,
    /// Shadows never blended towards unoccluded (see `psao_prt::fade`).
    Nofade,
    /// Shadows blended towards unoccluded by the pose's coverage in every mode.
    Fade,
    /// As `fade` with the coverage squared.
    Fade2,
    /// No per-vertex shrink (limits kept).
    Noshrink,
    /// The box alone, no ball and no shrink.
    Plain,
}

impl Variant {
    /// The method name's suffix.
    fn tag(self) -> &'static str {
        match self {
            Variant::Unlimited => "-unlimited",
            Variant::Box => "-box",
            Variant::Noshrink => "-noshrink",
            Variant::Plain => "-plain",
            Variant::Nofade => "-nofade",
            Variant::Fade => "-fade",
            Variant::Fade2 => "-fade2",
        }
    }

    /// This variant of the trained `model` (`unshrunk`: the same before its shrink).
    fn of(self, model: &PoseModel, unshrunk: &PoseModel) -> Method {
        let (base, limits) = match self {
            Variant::Unlimited => (model, PoseLimits::default()),
            Variant::Box => (model, model.limits.box_only()),
            Variant::Noshrink => (unshrunk, unshrunk.limits.clone()),
            Variant::Plain => (unshrunk, unshrunk.limits.box_only()),
            Variant::Nofade | Variant::Fade | Variant::Fade2 => (model, model.limits.clone()),
        };
        let fade = match self {
            Variant::Nofade => Some(FadeRule::NONE),
            Variant::Fade => Some(FadeRule { power: 1.0 }),
            Variant::Fade2 => Some(FadeRule { power: 2.0 }),
            _ => None,
        };
        Method {
            model: PoseModel {
                limits,
                ..base.clone()
            },
            fade,
        }
    }
}

/// A model as shaded: its weights and limits, and how it fades its shadows.
struct Method {
    model: PoseModel,
    /// `None`: as the mode does by default (`FadeRule::of_mode`).
    fade: Option<FadeRule>,
}

impl Method {
    /// The model's raw outputs at the pose of `joint_rotations`, faded for `mode`, into
    /// `raw`.
    fn predict(&self, mode: Mode, joint_rotations: &[glam::Vec3], raw: &mut Vec<f32>) {
        let rule = self.fade.unwrap_or_else(|| FadeRule::of_mode(mode));
        fade::predict(&self.model, rule, joint_rotations, raw);
    }
}

/// The lighting of the reference.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum RefLighting {
    /// The environment map at full resolution.
    Full,
    /// The order-4 SH projection of the map.
    Sh,
}

/// Fit error of one lobe count.
#[derive(Clone, Serialize)]
struct FitError {
    lobes: usize,
    /// Mean RMS-over-the-sphere error of the model's visibility on the test frames.
    mean: f32,
    std: f32,
    /// The 99th percentile of the per-vertex errors (the badly predicted vertices).
    p99: f32,
    /// The direct lobe fit's error on the training frames (before the linear model).
    lobe_fit_mean: f32,
    lobe_fit_std: f32,
    train_s: f64,
    model_mb: f64,
    ridge: f64,
    ms_per_frame: f64,
    /// Per test frame: its pose's distance from the training poses' mean as a multiple of
    /// the farthest training pose's (the pose limits' ball; `null` without one).
    pose_reach: Vec<Option<f32>>,
    /// Per test frame: the share of its pose's departure from the training mean that the
    /// limits' box keeps (`PoseLimits::coverage`; 1 inside the box).
    pose_coverage: Vec<f32>,
}

/// Averages of one method.
#[derive(Serialize)]
struct MethodRow {
    name: String,
    psnr: f64,
    ssim: f64,
    flip: f64,
    /// Smallest PSNR gain over `unshadowed` on any test frame (dB; positive: better on all).
    worst_psnr_gain: f64,
    /// Smallest FLIP reduction from `unshadowed` on any test frame (positive: better on all).
    worst_flip_gain: f64,
}

/// One method on one test frame.
#[derive(Serialize)]
struct FrameRow {
    name: String,
    time_s: f32,
    psnr: f64,
    ssim: f64,
    flip: f64,
}

/// The paper's Fig. 3: lobes fitted to plain vs cosine-weighted SH visibility (see
/// `psao_prt::model::cosine_fit_errors`), mean and standard deviation.
#[derive(Clone, Serialize)]
struct ShFit {
    lobes: usize,
    plain: (f32, f32),
    cosine: (f32, f32),
    plain_convolved: (f32, f32),
}

#[derive(Serialize)]
struct Report {
    character: String,
    clip: String,
    /// The clip the test frames come from.
    test_clip: String,
    /// The test frames' block (clip frames at 30 fps, end excluded).
    test_frames: [u32; 2],
    mode: String,
    vertices: usize,
    /// Skinned primitives (glTF node × primitive) merged into the character.
    primitives: usize,
    train_frames: usize,
    validation_frames: usize,
    test_times_s: Vec<f32>,
    rays: u32,
    ref_samples: u32,
    ref_lighting: RefLighting,
    /// The visibility filters compared (the first is `--filter`'s, or the only one).
    filters: Vec<String>,
    fit_error: Vec<FitError>,
    /// Fig. 3: plain vs cosine-weighted visibility.
    sh_fit: Vec<ShFit>,
    methods: Vec<MethodRow>,
    /// A second reference with independent samples against the first (the noise floor).
    reference_noise: MethodRow,
    frames: Vec<FrameRow>,
    /// The reseeded reference per test frame.
    reference_noise_frames: Vec<FrameRow>,
}

/// The averages of method `name` over the test frames of `rows`, and its worst frame's gain
/// over `unshadowed` (0 for `unshadowed` itself and for methods with no such frames).
fn method_row(name: &str, rows: &[FrameRow]) -> MethodRow {
    let r: Vec<&FrameRow> = rows.iter().filter(|r| r.name == name).collect();
    let avg = |f: fn(&FrameRow) -> f64| r.iter().map(|x| f(x)).sum::<f64>() / r.len() as f64;
    let worst = |f: fn(&FrameRow, &FrameRow) -> f64| {
        r.iter()
            .filter_map(|x| {
                rows.iter()
                    .find(|u| u.name == "unshadowed" && u.time_s == x.time_s)
                    .map(|u| f(x, u))
            })
            .fold(None, |m: Option<f64>, g| Some(m.map_or(g, |m| m.min(g))))
            .unwrap_or(0.0)
    };
    MethodRow {
        name: name.to_string(),
        psnr: avg(|x| x.psnr),
        ssim: avg(|x| x.ssim),
        flip: avg(|x| x.flip),
        worst_psnr_gain: worst(|x, u| x.psnr - u.psnr),
        worst_flip_gain: worst(|x, u| u.flip - x.flip),
    }
}

/// Runs `psao relight eval`.
pub fn run(args: &EvalArgs) -> Result<()> {
    if args.lobes.is_empty() || args.lobes.iter().any(|l| !(1..=3).contains(l)) {
        bail!("--lobes takes counts among 1, 2 and 3");
    }
    if args.tests == 0 || args.rays == 0 || args.ref_samples == 0 {
        bail!("--tests, --rays and --ref-samples must be at least 1");
    }
    let loaded = load_character(&args.character, args.clip.as_deref())?;
    let other = match &args.test_clip {
        Some(clip) => Some(load_character(&args.character, Some(clip))?),
        None => None,
    };
    let env = load_env(&args.env)?;
    let modes: Vec<(ModeArg, Mode)> = if args.modes.is_empty() {
        vec![(args.shading.mode, args.shading.mode()?)]
    } else {
        args.modes
            .iter()
            .map(|&m| {
                let shading = ShadingArgs {
                    mode: m,
                    ..args.shading.clone()
                };
                Ok((m, shading.mode()?))
            })
            .collect::<Result<_>>()?
    };
    let c = &loaded.character;
    // The character playing the test clip (the same file, so the same joints and vertices).
    let tc = other.as_ref().map_or(c, |o| &o.character);
    let block = match (args.test, &other) {
        (Some(t), _) => frame_range(tc, Some(t)).context("--test")?,
        (None, Some(_)) => frame_range(tc, None)?,
        (None, None) => last_quarter(clip_frames(tc)),
    };
    if block.start >= block.end {
        bail!("the test block {}..{} is empty", block.start, block.end);
    }
    let range = frame_range(c, args.train)?;
    let split = split(range, args.every, other.is_none().then_some(block))?;
    let test_times = test_times(block, args.tests);
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;

    let (train_set, validate) = gather_split(c, &split, args.rays, args.seed)?;
    // Test visibility with rays independent of training's.
    let tests = gather(
        tc,
        &test_times,
        args.rays,
        args.seed ^ TEST_SEED,
        "tracing test frames",
    )?;

    // Per lobe count: the model and its variants, each with its method name.
    let mut models: Vec<(usize, Vec<(String, Method)>)> = Vec::new();
    let mut fit_error = Vec::new();
    for &lobes in &args.lobes {
        let start = Instant::now();
        let (model, report) = train_model(&loaded.name, &train_set, &validate, lobes)?;
        let train_s = start.elapsed().as_secs_f64();
        let mut errors = model_errors(&model, &tests);
        let (mean, std) = mean_std(errors.iter().copied());
        errors.sort_by(f32::total_cmp);
        fit_error.push(FitError {
            lobes,
            mean,
            std,
            p99: errors[(errors.len() * 99 / 100).min(errors.len() - 1)],
            lobe_fit_mean: report.lobe_fit_error.0,
            lobe_fit_std: report.lobe_fit_error.1,
            train_s,
            model_mb: model.megabytes(),
            ridge: report.ridge,
            ms_per_frame: 0.0,
            pose_reach: tests
                .iter()
                .map(|s| {
                    let pose = model.raw_pose_vector(&s.joint_rotations);
                    model.limits.reach(&pose[1..])
                })
                .collect(),
            pose_coverage: tests
                .iter()
                .map(|s| {
                    let pose = model.raw_pose_vector(&s.joint_rotations);
                    model.limits.coverage(&pose[1..])
                })
                .collect(),
        });
        let variants = args.variants.iter().map(|v| {
            (
                format!("lobes{lobes}{}", v.tag()),
                v.of(&model, &report.unshrunk),
            )
        });
        let named: Vec<(String, Method)> = variants.collect();
        let default = Method { model, fade: None };
        let all = std::iter::once((format!("lobes{lobes}"), default)).chain(named);
        models.push((lobes, all.collect()));
    }

    // Fig. 3 on at most FIG3_FRAMES training frames spread over the set.
    let fig3_frames: Vec<_> = (0..FIG3_FRAMES.min(train_set.len()))
        .map(|k| train_set[k * train_set.len() / FIG3_FRAMES.min(train_set.len())].clone())
        .collect();
    let sh_fit: Vec<ShFit> = args
        .lobes
        .iter()
        .map(|&lobes| {
            let e = cosine_fit_errors(&fig3_frames, lobes);
            ShFit {
                lobes,
                plain: e.plain,
                cosine: e.cosine,
                plain_convolved: e.plain_convolved,
            }
        })
        .collect();

    let shared = Shared {
        args,
        name: &loaded.name,
        clip: c.clip_name(),
        tc,
        block,
        train_frames: train_set.len(),
        validation_frames: validate.len(),
        test_times: &test_times,
        tests: &tests,
        models: &models,
        fit_error: &fit_error,
        sh_fit: &sh_fit,
        env: &env,
    };
    for &(arg, mode) in &modes {
        let out = if args.modes.is_empty() {
            args.out.clone()
        } else {
            args.out.join(
                arg.to_possible_value()
                    .expect("no skipped modes")
                    .get_name(),
            )
        };
        std::fs::create_dir_all(&out)
            .with_context(|| format!("cannot create {}", out.display()))?;
        evaluate_mode(&shared, mode, &out)?;
    }
    Ok(())
}

/// What every mode's evaluation shares: the trained models and the test frames.
struct Shared<'a> {
    args: &'a EvalArgs,
    name: &'a str,
    clip: &'a str,
    /// The character playing the test clip.
    tc: &'a Character,
    block: FrameRange,
    train_frames: usize,
    validation_frames: usize,
    test_times: &'a [f32],
    /// The test frames' traced visibility.
    tests: &'a [Sample],
    /// Per lobe count: the model and its variants, each with its method name.
    models: &'a [(usize, Vec<(String, Method)>)],
    fit_error: &'a [FitError],
    sh_fit: &'a [ShFit],
    env: &'a EnvMap,
}

/// Renders the test frames in `mode` with every method against the reference and writes
/// the report and pictures to `out`.
fn evaluate_mode(shared: &Shared, mode: Mode, out: &std::path::Path) -> Result<()> {
    let Shared {
        args,
        tc,
        test_times,
        tests,
        models,
        env,
        ..
    } = *shared;
    let filters = if args.filters.is_empty() {
        vec![args.shading.filter]
    } else {
        args.filters.clone()
    };
    let shaders: Vec<(String, Shader)> = filters
        .iter()
        .map(|&f| {
            let suffix = if filters.len() > 1 {
                format!(":{f}")
            } else {
                String::new()
            };
            Ok((suffix, Shader::with_filter(mode, f)?))
        })
        .collect::<Result<_>>()?;
    let shader = &shaders[0].1;
    let mut fit_error = shared.fit_error.to_vec();
    let lighting = env.project();
    let radiance: &dyn Radiance = match args.ref_lighting {
        RefLighting::Full => env,
        RefLighting::Sh => &lighting,
    };
    let (w, h) = (args.res.width, args.res.height);
    let camera = framing_camera(&tc.pose(test_times[0]), w, h);
    let mut tracer = SelfTracer::new(tc.occluder_mesh())?;
    let mut image = VertexImage::new(tc);
    let mut exposure = None;
    let mut rows: Vec<FrameRow> = Vec::new();
    let mut noise_rows: Vec<FrameRow> = Vec::new();
    let mut raw = Vec::new();
    let progress = crate::progress::bar(test_times.len() as u64, "rendering test frames", "frames");
    for (k, (&t, sample)) in test_times.iter().zip(tests).enumerate() {
        let pose = tc.pose(t);
        tracer.set_pose(&pose)?;
        let reference_with = |seed: u64| -> Vec<f32> {
            reference_shading(
                &tracer,
                &pose,
                radiance,
                &ReferenceSettings {
                    mode,
                    eye: camera.position,
                    env_rotation: 0.0,
                    samples: args.ref_samples,
                    seed,
                },
            )
            .into_iter()
            .flatten()
            .collect()
        };
        let reference = reference_with(args.seed ^ 0x5245_4600 ^ k as u64);
        // The same reference with independent samples: its distance to the first is the
        // reference's own noise, below which methods cannot be told apart.
        let reseeded = reference_with(args.seed ^ 0x4e4f_4953_4500 ^ k as u64);
        image.rasterize(&pose, &camera, w, h)?;
        let ref_pixels = image.shade(&reference, 3);
        let exposure = *exposure.get_or_insert_with(|| exposure_for(&luminance(&ref_pixels)));
        let ref_image = to_image(&ref_pixels, w, h, exposure);
        let m = psao_eval::compare(
            &ref_image,
            &to_image(&image.shade(&reseeded, 3), w, h, exposure),
        )?;
        noise_rows.push(FrameRow {
            name: "reference_reseeded".into(),
            time_s: t,
            psnr: m.psnr,
            ssim: m.ssim,
            flip: m.flip,
        });
        let geometry = ShadingGeometry {
            positions: &pose.positions,
            frames: &pose.frames,
            transform: pose.transform,
        };
        let mut methods: Vec<(String, Vec<f32>)> = vec![(
            "unshadowed".into(),
            shader.shade(
                Visibility::Unshadowed,
                geometry,
                &lighting.rgb,
                camera.position,
            )?,
        )];
        for (suffix, shader) in &shaders {
            methods.push((
                format!("projected{suffix}"),
                shader.shade(
                    Visibility::Projected(&sample.visibility),
                    geometry,
                    &lighting.rgb,
                    camera.position,
                )?,
            ));
        }
        for (name, method) in models.iter().flat_map(|(_, named)| named) {
            method.predict(mode, &pose.joint_rotations, &mut raw);
            for (suffix, shader) in &shaders {
                methods.push((
                    format!("{name}{suffix}"),
                    shader.shade(
                        Visibility::Model(&method.model, &raw),
                        geometry,
                        &lighting.rgb,
                        camera.position,
                    )?,
                ));
            }
        }
        let mut pictures = vec![("reference".to_string(), ref_pixels.clone())];
        for (name, values) in &methods {
            let pixels = image.shade(values, 3);
            let m: Metrics = psao_eval::compare(&ref_image, &to_image(&pixels, w, h, exposure))?;
            rows.push(FrameRow {
                name: name.clone(),
                time_s: t,
                psnr: m.psnr,
                ssim: m.ssim,
                flip: m.flip,
            });
            pictures.push((name.clone(), pixels));
        }
        if k == 0 {
            write_pictures(out, &pictures, w, h, exposure)?;
        }
        progress.inc(1);
    }
    progress.finish_and_clear();

    // Run time: synthesis + shading per frame, median of the test frames (3 runs each).
    for (fe, (_, named)) in fit_error.iter_mut().zip(models) {
        let method = &named[0].1;
        let mut times = Vec::new();
        for &t in test_times {
            let pose = tc.pose(t);
            for _ in 0..3 {
                let start = Instant::now();
                method.predict(mode, &pose.joint_rotations, &mut raw);
                let v = shader.shade(
                    Visibility::Model(&method.model, &raw),
                    ShadingGeometry {
                        positions: &pose.positions,
                        frames: &pose.frames,
                        transform: pose.transform,
                    },
                    &[lighting.luminance()],
                    camera.position,
                )?;
                std::hint::black_box(v);
                times.push(start.elapsed().as_secs_f64() * 1e3);
            }
        }
        times.sort_by(f64::total_cmp);
        fe.ms_per_frame = times[times.len() / 2];
    }

    let names: Vec<String> = rows
        .iter()
        .map(|r| r.name.clone())
        .fold(Vec::new(), |mut v, n| {
            if !v.contains(&n) {
                v.push(n);
            }
            v
        });
    let methods: Vec<MethodRow> = names.iter().map(|n| method_row(n, &rows)).collect();
    let reference_noise = method_row("reference_reseeded", &noise_rows);
    let report = Report {
        character: shared.name.to_string(),
        clip: shared.clip.to_string(),
        test_clip: tc.clip_name().to_string(),
        test_frames: [shared.block.start, shared.block.end],
        mode: format!("{mode:?}"),
        vertices: tc.vertex_count(),
        primitives: tc.part_count(),
        train_frames: shared.train_frames,
        validation_frames: shared.validation_frames,
        test_times_s: test_times.to_vec(),
        rays: args.rays,
        ref_samples: args.ref_samples,
        ref_lighting: args.ref_lighting,
        filters: filters.iter().map(ToString::to_string).collect(),
        fit_error,
        sh_fit: shared.sh_fit.to_vec(),
        methods,
        reference_noise,
        frames: rows,
        reference_noise_frames: noise_rows,
    };
    let json = serde_json::to_string_pretty(&report)?;
    std::fs::write(out.join("report.json"), json).context("cannot write report.json")?;
    std::fs::write(out.join("report.md"), markdown(&report)).context("cannot write report.md")?;
    print!("{}", markdown(&report));
    Ok(())
}

/// Training frames the Fig. 3 fits are measured on.
const FIG3_FRAMES: usize = 4;

/// Salt of the test frames' visibility seed: their rays are independent of training's.
const TEST_SEED: u64 = 0x7465_7374;

/// The last quarter of a clip of `frames` frames (at least one frame).
pub fn last_quarter(frames: u32) -> FrameRange {
    FrameRange {
        start: (frames - frames / 4).min(frames.saturating_sub(1)),
        end: frames,
    }
}

/// `count` frames of `block` evenly spread (all of them when it has no more), in seconds.
fn test_times(block: FrameRange, count: usize) -> Vec<f32> {
    let n = (block.end - block.start) as usize;
    let count = count.min(n).max(1);
    (0..count)
        .map(|k| (block.start + (k * n / count) as u32) as f32 / FPS)
        .collect()
}

/// Per-pixel luminance of interleaved RGB.
pub fn luminance(rgb: &[f32]) -> Vec<f32> {
    rgb.chunks(3)
        .map(|p| p.iter().zip(LUMINANCE).map(|(a, b)| a * b).sum())
        .collect()
}

/// The displayed luminance image compared by the metrics.
pub fn to_image(rgb: &[f32], w: u32, h: u32, exposure: f32) -> AoImage {
    AoImage {
        width: w,
        height: h,
        data: luminance(rgb)
            .iter()
            .map(|&v| display(v, exposure))
            .collect(),
    }
}

/// Each method's picture of the first test frame, and reference | lobes2 | unshadowed side by side.
fn write_pictures(
    out: &std::path::Path,
    pictures: &[(String, Vec<f32>)],
    w: u32,
    h: u32,
    exposure: f32,
) -> Result<()> {
    for (name, p) in pictures {
        write_rgb_png(
            &out.join(format!("{name}.png")),
            w,
            h,
            to_display_bytes(p, exposure),
        )?;
    }
    let shadowed = pictures
        .iter()
        .find(|(n, _)| n == "lobes2")
        .or_else(|| pictures.iter().find(|(n, _)| n.starts_with("lobes")));
    let find = |name: &str| pictures.iter().find(|(n, _)| n == name);
    let panels: Vec<&[f32]> = [find("reference"), shadowed, find("unshadowed")]
        .into_iter()
        .flatten()
        .map(|(_, p)| p.as_slice())
        .collect();
    let (pw, side) = side_by_side(&panels, w, h, exposure);
    write_rgb_png(&out.join("side_by_side.png"), pw, h, side)
}

/// RGB `w × h` pictures (linear, interleaved) placed left to right and tone-mapped with
/// `exposure`: the combined width and its 8-bit pixels.
pub fn side_by_side(panels: &[&[f32]], w: u32, h: u32, exposure: f32) -> (u32, Vec<u8>) {
    let pw = w as usize * panels.len();
    let mut side = vec![0u8; pw * h as usize * 3];
    for (k, p) in panels.iter().enumerate() {
        let bytes = to_display_bytes(p, exposure);
        for y in 0..h as usize {
            let src = &bytes[y * w as usize * 3..(y + 1) * w as usize * 3];
            let dst = (y * pw + k * w as usize) * 3;
            side[dst..dst + src.len()].copy_from_slice(src);
        }
    }
    (pw as u32, side)
}

/// Linear values to 8-bit display values.
fn to_display_bytes(p: &[f32], exposure: f32) -> Vec<u8> {
    p.iter()
        .map(|&v| (display(v, exposure) * 255.0).round() as u8)
        .collect()
}

fn markdown(r: &Report) -> String {
    let mut s = format!(
        "# Relighting evaluation: {} (clip `{}`, {} vertices in {} skinned primitives), mode {}\n\n\
         {} training frames (ridge by blocked cross-validation over them), {} validation frames; tested on clip `{}` \
         frames {}..{} (held out of training), times {:?} s; \
         {} visibility rays per vertex; reference {} samples per vertex.\n\n\
         ## Fit error (RMS over the sphere of predicted vs projected visibility, test frames)\n\n\
         | lobes | mean | std | 99th percentile | lobe fit (train) | training s | model MB | ridge | ms per frame | pose reach per test frame | pose coverage per test frame |\n\
         |---|---|---|---|---|---|---|---|---|---|---|\n",
        r.character,
        r.clip,
        r.vertices,
        r.primitives,
        r.mode,
        r.train_frames,
        r.validation_frames,
        r.test_clip,
        r.test_frames[0],
        r.test_frames[1],
        r.test_times_s,
        r.rays,
        r.ref_samples
    );
    for f in &r.fit_error {
        s += &format!(
            "| {} | {:.4} | {:.4} | {:.4} | {:.4} ± {:.4} | {:.1} | {:.2} | {:.2e} | {:.2} | {} | {} |\n",
            f.lobes,
            f.mean,
            f.std,
            f.p99,
            f.lobe_fit_mean,
            f.lobe_fit_std,
            f.train_s,
            f.model_mb,
            f.ridge,
            f.ms_per_frame,
            f.pose_reach
                .iter()
                .map(|r| r.map_or("—".to_string(), |r| format!("{r:.2}")))
                .collect::<Vec<_>>()
                .join(", "),
            f.pose_coverage
                .iter()
                .map(|c| format!("{c:.2}"))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    s += "\n## Lobes fitted to plain vs cosine-weighted SH visibility (paper Fig. 3)\n\n\
          RMS over the sphere, mean ± std over vertices of 4 training frames; `convolved`: \
          the plain fit convolved with the clamped cosine, against the traced \
          cosine-weighted visibility (the cosine-weighted fit's error is in the same \
          units).\n\n\
          | lobes | plain fit | cosine-weighted fit | plain fit, convolved |\n|---|---|---|---|\n";
    for f in &r.sh_fit {
        s += &format!(
            "| {} | {:.4} ± {:.4} | {:.4} ± {:.4} | {:.4} ± {:.4} |\n",
            f.lobes,
            f.plain.0,
            f.plain.1,
            f.cosine.0,
            f.cosine.1,
            f.plain_convolved.0,
            f.plain_convolved.1
        );
    }
    s += "\n## Image quality against the reference (mean over test frames)\n\n\
          The last two columns: the smallest gain over `unshadowed` on any single test frame \
          (positive: better on every frame). `reference_reseeded` is the reference rendered \
          again with independent samples (its noise floor).\n\n\
          | method | PSNR dB | SSIM | FLIP | worst frame: PSNR gain | FLIP gain |\n\
          |---|---|---|---|---|---|\n";
    for m in r.methods.iter().chain([&r.reference_noise]) {
        let gains = if m.name == "unshadowed" || m.name == "reference_reseeded" {
            "— | —".to_string()
        } else {
            format!("{:+.2} dB | {:+.4}", m.worst_psnr_gain, m.worst_flip_gain)
        };
        s += &format!(
            "| {} | {:.2} | {:.4} | {:.4} | {gains} |\n",
            m.name, m.psnr, m.ssim, m.flip
        );
    }
    s += "\n## Per frame\n\n| time s | method | PSNR dB | SSIM | FLIP |\n|---|---|---|---|---|\n";
    for f in r.frames.iter().chain(&r.reference_noise_frames) {
        s += &format!(
            "| {:.3} | {} | {:.2} | {:.4} | {:.4} |\n",
            f.time_s, f.name, f.psnr, f.ssim, f.flip
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_test_block_is_the_last_quarter_spread_evenly() {
        assert_eq!(last_quarter(60), FrameRange { start: 45, end: 60 });
        assert_eq!(last_quarter(3), FrameRange { start: 2, end: 3 });
        let t = test_times(FrameRange { start: 45, end: 60 }, 4);
        let frames: Vec<u32> = t.iter().map(|x| (x * FPS).round() as u32).collect();
        assert_eq!(frames, [45, 48, 52, 56]);
        assert_eq!(test_times(FrameRange { start: 2, end: 4 }, 8).len(), 2);
    }
}
