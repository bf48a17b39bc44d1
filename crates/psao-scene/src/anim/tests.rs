use std::f32::consts::{FRAC_PI_2, FRAC_PI_4, PI};

use glam::{Affine3A, Mat4, Quat, Vec3};

use super::sample::{sample, Sampled};
use super::*;
use crate::model::{
    AnimatedProperty, Animation, Channel, Instance, Interpolation, Material, Mesh, Node, Skin,
    Walker,
};

fn close(a: Vec3, b: Vec3) -> bool {
    a.abs_diff_eq(b, 1e-5)
}

fn channel(
    property: AnimatedProperty,
    interpolation: Interpolation,
    times: &[f32],
    values: &[f32],
) -> Channel {
    Channel {
        node: 0,
        property,
        interpolation,
        times: times.to_vec(),
        values: values.to_vec(),
    }
}

fn vector(c: &Channel, t: f32) -> Vec3 {
    match sample(c, t) {
        Sampled::Vector(v) => v,
        Sampled::Rotation(r) => panic!("rotation {r:?}"),
    }
}

fn rotation(c: &Channel, t: f32) -> Quat {
    match sample(c, t) {
        Sampled::Rotation(r) => r,
        Sampled::Vector(v) => panic!("vector {v:?}"),
    }
}

fn node(name: &str, parent: Option<usize>, translation: Vec3) -> Node {
    Node {
        name: name.into(),
        parent,
        translation,
        rotation: Quat::IDENTITY,
        scale: Vec3::ONE,
    }
}

/// Three translation keys along x: 0, 10, 20 at t = 0, 1, 2.
fn x_keys(interpolation: Interpolation) -> Channel {
    channel(
        AnimatedProperty::Translation,
        interpolation,
        &[0.0, 1.0, 2.0],
        &[0.0, 0.0, 0.0, 10.0, 0.0, 0.0, 20.0, 0.0, 0.0],
    )
}

#[test]
fn step_holds_the_previous_key_and_clamps() {
    let c = x_keys(Interpolation::Step);
    assert_eq!(vector(&c, 0.5).x, 0.0);
    assert_eq!(vector(&c, 1.0).x, 10.0);
    assert_eq!(vector(&c, 1.99).x, 10.0);
    assert_eq!(vector(&c, -1.0).x, 0.0);
    assert_eq!(vector(&c, 7.0).x, 20.0);
}

#[test]
fn linear_interpolates_between_keys() {
    let c = x_keys(Interpolation::Linear);
    assert!((vector(&c, 0.25).x - 2.5).abs() < 1e-6);
    assert!((vector(&c, 1.5).x - 15.0).abs() < 1e-6);
    assert_eq!(vector(&c, 2.0).x, 20.0);
}

#[test]
fn linear_rotation_is_slerp() {
    let (s, c) = FRAC_PI_4.sin_cos();
    // Identity, then 90° about y (x, y, z, w).
    let ch = channel(
        AnimatedProperty::Rotation,
        Interpolation::Linear,
        &[0.0, 1.0],
        &[0.0, 0.0, 0.0, 1.0, 0.0, s, 0.0, c],
    );
    // Halfway: 45° about y = (0, sin 22.5°, 0, cos 22.5°); a component-wise lerp would
    // give a shorter, unnormalised quaternion with the same axis, so also check a quarter.
    let half = rotation(&ch, 0.5);
    let (s8, c8) = (PI / 8.0).sin_cos();
    assert!(
        half.abs_diff_eq(Quat::from_xyzw(0.0, s8, 0.0, c8), 1e-6),
        "{half:?}"
    );
    let quarter = rotation(&ch, 0.25);
    let want = Quat::from_rotation_y(FRAC_PI_2 * 0.25);
    assert!(quarter.abs_diff_eq(want, 1e-6), "{quarter:?}");
}

