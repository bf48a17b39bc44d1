//! Loads every shared scene and character file and checks what the data README states.

mod common;

use glam::{Mat4, Vec3};
use psao_scene::{load, load_scene, AnimatedProperty, Scene};

fn assert_valid(scene: &Scene) {
    for inst in &scene.instances {
        let mesh = &scene.meshes[inst.mesh];
        assert!(inst.transform.is_finite());
        assert!(mesh.material < scene.materials.len());
        assert_eq!(mesh.normals.len(), mesh.positions.len(), "{}", mesh.name);
        assert!(mesh.uvs.is_empty() || mesh.uvs.len() == mesh.positions.len());
        let n = mesh.positions.len() as u32;
        assert!(
            mesh.indices.iter().flatten().all(|&i| i < n),
            "{}",
            mesh.name
        );
        assert!(
            mesh.normals.iter().all(|v| (v.length() - 1.0).abs() < 1e-3),
            "{}: non-unit normal",
            mesh.name
        );
        if let Some(node) = inst.node {
            assert!(node < scene.nodes.len());
        }
        if let Some(s) = inst.skin {
            let joints = scene.skins[s].joints.len();
            assert!(mesh.joints.iter().flatten().all(|&j| (j as usize) < joints));
        }
    }
    for n in &scene.nodes {
        assert!(n.parent.is_none_or(|p| p < scene.nodes.len()));
    }
    for a in &scene.animations {
        for c in &a.channels {
            assert!(c.node < scene.nodes.len());
            assert!(c.times.windows(2).all(|w| w[0] <= w[1]));
        }
    }
}

/// Every vertex weight set sums to one.
fn assert_weights_normalised(scene: &Scene) {
    for mesh in scene.meshes.iter().filter(|m| !m.weights.is_empty()) {
        assert_eq!(mesh.weights.len(), mesh.positions.len());
        assert_eq!(mesh.joints.len(), mesh.positions.len());
        for w in &mesh.weights {
            let sum: f32 = w.iter().sum();
            assert!((sum - 1.0).abs() < 1e-5, "{}: weights {w:?}", mesh.name);
            assert!(w.iter().all(|&x| x >= 0.0));
        }
    }
}

/// At rest, every joint's world · inverse-bind maps mesh space like the instance transform
/// (the bind pose is the rest pose in these files).
fn assert_bind_pose_matches_instance(scene: &Scene) {
    let world = world_transforms(scene);
    for inst in scene.instances.iter().filter(|i| i.skin.is_some()) {
        let skin = &scene.skins[inst.skin.unwrap()];
        let expected = Mat4::from(inst.transform);
        let mesh = &scene.meshes[inst.mesh];
        let used: std::collections::BTreeSet<u16> = mesh.joints.iter().flatten().copied().collect();
        for j in used {
            let m = world[skin.joints[j as usize]] * skin.inverse_bind[j as usize];
            assert!(
                m.abs_diff_eq(expected, 2e-3),
                "{}: joint {j}: {m:?} vs {expected:?}",
                mesh.name
            );
        }
    }
}

fn world_transforms(scene: &Scene) -> Vec<Mat4> {
    fn world(scene: &Scene, i: usize) -> Mat4 {
        let local = Mat4::from(scene.nodes[i].local_transform());
        match scene.nodes[i].parent {
            Some(p) => world(scene, p) * local,
            None => local,
        }
    }
    (0..scene.nodes.len()).map(|i| world(scene, i)).collect()
}

#[test]
fn sponza_obj() {
    let Some(dir) = common::data_dir() else {
        return;
    };
    let loaded = load(&dir.join("scenes/dabrovic_sponza.obj")).unwrap();
    assert!(loaded.camera_paths.is_empty());
    let scene = loaded.scene;
    assert_valid(&scene);
    assert_eq!(scene.instanced_triangle_count(), 66_447);
    assert_eq!(scene.instances.len(), scene.meshes.len());
    assert!(scene.meshes.len() >= 33, "{} meshes", scene.meshes.len());
    assert_eq!(scene.materials.len(), scene.meshes.len());
    assert!(scene.meshes.iter().all(|m| m.uvs.is_empty()));
    assert!(scene.nodes.is_empty() && scene.animations.is_empty());
    let (lo, hi) = scene.bounds();
    assert!((hi - lo).max_element() > 20.0, "{lo} {hi}");
}

#[test]
fn arcade_gltf() {
    let Some(dir) = common::data_dir() else {
        return;
    };
    let scene = load_scene(&dir.join("scenes/arcade/arcade_with_animated_things4.gltf")).unwrap();
    assert_valid(&scene);
    assert_eq!(scene.instanced_triangle_count(), 53_757);
    assert_eq!(scene.nodes.len(), 14);
    assert_eq!(scene.meshes.len(), 29, "one mesh per primitive");
    assert!(scene.skins.is_empty());
    let clips: Vec<(&str, usize)> = scene
        .animations
        .iter()
        .map(|a| (a.name.as_str(), a.channels.len()))
        .collect();
    assert_eq!(
        clips,
        [
            ("CabinetAction.001", 2),
            ("ChairAction", 2),
            ("Chair2Action", 2),
            ("Palm_03.001Action", 2),
            ("posterAction", 3)
        ]
    );
    assert_eq!(scene.playing, vec![0, 1, 2, 3, 4]);
    for a in &scene.animations {
        assert!(
            a.duration() > 0.0 && a.duration() <= 10.0 + 1e-3,
            "{}",
            a.duration()
        );
        for c in &a.channels {
            let per_key = if c.property == AnimatedProperty::Rotation {
                4
            } else {
                3
            };
            assert_eq!(c.values.len(), c.times.len() * per_key);
        }
    }
    assert!(scene
        .meshes
        .iter()
        .all(|m| m.uvs.len() == m.positions.len()));
}

