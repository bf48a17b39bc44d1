//! `psao bench serve` (issue 4, in progress).

use anyhow::Result;

/// Arguments of `psao bench serve`.
#[derive(clap::Args, Debug)]
pub struct BenchServeArgs {}

/// Runs `psao bench serve`.
pub fn run(_args: &BenchServeArgs) -> Result<()> {
    anyhow::bail!("`psao bench serve` is not available yet")
}
