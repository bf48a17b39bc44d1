//! Grid: lookups, coverage of the 2×2×2 block, overflow, updates and client mirroring.

mod common;

use std::collections::HashSet;

use glam::{Affine3A, UVec3, Vec3};
use psao_points::pack::{quantize_ao, unpack_ao, NORMAL_MAX_ERROR_DEG};
use psao_points::{
    generate_instance_points, reconstruct_ao, Bucket, BucketEntry, Cell, GenerateParams,
    GridLayout, InstanceGrid, InstancePoints, PointLoc, PointsError, ReconstructParams,
};
use psao_scene::{Material, Mesh};

fn points_of(mesh: &Mesh, seed: u64) -> InstancePoints {
    generate_instance_points(
        mesh,
        &Material::default(),
        &Affine3A::IDENTITY,
        &GenerateParams {
            density: 1024.0,
            seed,
        },
        None,
    )
    .unwrap()
}

/// A real mesh when the data is present, else a bent generated one.
fn test_mesh() -> Mesh {
    if let Some(meshes) = common::sponza(usize::MAX) {
        if let Some(m) = meshes.into_iter().find(|m| m.name == "object23") {
            return m;
        }
    }
    let mut m = common::plane(2.0, 8, 0.0);
    for p in &mut m.positions {
        p.z = 0.3 * (p.x * 2.0).sin();
    }
    m
}

fn ao_of(i: usize) -> f32 {
    (i % 97) as f32 / 96.0
}

#[test]
fn lookups_find_every_cell_and_point() {
    let mesh = test_mesh();
    let pts = points_of(&mesh, 1);
    let layout = GridLayout::for_points(&pts).unwrap();
    let (grid, locs) = InstanceGrid::build(
        layout,
        pts.points
            .iter()
            .enumerate()
            .map(|(i, p)| (p.position, p.normal, ao_of(i))),
    );
    let half_step = layout.cell_size / 64.0 + 1e-5;
    let cos_bound = NORMAL_MAX_ERROR_DEG.to_radians().cos() - 1e-4;
    let mut ids = HashSet::new();
    let mut stored = 0;
    for (i, (p, loc)) in pts.points.iter().zip(&locs).enumerate() {
        let coord = layout.cell_coord(p.position).expect("inside the grid");
        ids.insert(layout.cell_id(coord));
        let Some(loc) = loc else { continue };
        stored += 1;
        assert_eq!(grid.cell_of(p.position), Some(loc.slot));
        assert_eq!(grid.find_cell(coord), Some(loc.slot));
        let bits = grid.point(*loc).expect("stored point");
        let d = layout.unpack(coord, bits).unwrap();
        assert!((d.position - p.position).abs().max_element() <= half_step);
        assert!(d.normal.dot(p.normal) >= cos_bound);
        assert_eq!(quantize_ao(d.ao), quantize_ao(ao_of(i)));
        assert!(grid.cell_points(coord).any(|q| q == d));
        assert!(grid
            .nearest_cells(p.position)
            .contains(&Some((coord, loc.slot))));
    }
    println!(
        "{} points, {} cells, {} buckets, overflow {} cells / {} points",
        pts.points.len(),
        grid.cell_count(),
        layout.bucket_count,
        grid.overflow_cells(),
        grid.overflow_points()
    );
    assert_eq!(stored, grid.point_count());
    assert_eq!(
        stored as u64 + grid.overflow_points(),
        pts.points.len() as u64
    );
    assert!(grid.overflow_points() * 50 < pts.points.len() as u64);
    // Every distinct cell got a bucket entry (or was counted as refused).
    assert_eq!(
        grid.cell_count() as u64 + grid.overflow_cells(),
        ids.len() as u64
    );
    // Every bucket entry names a cell in its own bucket and a distinct slot.
    let mut slots = HashSet::new();
    for (b, bucket) in grid.buckets().enumerate() {
        for e in bucket.entries.iter().filter(|e| e.key != 0) {
            let id = e.cell_id().unwrap();
            assert_eq!(layout.bucket_of(id), b);
            assert!(ids.contains(&id));
            assert!(slots.insert(e.slot));
            assert!(grid.cell(e.slot).count() > 0);
        }
    }
    assert_eq!(slots.len(), grid.cell_count());
}

