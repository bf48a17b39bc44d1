//! Dynamic geometry: refit quality tracking, rebuilds and the per-frame deforming update.

mod common;

use common::{assert_hit_t, instance, mesh, scene};
use glam::{Affine3A, Vec3};
use psao_trace::{Backend, GeometryMode, Ray, TraceError, Tracer};

/// A strip of `n` unit quads along x in the plane z = 0 (two triangles each).
fn strip(n: usize) -> psao_scene::Mesh {
    let mut positions = Vec::new();
    let mut indices = Vec::new();
    for i in 0..n {
        let b = positions.len() as u32;
        let x = i as f32;
        positions.extend([
            Vec3::new(x, 0.0, 0.0),
            Vec3::new(x + 1.0, 0.0, 0.0),
            Vec3::new(x + 1.0, 1.0, 0.0),
            Vec3::new(x, 1.0, 0.0),
        ]);
        indices.extend([[b, b + 1, b + 2], [b, b + 2, b + 3]]);
    }
    mesh(positions, indices, 0)
}

/// The strip with its quads rearranged: quad i moves to slot (i · 37) mod n, so every
/// subtree of the original BVH now spans the whole strip.
fn scrambled(m: &psao_scene::Mesh, n: usize) -> Vec<Vec3> {
    m.positions
        .iter()
        .enumerate()
        .map(|(v, p)| {
            let quad = v / 4;
            let slot = (quad * 37) % n;
            Vec3::new(p.x - quad as f32 + slot as f32, p.y, p.z)
        })
        .collect()
}

fn hit_t(t: &Tracer, x: f32) -> Option<f32> {
    let mut out = [None];
    t.intersect(
        &[Ray::new(Vec3::new(x, 0.5, 3.0), -Vec3::Z, 10.0)],
        &mut out,
    );
    out[0].map(|h| h.t)
}

#[test]
fn refit_cost_grows_and_rebuild_restores_it() {
    let n = 512;
    let m = strip(n);
    let s = scene(vec![m.clone()], vec![instance(0, Affine3A::IDENTITY)]);
    let mut t = Tracer::new(Backend::Obvhs, &s, GeometryMode::Occlusion).unwrap();
    assert_eq!(t.mesh_cost_ratio(0), None, "static until updated");
    // Moving every vertex rigidly keeps the ratio at 1.
    let lifted: Vec<Vec3> = m.positions.iter().map(|p| *p + Vec3::Y).collect();
    t.update_mesh_positions(0, &lifted).unwrap();
    t.update_mesh_positions(0, &m.positions).unwrap();
    let same = t.mesh_cost_ratio(0).unwrap();
    assert!((same - 1.0).abs() < 1e-3, "{same}");
    // Scrambling the quads makes refitted boxes overlap: the cost explodes.
    let mixed = scrambled(&m, n);
    t.update_mesh_positions(0, &mixed).unwrap();
    t.commit();
    let bad = t.mesh_cost_ratio(0).unwrap();
    assert!(bad > 5.0, "{bad}");
    assert_hit_t(hit_t(&t, 100.5), Some(3.0), "refit is still correct");
    t.rebuild_mesh_positions(0, &mixed).unwrap();
    t.commit();
    assert!((t.mesh_cost_ratio(0).unwrap() - 1.0).abs() < 1e-6);
    assert_hit_t(hit_t(&t, 100.5), Some(3.0), "rebuilt");
    assert_hit_t(hit_t(&t, 600.0), None, "beyond the strip");
}

#[test]
fn deforming_update_rebuilds_past_the_threshold() {
    let n = 256;
    let mut m = strip(n);
    // Skinned meshes are built ready for refits (the first update already refits).
    m.joints = vec![[0; 4]; m.positions.len()];
    m.weights = vec![[1.0, 0.0, 0.0, 0.0]; m.positions.len()];
    let s = scene(vec![m.clone()], vec![instance(0, Affine3A::IDENTITY)]);
    let mixed = scrambled(&m, n);
    for backend in Backend::compiled() {
        let mut t = Tracer::new(backend, &s, GeometryMode::Occlusion).unwrap();
        let first = t.update_deforming_mesh(0, &mixed, 1.3).unwrap();
        assert!(!first.rebuilt, "{backend}: nothing to compare yet: refit");
        let second = t.update_deforming_mesh(0, &m.positions, 1.3).unwrap();
        t.commit();
        assert_hit_t(hit_t(&t, 10.5), Some(3.0), &format!("{backend}"));
        if backend == Backend::Obvhs {
            assert!(first.cost_ratio.unwrap() > 1.3);
            assert!(second.rebuilt);
            assert!((second.cost_ratio.unwrap() - 1.0).abs() < 1e-6);
            // Below the threshold it keeps refitting.
            let third = t.update_deforming_mesh(0, &m.positions, 1.3).unwrap();
            assert!(!third.rebuilt);
        } else {
            assert_eq!(second.cost_ratio, None);
        }
        // A rebuild checks its input like an update.
        t.rebuild_mesh_positions(0, &mixed).unwrap();
        t.commit();
        assert_hit_t(hit_t(&t, 37.5), Some(3.0), &format!("{backend}"));
        assert!(matches!(
            t.rebuild_mesh_positions(0, &[Vec3::ZERO]),
            Err(TraceError::PositionCount { .. })
        ));
        assert!(matches!(
            t.update_deforming_mesh(3, &[], 1.3),
            Err(TraceError::NoSuchMesh { .. })
        ));
    }
}
