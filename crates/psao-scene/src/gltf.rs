//! glTF 2.0 import (`.gltf` + external/embedded buffers, `.glb`).
//!
//! The node hierarchy is kept ([`Scene::nodes`], same indices as the file) and flattened
//! into [`Instance`]s: one per (node, triangle primitive) of the displayed scene (the
//! default scene, else every root), with the node's world transform at rest. Each
//! primitive becomes one shared [`Mesh`]. Textures are read only for alpha masks: the
//! base-colour image of each `MASK` material is decoded (PNG from a buffer view, a data URI
//! or a file next to the glTF; JPEG has no alpha and is not read) into its
//! [`Material::alpha_texture`], with the sampler's wrap modes and the UV set it uses (that
//! set becomes [`Mesh::uvs`]). `KHR_texture_transform` is not applied.
//!
//! Clips that drive disjoint nodes all play; of clips sharing nodes only the first plays.
//!
//! For a skinned instance, `transform` is still its node's world transform; skinning in
//! mesh-local space uses `transform⁻¹ · world(joint) · inverse_bind(joint)` per joint.

mod accessor;
mod animation;
mod buffers;
mod hierarchy;
mod images;
mod precheck;
mod primitive;

use std::collections::hash_map::{Entry, HashMap};
use std::collections::HashSet;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;

use ::gltf::material::AlphaMode as GltfAlphaMode;
use ::gltf::Document;
use glam::Vec4;

pub use self::images::{MAX_IMAGE_BYTES, MAX_IMAGE_SIDE};

use self::accessor::BufferData;
use self::images::MaskImages;
use crate::alpha::{AlphaTexture, Wrap};
use crate::error::{read_file, SceneError};
#[cfg(doc)]
use crate::model::Mesh;
use crate::model::{AlphaMode, Animation, Instance, Material, Scene, DEFAULT_AO_RADIUS};

/// Loads a `.gltf` or `.glb` file (the format is detected from the content). The files its
/// buffers and images name must be regular files inside its folder.
pub fn load(path: &Path) -> Result<Scene, SceneError> {
    let bytes = read_file(path)?;
    let folder = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    parse(bytes, path, Some(folder))
}

/// Loads glTF or GLB bytes held in memory (`label` names them in errors); they may use data
/// URIs and the GLB chunk but name no files.
pub fn load_from_bytes(bytes: Vec<u8>, label: &Path) -> Result<Scene, SceneError> {
    parse(bytes, label, None)
}

/// Parses glTF or GLB `bytes` whose external files lie in `folder`.
fn parse(bytes: Vec<u8>, path: &Path, folder: Option<&Path>) -> Result<Scene, SceneError> {
    let bad = |e: ::gltf::Error| SceneError::parse(path, "glTF", e.to_string());
    if bytes.is_empty() {
        return Err(SceneError::parse(path, "glTF", "file is empty"));
    }
    let ::gltf::Gltf { document, blob } =
        guard(path, || ::gltf::Gltf::from_slice_without_validation(&bytes))?.map_err(bad)?;
    drop(bytes);
    let root = document.into_json();
    precheck::precheck(&root, path)?;
    let document = guard(path, || Document::from_json(root))?.map_err(bad)?;
    let buffers = buffers::load_buffers(&document, blob, path, folder)?;
    let masks = images::mask_images(&document, &buffers, path, folder)?;
    build(
        &document,
        &BufferData {
            path,
            buffers: &buffers,
        },
        &masks,
    )
}

/// Runs a `gltf` crate parse/validate step; a panic inside it (a gap in its validation
/// not covered by [`precheck`]) becomes an error instead of unwinding into the caller.
fn guard<T>(path: &Path, f: impl FnOnce() -> T) -> Result<T, SceneError> {
    catch_unwind(AssertUnwindSafe(f)).map_err(|_| {
        SceneError::parse(path, "glTF", "malformed file (rejected by the glTF parser)")
    })
}

/// Builds the scene from a parsed document, its loaded buffers and decoded alpha masks.
fn build(doc: &Document, data: &BufferData, masks: &MaskImages) -> Result<Scene, SceneError> {
    let tree = hierarchy::build(doc, data.path)?;
    let mut scene = Scene {
        materials: doc
            .materials()
            .map(|m| material(&m, masks, data.path))
            .collect::<Result<_, _>>()?,
        skins: doc
            .skins()
            .map(|s| animation::skin(&s, data))
            .collect::<Result<_, _>>()?,
        animations: doc
            .animations()
            .map(|a| animation::animation(&a, data))
            .collect::<Result<_, _>>()?,
        ao_radius: DEFAULT_AO_RADIUS,
        ..Default::default()
    };
    scene.playing = default_clips(&scene.animations);

    let nodes: Vec<_> = doc.nodes().collect();
    let mut mesh_map: HashMap<usize, Vec<usize>> = HashMap::new();
    let mut default_material = None;
    for &n in &tree.shown {
        let node = &nodes[n];
        let Some(gmesh) = node.mesh() else { continue };
        let ids = match mesh_map.entry(gmesh.index()) {
            Entry::Occupied(e) => e.into_mut(),
            Entry::Vacant(e) => e.insert(convert_mesh(
                &gmesh,
                &mut scene,
                &mut default_material,
                data,
            )?),
        };
        let skin = node.skin().map(|s| s.index());
        for &m in ids.iter() {
            let mesh = &scene.meshes[m];
            let skin = skin.filter(|_| !mesh.joints.is_empty());
            if let Some(s) = skin {
                let count = scene.skins[s].joints.len();
                if let Some(&bad) = mesh.joints.iter().flatten().find(|&&j| j as usize >= count) {
                    return Err(SceneError::index(
                        data.path,
                        format!("{} joint (skin {s})", mesh.name),
                        bad as usize,
                        count,
                    ));
                }
            }
            scene.instances.push(Instance {
                mesh: m,
                node: Some(n),
                transform: tree.world[n],
                skin,
            });
        }
    }
    scene.nodes = tree.nodes;
    Ok(scene)
}

