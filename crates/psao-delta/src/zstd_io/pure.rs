//! Decompression with ruzstd, pure Rust (wasm32 builds), with the checks of the C zstd path:
//! one frame that records its size, at most `limit` bytes, the checksum when present, and the
//! same error variants (a stream whose header gives no size is [`DeltaError::UnknownSize`]).
//! The decoder's buffer stays within the limit: the window of a frame that is not a single
//! segment must fit it, and the output is checked against the recorded size step by step.

use std::io::Read;

use ruzstd::decoding::{BlockDecodingStrategy, FrameDecoder};

use crate::DeltaError;

/// Decoded bytes between checks of the output against the recorded size.
const STEP: usize = 128 << 10;

/// What a frame header says about memory: the content size and the window.
struct Header {
    size: u64,
    /// The window of a multi-segment frame (a single segment's is its size).
    window: Option<u64>,
}

/// Decompress at most `limit` bytes, allocating exactly the recorded size.
pub(super) fn decompress(bytes: &[u8], limit: u64) -> Result<Vec<u8>, DeltaError> {
    let header = read_header(bytes).ok_or(DeltaError::UnknownSize)?;
    let size = header.size;
    for claimed in [Some(size), header.window].into_iter().flatten() {
        if claimed > limit {
            return Err(DeltaError::TooLarge {
                size: claimed,
                limit,
            });
        }
    }
    let size = size as usize; // At most `limit`, which the caller could allocate.
    let corrupt = |e: &dyn std::fmt::Display| DeltaError::Decompress(e.to_string());
    let mut input = bytes;
    let mut decoder = FrameDecoder::new();
    decoder.init(&mut input).map_err(|e| corrupt(&e))?;
    let mut out = Vec::with_capacity(size);
    loop {
        let finished = decoder.is_finished()
            || decoder
                .decode_blocks(&mut input, BlockDecodingStrategy::UptoBytes(STEP))
                .map_err(|e| corrupt(&e))?;
        let ready = decoder.can_collect();
        if out.len() + ready > size {
            return Err(expanded(out.len() + ready, size));
        }
        let start = out.len();
        out.resize(start + ready, 0);
        let read = decoder.read(&mut out[start..]).map_err(|e| corrupt(&e))?;
        out.truncate(start + read);
        if finished && (read == 0 || decoder.can_collect() == 0) {
            break;
        }
    }
    if out.len() != size {
        return Err(expanded(out.len(), size));
    }
    let stored = decoder.get_checksum_from_data();
    if stored.is_some() && stored != decoder.get_calculated_checksum() {
        return Err(DeltaError::Decompress("checksum mismatch".into()));
    }
    Ok(out)
}

fn expanded(got: usize, size: usize) -> DeltaError {
    DeltaError::Decompress(format!("expanded to {got} bytes, {size} recorded"))
}

/// The frame header's content size and window (RFC 8878 §3.1.1); `None` unless `bytes` are
/// exactly one frame whose header records the content size (what the C zstd path's size
/// lookup accepts, short of several frames, which no encoder here writes).
fn read_header(bytes: &[u8]) -> Option<Header> {
    let (magic, rest) = bytes.split_first_chunk::<4>()?;
    if u32::from_le_bytes(*magic) != super::stored::MAGIC {
        return None;
    }
    let (&descriptor, mut rest) = rest.split_first()?;
    let single_segment = descriptor & 0x20 != 0;
    let window = if single_segment {
        None
    } else {
        let (&w, tail) = rest.split_first()?;
        rest = tail;
        let base = 1u64 << (10 + (w >> 3));
        Some(base + base / 8 * u64::from(w & 7))
    };
    let dictionary_bytes = [0, 1, 2, 4][usize::from(descriptor & 3)];
    rest = rest.get(dictionary_bytes..)?;
    let (size, size_bytes) = match (descriptor >> 6, single_segment) {
        (0, false) => return None,
        (0, true) => (u64::from(*rest.first()?), 1),
        (1, _) => (u64::from(u16::from_le_bytes(*rest.first_chunk()?)) + 256, 2),
        (2, _) => (u64::from(u32::from_le_bytes(*rest.first_chunk()?)), 4),
        _ => (u64::from_le_bytes(*rest.first_chunk()?), 8),
    };
    let checksum_bytes = if descriptor & 4 != 0 { 4 } else { 0 };
    let after_blocks = skip_blocks(&rest[size_bytes..])?;
    (after_blocks.len() == checksum_bytes).then_some(Header { size, window })
}

