//! Fuzzes `.prt` model files: any bytes give a model or a typed error, never a panic, and a
//! model read writes back to bytes that read to the same bytes again.
//!
//! Half of the inputs (first byte even) are taken as they are; the other half become the body
//! of a file with the right magic bytes and a valid checksum, so that mutations reach the
//! counts, limits and weights behind them instead of stopping at the magic or the checksum.
#![no_main]

use libfuzzer_sys::fuzz_target;
use psao_prt::model_file::{from_bytes, to_bytes, MAGIC};

/// FNV-1a 64, the checksum of the format (written here independently of the reader).
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else {
        return;
    };
    let file = if mode & 1 == 0 {
        rest.to_vec()
    } else {
        let mut file = MAGIC.to_vec();
        file.extend_from_slice(rest);
        let sum = fnv1a(&file);
        file.extend_from_slice(&sum.to_le_bytes());
        file
    };
    if let Ok(model) = from_bytes(&file) {
        let bytes = to_bytes(&model);
        let again = from_bytes(&bytes).expect("a written model reads back");
        assert_eq!(to_bytes(&again), bytes);
    }
});
