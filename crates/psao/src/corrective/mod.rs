//! `psao corrective …`: perceptually guided corrective splatting (DESIGN §8).

mod bench;
mod eval;
mod plot;
pub mod split_args;

use anyhow::Result;

/// Corrective-splatting subcommands.
#[derive(clap::Subcommand, Debug)]
pub enum CorrectiveCommand {
    /// Time aging, reprojection and splatting of the sample cache on one camera move.
    Bench(bench::BenchArgs),
    /// Corrected frames along a camera path at several budgets and orderings against the
    /// reference: report.json, report.md, convergence.svg, base/corrected/reference PNGs.
    Eval(eval::EvalArgs),
}

/// Runs a `psao corrective` subcommand.
pub fn run(command: &CorrectiveCommand) -> Result<()> {
    match command {
        CorrectiveCommand::Bench(a) => bench::run(a),
        CorrectiveCommand::Eval(a) => eval::run(a),
    }
}
