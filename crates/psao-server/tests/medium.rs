//! The server's AO through a participating medium agrees with the reference estimator, and
//! the medium darkens the points inside it.

mod common;

use std::sync::Arc;

use common::*;
use glam::{IVec3, Quat, Vec3};
use psao_server::Server;
use psao_trace::ao::{ambient_occlusion_batch_in, Medium};
use psao_volume::{BrickFormat, PlacedVolume, Placement, SparseGrid, Volume};

/// A homogeneous medium (extinction 3 per metre) over the floor's x < 0 half, 1.2 m high.
fn medium() -> Arc<PlacedVolume> {
    let grid = SparseGrid::constant_fog(IVec3::new(4, 2, 8), 0.075, 1.0);
    let (vol, _) = Volume::build(&[grid], BrickFormat::F16, None).unwrap();
    let placement = Placement {
        translation: Vec3::new(-2.3, -0.1, -2.3),
        rotation: Quat::IDENTITY,
        scale: Vec3::ONE,
    };
    Arc::new(PlacedVolume::new(vol, 0, placement, 3.0).unwrap())
}

#[test]
fn server_ao_through_a_medium_matches_the_reference() {
    let medium = medium();
    let mut server =
        Server::with_medium(&scene(), config(), Some(medium.clone() as Arc<dyn Medium>)).unwrap();
    let mut plain = Server::new(&scene(), config()).unwrap();
    converge(&mut server, &[wide_view()], 64);
    converge(&mut plain, &[wide_view()], 64);
    let radius = server.ao_radius();
    let (lo, hi) = medium.world_bounds();
    let t = server.transforms()[0].1;
    // Floor points (instance 0): server estimate vs a 1024-spp reference through the medium.
    let pts: Vec<_> = server
        .points(0)
        .zip(plain.points(0))
        .filter_map(|(p, q)| Some((t.transform_point3(p.position), p.ao?, q.ao?)))
        .collect();
    let points: Vec<(Vec3, Vec3)> = pts.iter().map(|p| (p.0, Vec3::Y)).collect();
    let reference = ambient_occlusion_batch_in(
        server.tracer(),
        Some(medium.as_ref()),
        &points,
        radius,
        1024,
        99,
        |k| k as u64,
    );
    let (mut inside, mut err, mut darker) = (0usize, 0.0f32, 0.0f32);
    for ((x, with, without), r) in pts.iter().zip(&reference) {
        err += (with - r).abs();
        let deep = x.x > lo.x + 0.7 && x.x < hi.x - 0.7 && x.z.abs() < 1.5;
        if deep {
            inside += 1;
            darker += without - with;
        }
        if x.x > hi.x + radius {
            assert_eq!(with, without, "outside the medium's reach nothing changes");
        }
    }
    let mean = err / pts.len() as f32;
    let darker = darker / inside.max(1) as f32;
    println!("{} points, mean |server − reference| {mean:.4}; {inside} deep inside, darker by {darker:.3}", pts.len());
    assert!(pts.len() > 500 && inside > 50, "{} {inside}", pts.len());
    // 256 samples per point against 1024: both carry ratio-tracking noise.
    assert!(mean < 0.02, "mean error {mean}");
    // Open floor inside: AO drops from ~1 to (1 − e^(−1.8)) / 1.8 ≈ 0.46.
    assert!(darker > 0.3, "{darker}");
}
