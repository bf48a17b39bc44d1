//! Fuzzes the NATS payload decoders (record batches, snapshot chunks, snapshot marks, view
//! sets; the first byte picks one): any bytes give a payload or a typed error, never a panic
//! or a huge allocation, and a decoded payload re-encodes to bytes that decode to the same
//! bytes again.
#![no_main]

use libfuzzer_sys::fuzz_target;
use psao_net::scale::wire::{Batch, Snapshot, SnapshotMark, ViewSet};

/// Decodes `bytes` as `T`, and if that works checks the encode/decode round trip.
macro_rules! round_trip {
    ($ty:ty, $bytes:expr) => {
        if let Ok(p) = <$ty>::decode($bytes) {
            let encoded = p.encode();
            let again = <$ty>::decode(&encoded).expect("an encoded payload decodes");
            assert_eq!(again.encode(), encoded);
        }
    };
}

fuzz_target!(|data: &[u8]| {
    let Some((&kind, bytes)) = data.split_first() else {
        return;
    };
    match kind % 4 {
        0 => round_trip!(Batch, bytes),
        1 => round_trip!(Snapshot, bytes),
        2 => round_trip!(SnapshotMark, bytes),
        _ => round_trip!(ViewSet, bytes),
    }
});