/// The clips that play by default: every clip, except one that drives a node an earlier
/// chosen clip already drives (alternative clips of one character, e.g. Survey/Walk/Run:
/// the first one plays).
fn default_clips(animations: &[Animation]) -> Vec<usize> {
    let mut driven = HashSet::new();
    let mut playing = Vec::new();
    for (i, a) in animations.iter().enumerate() {
        let nodes: HashSet<usize> = a.channels.iter().map(|c| c.node).collect();
        if nodes.is_disjoint(&driven) {
            driven.extend(nodes);
            playing.push(i);
        }
    }
    playing
}

/// Converts the triangle primitives of a glTF mesh, appending them to `scene.meshes`;
/// returns their indices. Primitives without material share one appended default.
fn convert_mesh(
    gmesh: &::gltf::Mesh,
    scene: &mut Scene,
    default_material: &mut Option<usize>,
    data: &BufferData,
) -> Result<Vec<usize>, SceneError> {
    let base = gmesh
        .name()
        .map_or_else(|| format!("mesh{}", gmesh.index()), str::to_owned);
    let multi = gmesh.primitives().len() > 1;
    let mut ids = Vec::new();
    for prim in gmesh.primitives() {
        let name = if multi {
            format!("{base}/{}", prim.index())
        } else {
            base.clone()
        };
        let material = match prim.material().index() {
            Some(m) => m,
            None => *default_material.get_or_insert_with(|| {
                scene.materials.push(Material::default());
                scene.materials.len() - 1
            }),
        };
        let mask_uvs = scene.materials[material]
            .alpha_texture
            .as_ref()
            .map(|t| t.tex_coord);
        if let Some(mesh) = primitive::convert(&prim, name, material, mask_uvs, data)? {
            scene.meshes.push(mesh);
            ids.push(scene.meshes.len() - 1);
        }
    }
    Ok(ids)
}

/// Converts a glTF material: its factors, and for a `MASK` material the alpha texture
/// decoded in `masks` (textures are otherwise ignored).
fn material(m: &::gltf::Material, masks: &MaskImages, path: &Path) -> Result<Material, SceneError> {
    let name = m.name().map_or_else(
        || format!("material{}", m.index().unwrap_or(0)),
        str::to_owned,
    );
    let pbr = m.pbr_metallic_roughness();
    let base_color = Vec4::from_array(pbr.base_color_factor());
    let cutoff = m.alpha_cutoff().unwrap_or(0.5);
    let (metallic, roughness) = (pbr.metallic_factor(), pbr.roughness_factor());
    if !(base_color.is_finite()
        && cutoff.is_finite()
        && metallic.is_finite()
        && roughness.is_finite())
    {
        return Err(SceneError::non_finite(path, format!("material '{name}'")));
    }
    let alpha_mode = match m.alpha_mode() {
        GltfAlphaMode::Opaque => AlphaMode::Opaque,
        GltfAlphaMode::Mask => AlphaMode::Mask { cutoff },
        GltfAlphaMode::Blend => AlphaMode::Blend,
    };
    let alpha_texture = match (alpha_mode, pbr.base_color_texture()) {
        (AlphaMode::Mask { .. }, Some(info)) => {
            let texture = info.texture();
            let image = masks.get(&texture.source().index()).cloned().flatten();
            let sampler = texture.sampler();
            image.map(|image| AlphaTexture {
                image,
                tex_coord: info.tex_coord(),
                wrap_s: wrap(sampler.wrap_s()),
                wrap_t: wrap(sampler.wrap_t()),
            })
        }
        _ => None,
    };
    let transmission = m.transmission().map_or(0.0, |t| t.transmission_factor());
    let ior = m.ior().unwrap_or(crate::model::DEFAULT_IOR);
    let material = Material {
        name,
        base_color,
        double_sided: m.double_sided(),
        alpha_mode,
        metallic,
        roughness,
        transmission,
        ior,
        alpha_texture,
    };
    material.check().map_err(|e| {
        SceneError::parse(path, "glTF", format!("material '{}': {e}", material.name))
    })?;
    Ok(material)
}

fn wrap(mode: ::gltf::texture::WrappingMode) -> Wrap {
    use ::gltf::texture::WrappingMode as W;
    match mode {
        W::Repeat => Wrap::Repeat,
        W::ClampToEdge => Wrap::ClampToEdge,
        W::MirroredRepeat => Wrap::MirroredRepeat,
    }
}
