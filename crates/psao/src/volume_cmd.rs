//! `psao volume …`: inspect, convert, render and benchmark sparse volumes (DESIGN §6).

use crate::png_io::write_rgb_png;
use crate::progress;
use anyhow::{bail, Context, Result};
use glam::Vec3;
use psao_volume::render;
use psao_volume::{
    psv, vdb, BrickFormat, Camera, ClusterParams, GridClass, Procedural, RenderMode,
    RenderSettings, SparseGrid, Volume,
};
use std::path::{Path, PathBuf};
use std::time::Instant;

mod bench;

/// Volume subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum VolumeCommand {
    /// Print a summary of a volume file (.vdb or .psv).
    Info {
        /// The volume file.
        file: PathBuf,
    },
    /// Convert OpenVDB file(s) (several = animation frames) to a compact .psv file.
    Convert {
        /// Input .vdb files, in frame order.
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// Brick format: f32, f16, unorm8, bc4, bc7.
        #[arg(long, default_value = "bc7")]
        format: String,
        /// Brick clustering `K,ITERATIONS,THRESHOLD`.
        #[arg(long)]
        cluster: Option<String>,
        /// Seed of the clustering.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Grid name (default: the first float grid).
        #[arg(long)]
        grid: Option<String>,
        /// Output .psv file.
        #[arg(long)]
        out: PathBuf,
        /// Also write sizes and errors as JSON here.
        #[arg(long)]
        json: Option<PathBuf>,
    },
    /// Render a volume (.vdb files as frames, or one .psv) to a PNG.
    Render {
        /// Input file(s).
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// levelset, fog or deltatrack (default: levelset for level sets, fog otherwise).
        #[arg(long)]
        mode: Option<String>,
        /// Brick format for .vdb input.
        #[arg(long, default_value = "f32")]
        format: String,
        /// Image size WxH.
        #[arg(long, default_value = "512x512")]
        res: String,
        /// Frame to render.
        #[arg(long, default_value_t = 0)]
        frame: usize,
        /// Camera eye `x,y,z` (default: framing the world bounds).
        #[arg(long)]
        eye: Option<String>,
        /// Camera target `x,y,z` (default: bounds centre).
        #[arg(long)]
        target: Option<String>,
        /// Vertical field of view in degrees.
        #[arg(long, default_value_t = 40.0)]
        fov: f32,
        /// Extinction per world unit at density 1 (default: 1 / (8 voxels)).
        #[arg(long)]
        density_scale: Option<f32>,
        /// Samples per pixel (deltatrack).
        #[arg(long, default_value_t = 8)]
        spp: u32,
        /// Seed (deltatrack).
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Grid name for .vdb input.
        #[arg(long)]
        grid: Option<String>,
        /// Output PNG.
        #[arg(long)]
        out: PathBuf,
    },
    /// Per-format table (bits per voxel, RMSE, max error) and optional clustering rows.
    Table {
        /// Input .vdb file(s) (one volume; several = frames).
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// Clustering rows `K,ITERATIONS,THRESHOLD` (BC7), repeatable.
        #[arg(long)]
        cluster: Vec<String>,
        /// Seed of the clustering.
        #[arg(long, default_value_t = 1)]
        seed: u64,
    },
    /// Speed ratios on several volumes, one row per volume and mode, worst ratios last: fog
    /// through BC7 vs f32 bricks (target ≥ 0.8×), HDDA level set vs dense fixed-step march
    /// (target ≥ 3×).
    Bench {
        /// Input .vdb files, each measured on its own.
        files: Vec<PathBuf>,
        /// Generated volumes to add, comma-separated: cloud, box, torus, smoke, or `all`.
        #[arg(long)]
        generated: Option<String>,
        /// Domain edge in voxels of the generated volumes (default: per kind).
        #[arg(long)]
        size: Option<u32>,
        /// Seed of the generated volumes.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Image size WxH.
        #[arg(long, default_value = "384x384")]
        res: String,
        /// Repetitions per renderer, alternating (the best time counts).
        #[arg(long, default_value_t = 3)]
        reps: u32,
    },
}

