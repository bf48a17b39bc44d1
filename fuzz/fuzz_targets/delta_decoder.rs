//! Fuzzes the update decoders: the paper codec on the whole input, and the compact codec on
//! the input split into a short session of updates (to exercise its XOR reference state).
//! Malformed input must give a typed error, never a panic or an allocation past the limit.
#![no_main]

use libfuzzer_sys::fuzz_target;
use psao_delta::{Codec, CompactCodec, PaperCodec};

fuzz_target!(|data: &[u8]| {
    let mut paper = PaperCodec;
    if let Ok(update) = paper.decode(data) {
        // One re-encode normalises (compaction); after that encoding is a fixed point.
        let normal = paper.decode(&paper.encode(&update)).expect("re-decodes");
        let bytes = paper.encode(&normal);
        let again = paper.decode(&bytes).expect("re-decodes");
        assert_eq!(paper.encode(&again), bytes);
    }
    let mut compact = CompactCodec::new();
    compact.set_decode_limit(16 << 20);
    // Split before every zstd frame magic (28 B5 2F FD) after the first byte into consecutive updates.
    let mut start = 0;
    for i in 1..data.len().saturating_sub(3) {
        if data[i..i + 4] == [0x28, 0xb5, 0x2f, 0xfd] {
            let _ = compact.decode(&data[start..i]);
            start = i;
        }
    }
    let _ = compact.decode(&data[start..]);
});
