//! The `--corrective` options of `psao run`, `psao serve` and `psao view` (corrective
//! splatting over the split, `crates/psao-net/src/corrective.rs`).

use anyhow::{bail, Result};
use psao_net::corrective::{
    CorrectiveClientConfig, CorrectiveConfig, DEFAULT_ANALYZE_EVERY, DEFAULT_LIGHT_PATHS,
    DEFAULT_SAMPLES_PER_SECOND,
};

/// Corrective-splatting options.
#[derive(clap::Args, Debug, Clone)]
pub struct CorrectiveArgs {
    /// Corrective splatting: the client sends the regions and priorities of its frames, the
    /// server traces correction samples and streams them with the AO updates.
    #[arg(long)]
    pub corrective: bool,
    /// Server: correction samples per second per client.
    #[arg(long, default_value_t = DEFAULT_SAMPLES_PER_SECOND)]
    pub samples_per_second: u32,
    /// Server: milliseconds of worker tracing per server frame per client (the paper's
    /// per-frame time budget), on top of `--samples-per-second`; not in lockstep.
    #[arg(long)]
    pub correction_ms: Option<f32>,
    /// Client: frames between analyses of its frame (18 = 0.3 s at 60 Hz); a view not in
    /// lockstep analyses on its own thread every that many 60ths of a second of wall clock.
    #[arg(long, default_value_t = DEFAULT_ANALYZE_EVERY)]
    pub analyze_every: u32,
    /// Server: AO rays per diffuse point the correction rays reach.
    #[arg(long, default_value_t = 8)]
    pub corrective_ao_spp: u32,
    /// Server, when lit (`--lighting gi`): light paths per diffuse point the correction rays
    /// reach (the diffuse light of what reflections and refractions show).
    #[arg(long, default_value_t = DEFAULT_LIGHT_PATHS)]
    pub corrective_paths: u32,
}

impl CorrectiveArgs {
    /// The settings, when `--corrective` is given.
    pub fn config(&self) -> Result<Option<CorrectiveConfig>> {
        if !self.corrective {
            return Ok(None);
        }
        if self.analyze_every == 0 {
            bail!("--analyze-every must be at least 1");
        }
        if self.samples_per_second > 10_000_000 {
            bail!(
                "--samples-per-second {} is absurd (at most 10 000 000)",
                self.samples_per_second
            );
        }
        if let Some(ms) = self.correction_ms {
            if !(ms > 0.0 && ms <= 1000.0) {
                bail!("--correction-ms must be in (0, 1000], got {ms}");
            }
        }
        Ok(Some(CorrectiveConfig {
            samples_per_second: self.samples_per_second,
            frame_ms: self.correction_ms,
            ao_spp: self.corrective_ao_spp.clamp(1, 1024),
            light_paths: self.corrective_paths.clamp(1, 1024),
            client: CorrectiveClientConfig {
                analyze_every: self.analyze_every,
                ..CorrectiveClientConfig::default()
            },
        }))
    }
}
