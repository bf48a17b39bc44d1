//! Participating media that occlude AO rays (DESIGN §6 "volumes occlude AO").
//!
//! A medium with extinction σ(x) attenuates light along a segment by the transmittance
//! T(s) = exp(−∫₀ˢ σ(x + u·d) du). An AO ray sees the medium as a *soft occluder*: the
//! sample's occlusion distance is no longer the surface distance L = min(t, R) but the
//! transmittance-weighted distance D = ∫₀ᴸ T(s) ds, i.e. the expected distance to the first
//! collision when collisions with the medium count as hits (E[min(S, L)] = ∫₀ᴸ P(S > s) ds for
//! a free-flight distance S with P(S > s) = T(s)). Without a medium D = L; an opaque medium
//! starting at distance a gives D = min(a, L), exactly like a surface there. The AO sample
//! value is D / R (see [`super::sample_value`]).

use glam::Vec3;

/// A participating medium AO rays pass through. Implementations live with the volume data
/// (e.g. `psao-volume`), so the tracer, server and evaluation need not know the format.
pub trait Medium: Send + Sync + std::fmt::Debug {
    /// Per-worker sampling state (decoded-data caches); make one per parallel work item and
    /// reuse it for all of that item's rays.
    fn sampler(&self) -> Box<dyn MediumSampler + '_>;
}

/// Per-worker sampling of a [`Medium`].
pub trait MediumSampler {
    /// An estimate of the transmittance-weighted length ∫₀ˡᵉⁿᵍᵗʰ T(origin, origin + s·dir) ds
    /// (unit `dir`), unbiased or deterministic, with all random choices derived from
    /// `stream`. Must return exactly `length` when the segment does not touch the medium, and
    /// a value in `0..=length` otherwise.
    fn transmitted_length(&mut self, origin: Vec3, dir: Vec3, length: f32, stream: u64) -> f32;
}
