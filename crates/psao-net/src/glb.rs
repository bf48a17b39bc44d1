//! The served scene as binary glTF (`/scene.glb`), for the browser viewer.
//!
//! Node `i` (for `i` below the instance count) is instance `i` of the welcome's instance
//! table, at the root with its rest transform, its mesh and (when skinned) its skin; the
//! scene's own node hierarchy follows, shifted by the instance count, so skins' joints and
//! animation channels address it. Meshes carry positions, normals, indices and, when skinned,
//! `JOINTS_0`/`WEIGHTS_0`; materials their base colour, metallic/roughness, alpha mode and
//! sidedness. Walkers (procedural motion) have no glTF form: their instances move by the
//! transforms the server sends.
//!
//! What psao-scene's `Animator` needs beyond glTF rides in `extras`: the document's
//! `psao_playing` lists the animations that play (each looping over its own duration), and an
//! instance node that deforms by skinning (`Motion::Skinned`) carries `psao_skinned: true`
//! and `psao_node`, the node whose world transform is the instance's own (joint matrices are
//! taken relative to it), or null for an instance at its stored transform.
//!
//! The scene's camera paths ride along in the document's `extras.psao_camera_paths`, sampled
//! at the 60 Hz of `psao view` (one camera per path frame: position, target, up, vertical
//! FOV, near, far), so the browser follows a path by name with exactly the cameras the CPU
//! client uses.
//!
//! The lights the client shadow-maps ride in `extras.psao_lights` (see [`lights_json`]): the
//! scene's suns (with their time keys) and point lights, as `Scene::lights_at` turns them;
//! rectangle lights are left out, their soft light reaches clients through the points'
//! irradiance.
//!
//! The JSON document is built with `serde_json` rather than `gltf-json`, whose typed structs
//! need every optional field spelled out (and change with the workspace's `gltf` features);
//! the container is written by `gltf::binary::Glb`, and the tests read the result back with
//! the `gltf` crate.

use std::borrow::Cow;

use glam::Mat4;
use psao_scene::path::CameraPath;
use psao_scene::{AlphaMode, AnimatedProperty, Interpolation, Motion, Scene};
use serde_json::{json, Value};

use crate::NetError;

const FLOAT: u32 = 5126;
const UNSIGNED_SHORT: u32 = 5123;
const UNSIGNED_INT: u32 = 5125;
const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;

/// The binary buffer and the accessors into it, built together.
#[derive(Default)]
struct Builder {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Builder {
    /// Appends `bytes` as a buffer view and an accessor of `count` elements; returns the
    /// accessor's index.
    fn accessor(
        &mut self,
        bytes: &[u8],
        count: usize,
        component: u32,
        kind: &str,
        target: Option<u32>,
        bounds: Option<(Vec<f32>, Vec<f32>)>,
    ) -> usize {
        self.bin.resize(self.bin.len().next_multiple_of(4), 0);
        let mut view = json!({
            "buffer": 0,
            "byteOffset": self.bin.len(),
            "byteLength": bytes.len(),
        });
        if let Some(t) = target {
            view["target"] = json!(t);
        }
        self.bin.extend_from_slice(bytes);
        self.views.push(view);
        let mut acc = json!({
            "bufferView": self.views.len() - 1,
            "componentType": component,
            "count": count,
            "type": kind,
        });
        if let Some((min, max)) = bounds {
            acc["min"] = json!(min);
            acc["max"] = json!(max);
        }
        self.accessors.push(acc);
        self.accessors.len() - 1
    }

