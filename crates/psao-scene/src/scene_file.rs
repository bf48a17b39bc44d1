//! Scene files: TOML that composes assets into one scene.
//!
//! ```toml
//! ao_radius = 0.6                       # optional, default model::DEFAULT_AO_RADIUS
//! camera_paths = ["../paths/x.toml"]    # optional, relative to the scene file
//! environment = "../data/sky.hdr"       # optional: Radiance HDR latitude–longitude map, relative
//! environment_intensity = 1.0           # optional (1), ≥ 0: factor on the map
//! environment_rotation_deg = 0.0        # optional (0): turn of the map about +Y
//! sky = [0.6, 0.6, 0.6]                 # optional, without `environment`: constant sky radiance
//!                                       #   (default environment::DEFAULT_SKY)
//! [[asset]]
//! file = "../data/sponza.obj"           # relative to the scene file; "builtin:default" = built-in scene
//! translation = [0.0, 0.0, 0.0]         # optional
//! rotation_deg = [0.0, 0.0, 0.0]        # optional: about X, then Y, then Z (fixed axes)
//! scale = 1.0                           # optional, number or [x, y, z]
//! animations = ["Walk"]                 # optional: clip names or "all"; default: the asset's playing clips
//! # optional, at most one of:
//! walk = { points = [[0, 0, 0], [4, 0, 0]], speed = 1.2, loop = true, roll = false }
//! keys = { times = [0, 1], translation = [[0, 2, 0], [0, 0, 0]], rotation_deg = [[0, 0, 0], [90, 0, 0]], interpolation = "linear" }
//!
//! [[volume]]                            # optional, at most one: a medium occluding AO rays
//! file = "../data/smoke.vdb"            # .vdb or .psv, relative; a list of .vdb = flip-book frames
//! translation = [0.0, 0.0, 0.0]         # optional: placed point = translation + rotation · (scale ⊙ v)
//! rotation_deg = [0.0, 0.0, 0.0]        # optional, as for assets
//! scale = 0.1                           # optional, number or [x, y, z], positive
//! density_scale = 2.0                   # optional (1): extinction per metre at the densest voxel
//! format = "f16"                        # optional: in-memory bricks for .vdb (f32|f16|unorm8|bc4|bc7)
//! frame = 0                             # optional: the flip-book frame used (no playback)
//!
//! [[light]]                             # optional, any number: lights of the diffuse lighting and corrections
//! kind = "sun"                          # sun | point | rect
//! direction = [0.35, 1.0, 0.6]          # sun: towards the light
//! keys = { times = [0, 30], direction = [[1, 1, 0], [-1, 1, 0]] } # sun, instead of direction: turns over time
//! position = [0.0, 3.0, 0.0]            # point; rect: its centre
//! size = [1.0, 0.5]                     # rect: edge lengths
//! normal = [0.0, -1.0, 0.0]             # rect: the side it emits to (default down)
//! color = [1.0, 1.0, 1.0]               # optional, components in [0, 1]
//! power = 2.0                           # ≥ 0: sun irradiance, point intensity, rect radiance
//!
//! [[material]]                          # optional, any number: override materials by name
//! name = "stone"                        # every material of this name, in every asset
//! preset = "chrome"                     # optional: chrome | mirror | glossy | glass
//! base_color = [0.9, 0.9, 0.9]          # optional, and any of metallic, roughness,
//! roughness = 0.05                      #   transmission (all in [0, 1]) and ior (in [1, 5])
//! ```
//!
//! Lights of the built-in default scene come along with it (moved by the asset transform).
//! A sun's `keys` turn its direction over scene time: spherical interpolation between
//! consecutive keys (which must not be opposite), looping over the last key time.
//!
//! `file` may also be `builtin:sphere` (radius 0.5), `builtin:box` (1 m cube) or
//! `builtin:cylinder` (radius 0.5, 1 m high, standing on y = 0), each centred on the origin
//! in x and z.
//!
//! Each asset that has a node hierarchy gets a new root node (the *wrapper*) carrying the
//! asset transform, parent of all its former roots; node-less instances get the transform
//! baked in, unless the asset moves (then each gets a node under the wrapper).
//!
//! `walk` carries the wrapper along the path (world points; `loop = true`: closed, round and
//! round; `false`: there and back) at `speed` m/s, keeping the asset's bounds centre above
//! the path at its rest height and turning its +Z axis (after `rotation_deg`) to the
//! direction of travel; `roll = true` also rolls it as a ball of half its height. `walk`
//! replaces `translation`. `keys` animates the wrapper's translation and/or rotation
//! (absolute, replacing `translation` / `rotation_deg` where given), looping over the last
//! key time. The asset's own clips keep playing in both cases.

