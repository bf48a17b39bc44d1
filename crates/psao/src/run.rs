//! `psao run`: server and client in one process along a camera path.

use crate::args::{FrameRange, Resolution};
use crate::png_io::{write_ao_png, write_rgb_png};
use crate::progress;
use crate::reference::Lighting;
use crate::scene_source::SceneArgs;
use crate::served_characters::{served_characters, RelightArgs};
use anyhow::{bail, Context, Result};
use clap::Args;
use psao_net::pipeline::{frame_rgb8, FrameRecord, Pipeline, PipelineConfig};
use psao_server::{Invalidation, LightingConfig, ServerConfig, MAX_BOUNCES};
use psao_trace::Backend;
use psao_wire::{capabilities, Message};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Server tuning shared by `run`, `eval` and `demo`.
#[derive(Args, Debug, Clone)]
pub struct ServerTuning {
    /// Rays the server traces per server frame at most.
    #[arg(long, default_value_t = ServerConfig::default().ray_budget)]
    pub ray_budget: u64,
    /// Rays per point per server frame.
    #[arg(long, default_value_t = ServerConfig::default().rays_per_point)]
    pub rays_per_point: u32,
    /// Samples after which a point counts as converged and is not traced again.
    #[arg(long, default_value_t = ServerConfig::default().max_samples)]
    pub max_samples: u32,
    /// Update codec: `compact` (records predicted from what was last sent + byte planes +
    /// zstd 3) or `paper` (raw records + zstd 15).
    #[arg(long, default_value = "compact")]
    pub codec: String,
    /// Ray-tracing backend, `obvhs` or `embree` (default: the fastest compiled in).
    #[arg(long)]
    pub backend: Option<Backend>,
    /// Seed of point generation and AO sampling.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Which points re-trace after something moved: `proximity` (near moving geometry) or
    /// `everything` (every visible point each server frame, the published system's approach).
    #[arg(long, value_enum, default_value = "proximity")]
    pub invalidation: InvalidationArg,
    /// Folder where generated, burial-tested points are kept between runs, so a restart with
    /// the same scene and settings skips making them (default: `$PSAO_CACHE_DIR/points`,
    /// `$XDG_CACHE_HOME/psao/points` or `~/.cache/psao/points`).
    #[arg(long)]
    pub points_cache: Option<PathBuf>,
    /// Generate the points afresh and keep none on disk.
    #[arg(long, conflicts_with = "points_cache")]
    pub no_points_cache: bool,
    /// Apply the client's screen-space contact term below the point spacing
    /// (`psao_client::apply_detail`, docs/BENCHMARKS.md "Fine detail") after reconstruction.
    #[arg(long)]
    pub detail: bool,
    /// Adaptive point placement: the density where near-field occlusion is strongest,
    /// relative to open areas, at the same point count (1 = uniform; docs/BENCHMARKS.md
    /// "Fine detail").
    #[arg(long, default_value_t = 1.0)]
    pub adaptive_boost: f32,
    /// Reconstruction footprint following the local point spacing: radius
    /// min(r, FACTOR × distance to the third nearest compatible point) (off by default;
    /// `psao_points::ReconstructParams::adaptive_radius`).
    #[arg(long)]
    pub adaptive_radius: Option<f32>,
}

/// `--invalidation` values.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum InvalidationArg {
    /// Points within the AO radius of geometry that moved relative to them.
    Proximity,
    /// Every point, whenever anything moved.
    Everything,
}

impl From<InvalidationArg> for Invalidation {
    fn from(a: InvalidationArg) -> Self {
        match a {
            InvalidationArg::Proximity => Invalidation::Proximity,
            InvalidationArg::Everything => Invalidation::Everything,
        }
    }
}