/// Runs a volume subcommand.
pub fn run(command: &VolumeCommand) -> Result<()> {
    match command {
        VolumeCommand::Info { file } => info(file),
        VolumeCommand::Convert {
            files,
            format,
            cluster,
            seed,
            grid,
            out,
            json,
        } => convert(
            files,
            format,
            cluster.as_deref(),
            *seed,
            grid.as_deref(),
            out,
            json.as_deref(),
        ),
        VolumeCommand::Render {
            files,
            mode,
            format,
            res,
            frame,
            eye,
            target,
            fov,
            density_scale,
            spp,
            seed,
            grid,
            out,
        } => {
            let vol = load_volume(files, format, grid.as_deref())?;
            let (w, h) = parse_res(res)?;
            let mode = match mode.as_deref() {
                None if vol.class == GridClass::LevelSet => RenderMode::LevelSet,
                None => RenderMode::Fog,
                Some(m) => parse_mode(m)?,
            };
            if *frame >= vol.frames() {
                bail!(
                    "frame {frame} out of range (the volume has {} frames)",
                    vol.frames()
                );
            }
            let mut cam = Camera::framing(vol.world_bounds(*frame), *fov);
            if let Some(t) = target {
                cam.target = parse_vec3(t).context("--target")?;
            }
            if let Some(e) = eye {
                cam.eye = parse_vec3(e).context("--eye")?;
            }
            let mut st = RenderSettings::new(&vol, w, h, mode);
            st.frame = *frame;
            st.spp = (*spp).max(1);
            st.seed = *seed;
            if let Some(d) = density_scale {
                st.density_scale = *d;
            }
            let start = Instant::now();
            let img = render::render(&vol, &cam, &st).context("rendering failed")?;
            eprintln!("rendered {w}x{h} in {:.3} s", start.elapsed().as_secs_f64());
            write_gray(out, &img)
        }
        VolumeCommand::Table {
            files,
            cluster,
            seed,
        } => table(files, cluster, *seed),
        VolumeCommand::Bench {
            files,
            generated,
            size,
            seed,
            res,
            reps,
        } => {
            let (w, h) = parse_res(res)?;
            let mut inputs: Vec<bench::Input> =
                files.iter().cloned().map(bench::Input::File).collect();
            for kind in parse_generated(generated.as_deref())? {
                let n = size.unwrap_or_else(|| kind.default_size());
                inputs.push(bench::Input::Generated(kind, n, *seed));
            }
            if inputs.is_empty() {
                bail!("no volume to measure: give .vdb files and/or --generated KINDS");
            }
            bench::run(&inputs, w, h, (*reps).max(1))
        }
    }
}

/// Kinds named by `--generated` (comma-separated, or `all`).
fn parse_generated(s: Option<&str>) -> Result<Vec<Procedural>> {
    match s {
        None => Ok(Vec::new()),
        Some("all") => Ok(Procedural::ALL.to_vec()),
        Some(list) => list
            .split(',')
            .map(|k| {
                Procedural::parse(k.trim()).with_context(|| {
                    format!("unknown generated volume `{k}` (cloud, box, torus, smoke, all)")
                })
            })
            .collect(),
    }
}

fn parse_format(s: &str) -> Result<BrickFormat> {
    BrickFormat::parse(s)
        .with_context(|| format!("unknown brick format `{s}` (f32, f16, unorm8, bc4, bc7)"))
}

fn parse_mode(s: &str) -> Result<RenderMode> {
    Ok(match s {
        "levelset" => RenderMode::LevelSet,
        "fog" => RenderMode::Fog,
        "deltatrack" => RenderMode::DeltaTrack,
        _ => bail!("unknown mode `{s}` (levelset, fog, deltatrack)"),
    })
}

fn parse_res(s: &str) -> Result<(u32, u32)> {
    let (a, b) = s
        .split_once('x')
        .with_context(|| format!("--res `{s}` is not WxH"))?;
    let (w, h): (u32, u32) = (a.parse()?, b.parse()?);
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        bail!("--res `{s}` out of range");
    }
    Ok((w, h))
}

fn parse_vec3(s: &str) -> Result<Vec3> {
    let v: Vec<f32> = s
        .split(',')
        .map(|x| x.trim().parse::<f32>())
        .collect::<std::result::Result<_, _>>()
        .with_context(|| format!("`{s}` is not x,y,z"))?;
    if v.len() != 3 {
        bail!("`{s}` is not x,y,z");
    }
    Ok(Vec3::new(v[0], v[1], v[2]))
}

fn parse_cluster(s: &str, seed: u64) -> Result<ClusterParams> {
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() != 3 {
        bail!("--cluster `{s}` is not K,ITERATIONS,THRESHOLD");
    }
    Ok(ClusterParams {
        k: parts[0].trim().parse().context("cluster K")?,
        iterations: parts[1].trim().parse().context("cluster iterations")?,
        threshold: parts[2].trim().parse().context("cluster threshold")?,
        seed,
    })
}