#[test]
fn nearest_cells_cover_the_interpolation_radius() {
    let mesh = test_mesh();
    let pts = points_of(&mesh, 2);
    let (grid, locs) = InstanceGrid::from_points(&pts, 0.5).unwrap();
    let layout = *grid.layout();
    let r = 2.0 * layout.poisson_radius;
    assert!(r <= 0.5 * layout.cell_size + 1e-6);
    let stored: Vec<(Vec3, PointLoc)> = pts
        .points
        .iter()
        .zip(&locs)
        .filter_map(|(p, l)| l.map(|l| (p.position, l)))
        .collect();
    for q in pts.points.iter().step_by(97) {
        // Query slightly off the sample positions.
        let p = q.position + Vec3::new(0.3, -0.2, 0.1) * layout.poisson_radius;
        let near = grid.nearest_cells(p);
        for (pos, loc) in &stored {
            let decoded =
                layout.unpack_position(layout.cell_coord(*pos).unwrap(), grid.point(*loc).unwrap());
            if decoded.distance(p) < r {
                assert!(
                    near.iter().flatten().any(|&(_, s)| s == loc.slot),
                    "point within r of {p} not in the 2×2×2 block"
                );
            }
        }
    }
}

#[test]
fn overflow_is_counted() {
    // A 10×10×10-cell grid with a single 8-entry bucket (tiny surface area).
    let layout = GridLayout::new((Vec3::ZERO, Vec3::splat(0.95)), 0.025, 0.1, 0.0).unwrap();
    assert_eq!(layout.bucket_count, 1);
    let centre = |c: UVec3| (c.as_vec3() + 0.5) * 0.1;
    // One point in each of 20 distinct cells: only 8 cells fit.
    let mut input: Vec<(Vec3, Vec3, f32)> = (0..20)
        .map(|i| (centre(UVec3::new(i % 10, i / 10, 3)), Vec3::Z, 0.5))
        .collect();
    // Ten more points in the first cell: 7 fit in total.
    input.extend((0..10).map(|k| {
        (
            centre(UVec3::new(0, 0, 3)) + Vec3::splat(0.001 * k as f32),
            Vec3::Z,
            0.5,
        )
    }));
    // One outside the grid.
    input.push((Vec3::splat(5.0), Vec3::Z, 0.5));
    let (mut grid, locs) = InstanceGrid::build(layout, input.clone());
    assert_eq!(grid.cell_count(), 8);
    assert_eq!(grid.overflow_cells(), 12);
    assert_eq!(grid.point_count(), 7 + 7);
    assert_eq!(grid.overflow_points(), 12 + 4 + 1);
    assert_eq!(locs.iter().filter(|l| l.is_some()).count(), 14);
    // Incremental inserts report and count the same overflow kinds.
    assert!(matches!(
        grid.insert(centre(UVec3::new(9, 9, 9)), Vec3::Z, 0.5),
        Err(PointsError::BucketFull { bucket: 0 })
    ));
    assert!(matches!(
        grid.insert(centre(UVec3::new(0, 0, 3)), Vec3::Z, 0.5),
        Err(PointsError::CellFull { .. })
    ));
    assert!(matches!(
        grid.insert(Vec3::splat(-1.0), Vec3::Z, 0.5),
        Err(PointsError::OutsideGrid(_))
    ));
    assert_eq!(grid.overflow_cells(), 13);
    assert_eq!(grid.overflow_points(), 17 + 3);
}

