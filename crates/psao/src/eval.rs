//! `psao eval`: PSAO at several densities and server rates against SSAO and few-spp RTAO,
//! all measured against a cached per-pixel reference (DESIGN §5).
//!
//! With `--lighting gi` (DESIGN §12, docs/LIGHTING.md) the servers also trace irradiance, and
//! the composited columns (`*_comp`) measure the image a person sees against the path-traced
//! diffuse lighting of `psao reference --lighting gi` (luma of the sRGB images, as for AO):
//! row `psao` is the lit client composite, row `psao-ao` the same session's AO-only
//! composite (what the client showed before lighting), and SSAO and RTAO enter with their
//! AO-only composites. The AO columns stay against the reference AO.

use crate::args::{FrameRange, Resolution};
use crate::lpips_weights::{LpipsArgs, LpipsChoice};
use crate::png_io::{read_ao_png, write_ao_png};
use crate::progress;
use crate::reference::{Lighting, ReferenceRenderer};
use crate::report::{self, Report, Row, Series, ServerWork};
use crate::run::{LightingArgs, ServerTuning};
use crate::scene_source::{SceneArgs, SceneInput};
use anyhow::{bail, Context, Result};
use clap::Args;
use psao_eval::{compare, ssao, AoImage, Lpips, Metrics, SsaoSettings};
use psao_net::pipeline::{client_time, composite_rgb8, frame_rgb8, luma, Pipeline, CLIENT_HZ};
use psao_raster::GBuffer;
use psao_scene::path::CameraPath;
use psao_scene::{Animator, Scene};
use std::hash::{Hash, Hasher};
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `psao eval`.
#[derive(Args, Debug)]
pub struct EvalArgs {
    #[command(flatten)]
    pub input: SceneArgs,
    /// Image size, `WxH`.
    #[arg(long, default_value = "640x360")]
    pub res: Resolution,
    /// Half-open range of client frames `A..B` (default: the whole path).
    #[arg(long)]
    pub frames: Option<FrameRange>,
    /// Measure image quality on every K-th frame.
    #[arg(long, default_value_t = 30)]
    pub every: u32,
    /// PSAO densities (points per unit area) to evaluate.
    #[arg(long, value_delimiter = ',', default_value = "512,1024,1536,2048")]
    pub points: Vec<f32>,
    /// Server rates to evaluate.
    #[arg(long, value_delimiter = ',', default_value = "60")]
    pub server_hz: Vec<u32>,
    /// Rays per pixel of the reference.
    #[arg(long, default_value_t = 512)]
    pub spp: u32,
    /// Rays per pixel of the few-spp per-pixel RTAO baseline.
    #[arg(long, default_value_t = 4)]
    pub rtao_spp: u32,
    /// Server frames run at the first frame's time and camera before the measured range
    /// (not counted in any statistic), so the range starts from an accumulated state instead
    /// of a cold start.
    #[arg(long, default_value_t = 0)]
    pub warm_up: u32,
    #[command(flatten)]
    pub tuning: ServerTuning,
    #[command(flatten)]
    pub lighting: LightingArgs,
    #[command(flatten)]
    pub lpips: LpipsArgs,
    /// Folder of cached reference images.
    #[arg(long, default_value = "out/cache")]
    pub cache: PathBuf,
    /// Output folder for `report.json`, `report.md`, plots and crops.
    #[arg(long)]
    pub out: PathBuf,
}

/// One evaluated frame: its G-buffer, reference AO and the reference of the composited
/// images (luma): the AO composite of the reference AO, or with `--lighting gi` the reference
/// diffuse lighting.
struct EvalFrame {
    frame: u32,
    gbuffer: GBuffer,
    reference: AoImage,
    reference_comp: AoImage,
}

