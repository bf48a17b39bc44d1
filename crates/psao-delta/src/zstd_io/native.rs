//! The C zstd (native builds).

use zstd::zstd_safe::{CParameter, Strategy};

use super::Search;
use crate::DeltaError;

/// Compress `payload` at `level` with `search`, recording the content size and a checksum.
pub(super) fn compress_with(payload: &[u8], level: i32, search: Search) -> Vec<u8> {
    let strategy = match search {
        Search::Default => None,
        Search::Lazy => Some(CParameter::Strategy(Strategy::ZSTD_lazy)),
    };
    let params = [
        CParameter::CompressionLevel(level),
        CParameter::ContentSizeFlag(true),
        CParameter::ChecksumFlag(true),
    ];
    let result = zstd::bulk::Compressor::new(level).and_then(|mut c| {
        params
            .into_iter()
            .chain(strategy)
            .try_for_each(|p| c.set_parameter(p))?;
        c.compress(payload)
    });
    // Constant, valid parameters into a buffer of `compress_bound` bytes: zstd cannot fail
    // here short of running out of memory, which aborts anyway.
    result.expect("zstd compression with fixed valid parameters")
}

/// Decompress at most `limit` bytes, allocating exactly the recorded size.
pub(super) fn decompress(bytes: &[u8], limit: u64) -> Result<Vec<u8>, DeltaError> {
    let size = zstd::bulk::Decompressor::upper_bound(bytes).ok_or(DeltaError::UnknownSize)?;
    if size as u64 > limit {
        return Err(DeltaError::TooLarge {
            size: size as u64,
            limit,
        });
    }
    let out = zstd::bulk::Decompressor::new()
        .and_then(|mut d| d.decompress(bytes, size))
        .map_err(|e| DeltaError::Decompress(e.to_string()))?;
    if out.len() != size {
        return Err(DeltaError::Decompress(format!(
            "expanded to {} bytes, {size} recorded",
            out.len()
        )));
    }
    Ok(out)
}
