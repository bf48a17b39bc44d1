//! The in-memory scene: meshes, materials, node hierarchy, instances, skins and animations.

use glam::{Affine3A, Mat4, Quat, Vec2, Vec3, Vec4};

use crate::alpha::AlphaTexture;

/// A triangle mesh in its own local space (one glTF primitive or one OBJ object).
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    /// Human-readable name (from the file, or generated).
    pub name: String,
    /// Vertex positions in mesh-local space, metres.
    pub positions: Vec<Vec3>,
    /// Unit vertex normals, one per position (computed when the file has none).
    pub normals: Vec<Vec3>,
    /// Texture coordinates, one per position, or empty when the file has none: the set the
    /// material's [`Material::alpha_texture`] is addressed with, else `TEXCOORD_0`.
    pub uvs: Vec<Vec2>,
    /// Triangles as counter-clockwise (front-facing) vertex index triples.
    pub indices: Vec<[u32; 3]>,
    /// Index into [`Scene::materials`].
    pub material: usize,
    /// Skinning joints (indices into the skin's joint list), one per position; empty when not skinned.
    pub joints: Vec<[u16; 4]>,
    /// Skinning weights, one per position, renormalised to sum to 1; empty when not skinned.
    pub weights: Vec<[f32; 4]>,
}

/// How a material treats alpha (glTF `alphaMode`).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub enum AlphaMode {
    /// Fully opaque.
    #[default]
    Opaque,
    /// Alpha-tested with the given cutoff; rays skip such geometry (DESIGN §2), points and
    /// rasterized fragments on masked-out texels are dropped.
    Mask {
        /// Surface where alpha (texture alpha × base-colour alpha) is below this is cut out.
        cutoff: f32,
    },
    /// Alpha-blended (treated as opaque for AO).
    Blend,
}

/// Surface properties psao needs: colour for base shading and flags for AO and corrections.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// Name from the file, or generated.
    pub name: String,
    /// Linear RGBA base colour factor.
    pub base_color: Vec4,
    /// Whether both faces are rendered and receive points.
    pub double_sided: bool,
    /// Alpha handling.
    pub alpha_mode: AlphaMode,
    /// glTF metallic factor (0 for OBJ).
    pub metallic: f32,
    /// glTF roughness factor (OBJ: `√(2 / (Ns + 2))` when `Ks` is non-black, else 1).
    pub roughness: f32,
    /// Fraction of light transmitted through the surface, in [0, 1] (glTF
    /// `KHR_materials_transmission`; OBJ: `1 − d`).
    pub transmission: f32,
    /// Index of refraction (glTF `KHR_materials_ior`, OBJ `Ni`; default 1.5), in [1, 5].
    pub ior: f32,
    /// Alpha channel of the base-colour texture, loaded only for [`AlphaMode::Mask`]
    /// materials whose texture has one (`None`: the alpha is `base_color.w` everywhere).
    pub alpha_texture: Option<AlphaTexture>,
}

impl Default for Material {
    fn default() -> Self {
        Self {
            name: "default".into(),
            base_color: Vec4::new(0.8, 0.8, 0.8, 1.0),
            double_sided: false,
            alpha_mode: AlphaMode::Opaque,
            metallic: 0.0,
            roughness: 1.0,
            transmission: 0.0,
            ior: DEFAULT_IOR,
            alpha_texture: None,
        }
    }
}

/// Default index of refraction (glass-like dielectrics; glTF's default).
pub const DEFAULT_IOR: f32 = 1.5;

/// Roughness below which a dielectric counts as glossy (see [`Material::is_non_diffuse`]).
pub const GLOSSY_ROUGHNESS: f32 = 0.3;

impl Material {
    /// The non-diffuse rule: a surface whose look a view-independent (diffuse + AO) solution
    /// cannot show — metallic (`metallic > 0.5`), glossy (`roughness < 0.3`) or transmissive
    /// (`transmission > 0`). Such surfaces get ray-traced corrections.
    pub fn is_non_diffuse(&self) -> bool {
        self.metallic > 0.5 || self.roughness < GLOSSY_ROUGHNESS || self.transmission > 0.0
    }

