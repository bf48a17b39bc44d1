use std::collections::HashMap;

use glam::{Affine3A, Quat, Vec2, Vec3};

use super::default_scene;
use super::shapes::{arcade, cuboid, cylinder, lathe, sphere, stairs};
use crate::model::{AnimatedProperty, Mesh, Scene};

fn face_normal(m: &Mesh, t: [u32; 3]) -> Vec3 {
    let [a, b, c] = t.map(|i| m.positions[i as usize]);
    (b - a).cross(c - a)
}

/// Signed volume by the divergence theorem: positive for outward-wound closed meshes.
fn volume(m: &Mesh) -> f32 {
    m.indices
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| m.positions[i as usize]);
            a.dot(b.cross(c)) / 6.0
        })
        .sum()
}

/// Every directed edge (by welded position) has exactly one reverse partner.
fn assert_closed(m: &Mesh) {
    let key = |p: Vec3| (p * 1e5).round().as_ivec3().to_array();
    let mut edges: HashMap<_, i32> = HashMap::new();
    for t in &m.indices {
        for k in 0..3 {
            let (a, b) = (
                key(m.positions[t[k] as usize]),
                key(m.positions[t[(k + 1) % 3] as usize]),
            );
            *edges.entry((a, b)).or_default() += 1;
        }
    }
    for (&(a, b), &n) in &edges {
        assert_eq!(n, 1, "{}: edge {a:?}->{b:?} used {n} times", m.name);
        assert_eq!(
            edges.get(&(b, a)),
            Some(&1),
            "{}: edge {a:?}->{b:?} has no twin",
            m.name
        );
    }
}

/// Geometric normals agree with the vertex normals of each triangle.
fn assert_winding_matches_normals(m: &Mesh) {
    for &t in &m.indices {
        let n = face_normal(m, t).normalize();
        for i in t {
            let d = n.dot(m.normals[i as usize]);
            assert!(
                d > 0.2,
                "{}: triangle {t:?} face normal {n} vs vertex normal (dot {d})",
                m.name
            );
        }
    }
}

fn test_shapes() -> Vec<(Mesh, f32)> {
    let pi = std::f32::consts::PI;
    let n = 48.0f32;
    let polygon_area = |r: f32| 0.5 * n * r * r * (std::f32::consts::TAU / n).sin();
    vec![
        (cuboid(Vec3::new(0.5, 1.0, 1.5)), 6.0),
        (cylinder(0.5, 2.0, 48), polygon_area(0.5) * 2.0),
        (sphere(1.0, 48), 4.0 / 3.0 * pi),
        (
            stairs(2.0, 0.2, 0.3, 4, 1.0),
            2.0 * (0.3 * (0.2 + 0.4 + 0.6) + 1.0 * 0.8),
        ),
        // Two bays 2 m wide, 1.5 m tall, 0.5 deep, minus two half-disc openings of r = 0.6.
        (
            arcade(2, 1.0, 0.6, 1.5, 0.5, 48),
            0.5 * (4.0 * 1.5 - pi * 0.36),
        ),
    ]
}

#[test]
fn shapes_are_closed_outward_and_have_the_right_volume() {
    for (mesh, expected) in test_shapes() {
        assert_closed(&mesh);
        assert_winding_matches_normals(&mesh);
        let v = volume(&mesh);
        assert!(
            (v - expected).abs() < 0.01 * expected,
            "{}: volume {v}, expected {expected}",
            mesh.name
        );
    }
}

#[test]
fn lathe_with_an_interior_cavity_is_closed_and_outward() {
    // A cup: outer wall up, lip, inner wall down to an inner floor.
    let v = Vec2::new;
    let profile = [
        v(0.0, 0.0),
        v(1.0, 0.0),
        v(1.0, 2.0),
        v(0.8, 2.0),
        v(0.8, 0.5),
        v(0.0, 0.5),
    ];
    let cup = lathe(&profile, 64, 0.0);
    assert_closed(&cup);
    assert_winding_matches_normals(&cup);
    let n = 64.0f32;
    let area = |r: f32| 0.5 * n * r * r * (std::f32::consts::TAU / n).sin();
    let expected = area(1.0) * 2.0 - area(0.8) * 1.5;
    assert!((volume(&cup) - expected).abs() < 1e-3 * expected);
}

#[test]
fn triangle_count_is_in_range() {
    let scene = default_scene();
    let count = scene.instanced_triangle_count();
    assert!((50_000..=300_000).contains(&count), "{count} triangles");
}

#[test]
fn meshes_are_well_formed() {
    let scene = default_scene();
    for m in &scene.meshes {
        assert!(!m.indices.is_empty(), "{} has no triangles", m.name);
        assert_eq!(m.positions.len(), m.normals.len(), "{}", m.name);
        assert!(m.material < scene.materials.len());
        for n in &m.normals {
            assert!((n.length() - 1.0).abs() < 1e-4, "{}: normal {n}", m.name);
        }
        for &t in &m.indices {
            assert!(
                t.iter().all(|&i| (i as usize) < m.positions.len()),
                "{}",
                m.name
            );
            let area = 0.5 * face_normal(m, t).length();
            assert!(area > 1e-10, "{}: degenerate triangle {t:?}", m.name);
        }
        assert_winding_matches_normals(m);
    }
    assert!(scene.instances.iter().all(|i| i.mesh < scene.meshes.len()));
}

#[test]
fn scene_sits_in_the_hall() {
    let scene = default_scene();
    let (lo, hi) = scene.bounds();
    assert!(lo.abs_diff_eq(Vec3::new(-10.4, -0.32, -6.4), 1e-4), "{lo}");
    assert!(hi.abs_diff_eq(Vec3::new(10.4, 6.3, 6.4), 1e-4), "{hi}");
    assert_eq!(scene.ao_radius, crate::model::DEFAULT_AO_RADIUS);
}

