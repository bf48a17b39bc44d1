//! Coverage, fill rule, clipping, interpolation and robustness of the rasterizer.

mod common;

use common::{intersect, pixel_ray, scene_of, unproject};
use glam::{Affine3A, Vec2, Vec3};
use psao_raster::{
    rasterize, rasterize_posed, GBuffer, InstancePose, PoseError, RasterOptions, Rasterizer,
};
use psao_scene::Camera;

const W: u32 = 64;
const H: u32 = 48;

fn camera() -> Camera {
    Camera::look_at(Vec3::new(0.3, -0.2, 1.0), Vec3::new(0.5, 0.1, -2.0), 60.0)
}

fn opts() -> RasterOptions {
    RasterOptions::new(W, H)
}

/// A triangle whose vertices appear at the given pixel coordinates and view depths.
fn screen_tri(cam: &Camera, pts: [(f64, f64, f64); 3]) -> [Vec3; 3] {
    pts.map(|(x, y, z)| unproject(cam, x, y, z, W, H))
}

/// Twice the signed area test of point p against edge a→b, in f64.
fn edge(a: (f64, f64), b: (f64, f64), p: (f64, f64)) -> f64 {
    (b.0 - a.0) * (p.1 - a.1) - (b.1 - a.1) * (p.0 - a.0)
}

#[test]
fn single_triangle_covers_exactly_the_pixel_centres_inside() {
    let cam = camera();
    let v = [(3.2, 2.7), (50.9, 8.1), (12.3, 40.6)];
    let tri = screen_tri(
        &cam,
        [
            (v[0].0, v[0].1, 4.0),
            (v[1].0, v[1].1, 7.0),
            (v[2].0, v[2].1, 5.5),
        ],
    );
    let g = rasterize(&scene_of(&[tri]), &cam, &opts());
    let mut inside = 0;
    for y in 0..H {
        for x in 0..W {
            let p = (x as f64 + 0.5, y as f64 + 0.5);
            let e = [
                edge(v[0], v[1], p),
                edge(v[1], v[2], p),
                edge(v[2], v[0], p),
            ];
            let expect = e.iter().all(|&e| e > 0.0) || e.iter().all(|&e| e < 0.0);
            assert!(
                e.iter().all(|e| e.abs() > 1e-2),
                "test triangle passes a pixel centre"
            );
            assert_eq!(g.covered(g.index(x, y)), expect, "pixel {x},{y}");
            inside += usize::from(expect);
        }
    }
    assert_eq!(g.covered_count(), inside);
    let scene = scene_of(&[tri]);
    for i in [g.index(20, 10), g.index(63, 47)] {
        assert_eq!(g.material(&scene, i), g.covered(i).then_some(0));
    }
    assert!(g.covered(g.index(20, 10)) && !g.covered(g.index(63, 47)));
    assert!(inside > 500, "{inside}");
    assert!(g.triangle.iter().all(|&t| t == 0 || t == GBuffer::NONE));
}

#[test]
fn top_left_rule_owns_pixel_centres_on_top_and_left_edges() {
    let cam = camera();
    // A square whose edges pass exactly through pixel centres of columns/rows 8 and 16.
    let (a, b) = (8.5, 16.5);
    let quad = [
        screen_tri(&cam, [(a, a, 4.0), (a, b, 4.0), (b, b, 4.0)]),
        screen_tri(&cam, [(a, a, 4.0), (b, b, 4.0), (b, a, 4.0)]),
    ];
    let g = rasterize(&scene_of(&quad), &cam, &opts());
    for y in 0..H {
        for x in 0..W {
            let inside = (8..16).contains(&x) && (8..16).contains(&y);
            assert_eq!(g.covered(g.index(x, y)), inside, "pixel {x},{y}");
        }
    }
}

/// Rasterizes each triangle alone and counts how often each pixel is covered.
fn coverage_counts(cam: &Camera, tris: &[[Vec3; 3]]) -> Vec<u32> {
    let mut count = vec![0u32; (W * H) as usize];
    for t in tris {
        let g = rasterize(&scene_of(&[*t]), cam, &opts());
        for (c, &i) in count.iter_mut().zip(&g.instance) {
            *c += u32::from(i != GBuffer::NONE);
        }
    }
    count
}

