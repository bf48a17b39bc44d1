//! Networking of `psao serve` / `psao view`: transports (TCP and WebSocket carrying the same
//! `psao-wire` frames) and conversions between wire messages and the algorithm types.

pub mod convert;
pub mod transport;
