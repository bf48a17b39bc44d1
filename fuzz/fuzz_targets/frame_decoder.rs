//! Fuzzes the frame decoder: any bytes give a message or a typed error, never a panic, and a
//! decoded message survives a re-encode/decode round trip.
#![no_main]

use libfuzzer_sys::fuzz_target;
use psao_wire::{decode_frame, encode_frame, FrameHeader, HEADER_LEN};

fuzz_target!(|data: &[u8]| {
    if let Ok(message) = decode_frame(data, 1 << 20) {
        let again = encode_frame(&message).expect("a decoded message re-encodes");
        assert_eq!(decode_frame(&again, 1 << 20).expect("re-decodes"), message);
    }
    if let Some(header) = data.first_chunk::<HEADER_LEN>() {
        let _ = FrameHeader::parse(header, 1 << 16);
    }
});
