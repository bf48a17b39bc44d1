//! Mirroring: snapshots and deltas reproduce the server grids exactly, the state hash tracks
//! single-point changes, and malformed updates are rejected without changing anything.

mod common;

use glam::{Affine3A, Vec3};
use psao_client::{ClientError, ClientState};
use psao_delta::{InstanceDelta, Update};
use psao_points::pack::with_ao;
use psao_points::{Bucket, BucketEntry, Cell, InstanceGrid, PointLoc};

/// Recognises the error a malformed update must produce.
type ExpectedError = fn(&ClientError) -> bool;

struct Server {
    scene: psao_scene::Scene,
    points: Vec<psao_points::InstancePoints>,
    grids: Vec<InstanceGrid>,
    locs: Vec<Vec<Option<PointLoc>>>,
}

fn server(seed: u64) -> Server {
    let scene = common::scene(2.0, 2);
    let points = common::points(&scene, 256.0, seed);
    let (grids, locs) = common::grids(&points, |p| 0.5 + 0.4 * (3.0 * p.x).sin() * p.z.cos())
        .into_iter()
        .unzip();
    Server {
        scene,
        points,
        grids,
        locs,
    }
}

fn client_for(s: &Server) -> ClientState {
    ClientState::new(&common::table(&s.points, &s.grids))
}

#[test]
fn snapshot_then_deltas_mirror_exactly() {
    let mut s = server(7);
    let mut client = client_for(&s);
    assert_eq!(client.last_frame(), None);
    assert_eq!(client.instance_count(), 3);
    client
        .apply(&common::snapshot(1, &s.grids, common::transforms(&s.scene)))
        .unwrap();
    common::assert_mirrors(&client, &s.grids);
    assert_eq!(client.last_frame(), Some(1));
    assert_eq!(client.transform(1), Some(s.scene.instances[1].transform));
    assert!(client.point_count() > 1000);

    for round in 0..4u64 {
        let sent = s.grids.clone();
        for (inst, (grid, locs)) in s.grids.iter_mut().zip(&mut s.locs).enumerate() {
            let pts = &s.points[inst].points;
            for (k, (p, loc)) in pts.iter().zip(locs.iter_mut()).enumerate() {
                let Some(l) = *loc else { continue };
                match (k as u64 + round) % 5 {
                    // New AO in place.
                    0 => {
                        let ao = 0.1 * round as f32 + 0.3;
                        *loc = grid.update(l, p.position, p.normal, ao).ok();
                    }
                    // Move by a cell: freed and newly allocated cells and buckets.
                    1 if k % 7 == 0 => {
                        let step = Vec3::splat(grid.layout().cell_size * 0.9);
                        let moved = p.position + if round % 2 == 0 { step } else { -step };
                        *loc = grid.update(l, moved, p.normal, 0.2).ok();
                    }
                    2 if k % 11 == 0 => {
                        grid.remove(l).unwrap();
                        *loc = None;
                    }
                    _ => {}
                }
            }
        }
        let moved = Affine3A::from_translation(Vec3::new(0.1 * round as f32, 0.0, 0.0));
        let update = common::delta(10 + round, &sent, &s.grids, vec![(2, moved)]);
        assert!(!update.instances.is_empty());
        client.apply(&update).unwrap();
        common::assert_mirrors(&client, &s.grids);
        assert_eq!(client.last_frame(), Some(10 + round));
        assert_eq!(client.transform(2), Some(moved));
        // Transforms not in the delta keep their value.
        assert_eq!(client.transform(1), Some(s.scene.instances[1].transform));
    }
}

