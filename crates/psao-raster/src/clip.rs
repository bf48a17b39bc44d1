//! Homogeneous clipping of triangles against the near plane and a guard band.
//!
//! Clipping a shared edge always interpolates from its inside vertex towards its outside
//! vertex, so two triangles sharing an edge produce bit-identical new vertices (no cracks).

use glam::Vec4;

/// Most vertices a triangle can have after clipping against the five planes.
pub(crate) const MAX_VERTS: usize = 3 + 5;

/// A convex polygon in clip space.
#[derive(Clone, Copy)]
pub(crate) struct Polygon {
    verts: [Vec4; MAX_VERTS],
    len: usize,
}

impl Polygon {
    /// The polygon's vertices.
    pub fn verts(&self) -> &[Vec4] {
        &self.verts[..self.len]
    }

    fn push(&mut self, v: Vec4) {
        // Clipping a convex polygon by one plane adds at most one vertex, and at most five
        // planes are applied to a triangle, so this never exceeds MAX_VERTS.
        if self.len < MAX_VERTS {
            self.verts[self.len] = v;
            self.len += 1;
        }
    }
}

/// The clip volume: in front of the near plane and inside the guard band.
pub(crate) struct ClipVolume {
    /// Near distance (clip-space w of the near plane).
    pub near: f32,
    /// Guard band half-extent in NDC x (|x| ≤ gx·w).
    pub gx: f32,
    /// Guard band half-extent in NDC y (|y| ≤ gy·w).
    pub gy: f32,
}

impl ClipVolume {
    /// Signed distances of `v` to the five planes (≥ 0 inside).
    fn distances(&self, v: Vec4) -> [f32; 5] {
        [
            v.w - self.near,
            self.gx * v.w + v.x,
            self.gx * v.w - v.x,
            self.gy * v.w + v.y,
            self.gy * v.w - v.y,
        ]
    }

    /// Clips triangle `tri`. Returns `None` when nothing is left, otherwise the polygon (the
    /// unchanged triangle when it lies fully inside).
    pub fn clip(&self, tri: [Vec4; 3]) -> Option<Polygon> {
        // Bit p of a vertex's mask: the vertex is outside plane p.
        let [m0, m1, m2] = tri.map(|v| {
            (self.distances(v).iter().enumerate())
                .fold(0u8, |m, (p, &d)| m | (u8::from(d < 0.0) << p))
        });
        if m0 & m1 & m2 != 0 {
            return None;
        }
        let outside_mask = m0 | m1 | m2;
        let mut poly = Polygon {
            verts: [Vec4::ZERO; MAX_VERTS],
            len: 0,
        };
        for v in tri {
            poly.push(v);
        }
        for p in 0..5 {
            if outside_mask & (1 << p) != 0 {
                poly = self.clip_plane(&poly, p);
                if poly.len < 3 {
                    return None;
                }
            }
        }
        Some(poly)
    }

    /// Sutherland–Hodgman clip of `poly` against plane `p`.
    fn clip_plane(&self, poly: &Polygon, p: usize) -> Polygon {
        let mut out = Polygon {
            verts: [Vec4::ZERO; MAX_VERTS],
            len: 0,
        };
        let verts = poly.verts();
        for (i, &a) in verts.iter().enumerate() {
            let b = verts[(i + 1) % verts.len()];
            let da = self.distances(a)[p];
            let db = self.distances(b)[p];
            let (a_in, b_in) = (da >= 0.0, db >= 0.0);
            if a_in {
                out.push(a);
            }
            if a_in != b_in {
                // Interpolate from the inside vertex so both users of the edge agree exactly.
                let (vi, di, vo, dout) = if a_in { (a, da, b, db) } else { (b, db, a, da) };
                let t = di / (di - dout);
                out.push(vi + (vo - vi) * t);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn volume() -> ClipVolume {
        ClipVolume {
            near: 0.1,
            gx: 10.0,
            gy: 10.0,
        }
    }

    #[test]
    fn inside_triangle_is_unchanged() {
        let tri = [
            Vec4::new(0.0, 0.0, 0.5, 1.0),
            Vec4::new(1.0, 0.0, 0.5, 1.0),
            Vec4::new(0.0, 1.0, 0.5, 1.0),
        ];
        let poly = volume().clip(tri).expect("inside");
        assert_eq!(poly.verts(), &tri);
    }

    #[test]
    fn behind_triangle_is_dropped() {
        let tri = [
            Vec4::new(0.0, 0.0, 0.5, -1.0),
            Vec4::new(1.0, 0.0, 0.5, -2.0),
            Vec4::new(0.0, 1.0, 0.5, 0.05),
        ];
        assert!(volume().clip(tri).is_none());
    }

    #[test]
    fn near_crossing_triangle_becomes_quad_on_the_near_plane() {
        let tri = [
            Vec4::new(0.0, 0.0, 0.0, -1.0),
            Vec4::new(1.0, 0.0, 0.0, 1.0),
            Vec4::new(0.0, 1.0, 0.0, 1.0),
        ];
        let poly = volume().clip(tri).expect("partly visible");
        assert_eq!(poly.verts().len(), 4);
        for v in poly.verts() {
            assert!(v.w >= 0.1 - 1e-6, "{v}");
        }
        assert_eq!(
            poly.verts()
                .iter()
                .filter(|v| (v.w - 0.1).abs() < 1e-6)
                .count(),
            2
        );
    }

    #[test]
    fn shared_edge_clips_identically_in_both_directions() {
        let a = Vec4::new(0.3, 0.7, 0.0, -0.7);
        let b = Vec4::new(-0.2, 0.1, 0.0, 3.1);
        let c1 = Vec4::new(1.0, 1.0, 0.0, 1.0);
        let c2 = Vec4::new(-1.0, -1.0, 0.0, 2.0);
        let p1 = volume().clip([a, b, c1]).expect("visible");
        let p2 = volume().clip([b, a, c2]).expect("visible");
        let on_near = |p: &Polygon| {
            p.verts()
                .iter()
                .copied()
                .filter(|v| v.w < 0.1 + 1e-6)
                .map(|v| v.to_array().map(f32::to_bits))
                .collect::<Vec<_>>()
        };
        let shared: Vec<_> = on_near(&p1)
            .into_iter()
            .filter(|v| on_near(&p2).contains(v))
            .collect();
        assert_eq!(shared.len(), 1);
    }
}