#[test]
fn cubic_spline_follows_hermite_basis() {
    // Keys (in-tangent, value, out-tangent): t = 0: (_, 0, 1); t = 2: (0, 1, _), on x.
    let ch = channel(
        AnimatedProperty::Translation,
        Interpolation::CubicSpline,
        &[0.0, 2.0],
        &[
            9.0, 0.0, 0.0, /* value */ 0.0, 0.0, 0.0, /* out */ 1.0, 0.0, 0.0, //
            0.0, 0.0, 0.0, /* value */ 1.0, 0.0, 0.0, /* out */ 9.0, 0.0, 0.0,
        ],
    );
    // s = 0.5, dt = 2: h10 = 0.125 → 0.125·2·1 = 0.25; h01 = 0.5 → 0.5·1; total 0.75.
    assert!((vector(&ch, 1.0).x - 0.75).abs() < 1e-6);
    // s = 0.25: h10 = 0.140625 → 0.28125; h01 = 0.15625; total 0.4375.
    assert!((vector(&ch, 0.5).x - 0.4375).abs() < 1e-6);
    // Outside the keys: the values, never the tangents.
    assert_eq!(vector(&ch, -1.0).x, 0.0);
    assert_eq!(vector(&ch, 5.0).x, 1.0);
}

#[test]
fn cubic_spline_rotation_is_normalised() {
    let ch = channel(
        AnimatedProperty::Rotation,
        Interpolation::CubicSpline,
        &[0.0, 1.0],
        &[
            0.0, 0.0, 0.0, 0.0, /* */ 0.0, 0.0, 0.0, 1.0, /* */ 0.0, 0.0, 0.0,
            0.0, //
            0.0, 0.0, 0.0, 0.0, /* */ 0.0, 1.0, 0.0, 0.0, /* */ 0.0, 0.0, 0.0, 0.0,
        ],
    );
    let q = rotation(&ch, 0.5);
    assert!((q.length() - 1.0).abs() < 1e-6);
    // Symmetric blend of identity and 180° about y: 90° about y.
    assert!(
        q.abs_diff_eq(Quat::from_rotation_y(FRAC_PI_2), 1e-5),
        "{q:?}"
    );
}

/// One node, one mesh instance on it, and one linear clip moving it along x from 0 to 2
/// over 2 s.
fn sliding_scene() -> Scene {
    Scene {
        meshes: vec![Mesh {
            positions: vec![Vec3::ZERO],
            normals: vec![Vec3::Y],
            ..Default::default()
        }],
        materials: vec![Material::default()],
        nodes: vec![node("slider", None, Vec3::ZERO)],
        instances: vec![Instance {
            mesh: 0,
            node: Some(0),
            transform: Affine3A::IDENTITY,
            skin: None,
        }],
        animations: vec![Animation {
            name: "slide".into(),
            channels: vec![channel(
                AnimatedProperty::Translation,
                Interpolation::Linear,
                &[0.0, 2.0],
                &[0.0, 0.0, 0.0, 2.0, 0.0, 0.0],
            )],
        }],
        playing: vec![0],
        ..Default::default()
    }
}

#[test]
fn clips_loop_over_their_duration() {
    let a = Animator::new(&sliding_scene()).unwrap();
    assert_eq!(a.motion(), &[Motion::Rigid]);
    assert!(a.is_dynamic());
    let x = |t: f32| a.pose_at(t).transforms[0].translation.x;
    assert!((x(0.5) - 0.5).abs() < 1e-6);
    assert!((x(2.5) - 0.5).abs() < 1e-6);
    assert!((x(4.75) - 0.75).abs() < 1e-5);
    assert!((x(-0.5) - 1.5).abs() < 1e-6);
}

#[test]
fn clips_that_do_not_play_leave_the_scene_static() {
    let mut scene = sliding_scene();
    scene.playing.clear();
    let a = Animator::new(&scene).unwrap();
    assert_eq!(a.motion(), &[Motion::Static]);
    assert!(!scene.is_dynamic().unwrap());
    assert_eq!(a.pose_at(1.0).transforms[0], Affine3A::IDENTITY);
}

#[test]
fn children_follow_animated_parents() {
    let mut scene = sliding_scene();
    scene
        .nodes
        .push(node("child", Some(0), Vec3::new(0.0, 1.0, 0.0)));
    scene.instances[0].node = Some(1);
    // Turn the parent by 90° about z halfway through.
    scene.animations[0].channels.push(Channel {
        node: 0,
        property: AnimatedProperty::Rotation,
        interpolation: Interpolation::Step,
        times: vec![0.0, 1.0],
        values: [Quat::IDENTITY, Quat::from_rotation_z(FRAC_PI_2)]
            .iter()
            .flat_map(|q| q.to_array())
            .collect(),
    });
    let pose = scene.pose_at(1.5).unwrap();
    // Parent at x = 1.5 turned 90°: the child's +y offset points along -x.
    assert!(close(
        pose.transforms[0].translation.into(),
        Vec3::new(0.5, 0.0, 0.0)
    ));
    assert!(close(pose.nodes[1].transform_vector3(Vec3::X), Vec3::Y));
}