fn assert_scenes_equal(a: &Scene, b: &Scene) {
    assert_eq!(a.meshes.len(), b.meshes.len());
    for (x, y) in a.meshes.iter().zip(&b.meshes) {
        assert_eq!(x.name, y.name);
        assert_eq!(x.positions, y.positions);
        assert_eq!(x.normals, y.normals);
        assert_eq!(x.indices, y.indices);
        assert_eq!(x.material, y.material);
    }
    assert_eq!(a.materials, b.materials);
    assert_eq!(a.nodes, b.nodes);
    assert_eq!(a.instances, b.instances);
    assert_eq!(a.animations, b.animations);
    assert_eq!(a.playing, b.playing);
}

#[test]
fn deterministic() {
    assert_scenes_equal(&default_scene(), &default_scene());
}

fn world(scene: &Scene, node: usize) -> Affine3A {
    let n = &scene.nodes[node];
    let local = n.local_transform();
    n.parent.map_or(local, |p| world(scene, p) * local)
}

#[test]
fn animations_drive_the_moving_instances() {
    let scene = default_scene();
    assert_eq!(scene.animations.len(), 4);
    assert_eq!(scene.playing, vec![0, 1, 2, 3]);
    for anim in &scene.animations {
        assert!((anim.duration() - 10.0).abs() < 1e-5, "{}", anim.name);
        for c in &anim.channels {
            assert!(c.times.len() >= 5, "{}", anim.name);
            assert!(c.times.windows(2).all(|w| w[1] > w[0]));
            let width = match c.property {
                AnimatedProperty::Rotation => 4,
                _ => 3,
            };
            assert_eq!(c.values.len(), width * c.times.len());
            // Looping: the last key repeats the first (rotations up to sign).
            let (first, last) = (&c.values[..width], &c.values[c.values.len() - width..]);
            if width == 4 {
                let (q0, q1) = (Quat::from_slice(first), Quat::from_slice(last));
                assert!(q0.dot(q1).abs() > 0.9999, "{}", anim.name);
                // Consecutive keys stay in one hemisphere and less than 180° apart.
                for w in c.values.chunks(4).collect::<Vec<_>>().windows(2) {
                    assert!(Quat::from_slice(w[0]).dot(Quat::from_slice(w[1])) > 0.0);
                }
            } else {
                assert!(first.iter().zip(last).all(|(a, b)| (a - b).abs() < 1e-4));
            }
            // The node's rest pose is the pose at t = 0.
            let node = &scene.nodes[c.node];
            match c.property {
                AnimatedProperty::Rotation => {
                    assert!(node.rotation.dot(Quat::from_slice(first)).abs() > 0.9999)
                }
                _ => assert!(node.translation.abs_diff_eq(Vec3::from_slice(first), 1e-5)),
            }
        }
    }
    let moving: Vec<_> = scene
        .instances
        .iter()
        .filter(|i| i.node.is_some())
        .collect();
    assert_eq!(moving.len(), 7);
    let animated: Vec<usize> = scene
        .animations
        .iter()
        .flat_map(|a| a.channels.iter().map(|c| c.node))
        .collect();
    for inst in moving {
        let node = inst.node.unwrap();
        assert!(world(&scene, node).abs_diff_eq(inst.transform, 1e-5));
        // The node or one of its ancestors is animated.
        let mut n = Some(node);
        let mut driven = false;
        while let Some(i) = n {
            driven |= animated.contains(&i);
            n = scene.nodes[i].parent;
        }
        assert!(driven, "{} is not animated", scene.nodes[node].name);
    }
}

#[test]
fn builds_quickly() {
    let start = std::time::Instant::now();
    let scene = default_scene();
    let elapsed = start.elapsed();
    assert!(!scene.instances.is_empty());
    // Generous for unoptimised builds; a release build takes a few milliseconds.
    assert!(elapsed.as_secs_f32() < 2.0, "{elapsed:?}");
}

#[test]
fn repository_camera_paths_and_default_scene_file_load() {
    let root = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."));
    for name in ["default", "sponza", "arcade"] {
        for suffix in ["a", "b"] {
            let file = root.join(format!("paths/{name}_{suffix}.toml"));
            let path = crate::path::CameraPath::load(&file).expect("camera path parses");
            assert_eq!(path.name, format!("{name}_{suffix}"));
            assert!((6..=12).contains(&path.keys.len()), "{}", path.name);
            assert!((path.duration() - 15.0).abs() < 1e-6, "{}", path.name);
        }
    }
    let loaded = crate::load(&root.join("scenes/default.toml")).expect("default scene file loads");
    assert_eq!(loaded.camera_paths.len(), 2);
    assert!(loaded.camera_paths.iter().all(|p| p.is_file()));
    assert_eq!(
        loaded.scene.instanced_triangle_count(),
        default_scene().instanced_triangle_count()
    );
}

#[test]
fn hall_lights_are_valid_and_panels_emit_down_inside() {
    let scene = default_scene();
    assert!(scene.lights.iter().all(|l| l.check().is_ok()));
    let panels: Vec<_> = scene
        .lights
        .iter()
        .filter_map(|l| match l.shape {
            crate::LightShape::Rect {
                centre,
                half_u,
                half_v,
            } => Some((centre, half_u.cross(half_v).normalize())),
            _ => None,
        })
        .collect();
    assert_eq!(panels.len(), 3);
    for (centre, normal) in panels {
        assert!((normal - Vec3::NEG_Y).length() < 1e-6);
        assert!(centre.x.abs() < 10.0 && centre.z.abs() < 6.0 && centre.y < 6.0);
    }
}
