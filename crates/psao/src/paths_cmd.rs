//! `psao paths`: camera paths generated through a scene's free space
//! ([`psao_scene::path_gen`]), written as path files that every `--path` option reads, so
//! evaluations and benchmarks can run on views nobody tuned on.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use psao_eval::path_caster::generate_traced_paths;
use psao_scene::{CameraPath, PathGenConfig};
use psao_trace::Backend;

use crate::scene_source::SceneInput;

/// Arguments of `psao paths`.
#[derive(clap::Args, Debug)]
pub struct PathsArgs {
    /// Scene: `default` (built in) or a .gltf/.glb/.obj/.toml file.
    #[arg(long, default_value = crate::scene_source::BUILTIN_SCENE)]
    pub scene: String,
    /// Paths per seed.
    #[arg(long, default_value_t = 1)]
    pub count: usize,
    /// Seeds, comma separated: each gives its own paths.
    #[arg(long, default_value = "1", value_delimiter = ',')]
    pub seeds: Vec<u64>,
    /// Length of each path in seconds.
    #[arg(long, default_value_t = PathGenConfig::default().duration_s)]
    pub duration: f32,
    /// Folder to write the path files into (created if missing).
    #[arg(long)]
    pub out: PathBuf,
    /// Ray-tracing backend, `obvhs` or `embree` (default: the fastest compiled in).
    #[arg(long)]
    pub backend: Option<Backend>,
}

/// Runs `psao paths`: prints each file written.
pub fn run(args: &PathsArgs) -> Result<()> {
    if args.count == 0 || args.seeds.is_empty() {
        bail!("--count must be at least 1 and --seeds name at least one seed");
    }
    let input = SceneInput::load(&args.scene)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    for &seed in &args.seeds {
        let paths = generated_paths(&input, args.backend, args.count, seed, args.duration)?;
        for path in paths {
            let file = args.out.join(format!("{}.toml", path.name));
            std::fs::write(&file, path.to_toml())
                .with_context(|| format!("cannot write {}", file.display()))?;
            println!("{}", file.display());
        }
    }
    Ok(())
}

/// `count` paths of `duration_s` seconds through `input`'s scene for `seed`, named
/// `seed<seed>_<index>`.
pub fn generated_paths(
    input: &SceneInput,
    backend: Option<Backend>,
    count: usize,
    seed: u64,
    duration_s: f32,
) -> Result<Vec<CameraPath>> {
    let config = PathGenConfig {
        duration_s,
        ..PathGenConfig::default()
    };
    let paths = generate_traced_paths(
        &input.scene,
        backend.unwrap_or_default(),
        &config,
        count,
        seed,
    )
    .with_context(|| format!("cannot generate camera paths through {}", input.name))?;
    Ok(paths
        .into_iter()
        .enumerate()
        .map(|(i, p)| CameraPath {
            name: format!("seed{seed}_{i}"),
            ..p
        })
        .collect())
}
