//! Fuzzes the update decoders. The first input byte picks the mode: even = the rest is
//! decoded as is (zstd framing, checksums, limits); odd = the rest is first compressed, so the
//! mutations reach the payload parsers behind zstd's checksum. The paper codec decodes the
//! whole; the compact codec a short session of updates split at `|` separators (exercising its
//! XOR reference state). Malformed input must give a typed error, never a panic or an
//! allocation past the limit.
#![no_main]

use libfuzzer_sys::fuzz_target;
use psao_delta::{Codec, CompactCodec, PaperCodec};

fn frame(raw: &[u8], compress: bool) -> Vec<u8> {
    if compress {
        zstd::bulk::compress(raw, 1).expect("zstd compresses")
    } else {
        raw.to_vec()
    }
}

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else {
        return;
    };
    let compress = mode & 1 == 1;
    let mut paper = PaperCodec::new();
    if let Ok(update) = paper.decode(&frame(rest, compress)) {
        // One re-encode normalises (compaction); after that encoding is a fixed point.
        let first = paper.encode(&update);
        let normal = paper.decode(&first).expect("re-decodes");
        let bytes = paper.encode(&normal);
        let again = paper.decode(&bytes).expect("re-decodes");
        assert_eq!(paper.encode(&again), bytes);
    }
    let mut compact = CompactCodec::new();
    compact.set_decode_limit(16 << 20);
    for part in rest.split(|&b| b == b'|').take(8) {
        let _ = compact.decode(&frame(part, compress));
    }
});