/// View depth of a tilted plane at pixel (x, y).
fn plane_depth(x: f64, y: f64) -> f64 {
    3.0 + 0.04 * x + 0.02 * y
}

#[test]
fn grid_of_triangles_covers_every_pixel_exactly_once() {
    let cam = camera();
    // Grid lines at integers, pixel centres (x.5) and arbitrary fractions, so that many edges
    // (horizontal, vertical and diagonal) pass exactly through pixel centres.
    let xs = [0.0, 7.5, 16.0, 23.5, 31.25, 40.5, 48.0, 55.5, 64.0];
    let ys = [0.0, 8.5, 16.0, 24.5, 31.7, 40.0, 48.0];
    let p = |i: usize, j: usize| {
        let (x, y) = (xs[i], ys[j]);
        unproject(&cam, x, y, plane_depth(x, y), W, H)
    };
    let mut tris = Vec::new();
    for j in 0..ys.len() - 1 {
        for i in 0..xs.len() - 1 {
            let (a, b, c, d) = (p(i, j), p(i + 1, j), p(i + 1, j + 1), p(i, j + 1));
            // Alternate the split diagonal and the winding.
            if (i + j) % 2 == 0 {
                tris.push([a, b, c]);
                tris.push([a, d, c]);
            } else {
                tris.push([a, b, d]);
                tris.push([b, c, d]);
            }
        }
    }
    let count = coverage_counts(&cam, &tris);
    let bad: Vec<usize> = (0..count.len()).filter(|&i| count[i] != 1).collect();
    assert!(
        bad.is_empty(),
        "{} pixels not covered exactly once: {:?}",
        bad.len(),
        &bad[..bad.len().min(10)]
    );
}

#[test]
fn fan_of_triangles_covers_every_pixel_exactly_once() {
    let cam = camera();
    // Centre exactly on a pixel centre; rim points on the image border.
    let centre = (31.5, 23.5);
    let mut rim = Vec::new();
    for k in 0..8 {
        rim.push((k as f64 * 8.0, 0.0));
    }
    for k in 0..6 {
        rim.push((64.0, k as f64 * 8.0));
    }
    for k in 0..8 {
        rim.push((64.0 - k as f64 * 8.0, 48.0));
    }
    for k in 0..6 {
        rim.push((0.0, 48.0 - k as f64 * 8.0));
    }
    let at = |(x, y): (f64, f64)| unproject(&cam, x, y, plane_depth(x, y), W, H);
    let tris: Vec<[Vec3; 3]> = (0..rim.len())
        .map(|k| [at(centre), at(rim[k]), at(rim[(k + 1) % rim.len()])])
        .collect();
    let count = coverage_counts(&cam, &tris);
    assert!(count.iter().all(|&c| c == 1), "{count:?}");

    // The same fan in one scene: every pixel covered, each by a valid triangle.
    let g = rasterize(&scene_of(&tris), &cam, &opts());
    assert_eq!(g.covered_count(), (W * H) as usize);
}

#[test]
fn near_plane_clipping_keeps_the_visible_part() {
    // A floor triangle with two vertices behind the camera and one far ahead.
    let cam = Camera::look_at(Vec3::new(0.0, 1.0, 0.0), Vec3::new(0.0, 0.8, -1.0), 70.0);
    let tri = [
        Vec3::new(-50.0, 0.0, 20.0),
        Vec3::new(50.0, 0.0, 20.0),
        Vec3::new(0.0, 0.0, -50.0),
    ];
    let g = rasterize(&scene_of(&[tri]), &cam, &opts());
    let o = cam.position.as_dvec3();
    let mut expected = 0;
    let mut mismatched = 0;
    for y in 0..H {
        for x in 0..W {
            let d = pixel_ray(&cam, x, y, W, H);
            let hit = intersect(o, d, tri).filter(|h| h.0 >= cam.near as f64);
            let i = g.index(x, y);
            expected += usize::from(hit.is_some());
            if hit.is_some() != g.covered(i) {
                mismatched += 1;
            }
            if let Some((t, _, _)) = hit {
                if g.covered(i) {
                    assert!(
                        (g.depth[i] as f64 - t).abs() < 1e-4 * t,
                        "depth {} vs {t}",
                        g.depth[i]
                    );
                }
            }
        }
    }
    assert!(expected > (W * H / 3) as usize, "{expected}");
    assert!(
        mismatched <= 2,
        "{mismatched} pixels differ from ray casting"
    );

    // Entirely behind the camera: nothing.
    let behind = tri.map(|p| Vec3::new(p.x, p.y, 30.0 + p.z.abs()));
    assert_eq!(
        rasterize(&scene_of(&[behind]), &cam, &opts()).covered_count(),
        0
    );
}