/// Runs `psao eval`.
pub fn run(args: &EvalArgs) -> Result<()> {
    if args.every == 0 || args.points.is_empty() || args.server_hz.is_empty() {
        bail!("--every must be ≥ 1 and --points / --server-hz must not be empty");
    }
    if args.spp == 0 || args.spp > crate::reference::MAX_SPP || args.rtao_spp == 0 {
        bail!(
            "--spp and --rtao-spp must be in 1..={}",
            crate::reference::MAX_SPP
        );
    }
    // Checked before any work.
    args.lighting.config(Lighting::Ao)?;
    let (input, path) = args.input.load()?;
    let count = path.frame_count() as u32;
    let range = FrameRange::within_path(args.frames, count)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let eval_frames: Vec<u32> = (range.start..range.end)
        .step_by(args.every as usize)
        .collect();
    let (lpips, lpips_note) = match args.lpips.load()? {
        LpipsChoice::Ready(net) => {
            match psao_eval::lpips::check_size(args.res.width, args.res.height) {
                Ok(()) => (Some(*net), None),
                Err(e) => {
                    let note = format!("LPIPS left out: {e}");
                    tracing::warn!("{note}");
                    (None, Some(note))
                }
            }
        }
        LpipsChoice::Missing(note) => (None, Some(note)),
    };
    let frames = prepare_frames(&input, &path, &eval_frames, args)?;
    let lpips = lpips.as_ref();

    let mut rows = Vec::new();
    let mut bandwidth = Vec::new();
    let mut crops: Vec<(String, AoImage)> = vec![(
        "reference".into(),
        frames[frames.len() / 2].reference.clone(),
    )];
    for &hz in &args.server_hz {
        for &points in &args.points {
            let (psao_rows, series, middle) =
                eval_psao(&input, &path, range, &frames, points, hz, args, lpips)?;
            if hz == args.server_hz[0] && (crops.len() == 1) {
                crops.push((format!("PSAO-{points}"), middle));
            }
            bandwidth.push(series);
            rows.extend(psao_rows);
        }
    }
    let (ssao_row, ssao_middle) = eval_ssao(&input.scene, &path, &frames, lpips)?;
    crops.push(("SSAO".into(), ssao_middle));
    rows.push(ssao_row);
    rows.push(eval_rtao(&input, &path, &frames, args, lpips)?);

    let report = Report {
        scene: input.name.clone(),
        path: path.name.clone(),
        res: args.res.to_string(),
        frames: format!("{}..{}", range.start, range.end),
        every: args.every,
        spp: args.spp,
        command: std::env::args().collect::<Vec<_>>().join(" "),
        rows,
        lpips_note,
    };
    report::write(&args.out, &report, &bandwidth, &crops)?;
    println!("{}", report::table(&report.rows));
    println!("{}", report::work_table(&report.rows));
    println!("wrote {}", args.out.join("report.md").display());
    Ok(())
}

/// G-buffers and (cached) references of the evaluated frames.
fn prepare_frames(
    input: &SceneInput,
    path: &CameraPath,
    eval_frames: &[u32],
    args: &EvalArgs,
) -> Result<Vec<EvalFrame>> {
    let cache_dir = args
        .cache
        .join(reference_key(input, path, eval_frames, args)?);
    std::fs::create_dir_all(&cache_dir)
        .with_context(|| format!("cannot create {}", cache_dir.display()))?;
    let mut renderer = ReferenceRenderer::new(
        &input.scene,
        args.tuning.backend.unwrap_or_default(),
        args.spp,
        1,
    )?
    .with_medium(input.medium());
    let pixels = args.res.width as u64 * args.res.height as u64;
    let lighting = args.lighting.config(Lighting::Ao)?;
    let per_frame = pixels * if lighting.is_some() { 2 } else { 1 };
    let bar = progress::bar(per_frame * eval_frames.len() as u64, "references", "px");
    let gi_dir = match &lighting {
        Some(l) => {
            let dir = cache_dir.join(gi_key(&input.scene, l.bounces));
            std::fs::create_dir_all(&dir)
                .with_context(|| format!("cannot create {}", dir.display()))?;
            Some((dir, l.bounces))
        }
        None => None,
    };
    let mut frames = Vec::new();
    for &frame in eval_frames {
        let file = crate::reference::frame_file(&cache_dir, frame);
        // Posed at the frame's scene time when the scene is animated.
        let gbuffer = renderer.gbuffer(path, frame, args.res)?;
        let reference = match read_ao_png(&file) {
            Ok(img) if (img.width, img.height) == (args.res.width, args.res.height) => {
                bar.inc(pixels);
                img
            }
            _ => {
                let seed = 1u64.wrapping_add(frame as u64);
                let img = renderer.trace(&gbuffer, args.spp, seed, &|n| bar.inc(n));
                write_ao_png(&file, &img)?;
                // Use exactly what the cache holds, so cached and fresh runs agree.
                AoImage::from_u16(img.width, img.height, &img.to_u16())
            }
        };
        let reference_comp = match &gi_dir {
            None => composite_luma(&input.scene, &gbuffer, &reference),
            Some((dir, bounces)) => {
                let file = dir.join(format!("gi_luma_{frame:05}.png"));
                match read_ao_png(&file) {
                    Ok(img) if (img.width, img.height) == (args.res.width, args.res.height) => {
                        bar.inc(pixels);
                        img
                    }
                    _ => {
                        let gi =
                            renderer.render_gi(path, frame, args.res, *bounces, &|n| bar.inc(n))?;
                        let img =
                            luma(gi.width, gi.height, &psao_client::composite_srgb8(&gi.data));
                        write_ao_png(&file, &img)?;
                        AoImage::from_u16(img.width, img.height, &img.to_u16())
                    }
                }
            }
        };
        frames.push(EvalFrame {
            frame,
            gbuffer,
            reference,
            reference_comp,
        });
    }
    bar.finish_and_clear();
    Ok(frames)
}