impl ServerTuning {
    /// The pipeline configuration for `points` per unit area at `server_hz` and resolution `res`.
    pub fn config(&self, points: f32, server_hz: u32, res: Resolution) -> Result<PipelineConfig> {
        if !(points.is_finite() && points > 0.0 && points <= 65_536.0) {
            bail!("--points must be in (0, 65536], got {points}");
        }
        if !(self.adaptive_boost.is_finite() && (1.0..=16.0).contains(&self.adaptive_boost)) {
            bail!(
                "--adaptive-boost must be in [1, 16], got {}",
                self.adaptive_boost
            );
        }
        if let Some(f) = self.adaptive_radius {
            if !(f.is_finite() && f > 0.0) {
                bail!("--adaptive-radius must be finite and > 0, got {f}");
            }
        }
        psao_delta::codec_by_name(&self.codec)?;
        Ok(PipelineConfig {
            server: ServerConfig {
                density: points,
                ray_budget: self.ray_budget,
                rays_per_point: self.rays_per_point,
                max_samples: self.max_samples,
                seed: self.seed,
                backend: self.backend.unwrap_or_default(),
                invalidation: self.invalidation.into(),
                adaptive_boost: self.adaptive_boost,
                ..ServerConfig::default()
            },
            server_hz,
            codec: self.codec.clone(),
            res,
            medium: None,
            points_cache: self.points_cache_dir(),
            detail: self.detail.then(psao_client::DetailSettings::default),
            reconstruct: psao_client::ReconstructSettings {
                adaptive_radius: self.adaptive_radius,
                ..Default::default()
            },
            corrective: None,
        })
    }

    /// The folder of stored start points, if any.
    pub fn points_cache_dir(&self) -> Option<PathBuf> {
        if self.no_points_cache {
            return None;
        }
        self.points_cache
            .clone()
            .or_else(psao_net::start_cache::default_dir)
    }
}

/// Arguments of `psao run`.
#[derive(Args, Debug)]
pub struct RunArgs {
    #[command(flatten)]
    pub input: SceneArgs,
    /// Client image size, `WxH`.
    #[arg(long, default_value = "640x360")]
    pub res: Resolution,
    /// Half-open range of client frames `A..B` (default: the whole path).
    #[arg(long)]
    pub frames: Option<FrameRange>,
    /// Write images of every K-th frame only (statistics cover every frame).
    #[arg(long, default_value_t = 1)]
    pub every: u32,
    /// Points per unit area (after sample elimination).
    #[arg(long, default_value_t = 1024.0)]
    pub points: f32,
    /// Server frames per second of scene time.
    #[arg(long, default_value_t = 60)]
    pub server_hz: u32,
    #[command(flatten)]
    pub tuning: ServerTuning,
    #[command(flatten)]
    pub lighting: LightingArgs,
    /// Output folder: `frame_NNNNN.png` (composited), `ao_NNNNN.png` (AO only), `stats.json`.
    #[arg(long)]
    pub out: PathBuf,
    /// Also write the summary as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    #[command(flatten)]
    pub corrective: crate::corrective::split_args::CorrectiveArgs,
    #[command(flatten)]
    pub relight: RelightArgs,
}

/// What the server's points carry (`psao run`, `psao serve`, `psao demo`, `psao eval`).
#[derive(Args, Debug, Clone)]
pub struct LightingArgs {
    /// What the points carry: `gi` (AO and diffuse irradiance from the scene's environment
    /// and lights with `--bounces` bounces, traced on the server and streamed as 32-bit
    /// records beside the AO; clients then show base colour / π × (shadow-mapped direct
    /// light + irradiance); docs/LIGHTING.md) or `ao` (ambient occlusion only, the AO
    /// composite). Default: `gi` for `run`, `serve` and `demo`, `ao` for `eval`.
    #[arg(long, value_enum)]
    pub lighting: Option<Lighting>,
    /// Indirect diffuse bounces of the points' light paths with `--lighting gi` (a fixed
    /// depth).
    #[arg(long, default_value_t = LightingConfig::default().bounces)]
    pub bounces: u32,
    /// Light paths a selected point takes per server frame with `--lighting gi`, beside its
    /// `--rays-per-point` AO rays (a point's irradiance converges at `--max-samples` ×
    /// this / `--rays-per-point` paths; docs/LIGHTING.md, "One selection, one budget").
    #[arg(long, default_value_t = LightingConfig::default().paths_per_point)]
    pub paths_per_point: u32,
    /// Paths a published irradiance record pools at least with `--lighting gi`: while the
    /// points within the reconstruction radius hold fewer, the reach widens to the nearest
    /// coplanar points beyond (at most 4 radii); 0 keeps the reconstruction radius
    /// (docs/LIGHTING.md, "Pooling").
    #[arg(long, default_value_t = LightingConfig::default().pool_paths)]
    pub pool_paths: u32,
}