/// Two joints (root at the origin, child 1 m up), a separate mesh node at x = 5 and three
/// vertices bound to joint 0, joint 1 and half/half (given as `half_weights`); the clip
/// turns joint 1 by 90° about z from t = 1 (step).
fn two_joint_scene(half_weights: [f32; 4]) -> Scene {
    let turn: Vec<f32> = [Quat::IDENTITY, Quat::from_rotation_z(FRAC_PI_2)]
        .iter()
        .flat_map(|q| q.to_array())
        .collect();
    Scene {
        meshes: vec![Mesh {
            name: "bar".into(),
            positions: vec![
                Vec3::new(0.0, 0.5, 0.0),
                Vec3::new(0.0, 1.5, 0.0),
                Vec3::new(0.0, 1.2, 0.0),
            ],
            normals: vec![Vec3::X; 3],
            indices: vec![[0, 1, 2]],
            joints: vec![[0, 0, 0, 0], [1, 0, 0, 0], [0, 1, 0, 0]],
            weights: vec![[1.0, 0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], half_weights],
            ..Default::default()
        }],
        materials: vec![Material::default()],
        nodes: vec![
            node("root", None, Vec3::ZERO),
            node("tip", Some(0), Vec3::Y),
            node("mesh", None, Vec3::new(5.0, 0.0, 0.0)),
        ],
        instances: vec![Instance {
            mesh: 0,
            node: Some(2),
            transform: Affine3A::from_translation(Vec3::new(5.0, 0.0, 0.0)),
            skin: Some(0),
        }],
        skins: vec![Skin {
            name: "arm".into(),
            joints: vec![0, 1],
            inverse_bind: vec![Mat4::IDENTITY, Mat4::from_translation(-Vec3::Y)],
        }],
        animations: vec![Animation {
            name: "bend".into(),
            channels: vec![Channel {
                node: 1,
                property: AnimatedProperty::Rotation,
                interpolation: Interpolation::Step,
                times: vec![0.0, 1.0, 2.0],
                values: [turn.clone(), turn[4..].to_vec()].concat(),
            }],
        }],
        playing: vec![0],
        ..Default::default()
    }
}

#[test]
fn two_joint_skin_blends_hand_computed_matrices() {
    let scene = two_joint_scene([0.5, 0.5, 0.0, 0.0]);
    let a = Animator::new(&scene).unwrap();
    assert_eq!(a.motion(), &[Motion::Skinned]);
    // Before the bend: the bind pose, in mesh-local space (the mesh node sits at x = 5, the
    // skeleton at the origin, so local = world - 5x).
    let rest = a.pose_at(0.5);
    let g = rest.skinned[0].as_ref().unwrap();
    let shift = Vec3::new(-5.0, 0.0, 0.0);
    for (p, q) in g.positions.iter().zip(&scene.meshes[0].positions) {
        assert!(close(*p, *q + shift), "{p} vs {q}");
    }
    // Bent: joint 1's matrix is T(0,1,0)·Rz(90°)·T(0,-1,0).
    let bent = a.pose_at(1.5);
    let g = bent.skinned[0].as_ref().unwrap();
    assert!(close(g.positions[0], Vec3::new(0.0, 0.5, 0.0) + shift));
    // (0, 1.5, 0) → (0, 0.5, 0) → (-0.5, 0, 0) → (-0.5, 1, 0).
    assert!(
        close(g.positions[1], Vec3::new(-0.5, 1.0, 0.0) + shift),
        "{}",
        g.positions[1]
    );
    // Half of (0, 1.2, 0) and half of (-0.2, 1, 0).
    assert!(
        close(g.positions[2], Vec3::new(-0.1, 1.1, 0.0) + shift),
        "{}",
        g.positions[2]
    );
    // Normals: +x stays for joint 0, turns to +y for joint 1, halfway for the blend.
    assert!(close(g.normals[0], Vec3::X));
    assert!(close(g.normals[1], Vec3::Y));
    assert!(close(g.normals[2], Vec3::new(1.0, 1.0, 0.0).normalize()));
    // The instance itself does not move.
    assert_eq!(bent.transforms[0], scene.instances[0].transform);
    let posed = bent.instance(0).unwrap();
    assert_eq!(posed.transform, scene.instances[0].transform);
    assert_eq!(posed.positions.map(<[Vec3]>::len), Some(3));
    assert_eq!(posed.normals, Some(g.normals.as_slice()));
    assert!(bent.instance(1).is_none());
}

