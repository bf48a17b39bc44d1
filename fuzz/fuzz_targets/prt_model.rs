//! Fuzzes `.prt` model files: any bytes give a model or a typed error, never a panic, and a
//! model read writes back to bytes that read to the same bytes again.
#![no_main]

use libfuzzer_sys::fuzz_target;
use psao_prt::model_file::{from_bytes, to_bytes};

fuzz_target!(|data: &[u8]| {
    if let Ok(model) = from_bytes(data) {
        let bytes = to_bytes(&model);
        let again = from_bytes(&bytes).expect("a written model reads back");
        assert_eq!(to_bytes(&again), bytes);
    }
});
