//! Perceptually guided corrective splatting (DESIGN §8): √5 hierarchical image-space sampling,
//! an Itti-style saliency model with top-down task importance, an aged and reprojected sample
//! cache, and the scheduling of correction jobs. Pure code: no file or network I/O.

pub mod attention;
pub mod base;
pub mod cache;
pub mod saliency;
pub mod schedule;
pub mod screen;
pub mod session;
pub mod splat;
pub mod sqrt5;
pub mod trace;
pub mod workers;
