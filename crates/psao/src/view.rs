//! `psao view` (issue 4, in progress).

use anyhow::Result;

/// Arguments of `psao view`.
#[derive(clap::Args, Debug)]
pub struct ViewArgs {}

/// Runs `psao view`.
pub fn run(_args: &ViewArgs) -> Result<()> {
    anyhow::bail!("`psao view` is not available yet")
}
