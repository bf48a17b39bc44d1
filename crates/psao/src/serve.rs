//! `psao serve` (issue 4, in progress).

use anyhow::Result;

/// Arguments of `psao serve`.
#[derive(clap::Args, Debug)]
pub struct ServeArgs {}

/// Runs `psao serve`.
pub fn run(_args: &ServeArgs) -> Result<()> {
    anyhow::bail!("`psao serve` is not available yet")
}
