//! The rigidly moving objects of the default scene, each a node hierarchy driven by its own
//! looping 10 s animation with linear keys: a ball rolling across the nave, a box sliding and
//! turning on the table, a pendulum hanging from a ceiling beam, and a turntable carrying a
//! crate and a vase.

use std::f32::consts::TAU;

use glam::{Affine3A, Quat, Vec3};

use super::hall::BEAM_BOTTOM;
use super::props::{crate_mesh, vase_mesh, TABLE_TOP, TABLE_X};
use super::shapes::{append, cuboid, cylinder, sphere};
use super::{Palette, SceneBuilder};
use crate::model::{AnimatedProperty, Animation, Channel, Interpolation, Mesh};

/// Length of every clip in seconds.
pub(super) const LOOP_SECONDS: f32 = 10.0;

/// Builds the moving objects and their animations.
pub(super) fn build(b: &mut SceneBuilder, p: &Palette) {
    rolling_ball(b, p);
    sliding_box(b, p);
    pendulum(b, p);
    turntable(b, p);
}

/// Samples a node's pose at `keys + 1` evenly spaced times over the loop and returns the
/// translation and rotation channels (rotations kept in one hemisphere so slerp is short).
fn sampled_channels(node: usize, keys: usize, pose: impl Fn(f32) -> (Vec3, Quat)) -> Vec<Channel> {
    let times: Vec<f32> = (0..=keys)
        .map(|k| LOOP_SECONDS * k as f32 / keys as f32)
        .collect();
    let mut translations = Vec::with_capacity(3 * times.len());
    let mut rotations = Vec::with_capacity(4 * times.len());
    let mut previous = Quat::IDENTITY;
    for &t in &times {
        let (translation, mut rotation) = pose(t);
        if rotation.dot(previous) < 0.0 {
            rotation = -rotation;
        }
        previous = rotation;
        translations.extend(translation.to_array());
        rotations.extend(rotation.to_array());
    }
    let channel = |property, values| Channel {
        node,
        property,
        interpolation: Interpolation::Linear,
        times: times.clone(),
        values,
    };
    vec![
        channel(AnimatedProperty::Translation, translations),
        channel(AnimatedProperty::Rotation, rotations),
    ]
}

/// Adds a root node posed at `pose(0)` with an animation clip of the sampled pose.
fn animated_root(
    b: &mut SceneBuilder,
    name: &str,
    keys: usize,
    pose: impl Fn(f32) -> (Vec3, Quat),
) -> usize {
    let (translation, rotation) = pose(0.0);
    let node = b.node(name, None, translation, rotation);
    b.scene.animations.push(Animation {
        name: name.into(),
        channels: sampled_channels(node, keys, pose),
    });
    node
}

/// A red ball (r = 0.25 m) rolling without slipping along z = 1.5 from x = -6 to 5 and back.
fn rolling_ball(b: &mut SceneBuilder, p: &Palette) {
    const R: f32 = 0.25;
    let x = |t: f32| -0.5 - 5.5 * (TAU * t / LOOP_SECONDS).cos();
    let node = animated_root(b, "rolling_ball", 80, |t| {
        let travelled = x(t) - x(0.0);
        (
            Vec3::new(x(t), R, 1.5),
            Quat::from_rotation_z(-travelled / R),
        )
    });
    let mesh = b.mesh(sphere(R, 48), "rolling_ball", p.paint);
    b.place_on_node(mesh, node);
}

/// A small box sliding back and forth on the table while turning by up to 90°.
fn sliding_box(b: &mut SceneBuilder, p: &Palette) {
    let half = Vec3::new(0.1, 0.06, 0.075);
    let node = animated_root(b, "sliding_box", 20, |t| {
        let phase = 0.5 - 0.5 * (TAU * t / LOOP_SECONDS).cos();
        (
            Vec3::new(TABLE_X - 0.55 + 0.8 * phase, TABLE_TOP + half.y, 0.12),
            Quat::from_rotation_y(phase * 90f32.to_radians()),
        )
    });
    let mesh = b.mesh(cuboid(half), "sliding_box", p.paint);
    b.place_on_node(mesh, node);
}

/// A brass pendulum hanging from the ceiling beam at x = 3, swinging ±25° in the x–y plane
/// with a 5 s period; its bob passes 0.5 m above the floor.
fn pendulum(b: &mut SceneBuilder, p: &Palette) {
    const LENGTH: f32 = 4.9;
    let pivot = Vec3::new(3.0, BEAM_BOTTOM, 0.0);
    let node = animated_root(b, "pendulum", 40, |t| {
        let swing = 25f32.to_radians() * (2.0 * TAU * t / LOOP_SECONDS).cos();
        (pivot, Quat::from_rotation_z(swing))
    });
    let mut rod = Mesh::default();
    append(
        &mut rod,
        &cylinder(0.012, LENGTH, 12),
        Affine3A::from_translation(Vec3::new(0.0, -LENGTH, 0.0)),
    );
    append(
        &mut rod,
        &cuboid(Vec3::new(0.04, 0.03, 0.04)),
        Affine3A::from_translation(Vec3::new(0.0, -0.03, 0.0)),
    );
    let rod = b.mesh(rod, "pendulum_rod", p.brass);
    let rod_node = b.node("pendulum_rod", Some(node), Vec3::ZERO, Quat::IDENTITY);
    b.place_on_node(rod, rod_node);
    let bob = b.mesh(sphere(0.2, 40), "pendulum_bob", p.brass);
    let bob_node = b.node(
        "pendulum_bob",
        Some(node),
        Vec3::new(0.0, -LENGTH, 0.0),
        Quat::IDENTITY,
    );
    b.place_on_node(bob, bob_node);
}

/// A low round turntable in the west of the nave, turning once per loop, carrying a crate and
/// a vase.
fn turntable(b: &mut SceneBuilder, p: &Palette) {
    const DISC_HEIGHT: f32 = 0.08;
    let node = animated_root(b, "turntable", 20, |t| {
        (
            Vec3::new(-7.4, 0.0, 0.0),
            Quat::from_rotation_y(TAU * t / LOOP_SECONDS),
        )
    });
    let disc = b.mesh(
        cylinder(0.6, DISC_HEIGHT, 48),
        "turntable_disc",
        p.wood_dark,
    );
    let disc_node = b.node("turntable_disc", Some(node), Vec3::ZERO, Quat::IDENTITY);
    b.place_on_node(disc, disc_node);
    let crate_ = b.mesh(crate_mesh(0.4), "turntable_crate", p.wood);
    let crate_node = b.node(
        "turntable_crate",
        Some(node),
        Vec3::new(0.22, DISC_HEIGHT, 0.12),
        Quat::from_rotation_y(0.3),
    );
    b.place_on_node(crate_, crate_node);
    let vase = b.mesh(vase_mesh(0.6, 0.16), "turntable_vase", p.terracotta);
    let vase_node = b.node(
        "turntable_vase",
        Some(node),
        Vec3::new(-0.28, DISC_HEIGHT, -0.15),
        Quat::IDENTITY,
    );
    b.place_on_node(vase, vase_node);
}