/// The cache folder name of a reference configuration: readable parts plus a hash of everything
/// that changes the images (scene geometry, camera keys, resolution, spp, radius, for an
/// animated scene its pose at the evaluated frames, and the volume: its files' bytes,
/// placement, density scale, format and frame).
fn reference_key(
    input: &SceneInput,
    path: &CameraPath,
    eval_frames: &[u32],
    args: &EvalArgs,
) -> Result<String> {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    let animator = Animator::new(&input.scene).context("the scene's animation cannot be played")?;
    if animator.is_dynamic() {
        for &frame in eval_frames {
            let pose = animator.pose_at(client_time(frame));
            format!("{:?}", pose.transforms).hash(&mut h);
            for g in pose.skinned.iter().flatten() {
                let sum = g.positions.iter().fold(glam::Vec3::ZERO, |a, p| a + *p);
                format!("{sum:?}").hash(&mut h);
            }
        }
    }
    args.input.scene.hash(&mut h);
    input.scene.instanced_triangle_count().hash(&mut h);
    format!("{:?}", path.keys).hash(&mut h);
    input.scene.ao_radius.to_bits().hash(&mut h);
    let (lo, hi) = input.scene.bounds();
    format!("{lo:?}{hi:?}").hash(&mut h);
    if let Some(v) = &input.volume {
        v.key.hash(&mut h);
    }
    Ok(format!(
        "{}_{}_{}_{}spp_{:016x}",
        input.name,
        path.name,
        args.res,
        args.spp,
        h.finish()
    ))
}

/// The cache folder name (inside the reference's) of the reference lighting with `bounces`
/// bounces: a hash of what lights the scene beyond its geometry (lights, sun keys, base
/// colours, environment: its constant, or its map's intensity, turn and radiance in 26
/// directions).
fn gi_key(scene: &Scene, bounces: u32) -> String {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    format!("{:?}{:?}", scene.lights, scene.sun_keys).hash(&mut h);
    for m in &scene.materials {
        format!("{:?}", m.base_color).hash(&mut h);
    }
    match &scene.environment {
        psao_scene::Environment::Constant(c) => format!("{c:?}").hash(&mut h),
        env => {
            for x in -1..=1 {
                for y in -1..=1 {
                    for z in -1..=1 {
                        let d = glam::Vec3::new(x as f32, y as f32, z as f32);
                        if d != glam::Vec3::ZERO {
                            format!("{:?}", env.radiance(d.normalize())).hash(&mut h);
                        }
                    }
                }
            }
        }
    }
    format!("gi{bounces}_{:016x}", h.finish())
}

fn composite_luma(scene: &Scene, gbuffer: &GBuffer, ao: &AoImage) -> AoImage {
    luma(
        gbuffer.width,
        gbuffer.height,
        &composite_rgb8(scene, gbuffer, ao),
    )
}

/// Mean metrics over frames for AO-only and composited images (LPIPS with a network).
struct MetricSums<'a> {
    lpips: Option<&'a Lpips>,
    ao: Vec<Metrics>,
    comp: Vec<Metrics>,
    lpips_ao: Vec<f64>,
    lpips_comp: Vec<f64>,
}

impl<'a> MetricSums<'a> {
    fn new(lpips: Option<&'a Lpips>) -> Self {
        Self {
            lpips,
            ao: Vec::new(),
            comp: Vec::new(),
            lpips_ao: Vec::new(),
            lpips_comp: Vec::new(),
        }
    }

