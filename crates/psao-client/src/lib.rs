//! The PSAO client's algorithms (DESIGN §1–§3, paper §3.5): mirror the server's point grids
//! from applied updates ([`ClientState`]), reconstruct AO per pixel of a rasterized G-buffer
//! ([`reconstruct`]) and composite it over a simple base shading ([`composite`],
//! [`composite_srgb8`]). Pure computation: no file or network I/O.
//!
//! A frame: `state.apply(&update)?` for every update received since the last frame, rasterize
//! the scene (`psao_raster`), then `reconstruct(&state, &gbuffer, &settings)` and
//! `composite(&scene, &gbuffer, &ao, &shading)`.
//!
//! With lighting (DESIGN §12; the state then holds irradiance records,
//! [`ClientState::has_lights`]): `reconstruct_lit_into` gives the AO and the points'
//! irradiance per pixel (filling pixels without a compatible point from their neighbours),
//! [`direct_light`] the shadow-mapped light of suns and point lights
//! (`psao_raster::ShadowMaps`), and [`composite_lit`] the radiance
//! `base colour / π × (direct + irradiance)`.

#![warn(missing_docs)]

#[cfg(feature = "render")]
mod composite;
#[cfg(feature = "render")]
mod detail;
mod error;
#[cfg(feature = "render")]
mod fill;
#[cfg(feature = "render")]
mod gather;
mod hash;
#[cfg(feature = "render")]
mod reconstruct;
mod state;

#[cfg(feature = "render")]
pub use composite::{
    composite, composite_lit, composite_srgb8, composite_tinted, direct_light, encode_srgb,
    Shading, SKY_GREY,
};
#[cfg(feature = "render")]
pub use detail::{apply_detail, DetailSettings};
pub use error::ClientError;
pub use hash::{lit_state_hash_of, state_hash_of, HashedGrid};
#[cfg(feature = "render")]
pub use reconstruct::{reconstruct, reconstruct_into, reconstruct_lit_into, ReconstructSettings};
pub use state::{layout_is_usable, CellLights, ClientState};
