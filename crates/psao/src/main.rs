//! `psao`: point-based split ambient occlusion — command-line entry point.

mod access_args;
mod args;
mod bench_client;
mod bench_nats;
mod bench_relight;
mod bench_scale;
mod bench_serve;
mod bench_step;
mod bench_trace;
mod compare;
mod corrective;
mod demo;
mod demo_relight;
mod eval;
mod lpips_weights;
mod memory_account;
mod paths_cmd;
mod png_io;
mod progress;
mod reference;
mod relight_cmd;
mod relight_eval;
mod relight_io;
mod report;
mod run;
mod scale_cmd;
mod scene_source;
mod scene_volume;
mod serve;
mod served_characters;
mod video;
mod view;
mod volume_cmd;

use anyhow::Result;
use clap::{Parser, Subcommand};

/// Split-rendered ambient occlusion: a server ray-traces AO at surface points, clients rasterize
/// and reconstruct it per pixel.
#[derive(Parser, Debug)]
#[command(name = "psao", version, about, long_about = None)]
struct Cli {
    /// Log level filter (error, warn, info, debug, trace), or any `tracing` env-filter directive.
    #[arg(long, global = true, default_value = "info")]
    log: String,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Run the main job on the built-in default scene and write images and a report.
    Demo(demo::DemoArgs),
    /// Run server and client in one process along a camera path, writing frames and stats.
    Run(run::RunArgs),
    /// Evaluate PSAO against the reference, SSAO and few-spp RTAO; write report.json and report.md.
    Eval(eval::EvalArgs),
    /// Render per-pixel reference AO (16-bit grayscale PNGs) or path-traced diffuse lighting
    /// (`--lighting gi`: linear HDR and an sRGB preview) along a camera path.
    Reference(reference::ReferenceArgs),
    /// Compare two AO images: PSNR, SSIM and FLIP.
    Compare(compare::CompareArgs),
    /// Serve AO updates to `psao view` clients over TCP and WebSocket.
    Serve(serve::ServeArgs),
    /// Trace one partition of a scene's points and publish its records through NATS
    /// (docs/SCALE-OUT.md).
    TraceNode(scale_cmd::TraceNodeArgs),
    /// Rebuild the published point state from NATS and serve viewers like `psao serve`.
    Edge(scale_cmd::EdgeArgs),
    /// Connect to a `psao serve`, follow a camera path and write frames (headless client).
    View(view::ViewArgs),
    /// Sparse volumes: inspect, convert and render OpenVDB and `.psv` files.
    #[command(subcommand)]
    Volume(volume_cmd::VolumeCommand),
    /// Shadowed relighting of skinned characters: train, render and evaluate.
    #[command(subcommand)]
    Relight(relight_cmd::RelightCommand),
    /// Perceptually guided corrective splatting: evaluation and benchmarks.
    #[command(subcommand)]
    Corrective(corrective::CorrectiveCommand),
    /// Benchmarks.
    #[command(subcommand)]
    Bench(BenchCommand),
    /// Generate camera paths through a scene's free space (walks at eye height, per seed)
    /// and write them as path files for `--path`.
    Paths(paths_cmd::PathsArgs),
}

#[derive(Subcommand, Debug)]
enum BenchCommand {
    /// Trace one AO ray set through every compiled backend, unsorted and sorted, on 1 and 2 threads.
    Trace(bench_trace::BenchTraceArgs),
    /// Time the client's AO reconstruction against SSAO on the same G-buffer.
    Client(bench_client::BenchClientArgs),
    /// One server and N headless clients on loopback: per-client Mbit/s, server ms, coalescing.
    Serve(bench_serve::BenchServeArgs),
    /// The server alone in this process: N clients' views, per-phase ms and CPU per frame.
    Step(bench_step::BenchStepArgs),
    /// Trace nodes over NATS against the one-process server: rays/s, bytes, takeover time.
    Scale(bench_scale::BenchScaleArgs),
    /// Synthesis + shading time per frame of a relighting model.
    Relight(bench_relight::BenchRelightArgs),
    /// One NATS server's rate storing record-batch-sized messages for 1, 2, 4, … consumers.
    Nats(bench_nats::BenchNatsArgs),
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let filter = tracing_subscriber::EnvFilter::try_new(&cli.log)
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_target(false)
        .init();
    match run(cli.command) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(command: Command) -> Result<()> {
    match command {
        Command::Demo(a) => demo::run(&a),
        Command::Run(a) => run::run(&a),
        Command::Eval(a) => eval::run(&a),
        Command::Reference(a) => reference::run(&a),
        Command::Compare(a) => compare::run(&a),
        Command::Bench(BenchCommand::Trace(a)) => bench_trace::run(&a),
        Command::Bench(BenchCommand::Client(a)) => bench_client::run(&a),
        Command::Bench(BenchCommand::Serve(a)) => bench_serve::run(&a),
        Command::Bench(BenchCommand::Step(a)) => bench_step::run(&a),
        Command::Bench(BenchCommand::Relight(a)) => bench_relight::run(&a),
        Command::Bench(BenchCommand::Scale(a)) => bench_scale::run(&a),
        Command::Bench(BenchCommand::Nats(a)) => bench_nats::run(&a),
        Command::Serve(a) => serve::run(&a),
        Command::View(a) => view::run(&a),
        Command::TraceNode(a) => scale_cmd::run_trace_node(&a),
        Command::Edge(a) => scale_cmd::run_edge(&a),
        Command::Volume(c) => volume_cmd::run(&c),
        Command::Relight(c) => relight_cmd::run(&c),
        Command::Corrective(c) => corrective::run(&c),
        Command::Paths(a) => paths_cmd::run(&a),
    }
}
