//! Finding and reading the LPIPS weights (`--lpips-weights`, else the default location).

use anyhow::{Context, Result};
use clap::Args;
use psao_eval::lpips::WEIGHTS_FILE_NAME;
use psao_eval::Lpips;
use std::path::{Path, PathBuf};

/// The `--lpips-weights` argument.
#[derive(Args, Debug, Clone)]
pub struct LpipsArgs {
    /// AlexNet LPIPS weights (safetensors, made by scripts/lpips_weights.py); default:
    /// $XDG_CACHE_HOME/psao/lpips_alex_v0.1.safetensors (~/.cache/psao/ without
    /// XDG_CACHE_HOME). Without weights, LPIPS is left out with a note.
    #[arg(long, value_name = "FILE")]
    pub lpips_weights: Option<PathBuf>,
}

/// The default location of the weights, if a cache folder is known.
pub fn default_weights_path() -> Option<PathBuf> {
    let cache = std::env::var_os("XDG_CACHE_HOME")
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| Path::new(&h).join(".cache")))?;
    Some(cache.join("psao").join(WEIGHTS_FILE_NAME))
}

/// LPIPS, or why it is left out.
pub enum LpipsChoice {
    /// The network, ready.
    Ready(Box<Lpips>),
    /// No weights were found: the note says where they were looked for.
    Missing(String),
}

impl LpipsArgs {
    /// Loads the network from `--lpips-weights` (an error if that file is missing or bad),
    /// else from the default location (an error if that file is bad, a note if it is absent).
    pub fn load(&self) -> Result<LpipsChoice> {
        let file = match (&self.lpips_weights, default_weights_path()) {
            (Some(f), _) => f.clone(),
            (None, Some(f)) if f.exists() => f,
            (None, default) => {
                let place = default.map_or("no cache folder ($HOME unset)".into(), |f| {
                    f.display().to_string()
                });
                let note = format!(
                    "LPIPS left out: no weights at {place} (make them with \
                     scripts/lpips_weights.py or give --lpips-weights FILE)"
                );
                tracing::warn!("{note}");
                return Ok(LpipsChoice::Missing(note));
            }
        };
        let bytes = std::fs::read(&file)
            .with_context(|| format!("cannot read LPIPS weights {}", file.display()))?;
        let net = Lpips::from_safetensors(&bytes)
            .with_context(|| format!("LPIPS weights {} are unusable", file.display()))?;
        tracing::info!("LPIPS weights from {}", file.display());
        Ok(LpipsChoice::Ready(Box::new(net)))
    }
}
