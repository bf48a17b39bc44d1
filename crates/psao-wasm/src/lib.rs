//! The browser viewer's decoder (web/, docs/PROTOCOL.md): psao-delta's `compact` decoder and
//! psao-client's [`ClientState`](psao_client::ClientState) with its state hash, compiled to
//! WebAssembly (`wasm32-unknown-unknown`, web/build-wasm.sh → web/dist/psao.wasm) so that
//! the browser decodes with the same code as `psao view`. The TypeScript keeps networking,
//! input and rendering; it calls the plain C ABI of [`abi`] and reads what the textures need
//! (the [`changes`] of each update, the transforms) straight from wasm memory. Served relit
//! characters ([`relit`], C ABI [`relit_abi`]) are relit with psao-prt's served relighter on
//! the scene posed by psao-scene's animator, as in `psao view`.
//!
//! Everything but [`abi`]'s and [`relit_abi`]'s pointer handling is safe Rust, built and unit-tested natively too.

pub mod abi;
pub mod changes;
pub mod relit;
pub mod relit_abi;
pub mod table;
pub mod viewer;

pub use viewer::{Viewer, ViewerError};
