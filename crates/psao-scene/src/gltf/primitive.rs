//! One glTF triangle primitive → one [`Mesh`].

use ::gltf::accessor::Dimensions;
use ::gltf::mesh::{Mode, Semantic};
use ::gltf::Primitive;
use glam::{Vec2, Vec3};

use super::accessor::BufferData;
use crate::error::SceneError;
use crate::geometry::{area_weighted_normals, repair_normals};
use crate::model::Mesh;

/// Converts a primitive; `Ok(None)` (with a warning) for non-triangle modes. The UVs are
/// read from `TEXCOORD_<mask_uvs>` when the material's alpha texture uses that set, else
/// from `TEXCOORD_0`.
pub(super) fn convert(
    prim: &Primitive,
    name: String,
    material: usize,
    mask_uvs: Option<u32>,
    data: &BufferData,
) -> Result<Option<Mesh>, SceneError> {
    if prim.mode() != Mode::Triangles {
        tracing::warn!(
            "{}: {name}: primitive mode {:?} skipped (triangles only)",
            data.path.display(),
            prim.mode()
        );
        return Ok(None);
    }
    if prim.morph_targets().len() > 0 {
        tracing::warn!("{}: {name}: morph targets ignored", data.path.display());
    }
    let what = |attr: &str| format!("{name} {attr}");
    let pos_acc = prim.get(&Semantic::Positions).ok_or_else(|| {
        SceneError::parse(
            data.path,
            "glTF",
            format!("{name}: primitive has no POSITION"),
        )
    })?;
    let positions = to_vec3(&data.floats(&pos_acc, &[Dimensions::Vec3], &what("POSITION"))?);
    let n = positions.len();
    let count_matches = |len: usize, attr: &str| {
        if len == n {
            Ok(())
        } else {
            Err(SceneError::parse(
                data.path,
                "glTF",
                format!("{name}: {attr} has {len} elements but POSITION has {n}"),
            ))
        }
    };

    let flat: Vec<u32> = match prim.indices() {
        Some(acc) => data.uints(&acc, &[Dimensions::Scalar], &what("indices"))?,
        None => (0..n as u32).collect(),
    };
    if !flat.len().is_multiple_of(3) {
        return Err(SceneError::parse(
            data.path,
            "glTF",
            format!(
                "{name}: {} indices is not a whole number of triangles",
                flat.len()
            ),
        ));
    }
    if let Some(&bad) = flat.iter().find(|&&i| i as usize >= n) {
        return Err(SceneError::index(
            data.path,
            what("vertex"),
            bad as usize,
            n,
        ));
    }
    let indices: Vec<[u32; 3]> = flat.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();

    let normals = match prim.get(&Semantic::Normals) {
        Some(acc) => {
            let mut normals = to_vec3(&data.floats(&acc, &[Dimensions::Vec3], &what("NORMAL"))?);
            count_matches(normals.len(), "NORMAL")?;
            let fixed = repair_normals(&mut normals, &positions, &indices);
            if fixed > 0 {
                tracing::warn!(
                    "{}: {name}: {fixed} degenerate normals recomputed",
                    data.path.display()
                );
            }
            normals
        }
        None => area_weighted_normals(&positions, &indices),
    };

    let uv_set = mask_uvs.unwrap_or(0);
    let uv_attr = format!("TEXCOORD_{uv_set}");
    let uvs = match prim.get(&Semantic::TexCoords(uv_set)) {
        Some(acc) => {
            let uv = data.floats(&acc, &[Dimensions::Vec2], &what(&uv_attr))?;
            let uvs: Vec<Vec2> = uv.chunks_exact(2).map(Vec2::from_slice).collect();
            count_matches(uvs.len(), &uv_attr)?;
            uvs
        }
        None => {
            if mask_uvs.is_some() {
                tracing::warn!(
                    "{}: {name}: no {uv_attr} for the alpha mask: only the alpha factor applies",
                    data.path.display()
                );
            }
            Vec::new()
        }
    };

    let (joints, weights) = match (
        prim.get(&Semantic::Joints(0)),
        prim.get(&Semantic::Weights(0)),
    ) {
        (Some(j), Some(w)) => {
            let j = data.uints(&j, &[Dimensions::Vec4], &what("JOINTS_0"))?;
            let w = data.floats(&w, &[Dimensions::Vec4], &what("WEIGHTS_0"))?;
            count_matches(j.len() / 4, "JOINTS_0")?;
            count_matches(w.len() / 4, "WEIGHTS_0")?;
            if prim.get(&Semantic::Joints(1)).is_some() {
                tracing::warn!(
                    "{}: {name}: only the first 4 joint influences are used",
                    data.path.display()
                );
            }
            skin_influences(&j, &w, data, &name)?
        }
        (None, None) => (Vec::new(), Vec::new()),
        _ => {
            tracing::warn!(
                "{}: {name}: JOINTS_0 without WEIGHTS_0 (or vice versa) ignored",
                data.path.display()
            );
            (Vec::new(), Vec::new())
        }
    };

    Ok(Some(Mesh {
        name,
        positions,
        normals,
        uvs,
        indices,
        material,
        joints,
        weights,
    }))
}

/// Per-vertex joint indices and weights.
type Influences = (Vec<[u16; 4]>, Vec<[f32; 4]>);

fn to_vec3(flat: &[f32]) -> Vec<Vec3> {
    flat.chunks_exact(3).map(Vec3::from_slice).collect()
}

/// Per-vertex joints and weights: negative weights clamp to 0, weights are renormalised to
/// sum to 1 (all-zero → joint slot 0 gets 1), and slots without weight point at joint 0.
fn skin_influences(
    joints: &[u32],
    weights: &[f32],
    data: &BufferData,
    name: &str,
) -> Result<Influences, SceneError> {
    let mut out_j = Vec::with_capacity(joints.len() / 4);
    let mut out_w = Vec::with_capacity(weights.len() / 4);
    let mut unweighted = 0usize;
    for (j, w) in joints.chunks_exact(4).zip(weights.chunks_exact(4)) {
        let mut w = [w[0], w[1], w[2], w[3]].map(|x| x.max(0.0));
        let sum: f32 = w.iter().sum();
        if sum > 0.0 {
            w = w.map(|x| x / sum);
        } else {
            unweighted += 1;
            w = [1.0, 0.0, 0.0, 0.0];
        }
        let mut jj = [0u16; 4];
        for k in 0..4 {
            if w[k] > 0.0 {
                jj[k] = u16::try_from(j[k]).map_err(|_| {
                    SceneError::index(data.path, format!("{name} joint"), j[k] as usize, 1 << 16)
                })?;
            }
        }
        out_j.push(jj);
        out_w.push(w);
    }
    if unweighted > 0 {
        tracing::warn!(
            "{}: {name}: {unweighted} vertices without skin weight bound to their first joint",
            data.path.display()
        );
    }
    Ok((out_j, out_w))
}
