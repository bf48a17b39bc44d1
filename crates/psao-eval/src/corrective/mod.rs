//! The evaluation of corrective splatting (DESIGN §8, `docs/CORRECTIVE.md`): corrected frames
//! along camera paths against the reference ([`run`]), on committed or generated paths, and
//! the mean and spread of the results over seeds ([`seeds`]).

pub mod dump;
pub mod frame;
pub mod metrics;
pub mod report;
pub mod run;
pub mod seeds;
pub mod worse;

pub use run::{evaluate_path, Budget, EvalConfig, GiEval, Order, PathEval, Tracers};

/// Why an evaluation could not run.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// A setting is out of range.
    #[error("corrective eval: {0}")]
    Config(String),
    /// A tracer could not be built.
    #[error(transparent)]
    Trace(#[from] psao_trace::TraceError),
    /// The sample cache refused its settings or samples.
    #[error(transparent)]
    Cache(#[from] psao_corrective::cache::CacheError),
    /// No camera paths could be generated.
    #[error(transparent)]
    Paths(#[from] psao_scene::PathGenError),
}
