//! The evaluation report: `report.json`, `report.md`, SVG plots and image crops.

use anyhow::{Context, Result};
use plotters::prelude::*;
use psao_eval::AoImage;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::Path;

/// One method's mean results (a row of the paper's Table 1).
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    /// `psao`, `ssao` or `rtao`; with `--lighting gi` also `psao-ao` (the PSAO session's
    /// AO-only composite).
    pub method: String,
    /// Points per unit area (PSAO only).
    pub points: Option<f32>,
    /// Server rate (PSAO only).
    pub server_hz: Option<u32>,
    /// Update codec (PSAO only).
    pub codec: Option<String>,
    /// LPIPS (AlexNet, v0.1) of AO-only images; left out without weights.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lpips_ao: Option<f64>,
    /// LPIPS of composited images (luma); left out without weights.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lpips_comp: Option<f64>,
    /// PSNR of AO-only images (dB).
    pub psnr_ao: f64,
    /// SSIM of AO-only images.
    pub ssim_ao: f64,
    /// FLIP of AO-only images.
    pub flip_ao: f64,
    /// PSNR of composited images (luma, dB).
    pub psnr_comp: f64,
    /// SSIM of composited images (luma).
    pub ssim_comp: f64,
    /// FLIP of composited images (luma).
    pub flip_comp: f64,
    /// Received bandwidth, Mbit per second of scene time.
    pub mbit_s: f64,
    /// Mean server time per server frame (ms).
    pub server_ms: f64,
    /// Mean client (or per-pixel method) time per evaluated frame (ms).
    pub client_ms: f64,
    /// PSAO server work per server frame (means), `None` for other methods.
    pub work: Option<ServerWork>,
}

/// Mean server work per server frame of one PSAO run.
#[derive(Clone, Debug, Default, Serialize)]
pub struct ServerWork {
    /// `proximity` or `everything`.
    pub invalidation: String,
    /// Rays traced.
    pub rays: f64,
    /// Points restarted because geometry near them moved.
    pub invalidated_points: f64,
    /// Restarted points traced, and their rays.
    pub retraced_points: f64,
    pub retrace_rays: f64,
    /// Server ms spent posing and invalidating.
    pub animate_ms: f64,
    /// Largest server ms of a frame.
    pub max_server_ms: f64,
}

/// Bandwidth of one PSAO configuration over time.
pub struct Series {
    /// Legend label.
    pub label: String,
    /// Mbit received in each second of scene time.
    pub mbit_per_second: Vec<f64>,
}

/// Everything the report says.
pub struct Report {
    /// Scene name.
    pub scene: String,
    /// Camera path name.
    pub path: String,
    /// Resolution.
    pub res: String,
    /// Frame range `A..B`.
    pub frames: String,
    /// Metric stride.
    pub every: u32,
    /// Reference spp.
    pub spp: u32,
    /// The command line that made it.
    pub command: String,
    /// Result rows.
    pub rows: Vec<Row>,
    /// Why the rows have no LPIPS, when they have none.
    pub lpips_note: Option<String>,
}

/// The results as a Markdown table; LPIPS columns come first (like the paper's Table 1)
/// when any row has LPIPS.
pub fn table(rows: &[Row]) -> String {
    let with_lpips = rows.iter().any(|r| r.lpips_ao.is_some());
    let (lpips_head, lpips_rule) = if with_lpips {
        ("LPIPS AO | LPIPS comp | ", "---:|---:|")
    } else {
        ("", "")
    };
    let mut s = format!(
        "| method | points | server Hz | codec | {lpips_head}PSNR AO | SSIM AO | FLIP AO | PSNR comp | SSIM comp | FLIP comp | Mbit/s | server ms | client ms |\n\
         |---|---:|---:|---|{lpips_rule}---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for r in rows {
        let opt = |v: Option<String>| v.unwrap_or_else(|| "–".into());
        let lpips = if with_lpips {
            let cell = |v: Option<f64>| opt(v.map(|d| format!("{d:.4}")));
            format!("{} | {} | ", cell(r.lpips_ao), cell(r.lpips_comp))
        } else {
            String::new()
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {lpips}{:.2} | {:.4} | {:.4} | {:.2} | {:.4} | {:.4} | {:.2} | {:.1} | {:.1} |",
            r.method,
            opt(r.points.map(|p| format!("{p}"))),
            opt(r.server_hz.map(|h| h.to_string())),
            opt(r.codec.clone()),
            r.psnr_ao,
            r.ssim_ao,
            r.flip_ao,
            r.psnr_comp,
            r.ssim_comp,
            r.flip_comp,
            r.mbit_s,
            r.server_ms,
            r.client_ms
        );
    }
    s
}