    /// Checks the shading parameters: base colour components, metallic, roughness and
    /// transmission in [0, 1], `ior` in [1, 5], all finite; the message names the value.
    pub fn check(&self) -> Result<(), String> {
        let unit = |what: &str, v: f32| {
            if (0.0..=1.0).contains(&v) {
                Ok(())
            } else {
                Err(format!("{what} must be in [0, 1], got {v}"))
            }
        };
        for (c, v) in ["red", "green", "blue", "alpha"]
            .iter()
            .zip(self.base_color.to_array())
        {
            unit(&format!("base colour {c}"), v)?;
        }
        unit("metallic", self.metallic)?;
        unit("roughness", self.roughness)?;
        unit("transmission", self.transmission)?;
        if !(1.0..=5.0).contains(&self.ior) {
            return Err(format!("ior must be in [1, 5], got {}", self.ior));
        }
        Ok(())
    }
    /// True when AO rays pass through this material's geometry.
    pub fn skipped_by_rays(&self) -> bool {
        matches!(self.alpha_mode, AlphaMode::Mask { .. })
    }
    /// Whether the surface is present (not cut out) where its texture coordinates are `uv`:
    /// always for non-masked materials; for [`AlphaMode::Mask`], whether
    /// `base_color.w × texture alpha ≥ cutoff`, the texture counting only when it and `uv`
    /// are both given.
    pub fn opaque_at(&self, uv: Option<Vec2>) -> bool {
        let AlphaMode::Mask { cutoff } = self.alpha_mode else {
            return true;
        };
        let texel = match (&self.alpha_texture, uv) {
            (Some(t), Some(uv)) => t.sample(uv),
            _ => 1.0,
        };
        self.base_color.w * texel >= cutoff
    }
    /// Whether [`Material::opaque_at`] depends on the texture coordinates (a masked material
    /// with an alpha texture); otherwise `opaque_at(None)` holds for the whole surface.
    pub fn has_texel_mask(&self) -> bool {
        matches!(self.alpha_mode, AlphaMode::Mask { .. }) && self.alpha_texture.is_some()
    }
}

impl Mesh {
    /// Texture coordinates at barycentrics `bary` (weights of the three vertices) of triangle
    /// `tri`; `None` without UVs or for an out-of-range triangle or vertex.
    pub fn uv_at(&self, tri: u32, bary: Vec3) -> Option<Vec2> {
        let [a, b, c] = self
            .indices
            .get(tri as usize)?
            .map(|i| self.uvs.get(i as usize));
        Some(*a? * bary.x + *b? * bary.y + *c? * bary.z)
    }
}

/// A node of the flattened-but-kept hierarchy, used by animation to recompute instance transforms.
#[derive(Clone, Debug, PartialEq)]
pub struct Node {
    /// Name from the file.
    pub name: String,
    /// Parent node index, `None` for roots.
    pub parent: Option<usize>,
    /// Local translation.
    pub translation: Vec3,
    /// Local rotation.
    pub rotation: Quat,
    /// Local scale.
    pub scale: Vec3,
}

impl Node {
    /// The node's local transform (T·R·S).
    pub fn local_transform(&self) -> Affine3A {
        Affine3A::from_scale_rotation_translation(self.scale, self.rotation, self.translation)
    }
}

/// One placed copy of a mesh.
#[derive(Clone, Debug, PartialEq)]
pub struct Instance {
    /// Index into [`Scene::meshes`].
    pub mesh: usize,
    /// The node that places it, when it comes from a hierarchy.
    pub node: Option<usize>,
    /// Mesh-local to world transform at scene time 0 (for skinned meshes: the skeleton's space).
    pub transform: Affine3A,
    /// Index into [`Scene::skins`] when the mesh is skinned.
    pub skin: Option<usize>,
}

/// A glTF skin: the joints that deform a mesh.
#[derive(Clone, Debug, PartialEq)]
pub struct Skin {
    /// Name from the file.
    pub name: String,
    /// Joint node indices.
    pub joints: Vec<usize>,
    /// One inverse bind matrix per joint.
    pub inverse_bind: Vec<Mat4>,
}

/// What an animation channel drives.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AnimatedProperty {
    /// Node translation (3 floats per key).
    Translation,
    /// Node rotation quaternion x, y, z, w (4 floats per key).
    Rotation,
    /// Node scale (3 floats per key).
    Scale,
}

/// Keyframe interpolation (glTF sampler interpolation).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interpolation {
    /// Hold the previous key.
    Step,
    /// Linear (slerp for rotations).
    Linear,
    /// Cubic Hermite spline with in/out tangents stored around each value.
    CubicSpline,
}

/// One animated property of one node.
#[derive(Clone, Debug, PartialEq)]
pub struct Channel {
    /// Target node index.
    pub node: usize,
    /// Target property.
    pub property: AnimatedProperty,
    /// Interpolation between keys.
    pub interpolation: Interpolation,
    /// Key times in seconds, increasing.
    pub times: Vec<f32>,
    /// Flat key values; for cubic spline, (in-tangent, value, out-tangent) per key.
    pub values: Vec<f32>,
}

/// A named animation clip.
#[derive(Clone, Debug, PartialEq)]
pub struct Animation {
    /// Clip name.
    pub name: String,
    /// Its channels.
    pub channels: Vec<Channel>,
}

impl Animation {
    /// Length of the clip in seconds (last key time over all channels).
    pub fn duration(&self) -> f32 {
        self.channels
            .iter()
            .filter_map(|c| c.times.last().copied())
            .fold(0.0, f32::max)
    }
}

