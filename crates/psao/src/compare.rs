//! `psao compare`: image metrics between two AO images.

use crate::lpips_weights::{LpipsArgs, LpipsChoice};
use crate::png_io::read_ao_png;
use anyhow::{bail, Context, Result};
use clap::Args;
use std::path::PathBuf;

/// Arguments of `psao compare`.
#[derive(Args, Debug)]
pub struct CompareArgs {
    /// The reference image (PNG).
    pub reference: PathBuf,
    /// The image to evaluate (PNG).
    pub test: PathBuf,
    /// Print JSON (`lpips` when weights are found, `psnr`, `ssim`, `flip`) instead of text.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub lpips: LpipsArgs,
    /// Also print both images' mean AO over the pixel rectangle `X0,Y0,X1,Y1` (half-open).
    #[arg(long, value_delimiter = ',')]
    pub region: Option<Vec<u32>>,
}

/// Mean of `img` over the half-open pixel rectangle `r` = [x0, y0, x1, y1].
fn region_mean(img: &psao_eval::AoImage, r: &[u32]) -> f64 {
    let (mut sum, mut n) = (0.0, 0u64);
    for y in r[1]..r[3] {
        for x in r[0]..r[2] {
            sum += img.data[(y * img.width + x) as usize] as f64;
            n += 1;
        }
    }
    sum / n as f64
}

/// Runs `psao compare`.
pub fn run(args: &CompareArgs) -> Result<()> {
    let a = read_ao_png(&args.reference)?;
    let b = read_ao_png(&args.test)?;
    let m = psao_eval::compare(&a, &b).with_context(|| {
        format!(
            "cannot compare {} with {}",
            args.reference.display(),
            args.test.display()
        )
    })?;
    if let Some(r) = &args.region {
        if r.len() != 4 || r[0] >= r[2] || r[1] >= r[3] || r[2] > a.width || r[3] > a.height {
            bail!(
                "--region must be X0,Y0,X1,Y1 inside the {}x{} image",
                a.width,
                a.height
            );
        }
        println!(
            "mean AO over {}..{} x {}..{}: {:.4} (reference) vs {:.4} (test)",
            r[0],
            r[2],
            r[1],
            r[3],
            region_mean(&a, r),
            region_mean(&b, r)
        );
    }
    let lpips = match args.lpips.load()? {
        LpipsChoice::Ready(net) => Some(net.distance(&a, &b).with_context(|| {
            format!(
                "cannot compute LPIPS of {} against {}",
                args.test.display(),
                args.reference.display()
            )
        })?),
        LpipsChoice::Missing(_) => None,
    };
    if args.json {
        let mut out = serde_json::Map::new();
        if let Some(d) = lpips {
            out.insert("lpips".into(), d.into());
        }
        if let serde_json::Value::Object(fields) = serde_json::to_value(m)? {
            out.extend(fields);
        }
        println!("{}", serde_json::Value::Object(out));
    } else {
        let lpips = lpips.map_or_else(String::new, |d| format!("LPIPS {d:.4}  "));
        println!(
            "{lpips}PSNR {:.2} dB  SSIM {:.4}  FLIP {:.4}",
            m.psnr, m.ssim, m.flip
        );
    }
    Ok(())
}
