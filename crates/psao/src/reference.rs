//! `psao reference`: per-pixel reference AO, or the reference of the diffuse lighting
//! (`--lighting gi`), along a camera path.

use crate::args::{FrameRange, Resolution};
use crate::png_io::{write_ao_png, write_rgb_hdr, write_rgb_png};
use crate::progress;
use crate::scene_source::SceneArgs;
use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use psao_eval::{reference_ao_in, reference_gi, AoImage, GiSettings, ReferenceSettings, RgbImage};
use psao_raster::{rasterize, rasterize_posed, GBuffer, InstancePose, RasterOptions};
use psao_scene::path::CameraPath;
use psao_scene::{Animator, Motion, Scene, ScenePose, PATH_HZ};
use psao_trace::ao::Medium;
use psao_trace::gi::DiffuseLighting;
use psao_trace::{Backend, GeometryMode, Tracer};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Largest accepted rays per pixel.
pub const MAX_SPP: u32 = 1 << 16;

/// Largest accepted `--bounces`.
pub const MAX_BOUNCES: u32 = 64;

/// What `psao reference` renders.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Lighting {
    /// Ambient occlusion (DESIGN §2), `ao_NNNNN.png`.
    Ao,
    /// Path-traced diffuse lighting (DESIGN §12): linear radiance `gi_NNNNN.hdr` and an sRGB
    /// preview `gi_NNNNN.png`.
    Gi,
}

/// Arguments of `psao reference`.
#[derive(Args, Debug)]
pub struct ReferenceArgs {
    #[command(flatten)]
    pub input: SceneArgs,
    /// A single frame of the path (60 Hz).
    #[arg(long, conflicts_with = "frames")]
    pub frame: Option<u32>,
    /// A half-open range of frames, `A..B`.
    #[arg(long)]
    pub frames: Option<FrameRange>,
    /// What to render: `ao` or `gi` (diffuse lighting: the scene's lights, environment and
    /// `--bounces` indirect bounces).
    #[arg(long, value_enum, default_value_t = Lighting::Ao)]
    pub lighting: Lighting,
    /// Indirect diffuse bounces of `--lighting gi` (a fixed depth).
    #[arg(long, default_value_t = 1)]
    pub bounces: u32,
    /// Rays per pixel (paths per pixel for `--lighting gi`).
    #[arg(long, default_value_t = 512)]
    pub spp: u32,
    /// Image size, `WxH`.
    #[arg(long, default_value = "640x360")]
    pub res: Resolution,
    /// Seed of the sample pattern (each frame adds its number).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Ray-tracing backend, `obvhs` or `embree` (default: the fastest compiled in).
    #[arg(long)]
    pub backend: Option<Backend>,
    /// Output folder for `ao_NNNNN.png` (or `gi_NNNNN.hdr` and `gi_NNNNN.png`).
    #[arg(long)]
    pub out: PathBuf,
}

/// Runs `psao reference`.
pub fn run(args: &ReferenceArgs) -> Result<()> {
    if args.spp == 0 || args.spp > MAX_SPP {
        bail!("--spp must be in 1..={MAX_SPP}, got {}", args.spp);
    }
    if args.bounces > MAX_BOUNCES {
        bail!(
            "--bounces must be in 0..={MAX_BOUNCES}, got {}",
            args.bounces
        );
    }
    let (input, path) = args.input.load()?;
    let frames = select_frames(&path, args.frame, args.frames)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let mut renderer = ReferenceRenderer::new(
        &input.scene,
        args.backend.unwrap_or_default(),
        args.spp,
        args.seed,
    )?
    .with_medium(input.medium());
    let pixels = args.res.width as u64 * args.res.height as u64;
    let what = match args.lighting {
        Lighting::Ao => "reference AO",
        Lighting::Gi => "reference lighting",
    };
    let bar = progress::bar(pixels * frames.len() as u64, what, "px");
    for &frame in &frames {
        match args.lighting {
            Lighting::Ao => {
                let image = renderer.render(&path, frame, args.res, &|n| bar.inc(n))?;
                write_ao_png(&frame_file(&args.out, frame), &image)?;
            }
            Lighting::Gi => {
                let image =
                    renderer.render_gi(&path, frame, args.res, args.bounces, &|n| bar.inc(n))?;
                let stem = args.out.join(format!("gi_{frame:05}"));
                write_rgb_hdr(&stem.with_extension("hdr"), &image)?;
                let srgb = psao_client::composite_srgb8(&image.data);
                write_rgb_png(&stem.with_extension("png"), image.width, image.height, srgb)?;
            }
        }
    }
    bar.finish_and_clear();
    tracing::info!(
        "wrote {} reference frame(s) at {} with {} spp to {}",
        frames.len(),
        args.res,
        args.spp,
        args.out.display()
    );
    Ok(())
}

/// The file name of frame `frame` in `dir`.
pub fn frame_file(dir: &Path, frame: u32) -> PathBuf {
    dir.join(format!("ao_{frame:05}.png"))
}

