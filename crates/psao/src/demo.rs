//! `psao demo`: the split pipeline on the built-in default scene, end to end.
//!
//! Server and client run in one process along the scene's first camera path; the client's
//! composited and AO-only frames are written (and an MP4 when `ffmpeg` is installed), and a few
//! frames are compared with the per-pixel reference and with SSAO in `report.md`.

use crate::args::Resolution;
use crate::progress;
use crate::reference::ReferenceRenderer;
use crate::run::{write_frame_images, write_json, LightingArgs, ServerTuning, SESSION_LIGHTING};
use crate::scene_source::{SceneInput, BUILTIN_SCENE};
use crate::video::encode_video;
use anyhow::{bail, Context, Result};
use clap::Args;
use psao_eval::{compare, ssao, Metrics, SsaoSettings};
use psao_net::pipeline::{Pipeline, CLIENT_HZ};
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `psao demo`.
#[derive(Args, Debug)]
pub struct DemoArgs {
    /// Output folder.
    #[arg(long, default_value = "out/demo")]
    pub out: PathBuf,
    /// Seconds of the camera path to run.
    #[arg(long, default_value_t = 4.0)]
    pub seconds: f32,
    /// Client image size, `WxH`.
    #[arg(long, default_value = "640x360")]
    pub res: Resolution,
    /// Points per unit area.
    #[arg(long, default_value_t = 1024.0)]
    pub points: f32,
    /// Server frames per second.
    #[arg(long, default_value_t = 15)]
    pub server_hz: u32,
    /// Write every K-th client frame (the video runs at 60/K frames per second).
    #[arg(long, default_value_t = 2)]
    pub every: u32,
    /// Rays per pixel of the reference used for the quality table.
    #[arg(long, default_value_t = 128)]
    pub spp: u32,
    #[command(flatten)]
    pub tuning: ServerTuning,
    #[command(flatten)]
    pub lighting: LightingArgs,
}

/// Frames compared with the reference in the report.
const COMPARED_FRAMES: u32 = 3;

