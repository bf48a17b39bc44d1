//! `psao corrective …`: perceptually guided corrective splatting (DESIGN §8).

mod bench;

use anyhow::Result;

/// Corrective-splatting subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum CorrectiveCommand {
    /// Time aging, reprojection and splatting of the sample cache on one camera move.
    Bench(bench::BenchArgs),
}

/// Runs a `psao corrective` subcommand.
pub fn run(command: &CorrectiveCommand) -> Result<()> {
    match command {
        CorrectiveCommand::Bench(a) => bench::run(a),
    }
}