#[test]
fn world_bounds_follow_rigid_and_skinned_poses() {
    let scene = two_joint_scene([0.5, 0.5, 0.0, 0.0]);
    let a = Animator::new(&scene).unwrap();
    // Bent: the vertices span x in [-0.5, 0] and y in [0.5, 1.1] around the skeleton.
    let (lo, hi) = a.world_bounds(&a.pose_at(1.5), 0).unwrap();
    assert!(
        close(lo, Vec3::new(-0.5, 0.5, 0.0)) && close(hi, Vec3::new(0.0, 1.1, 0.0)),
        "{lo} {hi}"
    );
    let slider = sliding_scene();
    let a = Animator::new(&slider).unwrap();
    let (lo, hi) = a.world_bounds(&a.pose_at(1.0), 0).unwrap();
    assert!(close(lo, Vec3::X) && close(hi, Vec3::X));
    assert!(a.world_bounds(&a.pose_at(1.0), 1).is_none());
}

#[test]
fn skin_weights_are_renormalised() {
    let normalised = Animator::new(&two_joint_scene([0.5, 0.5, 0.0, 0.0])).unwrap();
    let raw = Animator::new(&two_joint_scene([2.0, 2.0, 0.0, 0.0])).unwrap();
    let a = normalised.pose_at(1.5).skinned[0].clone().unwrap();
    let b = raw.pose_at(1.5).skinned[0].clone().unwrap();
    assert!(close(a.positions[2], b.positions[2]));
    // Without renormalisation the vertex would be scaled by 4 away from the origin.
    assert!(b.positions[2].y < 1.2);
    // All-zero weights fall back to the first slot (joint 0 here).
    let zero = Animator::new(&two_joint_scene([0.0; 4])).unwrap();
    let z = zero.pose_at(1.5).skinned[0].clone().unwrap();
    assert!(close(z.positions[2], Vec3::new(-5.0, 1.2, 0.0)));
}

#[test]
fn skeleton_moved_with_the_mesh_node_is_rigid_not_skinned() {
    let mut scene = two_joint_scene([0.5, 0.5, 0.0, 0.0]);
    // A common parent above both the skeleton and the mesh node, animated instead of a joint.
    scene.nodes.push(node("wrapper", None, Vec3::ZERO));
    scene.nodes[0].parent = Some(3);
    scene.nodes[2].parent = Some(3);
    scene.animations[0].channels[0].node = 3;
    let a = Animator::new(&scene).unwrap();
    assert_eq!(a.motion(), &[Motion::Rigid]);
    assert!(a.pose_at(1.5).skinned[0].is_none());
}

#[test]
fn walker_follows_a_closed_path_facing_forward() {
    let mut scene = sliding_scene();
    scene.playing.clear();
    scene.walkers.push(Walker {
        node: 0,
        points: vec![
            Vec3::ZERO,
            Vec3::new(4.0, 0.0, 0.0),
            Vec3::new(4.0, 0.0, 4.0),
            Vec3::new(0.0, 0.0, 4.0),
        ],
        speed: 2.0,
        closed: true,
        rotation: Quat::IDENTITY,
        centre: Vec3::ZERO,
        lift: 0.0,
        roll_radius: None,
    });
    let a = Animator::new(&scene).unwrap();
    assert_eq!(a.motion(), &[Motion::Rigid]);
    let at = |t: f32| a.pose_at(t).transforms[0];
    // t = 1: 2 m along the first side, facing +x (the asset's +z turned to +x).
    assert!(close(at(1.0).translation.into(), Vec3::new(2.0, 0.0, 0.0)));
    assert!(close(at(1.0).transform_vector3(Vec3::Z), Vec3::X));
    // t = 3: 6 m: halfway up the second side, facing +z.
    assert!(close(at(3.0).translation.into(), Vec3::new(4.0, 0.0, 2.0)));
    assert!(close(at(3.0).transform_vector3(Vec3::Z), Vec3::Z));
    // t = 7: the closing side back to the start, facing -z.
    assert!(close(at(7.0).translation.into(), Vec3::new(0.0, 0.0, 2.0)));
    assert!(close(at(7.0).transform_vector3(Vec3::Z), -Vec3::Z));
    // One lap is 16 m = 8 s.
    assert!(at(9.0).abs_diff_eq(at(1.0), 1e-5));
    // Exactly at a corner the heading is halfway round it.
    let diagonal = Vec3::new(1.0, 0.0, 1.0).normalize();
    assert!(close(at(2.0).transform_vector3(Vec3::Z), diagonal));
}

