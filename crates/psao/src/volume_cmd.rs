//! `psao volume …` (issue 6, in progress).

use anyhow::Result;
use std::path::PathBuf;

/// Volume subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum VolumeCommand {
    /// Print a summary of a volume file.
    Info {
        /// The volume file.
        file: PathBuf,
    },
}

/// Runs a volume subcommand.
pub fn run(_command: &VolumeCommand) -> Result<()> {
    anyhow::bail!("`psao volume` is not available yet")
}
