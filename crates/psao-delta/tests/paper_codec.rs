//! Round trips and hostile input for the `paper` codec.

use glam::{Affine3A, Quat, Vec3};
use psao_delta::{
    codec_by_name, Codec, DeltaError, InstanceDelta, PaperCodec, Update, CODEC_NAMES,
    MAX_DECODED_BYTES, MAX_DECODE_LIMIT,
};
use psao_points::pack::VALID_BIT;
use psao_points::{Bucket, BucketEntry, Cell};

/// splitmix64: a tiny deterministic generator for test data.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
    fn f32(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
    }
}

/// A random compacted update (the form servers produce); `wide` allows keys above 32 bits.
fn random_update(rng: &mut Rng, wide: bool) -> Update {
    let transforms = (0..rng.below(5))
        .map(|i| {
            let t = Affine3A::from_scale_rotation_translation(
                Vec3::splat(1.0 + rng.f32().abs()),
                Quat::from_rotation_y(rng.f32() * 3.0),
                Vec3::new(rng.f32(), rng.f32(), rng.f32()) * 50.0,
            );
            (i as u32, t)
        })
        .collect();
    let instances = (0..rng.below(4))
        .map(|i| {
            let buckets = (0..rng.below(40))
                .map(|_| {
                    let mut b = Bucket::default();
                    for e in b.entries.iter_mut().take(rng.below(9) as usize) {
                        let key_range = if wide {
                            u64::MAX - 1
                        } else {
                            u64::from(u32::MAX)
                        };
                        *e = BucketEntry {
                            key: 1 + rng.below(key_range),
                            slot: rng.next() as u32,
                        };
                    }
                    (rng.next() as u32, b)
                })
                .collect();
            let cells = (0..rng.below(60))
                .map(|_| {
                    let mut c = Cell::default();
                    for p in c.points.iter_mut().take(rng.below(8) as usize) {
                        *p = VALID_BIT | (rng.next() as u32);
                    }
                    (rng.next() as u32, c)
                })
                .collect();
            InstanceDelta {
                instance: i as u32 * 3,
                buckets,
                cells,
                lights: Vec::new(),
            }
        })
        .collect();
    Update {
        frame: rng.next(),
        snapshot: rng.below(2) == 0,
        transforms,
        instances,
    }
}

#[test]
fn random_updates_round_trip_bit_identically() {
    let mut rng = Rng(1);
    let mut codec = codec_by_name("paper").unwrap();
    assert_eq!(codec.name(), "paper");
    for i in 0..200 {
        let update = random_update(&mut rng, i % 4 == 0);
        let bytes = codec.encode(&update);
        let back = codec.decode(&bytes).unwrap();
        assert_eq!(back, update, "update {i}");
        // Floats compare bit for bit, not just by value.
        for ((_, a), (_, b)) in back.transforms.iter().zip(&update.transforms) {
            let bits = |t: &Affine3A| t.to_cols_array().map(f32::to_bits);
            assert_eq!(bits(a), bits(b));
        }
    }
}

#[test]
fn empty_update_round_trips_and_is_small() {
    let mut codec = PaperCodec::new();
    let update = Update::default();
    let bytes = codec.encode(&update);
    assert!(bytes.len() < 64, "{} bytes", bytes.len());
    assert_eq!(codec.decode(&bytes).unwrap(), update);
}

#[test]
fn encoding_compacts_buckets_and_cells() {
    let mut bucket = Bucket::default();
    bucket.entries[5] = BucketEntry::new(41, 2);
    let mut cell = Cell::default();
    cell.points[4] = VALID_BIT | 99;
    let update = Update {
        instances: vec![InstanceDelta {
            instance: 0,
            buckets: vec![(1, bucket)],
            cells: vec![(2, cell)],
            lights: Vec::new(),
        }],
        ..Default::default()
    };
    let mut codec = PaperCodec::new();
    let bytes = codec.encode(&update);
    let back = codec.decode(&bytes).unwrap();
    let d = &back.instances[0];
    assert_eq!(d.buckets[0].1.entries[0], BucketEntry::new(41, 2));
    assert_eq!(d.buckets[0].1.len(), 1);
    assert_eq!(d.cells[0].1.points[0], VALID_BIT | 99);
    assert_eq!(d.cells[0].1.count(), 1);
}

#[test]
fn unknown_codec_is_an_error() {
    assert!(matches!(
        codec_by_name("lz5"),
        Err(DeltaError::UnknownCodec(_))
    ));
}

#[test]
fn truncated_garbage_and_bit_flipped_input_is_rejected() {
    let mut rng = Rng(7);
    let mut codec = PaperCodec::new();
    let update = random_update(&mut rng, false);
    let bytes = codec.encode(&update);
    for len in 0..bytes.len() {
        assert!(codec.decode(&bytes[..len]).is_err(), "prefix {len}");
    }
    // No single-bit flip yields a different update: zstd's frame checks, the content
    // checksum and the structural checks catch all of them except the few bits zstd ignores
    // (unused header and padding bits), which decode to the original.
    let mut rejected = 0;
    for bit in 0..bytes.len() * 8 {
        let mut b = bytes.clone();
        b[bit / 8] ^= 1 << (bit % 8);
        match codec.decode(&b) {
            Ok(u) => assert_eq!(u, update, "bit {bit} changed the update silently"),
            Err(_) => rejected += 1,
        }
    }
    assert!(rejected * 10 >= bytes.len() * 8 * 9, "{rejected} rejected");
    // Random multi-byte corruption and pure garbage never panic and are rejected.
    for _ in 0..2000 {
        let mut b = bytes.clone();
        for _ in 0..1 + rng.below(8) {
            let i = rng.below(b.len() as u64) as usize;
            b[i] = rng.next() as u8;
        }
        if let Ok(u) = codec.decode(&b) {
            assert_eq!(u, update);
        }
        let garbage: Vec<u8> = (0..rng.below(300)).map(|_| rng.next() as u8).collect();
        assert!(codec.decode(&garbage).is_err());
    }
}

