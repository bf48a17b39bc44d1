//! Golden `compact` payloads for the browser viewer's decoder: a session of updates (a
//! snapshot, then points moving, appearing and disappearing, cells and bucket entries coming
//! and going, transforms changing) encoded by psao-delta's `CompactCodec`, with what its own
//! decoder reads back and psao-client's state hash after applying each to the session's
//! instance table, in `web/test/golden/compact.json` (decoded and applied in order by the
//! viewer's wasm in `web/test/compact.test.ts`). Fails when the encoder's bytes change;
//! `PSAO_BLESS=1` rewrites the file.

use glam::{Affine3A, Quat, UVec3, Vec3};
use psao_client::ClientState;
use psao_delta::{Codec, CompactCodec, GridLayout, InstanceDelta, InstanceInfo, Update};
use psao_points::pack::VALID_BIT;
use psao_points::{Bucket, BucketEntry, Cell};

/// Buckets per instance.
const BUCKETS: u32 = 64;

/// The session's two instances: cells up to 10⁵ per axis, so cell ids use the high words.
fn table() -> Vec<InstanceInfo> {
    let layout = GridLayout {
        origin: Vec3::new(-1.0, 0.0, 2.0),
        cell_size: 0.25,
        dims: UVec3::new(100_000, 90_000, 80_000),
        poisson_radius: 0.05,
        bucket_count: BUCKETS,
    };
    vec![
        InstanceInfo {
            layout,
            poisson_radius: 0.05,
            point_count: 500,
        };
        2
    ]
}

/// A cell id of the table's layout that hashes to bucket `b`.
fn id_in_bucket(rng: &mut Rng, b: u32) -> u64 {
    let layout = table()[0].layout;
    loop {
        let d = layout.dims;
        let coord = UVec3::new(
            rng.below(u64::from(d.x)) as u32,
            rng.below(u64::from(d.y)) as u32,
            rng.below(u64::from(d.z)) as u32,
        );
        let id = layout.cell_id(coord);
        if layout.bucket_of(id) == b as usize {
            return id;
        }
    }
}
use serde_json::{json, Value};

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// A deterministic generator (SplitMix64).
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
}

/// Bucket `b` holding `n` entries of cells that hash to it, at slots from `slot`.
fn bucket(rng: &mut Rng, b: u32, n: usize, slot: u32) -> Bucket {
    let mut out = Bucket::default();
    for (i, e) in out.entries.iter_mut().take(n).enumerate() {
        *e = BucketEntry::new(id_in_bucket(rng, b), slot + i as u32);
    }
    out
}

fn cell(rng: &mut Rng, n: usize) -> Cell {
    let mut c = Cell::default();
    for p in c.points.iter_mut().take(n) {
        *p = VALID_BIT | (rng.next() as u32 & !VALID_BIT);
    }
    c
}