#[test]
fn snapshot_resets_previous_state() {
    let a = server(1);
    // Same layouts, other content: every other point, constant AO.
    let b: Vec<InstanceGrid> = a
        .points
        .iter()
        .zip(&a.grids)
        .map(|(pts, g)| {
            let half = pts.points.iter().step_by(2);
            InstanceGrid::build(*g.layout(), half.map(|p| (p.position, p.normal, 0.9))).0
        })
        .collect();
    assert!(b[0].cell_count() < a.grids[0].cell_count());
    let mut client = client_for(&a);
    client
        .apply(&common::snapshot(1, &a.grids, common::transforms(&a.scene)))
        .unwrap();
    let hash_a = client.state_hash();
    client
        .apply(&common::snapshot(2, &b, vec![(0, Affine3A::IDENTITY)]))
        .unwrap();
    common::assert_mirrors(&client, &b);
    assert_ne!(client.state_hash(), hash_a);
    // A snapshot forgets transforms it does not carry.
    assert_eq!(client.transform(0), Some(Affine3A::IDENTITY));
    assert_eq!(client.transform(1), None);
}

#[test]
fn hash_tracks_a_single_point() {
    let s = server(3);
    let mut client = client_for(&s);
    client
        .apply(&common::snapshot(1, &s.grids, Vec::new()))
        .unwrap();
    let h0 = client.state_hash();
    assert_eq!(h0, client.clone().state_hash());

    let grid = &s.grids[0];
    let (slot, cell) = grid
        .cells()
        .enumerate()
        .find(|(_, c)| c.count() > 2)
        .unwrap();
    let mut changed = *cell;
    let idx = changed.points.iter().position(|&b| b != 0).unwrap();
    let old_ao = changed.points[idx] & 0xFF;
    changed.points[idx] = with_ao(changed.points[idx], if old_ao > 128 { 0.0 } else { 1.0 });
    let one_cell = |frame, cell: Cell| Update {
        frame,
        snapshot: false,
        transforms: Vec::new(),
        instances: vec![InstanceDelta {
            instance: 0,
            buckets: Vec::new(),
            cells: vec![(slot as u32, cell)],
            lights: Vec::new(),
        }],
    };
    client.apply(&one_cell(2, changed)).unwrap();
    let h1 = client.state_hash();
    assert_ne!(h1, h0);
    // Transforms are not part of the hash.
    client
        .apply(&Update {
            frame: 3,
            snapshot: false,
            transforms: vec![(1, Affine3A::from_translation(Vec3::X))],
            instances: Vec::new(),
        })
        .unwrap();
    assert_eq!(client.state_hash(), h1);
    client.apply(&one_cell(4, *cell)).unwrap();
    assert_eq!(client.state_hash(), h0);
    common::assert_mirrors(&client, &s.grids);
}

