//! Evaluation: the per-pixel reference AO (DESIGN §2) and image quality metrics (LPIPS, PSNR,
//! SSIM, FLIP).
//!
//! Pure code: images come in and numbers go out; reading and writing files is the CLI's job.

pub mod ao_image;
pub mod lpips;
pub mod metrics;
pub mod reference;
pub mod ssao;

pub use ao_image::AoImage;
pub use lpips::{Lpips, LpipsError};
pub use metrics::{compare, Metrics, MetricsError};
pub use reference::{reference_ao_in, ReferenceSettings};
pub use ssao::{ssao, SsaoSettings};