/// What follows a frame's blocks (RFC 8878 §3.1.1.2); `None` when a block runs past the end
/// or has the reserved type.
fn skip_blocks(mut bytes: &[u8]) -> Option<&[u8]> {
    loop {
        let (&[a, b, c], rest) = bytes.split_first_chunk::<3>()?;
        let header = u32::from_le_bytes([a, b, c, 0]);
        let body = match (header >> 1) & 3 {
            0 | 2 => (header >> 3) as usize,
            1 => 1,
            _ => return None,
        };
        bytes = rest.get(body..)?;
        if header & 1 != 0 {
            return Some(bytes);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::native;
    use super::*;

    fn payload(len: usize) -> Vec<u8> {
        (0..len)
            .map(|i| ((i * i) >> 7) as u8 ^ (i / 5000) as u8)
            .collect()
    }

    #[test]
    fn reads_what_the_c_zstd_writes() {
        for (len, level) in [(0, 1), (5, 1), (300, 3), (70_000, 1), (1 << 20, 15)] {
            let data = payload(len);
            for search in [super::super::Search::Default, super::super::Search::Lazy] {
                let frame = native::compress_with(&data, level, search);
                assert_eq!(decompress(&frame, len as u64).unwrap(), data, "{len} bytes");
            }
        }
    }

    #[test]
    fn errors_like_the_c_zstd() {
        let data = payload(200_000);
        let frame = native::compress_with(&data, 3, super::super::Search::Default);
        let both = |bytes: &[u8], limit: u64| {
            let (p, n) = (decompress(bytes, limit), native::decompress(bytes, limit));
            assert_eq!(
                std::mem::discriminant(&p.clone().unwrap_err()),
                std::mem::discriminant(&n.unwrap_err()),
                "{p:?}"
            );
            p.unwrap_err()
        };
        assert!(matches!(
            both(&frame, 1000),
            DeltaError::TooLarge {
                size: 200_000,
                limit: 1000
            }
        ));
        assert_eq!(both(&frame[..3], 1 << 20), DeltaError::UnknownSize);
        assert_eq!(both(b"not zstd at all", 1 << 20), DeltaError::UnknownSize);
        for cut in [20, frame.len() / 2, frame.len() - 1] {
            assert_eq!(both(&frame[..cut], 1 << 20), DeltaError::UnknownSize);
        }
        let mut longer = frame.clone();
        longer.push(0);
        assert_eq!(both(&longer, 1 << 20), DeltaError::UnknownSize);
        // Flipped bits anywhere past the header: corrupt data or a wrong checksum.
        for at in (20..frame.len()).step_by(997) {
            let mut bad = frame.clone();
            bad[at] ^= 0x10;
            if let Err(e) = decompress(&bad, 1 << 20) {
                assert!(matches!(e, DeltaError::Decompress(_)), "{e:?}");
            } else {
                panic!("a flipped bit at {at} went unnoticed");
            }
        }
    }

    #[test]
    fn a_window_past_the_limit_is_refused_before_decoding() {
        // A multi-segment header (window byte 0x88: 2^27 bytes) recording 1000 bytes.
        let mut frame = header_with(0b1000_0000);
        frame.push(0x88);
        frame.extend_from_slice(&1000u32.to_le_bytes());
        frame.extend_from_slice(&[1, 0, 0]); // An empty last raw block, no checksum.
        let err = decompress(&frame, 1 << 20).unwrap_err();
        assert_eq!(
            err,
            DeltaError::TooLarge {
                size: 1 << 27,
                limit: 1 << 20
            }
        );
    }

    /// The frame magic and a header descriptor.
    fn header_with(descriptor: u8) -> Vec<u8> {
        let mut v = super::super::stored::MAGIC.to_le_bytes().to_vec();
        v.push(descriptor);
        v
    }
}
