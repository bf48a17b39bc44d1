//! Scene-file motion: `walk`, `keys` and the built-in shape assets, and the repository's
//! dynamic scene files, and freezing a scene (`--static`).

mod common;

use std::fs;
use std::path::Path;

use glam::Vec3;
use psao_scene::{load_scene, Animator, Motion, Scene, ScenePose};

/// World bounds of instance `i` in `pose` (skinned vertices where present).
fn posed_bounds(scene: &Scene, pose: &ScenePose, i: usize) -> (Vec3, Vec3) {
    let posed = pose.instance(i).unwrap();
    let positions = posed
        .positions
        .unwrap_or(&scene.meshes[scene.instances[i].mesh].positions);
    positions.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| {
            let w = posed.transform.transform_point3(*p);
            (lo.min(w), hi.max(w))
        },
    )
}

fn write_scene(text: &str) -> (tempfile::TempDir, std::path::PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("s.toml");
    fs::write(&path, text).unwrap();
    (tmp, path)
}

#[test]
fn rolling_builtin_sphere_stays_on_the_ground() {
    let (_tmp, path) = write_scene(
        "[[asset]]\nfile = \"builtin:sphere\"\nscale = 0.6\n\
         walk = { points = [[0, 1, 0], [10, 1, 0]], speed = 2.0, loop = false, roll = true }\n",
    );
    let scene = load_scene(&path).unwrap();
    let a = Animator::new(&scene).unwrap();
    assert_eq!(a.motion(), &[Motion::Rigid]);
    // Rest transform = pose at t = 0: centre 0.3 m above the first point.
    assert!(scene.instances[0]
        .transform
        .abs_diff_eq(a.pose_at(0.0).transforms[0], 1e-5));
    for t in [0.0, 1.3, 4.0, 7.7] {
        let pose = a.pose_at(t);
        let (lo, hi) = posed_bounds(&scene, &pose, 0);
        assert!(
            (lo.y - 1.0).abs() < 2e-3 && (hi.y - 1.6).abs() < 2e-3,
            "{lo} {hi}"
        );
        let centre = 0.5 * (lo + hi);
        // There (5 s to the end) and back.
        let x = if t <= 5.0 { 2.0 * t } else { 20.0 - 2.0 * t };
        assert!((centre.x - x).abs() < 2e-3, "t {t}: {centre}");
    }
    // Rolled 2 m at t = 1: the ball turned 2 / 0.3 rad about the z axis (travel along +x).
    let r = a.pose_at(1.0).transforms[0].matrix3;
    let angle = 2.0f32 / 0.3;
    let up = (r * glam::Vec3A::Y).normalize();
    assert!(
        (up.y - angle.cos()).abs() < 1e-4 && (up.x - angle.sin()).abs() < 1e-4,
        "{up}"
    );
}

#[test]
fn keys_drive_the_wrapper_of_a_builtin_box() {
    let (_tmp, path) = write_scene(
        "[[asset]]\nfile = \"builtin:box\"\n\
         keys = { times = [0, 2], translation = [[0, 3, 0], [0, 0.5, 0]], rotation_deg = [[0, 0, 0], [0, 90, 0]] }\n\
         [[asset]]\nfile = \"builtin:cylinder\"\ntranslation = [5, 0, 0]\n",
    );
    let scene = load_scene(&path).unwrap();
    let a = Animator::new(&scene).unwrap();
    assert_eq!(a.motion(), &[Motion::Rigid, Motion::Static]);
    let t = a.pose_at(1.0).transforms[0];
    assert!(Vec3::from(t.translation).abs_diff_eq(Vec3::new(0.0, 1.75, 0.0), 1e-5));
    let turned = t.transform_vector3(Vec3::X);
    let (s, c) = 45f32.to_radians().sin_cos();
    assert!(turned.abs_diff_eq(Vec3::new(c, 0.0, -s), 1e-5), "{turned}");
    // The keys clip plays and loops over 2 s.
    assert!(a.pose_at(2.5).transforms[0].abs_diff_eq(a.pose_at(0.5).transforms[0], 1e-5));
    let (lo, hi) = posed_bounds(&scene, &a.pose_at(0.0), 1);
    assert!(lo.abs_diff_eq(Vec3::new(4.5, 0.0, -0.5), 2e-3) && (hi.y - 1.0).abs() < 1e-5);
}

