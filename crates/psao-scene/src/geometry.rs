//! Mesh helpers shared by the importers: normal generation and repair.

use glam::{Vec2, Vec3};

/// Fallback for vertices that touch no triangle with area.
const FALLBACK_NORMAL: Vec3 = Vec3::Y;

/// Unit area-weighted vertex normals (each triangle adds its unnormalised face normal).
/// Vertices on no non-degenerate triangle get +Y.
pub(crate) fn area_weighted_normals(positions: &[Vec3], indices: &[[u32; 3]]) -> Vec<Vec3> {
    let mut sums = vec![Vec3::ZERO; positions.len()];
    for tri in indices {
        let [a, b, c] = tri.map(|i| i as usize);
        let n = (positions[b] - positions[a]).cross(positions[c] - positions[a]);
        for v in [a, b, c] {
            sums[v] += n;
        }
    }
    sums.into_iter()
        .map(|n| n.try_normalize().unwrap_or(FALLBACK_NORMAL))
        .collect()
}

/// Normalises given normals in place; zero-length or non-finite ones are replaced by the
/// area-weighted normal of their vertex. Returns how many were replaced.
pub(crate) fn repair_normals(
    normals: &mut [Vec3],
    positions: &[Vec3],
    indices: &[[u32; 3]],
) -> usize {
    let mut computed: Option<Vec<Vec3>> = None;
    let mut replaced = 0;
    for (i, n) in normals.iter_mut().enumerate() {
        match n.try_normalize() {
            Some(unit) => *n = unit,
            None => {
                let computed =
                    computed.get_or_insert_with(|| area_weighted_normals(positions, indices));
                *n = computed[i];
                replaced += 1;
            }
        }
    }
    replaced
}

/// Faceted copy of an indexed mesh: three fresh vertices per triangle, each carrying the
/// triangle's unit normal (+Y for degenerate triangles). UVs are copied when present.
pub(crate) struct Flat {
    /// Unshared positions.
    pub positions: Vec<Vec3>,
    /// Face normals per vertex.
    pub normals: Vec<Vec3>,
    /// UVs per vertex, or empty.
    pub uvs: Vec<Vec2>,
    /// Triangles `[3k, 3k+1, 3k+2]`.
    pub indices: Vec<[u32; 3]>,
}

/// Builds the faceted copy (see [`Flat`]); indices must already be validated.
pub(crate) fn flatten(positions: &[Vec3], uvs: &[Vec2], indices: &[[u32; 3]]) -> Flat {
    let mut out = Flat {
        positions: Vec::with_capacity(indices.len() * 3),
        normals: Vec::with_capacity(indices.len() * 3),
        uvs: Vec::with_capacity(if uvs.is_empty() { 0 } else { indices.len() * 3 }),
        indices: Vec::with_capacity(indices.len()),
    };
    for (t, tri) in indices.iter().enumerate() {
        let [a, b, c] = tri.map(|i| i as usize);
        let n = (positions[b] - positions[a])
            .cross(positions[c] - positions[a])
            .try_normalize()
            .unwrap_or(FALLBACK_NORMAL);
        for v in [a, b, c] {
            out.positions.push(positions[v]);
            out.normals.push(n);
            if !uvs.is_empty() {
                out.uvs.push(uvs[v]);
            }
        }
        let base = (t * 3) as u32;
        out.indices.push([base, base + 1, base + 2]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn area_weighting_prefers_the_larger_face() {
        // Two triangles sharing vertex 0: a big one in the XY plane, a small one in XZ.
        let p = [
            Vec3::ZERO,
            Vec3::new(10.0, 0.0, 0.0),
            Vec3::new(0.0, 10.0, 0.0),
            Vec3::new(0.0, 0.0, -1.0),
            Vec3::new(1.0, 0.0, 0.0),
        ];
        let n = area_weighted_normals(&p, &[[0, 1, 2], [0, 4, 3]]);
        assert!(n[0].z > 0.9 && n[0].y > 0.0, "{:?}", n[0]);
        assert!((n[2] - Vec3::Z).length() < 1e-6);
        assert!((n[3] - Vec3::Y).length() < 1e-6);
    }

    #[test]
    fn repair_replaces_only_bad_normals() {
        let p = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let mut n = [Vec3::new(0.0, 0.0, 2.0), Vec3::ZERO, Vec3::NAN];
        assert_eq!(repair_normals(&mut n, &p, &[[0, 1, 2]]), 2);
        assert!(n.iter().all(|v| (*v - Vec3::Z).length() < 1e-6));
    }

    #[test]
    fn flatten_unshares_vertices() {
        let p = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z];
        let f = flatten(&p, &[], &[[0, 1, 2], [0, 3, 1]]);
        assert_eq!(f.positions.len(), 6);
        assert_eq!(f.indices, vec![[0, 1, 2], [3, 4, 5]]);
        assert!((f.normals[0] - Vec3::Z).length() < 1e-6);
        assert!((f.normals[3] - Vec3::Y).length() < 1e-6);
        assert!(f.uvs.is_empty());
    }
}