#[test]
fn open_walker_turns_back_and_centres_its_pivot() {
    let mut scene = sliding_scene();
    scene.playing.clear();
    scene.walkers.push(Walker {
        node: 0,
        points: vec![Vec3::ZERO, Vec3::new(4.0, 0.0, 0.0)],
        speed: 1.0,
        closed: false,
        rotation: Quat::IDENTITY,
        centre: Vec3::new(1.0, 0.5, 0.0),
        lift: 0.8,
        roll_radius: None,
    });
    let a = Animator::new(&scene).unwrap();
    // t = 5: back at 3 m, facing -x; the centre sits 0.8 m above the path point.
    let t = a.pose_at(5.0).transforms[0];
    assert!(close(t.transform_vector3(Vec3::Z), -Vec3::X));
    assert!(close(
        t.transform_point3(Vec3::new(1.0, 0.5, 0.0)),
        Vec3::new(3.0, 0.8, 0.0)
    ));
    let t = a.pose_at(1.0).transforms[0];
    assert!(close(
        t.transform_point3(Vec3::new(1.0, 0.5, 0.0)),
        Vec3::new(1.0, 0.8, 0.0)
    ));
}

#[test]
fn rolling_walker_turns_by_distance_over_radius() {
    let mut scene = sliding_scene();
    scene.playing.clear();
    scene.walkers.push(Walker {
        node: 0,
        points: vec![Vec3::ZERO, Vec3::new(0.0, 0.0, 100.0)],
        speed: 1.0,
        closed: false,
        rotation: Quat::IDENTITY,
        centre: Vec3::ZERO,
        lift: 0.5,
        roll_radius: Some(0.5),
    });
    let a = Animator::new(&scene).unwrap();
    // After π/4 m a ball of radius 0.5 has turned π/2 forward: its top now points along +z.
    let t = a.pose_at(FRAC_PI_4).transforms[0];
    assert!(
        close(t.transform_vector3(Vec3::Y), Vec3::Z),
        "{}",
        t.transform_vector3(Vec3::Y)
    );
    assert!(close(t.translation.into(), Vec3::new(0.0, 0.5, FRAC_PI_4)));
}

#[test]
fn inconsistent_data_is_an_error() {
    let mut bad = sliding_scene();
    bad.animations[0].channels[0].values.pop();
    assert!(matches!(
        Animator::new(&bad),
        Err(AnimationError::Channel { .. })
    ));
    let mut cycle = sliding_scene();
    cycle.nodes.push(node("a", Some(0), Vec3::ZERO));
    cycle.nodes[0].parent = Some(1);
    assert_eq!(Animator::new(&cycle).unwrap_err(), AnimationError::Cycle);
    let mut joint = two_joint_scene([0.5, 0.5, 0.0, 0.0]);
    joint.meshes[0].joints[1] = [7, 0, 0, 0];
    assert!(matches!(
        Animator::new(&joint),
        Err(AnimationError::Index { .. })
    ));
    let mut walker = sliding_scene();
    walker.nodes.push(node("child", Some(0), Vec3::ZERO));
    walker.walkers.push(Walker {
        node: 1,
        points: vec![Vec3::ZERO],
        speed: 1.0,
        closed: true,
        rotation: Quat::IDENTITY,
        centre: Vec3::ZERO,
        lift: 0.0,
        roll_radius: None,
    });
    assert!(matches!(
        Animator::new(&walker),
        Err(AnimationError::Walker { .. })
    ));
}
