//! A placed volume as a medium for AO rays: the ratio-tracking estimate of the
//! transmittance-weighted length against closed forms, the placement, the box test, and
//! transmittance-weighted AO through `psao-trace`.

use glam::{IVec3, Quat, Vec3};
use psao_scene::{Mesh, Scene};
use psao_trace::ao::{ambient_occlusion_batch, ambient_occlusion_batch_in, Medium};
use psao_trace::{Backend, GeometryMode, Tracer};
use psao_volume::*;

/// A homogeneous medium of extinction `sigma` per metre: 4³ leaves of 0.1 m voxels
/// (constant where trilinear samples stay inside, a 3.1 m cube) centred on `centre`.
fn slab(sigma: f32, centre: Vec3, rotation: Quat) -> PlacedVolume {
    let grid = SparseGrid::constant_fog(IVec3::splat(4), 0.1, 0.25);
    let (vol, _) = Volume::build(&[grid], BrickFormat::F16, None).unwrap();
    let half = Vec3::splat(1.55);
    let placement = Placement {
        translation: centre - rotation * half,
        rotation,
        scale: Vec3::ONE,
    };
    PlacedVolume::new(vol, 0, placement, sigma).unwrap()
}

/// Mean and standard error of `n` independent estimates.
fn mean_and_error(values: &[f32]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().map(|&v| v as f64).sum::<f64>() / n;
    let var = values
        .iter()
        .map(|&v| (v as f64 - mean).powi(2))
        .sum::<f64>()
        / (n - 1.0);
    (mean, (var / n).sqrt())
}

#[test]
fn ratio_tracking_matches_the_closed_form_in_a_homogeneous_medium() {
    let sigma = 2.0;
    let rotation = Quat::from_euler(glam::EulerRot::XYZ, 0.3, -0.7, 0.2);
    let placed = slab(sigma, Vec3::new(5.0, 1.0, -2.0), rotation);
    let mut s = placed.sampler();
    for (length, dir) in [
        (0.6f32, Vec3::new(0.3, 0.9, -0.2).normalize()),
        (1.2, Vec3::new(-1.0, 0.1, 0.4).normalize()),
    ] {
        let origin = Vec3::new(5.0, 1.0, -2.0) - dir * 0.5 * length;
        let n = 4000;
        let values: Vec<f32> = (0..n)
            .map(|i| s.transmitted_length(origin, dir, length, i as u64 * 7919 + 13))
            .collect();
        assert!(values.iter().all(|&v| (0.0..=length).contains(&v)));
        let exact = (1.0 - (-sigma as f64 * length as f64).exp()) / sigma as f64;
        let (mean, err) = mean_and_error(&values);
        println!("L {length}: mean {mean:.5} ± {err:.5}, exact {exact:.5}");
        // Four standard errors of 4000 independent walks; the estimate must be informative.
        assert!(err < 0.01 * length as f64, "standard error {err}");
        assert!(
            (mean - exact).abs() < 4.0 * err,
            "{mean} vs {exact} ± {err}"
        );
    }
}

#[test]
fn rays_that_miss_the_bounds_return_exactly_their_length_and_streams_are_deterministic() {
    let placed = slab(3.0, Vec3::new(0.0, 10.0, 0.0), Quat::from_rotation_y(0.4));
    let (lo, hi) = placed.world_bounds();
    assert!(lo.y > 7.0 && hi.y < 13.0, "{lo} {hi}");
    let mut s = placed.sampler();
    // Ends short of the box, points away from it, or passes beside it.
    for (o, d, l) in [
        (Vec3::ZERO, Vec3::Y, 6.0f32),
        (Vec3::new(0.0, 5.0, 0.0), -Vec3::Y, 100.0),
        (Vec3::new(5.0, 0.0, 0.0), Vec3::Y, 100.0),
    ] {
        assert_eq!(s.transmitted_length(o, d, l, 1).to_bits(), l.to_bits());
    }
    let through = |s: &mut Box<dyn psao_trace::ao::MediumSampler + '_>, stream| {
        s.transmitted_length(Vec3::new(0.0, 9.5, 0.0), Vec3::X, 0.8, stream)
    };
    let a = through(&mut s, 42);
    assert_eq!(a.to_bits(), through(&mut placed.sampler(), 42).to_bits());
    assert!((0..8).any(|k| through(&mut s, k) != a));
    assert!(a < 0.8);
}