fn read_frames(files: &[PathBuf], grid: Option<&str>) -> Result<Vec<SparseGrid>> {
    let bar = progress::bar(files.len() as u64, "reading", "files");
    let mut frames = Vec::new();
    for f in files {
        let g =
            vdb::read_vdb_file(f, grid).with_context(|| format!("cannot load {}", f.display()))?;
        frames.push(g);
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok(frames)
}

fn is_psv_file(path: &Path) -> bool {
    let mut head = [0u8; 8];
    std::fs::File::open(path)
        .and_then(|mut f| std::io::Read::read_exact(&mut f, &mut head))
        .is_ok()
        && psv::is_psv(&head)
}

fn load_volume(files: &[PathBuf], format: &str, grid: Option<&str>) -> Result<Volume> {
    if files.len() == 1 && is_psv_file(&files[0]) {
        return psv::read_file(&files[0])
            .with_context(|| format!("cannot load {}", files[0].display()));
    }
    let frames = read_frames(files, grid)?;
    let (vol, _) =
        Volume::build(&frames, parse_format(format)?, None).context("cannot build the volume")?;
    Ok(vol)
}

fn write_gray(out: &Path, img: &psao_volume::Image) -> Result<()> {
    let rgb: Vec<u8> = img
        .pixels
        .iter()
        .flat_map(|&v| {
            let g = (v.clamp(0.0, 1.0).powf(1.0 / 2.2) * 255.0).round() as u8;
            [g, g, g]
        })
        .collect();
    write_rgb_png(out, img.width, img.height, rgb)
}

fn info(file: &Path) -> Result<()> {
    if is_psv_file(file) {
        let vol =
            psv::read_file(file).with_context(|| format!("cannot load {}", file.display()))?;
        let s = vol.tree.stats();
        println!(
            "{}: .psv, {} volume, {} frames, format {}",
            file.display(),
            vol.class.name(),
            vol.frames(),
            vol.pool.format.name()
        );
        println!(
            "  bricks {}, brick bytes {}, tree bytes {}",
            vol.pool.len(),
            vol.pool.byte_size(),
            s.total_bytes()
        );
        print_tree(&s);
        let (lo, hi) = vol.world_bounds(0);
        println!("  world bounds {lo} .. {hi}");
        return Ok(());
    }
    let bytes = vdb::read_regular_file(file)?;
    let label = file.display().to_string();
    let header =
        vdb::inspect_vdb(&bytes, &label).with_context(|| format!("cannot load {label}"))?;
    println!("{label}: OpenVDB file version {}", header.file_version);
    for g in &header.grids {
        println!(
            "  grid `{}`: {} class {} half {} transform {} background {}",
            g.name,
            g.grid_type,
            g.class.as_deref().unwrap_or("-"),
            g.half_float,
            g.transform_name,
            g.background
        );
    }
    let grid = vdb::read_vdb_bytes(&bytes, &label, None)
        .with_context(|| format!("cannot load {label}"))?;
    let (lo, hi) = grid.leaf_bounds().context("no leaves")?;
    println!(
        "  read `{}`: {} grid, {} leaves, {} tiles, {} active voxels, index bounds {lo} .. {hi}, voxel size {}, translation {}",
        grid.name,
        grid.class.name(),
        grid.leaves.len(),
        grid.tiles.len(),
        grid.active_voxels(),
        grid.transform.scale,
        grid.transform.translation
    );
    Ok(())
}

fn print_tree(s: &psao_volume::tree::TreeStats) {
    println!("  level | nodes | bytes");
    println!("  L1 | {} | {}", s.l1_nodes, s.l1_bytes);
    println!("  L2 | {} | {}", s.l2_nodes, s.l2_bytes);
    println!("  L3 | {} | {}", s.l3_nodes, s.l3_bytes);
    println!(
        "  masks ({} full, no entry) | {} | {}",
        s.full_masks,
        s.l3_nodes - s.full_masks,
        s.mask_bytes
    );
}

fn convert(
    files: &[PathBuf],
    format: &str,
    cluster: Option<&str>,
    seed: u64,
    grid: Option<&str>,
    out: &Path,
    json: Option<&Path>,
) -> Result<()> {
    let format = parse_format(format)?;
    let params = cluster.map(|c| parse_cluster(c, seed)).transpose()?;
    let frames = read_frames(files, grid)?;
    let start = Instant::now();
    let (vol, build) =
        Volume::build(&frames, format, params.as_ref()).context("cannot build the volume")?;
    let build_s = start.elapsed().as_secs_f64();
    psv::write_file(&vol, out).with_context(|| format!("cannot write {}", out.display()))?;
    let active: u64 = frames.iter().map(|g| g.active_voxels()).sum();
    let sizes = vol.sizes(active);
    let err = vol.compare(&frames)?;
    println!(
        "{} -> {}: {} frames, {}, bricks {} -> {}, bits/voxel bricks {:.3} total {:.3}, bits/active voxel {:.3}, RMSE {:.5}, max error {:.4} ({build_s:.2} s)",
        files[0].display(),
        out.display(),
        vol.frames(),
        format.name(),
        build.bricks_before,
        build.bricks_after,
        sizes.bits_per_voxel_bricks(),
        sizes.bits_per_voxel_total(),
        sizes.bits_per_active_voxel(),
        err.rmse,
        err.max_error
    );
    print_tree(&sizes.tree);
    if let Some(path) = json {
        let value = serde_json::json!({
            "files": files.iter().map(|f| f.display().to_string()).collect::<Vec<_>>(),
            "format": format.name(),
            "frames": vol.frames(),
            "cluster": params.map(|p| serde_json::json!({"k": p.k, "iterations": p.iterations, "threshold": p.threshold, "seed": p.seed})),
            "active_voxels": active,
            "brick_bytes": sizes.brick_bytes,
            "tree_bytes": sizes.tree.total_bytes(),
            "tree": {
                "l1_nodes": sizes.tree.l1_nodes, "l1_bytes": sizes.tree.l1_bytes,
                "l2_nodes": sizes.tree.l2_nodes, "l2_bytes": sizes.tree.l2_bytes,
                "l3_nodes": sizes.tree.l3_nodes, "l3_bytes": sizes.tree.l3_bytes,
                "full_masks": sizes.tree.full_masks, "mask_bytes": sizes.tree.mask_bytes,
            },
            "bits_per_voxel_bricks": sizes.bits_per_voxel_bricks(),
            "bits_per_voxel_total": sizes.bits_per_voxel_total(),
            "bits_per_active_voxel": sizes.bits_per_active_voxel(),
            "rmse": err.rmse,
            "max_error": err.max_error,
            "bricks_before": build.bricks_before,
            "bricks_after": build.bricks_after,
            "build_seconds": build_s,
        });
        std::fs::write(path, serde_json::to_string_pretty(&value)?)
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}

fn table(files: &[PathBuf], cluster: &[String], seed: u64) -> Result<()> {
    let frames = read_frames(files, None)?;
    let active: u64 = frames.iter().map(|g| g.active_voxels()).sum();
    println!(
        "{}: {} frames, {} active voxels",
        files[0].display(),
        frames.len(),
        active
    );
    println!("| format | bits/voxel bricks | bits/voxel tree+bricks | bits/active voxel | RMSE | max error |");
    println!("|---|---|---|---|---|---|");
    let mut tree = None;
    for format in BrickFormat::ALL {
        let (vol, _) = Volume::build(&frames, format, None)?;
        let s = vol.sizes(active);
        let e = vol.compare(&frames)?;
        println!(
            "| {} | {:.3} | {:.3} | {:.3} | {:.5} | {:.4} |",
            format.name(),
            s.bits_per_voxel_bricks(),
            s.bits_per_voxel_total(),
            s.bits_per_active_voxel(),
            e.rmse,
            e.max_error
        );
        tree = Some(s.tree);
    }
    if let Some(t) = tree {
        print_tree(&t);
    }
    if !cluster.is_empty() {
        let (base, _) = Volume::build(&frames, BrickFormat::Bc7, None)?;
        let base_rmse = base.compare(&frames)?.rmse;
        println!("| k | iterations | threshold | bricks before | after | ratio | RMSE (bc7) | extra RMSE |");
        println!("|---|---|---|---|---|---|---|---|");
        for c in cluster {
            let p = parse_cluster(c, seed)?;
            let (vol, b) = Volume::build(&frames, BrickFormat::Bc7, Some(&p))?;
            let e = vol.compare(&frames)?;
            println!(
                "| {} | {} | {} | {} | {} | {:.4} | {:.5} | {:+.5} |",
                p.k,
                p.iterations,
                p.threshold,
                b.bricks_before,
                b.bricks_after,
                b.bricks_after as f64 / b.bricks_before as f64,
                e.rmse,
                e.rmse - base_rmse
            );
        }
    }
    Ok(())
}