/// Frames chosen by `--frame`/`--frames` (default: frame 0), checked against the path length.
fn select_frames(
    path: &CameraPath,
    frame: Option<u32>,
    frames: Option<FrameRange>,
) -> Result<Vec<u32>> {
    let range = match (frame, frames) {
        (Some(f), _) => FrameRange {
            start: f,
            end: f.saturating_add(1),
        },
        (None, Some(r)) => r,
        (None, None) => FrameRange { start: 0, end: 1 },
    };
    let range = FrameRange::within_path(Some(range), path.frame_count() as u32)?;
    Ok((range.start..range.end).collect())
}

/// Renders reference AO frames of a scene, posed at each frame's scene time (`frame / 60`)
/// when it is animated: the G-buffer and the AO rays see the same pose (skinned meshes are
/// rebuilt, not refitted, for full tracing quality).
pub struct ReferenceRenderer<'a> {
    scene: &'a Scene,
    tracer: Tracer,
    medium: Option<Arc<dyn Medium>>,
    spp: u32,
    seed: u64,
    animation: Option<(Animator, ScenePose)>,
}

impl<'a> ReferenceRenderer<'a> {
    /// Builds the tracer for `scene`.
    pub fn new(scene: &'a Scene, backend: Backend, spp: u32, seed: u64) -> Result<Self> {
        let tracer = Tracer::new(backend, scene, GeometryMode::Occlusion)
            .context("cannot build the ray-tracing structure")?;
        let animator = Animator::new(scene).context("the scene's animation cannot be played")?;
        Ok(Self {
            scene,
            tracer,
            medium: None,
            spp,
            seed,
            animation: animator
                .is_dynamic()
                .then(|| (animator, ScenePose::default())),
        })
    }

    /// Lets the AO rays pass through `medium` (the scene's volume).
    pub fn with_medium(mut self, medium: Option<Arc<dyn Medium>>) -> Self {
        self.medium = medium;
        self
    }

    /// Poses the scene (tracer included) at client frame `frame` and rasterizes `path`'s
    /// camera of that frame at `res`.
    pub fn gbuffer(&mut self, path: &CameraPath, frame: u32, res: Resolution) -> Result<GBuffer> {
        let camera = path.camera_at_frame(frame as usize);
        let opts = RasterOptions::new(res.width, res.height);
        let Some((animator, pose)) = &mut self.animation else {
            return Ok(rasterize(self.scene, &camera, &opts));
        };
        animator.pose_into(frame as f32 / PATH_HZ, pose);
        for (i, motion) in animator.motion().iter().enumerate() {
            if *motion == Motion::Static {
                continue;
            }
            self.tracer.set_instance_transform(i, pose.transforms[i]);
            if let Some(g) = &pose.skinned[i] {
                self.tracer
                    .rebuild_mesh_positions(self.scene.instances[i].mesh, &g.positions)
                    .context("cannot trace the posed scene")?;
            }
        }
        self.tracer.commit();
        let poses: Vec<InstancePose<'_>> = (0..self.scene.instances.len())
            .filter_map(|i| pose.instance(i))
            .map(|p| InstancePose {
                transform: p.transform,
                positions: p.positions,
                normals: p.normals,
            })
            .collect();
        rasterize_posed(self.scene, &poses, &camera, &opts).context("cannot rasterize the pose")
    }

    /// Reference AO of `frame` of `path` at `res`; `progress` counts pixels.
    pub fn render(
        &mut self,
        path: &CameraPath,
        frame: u32,
        res: Resolution,
        progress: &(dyn Fn(u64) + Sync),
    ) -> Result<AoImage> {
        let gbuffer = self.gbuffer(path, frame, res)?;
        Ok(self.trace(
            &gbuffer,
            self.spp,
            self.seed.wrapping_add(frame as u64),
            progress,
        ))
    }

    /// Reference diffuse lighting of `frame` of `path` at `res` with `bounces` indirect
    /// bounces (the lights at the frame's scene time; pixels without a surface show the
    /// client's sky grey); `progress` counts pixels. The volume, if any, is not part of it.
    pub fn render_gi(
        &mut self,
        path: &CameraPath,
        frame: u32,
        res: Resolution,
        bounces: u32,
        progress: &(dyn Fn(u64) + Sync),
    ) -> Result<RgbImage> {
        let gbuffer = self.gbuffer(path, frame, res)?;
        let lighting = DiffuseLighting::new(self.scene, frame as f32 / PATH_HZ, bounces);
        let lighting = match &self.animation {
            Some((_, pose)) => lighting.posed(pose),
            None => lighting,
        };
        let settings = GiSettings {
            spp: self.spp,
            seed: self.seed.wrapping_add(frame as u64),
            background: glam::Vec3::from_array(psao_client::SKY_GREY),
        };
        Ok(reference_gi(
            &gbuffer,
            self.scene,
            &lighting,
            &self.tracer,
            &settings,
            progress,
        ))
    }

    /// Per-pixel AO of `gbuffer` with `spp` rays per pixel in the pose of the last
    /// [`Self::gbuffer`].
    pub fn trace(
        &self,
        gbuffer: &GBuffer,
        spp: u32,
        seed: u64,
        progress: &(dyn Fn(u64) + Sync),
    ) -> AoImage {
        let settings = ReferenceSettings {
            spp,
            radius: self.scene.ao_radius,
            seed,
        };
        reference_ao_in(
            gbuffer,
            &self.tracer,
            self.medium.as_deref(),
            &settings,
            progress,
        )
    }
}
