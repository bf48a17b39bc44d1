//! `psao relight train|render|eval`: shadowed relighting of skinned characters (DESIGN §7,
//! crate `psao-prt`).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand, ValueEnum};
use psao_prt::character::Character;
use psao_prt::fade::{self, FadeRule};
use psao_prt::filter::Filter;
use psao_prt::model::{train, Sample, TrainReport};
use psao_prt::shade::{Mode, Shader, ShadingGeometry, Visibility};
use psao_prt::visibility::{visibility_sh, SelfTracer};

use crate::args::{FrameRange, Resolution};
use crate::png_io::write_rgb_png;
use crate::progress::bar;
use crate::relight_io::{
    clip_frames, display, exposure_for, framing_camera, load_character, load_env, read_model,
    write_model, LoadedCharacter, VertexImage, FPS,
};
use crate::video::encode_video;

/// The relighting subcommands.
#[derive(Subcommand, Debug)]
pub enum RelightCommand {
    /// Trace visibility over a clip, fit zonal lobes and train the linear pose model.
    Train(TrainArgs),
    /// Render a clip relit by a trained model under an HDR environment (PNG frames, MP4).
    Render(RenderArgs),
    /// Evaluate against a Monte Carlo reference: fit errors, PSNR/SSIM/FLIP per method.
    Eval(crate::relight_eval::EvalArgs),
}

/// Which clip and frames of a character.
#[derive(Args, Debug, Clone)]
pub struct ClipArgs {
    /// The skinned character (glTF/GLB).
    #[arg(long)]
    pub character: PathBuf,
    /// Clip name or index (default: the first clip).
    #[arg(long)]
    pub clip: Option<String>,
    /// Frames `A..B` of the clip at 30 frames per second (default: the whole clip).
    #[arg(long)]
    pub frames: Option<FrameRange>,
}

/// Arguments of `psao relight train`.
#[derive(Args, Debug)]
pub struct TrainArgs {
    #[command(flatten)]
    pub clip: ClipArgs,
    /// Train on every K-th frame of the range.
    #[arg(long, default_value_t = 1)]
    pub every: u32,
    /// Zonal lobes per vertex (1, 2 or 3).
    #[arg(long, default_value_t = 2)]
    pub lobes: usize,
    /// Visibility rays per vertex and frame.
    #[arg(long, default_value_t = 512)]
    pub rays: u32,
    /// Seed of the ray directions.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The model file to write.
    #[arg(long)]
    pub out: PathBuf,
}

/// The reflection model on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ModeArg {
    /// Lambertian.
    Diffuse,
    /// Normalised Phong about the reflection vector.
    Phong,
    /// Thin-membrane translucency with a shadowed front lobe.
    Translucent,
}

/// Shading options shared by render, eval and bench.
#[derive(Args, Debug, Clone)]
pub struct ShadingArgs {
    /// Reflection model.
    #[arg(long, value_enum, default_value_t = ModeArg::Diffuse)]
    pub mode: ModeArg,
    /// Phong exponent (≥ 1) for `--mode phong`.
    #[arg(long, default_value_t = 16.0)]
    pub alpha: f32,
    /// Transmitted fraction for `--mode translucent`.
    #[arg(long, default_value_t = 0.3)]
    pub transmission: f32,
    /// What is done to reconstructed visibility before shading: `none`, or `+`-joined
    /// `hanning` / `lanczos` (a window on the SH bands) and `clamp` (to [0, 1] over the
    /// sphere); see docs/RELIGHTING.md.
    #[arg(long, default_value = "none")]
    pub filter: Filter,
}

impl ShadingArgs {
    /// The mode, checked.
    pub fn mode(&self) -> Result<Mode> {
        let mode = match self.mode {
            ModeArg::Diffuse => Mode::Diffuse,
            ModeArg::Phong => Mode::Phong { alpha: self.alpha },
            ModeArg::Translucent => Mode::Translucent {
                transmission: self.transmission,
            },
        };
        Ok(mode.validate()?)
    }

    /// The shader of these options.
    pub fn shader(&self) -> Result<Shader> {
        Ok(Shader::with_filter(self.mode()?, self.filter)?)
    }
}

/// Arguments of `psao relight render`.
#[derive(Args, Debug)]
pub struct RenderArgs {
    /// The model file (from `psao relight train`).
    #[arg(long)]
    pub model: PathBuf,
    #[command(flatten)]
    pub clip: ClipArgs,
    /// Radiance `.hdr` environment map (latitude–longitude).
    #[arg(long)]
    pub env: PathBuf,
    #[command(flatten)]
    pub shading: ShadingArgs,
    /// Turn the lighting about the vertical axis at this many degrees per second.
    #[arg(long, default_value_t = 0.0)]
    pub light_rotate: f32,
    /// Image size.
    #[arg(long, default_value = "640x480")]
    pub res: Resolution,
    /// Output folder (frames `frame_NNNNN.png`, `relight.mp4` when ffmpeg is installed).
    #[arg(long)]
    pub out: PathBuf,
}