/// A 40 m floor at y = 0 (and a wall at x = 0 when `wall`).
fn floor_scene(wall: bool) -> Scene {
    let quad = |c: Vec3, u: Vec3, v: Vec3| Mesh {
        name: "q".into(),
        positions: vec![c - u - v, c + u - v, c + u + v, c - u + v],
        normals: vec![u.cross(v).normalize(); 4],
        indices: vec![[0, 1, 2], [0, 2, 3]],
        ..Default::default()
    };
    let mut meshes = vec![quad(Vec3::ZERO, Vec3::Z * 20.0, Vec3::X * 20.0)];
    if wall {
        meshes.push(quad(Vec3::ZERO, Vec3::Y * 20.0, Vec3::Z * 20.0));
    }
    Scene::of_meshes(meshes)
}

#[test]
fn ao_under_a_homogeneous_medium_matches_the_closed_form() {
    // On an open floor inside the medium every ray runs its full length R, so
    // AO = ∫₀ᴿ e^(−σs) ds / R = (1 − e^(−σR)) / (σR) whatever the direction.
    let (sigma, radius) = (2.0f32, 0.6f32);
    let placed = slab(sigma, Vec3::new(0.0, 0.5, 0.0), Quat::IDENTITY);
    let tracer = Tracer::new(Backend::Obvhs, &floor_scene(false), GeometryMode::Occlusion).unwrap();
    let points: Vec<(Vec3, Vec3)> = (0..256)
        .map(|i| {
            (
                Vec3::new(
                    (i % 16) as f32 * 0.05 - 0.4,
                    0.0,
                    (i / 16) as f32 * 0.05 - 0.4,
                ),
                Vec3::Y,
            )
        })
        .collect();
    let spp = 16;
    let ao = ambient_occlusion_batch_in(&tracer, Some(&placed), &points, radius, spp, 3, |k| {
        k as u64
    });
    let exact = (1.0 - (-(sigma * radius) as f64).exp()) / (sigma * radius) as f64;
    let (mean, err) = mean_and_error(&ao);
    println!("AO {mean:.5} ± {err:.5}, exact {exact:.5}");
    // 256 points × 16 rays; four standard errors of the per-point means.
    assert!(err < 0.01, "standard error {err}");
    assert!(
        (mean - exact).abs() < 4.0 * err,
        "{mean} vs {exact} ± {err}"
    );
    let again = ambient_occlusion_batch_in(&tracer, Some(&placed), &points, radius, spp, 3, |k| {
        k as u64
    });
    assert_eq!(ao, again, "deterministic");
}

#[test]
fn a_far_volume_changes_no_ao_bit() {
    let tracer = Tracer::new(Backend::Obvhs, &floor_scene(true), GeometryMode::Occlusion).unwrap();
    let points: Vec<(Vec3, Vec3)> = (0..64)
        .map(|i| (Vec3::new(0.02 + i as f32 * 0.02, 0.0, 0.3), Vec3::Y))
        .collect();
    let far = slab(5.0, Vec3::new(0.0, 0.0, 30.0), Quat::IDENTITY);
    let plain = ambient_occlusion_batch(&tracer, &points, 0.6, 32, 9, |k| k as u64);
    let with = ambient_occlusion_batch_in(&tracer, Some(&far), &points, 0.6, 32, 9, |k| k as u64);
    assert!(plain.iter().any(|&v| v < 0.9), "the wall occludes");
    assert_eq!(
        plain.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        with.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
    );
}

#[test]
fn placement_rejects_bad_values() {
    let grid = SparseGrid::constant_fog(IVec3::ONE, 0.1, 1.0);
    let (vol, _) = Volume::build(&[grid], BrickFormat::F32, None).unwrap();
    let ok = Placement::default();
    assert!(PlacedVolume::new(vol.clone(), 1, ok, 1.0).is_err());
    assert!(PlacedVolume::new(vol.clone(), 0, ok, -1.0).is_err());
    assert!(PlacedVolume::new(vol.clone(), 0, ok, f32::NAN).is_err());
    let flat = Placement {
        scale: Vec3::new(1.0, 0.0, 1.0),
        ..ok
    };
    assert!(PlacedVolume::new(vol.clone(), 0, flat, 1.0).is_err());
    let placed = PlacedVolume::new(
        vol,
        0,
        Placement {
            scale: Vec3::splat(2.0),
            ..ok
        },
        1.0,
    )
    .unwrap();
    let (lo, hi) = placed.world_bounds();
    assert!(
        (hi - lo - Vec3::splat(1.6)).abs().max_element() < 1e-5,
        "{lo} {hi}"
    );
}
