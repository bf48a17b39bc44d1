//! Tests on the real OpenVDB files in the shared data folder (skipped when it is missing).

use glam::{IVec3, Vec3};
use psao_volume::render::{self, DenseGrid};
use psao_volume::trace::{optical_depth, IndexRay};
use psao_volume::tree::Locate;
use psao_volume::*;
use std::path::PathBuf;

fn data(name: &str) -> Option<PathBuf> {
    let p = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/data/volumes"
    ))
    .join(name);
    if p.exists() {
        Some(p)
    } else {
        eprintln!("note: {} missing, test skipped", p.display());
        None
    }
}

#[test]
fn all_three_files_load_with_their_transforms() {
    for (name, class, active, voxel, translation) in [
        (
            "smoke1.vdb",
            GridClass::Fog,
            1_049_275,
            0.476190,
            Vec3::new(-34.0476, -13.0952, -26.4286),
        ),
        ("sphere.vdb", GridClass::LevelSet, 270_638, 0.05, Vec3::ZERO),
        (
            "dragon_sergeneren.vdb",
            GridClass::Fog,
            19_660,
            0.1,
            Vec3::ZERO,
        ),
    ] {
        let Some(path) = data(name) else { return };
        let g = vdb::read_vdb_file(&path, None).unwrap();
        assert_eq!(g.class, class, "{name}");
        assert_eq!(g.active_voxels(), active, "{name}");
        assert!((g.transform.scale.x - voxel).abs() < 1e-5, "{name}");
        assert!(
            (g.transform.translation.as_vec3() - translation).length() < 1e-3,
            "{name}"
        );
    }
}

#[test]
fn level_set_inactive_voxels_get_signed_background() {
    let Some(path) = data("sphere.vdb") else {
        return;
    };
    let g = vdb::read_vdb_file(&path, None).unwrap();
    let bg = g.background;
    assert!((bg - 0.15).abs() < 1e-3);
    let (mut inside, mut outside) = (0, 0);
    for l in &g.leaves {
        for i in 0..BRICK_VOXELS {
            if !l.is_active(i) {
                assert_eq!(l.values[i].abs(), bg);
                if l.values[i] < 0.0 {
                    inside += 1;
                } else {
                    outside += 1;
                }
            }
        }
    }
    assert!(inside > 1000 && outside > 1000, "{inside} {outside}");
}

fn copy_with(path: &PathBuf, edit: impl FnOnce(&mut Vec<u8>)) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let mut bytes = std::fs::read(path).unwrap();
    edit(&mut bytes);
    let out = dir.path().join("broken.vdb");
    std::fs::write(&out, bytes).unwrap();
    (dir, out)
}

fn replace(bytes: &mut [u8], from: &[u8], to: &[u8]) {
    assert_eq!(from.len(), to.len());
    let at = bytes
        .windows(from.len())
        .position(|w| w == from)
        .expect("pattern in file");
    bytes[at..at + to.len()].copy_from_slice(to);
}

#[test]
fn broken_files_give_errors_not_panics() {
    let Some(path) = data("sphere.vdb") else {
        return;
    };
    let len = std::fs::metadata(&path).unwrap().len() as usize;
    for cut in [4, 40, 300, 2000, len / 2, len - 10] {
        let (_d, p) = copy_with(&path, |b| b.truncate(cut));
        assert!(vdb::read_vdb_file(&p, None).is_err(), "truncated at {cut}");
    }
    let (_d, p) = copy_with(&path, |b| b[0] ^= 0xff);
    assert!(matches!(
        vdb::read_vdb_file(&p, None),
        Err(VolumeError::InvalidVdb(..))
    ));
    let (_d, p) = copy_with(&path, |b| {
        replace(b, b"UniformScaleMap", b"UnitaryMap_ABCD")
    });
    let e = vdb::read_vdb_file(&p, None).unwrap_err();
    assert!(matches!(e, VolumeError::UnsupportedTransform(..)), "{e}");
    assert!(e.to_string().contains("UnitaryMap_ABCD"));
    let (_d, p) = copy_with(&path, |b| {
        replace(b, b"Tree_float_5_4_3", b"Tree_int32_5_4_3")
    });
    assert!(matches!(
        vdb::read_vdb_file(&p, None),
        Err(VolumeError::UnsupportedGrid(..))
    ));
    // Damage inside the tree data: whatever happens, no panic escapes.
    for k in 1..8 {
        let (_d, p) = copy_with(&path, |b| {
            let at = len * k / 8;
            for x in &mut b[at..at + 64] {
                *x = x.wrapping_mul(31).wrapping_add(7);
            }
        });
        let _ = vdb::read_vdb_file(&p, None);
    }
}

