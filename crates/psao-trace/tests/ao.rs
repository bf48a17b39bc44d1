//! Ambient occlusion against known answers, and its determinism.

mod common;

use common::{instance, quad, scene, uniform};
use glam::{Affine3A, Vec3};
use psao_scene::Scene;
use psao_trace::ao::{ambient_occlusion, ambient_occlusion_batch, ao_rays, ao_value};
use psao_trace::{Backend, GeometryMode, Hit, Tracer};

const R: f32 = 0.6;

/// A floor (y = 0, x ≥ 0) meeting a wall (x = 0, y ≥ 0), both 200 units wide.
fn corner() -> Scene {
    let half = 100.0;
    scene(
        vec![
            quad(Vec3::new(half, 0.0, 0.0), Vec3::Z, Vec3::X, half),
            quad(Vec3::new(0.0, half, 0.0), Vec3::Y, Vec3::Z, half),
        ],
        vec![
            instance(0, Affine3A::IDENTITY),
            instance(1, Affine3A::IDENTITY),
        ],
    )
}

/// Independent numerical AO on the floor at distance `d` from the wall: midpoint rule over
/// the cosine-warped unit square, where a direction ω reaches the wall at t = d / (−ω.x).
fn corner_reference(d: f32) -> f32 {
    let n = 1000;
    let mut sum = 0.0f64;
    for i in 0..n {
        for j in 0..n {
            let u1 = (i as f64 + 0.5) / n as f64;
            let phi = std::f64::consts::TAU * (j as f64 + 0.5) / n as f64;
            let wx = u1.sqrt() * phi.cos();
            let t = if wx < 0.0 {
                d as f64 / -wx
            } else {
                f64::INFINITY
            };
            sum += (t / R as f64).min(1.0);
        }
    }
    (sum / (n * n) as f64) as f32
}

#[test]
fn open_plane_is_unoccluded() {
    let s = scene(
        vec![quad(Vec3::ZERO, Vec3::Z, Vec3::X, 1000.0)],
        vec![instance(0, Affine3A::IDENTITY)],
    );
    for backend in Backend::compiled() {
        let t = Tracer::new(backend, &s, GeometryMode::Occlusion).unwrap();
        for x in [
            Vec3::ZERO,
            Vec3::new(100.0, 0.0, -37.0),
            Vec3::new(-512.3, 0.0, 700.1),
        ] {
            let ao = ambient_occlusion(&t, x, Vec3::Y, R, 256, 1, 0);
            assert_eq!(ao, 1.0, "{backend} at {x}");
        }
        // Below the plane looking up, everything is blocked at distance ~0.
        let ao = ambient_occlusion(&t, Vec3::new(0.0, -0.01, 0.0), Vec3::Y, R, 64, 1, 0);
        assert!(ao < 0.05, "{backend}: {ao}");
    }
}

#[test]
fn inner_corner_matches_numerical_integration() {
    let s = corner();
    for backend in Backend::compiled() {
        let t = Tracer::new(backend, &s, GeometryMode::Occlusion).unwrap();
        for d in [0.02, 0.1, 0.3] {
            let expected = corner_reference(d);
            // Average a few points along the edge so each uses a different rotation.
            let ao: f32 = (0..8)
                .map(|k| {
                    let x = Vec3::new(d, 0.0, -3.0 + k as f32);
                    ambient_occlusion(&t, x, Vec3::Y, R, 1024, 5, k)
                })
                .sum::<f32>()
                / 8.0;
            assert!(
                (ao - expected).abs() < 0.01,
                "{backend} d={d}: {ao} vs {expected}"
            );
            // The same by symmetry on the wall.
            let on_wall = ambient_occlusion(&t, Vec3::new(0.0, d, 1.0), Vec3::X, R, 4096, 5, 9);
            assert!(
                (on_wall - expected).abs() < 0.01,
                "{backend} wall d={d}: {on_wall}"
            );
        }
        assert!(
            corner_reference(0.02) < 0.75,
            "the reference is far from trivial"
        );
        let far = ambient_occlusion(&t, Vec3::new(0.7, 0.0, 0.0), Vec3::Y, R, 256, 5, 0);
        assert_eq!(far, 1.0, "beyond R from the wall nothing occludes");
    }
}