/// Runs a relight subcommand.
pub fn run(command: &RelightCommand) -> Result<()> {
    match command {
        RelightCommand::Train(a) => run_train(a),
        RelightCommand::Render(a) => run_render(a),
        RelightCommand::Eval(a) => crate::relight_eval::run(a),
    }
}

/// The clip's frame range: `requested` checked against the clip, or the whole clip.
pub fn frame_range(character: &Character, requested: Option<FrameRange>) -> Result<FrameRange> {
    let count = clip_frames(character);
    let range = requested.unwrap_or(FrameRange {
        start: 0,
        end: count,
    });
    if range.end > count {
        bail!(
            "clip `{}` has {count} frames at {FPS} fps (0..{count}); asked for {}..{}",
            character.clip_name(),
            range.start,
            range.end
        );
    }
    Ok(range)
}

/// Times of one training split: training frames at `i / FPS` for every `every`-th frame;
/// validation (ridge choice) times half a frame after the training frames at even positions.
/// Test times are the frames of `test` when given (training frames inside it are dropped),
/// otherwise half a frame after the training frames at odd positions; the three sets never
/// share a pose.
pub struct Split {
    /// Training times (seconds), in order.
    pub train: Vec<f32>,
    /// Validation times.
    pub validate: Vec<f32>,
    /// Test times.
    pub test: Vec<f32>,
}

/// The split of `range` with every `every`-th frame trained on and the frames of `test`, if
/// any, held out for testing.
pub fn split(range: FrameRange, every: u32, test: Option<FrameRange>) -> Result<Split> {
    if every == 0 {
        bail!("--every must be at least 1");
    }
    let held_out = |i: &u32| test.is_some_and(|t| (t.start..t.end).contains(i));
    let frames: Vec<u32> = (range.start..range.end)
        .step_by(every as usize)
        .filter(|i| !held_out(i))
        .collect();
    if frames.len() < 2 {
        bail!(
            "frames {}..{} with --every {every}{} give {} training frame(s); at least 2 are needed",
            range.start,
            range.end,
            if test.is_some() {
                " outside the test frames"
            } else {
                ""
            },
            frames.len()
        );
    }
    let half = |i: u32| (i as f32 + 0.5) / FPS;
    let test = match test {
        Some(t) => (t.start..t.end).map(|i| i as f32 / FPS).collect(),
        None => frames.iter().skip(1).step_by(2).map(|&i| half(i)).collect(),
    };
    Ok(Split {
        train: frames.iter().map(|&i| i as f32 / FPS).collect(),
        validate: frames.iter().step_by(2).map(|&i| half(i)).collect(),
        test,
    })
}

/// Visibility samples of a split's training and validation times (see [`gather`]).
pub fn gather_split(
    character: &Character,
    split: &Split,
    rays: u32,
    seed: u64,
) -> Result<(Vec<Sample>, Vec<Sample>)> {
    let train = gather(
        character,
        &split.train,
        rays,
        seed,
        "tracing training frames",
    )?;
    let validate = gather(
        character,
        &split.validate,
        rays,
        seed,
        "tracing validation frames",
    )?;
    Ok((train, validate))
}

/// Visibility samples at `times`, traced with `rays` rays per vertex (a progress bar).
pub fn gather(
    character: &Character,
    times: &[f32],
    rays: u32,
    seed: u64,
    what: &str,
) -> Result<Vec<Sample>> {
    let mut tracer = SelfTracer::new(character.occluder_mesh())?;
    let progress = bar(times.len() as u64, what, "frames");
    let mut out = Vec::with_capacity(times.len());
    for &t in times {
        let pose = character.pose(t);
        tracer.set_pose(&pose)?;
        out.push(Sample {
            visibility: visibility_sh(&tracer, &pose, rays, seed),
            joint_rotations: pose.joint_rotations,
        });
        progress.inc(1);
    }
    progress.finish_and_clear();
    Ok(out)
}

/// Trains a `lobes`-lobe model with a progress bar over vertices.
pub fn train_model(
    name: &str,
    train_set: &[Sample],
    validate: &[Sample],
    lobes: usize,
) -> Result<(psao_prt::model::PoseModel, TrainReport)> {
    let vertices = train_set.first().map_or(0, |s| s.visibility.len());
    let progress = bar(
        vertices as u64,
        &format!("fitting {lobes} lobe(s)"),
        "vertices",
    );
    let result = train(name, train_set, validate, lobes, &|done, _| {
        progress.set_position(done as u64)
    });
    progress.finish_and_clear();
    Ok(result?)
}