#[test]
fn valid_zstd_with_malformed_payload_is_rejected() {
    // Well-formed compression around broken payloads reaches the structural checks.
    let compress = |words: &[u32]| {
        let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
        zstd::bulk::compress(&bytes, 3).unwrap()
    };
    let tag = u32::from_le_bytes(*b"PSD1");
    let mut codec = PaperCodec::new();
    type Check = fn(&DeltaError) -> bool;
    let cases: [(Vec<u32>, Check); 5] = [
        (vec![0xdead_beef], |e| {
            matches!(e, DeltaError::BadTag { .. })
        }),
        (vec![tag, 0, 0, 8], |e| {
            matches!(e, DeltaError::UnknownFlags(8))
        }),
        // A count of 2^32 − 1 transforms with nothing behind it: refused before allocating.
        (vec![tag, 0, 0, 0, u32::MAX], |e| {
            matches!(e, DeltaError::Truncated { .. })
        }),
        (vec![tag, 0, 0, 0, 0, 1, 0, u32::MAX, 0], |e| {
            matches!(e, DeltaError::Truncated { .. })
        }),
        (vec![tag, 0, 0, 0, 0, 0, 9], |e| {
            matches!(e, DeltaError::Trailing(1))
        }),
    ];
    for (words, check) in cases {
        let err = codec.decode(&compress(&words)).unwrap_err();
        assert!(check(&err), "{words:?}: {err}");
    }
    let odd = zstd::bulk::compress(&[1, 2, 3, 4, 5], 3).unwrap();
    assert_eq!(codec.decode(&odd).unwrap_err(), DeltaError::Unaligned(5));
}

/// A zstd frame by hand: header recording `claimed` bytes, then RLE blocks (one repeated
/// byte each, at most 128 KiB) adding up to `actual` bytes of zeros.
fn rle_frame(claimed: Option<u64>, actual: u64) -> Vec<u8> {
    let mut f = vec![0x28, 0xb5, 0x2f, 0xfd];
    match claimed {
        Some(size) => {
            f.push(0xe0); // 8-byte content size, single segment
            f.extend_from_slice(&size.to_le_bytes());
        }
        None => {
            f.push(0x00); // no content size: a window descriptor follows
            f.push(0x58); // window 2^(10 + 11) = 2 MiB
        }
    }
    let mut left = actual;
    loop {
        let n = left.min(128 << 10);
        left -= n;
        let header = (u32::from(left == 0)) | (1 << 1) | ((n as u32) << 3);
        f.extend_from_slice(&header.to_le_bytes()[..3]);
        f.push(0);
        if left == 0 {
            return f;
        }
    }
}

#[test]
fn decompression_bombs_are_refused() {
    let mut codec = PaperCodec::new();
    // The hand-made frame is valid zstd: a small one expands and fails on its (zero) tag.
    let small = rle_frame(Some(4096), 4096);
    assert!(matches!(
        codec.decode(&small),
        Err(DeltaError::BadTag { found: 0, .. })
    ));
    // 257 MiB of zeros in 8 KiB: refused from the header, before any allocation.
    let bomb = rle_frame(
        Some(MAX_DECODED_BYTES + (1 << 20)),
        MAX_DECODED_BYTES + (1 << 20),
    );
    assert!(bomb.len() < 16 << 10);
    assert!(matches!(
        codec.decode(&bomb),
        Err(DeltaError::TooLarge { .. })
    ));
    // A header that under-states the size cannot make the decoder write past it.
    let liar = rle_frame(Some(64), 64 << 20);
    assert!(matches!(
        codec.decode(&liar),
        Err(DeltaError::Decompress(_))
    ));
    // A frame without a recorded size is refused rather than decoded into a guessed buffer.
    let unsized_frame = rle_frame(None, 1 << 20);
    assert_eq!(codec.decode(&unsized_frame), Err(DeltaError::UnknownSize));
}

#[test]
fn decode_limits_follow_the_table_up_to_the_ceiling() {
    // A frame claiming 8 GiB is refused from its header; the error names the limit in force.
    let huge = rle_frame(Some(8 << 30), 4096);
    for name in CODEC_NAMES {
        let limit_after = |set: Option<u64>| {
            let mut codec = codec_by_name(name).unwrap();
            if let Some(bytes) = set {
                codec.set_decode_limit(bytes);
            }
            match codec.decode(&huge) {
                Err(DeltaError::TooLarge { limit, .. }) => limit,
                other => panic!("{name}: {other:?}"),
            }
        };
        assert_eq!(limit_after(None), MAX_DECODED_BYTES, "{name}");
        assert_eq!(limit_after(Some(1 << 20)), 1 << 20, "{name}");
        // Above the default: what a dense instance table needs is granted…
        assert_eq!(limit_after(Some(3 << 30)), 3 << 30, "{name}");
        // …up to the absolute ceiling.
        assert_eq!(limit_after(Some(u64::MAX)), MAX_DECODE_LIMIT, "{name}");
    }
}