#[test]
fn tree_locates_every_leaf_and_its_mask() {
    let Some(path) = data("sphere.vdb") else {
        return;
    };
    let g = vdb::read_vdb_file(&path, None).unwrap();
    let (vol, stats) = Volume::build(std::slice::from_ref(&g), BrickFormat::F32, None).unwrap();
    assert_eq!(stats.bricks_after, g.leaves.len());
    let mut out = [0.0; BRICK_VOXELS];
    for l in &g.leaves {
        let Locate::Leaf(i, o) = vol.tree.locate(0, l.origin + IVec3::new(3, 5, 7)) else {
            panic!("leaf at {} not found", l.origin)
        };
        assert_eq!(o, l.origin);
        vol.pool.decode(vol.tree.l3[i as usize].brick(), &mut out);
        assert_eq!(&out[..], &l.values[..]);
        for (x, y, z) in [(0, 0, 0), (7, 7, 7), (3, 1, 4), (5, 2, 6)] {
            let v = x + 8 * (y + 8 * z);
            let p = l.origin + IVec3::new(x as i32, y as i32, z as i32);
            assert_eq!(vol.tree.is_active(0, p), l.is_active(v), "{p}");
        }
    }
    assert!(matches!(
        vol.tree.locate(0, IVec3::splat(100_000)),
        Locate::Outside
    ));
    let e = vol.compare(std::slice::from_ref(&g)).unwrap();
    assert_eq!(e.rmse, 0.0);
    assert_eq!(e.active_voxels, 270_638);
}

#[test]
fn compressed_formats_keep_errors_small_and_psv_round_trips() {
    let Some(path) = data("dragon_sergeneren.vdb") else {
        return;
    };
    let g = vdb::read_vdb_file(&path, None).unwrap();
    let frames = vec![g.clone(), g];
    let mut last = -1.0;
    for format in [BrickFormat::F16, BrickFormat::Unorm8, BrickFormat::Bc7] {
        let (vol, _) = Volume::build(&frames, format, None).unwrap();
        assert_eq!(vol.frames(), 2);
        let e = vol.compare(&frames).unwrap();
        assert!(e.rmse >= last && e.rmse < 0.05, "{format:?}: {e:?}");
        last = e.rmse;
        let s = vol.sizes(frames.iter().map(|f| f.active_voxels()).sum());
        // BC7 adds its refinement layer (1/64 of the bricks) on top of 2 bits per voxel.
        let nominal = format.brick_bytes() as f64 * 8.0 / 512.0;
        let extra = if format == BrickFormat::Bc7 {
            0.05
        } else {
            1e-9
        };
        let bpv = s.bits_per_voxel_bricks();
        assert!(bpv >= nominal && bpv < nominal + extra, "{format:?}: {bpv}");
        let bytes = psv::to_bytes(&vol);
        let back = psv::from_bytes(&bytes).unwrap();
        assert_eq!(back.pool.data, vol.pool.data);
        assert_eq!(back.pool.refined, vol.pool.refined);
        assert_eq!(back.tree.l3, vol.tree.l3);
        assert_eq!(back.compare(&frames).unwrap(), e);
        let mut damaged = bytes.clone();
        let n = damaged.len();
        damaged[n / 2] ^= 1;
        assert!(
            matches!(psv::from_bytes(&damaged), Err(VolumeError::InvalidPsv(m)) if m.contains("checksum"))
        );
        assert!(psv::from_bytes(&bytes[..n - 3]).is_err());
    }
}

#[test]
fn clustering_merges_bricks_deterministically() {
    let Some(path) = data("sphere.vdb") else {
        return;
    };
    let g = vdb::read_vdb_file(&path, None).unwrap();
    let frames = [g];
    let p = ClusterParams {
        k: 32,
        iterations: 5,
        threshold: 0.05,
        seed: 3,
    };
    let (a, sa) = Volume::build(&frames, BrickFormat::F16, Some(&p)).unwrap();
    let (b, sb) = Volume::build(&frames, BrickFormat::F16, Some(&p)).unwrap();
    assert_eq!(sa, sb);
    assert_eq!(a.pool.data, b.pool.data);
    assert!(sa.bricks_after < sa.bricks_before, "{sa:?}");
    assert!(sa.cluster_candidates > 0);
    let e = a.compare(&frames).unwrap();
    assert!(e.rmse > 0.0 && e.rmse < 0.05, "{e:?}");
}