fn session() -> Vec<Update> {
    let mut rng = Rng(7);
    let count = BUCKETS;
    let mut buckets: Vec<Vec<(u32, Bucket)>> = vec![Vec::new(), Vec::new()];
    let mut cells: Vec<Vec<(u32, Cell)>> = vec![Vec::new(), Vec::new()];
    for (inst, (bs, cs)) in buckets.iter_mut().zip(cells.iter_mut()).enumerate() {
        for k in 0..12u32 {
            let b = (k * 5 + inst as u32) % count;
            bs.push((b, bucket(&mut rng, b, 1 + (k as usize % 8), k * 8)));
        }
        for s in 0..40u32 {
            cs.push((s, cell(&mut rng, 1 + (s as usize % 7))));
        }
    }
    let transform = |k: f32| {
        Affine3A::from_scale_rotation_translation(
            Vec3::splat(1.0 + k * 0.1),
            Quat::from_rotation_y(k * 0.3),
            Vec3::new(k, -2.0 * k, 0.5),
        )
    };
    let mut updates = vec![Update {
        frame: 1,
        snapshot: true,
        transforms: vec![(0, transform(0.0)), (1, transform(1.0))],
        instances: (0..2)
            .map(|i| InstanceDelta {
                instance: i as u32,
                buckets: buckets[i].clone(),
                cells: cells[i].clone(),
                lights: Vec::new(),
            })
            .collect(),
    }];
    for frame in 2..8u64 {
        let mut instances = Vec::new();
        for i in 0..2usize {
            let mut d = InstanceDelta {
                instance: i as u32,
                ..Default::default()
            };
            for _ in 0..6 {
                let k = rng.below(cells[i].len() as u64) as usize;
                let (slot, mut c) = cells[i][k];
                match rng.below(4) {
                    // Move a point a little (position fields) or re-shade it (AO field).
                    0 => c.points[0] ^= 0x0400_0001,
                    // Insert a point in front.
                    1 => {
                        c.points.rotate_right(1);
                        c.points[0] = VALID_BIT | (rng.next() as u32 & !VALID_BIT);
                    }
                    // Remove the first point.
                    2 => {
                        c.points.rotate_left(1);
                        c.points[6] = 0;
                    }
                    _ => {
                        let n = 1 + rng.below(7) as usize;
                        c = cell(&mut rng, n);
                    }
                }
                cells[i][k] = (slot, c);
                if !d.cells.iter().any(|(s, _)| *s == slot) {
                    d.cells.push((slot, c));
                }
            }
            // A new cell with its bucket entry (coded by rank), and a bucket reordered.
            let slot = 100 + frame as u32 * 2 + i as u32;
            let c = cell(&mut rng, 3);
            cells[i].push((slot, c));
            d.cells.push((slot, c));
            let k = rng.below(buckets[i].len() as u64) as usize;
            let (b, mut bk) = buckets[i][k];
            bk.entries.rotate_left(1);
            let used = bk.entries.iter().filter(|e| e.key != 0).count();
            if used < 8 {
                bk.entries[7] = BucketEntry::new(id_in_bucket(&mut rng, b), slot);
            }
            buckets[i][k] = (b, bk);
            d.buckets.push((b, bk));
            d.buckets.sort_by_key(|(b, _)| *b);
            d.cells.sort_by_key(|(s, _)| *s);
            instances.push(d);
        }
        updates.push(Update {
            frame,
            snapshot: false,
            transforms: vec![(1, transform(frame as f32))],
            instances,
        });
    }
    updates
}

fn update_json(u: &Update) -> Value {
    json!({
        "frame": u.frame,
        "snapshot": u.snapshot,
        "transforms": u.transforms.iter().map(|(i, t)| json!([i, t.to_cols_array()])).collect::<Vec<_>>(),
        "instances": u.instances.iter().map(|d| json!({
            "instance": d.instance,
            "buckets": d.buckets.iter().map(|(b, bk)| json!([b, bk.entries.iter()
                .map(|&e| { let (key, slot) = (e.key, e.slot); json!([format!("{key:016x}"), slot]) }).collect::<Vec<_>>()]))
                .collect::<Vec<_>>(),
            "cells": d.cells.iter().map(|(s, c)| json!([s, c.points])).collect::<Vec<_>>(),
        })).collect::<Vec<_>>(),
    })
}

#[test]
fn golden_compact_payloads_match_the_committed_file() {
    let mut encoder = CompactCodec::new();
    let mut decoder = CompactCodec::new();
    let mut state = ClientState::new(&table());
    let mut items = Vec::new();
    for u in session() {
        let payload = encoder.encode(&u);
        let decoded = decoder.decode(&payload).unwrap();
        state.apply(&decoded).unwrap();
        items.push(json!({
            "payload": hex(&payload),
            "expect": update_json(&decoded),
            "state_hash": format!("{:016x}", state.state_hash()),
        }));
    }
    let table: Vec<Value> = table()
        .iter()
        .map(|i| {
            let l = &i.layout;
            json!({
                "origin": l.origin.to_array(), "cellSize": l.cell_size, "dims": l.dims.to_array(),
                "layoutPoissonRadius": l.poisson_radius, "bucketCount": l.bucket_count,
                "poissonRadius": i.poisson_radius, "pointCount": i.point_count,
            })
        })
        .collect();
    let text =
        serde_json::to_string_pretty(&json!({ "table": table, "updates": items })).unwrap() + "\n";
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../web/test/golden/compact.json"
    );
    if std::env::var_os("PSAO_BLESS").is_some() {
        std::fs::write(path, &text).unwrap();
    }
    let committed = std::fs::read_to_string(path).unwrap_or_default();
    assert!(
        committed == text,
        "{path} differs from what the compact codec encodes now; rerun with PSAO_BLESS=1 and \
         check the viewer's decoder (crates/psao-wasm, web/test/compact.test.ts)"
    );
}
