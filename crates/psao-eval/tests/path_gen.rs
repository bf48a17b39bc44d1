//! Generated camera paths through the built-in scene with the tracer as ray caster: eyes in
//! free space, no step through a wall, deterministic per seed, different across seeds; a
//! solid block has no free space.

use glam::Vec3;
use psao_eval::path_caster::TracerCaster;
use psao_scene::path_gen::{is_free, step_is_clear};
use psao_scene::{generate_paths, CameraPath, Mesh, PathGenConfig, PathGenError, RayCaster, Scene};
use psao_trace::{Backend, GeometryMode, Tracer};

fn config() -> PathGenConfig {
    PathGenConfig {
        duration_s: 4.0,
        ..PathGenConfig::default()
    }
}

fn builtin() -> Scene {
    let mut scene = psao_scene::builtin::default_scene();
    scene.freeze();
    scene
}

/// 200 directions spread over the sphere (Fibonacci lattice), more than the generator's 26.
fn sphere_directions() -> Vec<Vec3> {
    let n = 200;
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    (0..n)
        .map(|i| {
            let y = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
            let r = (1.0 - y * y).sqrt();
            let a = golden * i as f32;
            Vec3::new(r * a.cos(), y, r * a.sin())
        })
        .collect()
}

#[test]
fn paths_of_the_builtin_scene_stay_in_free_space() {
    let scene = builtin();
    for backend in Backend::compiled() {
        let tracer = Tracer::new(backend, &scene, GeometryMode::Primary).unwrap();
        let caster = TracerCaster::new(&scene, &tracer);
        let paths = generate_paths(&scene, &caster, &config(), 3, 7).unwrap();
        let dirs = sphere_directions();
        for path in &paths {
            assert!(path.duration() >= 4.0 - 1e-3, "{}", path.duration());
            let mut previous: Option<Vec3> = None;
            for i in 0..path.frame_count() {
                let eye = path.camera_at_frame(i).position;
                // Inside the hall's walls (inner half extents 10 × 6, ceiling at 6).
                assert!(eye.x.abs() < 10.0 && eye.z.abs() < 6.0, "{eye}");
                assert!(eye.y > 0.0 && eye.y < 6.0, "{eye}");
                // Every surface seen from the eye is seen from its front, at least 0.3 away.
                for &d in &dirs {
                    if let Some(h) = caster.cast(eye, d, 100.0) {
                        assert!(
                            h.front && h.t >= 0.29,
                            "{backend:?} frame {i} {eye} {d} {h:?}"
                        );
                    }
                }
                if let Some(p) = previous {
                    assert!(p.distance(eye) < 1.2 * 4.0 / 60.0, "jump {p} → {eye}");
                    assert!(step_is_clear(&caster, p, eye), "step {p} → {eye}");
                }
                previous = Some(eye);
            }
        }
    }
}

fn keys(path: &CameraPath) -> Vec<[f32; 7]> {
    path.keys
        .iter()
        .map(|k| {
            let (p, l) = (k.position, k.look_at);
            [k.time, p.x, p.y, p.z, l.x, l.y, l.z]
        })
        .collect()
}

#[test]
fn paths_repeat_per_seed_and_differ_across_seeds_and_indices() {
    let scene = builtin();
    let tracer = Tracer::new(Backend::compiled()[0], &scene, GeometryMode::Primary).unwrap();
    let caster = TracerCaster::new(&scene, &tracer);
    let a = generate_paths(&scene, &caster, &config(), 2, 1).unwrap();
    let again = generate_paths(&scene, &caster, &config(), 2, 1).unwrap();
    let other = generate_paths(&scene, &caster, &config(), 2, 2).unwrap();
    assert_eq!(keys(&a[0]), keys(&again[0]));
    assert_eq!(keys(&a[1]), keys(&again[1]));
    assert_ne!(keys(&a[0]), keys(&other[0]));
    assert_ne!(keys(&a[0]), keys(&a[1]));
    // Path k of a seed does not depend on how many paths were asked for.
    let one = generate_paths(&scene, &caster, &config(), 1, 1).unwrap();
    assert_eq!(keys(&a[0]), keys(&one[0]));
}

#[test]
fn some_keys_look_at_non_diffuse_surfaces() {
    let scene = builtin();
    let tracer = Tracer::new(Backend::compiled()[0], &scene, GeometryMode::Primary).unwrap();
    let caster = TracerCaster::new(&scene, &tracer);
    let config = PathGenConfig {
        non_diffuse_look: 1.0,
        ..config()
    };
    let paths = generate_paths(&scene, &caster, &config, 3, 3).unwrap();
    let looking = paths
        .iter()
        .flat_map(|p| &p.keys)
        .filter(|k| {
            let d = (k.look_at - k.position).normalize();
            caster
                .cast(k.position, d, 100.0)
                .is_some_and(|h| h.non_diffuse)
        })
        .count();
    assert!(looking > 0, "no key looks at a non-diffuse surface");
}

/// A closed 40 m cube (counter-clockwise seen from outside): every point of its bounds is
/// inside it.
fn solid_block() -> Scene {
    let h = 20.0;
    let positions: Vec<Vec3> = (0..8)
        .map(|i| {
            Vec3::new(
                if i & 1 == 0 { -h } else { h },
                if i & 2 == 0 { -h } else { h },
                if i & 4 == 0 { -h } else { h },
            )
        })
        .collect();
    let quads = [
        [0, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ];
    let indices = quads
        .iter()
        .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .collect();
    Scene::of_meshes(vec![Mesh {
        name: "block".into(),
        normals: vec![Vec3::Y; 8],
        positions,
        indices,
        ..Mesh::default()
    }])
}

#[test]
fn a_solid_block_has_no_free_space() {
    let scene = solid_block();
    let tracer = Tracer::new(Backend::compiled()[0], &scene, GeometryMode::Primary).unwrap();
    let caster = TracerCaster::new(&scene, &tracer);
    // The cube's faces point outwards: from outside, the eye sees fronts; from inside, backs.
    assert!(is_free(&caster, Vec3::new(0.0, 0.0, 30.0), 0.3, 200.0));
    assert!(!is_free(&caster, Vec3::ZERO, 0.3, 200.0));
    let err = generate_paths(&scene, &caster, &config(), 1, 1).unwrap_err();
    assert!(matches!(err, PathGenError::NoFreeSpace { .. }), "{err}");
    assert!(err.to_string().contains("no free space"), "{err}");
}