/// A root node carried along a path at constant speed, turned to face its direction of travel
/// (and optionally rolling like a ball), while the node's own clips keep playing.
///
/// At path arc length `s` with heading yaw `θ` (the angle turning +Z into the direction of
/// travel) the node's local transform becomes `T · R · S` with the node's rest scale `S`,
/// `R = yaw(θ) · roll · rotation` and `T` chosen so that `centre` (a point in the node's
/// child space, e.g. the asset's bounds centre) lands `lift` metres above the path point.
#[derive(Clone, Debug, PartialEq)]
pub struct Walker {
    /// The moved node; must be a root.
    pub node: usize,
    /// Path corners in world space (at least one).
    pub points: Vec<Vec3>,
    /// Speed along the path in metres per second.
    pub speed: f32,
    /// `true`: the path is closed (last point back to the first) and is walked round and
    /// round; `false`: it is walked to its end and back again.
    pub closed: bool,
    /// Orientation applied before the heading (the asset's `rotation_deg`).
    pub rotation: Quat,
    /// The point of the node's child space that follows the path.
    pub centre: Vec3,
    /// Height of `centre` above the path point (e.g. half the asset's height).
    pub lift: f32,
    /// When set, the node also rolls without slipping as a ball of this radius.
    pub roll_radius: Option<f32>,
}

/// A whole scene ready for tracing and rasterizing.
#[derive(Clone, Debug, Default)]
pub struct Scene {
    /// Meshes, shared by instances.
    pub meshes: Vec<Mesh>,
    /// Materials, indexed by [`Mesh::material`].
    pub materials: Vec<Material>,
    /// Node hierarchy (may be empty for OBJ).
    pub nodes: Vec<Node>,
    /// Placed meshes.
    pub instances: Vec<Instance>,
    /// Skins.
    pub skins: Vec<Skin>,
    /// Animation clips.
    pub animations: Vec<Animation>,
    /// Indices into [`Scene::animations`] that play.
    pub playing: Vec<usize>,
    /// Root nodes moved along paths (scene-file `walk` entries).
    pub walkers: Vec<Walker>,
    /// AO ray length in scene units (DESIGN §2 default 0.6).
    pub ao_radius: f32,
    /// Light sources (their placement at scene time 0; see [`Scene::lights_at`]).
    pub lights: Vec<crate::light::Light>,
    /// Suns whose direction follows keys over time.
    pub sun_keys: Vec<crate::light::SunKeys>,
    /// Light from directions where rays leave the scene.
    pub environment: crate::environment::Environment,
}

/// Default AO radius in metres (DESIGN §2).
pub const DEFAULT_AO_RADIUS: f32 = 0.6;

impl Scene {
    /// A static scene placing each of `meshes` once, untransformed, with one default
    /// material and the default AO radius.
    pub fn of_meshes(meshes: Vec<Mesh>) -> Scene {
        Scene {
            instances: (0..meshes.len())
                .map(|mesh| Instance {
                    mesh,
                    node: None,
                    transform: Affine3A::IDENTITY,
                    skin: None,
                })
                .collect(),
            meshes,
            materials: vec![Material::default()],
            ao_radius: DEFAULT_AO_RADIUS,
            ..Scene::default()
        }
    }

    /// Stops all motion: no clip plays and no walker walks, so every node keeps its rest
    /// transform and the scene is static.
    pub fn freeze(&mut self) {
        self.playing.clear();
        self.walkers.clear();
    }

    /// Whether mesh `mesh` is present (not alpha-cut, see [`Material::opaque_at`]) at
    /// barycentrics `bary` of triangle `tri`; `true` for a missing mesh or material.
    pub fn opaque_at(&self, mesh: usize, tri: u32, bary: Vec3) -> bool {
        let Some(m) = self.meshes.get(mesh) else {
            return true;
        };
        self.materials.get(m.material).is_none_or(|mat| {
            mat.opaque_at(mat.has_texel_mask().then(|| m.uv_at(tri, bary)).flatten())
        })
    }

    /// The lights at scene time `time` seconds: keyed suns turned to their direction then.
    pub fn lights_at(&self, time: f32) -> Vec<crate::light::Light> {
        let mut lights = self.lights.clone();
        for keys in &self.sun_keys {
            if let Some(l) = lights.get_mut(keys.light) {
                l.shape = crate::light::LightShape::Sun {
                    direction: keys.direction_at(time),
                };
            }
        }
        lights
    }

    /// Whether any light moves over time.
    pub fn lights_move(&self) -> bool {
        !self.sun_keys.is_empty()
    }

    /// Total triangle count over all instances.
    pub fn instanced_triangle_count(&self) -> usize {
        self.instances
            .iter()
            .map(|i| self.meshes[i.mesh].indices.len())
            .sum()
    }

    /// World-space bounds (min, max) of all instances at their current transforms.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        for inst in &self.instances {
            for p in &self.meshes[inst.mesh].positions {
                let w = inst.transform.transform_point3(*p);
                lo = lo.min(w);
                hi = hi.max(w);
            }
        }
        (lo, hi)
    }
}