#[test]
fn hdda_agrees_with_dense_marching_and_transmittance_is_consistent() {
    let Some(path) = data("sphere.vdb") else {
        return;
    };
    let g = vdb::read_vdb_file(&path, None).unwrap();
    let (vol, _) = Volume::build(&[g], BrickFormat::F32, None).unwrap();
    let cam = Camera::framing(vol.world_bounds(0), 40.0);
    let st = RenderSettings::new(&vol, 48, 48, RenderMode::LevelSet);
    let a = render::render(&vol, &cam, &st).unwrap();
    let b =
        render::render_dense_level_set(&vol, &DenseGrid::from_volume(&vol, 0), &cam, &st).unwrap();
    assert!(a.pixels.iter().filter(|&&p| p > 0.0).count() > 300);
    assert!(a.mean_abs_diff(&b) < 0.01, "{}", a.mean_abs_diff(&b));
    // The sphere (radius about 3 units at the origin) blocks a ray through its centre.
    let (lo, hi) = vol.world_bounds(0);
    assert!(lo.x < -2.5 && hi.x > 2.5);
    assert_eq!(
        vol.transmittance(0, Vec3::new(-5.0, 0.1, 0.2), Vec3::X, 10.0, 1.0),
        0.0
    );
    assert_eq!(
        vol.transmittance(0, Vec3::new(-5.0, 0.1, 0.2), Vec3::X, 1.0, 1.0),
        1.0
    );
    assert_eq!(
        vol.transmittance(0, Vec3::new(-5.0, 4.0, 0.2), Vec3::X, 10.0, 1.0),
        1.0
    );
}

#[test]
fn fog_optical_depth_matches_brute_force_and_delta_tracking_is_seeded() {
    let Some(path) = data("dragon_sergeneren.vdb") else {
        return;
    };
    let g = vdb::read_vdb_file(&path, None).unwrap();
    let (vol, _) = Volume::build(&[g], BrickFormat::F32, None).unwrap();
    let (lo, hi) = vol.world_bounds(0);
    let c = (lo + hi) * 0.5;
    let mut s = Sampler::new(&vol, 0);
    let mut hits = 0;
    for k in 0..16 {
        let dir = Vec3::new(1.0, 0.2 * (k as f32 - 8.0) / 8.0, 0.1 * (k % 3) as f32).normalize();
        let origin = c - dir * 20.0;
        let ray = IndexRay::from_world(&vol, origin, dir);
        let tau = optical_depth(&mut s, &ray, 40.0);
        // Brute force: tiny fixed steps over the whole ray, no tree skipping.
        let h = 0.005;
        let brute: f32 = (0..8000)
            .map(|i| s.trilinear(ray.at((i as f32 + 0.5) * h)).max(0.0) * h)
            .sum();
        assert!(
            (tau - brute).abs() <= 0.02 * brute.max(0.05),
            "{tau} vs {brute}"
        );
        hits += (tau > 0.0) as i32;
        let t = vol.transmittance(0, origin, dir, 40.0, 2.0);
        assert!((t - (-2.0 * tau).exp()).abs() < 1e-5);
    }
    assert!(hits > 4);
    let cam = Camera::framing((lo, hi), 40.0);
    let mut st = RenderSettings::new(&vol, 24, 24, RenderMode::DeltaTrack);
    st.spp = 4;
    let a = render::render(&vol, &cam, &st).unwrap();
    let b = render::render(&vol, &cam, &st).unwrap();
    assert_eq!(a, b);
    st.seed = 2;
    let c2 = render::render(&vol, &cam, &st).unwrap();
    assert_ne!(a, c2);
    assert!(a.pixels.iter().any(|&p| p > 0.0));
}

#[test]
fn the_largest_real_file_is_far_inside_the_reader_limits() {
    let Some(path) = data("smoke1.vdb") else {
        return;
    };
    let g = vdb::read_vdb_file(&path, None).unwrap();
    // The counts the limits' documentation (`vdb.rs`) quotes.
    assert_eq!((g.leaves.len(), g.tiles.len()), (3117, 0));
    assert!(g.leaves.len() * 64 < vdb::MAX_LEAVES);
    assert!(g.leaves.len() * 64 < vdb::MAX_CELLS);
}
