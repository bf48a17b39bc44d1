//! Alpha-masked materials: fragments on cut-out texels are not drawn and the surface behind
//! shows through; the decision matches `Scene::opaque_at` (the one the server's point
//! generation uses) at the resolved barycentrics.

use std::sync::Arc;

use glam::{Affine3A, Vec2, Vec3};
use psao_raster::{rasterize, GBuffer, RasterOptions};
use psao_scene::{
    AlphaImage, AlphaMode, AlphaTexture, Camera, Instance, Material, Mesh, Scene, Wrap,
};

const SIZE: u32 = 8;
const CELL: u32 = 2;
const W: u32 = 96;
const H: u32 = 80;

fn opaque_texel(x: u32, y: u32) -> bool {
    (x / CELL + y / CELL).is_multiple_of(2)
}

/// A quad over [0, s]² in the plane z = `z`, facing +z, UV = (x, y) / s.
fn quad(s: f32, z: f32, material: usize) -> Mesh {
    let positions = vec![
        Vec3::new(0.0, 0.0, z),
        Vec3::new(s, 0.0, z),
        Vec3::new(s, s, z),
        Vec3::new(0.0, s, z),
    ];
    Mesh {
        name: "quad".into(),
        uvs: positions.iter().map(|p| Vec2::new(p.x, p.y) / s).collect(),
        positions,
        normals: vec![Vec3::Z; 4],
        indices: vec![[0, 1, 2], [0, 2, 3]],
        material,
        ..Mesh::default()
    }
}

/// Instance 0: the masked unit quad at z = 0; instance 1: an opaque 3 m wall behind it.
fn scene(masked: Material) -> Scene {
    let alpha: Vec<u8> = (0..SIZE * SIZE)
        .map(|i| {
            if opaque_texel(i % SIZE, i / SIZE) {
                255
            } else {
                0
            }
        })
        .collect();
    let masked = Material {
        alpha_texture: masked.alpha_texture.or(Some(AlphaTexture {
            image: Arc::new(AlphaImage::new(SIZE, SIZE, alpha).unwrap()),
            tex_coord: 0,
            wrap_s: Wrap::Repeat,
            wrap_t: Wrap::Repeat,
        })),
        ..masked
    };
    let place = |mesh: usize, at: Vec3| Instance {
        mesh,
        node: None,
        transform: Affine3A::from_translation(at),
        skin: None,
    };
    Scene {
        meshes: vec![quad(1.0, 0.0, 0), quad(3.0, 0.0, 1)],
        materials: vec![masked, Material::default()],
        instances: vec![place(0, Vec3::ZERO), place(1, Vec3::new(-1.0, -1.0, -1.0))],
        ao_radius: psao_scene::DEFAULT_AO_RADIUS,
        ..Scene::default()
    }
}

fn render(scene: &Scene) -> GBuffer {
    let camera = Camera::look_at(Vec3::new(0.5, 0.5, 2.0), Vec3::new(0.5, 0.5, 0.0), 40.0);
    rasterize(scene, &camera, &RasterOptions::new(W, H))
}

fn masked_material() -> Material {
    Material {
        name: "checker".into(),
        alpha_mode: AlphaMode::Mask { cutoff: 0.5 },
        ..Material::default()
    }
}

#[test]
fn cut_out_texels_show_the_surface_behind() {
    let scene = scene(masked_material());
    let g = render(&scene);
    let (mut front, mut behind_hole) = (0, 0);
    let camera = Camera::look_at(Vec3::new(0.5, 0.5, 2.0), Vec3::new(0.5, 0.5, 0.0), 40.0);
    for y in 0..H {
        for x in 0..W {
            let i = g.index(x, y);
            assert!(g.covered(i), "the wall covers the whole view");
            match g.instance[i] {
                0 => {
                    let b = g.barycentric[i];
                    let bary = Vec3::new(1.0 - b.x - b.y, b.x, b.y);
                    assert!(scene.opaque_at(0, g.triangle[i], bary), "pixel {x},{y}");
                    front += 1;
                }
                1 => {
                    // Where the pixel ray crosses the quad's plane inside the quad, the texel
                    // there must be cut out (texel borders skipped: the ray and the resolved
                    // barycentrics differ by rounding).
                    let d = camera.ray_direction(x as f32 + 0.5, y as f32 + 0.5, W, H);
                    let p = camera.position + d * (-camera.position.z / d.z);
                    let t = Vec2::new(p.x, p.y) * SIZE as f32;
                    let near_border = (t - t.round()).abs().min_element() < 1e-3;
                    if (0.0..1.0).contains(&p.x) && (0.0..1.0).contains(&p.y) && !near_border {
                        assert!(
                            !opaque_texel(t.x as u32, t.y as u32),
                            "pixel {x},{y} at {t}"
                        );
                        behind_hole += 1;
                    }
                }
                other => panic!("unexpected instance {other}"),
            }
        }
    }
    // The quad covers a large part of the view and half of it is cut out.
    assert!(
        front > 500 && behind_hole > 500,
        "{front} front, {behind_hole} through holes"
    );
    let ratio = front as f64 / (front + behind_hole) as f64;
    assert!((0.4..0.6).contains(&ratio), "{ratio}");
}

#[test]
fn factor_alone_below_the_cutoff_hides_the_whole_surface() {
    let faint = Material {
        base_color: glam::Vec4::new(1.0, 1.0, 1.0, 0.2),
        ..masked_material()
    };
    let mut scene = scene(faint);
    scene.materials[0].alpha_texture = None;
    let g = render(&scene);
    assert!(g.instance.iter().all(|&i| i == 1));
    // Opaque mode: the texture is ignored and the quad is drawn whole.
    scene.materials[0].alpha_mode = AlphaMode::Opaque;
    let g = render(&scene);
    let front = g.instance.iter().filter(|&&i| i == 0).count();
    let expected = render(&Scene {
        materials: vec![Material::default(), Material::default()],
        ..scene.clone()
    });
    assert!(front > 1000);
    assert_eq!(g.instance, expected.instance);
}
