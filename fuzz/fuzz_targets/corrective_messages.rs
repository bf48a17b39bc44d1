//! Fuzzes the corrective messages (Regions, Samples) past the frame checksum: the first byte
//! picks the message, the rest is its postcard body, framed here with a valid header so
//! that every input reaches the decoder and `Message::validate`. Any bytes give a valid
//! message or a typed error, never a panic; a decoded message survives a round trip.
#![no_main]

use libfuzzer_sys::fuzz_target;
use psao_wire::{decode_frame, encode_frame, frame_payload, Message, MAX_CLIENT_FRAME};

/// postcard variant indices of `Message::Regions` and `Message::Samples`.
const REGIONS: u8 = 9;
const SAMPLES: u8 = 10;

fuzz_target!(|data: &[u8]| {
    let Some((&kind, body)) = data.split_first() else {
        return;
    };
    let mut payload = vec![if kind & 1 == 0 { REGIONS } else { SAMPLES }];
    payload.extend_from_slice(body);
    let Ok(frame) = frame_payload(&payload) else {
        return;
    };
    if let Ok(message) = decode_frame(&frame, MAX_CLIENT_FRAME) {
        assert!(matches!(message, Message::Regions(_) | Message::Samples(_)));
        let again = encode_frame(&message).expect("a decoded message re-encodes");
        assert_eq!(
            decode_frame(&again, MAX_CLIENT_FRAME).expect("re-decodes"),
            message
        );
    }
});