    /// Adds a frame's AO and its AO-only composite.
    fn add(&mut self, scene: &Scene, f: &EvalFrame, ao: &AoImage) -> Result<()> {
        self.add_composited(f, ao, &composite_luma(scene, &f.gbuffer, ao))
    }

    /// Adds a frame's AO and a composite (luma) made otherwise.
    fn add_composited(&mut self, f: &EvalFrame, ao: &AoImage, comp: &AoImage) -> Result<()> {
        self.ao.push(compare(&f.reference, ao)?);
        self.comp.push(compare(&f.reference_comp, comp)?);
        if let Some(net) = self.lpips {
            self.lpips_ao.push(net.distance(&f.reference, ao)?);
            self.lpips_comp.push(net.distance(&f.reference_comp, comp)?);
        }
        Ok(())
    }

    fn row(&self, method: &str) -> Row {
        let mean = |v: &[Metrics], g: fn(&Metrics) -> f64| {
            v.iter().map(g).sum::<f64>() / v.len().max(1) as f64
        };
        let mean_of = |v: &[f64]| {
            self.lpips
                .map(|_| v.iter().sum::<f64>() / v.len().max(1) as f64)
        };
        Row {
            method: method.into(),
            points: None,
            server_hz: None,
            codec: None,
            lpips_ao: mean_of(&self.lpips_ao),
            lpips_comp: mean_of(&self.lpips_comp),
            psnr_ao: mean(&self.ao, |m| m.psnr),
            ssim_ao: mean(&self.ao, |m| m.ssim),
            flip_ao: mean(&self.ao, |m| m.flip),
            psnr_comp: mean(&self.comp, |m| m.psnr),
            ssim_comp: mean(&self.comp, |m| m.ssim),
            flip_comp: mean(&self.comp, |m| m.flip),
            mbit_s: 0.0,
            server_ms: 0.0,
            client_ms: 0.0,
            work: None,
        }
    }
}