use std::path::Path;

use glam::{Quat, Vec3};
use serde::Deserialize;

use crate::error::{read_file, toml_message, SceneError};
use crate::load::{load_asset, LoadedScene};
use crate::model::{Node, Scene, DEFAULT_AO_RADIUS};

mod motion;
mod shading;
mod sky;
mod volume;

use motion::{KeysEntry, WalkEntry};
pub use volume::SceneVolume;
use volume::VolumeEntry;

/// The `file` value naming the built-in default scene.
pub const BUILTIN_DEFAULT: &str = "builtin:default";

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneFile {
    ao_radius: Option<f32>,
    #[serde(default)]
    camera_paths: Vec<String>,
    #[serde(default)]
    asset: Vec<AssetEntry>,
    #[serde(default)]
    volume: Vec<VolumeEntry>,
    #[serde(default)]
    light: Vec<shading::LightEntry>,
    #[serde(default)]
    material: Vec<shading::MaterialEntry>,
    environment: Option<String>,
    environment_intensity: Option<f32>,
    environment_rotation_deg: Option<f32>,
    sky: Option<[f32; 3]>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct AssetEntry {
    file: String,
    translation: Option<[f32; 3]>,
    #[serde(default)]
    rotation_deg: [f32; 3],
    scale: Option<Scale>,
    animations: Option<Vec<String>>,
    walk: Option<WalkEntry>,
    keys: Option<KeysEntry>,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum Scale {
    Uniform(f32),
    PerAxis([f32; 3]),
}

/// Loads a scene file and every asset it lists (camera paths are resolved, checked to
/// exist, but not parsed).
pub fn load(path: &Path) -> Result<LoadedScene, SceneError> {
    let bad = |message: String| SceneError::parse(path, "scene file", message);
    let bytes = read_file(path)?;
    let text = String::from_utf8(bytes).map_err(|_| bad("file is not UTF-8 text".into()))?;
    let file: SceneFile = toml::from_str(&text).map_err(|e| bad(toml_message(&text, &e)))?;
    let dir = path.parent().unwrap_or_else(|| Path::new(""));

    let ao_radius = file.ao_radius.unwrap_or(DEFAULT_AO_RADIUS);
    if !(ao_radius.is_finite() && ao_radius > 0.0) {
        return Err(bad(format!(
            "ao_radius must be a positive number, got {ao_radius}"
        )));
    }
    if file.asset.is_empty() {
        return Err(bad("no [[asset]] entries".into()));
    }
    let mut scene = Scene {
        ao_radius,
        ..Default::default()
    };
    for (i, entry) in file.asset.iter().enumerate() {
        let (translation, rotation, scale) =
            entry_trs(entry).map_err(|m| bad(format!("asset {i} ({}): {m}", entry.file)))?;
        let what = |m: String| bad(format!("asset {i} ({}): {m}", entry.file));
        let mut asset = if entry.file == BUILTIN_DEFAULT {
            crate::builtin::default_scene()
        } else if let Some(shape) = entry.file.strip_prefix("builtin:") {
            crate::builtin::shape_asset(shape).ok_or_else(|| {
                what("unknown built-in asset (builtin:default, builtin:sphere, builtin:box, builtin:cylinder)".into())
            })?
        } else {
            let asset_path = dir.join(&entry.file);
            let is_scene_file = asset_path
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("toml"));
            if is_scene_file {
                return Err(SceneError::unsupported(
                    path,
                    format!(
                        "asset {i} ({}): scene files cannot include scene files",
                        entry.file
                    ),
                ));
            }
            load_asset(&asset_path).map_err(|e| SceneError::Asset {
                scene: path.to_path_buf(),
                source: Box::new(e),
            })?
        };
        let playing = select_clips(&asset, entry.animations.as_deref()).map_err(what)?;
        let mut wrapper = Node {
            name: format!("asset:{}", entry.file),
            parent: None,
            translation,
            rotation,
            scale,
        };
        if entry.walk.is_some() && (entry.keys.is_some() || entry.translation.is_some()) {
            return Err(what("walk excludes keys and translation".into()));
        }
        let mut walker = None;
        let mut keys = None;
        if entry.walk.is_some() || entry.keys.is_some() {
            motion::attach_loose_instances(&mut asset);
            asset.playing = playing.clone();
        }
        if let Some(w) = &entry.walk {
            let (w, t, r) = motion::walker(w, &asset, rotation, scale).map_err(what)?;
            (wrapper.translation, wrapper.rotation) = (t, r);
            walker = Some(w);
        }
        if let Some(k) = &entry.keys {
            let (clip, t, r) =
                motion::keys_clip(k, &entry.file, 0, (translation, rotation)).map_err(what)?;
            (wrapper.translation, wrapper.rotation) = (t, r);
            keys = Some(clip);
        }
        let root = append(&mut scene, asset, wrapper, playing);
        if let (Some(mut w), Some(root)) = (walker, root) {
            w.node = root;
            scene.walkers.push(w);
        }
        if let (Some(mut clip), Some(root)) = (keys, root) {
            clip.channels.iter_mut().for_each(|c| c.node = root);
            scene.animations.push(clip);
            scene.playing.push(scene.animations.len() - 1);
        }
    }

    shading::apply_overrides(&mut scene, &file.material).map_err(bad)?;
    for (i, entry) in file.light.iter().enumerate() {
        let (light, keys) = shading::light(entry, scene.lights.len())
            .map_err(|m| bad(format!("light {i}: {m}")))?;
        scene.lights.push(light);
        scene.sun_keys.extend(keys);
    }
    let sky = sky::SkyEntries {
        environment: file.environment.as_deref(),
        intensity: file.environment_intensity,
        rotation_deg: file.environment_rotation_deg,
        sky: file.sky,
    };
    scene.environment = sky::environment(&sky, dir, bad)?;

    if file.volume.len() > 1 {
        return Err(bad(format!(
            "{} [[volume]] entries: at most one volume is supported",
            file.volume.len()
        )));
    }
    let volumes = file
        .volume
        .iter()
        .enumerate()
        .map(|(i, v)| {
            volume::scene_volume(path, dir, v).map_err(|m| bad(format!("volume {i}: {m}")))
        })
        .collect::<Result<Vec<_>, _>>()?;

    let mut camera_paths = Vec::with_capacity(file.camera_paths.len());
    for p in &file.camera_paths {
        let resolved = dir.join(p);
        if !resolved.is_file() {
            return Err(bad(format!(
                "camera path file '{}' not found",
                resolved.display()
            )));
        }
        camera_paths.push(resolved);
    }
    Ok(LoadedScene {
        scene,
        camera_paths,
        volumes,
    })
}

/// Validated asset transform as (translation, rotation, scale).
fn entry_trs(e: &AssetEntry) -> Result<(Vec3, Quat, Vec3), String> {
    let t = Vec3::from_array(e.translation.unwrap_or_default());
    let r = motion::euler_deg(e.rotation_deg);
    let s = match e.scale {
        None => Vec3::ONE,
        Some(Scale::Uniform(s)) => Vec3::splat(s),
        Some(Scale::PerAxis(s)) => Vec3::from_array(s),
    };
    if !(t.is_finite() && r.is_finite() && s.is_finite()) {
        return Err("non-finite transform".into());
    }
    if s.cmpeq(Vec3::ZERO).any() {
        return Err("scale must not be zero".into());
    }
    Ok((t, r, s))
}

/// Indices (into the asset's clips) of the clips that play.
fn select_clips(asset: &Scene, names: Option<&[String]>) -> Result<Vec<usize>, String> {
    let Some(names) = names else {
        return Ok(asset.playing.clone());
    };
    let mut out = Vec::new();
    for name in names {
        if name == "all" {
            out.extend(0..asset.animations.len());
            continue;
        }
        match asset.animations.iter().position(|a| &a.name == name) {
            Some(i) => out.push(i),
            None => {
                let known: Vec<&str> = asset.animations.iter().map(|a| a.name.as_str()).collect();
                return Err(format!("no animation named '{name}' (clips: {known:?})"));
            }
        }
    }
    out.sort_unstable();
    out.dedup();
    Ok(out)
}

/// Appends `src` to `dst` under the asset transform `wrapper`, offsetting every index;
/// `playing` indexes `src.animations`. Returns the wrapper's node index (`None` when `src`
/// has no nodes and so gets no wrapper).
fn append(dst: &mut Scene, src: Scene, wrapper: Node, playing: Vec<usize>) -> Option<usize> {
    let asset = wrapper.local_transform();
    let mesh_base = dst.meshes.len();
    let material_base = dst.materials.len();
    let skin_base = dst.skins.len();
    let anim_base = dst.animations.len();
    let root = (!src.nodes.is_empty()).then(|| {
        dst.nodes.push(wrapper);
        dst.nodes.len() - 1
    });
    let node_base = dst.nodes.len();

    dst.nodes.extend(src.nodes.into_iter().map(|mut n| {
        n.parent = n.parent.map(|p| p + node_base).or(root);
        n
    }));
    dst.meshes.extend(src.meshes.into_iter().map(|mut m| {
        m.material += material_base;
        m
    }));
    dst.materials.extend(src.materials);
    dst.lights
        .extend(src.lights.iter().map(|l| l.transformed(&asset)));
    dst.instances.extend(src.instances.into_iter().map(|mut i| {
        i.mesh += mesh_base;
        i.node = i.node.map(|n| n + node_base);
        i.skin = i.skin.map(|s| s + skin_base);
        i.transform = asset * i.transform;
        i
    }));
    dst.skins.extend(src.skins.into_iter().map(|mut s| {
        s.joints.iter_mut().for_each(|j| *j += node_base);
        s
    }));
    dst.animations
        .extend(src.animations.into_iter().map(|mut a| {
            a.channels.iter_mut().for_each(|c| c.node += node_base);
            a
        }));
    dst.playing
        .extend(playing.into_iter().map(|p| p + anim_base));
    dst.walkers.extend(src.walkers.into_iter().map(|mut w| {
        w.node += node_base;
        w
    }));
    root
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{
        AnimatedProperty, Animation, Channel, Instance, Interpolation, Material, Mesh, Skin,
    };
    use glam::{Affine3A, Mat4};

    fn small_asset() -> Scene {
        let node = |parent| Node {
            name: "n".into(),
            parent,
            translation: Vec3::X,
            rotation: Quat::IDENTITY,
            scale: Vec3::ONE,
        };
        Scene {
            meshes: vec![Mesh {
                positions: vec![Vec3::ZERO],
                material: 0,
                ..Default::default()
            }],
            materials: vec![Material::default()],
            nodes: vec![node(None), node(Some(0))],
            instances: vec![Instance {
                mesh: 0,
                node: Some(1),
                transform: Affine3A::from_translation(Vec3::new(2.0, 0.0, 0.0)),
                skin: Some(0),
            }],
            skins: vec![Skin {
                name: "s".into(),
                joints: vec![0, 1],
                inverse_bind: vec![Mat4::IDENTITY; 2],
            }],
            animations: vec![Animation {
                name: "a".into(),
                channels: vec![Channel {
                    node: 1,
                    property: AnimatedProperty::Translation,
                    interpolation: Interpolation::Linear,
                    times: vec![0.0],
                    values: vec![0.0; 3],
                }],
            }],
            playing: vec![0],
            walkers: Vec::new(),
            ao_radius: DEFAULT_AO_RADIUS,
            lights: Vec::new(),
            sun_keys: Vec::new(),
            environment: Default::default(),
        }
    }

    #[test]
    fn append_offsets_every_index_and_wraps_roots() {
        let mut dst = small_asset();
        let wrapper = Node {
            name: "w".into(),
            parent: None,
            translation: Vec3::new(0.0, 5.0, 0.0),
            rotation: Quat::IDENTITY,
            scale: Vec3::ONE,
        };
        append(&mut dst, small_asset(), wrapper, vec![0]);
        assert_eq!(dst.nodes.len(), 5);
        assert_eq!(dst.nodes[2].name, "w");
        assert_eq!(dst.nodes[3].parent, Some(2));
        assert_eq!(dst.nodes[4].parent, Some(3));
        let inst = &dst.instances[1];
        assert_eq!((inst.mesh, inst.node, inst.skin), (1, Some(4), Some(1)));
        assert_eq!(dst.meshes[1].material, 1);
        assert_eq!(dst.skins[1].joints, vec![3, 4]);
        assert_eq!(dst.animations[1].channels[0].node, 4);
        assert_eq!(dst.playing, vec![0, 1]);
        let moved = inst.transform.transform_point3(Vec3::ZERO);
        assert!((moved - Vec3::new(2.0, 5.0, 0.0)).length() < 1e-6);
    }

    #[test]
    fn clip_selection_by_name_and_all() {
        let asset = small_asset();
        assert_eq!(select_clips(&asset, None).unwrap(), vec![0]);
        assert_eq!(
            select_clips(&asset, Some(&["all".into()])).unwrap(),
            vec![0]
        );
        assert!(select_clips(&asset, Some(&[])).unwrap().is_empty());
        let err = select_clips(&asset, Some(&["Walk".into()])).unwrap_err();
        assert!(err.contains("Walk") && err.contains("\"a\""), "{err}");
    }

    #[test]
    fn rotation_is_x_then_y_then_z() {
        let e = AssetEntry {
            file: String::new(),
            translation: None,
            rotation_deg: [90.0, 90.0, 0.0],
            scale: Some(Scale::Uniform(2.0)),
            animations: None,
            walk: None,
            keys: None,
        };
        let (_, r, s) = entry_trs(&e).unwrap();
        // X first maps +Y to +Z, then Y maps +Z to +X.
        assert!((r * Vec3::Y - Vec3::X).length() < 1e-6);
        assert_eq!(s, Vec3::splat(2.0));
    }
}
