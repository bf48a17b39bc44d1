//! `psao serve`: arguments, scene loading and printing around [`psao_net::serve`].

use std::net::SocketAddr;
use std::path::PathBuf;

use anyhow::{Context, Result};
use psao_net::serve::{Serve, ServeConfig};
use psao_net::start_cache::start_server;
use psao_net::Resolution;

use crate::access_args::ExposureArgs;
use crate::run::{write_json, LightingArgs, ServerTuning, SESSION_LIGHTING};
use crate::scene_source::SceneInput;
use crate::served_characters::{served_characters, RelightArgs};

/// Arguments of `psao serve`.
#[derive(clap::Args, Debug, Clone)]
pub struct ServeArgs {
    /// Scene: `default` (built in) or a .gltf/.glb/.obj/.toml file.
    #[arg(long, default_value = crate::scene_source::BUILTIN_SCENE)]
    pub scene: String,
    /// Address to listen on (TCP and WebSocket on the same port); port 0 picks a free one.
    #[arg(long, default_value = "127.0.0.1:7878")]
    pub listen: SocketAddr,
    #[command(flatten)]
    pub exposure: ExposureArgs,
    /// Points per unit area (after sample elimination).
    #[arg(long, default_value_t = 1024.0)]
    pub points: f32,
    /// Server frames per second of scene time.
    #[arg(long, default_value_t = 30)]
    pub hz: u32,
    #[command(flatten)]
    pub tuning: ServerTuning,
    #[command(flatten)]
    pub lighting: LightingArgs,
    /// Step once per round of client camera messages (deterministic; see docs/STREAMING.md).
    #[arg(long)]
    pub lockstep: bool,
    /// Wait for this many clients before the first server frame.
    #[arg(long, default_value_t = 1)]
    pub wait_clients: usize,
    /// Most clients at once; later ones are refused with a `Server` error.
    #[arg(long, default_value_t = 64)]
    pub max_clients: usize,
    /// Exit once every client has left (after at least one joined).
    #[arg(long)]
    pub once: bool,
    /// Write server statistics as JSON to this file on exit.
    #[arg(long)]
    pub json: Option<PathBuf>,
    #[command(flatten)]
    pub corrective: crate::corrective::split_args::CorrectiveArgs,
    #[command(flatten)]
    pub relight: RelightArgs,
}

/// Runs `psao serve`.
pub fn run(args: &ServeArgs) -> Result<()> {
    psao_net::process_memory::map_large_blocks_apart();
    let tls = args.exposure.tls()?;
    let token = args.exposure.token.token()?;
    let input = SceneInput::load(&args.scene)?;
    let lighting = args.lighting.config(SESSION_LIGHTING)?;
    let server = scene_server(&input, &args.tuning, lighting, args.points, args.hz)?;
    tracing::info!(
        "{} points on {} instances; codec {}",
        server.point_count(),
        input.scene.instances.len(),
        args.tuning.codec
    );
    let characters = served_characters(
        &input.scene,
        &args.relight,
        args.tuning.seed,
        args.tuning.points_cache_dir().as_deref(),
    )?;
    let config = ServeConfig {
        listen: args.listen,
        token,
        allow_origins: args.exposure.allow_origins.clone(),
        max_per_source: args.exposure.max_per_source,
        scene_name: input.name.clone(),
        codec: args.tuning.codec.clone(),
        hz: args.hz,
        lockstep: args.lockstep,
        wait_clients: args.wait_clients,
        max_clients: args.max_clients,
        once: args.once,
        stop_on_ctrl_c: true,
        scene_glb: psao_net::glb::scene_glb(&input.scene, &input.paths)?,
        characters: std::sync::Arc::new(characters),
        tls,
    };
    let mut serve = Serve::bind(server, config)?;
    if let Some(c) = args.corrective.config()? {
        let engine = psao_net::corrective::CorrectionEngine::new(
            std::sync::Arc::new(input.scene.clone()),
            args.tuning.backend.unwrap_or_default(),
            c.ao_spp,
            args.tuning.seed,
        )?
        .with_lighting(psao_net::corrective::LitCorrections::of(
            lighting.as_ref(),
            &c,
        ));
        serve = serve.with_corrections(
            psao_net::serve::Corrections::new(
                std::sync::Arc::new(engine),
                c.samples_per_second,
                psao_net::serve::DEFAULT_CORRECTION_WORKERS,
            )
            .with_time_budget(
                c.frame_ms
                    .map(|ms| std::time::Duration::from_secs_f32(ms / 1e3)),
            ),
        );
    }
    println!("listening on {}", serve.local_addr());
    let stats = serve.run();
    if let Some(json) = &args.json {
        write_json(json, &stats)?;
    }
    Ok(())
}

/// A server for `input` with `tuning` and `lighting` (`None`: AO only) at `points` per unit
/// area and `hz` server frames per second, started from stored start points when `tuning` allows (serving
/// has no image, so the resolution is 1×1).
pub(crate) fn scene_server(
    input: &SceneInput,
    tuning: &ServerTuning,
    lighting: Option<psao_server::LightingConfig>,
    points: f32,
    hz: u32,
) -> Result<psao_server::Server> {
    let mut config = tuning.config(
        points,
        hz,
        Resolution {
            width: 1,
            height: 1,
        },
    )?;
    config.server.lighting = lighting;
    let server = start_server(
        &input.scene,
        config.server,
        input.medium(),
        config.points_cache.as_deref(),
    )
    .context("cannot start the server (point generation or tracer)")?;
    // Start-up's temporary buffers are freed by now: give their pages back (docs/BENCHMARKS.md,
    // "The server process").
    psao_net::process_memory::release_free_memory();
    Ok(server)
}