#[test]
fn barycentrics_depth_and_normals_match_ray_casting() {
    let cam = camera();
    let tri = screen_tri(
        &cam,
        [(-10.0, 5.0, 1.5), (70.0, -3.0, 12.0), (20.0, 60.0, 3.0)],
    );
    let g = rasterize(&scene_of(&[tri]), &cam, &opts());
    let o = cam.position.as_dvec3();
    let (f, _, _) = common::basis(&cam);
    let n = (tri[1] - tri[0]).cross(tri[2] - tri[0]).normalize();
    let mut checked = 0;
    for y in 0..H {
        for x in 0..W {
            let i = g.index(x, y);
            if !g.covered(i) {
                continue;
            }
            let d = pixel_ray(&cam, x, y, W, H);
            let (t, u, v) = intersect(o, d, tri)
                .or_else(|| {
                    // Pixel centres within snapping distance of an edge: plane barycentrics.
                    let t = (tri[0].as_dvec3() - o).dot(n.as_dvec3()) / d.dot(n.as_dvec3());
                    let p = (o + t * d).as_vec3();
                    let b = barycentric_of(p, tri);
                    Some((t, b.x as f64, b.y as f64))
                })
                .unwrap();
            let b = g.barycentric[i];
            assert!(
                (b.x as f64 - u).abs() < 1e-3 && (b.y as f64 - v).abs() < 1e-3,
                "{b} vs {u},{v}"
            );
            assert!((g.depth[i] as f64 - t).abs() < 1e-4 * t);
            let expect_p = (o + t * d).as_vec3();
            assert!(g.position[i].distance(expect_p) < 1e-3 * t as f32);
            assert!(((g.position[i] - cam.position).dot(f) - g.depth[i]).abs() < 1e-4);
            let view = d.as_vec3();
            assert!(g.geometric_normal[i].dot(view) < 0.0);
            assert!((g.geometric_normal[i].abs() - n.abs()).length() < 1e-5);
            assert!((g.normal[i].length() - 1.0).abs() < 1e-5 && g.normal[i].dot(view) < 0.0);
            checked += 1;
        }
    }
    assert!(checked > 1000, "{checked}");
}

/// Barycentrics (u, v) of point p (on the plane) in triangle t.
fn barycentric_of(p: Vec3, t: [Vec3; 3]) -> Vec2 {
    let (e1, e2, ep) = (t[1] - t[0], t[2] - t[0], p - t[0]);
    let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (dp1, dp2) = (ep.dot(e1), ep.dot(e2));
    let det = d11 * d22 - d12 * d12;
    Vec2::new((d22 * dp1 - d12 * dp2) / det, (d11 * dp2 - d12 * dp1) / det)
}

#[test]
fn nearer_triangle_wins_regardless_of_order() {
    let cam = camera();
    let big = |z: f64| {
        screen_tri(
            &cam,
            [(-20.0, -20.0, z), (100.0, -20.0, z), (-20.0, 100.0, z)],
        )
    };
    for tris in [[big(3.0), big(5.0)], [big(5.0), big(3.0)]] {
        let g = rasterize(&scene_of(&tris), &cam, &opts());
        let near = if (tris[0][0] - cam.position).length() < (tris[1][0] - cam.position).length() {
            0
        } else {
            1
        };
        for i in 0..g.len() {
            if g.covered(i) {
                assert_eq!(g.triangle[i], near);
                assert!((g.depth[i] - 3.0).abs() < 1e-4);
            }
        }
        assert!(g.covered_count() > (W * H / 2) as usize);
    }
}