    fn floats(&mut self, values: &[f32], width: usize, kind: &str, target: Option<u32>) -> usize {
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.accessor(&bytes, values.len() / width, FLOAT, kind, target, None)
    }
}

/// `scene` and its camera `paths` as a binary glTF file (see the module documentation).
pub fn scene_glb(scene: &Scene, paths: &[CameraPath]) -> Result<Vec<u8>, NetError> {
    let mut b = Builder::default();
    let meshes: Vec<Value> = scene
        .meshes
        .iter()
        .map(|m| {
            let flat: Vec<f32> = m.positions.iter().flat_map(|p| p.to_array()).collect();
            let (mut min, mut max) = ([f32::MAX; 3], [f32::MIN; 3]);
            for p in &m.positions {
                for k in 0..3 {
                    min[k] = min[k].min(p[k]);
                    max[k] = max[k].max(p[k]);
                }
            }
            let bytes: Vec<u8> = flat.iter().flat_map(|v| v.to_le_bytes()).collect();
            let bounds = (!m.positions.is_empty()).then(|| (min.to_vec(), max.to_vec()));
            let position = b.accessor(
                &bytes,
                m.positions.len(),
                FLOAT,
                "VEC3",
                Some(ARRAY_BUFFER),
                bounds,
            );
            let normals: Vec<f32> = m.normals.iter().flat_map(|n| n.to_array()).collect();
            let normal = b.floats(&normals, 3, "VEC3", Some(ARRAY_BUFFER));
            let index_bytes: Vec<u8> = m
                .indices
                .iter()
                .flatten()
                .flat_map(|i| i.to_le_bytes())
                .collect();
            let indices = b.accessor(
                &index_bytes,
                m.indices.len() * 3,
                UNSIGNED_INT,
                "SCALAR",
                Some(ELEMENT_ARRAY_BUFFER),
                None,
            );
            let mut attributes = json!({ "POSITION": position, "NORMAL": normal });
            if !m.joints.is_empty() && m.joints.len() == m.positions.len() {
                let joints: Vec<u8> = m
                    .joints
                    .iter()
                    .flatten()
                    .flat_map(|j| j.to_le_bytes())
                    .collect();
                attributes["JOINTS_0"] = json!(b.accessor(
                    &joints,
                    m.joints.len(),
                    UNSIGNED_SHORT,
                    "VEC4",
                    Some(ARRAY_BUFFER),
                    None
                ));
                let weights: Vec<f32> = m.weights.iter().flatten().copied().collect();
                attributes["WEIGHTS_0"] = json!(b.floats(&weights, 4, "VEC4", Some(ARRAY_BUFFER)));
            }
            json!({
                "name": m.name,
                "primitives": [{
                    "attributes": attributes,
                    "indices": indices,
                    "material": m.material,
                    "mode": 4,
                }],
            })
        })
        .collect();
    let materials: Vec<Value> = scene
        .materials
        .iter()
        .map(|m| {
            let mut v = json!({
                "name": m.name,
                "pbrMetallicRoughness": {
                    "baseColorFactor": m.base_color.to_array(),
                    "metallicFactor": m.metallic,
                    "roughnessFactor": m.roughness,
                },
                "doubleSided": m.double_sided,
            });
            match m.alpha_mode {
                AlphaMode::Opaque => {}
                AlphaMode::Mask { cutoff } => {
                    v["alphaMode"] = json!("MASK");
                    v["alphaCutoff"] = json!(cutoff);
                }
                AlphaMode::Blend => v["alphaMode"] = json!("BLEND"),
            }
            v
        })
        .collect();
    let offset = scene.instances.len();
    let motion = scene.instance_motion()?;
    let mut nodes: Vec<Value> = scene
        .instances
        .iter()
        .enumerate()
        .map(|(i, inst)| {
            let mut n = json!({
                "name": format!("instance {i}"),
                "mesh": inst.mesh,
                "matrix": Mat4::from(inst.transform).to_cols_array(),
            });
            if let Some(s) = inst.skin {
                n["skin"] = json!(s);
            }
            if motion[i] == Motion::Skinned {
                n["extras"] = json!({
                    "psao_skinned": true,
                    "psao_node": inst.node.map(|k| offset + k),
                });
            }
            n
        })
        .collect();
    for (k, node) in scene.nodes.iter().enumerate() {
        let children: Vec<usize> = scene
            .nodes
            .iter()
            .enumerate()
            .filter(|(_, c)| c.parent == Some(k))
            .map(|(c, _)| offset + c)
            .collect();
        let mut n = json!({
            "name": node.name,
            "translation": node.translation.to_array(),
            "rotation": node.rotation.to_array(),
            "scale": node.scale.to_array(),
        });
        if !children.is_empty() {
            n["children"] = json!(children);
        }
        nodes.push(n);
    }
    let roots: Vec<usize> = (0..offset)
        .chain(
            scene
                .nodes
                .iter()
                .enumerate()
                .filter(|(_, n)| n.parent.is_none())
                .map(|(k, _)| offset + k),
        )
        .collect();
    let skins: Vec<Value> = scene
        .skins
        .iter()
        .map(|s| {
            let ibm: Vec<f32> = s
                .inverse_bind
                .iter()
                .flat_map(|m| m.to_cols_array())
                .collect();
            json!({
                "name": s.name,
                "joints": s.joints.iter().map(|j| offset + j).collect::<Vec<_>>(),
                "inverseBindMatrices": b.floats(&ibm, 16, "MAT4", None),
            })
        })
        .collect();
    let animations: Vec<Value> = scene
        .animations
        .iter()
        .map(|a| {
            let (mut samplers, mut channels) = (Vec::new(), Vec::new());
            for c in &a.channels {
                let (path, width, kind) = match c.property {
                    AnimatedProperty::Translation => ("translation", 3, "VEC3"),
                    AnimatedProperty::Rotation => ("rotation", 4, "VEC4"),
                    AnimatedProperty::Scale => ("scale", 3, "VEC3"),
                };
                let interpolation = match c.interpolation {
                    Interpolation::Step => "STEP",
                    Interpolation::Linear => "LINEAR",
                    Interpolation::CubicSpline => "CUBICSPLINE",
                };
                let first = c.times.first().copied().unwrap_or(0.0);
                let last = c.times.last().copied().unwrap_or(0.0);
                let times: Vec<u8> = c.times.iter().flat_map(|t| t.to_le_bytes()).collect();
                let input = b.accessor(
                    &times,
                    c.times.len(),
                    FLOAT,
                    "SCALAR",
                    None,
                    Some((vec![first], vec![last])),
                );
                let output = b.floats(&c.values, width, kind, None);
                samplers.push(json!({
                    "input": input,
                    "output": output,
                    "interpolation": interpolation,
                }));
                channels.push(json!({
                    "sampler": samplers.len() - 1,
                    "target": { "node": offset + c.node, "path": path },
                }));
            }
            json!({ "name": a.name, "samplers": samplers, "channels": channels })
        })
        .collect();
    let mut doc = json!({
        "asset": { "version": "2.0", "generator": "psao serve" },
        "scene": 0,
        "scenes": [{ "nodes": roots }],
        "nodes": nodes,
        "meshes": meshes,
        "materials": materials,
        "buffers": [{ "byteLength": b.bin.len() }],
        "bufferViews": b.views,
        "accessors": b.accessors,
    });
    if !skins.is_empty() {
        doc["skins"] = json!(skins);
    }
    if !animations.is_empty() {
        doc["animations"] = json!(animations);
    }
    doc["extras"] = json!({ "psao_playing": scene.playing, "psao_lights": lights_json(scene) });
    if !paths.is_empty() {
        doc["extras"]["psao_camera_paths"] = json!(paths.iter().map(path_json).collect::<Vec<_>>());
    }
    let json = serde_json::to_vec(&doc).map_err(|e| NetError::Protocol(e.to_string()))?;
    let glb = gltf::binary::Glb {
        header: gltf::binary::Header {
            magic: *b"glTF",
            version: 2,
            length: 0,
        },
        json: Cow::Owned(json),
        bin: Some(Cow::Owned(b.bin)),
    };
    glb.to_vec()
        .map_err(|e| NetError::Protocol(format!("cannot write the scene as glTF: {e}")))
}

/// The scene's suns and point lights, in the order of `Scene::lights` (rectangles skipped):
/// `{ "kind": "sun", "direction", "color", "power", "keys"? }` with `keys` =
/// `{ "times": [s, …], "directions": [[x, y, z], …] }` for a sun that turns
/// (`psao_scene::SunKeys`: slerp between keys, looping over the last key time), and
/// `{ "kind": "point", "position", "color", "power" }`.
fn lights_json(scene: &Scene) -> Vec<Value> {
    use psao_scene::LightShape;
    scene
        .lights
        .iter()
        .enumerate()
        .filter_map(|(k, light)| {
            let mut v = match light.shape {
                LightShape::Sun { direction } => {
                    json!({ "kind": "sun", "direction": direction.to_array() })
                }
                LightShape::Point { position } => {
                    json!({ "kind": "point", "position": position.to_array() })
                }
                LightShape::Rect { .. } => return None,
            };
            v["color"] = json!(light.color.to_array());
            v["power"] = json!(light.power);
            if let Some(keys) = scene.sun_keys.iter().find(|keys| keys.light == k) {
                let directions: Vec<[f32; 3]> =
                    keys.directions.iter().map(|d| d.to_array()).collect();
                v["keys"] = json!({ "times": keys.times, "directions": directions });
            }
            Some(v)
        })
        .collect()
}

/// A camera path as `{ "name", "frames": [[position, target, up, fov_y, near, far], …] }`
/// (12 numbers per frame, every frame of [`CameraPath::camera_at_frame`]).
fn path_json(path: &CameraPath) -> Value {
    let frames: Vec<Vec<f32>> = (0..path.frame_count())
        .map(|i| {
            let c = path.camera_at_frame(i);
            let mut f = Vec::with_capacity(12);
            f.extend(c.position.to_array());
            f.extend(c.target.to_array());
            f.extend(c.up.to_array());
            f.extend([c.fov_y, c.near, c.far]);
            f
        })
        .collect();
    json!({ "name": path.name, "frames": frames })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builtin_scene_reads_back_in_instance_order() {
        let scene = psao_scene::builtin::default_scene();
        let path = CameraPath::parse(include_str!("../../../paths/default_a.toml")).unwrap();
        let bytes = scene_glb(&scene, std::slice::from_ref(&path)).unwrap();
        let (doc, buffers, _) = gltf::import_slice(&bytes).unwrap();
        let nodes: Vec<_> = doc.nodes().collect();
        assert!(nodes.len() >= scene.instances.len());
        for (i, inst) in scene.instances.iter().enumerate() {
            let node = &nodes[i];
            let mesh = node.mesh().expect("instance node has a mesh");
            assert_eq!(mesh.index(), inst.mesh);
            let m = Mat4::from_cols_array_2d(&node.transform().matrix());
            assert!(m.abs_diff_eq(Mat4::from(inst.transform), 1e-6));
        }
        for (m, src) in doc.meshes().zip(&scene.meshes) {
            let prim = m.primitives().next().unwrap();
            let reader = prim.reader(|b| Some(&buffers[b.index()]));
            let positions: Vec<[f32; 3]> = reader.read_positions().unwrap().collect();
            assert_eq!(positions.len(), src.positions.len());
            assert_eq!(positions[0], src.positions[0].to_array());
            let indices: Vec<u32> = reader.read_indices().unwrap().into_u32().collect();
            assert_eq!(indices.len(), src.indices.len() * 3);
            let colour = prim.material().pbr_metallic_roughness().base_color_factor();
            assert_eq!(colour, scene.materials[src.material].base_color.to_array());
        }
        // The camera path's frames, exactly (f32 → JSON → f32).
        let glb = gltf::binary::Glb::from_slice(&bytes).unwrap();
        let json: Value = serde_json::from_slice(&glb.json).unwrap();
        let served = &json["extras"]["psao_camera_paths"][0];
        assert_eq!(served["name"], path.name.as_str());
        let frames = served["frames"].as_array().unwrap();
        assert_eq!(frames.len(), path.frame_count());
        let c = path.camera_at_frame(37);
        let got: Vec<f32> = frames[37]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap() as f32)
            .collect();
        assert_eq!(got[..3], c.position.to_array());
        assert_eq!(got[3..6], c.target.to_array());
        assert_eq!(got[9], c.fov_y);
        // The sun (the hall's rectangles are left out).
        let lights = json["extras"]["psao_lights"].as_array().unwrap();
        assert_eq!(lights.len(), 1);
        assert_eq!(lights[0]["kind"], "sun");
        assert_eq!(
            lights[0]["power"].as_f64().unwrap() as f32,
            scene.lights[0].power
        );
        assert!(lights[0].get("keys").is_none());
    }

