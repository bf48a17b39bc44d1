//! psao-prt: shadowed relighting of skinned characters (DESIGN §7; paper
//! `shadowed-relighting-1d-brdfs`).
//!
//! Order-4 real SH ([`sh`]), projection by quadrature ([`quadrature`]), rotation
//! ([`rotation`]), zonal lobes ([`zonal`]) and the analytic normalised-Phong convolution
//! operator ([`phong`]) form the toolkit. On top: per-vertex visibility of a posed character
//! ([`visibility`]), multi-lobe zonal fits kept in correspondence over frames ([`fit`]), the
//! linear pose model ([`model`]) with its pose limits ([`limits`]), per-vertex shrink ([`shrink`]) and glossy fade
//! ([`fade`]), environment lighting ([`lighting`]) and run-time shading
//! ([`shade`]) with its Monte Carlo reference ([`reference`]); [`runtime`] relights a
//! character frame by frame from its joint transforms, as a client does, with the model
//! compacted ([`compact`]) and the lighting tabulated over the sphere ([`transfer_table`]). Pure code: no
//! file I/O.

pub mod character;
pub mod compact;
mod error;
pub mod fade;
pub mod filter;
pub mod fit;
pub mod groups;
pub mod lighting;
pub mod limits;
pub mod model;
pub mod model_file;
pub mod phong;
pub mod quadrature;
pub mod reference;
pub mod rotation;
pub mod runtime;
pub mod served;
pub mod served_character;
pub mod sh;
pub mod shade;
pub mod shrink;
mod small;
pub mod transfer_table;
pub mod visibility;
pub mod zonal;

pub use error::PrtError;
