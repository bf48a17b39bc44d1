//! Alpha masks: fragments of alpha-masked materials are dropped where the surface is cut out
//! ([`Material::opaque_at`] at the fragment's texture coordinates), before the depth test, so
//! the surface behind shows through.

use glam::Vec2;
use psao_scene::{Material, Mesh};

use crate::geometry::{locate, PosedInstance};
use crate::resolve::BaryPlane;
use crate::view::View;

/// How an instance's material cuts its surface.
#[derive(Clone, Copy)]
pub(crate) enum Cut<'a> {
    /// Every fragment is drawn.
    Nothing,
    /// No fragment is drawn (an alpha-masked material whose alpha factor alone is below the
    /// cutoff).
    Everything,
    /// Fragments are drawn where the material's alpha texture, addressed with `uvs`, is opaque.
    Texels {
        /// The alpha-masked material.
        material: &'a Material,
        /// One texture coordinate per vertex.
        uvs: &'a [Vec2],
    },
}

impl<'a> Cut<'a> {
    /// The cut of `mesh` (with `vertices` posed vertices) in `material`.
    pub fn of(mesh: &'a Mesh, material: &'a Material, vertices: usize) -> Self {
        if material.has_texel_mask() && mesh.uvs.len() == vertices {
            Self::Texels {
                material,
                uvs: &mesh.uvs,
            }
        } else if material.opaque_at(None) {
            Self::Nothing
        } else {
            Self::Everything
        }
    }
}

/// Finds the alpha test of triangles by global id.
pub(crate) struct MaskTest<'a> {
    /// The view.
    pub view: &'a View,
    /// Posed instances.
    pub instances: &'a [PosedInstance<'a>],
    /// First global id of each instance.
    pub first_id: &'a [u32],
}

impl<'a> MaskTest<'a> {
    /// The alpha test of global triangle `id`; `None` when its instance has no texel mask.
    pub fn triangle(&self, id: u32) -> Option<MaskedTriangle<'a>> {
        let (instance, triangle) = locate(self.first_id, id)?;
        let posed = &self.instances[instance];
        let Cut::Texels { material, uvs } = posed.cut else {
            return None;
        };
        let (idx, p) = posed.triangle(triangle as usize)?;
        let [a, b, c] = idx.map(|i| uvs.get(i as usize).copied());
        Some(MaskedTriangle {
            bary: BaryPlane::new(self.view, p),
            uv: [a?, b?, c?],
            material,
        })
    }
}

/// One alpha-masked triangle as seen in the view.
pub(crate) struct MaskedTriangle<'a> {
    bary: BaryPlane,
    uv: [Vec2; 3],
    material: &'a Material,
}

impl MaskedTriangle<'_> {
    /// Whether the fragment at the centre of pixel (`x`, `y`) is kept.
    pub fn keeps(&self, x: u32, y: u32) -> bool {
        let b = self.bary.at(x, y);
        let uv = (1.0 - b.x - b.y) * self.uv[0] + b.x * self.uv[1] + b.y * self.uv[2];
        self.material.opaque_at(Some(uv))
    }
}
