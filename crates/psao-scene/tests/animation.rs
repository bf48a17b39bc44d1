//! Playback of the real animated files: rigid clips, skinned characters, the built-in scene.

mod common;

use std::time::Instant;

use glam::{Affine3A, Mat4, Quat, Vec3, Vec4};
use psao_scene::{
    builtin, load_scene, AnimatedProperty, Animator, Channel, Interpolation, Motion, Scene,
    ScenePose,
};

/// Key `k` of a linear channel as a 4-vector (w = 0 for 3-vectors).
fn key(c: &Channel, k: usize) -> Vec4 {
    let w = if c.property == AnimatedProperty::Rotation {
        4
    } else {
        3
    };
    let v = &c.values[k * w..(k + 1) * w];
    Vec4::new(v[0], v[1], v[2], v.get(3).copied().unwrap_or(0.0))
}

/// Spherical interpolation written out: sin((1-s)θ)/sin θ · a + sin(sθ)/sin θ · b.
fn slerp_by_hand(a: Vec4, b: Vec4, s: f32) -> Quat {
    let (a, mut b) = (a.normalize(), b.normalize());
    if a.dot(b) < 0.0 {
        b = -b;
    }
    let theta = a.dot(b).clamp(-1.0, 1.0).acos();
    if theta < 1e-5 {
        return Quat::from_vec4(a.lerp(b, s).normalize());
    }
    let q = a * (((1.0 - s) * theta).sin() / theta.sin()) + b * ((s * theta).sin() / theta.sin());
    Quat::from_vec4(q.normalize())
}

/// The local transform of `node` at `t` between keys 0 and 1 of its linear channels in `scene`'s
/// first clip (rest values where a property is not animated).
fn local_by_hand(scene: &Scene, node: usize, t: f32) -> Affine3A {
    let n = &scene.nodes[node];
    let (mut tr, mut rot, mut sc) = (n.translation, n.rotation, n.scale);
    for c in scene.animations[0]
        .channels
        .iter()
        .filter(|c| c.node == node)
    {
        assert_eq!(c.interpolation, Interpolation::Linear);
        assert!(
            c.times[0] <= t && t <= c.times[1],
            "{t} not in the first interval"
        );
        let s = (t - c.times[0]) / (c.times[1] - c.times[0]);
        match c.property {
            AnimatedProperty::Translation => tr = key(c, 0).lerp(key(c, 1), s).truncate(),
            AnimatedProperty::Scale => sc = key(c, 0).lerp(key(c, 1), s).truncate(),
            AnimatedProperty::Rotation => rot = slerp_by_hand(key(c, 0), key(c, 1), s),
        }
    }
    Affine3A::from_scale_rotation_translation(sc, rot, tr)
}

#[test]
fn rigged_simple_joint_matches_hand_computed_transform() {
    let Some(dir) = common::data_dir() else {
        return;
    };
    let scene = load_scene(&dir.join("characters/RiggedSimple.glb")).unwrap();
    let animator = Animator::new(&scene).unwrap();
    assert_eq!(animator.motion(), &[Motion::Skinned]);
    // Node chain of joint 1 (node 3): 0 → 4 → 2 (joint 0, animated) → 3 (animated).
    let joint = scene.skins[0].joints[1];
    let c = &scene.animations[0].channels[0];
    let t = c.times[0] + 0.37 * (c.times[1] - c.times[0]);
    let mut chain = vec![joint];
    while let Some(p) = scene.nodes[*chain.last().unwrap()].parent {
        chain.push(p);
    }
    let world = chain.iter().rev().fold(Affine3A::IDENTITY, |acc, &n| {
        acc * local_by_hand(&scene, n, t)
    });
    let pose = animator.pose_at(t);
    assert!(
        pose.nodes[joint].abs_diff_eq(world, 1e-4),
        "{:?} vs {world:?}",
        pose.nodes[joint]
    );
    // The pose differs from the rest pose (otherwise this proves little).
    assert!(!pose.nodes[joint].abs_diff_eq(animator.pose_at(0.0).nodes[joint], 1e-3));
    // A vertex bound only to joint 1 follows transform⁻¹ · world · inverse_bind.
    let mesh = &scene.meshes[0];
    let v = (0..mesh.positions.len())
        .find(|&v| mesh.joints[v][0] == 1 && mesh.weights[v][0] == 1.0)
        .expect("a vertex fully bound to joint 1");
    let m = Mat4::from(pose.transforms[0].inverse())
        * Mat4::from(world)
        * scene.skins[0].inverse_bind[1];
    let want = m.transform_point3(mesh.positions[v]);
    let got = pose.skinned[0].as_ref().unwrap().positions[v];
    assert!(got.abs_diff_eq(want, 1e-3), "{got} vs {want}");
}