/// The lighting of `psao run`, `psao serve` and `psao demo` when `--lighting` is not given:
/// what a person watching them should see is the lit composite.
pub const SESSION_LIGHTING: Lighting = Lighting::Gi;

impl LightingArgs {
    /// The server's lighting, `default` when `--lighting` is not given: `None` for `ao`.
    pub fn config(&self, default: Lighting) -> Result<Option<LightingConfig>> {
        if self.bounces > MAX_BOUNCES {
            bail!(
                "--bounces must be at most {MAX_BOUNCES}, got {}",
                self.bounces
            );
        }
        if self.paths_per_point == 0 {
            bail!("--paths-per-point must be at least 1");
        }
        Ok(
            (self.lighting.unwrap_or(default) == Lighting::Gi).then(|| LightingConfig {
                bounces: self.bounces,
                paths_per_point: self.paths_per_point,
                pool_paths: self.pool_paths,
                ..LightingConfig::default()
            }),
        )
    }
}

/// Summary and per-frame statistics of a run.
#[derive(Serialize)]
pub struct RunStats {
    /// Scene name.
    pub scene: String,
    /// Camera path name.
    pub path: String,
    /// Codec name.
    pub codec: String,
    /// Points per unit area.
    pub points_per_area: f32,
    /// Points generated on the server.
    pub points: usize,
    /// Server rate.
    pub server_hz: u32,
    /// With `--lighting gi`: the bounces of the points' light paths.
    pub bounces: Option<u32>,
    /// Light paths the server traced over the run, and their rays.
    pub light_paths: u64,
    pub light_rays: u64,
    /// Client frames simulated.
    pub frames: usize,
    /// Bytes received over all frames.
    pub total_bytes: u64,
    /// Mean received bandwidth in Mbit per second of scene time.
    pub mbit_s: f64,
    /// Hash of the client's final buckets + cells.
    pub state_hash: String,
    /// Mean time to encode one update, ms over the server frames.
    pub encode_ms: f64,
    /// With `--corrective`: hash of the client's final correction state (its sample cache).
    pub corrective_state_hash: Option<String>,
    /// Per-frame records.
    pub per_frame: Vec<FrameRecord>,
}

/// Mean [`FrameRecord::encode_ms`] over the server frames (0 without any).
fn mean_encode_ms(records: &[FrameRecord]) -> f64 {
    let server: Vec<f64> = records
        .iter()
        .filter(|r| r.server_frame)
        .map(|r| r.encode_ms)
        .collect();
    server.iter().sum::<f64>() / server.len().max(1) as f64
}