#[test]
fn bad_motion_keys_are_errors() {
    for (text, needle) in [
        (
            "[[asset]]\nfile = \"builtin:box\"\ntranslation = [1, 0, 0]\nwalk = { points = [[0, 0, 0]] }\n",
            "walk excludes",
        ),
        (
            "[[asset]]\nfile = \"builtin:box\"\nkeys = { times = [0, 1], translation = [[0, 0, 0]] }\n",
            "1 translation values for 2 times",
        ),
        (
            "[[asset]]\nfile = \"builtin:box\"\nkeys = { times = [0, 1] }\n",
            "translation and/or rotation_deg",
        ),
        (
            "[[asset]]\nfile = \"builtin:teapot\"\n",
            "unknown built-in asset",
        ),
        (
            "[[asset]]\nfile = \"builtin:box\"\nwalk = { points = [], speed = 1.0 }\n",
            "non-empty",
        ),
        (
            "[[asset]]\nfile = \"builtin:box\"\nwalk = { points = [[0, 0, 0]], speed = -1.0 }\n",
            "speed",
        ),
    ] {
        let (_tmp, path) = write_scene(text);
        let err = load_scene(&path).unwrap_err().to_string();
        assert!(err.contains(needle), "{err}");
    }
}

fn repo_scene(name: &str) -> Option<Scene> {
    common::data_dir()?;
    let file = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../scenes")
        .join(name);
    Some(load_scene(&file).unwrap())
}

#[test]
fn arcade_dynamic_characters_walk_inside_the_room() {
    let Some(scene) = repo_scene("arcade_dynamic.toml") else {
        return;
    };
    let a = Animator::new(&scene).unwrap();
    assert_eq!(scene.walkers.len(), 2);
    let skinned: Vec<usize> = (0..scene.instances.len())
        .filter(|&i| a.motion()[i] == Motion::Skinned)
        .collect();
    assert_eq!(skinned.len(), 2);
    assert!(a.motion().iter().filter(|&&m| m == Motion::Rigid).count() >= 5);
    let mut pose = ScenePose::default();
    let mut travelled = [0.0f32; 2];
    let mut last = [None; 2];
    for k in 0..40 {
        a.pose_into(k as f32 * 0.5, &mut pose);
        for (n, &i) in skinned.iter().enumerate() {
            let (lo, hi) = posed_bounds(&scene, &pose, i);
            assert!(
                lo.x > -2.75 && hi.x < 1.0 && lo.z > -1.0 && hi.z < 6.5,
                "{lo} {hi}"
            );
            assert!(lo.y > -0.1 && lo.y < 0.1, "feet on the floor: {lo}");
            let c = 0.5 * (lo + hi);
            if let Some(p) = last[n] {
                travelled[n] += c.distance(p);
            }
            last[n] = Some(c);
        }
    }
    assert!(travelled.iter().all(|&d| d > 5.0), "{travelled:?}");
}

#[test]
fn sponza_dynamic_objects_move_in_the_courtyard() {
    let Some(scene) = repo_scene("sponza_dynamic.toml") else {
        return;
    };
    let a = Animator::new(&scene).unwrap();
    let moving: Vec<usize> = (0..scene.instances.len())
        .filter(|&i| a.motion()[i] != Motion::Static)
        .collect();
    assert_eq!(moving.len(), 4, "ball, box, cylinder, man");
    assert_eq!(a.motion()[moving[3]], Motion::Skinned);
    for t in [0.0, 0.9, 2.0, 3.3, 7.1] {
        let pose = a.pose_at(t);
        for &i in &moving {
            let (lo, hi) = posed_bounds(&scene, &pose, i);
            assert!(
                lo.x > -10.5 && hi.x < 10.5 && lo.z > -2.5 && hi.z < 2.5,
                "{i}: {lo} {hi}"
            );
            assert!(lo.y > 0.0, "{i} at {t}: {lo}");
        }
    }
    // The ball touches the ground; the box starts high and lands on a face.
    let ball = moving[0];
    assert!((posed_bounds(&scene, &a.pose_at(3.0), ball).0.y - 0.09).abs() < 2e-3);
    let boxi = moving[1];
    assert!(posed_bounds(&scene, &a.pose_at(0.0), boxi).0.y > 2.5);
    let (lo, hi) = posed_bounds(&scene, &a.pose_at(3.0), boxi);
    assert!(
        (lo.y - 0.09).abs() < 2e-3 && (hi.y - 0.59).abs() < 2e-3,
        "{lo} {hi}"
    );
}

#[test]
fn a_frozen_scene_is_static() {
    let mut scene = psao_scene::builtin::default_scene();
    assert!(scene.is_dynamic().unwrap(), "the hall's movers play");
    scene.freeze();
    assert!(!scene.is_dynamic().unwrap());
    assert!(scene.playing.is_empty() && scene.walkers.is_empty());
}
