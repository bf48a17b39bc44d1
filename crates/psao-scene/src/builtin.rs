//! The built-in default scene: a colonnaded stone hall with fine detail and a few rigidly
//! moving objects, generated in code (no files, deterministic).
//!
//! Units are metres, y is up and the floor's top is at y = 0. The hall spans x ∈ [-10, 10],
//! z ∈ [-6, 6] inside its walls and is 6 m high; two rows of columns at z = ±3 carry arcades,
//! a stepped dais fills the east end.

mod hall;
mod movers;
mod props;
pub mod shapes;
#[cfg(test)]
mod tests;

use glam::{Affine3A, Quat, Vec3, Vec4};

use crate::light::{Light, LightShape};
use crate::model::{Instance, Material, Mesh, Node, Scene, DEFAULT_AO_RADIUS};

/// The default scene (about 140k instanced triangles, four animated objects looping over 10 s).
///
/// Non-diffuse objects for corrections: chrome balls on the dais pedestals, glazed amphorae,
/// a glass vase on the table, the polished dais railing, the iron grille and the brass
/// pendulum; their base colours are those of the diffuse materials they had, so the base image
/// and the AO are as without them. One sun light, from the direction of the client's default
/// shading, with the irradiance `0.5·π` that makes a white Lambertian surface as bright as the
/// client's direct term, and three rectangular light panels under the ceiling that light the
/// closed hall inside.
pub fn default_scene() -> Scene {
    let mut b = SceneBuilder::default();
    let palette = Palette::new(&mut b);
    hall::build(&mut b, &palette);
    props::build(&mut b, &palette);
    movers::build(&mut b, &palette);
    let mut scene = b.scene;
    scene.lights.push(Light {
        shape: LightShape::Sun {
            direction: Vec3::new(0.35, 1.0, 0.6).normalize(),
        },
        color: Vec3::ONE,
        power: 0.5 * std::f32::consts::PI,
    });
    scene.lights.extend(hall::lights());
    scene.playing = (0..scene.animations.len()).collect();
    scene.ao_radius = DEFAULT_AO_RADIUS;
    scene
}

/// A one-object asset for scene files: `"sphere"` (radius 0.5, centred on the origin),
/// `"box"` (a 1 m cube centred on the origin) or `"cylinder"` (radius 0.5, standing on y = 0,
/// 1 m high); its single instance hangs on a root node. `None` for other names.
pub fn shape_asset(name: &str) -> Option<Scene> {
    let (mesh, rgb) = match name {
        "sphere" => (shapes::sphere(0.5, 48), [0.60, 0.12, 0.10]),
        "box" => (shapes::cuboid(Vec3::splat(0.5)), [0.48, 0.32, 0.19]),
        "cylinder" => (shapes::cylinder(0.5, 1.0, 48), [0.36, 0.35, 0.34]),
        _ => return None,
    };
    let mut b = SceneBuilder::default();
    let material = b.material(name, rgb, 0.0, 0.8);
    let mesh = b.mesh(mesh, name, material);
    let node = b.node(name, None, Vec3::ZERO, Quat::IDENTITY);
    b.place_on_node(mesh, node);
    let mut scene = b.scene;
    scene.ao_radius = DEFAULT_AO_RADIUS;
    Some(scene)
}

/// Material indices of the default scene.
struct Palette {
    stone: usize,
    marble_light: usize,
    marble_dark: usize,
    plaster: usize,
    wood: usize,
    wood_dark: usize,
    iron: usize,
    brass: usize,
    terracotta: usize,
    paint: usize,
    /// Chrome with the stone's base colour (the base frame looks the same; corrections mirror).
    chrome: usize,
    /// Glazed terracotta: glossy.
    glaze: usize,
    /// Terracotta-tinted glass.
    glass: usize,
    /// Polished iron.
    polished_iron: usize,
}