#[test]
fn ao_value_definition() {
    let hit = |t| {
        Some(Hit {
            t,
            instance: 0,
            triangle: 0,
            u: 0.0,
            v: 0.0,
        })
    };
    assert_eq!(ao_value(&[None, hit(0.3), hit(5.0), hit(0.0)], 0.6), 0.625);
    assert_eq!(ao_value(&[], 0.6), 1.0);
    assert_eq!(ao_value(&[hit(0.1)], 0.0), 1.0);
    let mut rays = Vec::new();
    ao_rays(Vec3::ONE, Vec3::Y, 0.6, 16, 3, 4, &mut rays);
    assert_eq!(rays.len(), 16);
    for r in &rays {
        assert!(r.origin.y > 1.0 && r.dir.y >= 0.0 && r.tmax == 0.6);
        assert!((r.dir.length() - 1.0).abs() < 1e-5);
    }
}

/// A closed box room with a pillar: points on its floor and walls.
fn room_points(count: usize) -> (Scene, Vec<(Vec3, Vec3)>) {
    let s = scene(
        vec![common::unit_cube()],
        vec![
            instance(0, Affine3A::from_scale(Vec3::splat(-4.0))),
            instance(0, Affine3A::from_scale(Vec3::new(0.5, 4.0, 0.5))),
        ],
    );
    let points = (0..count as u64)
        .map(|i| {
            let (a, b) = (
                uniform(1, 2 * i) * 4.0 - 2.0,
                uniform(1, 2 * i + 1) * 4.0 - 2.0,
            );
            if i % 2 == 0 {
                (Vec3::new(a, -2.0, b), Vec3::Y)
            } else {
                (Vec3::new(2.0, a, b), -Vec3::X)
            }
        })
        .collect();
    (s, points)
}

#[test]
fn deterministic_per_point_batch_and_thread_count() {
    let (s, points) = room_points(300);
    let spp = 32;
    let keys = |i: usize| 1000 + i as u64;
    for backend in Backend::compiled() {
        let t = Tracer::new(backend, &s, GeometryMode::Occlusion).unwrap();
        let single: Vec<f32> = points
            .iter()
            .enumerate()
            .map(|(i, &(x, n))| ambient_occlusion(&t, x, n, R, spp, 77, keys(i)))
            .collect();
        assert!(single.iter().any(|&a| a < 0.9), "the room occludes");
        let again = ambient_occlusion(&t, points[0].0, points[0].1, R, spp, 77, keys(0));
        assert_eq!(again, single[0], "same seed, same AO");
        let other_seed: Vec<f32> = points
            .iter()
            .enumerate()
            .map(|(i, &(x, n))| ambient_occlusion(&t, x, n, R, spp, 78, keys(i)))
            .collect();
        assert_ne!(other_seed, single, "the seed matters");

        let mut per_threads = Vec::new();
        for threads in [1, 2, 3] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            per_threads
                .push(pool.install(|| ambient_occlusion_batch(&t, &points, R, spp, 77, keys)));
        }
        assert_eq!(
            per_threads[0], per_threads[1],
            "{backend}: independent of threads"
        );
        assert_eq!(
            per_threads[0], per_threads[2],
            "{backend}: independent of threads"
        );
        // Batched rays are traced in another order (and other packets) than per point.
        for (b, s) in per_threads[0].iter().zip(&single) {
            assert!((b - s).abs() < 1e-5, "{backend}: batch {b} vs single {s}");
        }
        let big_spp = ambient_occlusion_batch(&t, &points[..3], R, 5000, 77, keys);
        assert_eq!(big_spp.len(), 3);
        assert!(ambient_occlusion_batch(&t, &points, R, 0, 77, keys)
            .iter()
            .all(|&a| a == 1.0));
    }
}
