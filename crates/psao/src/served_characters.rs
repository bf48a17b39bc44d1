//! `--relight` of `psao serve` and `psao run`: at start, a relighting model for every skinned
//! character of the scene, trained with few rays and poses or read back from the on-disk
//! cache, and the scene's environment lighting as SH (docs/RELIGHTING.md, "Served
//! characters").
//!
//! A character is one skinned node group: the skinned instances under one root node (in a
//! scene file, one asset) with the rigid instances of that group as occluders, relit as
//! `psao relight train` relights a file, and posed by the first playing clip that moves the
//! group.

use std::hash::Hasher;
use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use psao_net::characters::{model_size_ok, ServedCharacters};
use psao_net::start_cache::{keep_stored, read_stored};
use psao_prt::character::Character;
use psao_prt::groups::skinned_groups;
use psao_prt::lighting::{EnvMap, ShLighting};
use psao_prt::model_file;
use psao_scene::{Environment, Scene};

use crate::relight_cmd::{frame_range, gather_split, split, train_model};

/// Extension of the cached model files.
const MODEL_EXT: &str = "prt";
/// Version of the cache key (bump when training changes what it makes).
const KEY_VERSION: u32 = 1;

/// The relighting options of a serving command.
#[derive(clap::Args, Debug, Clone)]
pub struct RelightArgs {
    /// Relight the scene's skinned characters: at start, train a model per character (or read
    /// it from the cache folder of the start points) and serve it (docs/RELIGHTING.md).
    #[arg(long)]
    pub relight: bool,
    /// Visibility rays per vertex and training pose of `--relight`.
    #[arg(long, default_value_t = 64)]
    pub relight_rays: u32,
    /// Train `--relight` models on every K-th frame of the character's clip (30 fps).
    #[arg(long, default_value_t = 6)]
    pub relight_every: u32,
    /// Zonal lobes per vertex of `--relight` models (1, 2 or 3).
    #[arg(long, default_value_t = 1)]
    pub relight_lobes: usize,
}

/// The characters served for `scene` (none without `--relight`); models are trained with
/// `seed` and kept in `cache` when given.
pub fn served_characters(
    scene: &Scene,
    args: &RelightArgs,
    seed: u64,
    cache: Option<&Path>,
) -> Result<ServedCharacters> {
    if !args.relight {
        return Ok(ServedCharacters::default());
    }
    let mut models = Vec::new();
    for group in skinned_groups(scene) {
        let n = models.len();
        let character = Character::new(group.scene, None).with_context(|| {
            format!(
                "cannot relight the skinned character under node {}",
                group.root
            )
        })?;
        models.push(model(n, &character, args, seed, cache)?);
    }
    Ok(ServedCharacters::new(
        models,
        sh_lighting(&scene.environment)?,
    )?)
}

/// Character `n`'s model file: read from `cache` when stored there for these settings and
/// sound, else trained now (and stored).
fn model(
    n: usize,
    character: &Character,
    args: &RelightArgs,
    seed: u64,
    cache: Option<&Path>,
) -> Result<Vec<u8>> {
    let key = key(character, args, seed);
    if let Some((file, bytes)) = cache.and_then(|d| read_stored(d, key, MODEL_EXT, model_size_ok)) {
        match model_file::from_bytes(&bytes) {
            Ok(m)
                if m.vertices == character.vertex_count()
                    && m.joints == character.joint_count()
                    && m.lobes == args.relight_lobes =>
            {
                tracing::info!("character {n}: model read from {}", file.display());
                return Ok(bytes);
            }
            Ok(_) => tracing::warn!("{}: another character's model; training", file.display()),
            Err(e) => tracing::warn!("{}: {e}; training", file.display()),
        }
    }
    let start = Instant::now();
    let range = frame_range(character, None)?;
    let split = split(range, args.relight_every, None)
        .with_context(|| format!("character {n}'s clip `{}`", character.clip_name()))?;
    let (train_set, validate) = gather_split(character, &split, args.relight_rays, seed)?;
    let (model, _) = train_model(
        &format!("character{n}"),
        &train_set,
        &validate,
        args.relight_lobes,
    )?;
    let bytes = model_file::to_bytes(&model);
    tracing::info!(
        "character {n}: {} vertices, {} training poses, model of {} bytes trained in {:.1} s",
        model.vertices,
        train_set.len(),
        bytes.len(),
        start.elapsed().as_secs_f64()
    );
    if let Some(dir) = cache {
        keep_stored(dir, key, MODEL_EXT, &bytes);
    }
    Ok(bytes)
}

/// The cache key of a character's model: its relit mesh at rest, rig and clip, and the
/// training settings.
fn key(character: &Character, args: &RelightArgs, seed: u64) -> u64 {
    // std's SipHash with fixed keys, as the start points' key.
    let mut h = std::hash::DefaultHasher::new();
    h.write_u32(KEY_VERSION);
    let mesh = character.mesh();
    h.write_usize(mesh.positions.len());
    for p in &mesh.positions {
        p.to_array().iter().for_each(|x| h.write_u32(x.to_bits()));
    }
    h.write_usize(mesh.indices.len());
    mesh.indices.iter().flatten().for_each(|&i| h.write_u32(i));
    let occluders = character.occluder_mesh();
    h.write_usize(occluders.positions.len());
    for p in &occluders.positions {
        p.to_array().iter().for_each(|x| h.write_u32(x.to_bits()));
    }
    h.write_usize(character.joint_count());
    h.write(character.clip_name().as_bytes());
    h.write_u32(character.duration().to_bits());
    h.write_u32(args.relight_rays);
    h.write_u32(args.relight_every);
    h.write_usize(args.relight_lobes);
    h.write_u64(seed);
    h.finish()
}

/// The environment as order-4 SH radiance, red then green then blue (16 numbers each).
fn sh_lighting(environment: &Environment) -> Result<Vec<f32>> {
    let sh: ShLighting = match environment {
        Environment::Constant(c) => EnvMap::new(32, 16, vec![c.to_array(); 32 * 16])?.project(),
        Environment::Map {
            map,
            intensity,
            rotation,
        } => {
            let mut sh = EnvMap::from((**map).clone())
                .project()
                .rotated_about_up(*rotation);
            sh.rgb.iter_mut().flatten().for_each(|x| *x *= *intensity);
            sh
        }
    };
    Ok(sh.rgb.iter().flatten().copied().collect())
}