#[test]
fn cylinder_engine_glb() {
    let Some(dir) = common::data_dir() else {
        return;
    };
    let scene = load_scene(&dir.join("scenes/2CylinderEngine.glb")).unwrap();
    assert_valid(&scene);
    assert_eq!(scene.instanced_triangle_count(), 121_496);
    assert_eq!(scene.nodes.len(), 82);
    assert_eq!(scene.materials.len(), 34);
    assert!(scene.animations.is_empty());
}

#[test]
fn fox_glb_computes_normals() {
    let Some(dir) = common::data_dir() else {
        return;
    };
    let scene = load_scene(&dir.join("characters/Fox.glb")).unwrap();
    assert_valid(&scene);
    assert_weights_normalised(&scene);
    assert_bind_pose_matches_instance(&scene);
    assert_eq!(scene.instanced_triangle_count(), 576);
    assert_eq!(scene.skins.len(), 1);
    assert_eq!(scene.skins[0].joints.len(), 24);
    assert_eq!(scene.skins[0].inverse_bind.len(), 24);
    assert_eq!(scene.instances.len(), 1);
    assert_eq!(scene.instances[0].skin, Some(0));
    let mesh = &scene.meshes[0];
    // The file has no NORMAL attribute: the computed normals must follow the surface.
    // Every triangle's face normal agrees with the mean of its vertex normals.
    let mut agree = 0;
    for t in &mesh.indices {
        let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
        let face = (b - a).cross(c - a).normalize_or_zero();
        let mean: Vec3 = t.iter().map(|&i| mesh.normals[i as usize]).sum();
        agree += usize::from(face.dot(mean) > 0.0);
    }
    assert!(
        agree * 100 >= mesh.indices.len() * 95,
        "{agree} of {}",
        mesh.indices.len()
    );
    let clips: Vec<(&str, f32)> = scene
        .animations
        .iter()
        .map(|a| (a.name.as_str(), a.duration()))
        .collect();
    assert_eq!(clips.len(), 3);
    for ((name, d), (want, want_d)) in
        clips
            .iter()
            .zip([("Survey", 3.42), ("Walk", 0.71), ("Run", 1.16)])
    {
        assert_eq!(*name, want);
        assert!((d - want_d).abs() < 0.01, "{name}: {d}");
    }
}

#[test]
fn cesium_man_gltf() {
    let Some(dir) = common::data_dir() else {
        return;
    };
    let scene = load_scene(&dir.join("characters/CesiumMan/CesiumMan.gltf")).unwrap();
    assert_valid(&scene);
    assert_weights_normalised(&scene);
    assert_bind_pose_matches_instance(&scene);
    assert_eq!(scene.instanced_triangle_count(), 4_672);
    assert_eq!(scene.skins[0].joints.len(), 19);
    assert_eq!(scene.animations.len(), 1);
    assert!((scene.animations[0].duration() - 2.0).abs() < 0.05);
    assert_eq!(scene.instances[0].skin, Some(0));
}

#[test]
fn rigged_simple_glb() {
    let Some(dir) = common::data_dir() else {
        return;
    };
    let scene = load_scene(&dir.join("characters/RiggedSimple.glb")).unwrap();
    assert_valid(&scene);
    assert_weights_normalised(&scene);
    assert_bind_pose_matches_instance(&scene);
    assert_eq!(scene.instanced_triangle_count(), 188);
    assert_eq!(scene.skins[0].joints.len(), 2);
    assert!((scene.animations[0].duration() - 2.08).abs() < 0.01);
}

#[test]
fn rigged_figure_weights_are_renormalised() {
    let Some(dir) = common::data_dir() else {
        return;
    };
    let path = dir.join("characters/RiggedFigure.glb");
    // The raw file really is not normalised (otherwise this test proves nothing).
    let (doc, buffers, _) = gltf::import(&path).unwrap();
    let prim = doc.meshes().next().unwrap().primitives().next().unwrap();
    let reader = prim.reader(|b| Some(&buffers[b.index()]));
    let worst = reader
        .read_weights(0)
        .unwrap()
        .into_f32()
        .map(|w| (w.iter().sum::<f32>() - 1.0).abs())
        .fold(0.0, f32::max);
    assert!(worst > 1e-3, "raw weights already normalised ({worst})");

    let scene = load_scene(&path).unwrap();
    assert_valid(&scene);
    assert_weights_normalised(&scene);
    assert_bind_pose_matches_instance(&scene);
    assert_eq!(scene.instanced_triangle_count(), 256);
    assert_eq!(scene.skins[0].joints.len(), 19);
    assert!((scene.animations[0].duration() - 1.25).abs() < 0.01);
}
