//! `psao compare`: image metrics between two AO images.

use crate::png_io::read_ao_png;
use anyhow::{Context, Result};
use clap::Args;
use std::path::PathBuf;

/// Arguments of `psao compare`.
#[derive(Args, Debug)]
pub struct CompareArgs {
    /// The reference image (PNG).
    pub reference: PathBuf,
    /// The image to evaluate (PNG).
    pub test: PathBuf,
    /// Print JSON (`psnr`, `ssim`, `flip`) instead of text.
    #[arg(long)]
    pub json: bool,
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
    if args.json {
        println!("{}", serde_json::to_string(&m)?);
    } else {
        println!(
            "PSNR {:.2} dB  SSIM {:.4}  FLIP {:.4}",
            m.psnr, m.ssim, m.flip
        );
    }
    Ok(())
}
