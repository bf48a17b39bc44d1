//! Scene files composing several assets with transforms.

mod common;

use std::fs;

use glam::Vec3;
use psao_scene::{load, load_scene, Scene};

fn instance_bounds(scene: &Scene, range: std::ops::Range<usize>) -> (Vec3, Vec3) {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for inst in &scene.instances[range] {
        for p in &scene.meshes[inst.mesh].positions {
            let w = inst.transform.transform_point3(*p);
            lo = lo.min(w);
            hi = hi.max(w);
        }
    }
    (lo, hi)
}

#[test]
fn sponza_plus_two_cesium_men() {
    let Some(data) = common::data_dir() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let sponza = data.join("scenes/dabrovic_sponza.obj");
    let man = data.join("characters/CesiumMan/CesiumMan.gltf");
    fs::create_dir(tmp.path().join("paths")).unwrap();
    fs::write(
        tmp.path().join("paths/walk.toml"),
        "# not parsed by the scene loader\n",
    )
    .unwrap();
    let text = format!(
        r#"
ao_radius = 0.5
camera_paths = ["paths/walk.toml"]

[[asset]]
file = "{sponza}"

[[asset]]
file = "{man}"
translation = [10.0, 0.0, 0.0]

[[asset]]
file = "{man}"
translation = [0.0, 2.0, 0.0]
rotation_deg = [0.0, 90.0, 0.0]
scale = [2.0, 2.0, 2.0]
animations = []
"#,
        sponza = sponza.display(),
        man = man.display()
    );
    let scene_path = tmp.path().join("combo.toml");
    fs::write(&scene_path, text).unwrap();
    let loaded = load(&scene_path).unwrap();
    assert_eq!(
        loaded.camera_paths,
        vec![tmp.path().join("paths/walk.toml")]
    );
    let scene = loaded.scene;
    assert_eq!(scene.ao_radius, 0.5);

    let alone_sponza = load_scene(&sponza).unwrap();
    let alone_man = load_scene(&man).unwrap();
    let ns = alone_sponza.instances.len();
    assert_eq!(scene.instances.len(), ns + 2);
    assert_eq!(scene.instanced_triangle_count(), 66_447 + 2 * 4_672);
    assert_eq!(scene.meshes.len(), alone_sponza.meshes.len() + 2);
    assert_eq!(scene.skins.len(), 2);
    assert_eq!(scene.animations.len(), 2);
    assert_eq!(scene.playing, vec![0], "second man's clips are off");
    // Each character got a wrapper root above its own roots.
    assert_eq!(scene.nodes.len(), 2 * (alone_man.nodes.len() + 1));
    assert_eq!(scene.nodes.iter().filter(|n| n.parent.is_none()).count(), 2);
    let second_skin = &scene.skins[1];
    assert!(second_skin
        .joints
        .iter()
        .all(|&j| j > alone_man.nodes.len()));

    // Sponza unchanged.
    assert_eq!(instance_bounds(&scene, 0..ns), alone_sponza.bounds());
    // First man shifted by +10 in x.
    let (lo0, hi0) = alone_man.bounds();
    let (lo1, hi1) = instance_bounds(&scene, ns..ns + 1);
    assert!(
        (lo1 - (lo0 + Vec3::X * 10.0)).length() < 1e-4,
        "{lo1} vs {lo0}"
    );
    assert!((hi1 - (hi0 + Vec3::X * 10.0)).length() < 1e-4);
    // Second man: scaled 2x, turned 90° about Y (x extent becomes z extent), lifted by 2.
    let (lo2, hi2) = instance_bounds(&scene, ns + 1..ns + 2);
    let (size0, size2) = (hi0 - lo0, hi2 - lo2);
    assert!((size2.y - 2.0 * size0.y).abs() < 1e-3, "{size2} vs {size0}");
    assert!((size2.z - 2.0 * size0.x).abs() < 1e-3, "{size2} vs {size0}");
    assert!((size2.x - 2.0 * size0.z).abs() < 1e-3, "{size2} vs {size0}");
    assert!((lo2.y - (2.0 * lo0.y + 2.0)).abs() < 1e-3);
    // Node-based transforms agree with the instance transform (animation recomputes them).
    let inst = &scene.instances[ns + 1];
    let mut world = scene.nodes[inst.node.unwrap()].local_transform();
    let mut parent = scene.nodes[inst.node.unwrap()].parent;
    while let Some(p) = parent {
        world = scene.nodes[p].local_transform() * world;
        parent = scene.nodes[p].parent;
    }
    assert!(glam::Mat4::from(world).abs_diff_eq(glam::Mat4::from(inst.transform), 1e-4));
}

#[test]
fn builtin_asset_and_clip_selection() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("b.toml");
    fs::write(
        &path,
        "[[asset]]\nfile = \"builtin:default\"\nscale = 2.0\n",
    )
    .unwrap();
    let scene = load_scene(&path).unwrap();
    let alone = psao_scene::builtin::default_scene();
    assert_eq!(scene.instances.len(), alone.instances.len());
    assert_eq!(
        scene.instanced_triangle_count(),
        alone.instanced_triangle_count()
    );
    assert_eq!(scene.playing, alone.playing);
    let (lo, hi) = scene.bounds();
    let (alo, ahi) = alone.bounds();
    assert!(((hi - lo) - 2.0 * (ahi - alo)).length() < 1e-3);
    assert_eq!(scene.ao_radius, psao_scene::DEFAULT_AO_RADIUS);
}

#[test]
fn fox_clip_subset() {
    let Some(data) = common::data_dir() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("fox.toml");
    let fox = data.join("characters/Fox.glb");
    fs::write(
        &path,
        format!(
            "[[asset]]\nfile = \"{}\"\nanimations = [\"Walk\", \"Run\"]\n",
            fox.display()
        ),
    )
    .unwrap();
    let scene = load_scene(&path).unwrap();
    let names: Vec<&str> = scene
        .playing
        .iter()
        .map(|&i| scene.animations[i].name.as_str())
        .collect();
    assert_eq!(names, ["Walk", "Run"]);
}