impl Palette {
    fn new(b: &mut SceneBuilder) -> Self {
        Self {
            stone: b.material("stone", [0.62, 0.60, 0.56], 0.0, 0.9),
            marble_light: b.material("marble_light", [0.72, 0.70, 0.66], 0.0, 0.6),
            marble_dark: b.material("marble_dark", [0.36, 0.35, 0.34], 0.0, 0.6),
            plaster: b.material("plaster", [0.78, 0.75, 0.70], 0.0, 1.0),
            wood: b.material("wood", [0.48, 0.32, 0.19], 0.0, 0.8),
            wood_dark: b.material("wood_dark", [0.28, 0.18, 0.11], 0.0, 0.8),
            iron: b.material("iron", [0.20, 0.20, 0.21], 1.0, 0.5),
            brass: b.material("brass", [0.75, 0.60, 0.30], 1.0, 0.25),
            terracotta: b.material("terracotta", [0.62, 0.34, 0.22], 0.0, 0.9),
            paint: b.material("painted_red", [0.60, 0.12, 0.10], 0.0, 0.6),
            chrome: b.material("chrome", [0.62, 0.60, 0.56], 1.0, 0.02),
            glaze: b.material("glaze", [0.62, 0.34, 0.22], 0.0, 0.12),
            glass: {
                let m = b.material("glass", [0.62, 0.34, 0.22], 0.0, 0.0);
                b.scene.materials[m].transmission = 1.0;
                m
            },
            polished_iron: b.material("polished_iron", [0.20, 0.20, 0.21], 1.0, 0.1),
        }
    }
}

/// Accumulates materials, meshes, nodes and instances.
#[derive(Default)]
struct SceneBuilder {
    scene: Scene,
}

impl SceneBuilder {
    fn material(&mut self, name: &str, rgb: [f32; 3], metallic: f32, roughness: f32) -> usize {
        self.scene.materials.push(Material {
            name: name.into(),
            base_color: Vec4::new(rgb[0], rgb[1], rgb[2], 1.0),
            metallic,
            roughness,
            ..Material::default()
        });
        self.scene.materials.len() - 1
    }

    /// Adds a mesh with its name and material; returns its index.
    fn mesh(&mut self, mut mesh: Mesh, name: &str, material: usize) -> usize {
        mesh.name = name.into();
        mesh.material = material;
        self.scene.meshes.push(mesh);
        self.scene.meshes.len() - 1
    }

    /// A static instance of `mesh`.
    fn place(&mut self, mesh: usize, transform: Affine3A) {
        self.scene.instances.push(Instance {
            mesh,
            node: None,
            transform,
            skin: None,
        });
    }

    /// Adds a node (unit scale) and returns its index.
    fn node(
        &mut self,
        name: &str,
        parent: Option<usize>,
        translation: Vec3,
        rotation: Quat,
    ) -> usize {
        self.scene.nodes.push(Node {
            name: name.into(),
            parent,
            translation,
            rotation,
            scale: Vec3::ONE,
        });
        self.scene.nodes.len() - 1
    }

    /// An instance of `mesh` carried by `node`, placed at the node's current world transform.
    fn place_on_node(&mut self, mesh: usize, node: usize) {
        let transform = self.world_transform(node);
        self.scene.instances.push(Instance {
            mesh,
            node: Some(node),
            transform,
            skin: None,
        });
    }

    fn world_transform(&self, node: usize) -> Affine3A {
        let n = &self.scene.nodes[node];
        let local = n.local_transform();
        match n.parent {
            Some(p) => self.world_transform(p) * local,
            None => local,
        }
    }
}

/// A translation.
fn at(x: f32, y: f32, z: f32) -> Affine3A {
    Affine3A::from_translation(Vec3::new(x, y, z))
}

/// A rotation by `yaw_deg` about y followed by a translation.
fn at_yaw(x: f32, y: f32, z: f32, yaw_deg: f32) -> Affine3A {
    Affine3A::from_rotation_translation(
        Quat::from_rotation_y(yaw_deg.to_radians()),
        Vec3::new(x, y, z),
    )
}