    #[test]
    fn point_lights_and_sun_keys_ride_in_the_extras() {
        use glam::Vec3;
        use psao_scene::{Light, LightShape, SunKeys};
        let mut scene = psao_scene::builtin::shape_asset("box").unwrap();
        scene.lights = vec![
            Light {
                shape: LightShape::Point {
                    position: Vec3::new(1.0, 2.0, 3.0),
                },
                color: Vec3::new(1.0, 0.5, 0.25),
                power: 4.0,
            },
            Light {
                shape: LightShape::Sun { direction: Vec3::Y },
                color: Vec3::ONE,
                power: 2.0,
            },
        ];
        let keys = SunKeys::new(1, vec![0.0, 10.0], vec![Vec3::Y, Vec3::X]).unwrap();
        scene.sun_keys = vec![keys];
        let bytes = scene_glb(&scene, &[]).unwrap();
        let glb = gltf::binary::Glb::from_slice(&bytes).unwrap();
        let json: Value = serde_json::from_slice(&glb.json).unwrap();
        let lights = &json["extras"]["psao_lights"];
        assert_eq!(
            lights[0],
            json!({ "kind": "point", "position": [1.0, 2.0, 3.0], "color": [1.0, 0.5, 0.25], "power": 4.0 })
        );
        assert_eq!(lights[1]["kind"], "sun");
        assert_eq!(
            lights[1]["keys"],
            json!({ "times": [0.0, 10.0], "directions": [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0]] })
        );
    }
}