/// Runs `psao demo`.
pub fn run(args: &DemoArgs) -> Result<()> {
    if !(args.seconds > 0.0 && args.seconds <= 3600.0) || args.every == 0 {
        bail!("--seconds must be in (0, 3600] and --every at least 1");
    }
    let start = Instant::now();
    let input = SceneInput::load(BUILTIN_SCENE)?;
    let path = input.camera_path(None)?;
    let frames = ((args.seconds * CLIENT_HZ as f32) as u32).clamp(1, path.frame_count() as u32);
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let mut config = args.tuning.config(args.points, args.server_hz, args.res)?;
    config.server.lighting = args.lighting.config(SESSION_LIGHTING)?;
    let mut pipeline = Pipeline::new(&input.scene, &config)?;
    let compared: Vec<u32> = (1..=COMPARED_FRAMES)
        .map(|k| (k * frames / (COMPARED_FRAMES + 1)) / args.every * args.every)
        .collect();
    let mut renderer = ReferenceRenderer::new(&input.scene, config.server.backend, args.spp, 1)?;
    let bar = progress::bar(frames as u64, "demo: split pipeline", "frames");
    let mut records = Vec::new();
    let mut quality = String::new();
    for frame in 0..frames {
        let camera = path.camera_at_frame(frame as usize);
        let (record, image) = pipeline.frame(frame, &camera, frame.is_multiple_of(args.every))?;
        if let Some(img) = image {
            write_frame_images(&args.out, frame, &input.scene, &img)?;
            if compared.contains(&frame) {
                let reference = renderer.render(&path, frame, args.res, &|_| {})?;
                let ssao_ao = ssao(
                    &img.gbuffer,
                    &camera,
                    &SsaoSettings::new(input.scene.ao_radius),
                );
                let p = compare(&reference, &img.ao)?;
                let s = compare(&reference, &ssao_ao)?;
                crate::png_io::write_ao_png(
                    &args.out.join(format!("reference_{frame:05}.png")),
                    &reference,
                )?;
                writeln!(
                    quality,
                    "| {frame} | {} | {} |",
                    fmt_metrics(&p),
                    fmt_metrics(&s)
                )?;
            }
        }
        records.push(record);
        bar.inc(1);
    }
    bar.finish_and_clear();
    let video = encode_video(&args.out, CLIENT_HZ / args.every, "demo.mp4");
    let seconds = frames as f64 / CLIENT_HZ as f64;
    let server: Vec<_> = records.iter().filter(|r| r.server_frame).collect();
    let mean = |v: &mut dyn Iterator<Item = f64>, n: usize| v.sum::<f64>() / n.max(1) as f64;
    let rendered: Vec<_> = records
        .iter()
        .filter(|r| r.frame.is_multiple_of(args.every))
        .collect();
    let relight = crate::demo_relight::section(&args.out)?;
    let report = format!(
        "# psao demo\n\n\
         The split pipeline on the built-in default scene ({} instanced triangles): a server \
         ray-traces AO at {} points ({} per m²) and streams changed cells with the `{}` codec; \
         the client rasterizes its own G-buffer at {} and reconstructs AO per pixel.\n\n\
         | | |\n|---|---|\n\
         | camera path | `{}`, {:.1} s ({} client frames at {} Hz) |\n\
         | server | {} Hz, mean {:.1} ms per server frame, {:.2} Mrays per server frame |\n\
         | client | mean {:.1} ms per rendered frame (decode, raster, reconstruct) |\n\
         | bandwidth | {:.2} Mbit/s ({} bytes in total) |\n\
         | lighting | {} |\n\
         | backend | `{}` |\n\
         | video | {} |\n\
         | wall time | {:.1} s |\n\n\
         ## Quality against the {} spp per-pixel reference (AO only)\n\n\
         | frame | PSAO PSNR / SSIM / FLIP | SSAO PSNR / SSIM / FLIP |\n|---:|---|---|\n{}\n\
         Images: `frame_NNNNN.png` (composited), `ao_NNNNN.png` (AO only), \
         `reference_NNNNN.png`; per-frame numbers in `stats.json`.\n\n\
         {}\n\
         Command: `{}`\n",
        input.scene.instanced_triangle_count(),
        pipeline.server().point_count(),
        args.points,
        config.codec,
        args.res,
        path.name,
        seconds,
        frames,
        CLIENT_HZ,
        args.server_hz,
        mean(&mut server.iter().map(|r| r.server_ms), server.len()),
        mean(
            &mut server.iter().map(|r| r.rays as f64 / 1e6),
            server.len()
        ),
        mean(&mut rendered.iter().map(|r| r.client_ms), rendered.len()),
        pipeline.total_bytes as f64 * 8.0 / seconds / 1e6,
        pipeline.total_bytes,
        match config.server.lighting {
            Some(l) => format!(
                "`gi`: irradiance with {} bounce(s) at the points, shadow-mapped direct light on \
                 the client, `frame_NNNNN.png` = base colour / π × (direct + irradiance)",
                l.bounces
            ),
            None => "`ao`: `frame_NNNNN.png` is the AO composite".to_string(),
        },
        config.server.backend.name(),
        video,
        start.elapsed().as_secs_f64(),
        args.spp,
        quality,
        relight,
        std::env::args().collect::<Vec<_>>().join(" "),
    );
    write_json(&args.out.join("stats.json"), &records)?;
    let report_file = args.out.join("report.md");
    std::fs::write(&report_file, report)
        .with_context(|| format!("cannot write {}", report_file.display()))?;
    println!("wrote frames, {} and {}", video, report_file.display());
    Ok(())
}

fn fmt_metrics(m: &Metrics) -> String {
    format!("{:.2} dB / {:.4} / {:.4}", m.psnr, m.ssim, m.flip)
}