fn run_train(args: &TrainArgs) -> Result<()> {
    let loaded = load_character(&args.clip.character, args.clip.clip.as_deref())?;
    let c = &loaded.character;
    if args.rays == 0 {
        bail!("--rays must be at least 1");
    }
    let range = frame_range(c, args.clip.frames)?;
    let split = split(range, args.every, None)?;
    let start = Instant::now();
    let (train_set, validate) = gather_split(c, &split, args.rays, args.seed)?;
    let (model, report) = train_model(&loaded.name, &train_set, &validate, args.lobes)?;
    write_model(&args.out, &model)?;
    println!(
        "{}: clip `{}`, {} training + {} validation frames, {} vertices, {} active joints, {} lobe(s)",
        loaded.name,
        c.clip_name(),
        train_set.len(),
        validate.len(),
        model.vertices,
        model.active.len(),
        model.lobes
    );
    println!(
        "lobe fit error {:.4} ± {:.4}; ridge {:.0e} (relative, by blocked cross-validation); validation error {:.4}; model {:.2} MB; {:.1} s",
        report.lobe_fit_error.0,
        report.lobe_fit_error.1,
        report.ridge,
        report.validation_error,
        model.megabytes(),
        start.elapsed().as_secs_f64()
    );
    println!("wrote {}", args.out.display());
    Ok(())
}

fn run_render(args: &RenderArgs) -> Result<()> {
    let loaded = load_character(&args.clip.character, args.clip.clip.as_deref())?;
    let model = read_model(&args.model, &loaded)?;
    let env = load_env(&args.env)?;
    let shader = args.shading.shader()?;
    let c = &loaded.character;
    let range = frame_range(c, args.clip.frames)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let lighting = env.project();
    let (w, h) = (args.res.width, args.res.height);
    let first = c.pose(range.start as f32 / FPS);
    let camera = framing_camera(&first, w, h);
    let mut image = VertexImage::new(c);
    let mut raw = Vec::new();
    let mut exposure = None;
    let progress = bar((range.end - range.start) as u64, "rendering", "frames");
    for i in range.start..range.end {
        let t = i as f32 / FPS;
        let pose = c.pose(t);
        fade::predict(
            &model,
            FadeRule::of_mode(shader.mode()),
            &pose.joint_rotations,
            &mut raw,
        );
        let light = lighting.rotated_about_up((args.light_rotate * t).to_radians());
        let values = shader.shade(
            Visibility::Model(&model, &raw),
            ShadingGeometry {
                positions: &pose.positions,
                frames: &pose.frames,
                transform: pose.transform,
            },
            &light.rgb,
            camera.position,
        )?;
        let exposure = *exposure.get_or_insert_with(|| exposure_for(&values));
        image.rasterize(&pose, &camera, w, h)?;
        let pixels = image.shade(&values, 3);
        let rgb: Vec<u8> = pixels
            .iter()
            .map(|&v| (display(v, exposure) * 255.0).round() as u8)
            .collect();
        write_rgb_png(&args.out.join(format!("frame_{i:05}.png")), w, h, rgb)?;
        progress.inc(1);
    }
    progress.finish_and_clear();
    println!(
        "{} frames in {}; {}",
        range.end - range.start,
        args.out.display(),
        encode_video(&args.out, 30, "relight.mp4")
    );
    Ok(())
}

/// Loads a character and its model (used by eval and bench).
pub fn character_and_model(
    character: &Path,
    clip: Option<&str>,
    model: &Path,
) -> Result<(LoadedCharacter, psao_prt::model::PoseModel)> {
    let loaded = load_character(character, clip)?;
    let model = read_model(model, &loaded)?;
    Ok((loaded, model))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn test_frames_are_held_out_of_training_and_validation() {
        let range = FrameRange { start: 0, end: 20 };
        let s = split(range, 1, Some(FrameRange { start: 10, end: 13 })).unwrap();
        let expected: Vec<f32> = [10.0f32, 11.0, 12.0].iter().map(|i| i / FPS).collect();
        assert_eq!(s.test, expected);
        assert_eq!(s.train.len(), 17);
        for t in &s.test {
            assert!(!s.train.contains(t) && !s.validate.contains(t));
        }
        // Without a test range: half-frame times, none of them trained on.
        let s = split(range, 2, None).unwrap();
        assert_eq!(s.train.len(), 10);
        assert!(s
            .test
            .iter()
            .all(|t| !s.train.contains(t) && !s.validate.contains(t)));
        // A test range covering the whole training range leaves nothing to train on.
        assert!(split(range, 1, Some(FrameRange { start: 0, end: 19 })).is_err());
    }
}
