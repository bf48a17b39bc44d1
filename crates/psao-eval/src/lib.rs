//! Evaluation: the per-pixel reference AO (DESIGN §2), the per-pixel reference of the diffuse
//! lighting (DESIGN §12), image quality metrics (LPIPS, PSNR, SSIM, FLIP) and the evaluation
//! of corrective splatting on committed or generated camera paths (DESIGN §8).
//!
//! Pure code: images come in and numbers go out; reading and writing files is the CLI's job.

pub mod ao_image;
pub mod corrective;
pub mod lpips;
pub mod metrics;
pub mod path_caster;
pub mod reference;
pub mod reference_gi;
pub mod spread;
pub mod ssao;

pub use ao_image::AoImage;
pub use lpips::{Lpips, LpipsError};
pub use metrics::{compare, Metrics, MetricsError};
pub use reference::{reference_ao_in, ReferenceSettings};
pub use reference_gi::{reference_gi, GiSettings, RgbImage};
pub use spread::{spread, Spread};
pub use ssao::{ssao, SsaoSettings};
