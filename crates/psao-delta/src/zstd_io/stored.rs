//! Stored zstd frames: the payload in raw (uncompressed) blocks after a header recording its
//! size, then the checksum; any zstd decoder reads them. The compressor of wasm32 builds,
//! which have no C zstd.

/// zstd's frame magic number.
pub(super) const MAGIC: u32 = 0xFD2F_B528;
/// Frame header descriptor: an 8-byte content size (flag 3), single segment (no window
/// descriptor: the window is the content), a content checksum, no dictionary.
const DESCRIPTOR: u8 = 0b1110_0100;
/// zstd's largest block.
const MAX_BLOCK: usize = 128 << 10;

/// `payload` as one stored frame.
pub(super) fn compress(payload: &[u8]) -> Vec<u8> {
    let blocks = payload.len().div_ceil(MAX_BLOCK).max(1);
    let mut out = Vec::with_capacity(13 + 3 * blocks + payload.len() + 4);
    out.extend_from_slice(&MAGIC.to_le_bytes());
    out.push(DESCRIPTOR);
    out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    if payload.is_empty() {
        out.extend_from_slice(&raw_block_header(0, true));
    }
    let mut chunks = payload.chunks(MAX_BLOCK).peekable();
    while let Some(chunk) = chunks.next() {
        out.extend_from_slice(&raw_block_header(chunk.len(), chunks.peek().is_none()));
        out.extend_from_slice(chunk);
    }
    // The low 32 bits of the content's XXH64 (seed 0), as zstd's checksum.
    let checksum = twox_hash::XxHash64::oneshot(0, payload) as u32;
    out.extend_from_slice(&checksum.to_le_bytes());
    out
}

/// A raw block's 3-byte header: last-block bit, block type 0 (raw), size in bytes.
fn raw_block_header(size: usize, last: bool) -> [u8; 3] {
    let [a, b, c, _] = ((size as u32) << 3 | u32::from(last)).to_le_bytes();
    [a, b, c]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stored_frames_read_back_with_the_c_zstd_and_ruzstd() {
        let sizes = [0, 1, 1000, MAX_BLOCK, MAX_BLOCK + 1, 3 * MAX_BLOCK + 17];
        for size in sizes {
            let payload: Vec<u8> = (0..size).map(|i| (i * 7 + i / 300) as u8).collect();
            let frame = compress(&payload);
            assert_eq!(
                frame.len(),
                payload.len() + 17 + 3 * size.div_ceil(MAX_BLOCK).max(1)
            );
            let limit = size as u64;
            assert_eq!(
                super::super::native::decompress(&frame, limit).unwrap(),
                payload
            );
            assert_eq!(
                super::super::pure::decompress(&frame, limit).unwrap(),
                payload
            );
        }
    }
}