#[test]
fn insert_remove_update() {
    let layout = GridLayout::new((Vec3::ZERO, Vec3::ONE), 0.025, 0.1, 1.0).unwrap();
    let mut grid = InstanceGrid::new(layout);
    let a = grid
        .insert(Vec3::new(0.05, 0.05, 0.05), Vec3::Z, 0.25)
        .unwrap();
    let b = grid
        .insert(Vec3::new(0.06, 0.05, 0.05), Vec3::Z, 0.5)
        .unwrap();
    let c = grid
        .insert(Vec3::new(0.55, 0.05, 0.05), Vec3::X, 1.0)
        .unwrap();
    assert_eq!(a.slot, b.slot);
    assert_ne!(a.slot, c.slot);
    assert_eq!((grid.cell_count(), grid.point_count()), (2, 3));

    // Update inside the same cell keeps the location and rewrites the record.
    let a2 = grid
        .update(a, Vec3::new(0.07, 0.02, 0.03), Vec3::Y, 0.75)
        .unwrap();
    assert_eq!(a2, a);
    assert_eq!(
        unpack_ao(grid.point(a).unwrap()),
        quantize_ao(0.75) as f32 / 255.0
    );
    // Update into another cell moves it.
    let a3 = grid
        .update(a, Vec3::new(0.56, 0.05, 0.05), Vec3::X, 0.75)
        .unwrap();
    assert_eq!(a3.slot, c.slot);
    assert!(grid.point(a).is_none());

    // Removing the last point of a cell frees it and clears its bucket entry; the slot is reused.
    grid.remove(b).unwrap();
    assert_eq!(grid.cell_count(), 1);
    assert_eq!(grid.find_cell(UVec3::ZERO), None);
    assert!(grid
        .buckets()
        .all(|bk| bk.entries.iter().all(|e| e.slot != b.slot || e.key == 0)));
    let d = grid
        .insert(Vec3::new(0.95, 0.95, 0.95), Vec3::Z, 0.1)
        .unwrap();
    assert_eq!(d.slot, b.slot, "freed slot reused");
    assert!(matches!(
        grid.remove(b),
        Err(PointsError::NoSuchPoint { .. })
    ));
    assert!(grid
        .remove(PointLoc {
            slot: 999,
            index: 0
        })
        .is_err());
    assert!(grid
        .update(
            PointLoc {
                slot: c.slot,
                index: 6
            },
            Vec3::ZERO,
            Vec3::Z,
            0.0
        )
        .is_err());
}

#[test]
fn client_mirror_reproduces_server_state() {
    let mesh = test_mesh();
    let pts = points_of(&mesh, 4);
    let (server, _) = InstanceGrid::from_points(&pts, 0.3).unwrap();
    let layout = *server.layout();
    let mut client = InstanceGrid::new(layout);
    for (i, b) in server.buckets().enumerate() {
        if !b.is_empty() {
            client.set_bucket(i, b).unwrap();
        }
    }
    for (s, c) in server.cells().enumerate() {
        client.set_cell(s as u32, *c).unwrap();
    }
    assert!(client.buckets().eq(server.buckets()));
    assert!(client.cells().eq(server.cells()));
    let params = ReconstructParams::default();
    for p in pts.points.iter().step_by(11) {
        let q = p.position + Vec3::splat(0.2 * layout.poisson_radius);
        assert_eq!(
            reconstruct_ao(&client, q, p.normal, &params),
            reconstruct_ao(&server, q, p.normal, &params)
        );
    }
    // Clearing a bucket hides its cells.
    let (b, bucket) = server
        .buckets()
        .enumerate()
        .find(|(_, b)| !b.is_empty())
        .unwrap();
    let e = bucket.entries.iter().find(|e| e.key != 0).unwrap();
    let coord = layout.coord_of_id(e.cell_id().unwrap()).unwrap();
    assert!(client.find_cell(coord).is_some());
    client.set_bucket(b, Bucket::default()).unwrap();
    assert!(client.find_cell(coord).is_none());

    // Malformed input is an error, never a panic.
    let n = layout.bucket_count as usize;
    assert!(matches!(
        client.set_bucket(n, Bucket::default()),
        Err(PointsError::BucketOutOfRange { .. })
    ));
    let mut wrong = Bucket::default();
    wrong.entries[0] = BucketEntry::new(layout.cell_id(coord), 0);
    let other = (layout.bucket_of(layout.cell_id(coord)) + 1) % n;
    if other != b {
        assert!(matches!(
            client.set_bucket(other, wrong),
            Err(PointsError::InvalidBucketEntry { .. })
        ));
    }
    let mut far = Bucket::default();
    far.entries[0] = BucketEntry::new(layout.cell_id(coord), u32::MAX);
    assert!(matches!(
        client.set_bucket(layout.bucket_of(layout.cell_id(coord)), far),
        Err(PointsError::CellSlotOutOfRange { .. })
    ));
    assert!(client.set_cell(u32::MAX, Cell::default()).is_err());
}

