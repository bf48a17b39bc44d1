//! The default orbit of a scene without a camera path frames the scene's bounds.

use glam::{Vec3, Vec4Swizzles};
use psao_scene::orbit::{orbit_path, ORBIT_PERIOD_S};
use psao_scene::PATH_HZ;

/// Boxes of different sizes, shapes and places: a room, a flat ground plate, a tall tower,
/// a small object away from the origin.
const BOXES: [([f32; 3], [f32; 3]); 4] = [
    ([-10.0, 0.0, -6.0], [10.0, 8.0, 6.0]),
    ([-3.0, 0.0, -3.0], [3.0, 0.0, 3.0]),
    ([-0.5, -1.0, -0.5], [0.5, 30.0, 0.5]),
    ([100.0, 2.0, -40.0], [100.4, 2.3, -39.9]),
];

fn corners(lo: Vec3, hi: Vec3) -> impl Iterator<Item = Vec3> {
    (0..8).map(move |i| {
        Vec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        )
    })
}

#[test]
fn every_frame_of_the_orbit_sees_all_corners_of_the_bounds() {
    for (lo, hi) in BOXES {
        let (lo, hi) = (Vec3::from(lo), Vec3::from(hi));
        let path = orbit_path(lo, hi).unwrap();
        assert_eq!(path.duration(), ORBIT_PERIOD_S);
        assert_eq!(path.frame_count(), (ORBIT_PERIOD_S * PATH_HZ) as usize + 1);
        for frame in (0..path.frame_count()).step_by(7) {
            let cam = path.camera_at_frame(frame);
            for aspect in [1.0, 16.0 / 9.0, 2.5] {
                let clip_from_world = cam.projection(aspect) * cam.view();
                for c in corners(lo, hi) {
                    let clip = clip_from_world * c.extend(1.0);
                    let ndc = clip.xyz() / clip.w;
                    assert!(
                        clip.w > 0.0
                            && ndc.x.abs() <= 1.0
                            && ndc.y.abs() <= 1.0
                            && (0.0..=1.0).contains(&ndc.z),
                        "box {lo}..{hi}, frame {frame}, aspect {aspect}: corner {c} at {ndc}"
                    );
                }
            }
        }
    }
}

#[test]
fn the_orbit_circles_the_lower_half_from_above() {
    let (lo, hi) = (Vec3::new(-10.0, 0.0, -6.0), Vec3::new(10.0, 8.0, 6.0));
    let path = orbit_path(lo, hi).unwrap();
    let mid_height = 0.5 * (lo.y + hi.y);
    let first = path.camera_at_frame(0);
    let quarter = path.camera_at_frame(path.frame_count() / 4);
    for cam in [first, quarter] {
        assert!(
            cam.target.y > lo.y && cam.target.y < mid_height,
            "{}",
            cam.target
        );
        assert!(cam.position.y > cam.target.y, "{}", cam.position);
    }
    // A quarter of the period later the camera has turned by about 90° around the target.
    let a = (first.position - first.target).with_y(0.0).normalize();
    let b = (quarter.position - quarter.target).with_y(0.0).normalize();
    assert!(a.dot(b).abs() < 0.05, "{a} vs {b}");
    // It comes back to where it started.
    let last = path.camera_at_frame(path.frame_count() - 1);
    assert!(last.position.distance(first.position) < 1e-3 * first.position.length().max(1.0));
}

#[test]
fn the_orbit_is_deterministic_and_refuses_empty_bounds() {
    let (lo, hi) = (Vec3::new(-1.0, 0.0, -2.0), Vec3::new(3.0, 1.5, 2.0));
    assert_eq!(orbit_path(lo, hi), orbit_path(lo, hi));
    assert!(orbit_path(Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)).is_none());
    assert!(orbit_path(Vec3::ZERO, Vec3::new(f32::NAN, 1.0, 1.0)).is_none());
}