/// Largest distance any instance's origin moved between two poses.
fn largest_move(a: &ScenePose, b: &ScenePose) -> f32 {
    a.transforms
        .iter()
        .zip(&b.transforms)
        .map(|(x, y)| Vec3::from(x.translation).distance(y.translation.into()))
        .fold(0.0, f32::max)
}

#[test]
fn arcade_rigid_clips_play_and_loop() {
    let Some(dir) = common::data_dir() else {
        return;
    };
    let scene = load_scene(&dir.join("scenes/arcade/arcade_with_animated_things4.gltf")).unwrap();
    let a = Animator::new(&scene).unwrap();
    assert!(a.is_dynamic());
    assert!(!a.motion().contains(&Motion::Skinned));
    let rigid: Vec<usize> = (0..scene.instances.len())
        .filter(|&i| a.motion()[i] == Motion::Rigid)
        .collect();
    assert!(rigid.len() >= 5, "{rigid:?}");
    // Every playing clip moves some node between t = 1 and t = 4.
    let (p1, p4) = (a.pose_at(1.0), a.pose_at(4.0));
    for clip in &scene.animations {
        let moved = clip
            .channels
            .iter()
            .any(|c| !p1.nodes[c.node].abs_diff_eq(p4.nodes[c.node], 1e-4));
        assert!(moved, "{} does not move", clip.name);
    }
    // Static instances keep their stored transforms; each clip loops over its duration.
    for (i, m) in a.motion().iter().enumerate() {
        if *m == Motion::Static {
            assert_eq!(p4.transforms[i], scene.instances[i].transform);
        }
    }
    let longest = scene
        .animations
        .iter()
        .map(|c| c.duration())
        .fold(0.0, f32::max);
    if scene
        .animations
        .iter()
        .all(|c| (c.duration() - longest).abs() < 1e-4)
    {
        assert!(largest_move(&p1, &a.pose_at(1.0 + longest)) < 1e-3);
    }
}

#[test]
fn builtin_scene_movers_play_from_their_rest_pose() {
    let scene = builtin::default_scene();
    let a = Animator::new(&scene).unwrap();
    let movers = a.motion().iter().filter(|&&m| m == Motion::Rigid).count();
    assert_eq!(
        movers,
        scene.instances.iter().filter(|i| i.node.is_some()).count()
    );
    let p0 = a.pose_at(0.0);
    for (t, inst) in p0.transforms.iter().zip(&scene.instances) {
        assert!(t.abs_diff_eq(inst.transform, 1e-4));
    }
    assert!(
        largest_move(&p0, &a.pose_at(2.5)) > 1.0,
        "the ball rolls metres"
    );
    assert!(largest_move(&p0, &a.pose_at(10.0)) < 1e-3, "10 s loop");
}

#[test]
fn fox_plays_its_first_clip_with_unit_skinned_normals() {
    let Some(dir) = common::data_dir() else {
        return;
    };
    let scene = load_scene(&dir.join("characters/Fox.glb")).unwrap();
    // Survey, Walk and Run drive the same joints: only the first plays by default.
    assert_eq!(scene.playing, vec![0]);
    let pose = scene.pose_at(1.3).unwrap();
    let g = pose.skinned[0].as_ref().unwrap();
    assert_eq!(g.normals.len(), scene.meshes[0].positions.len());
    assert!(g.normals.iter().all(|n| (n.length() - 1.0).abs() < 1e-4));
    assert!(g.positions.iter().all(|p| p.is_finite()));
}

#[test]
fn five_cesium_men_skin_quickly() {
    if common::data_dir().is_none() {
        return;
    }
    let file = concat!(env!("CARGO_MANIFEST_DIR"), "/../../scenes/arcade.toml");
    let scene = psao_scene::load(std::path::Path::new(file)).unwrap().scene;
    let a = Animator::new(&scene).unwrap();
    let skinned = a.motion().iter().filter(|&&m| m == Motion::Skinned).count();
    assert_eq!(skinned, 5);
    let mut pose = ScenePose::default();
    a.pose_into(0.0, &mut pose);
    let frames = 60;
    let start = Instant::now();
    for f in 0..frames {
        a.pose_into(f as f32 / 60.0, &mut pose);
    }
    let ms = start.elapsed().as_secs_f64() * 1e3 / frames as f64;
    eprintln!("arcade + 5 CesiumMan: {ms:.3} ms per pose");
    assert!(ms < 25.0, "{ms} ms per pose");
    // The skinned men stand on the floor, at most 1.6 m tall.
    for (i, g) in pose.skinned.iter().enumerate() {
        let Some(g) = g else { continue };
        let t = pose.transforms[i];
        let ys: Vec<f32> = g
            .positions
            .iter()
            .map(|p| t.transform_point3(*p).y)
            .collect();
        let (lo, hi) = ys
            .iter()
            .fold((f32::MAX, f32::MIN), |(l, h), &y| (l.min(y), h.max(y)));
        assert!(lo > -0.1 && lo < 0.1 && hi > 1.2 && hi < 1.6, "{lo} {hi}");
    }
}