#[test]
fn irradiance_records_are_kept_and_hashed_only_when_present() {
    let s = server(5);
    let snapshot = common::snapshot(1, &s.grids, common::transforms(&s.scene));
    let mut ao_only = client_for(&s);
    ao_only.apply(&snapshot).unwrap();
    let ao_hash = ao_only.state_hash();
    // Without records the hash is exactly the grids' hash of before lighting.
    assert_eq!(
        ao_hash,
        psao_client::state_hash_of(s.grids.iter().map(Some))
    );
    assert!(!ao_only.has_lights());

    let lit_update = common::with_lights(snapshot.clone(), &s.grids, |p| {
        Vec3::new(1.0 + p.x.abs(), 0.5, 0.25 + p.z.abs())
    });
    let mut lit = client_for(&s);
    lit.apply(&lit_update).unwrap();
    assert!(lit.has_lights());
    // The same grids as without records; only the records differ.
    for i in 0..lit.instance_count() {
        assert_eq!(lit.grid(i), ao_only.grid(i), "instance {i}");
    }
    let lit_hash = lit.state_hash();
    assert_ne!(lit_hash, ao_hash);
    // The records are kept as received, per cell slot.
    let d = &lit_update.instances[0];
    let (slot, _) = d.cells[3];
    assert_eq!(lit.cell_lights(0, slot), d.lights[3]);
    assert_ne!(lit.cell_lights(0, slot), [0; psao_points::CELL_POINTS]);

    // One record of one cell changes: the hash changes; restoring it restores the hash.
    let mut one = Update {
        frame: 2,
        instances: vec![InstanceDelta {
            instance: 0,
            buckets: Vec::new(),
            cells: vec![d.cells[3]],
            lights: vec![d.lights[3]],
        }],
        ..Update::default()
    };
    let k = d.lights[3].iter().position(|&r| r != 0).unwrap();
    one.instances[0].lights[0][k] ^= 1;
    lit.apply(&one).unwrap();
    assert_ne!(lit.state_hash(), lit_hash);
    one.instances[0].lights[0][k] ^= 1;
    lit.apply(&one).unwrap();
    assert_eq!(lit.state_hash(), lit_hash);

    // The server's hash over the same records agrees with the mirror's.
    let server_hash = psao_client::lit_state_hash_of(s.grids.iter().map(Some), |i, slot| {
        lit_update.instances[i]
            .cells
            .iter()
            .position(|(s, _)| *s == slot)
            .map_or([0; psao_points::CELL_POINTS], |c| {
                lit_update.instances[i].lights[c]
            })
    });
    assert_eq!(server_hash, lit_hash);

    // Records that do not pair with the cells are refused, and change nothing.
    let mut bad = one.clone();
    bad.instances[0].lights.push([0; psao_points::CELL_POINTS]);
    assert!(matches!(
        lit.apply(&bad),
        Err(ClientError::LightsMismatch {
            lights: 2,
            cells: 1,
            ..
        })
    ));
    assert_eq!(lit.state_hash(), lit_hash);

    // A snapshot without records forgets them: back to the AO-only hash.
    lit.apply(&snapshot).unwrap();
    assert_eq!(lit.state_hash(), ao_hash);
}

