//! Client reconstruction: exactness on constant AO, empty grids, back faces, the distance
//! heuristic, and speed.

mod common;

use std::time::Instant;

use glam::{Affine3A, Vec3};
use psao_points::pack::dequantize_ao;
use psao_points::pack::quantize_ao;
use psao_points::{
    generate_instance_points, reconstruct_ao, GenerateParams, GridLayout, InstanceGrid,
    InstancePoints, ReconstructParams,
};
use psao_scene::{Material, Mesh};

fn gen(mesh: &Mesh, material: &Material, seed: u64) -> InstancePoints {
    generate_instance_points(
        mesh,
        material,
        &Affine3A::IDENTITY,
        &GenerateParams {
            density: 1024.0,
            seed,
        },
        None,
    )
    .unwrap()
}

fn q(ao: f32) -> f32 {
    dequantize_ao(quantize_ao(ao))
}

/// Query positions on the plane z = `z` over [margin, 2 − margin]², on a fine lattice.
fn queries(margin: f32, z: f32) -> impl Iterator<Item = Vec3> {
    let steps = 60;
    (0..steps * steps).map(move |k| {
        let (i, j) = (k % steps, k / steps);
        let t = |v: u32| margin + (2.0 - 2.0 * margin) * (v as f32 + 0.37) / steps as f32;
        Vec3::new(t(i), t(j), z)
    })
}

#[test]
fn constant_ao_plane_is_exact() {
    let pts = gen(&common::plane(2.0, 8, 0.0), &Material::default(), 1);
    let (grid, _) = InstanceGrid::from_points(&pts, 0.37).unwrap();
    let params = ReconstructParams::default();
    let margin = params.interpolation_factor * grid.layout().poisson_radius;
    for p in queries(margin, 0.0) {
        let ao = reconstruct_ao(&grid, p, Vec3::Z, &params);
        assert!(
            (ao - q(0.37)).abs() < 1e-6,
            "{p}: {ao} (1.0 = no point within r)"
        );
    }
}

#[test]
fn no_points_gives_one() {
    let pts = gen(&common::plane(2.0, 8, 0.0), &Material::default(), 1);
    let layout = GridLayout::for_points(&pts).unwrap();
    let empty = InstanceGrid::new(layout);
    let params = ReconstructParams::default();
    assert_eq!(
        reconstruct_ao(&empty, Vec3::new(1.0, 1.0, 0.0), Vec3::Z, &params),
        1.0
    );
    let (grid, _) = InstanceGrid::from_points(&pts, 0.2).unwrap();
    for far in [
        Vec3::new(1.0, 1.0, 0.5),
        Vec3::splat(-10.0),
        Vec3::splat(f32::MAX),
        Vec3::NAN,
    ] {
        assert_eq!(reconstruct_ao(&grid, far, Vec3::Z, &params), 1.0, "{far}");
    }
    let zero = ReconstructParams {
        interpolation_factor: 0.0,
        ..params
    };
    assert_eq!(
        reconstruct_ao(&grid, Vec3::new(1.0, 1.0, 0.0), Vec3::Z, &zero),
        1.0
    );
}

#[test]
fn back_facing_points_are_ignored() {
    // Double-sided plane: front AO 0.2, back AO 0.9, same positions.
    let material = Material {
        double_sided: true,
        ..Material::default()
    };
    let pts = gen(&common::plane(2.0, 8, 0.0), &material, 2);
    let layout = GridLayout::for_points(&pts).unwrap();
    let (grid, _) = InstanceGrid::build(
        layout,
        pts.points
            .iter()
            .map(|p| (p.position, p.normal, if p.back_face { 0.9 } else { 0.2 })),
    );
    println!(
        "double-sided: {} points, overflow {} points",
        pts.points.len(),
        grid.overflow_points()
    );
    let params = ReconstructParams::default();
    let margin = params.interpolation_factor * layout.poisson_radius;
    // Each side sees only its own points. Double-sided cells hold both sides, so a few more
    // points overflow and rare holes (AO 1) may appear; they must stay rare.
    let mut holes = 0;
    for p in queries(margin, 0.0) {
        for (n, want) in [(Vec3::Z, q(0.2)), (Vec3::NEG_Z, q(0.9))] {
            let ao = reconstruct_ao(&grid, p, n, &params);
            if ao == 1.0 {
                holes += 1;
            } else {
                assert!((ao - want).abs() < 1e-6, "{p} {n}: {ao}");
            }
        }
    }
    println!("double-sided holes: {holes} of 7200 queries");
    assert!(holes <= 4, "{holes}");
}

