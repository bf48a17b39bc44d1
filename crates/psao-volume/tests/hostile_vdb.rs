//! Hostile and tile-heavy OpenVDB files, written here by a small writer: the tile bomb (a root
//! child whose 32768 tiles are all active, ~8.6 kB on disk, 6.9 × 10¹⁰ voxels) is refused
//! before anything is expanded; a file with a few tiles loads them as tiles and samples
//! exactly; length fields that ask for more bytes than the file holds are refused.

use glam::{IVec3, Vec3};
use psao_volume::vdb::{self, MAX_CELLS};
use psao_volume::*;
use std::io::Write;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Compression flags of the written grids: zlib, with active-value masks.
const ZIP_ACTIVE: u32 = 3;

/// A 4-level node: tiles and leaves by child index (x slowest, as OpenVDB orders them).
struct Internal {
    tiles: Vec<(usize, f32)>,
    leaves: Vec<(usize, f32)>,
}

/// A root child at `origin` with tiles and 4-level children by index.
struct Root {
    origin: IVec3,
    tiles: Vec<(usize, f32)>,
    children: Vec<(usize, Internal)>,
}

fn u32s(out: &mut Vec<u8>, v: &[u32]) {
    for x in v {
        out.extend_from_slice(&x.to_le_bytes());
    }
}

fn name(out: &mut Vec<u8>, s: &str) {
    u32s(out, &[s.len() as u32]);
    out.extend_from_slice(s.as_bytes());
}

fn mask(n: usize, bits: impl Iterator<Item = usize>) -> Vec<u8> {
    let mut m = vec![0u8; n / 8];
    for b in bits {
        m[b / 8] |= 1 << (b % 8);
    }
    m
}

/// Node values: metadata 6 (all values stored), then zlib-compressed f32s.
fn values(out: &mut Vec<u8>, v: &[f32]) {
    out.push(6);
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
    for x in v {
        z.write_all(&x.to_le_bytes()).unwrap();
    }
    let z = z.finish().unwrap();
    out.extend_from_slice(&(z.len() as i64).to_le_bytes());
    out.extend_from_slice(&z);
}

/// An internal node with `n` entries: child mask, value mask (children and tiles) and values.
fn node(out: &mut Vec<u8>, n: usize, tiles: &[(usize, f32)], children: &[usize]) {
    out.extend(mask(n, children.iter().copied()));
    out.extend(mask(n, tiles.iter().map(|t| t.0)));
    let mut v = vec![0.0f32; n];
    for &(i, x) in tiles {
        v[i] = x;
    }
    values(out, &v);
}

/// A version-224 file with one fog grid `density` (voxel size 0.1) holding `roots`.
fn write_vdb(roots: &[Root]) -> Vec<u8> {
    let mut out = Vec::new();
    out.extend_from_slice(&0x5644_4220u64.to_le_bytes());
    u32s(&mut out, &[224, 10, 0]);
    out.push(1);
    out.extend_from_slice(b"00000000-0000-0000-0000-000000000000");
    u32s(&mut out, &[0, 1]);
    name(&mut out, "density");
    name(&mut out, "Tree_float_5_4_3");
    name(&mut out, "");
    let offsets = out.len();
    out.extend_from_slice(&[0; 24]);
    let grid_pos = out.len();
    u32s(&mut out, &[ZIP_ACTIVE, 1]);
    name(&mut out, "class");
    name(&mut out, "string");
    name(&mut out, "fog volume");
    name(&mut out, "UniformScaleMap");
    for v in [0.1, 0.1, 10.0, 100.0, 5.0] {
        for _ in 0..3 {
            out.extend_from_slice(&f64::to_le_bytes(v));
        }
    }
    u32s(&mut out, &[1, 0, 0, roots.len() as u32]);
    for r in roots {
        u32s(&mut out, &r.origin.to_array().map(|c| c as u32));
        let children: Vec<usize> = r.children.iter().map(|c| c.0).collect();
        node(&mut out, 32768, &r.tiles, &children);
        for (_, n4) in &r.children {
            let leaves: Vec<usize> = n4.leaves.iter().map(|l| l.0).collect();
            node(&mut out, 4096, &n4.tiles, &leaves);
            for _ in &n4.leaves {
                out.extend_from_slice(&[0xff; 64]);
            }
        }
    }
    let block_pos = out.len();
    for r in roots {
        for (_, n4) in &r.children {
            for &(_, v) in &n4.leaves {
                out.extend_from_slice(&[0xff; 64]);
                values(&mut out, &[v; 512]);
            }
        }
    }
    let end_pos = out.len();
    for (i, p) in [grid_pos, block_pos, end_pos].into_iter().enumerate() {
        out[offsets + 8 * i..offsets + 8 * i + 8].copy_from_slice(&(p as u64).to_le_bytes());
    }
    out
}

/// The tile bomb: one root child whose 32768 tiles (128³ voxels each) are all active.
fn tile_bomb() -> Vec<u8> {
    write_vdb(&[Root {
        origin: IVec3::ZERO,
        tiles: (0..32768).map(|i| (i, 1.0)).collect(),
        children: Vec::new(),
    }])
}

fn fixture() -> PathBuf {
    PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/tile_bomb.vdb"
    ))
}