/// The PSAO rows' server work per server frame as a Markdown table.
pub fn work_table(rows: &[Row]) -> String {
    let mut s = String::from(
        "| points | server Hz | invalidation | rays | invalidated points | re-traced points | re-trace rays | animate ms | server ms | max server ms |\n\
         |---:|---:|---|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for r in rows {
        let (Some(w), Some(points), Some(hz)) = (&r.work, r.points, r.server_hz) else {
            continue;
        };
        let _ = writeln!(
            s,
            "| {points} | {hz} | {} | {:.0} | {:.0} | {:.0} | {:.0} | {:.1} | {:.1} | {:.1} |",
            w.invalidation,
            w.rays,
            w.invalidated_points,
            w.retraced_points,
            w.retrace_rays,
            w.animate_ms,
            r.server_ms,
            w.max_server_ms
        );
    }
    s
}

/// Writes `report.json` (the list of rows), `report.md`, plots and crops into `dir`.
pub fn write(
    dir: &Path,
    report: &Report,
    bandwidth: &[Series],
    crops: &[(String, AoImage)],
) -> Result<()> {
    crate::run::write_json(&dir.join("report.json"), &report.rows)?;
    plot_quality_vs_points(&dir.join("quality_vs_points.svg"), &report.rows)?;
    plot_bandwidth(&dir.join("bandwidth.svg"), bandwidth)?;
    let multi_rate = report
        .rows
        .iter()
        .filter_map(|r| r.server_hz)
        .collect::<std::collections::BTreeSet<_>>()
        .len()
        > 1;
    if multi_rate {
        plot_quality_vs_rate(&dir.join("quality_vs_rate.svg"), &report.rows)?;
    }
    write_crops(&dir.join("crops.png"), crops)?;
    let mut md = format!(
        "# psao evaluation: {} / {}\n\n\
         {} px, frames {} (metrics on every {}th frame), reference {} spp. \
         AO-only and composited (base shading × AO, compared on luma) images against the reference.\n\n\
         Command: `{}`\n\n{}{}\n## Server work per server frame (means)\n\n{}\n",
        report.scene,
        report.path,
        report.res,
        report.frames,
        report.every,
        report.spp,
        report.command,
        table(&report.rows),
        report
            .lpips_note
            .as_ref()
            .map_or_else(String::new, |n| format!("\n{n}.\n")),
        work_table(&report.rows)
    );
    md.push_str("## Quality vs points\n\n![quality vs points](quality_vs_points.svg)\n\n");
    if multi_rate {
        md.push_str(
            "## Quality vs server rate\n\n![quality vs server rate](quality_vs_rate.svg)\n\n",
        );
    }
    md.push_str("## Bandwidth over time\n\n![bandwidth](bandwidth.svg)\n\n");
    let labels: Vec<&str> = crops.iter().map(|(l, _)| l.as_str()).collect();
    let _ = write!(
        md,
        "## Crops (middle evaluated frame, centre)\n\nLeft to right: {}.\n\n![crops](crops.png)\n",
        labels.join(" / ")
    );
    let file = dir.join("report.md");
    std::fs::write(&file, md).with_context(|| format!("cannot write {}", file.display()))
}

fn plot_err<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow::anyhow!("plotting failed: {e:?}")
}

/// One line of a plot.
struct Line {
    label: String,
    points: Vec<(f64, f64)>,
    markers: bool,
}

/// Axis captions and ranges of a plot.
struct Axes<'a> {
    caption: &'a str,
    x_desc: &'a str,
    y_desc: &'a str,
    x: std::ops::Range<f64>,
    y: std::ops::Range<f64>,
}

/// Draws `lines` into an SVG file with a legend.
fn line_plot(file: &Path, axes: &Axes, lines: &[Line]) -> Result<()> {
    let root = SVGBackend::new(file, (720, 420)).into_drawing_area();
    root.fill(&WHITE).map_err(plot_err)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(axes.caption, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(56)
        .build_cartesian_2d(axes.x.clone(), axes.y.clone())
        .map_err(plot_err)?;
    chart
        .configure_mesh()
        .x_desc(axes.x_desc)
        .y_desc(axes.y_desc)
        .draw()
        .map_err(plot_err)?;
    for (i, line) in lines.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        chart
            .draw_series(LineSeries::new(line.points.clone(), color.stroke_width(2)))
            .map_err(plot_err)?
            .label(line.label.clone())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], color));
        if line.markers {
            chart
                .draw_series(
                    line.points
                        .iter()
                        .map(|&p| Circle::new(p, 3, color.filled())),
                )
                .map_err(plot_err)?;
        }
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(plot_err)?;
    root.present().map_err(plot_err)
}

