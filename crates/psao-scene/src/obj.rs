//! Wavefront OBJ import via `tobj`: one [`Mesh`] and one material per object/group,
//! identity instances, no hierarchy. A missing or broken `.mtl` is ignored (default
//! grey materials); when it loads, its diffuse colour becomes the base colour.

use std::io::Cursor;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;

use glam::{Affine3A, Vec2, Vec3, Vec4};

use crate::error::{read_file, SceneError, MAX_ELEMENTS};
use crate::geometry::{flatten, repair_normals};
use crate::model::{Instance, Material, Mesh, Scene, DEFAULT_AO_RADIUS};

/// Loads an OBJ file. Faces are triangulated; meshes without normals get flat normals
/// (vertices unshared per face). Fails when the file holds no triangle at all.
pub fn load(path: &Path) -> Result<Scene, SceneError> {
    let bytes = read_file(path)?;
    let dir = path.parent().unwrap_or_else(|| Path::new("")).to_path_buf();
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ..Default::default()
    };
    // `tobj` does unchecked index arithmetic on some malformed faces; a panic there must
    // become an error, not abort the caller.
    let parsed = catch_unwind(AssertUnwindSafe(|| {
        tobj::load_obj_buf(&mut Cursor::new(&bytes), &options, |mtl| {
            tobj::load_mtl(dir.join(mtl))
        })
    }))
    .map_err(|_| SceneError::parse(path, "OBJ", "malformed file (parser failure)"))?;
    let (models, materials) = parsed.map_err(|e| SceneError::parse(path, "OBJ", e.to_string()))?;
    let materials = materials.unwrap_or_else(|e| {
        tracing::warn!(
            "{}: material library not loaded ({e}); using defaults",
            path.display()
        );
        Vec::new()
    });

    let mut scene = Scene {
        ao_radius: DEFAULT_AO_RADIUS,
        ..Default::default()
    };
    for (i, model) in models.into_iter().enumerate() {
        let name = if model.name.is_empty() {
            format!("object{i}")
        } else {
            model.name
        };
        let mtl = model.mesh.material_id.and_then(|m| materials.get(m));
        let Some(mut mesh) = convert(&model.mesh, name, path)? else {
            continue;
        };
        let mut material = Material {
            name: mtl.map_or_else(|| mesh.name.clone(), |m| m.name.clone()),
            ..Material::default()
        };
        if let Some(d) = mtl.and_then(|m| m.diffuse) {
            let c = Vec4::new(d[0], d[1], d[2], 1.0);
            if c.is_finite() {
                material.base_color = c;
            }
        }
        if let Some(m) = mtl {
            apply_mtl_specular(&mut material, m, path)?;
        }
        scene.materials.push(material);
        mesh.material = scene.materials.len() - 1;
        scene.meshes.push(mesh);
        scene.instances.push(Instance {
            mesh: scene.meshes.len() - 1,
            node: None,
            transform: Affine3A::IDENTITY,
            skin: None,
        });
    }
    if scene.meshes.is_empty() {
        return Err(SceneError::parse(path, "OBJ", "no triangles found"));
    }
    Ok(scene)
}

/// Reads the non-diffuse part of an MTL material: `Ks` and `Ns` give the roughness
/// `√(2 / (Ns + 2))` (the Blinn–Phong exponent's usual microfacet match) when `Ks` is not black,
/// `d` (dissolve) gives `transmission = 1 − d` and `Ni` the index of refraction. Values outside
/// their ranges (Ks or d outside [0, 1], negative Ns, Ni outside [1, 5]) are errors.
fn apply_mtl_specular(
    material: &mut Material,
    m: &tobj::Material,
    path: &Path,
) -> Result<(), SceneError> {
    let bad =
        |what: String| SceneError::parse(path, "OBJ", format!("material '{}': {what}", m.name));
    let ks = m.specular.unwrap_or([0.0; 3]);
    if ks.iter().any(|k| !(0.0..=1.0).contains(k)) {
        return Err(bad(format!("Ks must be in [0, 1], got {ks:?}")));
    }
    if let Some(ns) = m.shininess {
        if !(ns.is_finite() && ns >= 0.0) {
            return Err(bad(format!("Ns must be a non-negative number, got {ns}")));
        }
        if ks.iter().any(|&k| k > 0.0) {
            material.roughness = (2.0 / (ns + 2.0)).sqrt();
        }
    }
    if let Some(d) = m.dissolve {
        if !(0.0..=1.0).contains(&d) {
            return Err(bad(format!("d must be in [0, 1], got {d}")));
        }
        material.transmission = 1.0 - d;
    }
    if let Some(ni) = m.optical_density {
        if !(1.0..=5.0).contains(&ni) {
            return Err(bad(format!("Ni must be in [1, 5], got {ni}")));
        }
        material.ior = ni;
    }
    Ok(())
}

/// One `tobj` mesh to a [`Mesh`] (material assigned by the caller); `None` when empty.
fn convert(m: &tobj::Mesh, name: String, path: &Path) -> Result<Option<Mesh>, SceneError> {
    let n = m.positions.len() / 3;
    if n > MAX_ELEMENTS || m.indices.len() / 3 > MAX_ELEMENTS {
        return Err(SceneError::too_large(
            path,
            format!("{name} vertex count"),
            n as u64,
            MAX_ELEMENTS as u64,
        ));
    }
    let positions: Vec<Vec3> = m.positions.chunks_exact(3).map(Vec3::from_slice).collect();
    if positions.iter().any(|p| !p.is_finite()) {
        return Err(SceneError::non_finite(
            path,
            format!("{name} vertex positions"),
        ));
    }
    if let Some(&bad) = m.indices.iter().find(|&&i| i as usize >= n) {
        return Err(SceneError::index(
            path,
            format!("{name} vertex"),
            bad as usize,
            n,
        ));
    }
    let indices: Vec<[u32; 3]> = m
        .indices
        .chunks_exact(3)
        .map(|t| [t[0], t[1], t[2]])
        .collect();
    if indices.is_empty() {
        return Ok(None);
    }
    let uvs: Vec<Vec2> = if m.texcoords.len() == 2 * n {
        m.texcoords.chunks_exact(2).map(Vec2::from_slice).collect()
    } else {
        Vec::new()
    };
    if uvs.iter().any(|uv| !uv.is_finite()) {
        return Err(SceneError::non_finite(
            path,
            format!("{name} texture coordinates"),
        ));
    }
    let mesh = if m.normals.len() == 3 * n {
        let mut normals: Vec<Vec3> = m.normals.chunks_exact(3).map(Vec3::from_slice).collect();
        repair_normals(&mut normals, &positions, &indices);
        Mesh {
            name,
            positions,
            normals,
            uvs,
            indices,
            ..Default::default()
        }
    } else {
        let flat = flatten(&positions, &uvs, &indices);
        Mesh {
            name,
            positions: flat.positions,
            normals: flat.normals,
            uvs: flat.uvs,
            indices: flat.indices,
            ..Default::default()
        }
    };
    Ok(Some(mesh))
}