/// Runs the split pipeline over the whole range and measures the evaluated frames: one row
/// (`psao`), or with lighting the lit composite's row (`psao`) and the AO-only composite's
/// (`psao-ao`, same session, same figures but the composited ones).
#[allow(clippy::too_many_arguments)]
fn eval_psao(
    input: &SceneInput,
    path: &CameraPath,
    range: FrameRange,
    frames: &[EvalFrame],
    points: f32,
    hz: u32,
    args: &EvalArgs,
    lpips: Option<&Lpips>,
) -> Result<(Vec<Row>, Series, AoImage)> {
    let scene = &input.scene;
    let mut config = args.tuning.config(points, hz, args.res)?;
    config.medium = input.medium();
    config.server.lighting = args.lighting.config(Lighting::Ao)?;
    let lit = config.server.lighting.is_some();
    let mut pipeline = Pipeline::new(scene, &config)?;
    if args.warm_up > 0 {
        let camera = path.camera_at_frame(range.start as usize);
        pipeline.warm_up(range.start, &camera, args.warm_up)?;
    }
    let bar = progress::bar(
        (range.end - range.start) as u64,
        &format!("PSAO-{points} @ {hz} Hz"),
        "frames",
    );
    let mut sums = MetricSums::new(lpips);
    let mut lit_sums = MetricSums::new(lpips);
    let (mut server_ms, mut server_frames, mut client_ms) = (0.0, 0u32, 0.0);
    let mut work = ServerWork {
        invalidation: format!("{:?}", args.tuning.invalidation).to_lowercase(),
        ..ServerWork::default()
    };
    let mut per_second =
        vec![0u64; ((range.end - range.start) as usize).div_ceil(CLIENT_HZ as usize)];
    let mut middle = None;
    let mut next = frames.iter().peekable();
    for frame in range.start..range.end {
        let eval = next.next_if(|f| f.frame == frame);
        let camera = path.camera_at_frame(frame as usize);
        let (record, image) = pipeline.frame(frame, &camera, eval.is_some())?;
        if record.server_frame {
            server_ms += record.server_ms;
            server_frames += 1;
            work.rays += record.rays as f64;
            work.invalidated_points += record.invalidated_points as f64;
            work.retraced_points += record.retraced_points as f64;
            work.retrace_rays += record.retrace_rays as f64;
            work.animate_ms += record.animate_ms;
            work.max_server_ms = work.max_server_ms.max(record.server_ms);
        }
        per_second[((frame - range.start) / CLIENT_HZ) as usize] += record.bytes as u64;
        if let (Some(f), Some(img)) = (eval, image) {
            client_ms += record.client_ms;
            sums.add(scene, f, &img.ao)?;
            if lit {
                let (w, h) = (img.ao.width, img.ao.height);
                lit_sums.add_composited(f, &img.ao, &luma(w, h, &frame_rgb8(scene, &img)))?;
            }
            if std::ptr::eq(f, &frames[frames.len() / 2]) {
                middle = Some(img.ao);
            }
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    let seconds = (range.end - range.start) as f64 / CLIENT_HZ as f64;
    let mut row = if lit {
        lit_sums.row("psao")
    } else {
        sums.row("psao")
    };
    row.points = Some(points);
    row.server_hz = Some(hz);
    row.codec = Some(config.codec.clone());
    row.mbit_s = pipeline.total_bytes as f64 * 8.0 / seconds / 1e6;
    row.server_ms = server_ms / server_frames.max(1) as f64;
    let n = f64::from(server_frames.max(1));
    for v in [
        &mut work.rays,
        &mut work.invalidated_points,
        &mut work.retraced_points,
        &mut work.retrace_rays,
        &mut work.animate_ms,
    ] {
        *v /= n;
    }
    row.work = Some(work);
    row.client_ms = client_ms / frames.len().max(1) as f64;
    let series = Series {
        label: format!("PSAO-{points} @ {hz} Hz"),
        mbit_per_second: per_second.iter().map(|&b| b as f64 * 8.0 / 1e6).collect(),
    };
    // With lighting, the AO-only composite of the same session: only the composited figures
    // differ.
    let ao_only = lit.then(|| {
        let ao_only = sums.row("psao-ao");
        Row {
            method: ao_only.method,
            psnr_comp: ao_only.psnr_comp,
            ssim_comp: ao_only.ssim_comp,
            flip_comp: ao_only.flip_comp,
            lpips_comp: ao_only.lpips_comp,
            ..row.clone()
        }
    });
    let rows = std::iter::once(row).chain(ao_only).collect();
    Ok((rows, series, middle.context("no evaluated frame")?))
}

/// SSAO on the same G-buffers.
fn eval_ssao(
    scene: &Scene,
    path: &CameraPath,
    frames: &[EvalFrame],
    lpips: Option<&Lpips>,
) -> Result<(Row, AoImage)> {
    let mut sums = MetricSums::new(lpips);
    let mut ms = 0.0;
    let mut middle = None;
    for (i, f) in frames.iter().enumerate() {
        let camera = path.camera_at_frame(f.frame as usize);
        let t = Instant::now();
        let ao = ssao(&f.gbuffer, &camera, &SsaoSettings::new(scene.ao_radius));
        ms += t.elapsed().as_secs_f64() * 1e3;
        sums.add(scene, f, &ao)?;
        if i == frames.len() / 2 {
            middle = Some(ao);
        }
    }
    let mut row = sums.row("ssao");
    row.client_ms = ms / frames.len().max(1) as f64;
    Ok((row, middle.context("no evaluated frame")?))
}

/// Per-pixel RTAO with few rays per pixel (on the same pose as the reference, through the
/// scene's volume like the reference).
fn eval_rtao(
    input: &SceneInput,
    path: &CameraPath,
    frames: &[EvalFrame],
    args: &EvalArgs,
    lpips: Option<&Lpips>,
) -> Result<Row> {
    let scene = &input.scene;
    let mut renderer = ReferenceRenderer::new(
        scene,
        args.tuning.backend.unwrap_or_default(),
        args.rtao_spp,
        0,
    )?
    .with_medium(input.medium());
    let mut sums = MetricSums::new(lpips);
    let mut ms = 0.0;
    for f in frames {
        renderer.gbuffer(path, f.frame, args.res)?;
        let t = Instant::now();
        let ao = renderer.trace(
            &f.gbuffer,
            args.rtao_spp,
            0x7274_616f ^ f.frame as u64,
            &|_| {},
        );
        ms += t.elapsed().as_secs_f64() * 1e3;
        sums.add(scene, f, &ao)?;
    }
    let mut row = sums.row("rtao");
    row.client_ms = ms / frames.len().max(1) as f64;
    Ok(row)
}