/// Runs `psao run`.
pub fn run(args: &RunArgs) -> Result<()> {
    let (input, path) = args.input.load()?;
    let count = path.frame_count() as u32;
    let range = FrameRange::within_path(args.frames, count)?;
    if args.every == 0 {
        bail!("--every must be at least 1");
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let mut config = args.tuning.config(args.points, args.server_hz, args.res)?;
    config.server.lighting = args.lighting.config(SESSION_LIGHTING)?;
    config.medium = input.medium();
    config.corrective = args.corrective.config()?;
    let mut pipeline = Pipeline::new(&input.scene, &config)?;
    // The client gets the models `psao serve --relight` would send it.
    let characters = served_characters(
        &input.scene,
        &args.relight,
        config.server.seed,
        config.points_cache.as_deref(),
    )?;
    for msg in characters.messages_for(capabilities::RELIGHT) {
        if let Message::Relighting(r) = msg {
            pipeline.relight(&r)?;
        }
    }
    tracing::info!(
        "{} points on {} instances",
        pipeline.server().point_count(),
        input.scene.instances.len()
    );
    let bar = progress::bar((range.end - range.start) as u64, "psao run", "frames");
    let mut records = Vec::new();
    for frame in range.start..range.end {
        let camera = path.camera_at_frame(frame as usize);
        let render = (frame - range.start).is_multiple_of(args.every);
        let (record, image) = pipeline.frame(frame, &camera, render)?;
        if let Some(img) = image {
            write_frame_images(&args.out, frame, &input.scene, &img)?;
        }
        records.push(record);
        bar.inc(1);
    }
    bar.finish_and_clear();
    let seconds = records.len() as f64 / psao_net::pipeline::CLIENT_HZ as f64;
    let stats = RunStats {
        scene: input.name.clone(),
        path: path.name.clone(),
        codec: config.codec.clone(),
        points_per_area: config.server.density,
        points: pipeline.server().point_count(),
        server_hz: config.server_hz,
        bounces: config.server.lighting.map(|l| l.bounces),
        light_paths: records.iter().map(|r| r.light_paths).sum(),
        light_rays: records.iter().map(|r| r.light_rays).sum(),
        frames: records.len(),
        total_bytes: pipeline.total_bytes,
        mbit_s: pipeline.total_bytes as f64 * 8.0 / seconds / 1e6,
        state_hash: format!("{:016x}", pipeline.client().state_hash()),
        encode_ms: mean_encode_ms(&records),
        corrective_state_hash: pipeline
            .corrective_client()
            .map(|c| format!("{:016x}", c.state_hash())),
        per_frame: records,
    };
    let stats_file = args.out.join("stats.json");
    write_json(&stats_file, &stats)?;
    if let Some(json) = &args.json {
        write_json(json, &stats)?;
    }
    println!(
        "{} frames, {:.2} Mbit/s, state {} -> {}",
        stats.frames,
        stats.mbit_s,
        stats.state_hash,
        args.out.display()
    );
    if let Some(bounces) = stats.bounces {
        println!(
            "lighting: {} light paths ({} rays) with {bounces} bounce(s) on the server",
            stats.light_paths, stats.light_rays
        );
    }
    Ok(())
}

/// Writes the composited (lit when the frame has lighting) and AO-only images of one frame.
pub fn write_frame_images(
    dir: &Path,
    frame: u32,
    scene: &psao_scene::Scene,
    img: &psao_net::pipeline::ClientFrame,
) -> Result<()> {
    write_ao_png(&dir.join(format!("ao_{frame:05}.png")), &img.ao)?;
    let rgb = frame_rgb8(scene, img);
    write_rgb_png(
        &dir.join(format!("frame_{frame:05}.png")),
        img.ao.width,
        img.ao.height,
        rgb,
    )?;
    if let Some(corrected) = &img.corrected {
        write_rgb_png(
            &dir.join(format!("corrected_{frame:05}.png")),
            img.ao.width,
            img.ao.height,
            psao_client::composite_srgb8(corrected),
        )?;
    }
    Ok(())
}

/// Writes `value` as pretty JSON.
pub fn write_json<T: Serialize>(file: &Path, value: &T) -> Result<()> {
    let text = serde_json::to_string_pretty(value)?;
    std::fs::write(file, text).with_context(|| format!("cannot write {}", file.display()))
}