#[test]
fn backface_culling_respects_winding_and_double_sided_materials() {
    let cam = camera();
    let front = screen_tri(
        &cam,
        [(5.0, 5.0, 4.0), (10.0, 40.0, 4.0), (60.0, 20.0, 4.0)],
    );
    let (f, _, _) = common::basis(&cam);
    let n = (front[1] - front[0]).cross(front[2] - front[0]);
    assert!(
        n.dot(f) < 0.0,
        "test triangle must be counter-clockwise as seen"
    );
    let back = [front[0], front[2], front[1]];
    let cull = RasterOptions {
        cull_backfaces: true,
        ..opts()
    };
    let both = rasterize(&scene_of(&[front]), &cam, &opts()).covered_count();
    assert!(both > 100);
    assert_eq!(
        rasterize(&scene_of(&[front]), &cam, &cull).covered_count(),
        both
    );
    assert_eq!(
        rasterize(&scene_of(&[back]), &cam, &opts()).covered_count(),
        both
    );
    assert_eq!(
        rasterize(&scene_of(&[back]), &cam, &cull).covered_count(),
        0
    );
    let mut double = scene_of(&[back]);
    double.materials[0].double_sided = true;
    assert_eq!(rasterize(&double, &cam, &cull).covered_count(), both);
}

#[test]
fn degenerate_huge_and_invalid_input_does_not_panic() {
    let cam = camera();
    let ok = screen_tri(
        &cam,
        [(5.0, 5.0, 4.0), (10.0, 40.0, 4.0), (60.0, 20.0, 4.0)],
    );
    let huge = [
        Vec3::new(-1e30, -1e30, -5.0),
        Vec3::new(1e30, -1e30, -5.0),
        Vec3::new(0.0, 1e30, -5.0),
    ];
    let nan = [Vec3::NAN, Vec3::ONE, Vec3::ZERO];
    let zero_area = [
        Vec3::new(0.0, 0.0, -3.0),
        Vec3::new(1.0, 1.0, -3.0),
        Vec3::new(2.0, 2.0, -3.0),
    ];
    let point = [Vec3::new(0.5, 0.1, -3.0); 3];
    let mut scene = scene_of(&[huge, nan, zero_area, point, ok]);
    scene.meshes[0].indices.push([0, 1, 99]);
    scene.meshes[0].normals.clear();
    let g = rasterize(&scene, &cam, &opts());
    assert!(g.covered_count() > 0);
    assert!(g
        .normal
        .iter()
        .zip(&g.instance)
        .all(|(n, &i)| i == GBuffer::NONE || (n.length() - 1.0).abs() < 1e-4));
    assert!(g
        .triangle
        .iter()
        .all(|&t| t == 0 || t == 4 || t == GBuffer::NONE));
    assert_eq!(g.triangle[g.index(20, 20)], 4);

    // Zero-sized image, missing mesh, and a degenerate camera.
    assert!(rasterize(&scene, &cam, &RasterOptions::new(0, 10)).is_empty());
    let mut missing = scene.clone();
    missing.instances[0].mesh = 7;
    assert_eq!(rasterize(&missing, &cam, &opts()).covered_count(), 0);
    let degenerate = Camera::look_at(Vec3::ONE, Vec3::ONE, 60.0);
    assert_eq!(rasterize(&scene, &degenerate, &opts()).covered_count(), 0);

    // A zero near distance with a triangle crossing the eye plane: the visible part remains.
    let zero_near = Camera {
        near: 0.0,
        ..Camera::look_at(Vec3::ZERO, Vec3::new(0.0, 0.0, -1.0), 60.0)
    };
    let crossing = [
        Vec3::new(-5.0, -1.0, 5.0),
        Vec3::new(5.0, -1.0, 5.0),
        Vec3::new(0.0, -1.0, -5.0),
    ];
    let g = rasterize(&scene_of(&[crossing]), &zero_near, &opts());
    assert!(g.covered_count() > 0);
    assert!(g.depth.iter().all(|&d| d > 0.0));
}