#[test]
fn malformed_updates_are_rejected_without_change() {
    let s = server(4);
    let mut client = client_for(&s);
    client
        .apply(&common::snapshot(5, &s.grids, common::transforms(&s.scene)))
        .unwrap();
    let before = client.state_hash();
    let layout = *s.grids[1].layout();
    let max_slot = layout.max_cells() as u32;
    // A valid change, to check that nothing of a rejected update is applied.
    let good_cell = (0u32, Cell { points: [0; 7] });
    let with = |extra: InstanceDelta, transforms: Vec<(u32, Affine3A)>, snapshot: bool| Update {
        frame: 99,
        snapshot,
        transforms,
        instances: vec![
            InstanceDelta {
                instance: 1,
                buckets: Vec::new(),
                cells: vec![good_cell],
                lights: Vec::new(),
            },
            extra,
        ],
    };
    let delta = |instance, buckets: Vec<(u32, Bucket)>, cells: Vec<(u32, Cell)>| InstanceDelta {
        instance,
        buckets,
        cells,
        lights: Vec::new(),
    };
    // A key that exists in the grid but is put into the wrong bucket.
    let id = 0u64;
    let wrong_bucket = (layout.bucket_of(id) as u32 + 1) % layout.bucket_count;
    let entry = |key_id: u64, slot: u32| {
        let mut b = Bucket::default();
        b.entries[3] = BucketEntry::new(key_id, slot);
        b
    };
    let far_id =
        u64::from(layout.dims.x) * u64::from(layout.dims.y) * 31 * u64::from(layout.dims.z);
    let cases: Vec<(Update, ExpectedError)> = vec![
        (
            with(delta(3, Vec::new(), Vec::new()), Vec::new(), false),
            |e| {
                matches!(
                    e,
                    ClientError::InstanceOutOfRange {
                        instance: 3,
                        count: 3
                    }
                )
            },
        ),
        (
            with(
                delta(0, Vec::new(), Vec::new()),
                vec![(7, Affine3A::IDENTITY)],
                false,
            ),
            |e| matches!(e, ClientError::InstanceOutOfRange { instance: 7, .. }),
        ),
        (
            with(
                delta(0, Vec::new(), Vec::new()),
                vec![(0, Affine3A::from_translation(Vec3::new(f32::NAN, 0.0, 0.0)))],
                false,
            ),
            |e| matches!(e, ClientError::NonFiniteTransform { instance: 0 }),
        ),
        (
            with(
                delta(
                    1,
                    vec![(layout.bucket_count, Bucket::default())],
                    Vec::new(),
                ),
                Vec::new(),
                true,
            ),
            |e| matches!(e, ClientError::BucketOutOfRange { instance: 1, .. }),
        ),
        (
            with(
                delta(1, Vec::new(), vec![(max_slot, Cell::default())]),
                Vec::new(),
                true,
            ),
            |e| matches!(e, ClientError::CellSlotOutOfRange { instance: 1, .. }),
        ),
        (
            with(
                delta(
                    1,
                    vec![(layout.bucket_of(id) as u32, entry(id, max_slot))],
                    Vec::new(),
                ),
                Vec::new(),
                false,
            ),
            |e| matches!(e, ClientError::CellSlotOutOfRange { instance: 1, .. }),
        ),
        (
            with(
                delta(1, vec![(wrong_bucket, entry(id, 0))], Vec::new()),
                Vec::new(),
                false,
            ),
            |e| matches!(e, ClientError::InvalidBucketEntry { instance: 1, .. }),
        ),
        (
            with(
                delta(
                    1,
                    vec![(layout.bucket_of(far_id) as u32, entry(far_id, 0))],
                    Vec::new(),
                ),
                Vec::new(),
                false,
            ),
            |e| matches!(e, ClientError::InvalidBucketEntry { instance: 1, .. }),
        ),
    ];
    for (k, (update, expected)) in cases.iter().enumerate() {
        let err = client.apply(update).expect_err("malformed update accepted");
        assert!(expected(&err), "case {k}: unexpected error {err}");
        assert_eq!(client.state_hash(), before, "case {k} changed the grids");
        assert_eq!(client.last_frame(), Some(5), "case {k} changed the frame");
        assert_eq!(client.transform(0), Some(s.scene.instances[0].transform));
    }
    common::assert_mirrors(&client, &s.grids);
    // The valid part alone is accepted and does change the state.
    client
        .apply(&Update {
            instances: vec![InstanceDelta {
                instance: 1,
                buckets: Vec::new(),
                cells: vec![good_cell],
                lights: Vec::new(),
            }],
            ..with(delta(0, Vec::new(), Vec::new()), Vec::new(), false)
        })
        .unwrap();
    assert_ne!(client.state_hash(), before);
}

#[test]
fn unusable_layouts_get_no_grid() {
    let s = server(5);
    let mut table = common::table(&s.points, &s.grids);
    table[1].layout.bucket_count = 3;
    table[2].layout.cell_size = f32::NAN;
    let mut client = ClientState::new(&table);
    assert!(client.grid(0).is_some());
    assert!(client.grid(1).is_none() && client.grid(2).is_none() && client.grid(3).is_none());
    let err = client
        .apply(&Update {
            frame: 1,
            snapshot: true,
            transforms: Vec::new(),
            instances: vec![InstanceDelta {
                instance: 2,
                buckets: Vec::new(),
                cells: Vec::new(),
                lights: Vec::new(),
            }],
        })
        .unwrap_err();
    assert_eq!(err, ClientError::NoGrid { instance: 2 });
    assert_eq!(client.last_frame(), None);
    // Empty table: nothing to mirror, but frames still count.
    let mut empty = ClientState::new(&[]);
    empty
        .apply(&Update {
            frame: 4,
            snapshot: true,
            transforms: Vec::new(),
            instances: Vec::new(),
        })
        .unwrap();
    assert_eq!(empty.last_frame(), Some(4));
}
