//! zstd framing shared by the codecs (and by psao-net's scale-out record batches): content
//! size and checksum always recorded, bounded decompression.
//!
//! Native builds use the C zstd both ways ([`native`]). wasm32 builds (the browser viewer's
//! decoder, crates/psao-wasm) decompress with the pure-Rust ruzstd ([`pure`]: the same checks
//! and error variants) and compress into stored frames ([`stored`]: raw blocks, which any zstd
//! decoder reads); the browser never encodes an update, but the codecs stay whole there.

#[cfg(not(target_arch = "wasm32"))]
mod native;
#[cfg(any(target_arch = "wasm32", test))]
mod pure;
#[cfg(any(target_arch = "wasm32", test))]
mod stored;

use crate::DeltaError;

/// The match search a codec asks zstd for (stored frames have none).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Search {
    /// The level's own strategy.
    Default,
    /// zstd's "lazy" strategy (the paper codec).
    Lazy,
}

/// Compress `payload` at `level` with `search`, recording the content size and a checksum.
pub(crate) fn compress_with(payload: &[u8], level: i32, search: Search) -> Vec<u8> {
    #[cfg(not(target_arch = "wasm32"))]
    return native::compress_with(payload, level, search);
    #[cfg(target_arch = "wasm32")]
    {
        let _ = (level, search);
        stored::compress(payload)
    }
}

/// Compress `payload` at `level` (content size and checksum recorded).
pub fn compress(payload: &[u8], level: i32) -> Vec<u8> {
    compress_with(payload, level, Search::Default)
}

/// Decompress at most `limit` bytes, allocating exactly the recorded size.
pub fn decompress(bytes: &[u8], limit: u64) -> Result<Vec<u8>, DeltaError> {
    #[cfg(not(target_arch = "wasm32"))]
    return native::decompress(bytes, limit);
    #[cfg(target_arch = "wasm32")]
    pure::decompress(bytes, limit)
}