/// PSNR (AO only) of PSAO against points per unit area, one line per server rate, baselines flat.
fn plot_quality_vs_points(file: &Path, rows: &[Row]) -> Result<()> {
    let psao: Vec<&Row> = rows.iter().filter(|r| r.method == "psao").collect();
    let x_max = psao.iter().filter_map(|r| r.points).fold(0.0f32, f32::max) as f64 * 1.1 + 1.0;
    let rates: std::collections::BTreeSet<u32> = psao.iter().filter_map(|r| r.server_hz).collect();
    let mut lines: Vec<Line> = rates
        .iter()
        .map(|hz| Line {
            label: format!("PSAO @ {hz} Hz"),
            points: psao
                .iter()
                .filter(|r| r.server_hz == Some(*hz))
                .filter_map(|r| r.points.map(|p| (p as f64, r.psnr_ao)))
                .collect(),
            markers: true,
        })
        .collect();
    // Baselines: the methods without a density (the AO-only composite rows of a lit
    // evaluation, `psao-ao`, have the same AO as their `psao` rows).
    lines.extend(rows.iter().filter(|r| r.points.is_none()).map(|r| Line {
        label: r.method.clone(),
        points: vec![(0.0, r.psnr_ao), (x_max, r.psnr_ao)],
        markers: false,
    }));
    let (y_lo, y_hi) = y_range(rows.iter().map(|r| r.psnr_ao));
    let axes = Axes {
        caption: "AO PSNR vs points per unit area",
        x_desc: "points per unit area",
        y_desc: "PSNR (dB)",
        x: 0.0..x_max,
        y: y_lo..y_hi,
    };
    line_plot(file, &axes, &lines)
}

/// PSNR (AO only) against server rate, one line per density.
fn plot_quality_vs_rate(file: &Path, rows: &[Row]) -> Result<()> {
    let psao: Vec<&Row> = rows.iter().filter(|r| r.method == "psao").collect();
    let x_max = psao.iter().filter_map(|r| r.server_hz).max().unwrap_or(60) as f64 * 1.1;
    let mut densities: Vec<f32> = psao.iter().filter_map(|r| r.points).collect();
    densities.sort_by(f32::total_cmp);
    densities.dedup();
    let lines: Vec<Line> = densities
        .iter()
        .map(|n| {
            let mut points: Vec<(f64, f64)> = psao
                .iter()
                .filter(|r| r.points == Some(*n))
                .filter_map(|r| r.server_hz.map(|h| (h as f64, r.psnr_ao)))
                .collect();
            points.sort_by(|a, b| a.0.total_cmp(&b.0));
            Line {
                label: format!("PSAO-{n}"),
                points,
                markers: true,
            }
        })
        .collect();
    let mut lines = lines;
    if let Some(ssao) = rows.iter().find(|r| r.method == "ssao") {
        // SSAO runs on the client at every frame: a flat line.
        lines.push(Line {
            label: "SSAO".into(),
            points: vec![(0.0, ssao.psnr_ao), (x_max, ssao.psnr_ao)],
            markers: false,
        });
    }
    let (y_lo, y_hi) = y_range(rows.iter().map(|r| r.psnr_ao));
    let axes = Axes {
        caption: "AO PSNR vs server rate",
        x_desc: "server Hz",
        y_desc: "PSNR (dB)",
        x: 0.0..x_max,
        y: y_lo..y_hi,
    };
    line_plot(file, &axes, &lines)
}

/// Received Mbit per second of scene time for each configuration.
fn plot_bandwidth(file: &Path, series: &[Series]) -> Result<()> {
    let x_max = series
        .iter()
        .map(|s| s.mbit_per_second.len())
        .max()
        .unwrap_or(1) as f64;
    let y_max = series
        .iter()
        .flat_map(|s| s.mbit_per_second.iter().copied())
        .fold(0.0, f64::max)
        * 1.1
        + 1e-3;
    let lines: Vec<Line> = series
        .iter()
        .map(|s| Line {
            label: s.label.clone(),
            points: s
                .mbit_per_second
                .iter()
                .enumerate()
                .map(|(t, &v)| (t as f64 + 0.5, v))
                .collect(),
            markers: false,
        })
        .collect();
    let axes = Axes {
        caption: "Received bandwidth over time",
        x_desc: "scene time (s)",
        y_desc: "Mbit/s",
        x: 0.0..x_max,
        y: 0.0..y_max,
    };
    line_plot(file, &axes, &lines)
}

/// A y range with margin around finite values.
fn y_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
            (l.min(v), h.max(v))
        });
    if lo > hi {
        return (0.0, 1.0);
    }
    (lo - 2.0, hi + 2.0)
}

/// The central half of each image, side by side with a 4-pixel gap, as 8-bit gray.
fn write_crops(file: &Path, crops: &[(String, AoImage)]) -> Result<()> {
    let Some((_, first)) = crops.first() else {
        return Ok(());
    };
    let (cw, ch) = (first.width / 2, first.height / 2);
    let (x0, y0) = (first.width / 4, first.height / 4);
    let gap = 4;
    let width = crops.len() as u32 * (cw + gap) - gap;
    let mut out = image::GrayImage::from_pixel(width, ch, image::Luma([255]));
    for (k, (_, img)) in crops.iter().enumerate() {
        for y in 0..ch {
            for x in 0..cw {
                let v = img.data[((y + y0) * img.width + x + x0) as usize];
                let px = k as u32 * (cw + gap) + x;
                out.put_pixel(
                    px,
                    y,
                    image::Luma([(v.clamp(0.0, 1.0) * 255.0).round() as u8]),
                );
            }
        }
    }
    out.save(file)
        .with_context(|| format!("cannot write {}", file.display()))
}
