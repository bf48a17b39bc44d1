//! `psao demo`: the main job on the built-in default scene.
//!
//! For now it renders the reference AO of a few frames of the default scene's first camera path
//! and writes the images with a short report; the split pipeline replaces this when it lands.

use crate::args::Resolution;
use crate::png_io::write_ao_png;
use crate::progress;
use crate::reference::{frame_file, ReferenceRenderer};
use crate::scene_source::{SceneInput, BUILTIN_SCENE};
use anyhow::{bail, Context, Result};
use clap::Args;
use psao_trace::Backend;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `psao demo`.
#[derive(Args, Debug)]
pub struct DemoArgs {
    /// Output folder.
    #[arg(long, default_value = "out/demo")]
    pub out: PathBuf,
    /// Number of frames, spread evenly over the camera path.
    #[arg(long, default_value_t = 4)]
    pub frames: u32,
    /// Image size, `WxH`.
    #[arg(long, default_value = "480x270")]
    pub res: Resolution,
    /// Rays per pixel of the reference AO.
    #[arg(long, default_value_t = 128)]
    pub spp: u32,
}

/// Runs `psao demo`.
pub fn run(args: &DemoArgs) -> Result<()> {
    if args.frames == 0 || args.spp == 0 || args.spp > crate::reference::MAX_SPP {
        bail!(
            "--frames must be at least 1 and --spp in 1..={}",
            crate::reference::MAX_SPP
        );
    }
    let start = Instant::now();
    let input = SceneInput::load(BUILTIN_SCENE)?;
    let path = input.camera_path(None)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let backend = Backend::default();
    let renderer = ReferenceRenderer::new(&input.scene, backend, args.spp, 1)?;
    let last = path.frame_count().saturating_sub(1) as u32;
    let frames: Vec<u32> = (0..args.frames)
        .map(|k| k * last / (args.frames - 1).max(1))
        .collect();
    let pixels = args.res.width as u64 * args.res.height as u64;
    let bar = progress::bar(pixels * frames.len() as u64, "demo: reference AO", "px");
    let mut rows = String::new();
    for &frame in &frames {
        let t = Instant::now();
        let image = renderer.render(&path, frame, args.res, &|n| bar.inc(n));
        let file = frame_file(&args.out, frame);
        write_ao_png(&file, &image)?;
        writeln!(
            rows,
            "| {frame} | {:.2} | {:.3} | {:.0} | `{}` |",
            frame as f32 / psao_scene::path::PATH_HZ,
            image.mean(),
            t.elapsed().as_secs_f64() * 1e3,
            file.file_name().unwrap_or_default().to_string_lossy()
        )?;
    }
    bar.finish_and_clear();
    let report = format!(
        "# psao demo\n\n\
         Scene: built-in default ({} instanced triangles), camera path `{}`, {} at {} spp, \
         AO radius {} m, backend `{}`.\n\n\
         What this shows today: the per-pixel reference AO (DESIGN §2). The split pipeline \
         (server points, streaming, client reconstruction) replaces it as it lands.\n\n\
         | frame | time (s) | mean AO | render ms | image |\n|---:|---:|---:|---:|---|\n{rows}\n\
         Total wall time: {:.1} s. Command: `psao demo --out {} --frames {} --res {} --spp {}`.\n",
        input.scene.instanced_triangle_count(),
        path.name,
        args.res,
        args.spp,
        input.scene.ao_radius,
        backend.name(),
        start.elapsed().as_secs_f64(),
        args.out.display(),
        args.frames,
        args.res,
        args.spp,
    );
    let report_file = args.out.join("report.md");
    std::fs::write(&report_file, report)
        .with_context(|| format!("cannot write {}", report_file.display()))?;
    println!(
        "wrote {} frames and {}",
        frames.len(),
        report_file.display()
    );
    Ok(())
}