#[test]
fn points_in_front_of_the_surface_are_ignored() {
    // Two parallel planes facing +Z, h apart with h < r: from the lower plane every point of
    // the upper one within r lies almost straight above, (n·d/|d|)² ≥ h²/r² ≥ T_d.
    let params = ReconstructParams::default();
    let lower = gen(&common::plane(2.0, 8, 0.0), &Material::default(), 3);
    let r = params.interpolation_factor * lower.poisson_radius_local;
    let h = 0.88 * r;
    assert!(h * h / (r * r) >= params.direction_threshold);
    let upper = gen(&common::plane(2.0, 8, h), &Material::default(), 4);
    let layout = GridLayout::new(
        (Vec3::ZERO, Vec3::new(2.0, 2.0, h)),
        lower.poisson_radius_local,
        4.0 * lower.poisson_radius_local,
        8.0,
    )
    .unwrap();
    let input = lower
        .points
        .iter()
        .map(|p| (p.position, p.normal, 0.2))
        .chain(upper.points.iter().map(|p| (p.position, p.normal, 0.9)));
    let (grid, _) = InstanceGrid::build(layout, input);
    for p in queries(r, 0.0) {
        assert!(
            (reconstruct_ao(&grid, p, Vec3::Z, &params) - q(0.2)).abs() < 1e-6,
            "{p}"
        );
    }
    // Without the heuristic (and the plane test, which also rejects these points) the upper
    // plane leaks in.
    let leaky = ReconstructParams {
        direction_threshold: 1.1,
        plane_tolerance: f32::INFINITY,
        ..params
    };
    let mean: f32 = queries(r, 0.0)
        .map(|p| reconstruct_ao(&grid, p, Vec3::Z, &leaky))
        .sum::<f32>()
        / 3600.0;
    assert!(mean > q(0.2) + 0.01, "{mean}");
}

#[test]
fn points_off_the_tangent_plane_are_ignored() {
    // A parallel plane just above the tolerance: most of its points within r lie sideways
    // enough to pass the direction test, only the plane test keeps them out.
    let params = ReconstructParams::default();
    let lower = gen(&common::plane(2.0, 8, 0.0), &Material::default(), 5);
    let r_max = lower.poisson_radius_local;
    let h = 0.6 * r_max;
    assert!(h > params.plane_tolerance * r_max);
    let upper = gen(&common::plane(2.0, 8, h), &Material::default(), 6);
    let layout = GridLayout::new(
        (Vec3::ZERO, Vec3::new(2.0, 2.0, h)),
        r_max,
        4.0 * r_max,
        8.0,
    )
    .unwrap();
    let input = lower
        .points
        .iter()
        .map(|p| (p.position, p.normal, 0.2))
        .chain(upper.points.iter().map(|p| (p.position, p.normal, 0.9)));
    let (grid, _) = InstanceGrid::build(layout, input);
    let r = params.interpolation_factor * r_max;
    for p in queries(r, 0.0) {
        let ao = reconstruct_ao(&grid, p, Vec3::Z, &params);
        assert!((ao - q(0.2)).abs() < 1e-6, "{p}: {ao}");
    }
    let leaky = ReconstructParams {
        plane_tolerance: f32::INFINITY,
        ..params
    };
    let mean: f32 = queries(r, 0.0)
        .map(|p| reconstruct_ao(&grid, p, Vec3::Z, &leaky))
        .sum::<f32>()
        / 3600.0;
    assert!(mean > q(0.2) + 0.05, "{mean}");
}

/// A grid holding exactly `points` (local position, normal, AO), Poisson radius 0.01.
fn tiny_grid(points: &[(Vec3, Vec3, f32)]) -> InstanceGrid {
    let layout = GridLayout::new((Vec3::ZERO, Vec3::splat(0.2)), 0.01, 0.04, 8.0).unwrap();
    let (grid, locs) = InstanceGrid::build(layout, points.iter().copied());
    assert!(locs.iter().all(Option::is_some));
    grid
}

