//! Fuzzes the NATS payload decoders (record batches and their parts, snapshot chunks,
//! snapshot marks, view sets; the first byte picks one): any bytes give a payload or a typed
//! error, never a panic or a huge allocation, and a decoded payload re-encodes to bytes that
//! decode to the same bytes again. The last kind feeds a sequence of record-batch parts (each
//! prefixed with its length, u16 little endian) to one reassembler, as an edge takes them
//! from the records stream: decompression and reassembly stay within their bounds.
#![no_main]

use libfuzzer_sys::fuzz_target;
use psao_net::scale::parts::Reassembler;
use psao_net::scale::wire::{Batch, BatchPart, Snapshot, SnapshotMark, ViewSet};

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

/// Feeds the length-prefixed parts in `bytes` to one reassembler, each on the subject of
/// the partition its first byte names.
fn reassemble(mut bytes: &[u8]) {
    let mut parts = Reassembler::default();
    while bytes.len() >= 3 {
        let len = usize::from(u16::from_le_bytes([bytes[0], bytes[1]]));
        let subject = u32::from(bytes[2] % 4);
        let rest = &bytes[3..];
        let (payload, tail) = rest.split_at(len.min(rest.len()));
        let _ = parts.add_payload(Some(subject), payload);
        bytes = tail;
    }
}

fuzz_target!(|data: &[u8]| {
    let Some((&kind, bytes)) = data.split_first() else {
        return;
    };
    match kind % 6 {
        0 => round_trip!(Batch, bytes),
        1 => round_trip!(Snapshot, bytes),
        2 => round_trip!(SnapshotMark, bytes),
        3 => round_trip!(ViewSet, bytes),
        4 => round_trip!(BatchPart, bytes),
        _ => reassemble(bytes),
    }
});