/// Bucket tables are the largest part of a grid: an entry must stay 12 bytes (a 64-bit key and
/// a 32-bit slot, no padding), and its fields keep their values through copies.
#[test]
fn bucket_entries_carry_no_padding() {
    assert_eq!(std::mem::size_of::<BucketEntry>(), 12);
    assert_eq!(
        std::mem::size_of::<Bucket>(),
        12 * psao_points::BUCKET_ENTRIES
    );
    let e = BucketEntry::new(u64::MAX - 1, u32::MAX - 7);
    let copy = e;
    assert_eq!(copy.cell_id(), Some(u64::MAX - 1));
    assert_eq!({ copy.slot }, u32::MAX - 7);
}

#[test]
fn storage_grows_with_what_is_written_not_with_the_table() {
    // A table of 2^20 buckets (8 Mi addressable slots): empty, it holds only page tables.
    let layout = GridLayout::new((Vec3::ZERO, Vec3::splat(100.0)), 0.025, 0.1, 3.0e4).unwrap();
    assert!(layout.bucket_count >= 1 << 20);
    let mut grid = InstanceGrid::new(layout);
    let empty = grid.heap_bytes();
    assert!(empty <= u64::from(layout.bucket_count) / 4, "{empty} bytes");
    // One bucket entry and one cell far out in the table cost a page each, not the table.
    let id = layout.cell_id(UVec3::new(500, 400, 300));
    let slot = (layout.max_cells() - 1) as u32;
    let mut bucket = Bucket::default();
    bucket.entries[3] = BucketEntry::new(id, slot);
    grid.set_bucket(layout.bucket_of(id), bucket).unwrap();
    let mut cell = Cell::default();
    cell.points[0] = grid.layout().pack(
        UVec3::new(500, 400, 300),
        grid.layout().cell_min(UVec3::new(500, 400, 300)),
        Vec3::Z,
        0.5,
    );
    grid.set_cell(slot, cell).unwrap();
    assert_eq!(grid.bucket(layout.bucket_of(id)), bucket);
    assert_eq!(grid.find_cell(UVec3::new(500, 400, 300)), Some(slot));
    assert_eq!(grid.point_count(), 1);
    // Beyond a page of each, only the cell slots' page table grows (8 bytes per 64 slots up
    // to the highest one written).
    let written = grid.heap_bytes() - empty;
    let page_table = (u64::from(slot) / 64 + 1) * 8;
    assert!(
        written < page_table + 8 * 1024,
        "{written} bytes for one entry and one cell"
    );
    // The parts name where the bytes go: one record, the cell's six empty entries, the 63
    // other cells of its page, one bucket entry of 16 bytes (in a pool of some capacity).
    let parts = grid.memory_parts();
    assert_eq!(parts.total(), grid.heap_bytes());
    assert_eq!(parts.records, 4);
    assert_eq!(parts.empty_entries, 6 * 4);
    assert_eq!(parts.unheld_cells, 63 * 28);
    assert_eq!(parts.cell_page_table, page_table);
    assert!(parts.bucket_entries >= 16 && parts.bucket_entries.is_multiple_of(16));
    assert_eq!(parts.slot_lists, 0);
}