#[test]
fn points_with_the_pixels_normal_weigh_more() {
    // Two points at the same distance, in the tangent plane: one with the pixel's normal,
    // one tilted by 60° (cosine 0.5, passes T_n): (n·n_i)^8 makes the tilted one count ~1/256
    // in the weighted mean (the planar fit would tilt through two points).
    let params = ReconstructParams {
        linear_ridge: None,
        ..ReconstructParams::default()
    };
    let p = Vec3::new(0.1, 0.1, 0.1);
    let tilted = Vec3::new(0.75f32.sqrt(), 0.0, 0.5);
    let grid = tiny_grid(&[
        (p + Vec3::new(0.01, 0.0, 0.0), Vec3::Z, 0.2),
        (p + Vec3::new(0.0, 0.01, 0.0), tilted, 0.9),
    ]);
    let ao = reconstruct_ao(&grid, p, Vec3::Z, &params);
    // The tilted normal's 8-bit octahedral code has a cosine within 0.5..0.65 of +z.
    let most = (q(0.9) - q(0.2)) * 0.65f32.powi(8);
    assert!(ao > q(0.2) && ao < q(0.2) + most, "{ao}");
    let plain = ReconstructParams {
        normal_exponent: 0,
        ..params
    };
    let ao = reconstruct_ao(&grid, p, Vec3::Z, &plain);
    assert!((ao - 0.5 * (q(0.2) + q(0.9))).abs() < 0.01, "{ao}");
}

#[test]
fn holes_take_the_nearest_compatible_point() {
    let params = ReconstructParams::default();
    let r = params.interpolation_factor * 0.01;
    // p at 3/4 of cell (2, 2, 2): the visited block spans cells 2..=3 along every axis.
    let p = Vec3::splat(0.11);
    let near = (p + Vec3::new(1.2 * r, 0.0, 0.0), Vec3::Z, 0.3);
    let nearer_but_facing_away = (p + Vec3::new(0.0, 1.1 * r, 0.0), -Vec3::Z, 0.7);
    let farther = (p + Vec3::new(0.0, 1.4 * r, 0.0), Vec3::Z, 0.9);
    let grid = tiny_grid(&[near, nearer_but_facing_away, farther]);
    let ao = reconstruct_ao(&grid, p, Vec3::Z, &params);
    assert!((ao - q(0.3)).abs() < 1e-6, "{ao}");
    let design = ReconstructParams {
        nearest_fallback: false,
        ..params
    };
    assert_eq!(reconstruct_ao(&grid, p, Vec3::Z, &design), 1.0);
    // Nothing compatible at all: still 1.
    let grid = tiny_grid(&[nearer_but_facing_away]);
    assert_eq!(reconstruct_ao(&grid, p, Vec3::Z, &params), 1.0);
    // Nothing compatible in the visited block (cells 2..=3): the nearest compatible point of
    // the ring of cells around it, here in cell 1 along x (and not a farther one in cell 4).
    let ring = (p - Vec3::new(0.06, 0.0, 0.0), Vec3::Z, 0.4);
    let ring_far = (p + Vec3::new(0.0, 0.065, 0.0), Vec3::Z, 0.8);
    let grid = tiny_grid(&[nearer_but_facing_away, ring, ring_far]);
    let ao = reconstruct_ao(&grid, p, Vec3::Z, &params);
    assert!((ao - q(0.4)).abs() < 1e-6, "{ao}");
    assert_eq!(reconstruct_ao(&grid, p, Vec3::Z, &design), 1.0);
}

#[test]
fn reconstruction_speed() {
    let pts = gen(&common::plane(2.0, 8, 0.0), &Material::default(), 5);
    let (grid, _) = InstanceGrid::from_points(&pts, 0.5).unwrap();
    let params = ReconstructParams::default();
    let qs: Vec<Vec3> = queries(0.0, 0.0).collect();
    let t = Instant::now();
    let mut sum = 0.0;
    for _ in 0..100 {
        for p in &qs {
            sum += reconstruct_ao(&grid, *p, Vec3::Z, &params);
        }
    }
    let per = t.elapsed().as_secs_f64() / (100.0 * qs.len() as f64);
    println!(
        "reconstruct_ao: {:.0} ns per call (checksum {sum:.1})",
        per * 1e9
    );
    assert!(sum > 0.0);
}