#[test]
fn the_committed_tile_bomb_is_what_the_writer_makes() {
    let bytes = tile_bomb();
    assert!(bytes.len() < 9000, "{} bytes", bytes.len());
    if std::env::var_os("PSAO_WRITE_FIXTURES").is_some() {
        std::fs::write(fixture(), &bytes).unwrap();
    }
    assert_eq!(std::fs::read(fixture()).unwrap(), bytes);
}

#[test]
fn the_tile_bomb_is_refused_quickly_before_expanding() {
    let start = Instant::now();
    let e = vdb::read_vdb_file(&fixture(), None).unwrap_err();
    let took = start.elapsed();
    match &e {
        VolumeError::LimitExceeded { count, limit, .. } => {
            assert_eq!(*count, 32768 * 128 * 128 * 128);
            assert_eq!(*limit, MAX_CELLS as u64 * 512);
        }
        other => panic!("expected a limit error, got {other}"),
    }
    assert!(e.to_string().contains("tile_bomb.vdb"), "{e}");
    assert!(took < Duration::from_secs(1), "took {took:?}");
}

#[test]
fn a_root_child_at_the_most_negative_coordinate_is_refused() {
    // Found by the `vdb_reader` fuzzer: i32::MIN is a multiple of 4096, and its absolute
    // value does not fit an i32 (the origin check overflowed).
    for origin in [IVec3::new(i32::MIN, 0, 0), IVec3::new(0, 0, i32::MIN)] {
        let bytes = write_vdb(&[Root {
            origin,
            tiles: vec![(0, 1.0)],
            children: Vec::new(),
        }]);
        let e = vdb::read_vdb_bytes(&bytes, "origin.vdb", None).unwrap_err();
        assert!(e.to_string().contains("root child origin"), "{e}");
    }
}

#[test]
fn tiles_load_as_tiles_and_sample_exactly() {
    // Two 128³ tiles and a 4-level child with an 8³ tile and a leaf, at the origin.
    let bytes = write_vdb(&[Root {
        origin: IVec3::ZERO,
        tiles: vec![(1, 0.5), (32 * 32, 0.5)],
        children: vec![(
            0,
            Internal {
                tiles: vec![(1, 2.0)],
                leaves: vec![(0, 3.0)],
            },
        )],
    }]);
    let g = vdb::read_vdb_bytes(&bytes, "tiles", None).unwrap();
    assert_eq!(g.leaves.len(), 1);
    assert_eq!(g.tiles.len(), 3);
    assert_eq!(g.active_voxels(), 512 + 512 + 2 * 128 * 128 * 128);
    let (vol, stats) = Volume::build(std::slice::from_ref(&g), BrickFormat::F32, None).unwrap();
    // One brick for the leaf, one per distinct tile value (0.5 and 2.0).
    assert_eq!(stats.bricks_after, 3);
    assert_eq!(vol.tree.l3.len(), 1 + 1 + 2 * 4096);
    let mut s = Sampler::new(&vol, 0);
    // OpenVDB's child index is x slowest: tile 1 of the root child is at z = 128, tile 1024
    // at x = 128; the 4-level tile 1 is at z = 8.
    for (p, v) in [
        (IVec3::new(3, 4, 5), 3.0),
        (IVec3::new(3, 4, 13), 2.0),
        (IVec3::new(60, 70, 200), 0.5),
        (IVec3::new(200, 70, 60), 0.5),
        (IVec3::new(60, 200, 60), 0.0),
    ] {
        assert_eq!(s.voxel(p), v, "{p}");
    }
    assert_eq!(s.trilinear(Vec3::new(60.3, 70.6, 200.2)), 0.5);
    let err = vol.compare(&[g]).unwrap();
    assert_eq!(err.max_error, 0.0);
    assert_eq!(err.active_voxels, 512 + 512 + 2 * 128 * 128 * 128);
}

#[test]
fn length_fields_past_the_end_are_refused() {
    let good = write_vdb(&[Root {
        origin: IVec3::ZERO,
        tiles: Vec::new(),
        children: vec![(
            0,
            Internal {
                tiles: Vec::new(),
                leaves: vec![(0, 1.0)],
            },
        )],
    }]);
    assert!(vdb::read_vdb_bytes(&good, "good", None).is_ok());
    // The descriptor's block offset sits at byte 108; the leaf's zlib length follows its
    // 64-byte mask and metadata byte there.
    let block = u64::from_le_bytes(good[108..116].try_into().unwrap()) as usize;
    let at = block + 65;
    let mut bad = good.clone();
    bad[at..at + 8].copy_from_slice(&(1i64 << 40).to_le_bytes());
    let e = vdb::read_vdb_bytes(&bad, "bad", None).unwrap_err();
    assert!(e.to_string().contains("file ends inside"), "{e}");
    bad[at..at + 8].copy_from_slice(&(-(1i64 << 40)).to_le_bytes());
    let e = vdb::read_vdb_bytes(&bad, "bad", None).unwrap_err();
    assert!(e.to_string().contains("uncompressed bytes"), "{e}");
}

#[test]
fn devices_are_not_read_as_volumes() {
    let e = vdb::read_vdb_file(std::path::Path::new("/dev/zero"), None).unwrap_err();
    assert!(e.to_string().contains("not a regular file"), "{e}");
}