#[test]
fn huge_triangle_around_the_camera_covers_the_screen_with_correct_depth() {
    let cam = Camera::look_at(Vec3::ZERO, Vec3::new(0.0, 0.0, -1.0), 60.0);
    let tri = [
        Vec3::new(-1e7, -1e7, -10.0),
        Vec3::new(1e7, -1e7, -10.0),
        Vec3::new(0.0, 1e7, -10.0),
    ];
    let g = rasterize(&scene_of(&[tri]), &cam, &opts());
    assert_eq!(g.covered_count(), (W * H) as usize);
    assert!(g.depth.iter().all(|&d| (d - 10.0).abs() < 1e-4));
}

#[test]
fn posed_rasterization_moves_and_deforms_instances() {
    let cam = camera();
    let tri = screen_tri(
        &cam,
        [(5.0, 5.0, 4.0), (10.0, 40.0, 4.0), (30.0, 20.0, 4.0)],
    );
    let scene = scene_of(&[tri]);
    let (_, r, _) = common::basis(&cam);
    let rest = rasterize(&scene, &cam, &opts());
    // Shift right by exactly 16 pixels at depth 4 (pixel width there is 2·4·tan·aspect / W).
    let px = 2.0 * 4.0 * (cam.fov_y * 0.5).tan() * (W as f32 / H as f32) / W as f32;
    let moved = [InstancePose::rigid(Affine3A::from_translation(
        r * 16.0 * px,
    ))];
    let g = rasterize_posed(&scene, &moved, &cam, &opts()).unwrap();
    assert_eq!(g.covered_count(), rest.covered_count());
    for y in 0..H {
        for x in 0..W - 16 {
            assert_eq!(
                rest.covered(rest.index(x, y)),
                g.covered(g.index(x + 16, y)),
                "{x},{y}"
            );
        }
    }

    // Deformed positions replace the mesh's.
    let deformed = screen_tri(
        &cam,
        [(40.0, 5.0, 4.0), (40.0, 40.0, 4.0), (60.0, 20.0, 4.0)],
    );
    let pose = [InstancePose {
        positions: Some(&deformed),
        ..InstancePose::rest(&scene.instances[0])
    }];
    let g = rasterize_posed(&scene, &pose, &cam, &opts()).unwrap();
    assert!(g.covered(g.index(50, 20)) && !g.covered(g.index(15, 20)));

    // Mismatched poses are errors.
    assert_eq!(
        rasterize_posed(&scene, &[], &cam, &opts()),
        Err(PoseError::PoseCount {
            poses: 0,
            instances: 1
        })
    );
    let short = [InstancePose {
        normals: Some(&deformed[..2]),
        ..pose[0]
    }];
    assert!(matches!(
        rasterize_posed(&scene, &short, &cam, &opts()),
        Err(PoseError::VertexCount {
            what: "normal",
            got: 2,
            expected: 3,
            ..
        })
    ));
}

#[test]
fn reused_rasterizer_and_buffer_match_fresh_results_across_sizes() {
    let cam = camera();
    let a = screen_tri(
        &cam,
        [(5.0, 5.0, 4.0), (10.0, 40.0, 4.0), (60.0, 20.0, 4.0)],
    );
    let b = screen_tri(
        &cam,
        [(-5.0, 30.0, 3.0), (70.0, 47.0, 6.0), (30.0, 2.0, 9.0)],
    );
    let (one, two) = (scene_of(&[a]), scene_of(&[a, b]));
    let mut rasterizer = Rasterizer::new();
    let mut out = GBuffer::empty(0, 0);
    for (scene, w, h) in [(&two, W, H), (&one, 32, 16), (&two, 20, 70), (&one, W, H)] {
        let opts = RasterOptions::new(w, h);
        rasterizer.rasterize(scene, &cam, &opts, &mut out);
        let fresh = rasterize(scene, &cam, &opts);
        assert!(fresh.covered_count() > 0);
        assert!(out == fresh, "{w}x{h}");
    }
}
