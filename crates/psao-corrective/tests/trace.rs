//! The correction tracer on small scenes, through every compiled backend.

use glam::{Affine3A, Vec3, Vec4};
use psao_corrective::trace::{diffuse_weight, CorrectionTracer, DiffuseShade, TraceSettings};
use psao_scene::builtin::shapes::cuboid;
use psao_scene::{Instance, Light, LightShape, Material, Mesh, Scene};
use psao_trace::{Backend, GeometryMode, Tracer};

/// Diffuse surfaces show a colour per instance.
struct PerInstance;

const WALL: Vec3 = Vec3::new(0.2, 0.5, 0.9);

impl DiffuseShade for PerInstance {
    fn shade(&self, _p: Vec3, _n: Vec3, instance: u32, _m: &Material) -> Vec3 {
        if instance == 1 {
            WALL
        } else {
            Vec3::new(0.3, 0.3, 0.3)
        }
    }
}

/// Instance 0: a thin slab at z = 0 with `front` material; instance 1: a diffuse wall at
/// z = −3 behind it; instance 2: a diffuse wall at z = +3 facing it.
fn scene(front: Material) -> Scene {
    let slab = cuboid(Vec3::new(1.0, 1.0, 0.01));
    let mut wall = cuboid(Vec3::new(20.0, 20.0, 0.01));
    wall.material = 1;
    let mut s = Scene::of_meshes(vec![
        Mesh {
            material: 0,
            ..slab
        },
        wall,
    ]);
    s.materials = vec![
        front,
        Material {
            name: "wall".into(),
            ..Material::default()
        },
    ];
    s.instances = vec![
        Instance {
            mesh: 0,
            node: None,
            transform: Affine3A::IDENTITY,
            skin: None,
        },
        Instance {
            mesh: 1,
            node: None,
            transform: Affine3A::from_translation(Vec3::new(0.0, 0.0, -3.0)),
            skin: None,
        },
        Instance {
            mesh: 1,
            node: None,
            transform: Affine3A::from_translation(Vec3::new(0.0, 0.0, 3.0)),
            skin: None,
        },
    ];
    s
}

fn chrome(roughness: f32) -> Material {
    Material {
        name: "chrome".into(),
        base_color: Vec4::ONE,
        metallic: 1.0,
        roughness,
        ..Material::default()
    }
}

fn tracers(scene: &Scene) -> Vec<Tracer> {
    Backend::compiled()
        .into_iter()
        .map(|b| Tracer::new(b, scene, GeometryMode::Primary).unwrap())
        .collect()
}

const EYE: Vec3 = Vec3::new(0.0, 0.0, 2.0);

#[test]
fn a_white_mirror_shows_exactly_what_the_client_shows_behind_the_viewer() {
    let s = scene(chrome(0.0));
    for t in tracers(&s) {
        let ct = CorrectionTracer::new(&s, &t, &PerInstance, TraceSettings::default());
        let (l, hit) = ct.primary(EYE, Vec3::new(0.05, 0.02, -1.0), 0, 7);
        // White metal: Fresnel is 1 at every angle; the reflection hits the wall behind the eye.
        assert_eq!(l, Vec3::new(0.3, 0.3, 0.3), "{:?}", t.backend());
        let (p, n) = hit.unwrap();
        assert!((p.z - 0.01).abs() < 1e-4 && (n - Vec3::Z).length() < 1e-4);
    }
}

#[test]
fn clear_glass_of_index_one_passes_the_wall_behind_it() {
    let glass = Material {
        name: "glass".into(),
        base_color: Vec4::ONE,
        roughness: 0.0,
        transmission: 1.0,
        ior: 1.0,
        ..Material::default()
    };
    let s = scene(glass);
    for t in tracers(&s) {
        let ct = CorrectionTracer::new(&s, &t, &PerInstance, TraceSettings::default());
        let (l, _) = ct.primary(EYE, Vec3::new(0.1, -0.05, -1.0), 0, 3);
        assert!((l - WALL).length() < 1e-5, "{l}");
    }
}

#[test]
fn glass_reflects_more_at_grazing_angles() {
    let glass = Material {
        name: "glass".into(),
        base_color: Vec4::ONE,
        roughness: 0.0,
        transmission: 1.0,
        ior: 1.5,
        ..Material::default()
    };
    let s = scene(glass);
    let t = &tracers(&s)[0];
    let ct = CorrectionTracer::new(&s, t, &PerInstance, TraceSettings::default());
    // Blue share: the wall behind is blue, the wall in front grey.
    let blue = |dir: Vec3| {
        let (l, _) = ct.primary(EYE, dir, 0, 1);
        l.z - l.x
    };
    assert!(blue(Vec3::new(0.0, 0.0, -1.0)) > blue(Vec3::new(0.0, 0.45, -1.0)));
}

#[test]
fn glossy_samples_are_deterministic_per_pixel_and_frame() {
    let s = scene(chrome(0.4));
    let t = &tracers(&s)[0];
    let ct = CorrectionTracer::new(&s, t, &PerInstance, TraceSettings::default());
    let dir = Vec3::new(0.3, 0.2, -1.0);
    let a = ct.primary(EYE, dir, 5, 11).0;
    assert_eq!(a, ct.primary(EYE, dir, 5, 11).0);
    // Another frame or pixel draws other glossy rays (the slab's edge is within the lobe).
    let others = [ct.primary(EYE, dir, 6, 11).0, ct.primary(EYE, dir, 5, 12).0];
    assert!(others.iter().any(|&o| o != a));
}

#[test]
fn lights_add_highlights_and_shadow_rays_block_them() {
    let s0 = scene(chrome(0.3));
    let mut lit = s0.clone();
    // A point light just in front of the slab, mirrored around the view direction.
    lit.lights.push(Light {
        shape: LightShape::Point {
            position: Vec3::new(0.0, 0.0, 1.0),
        },
        color: Vec3::ONE,
        power: 2.0,
    });
    let mut blocked = lit.clone();
    // A small occluder between the light and the slab.
    blocked.meshes.push(Mesh {
        material: 1,
        ..cuboid(Vec3::new(0.2, 0.2, 0.01))
    });
    blocked.instances.push(Instance {
        mesh: 2,
        node: None,
        transform: Affine3A::from_translation(Vec3::new(0.0, 0.0, 0.5)),
        skin: None,
    });
    let settings = TraceSettings {
        glossy_rays: 1,
        ..TraceSettings::default()
    };
    let radiance = |s: &Scene| {
        let t = Tracer::new(Backend::Obvhs, s, GeometryMode::Primary).unwrap();
        let ct = CorrectionTracer::new(s, &t, &PerInstance, settings);
        // From the side, so the occluder does not hide the slab from the eye.
        ct.primary(Vec3::new(0.6, 0.0, 1.5), Vec3::new(-0.6, 0.0, -1.5), 0, 0)
            .0
    };
    let (dark, bright, shadowed) = (radiance(&s0), radiance(&lit), radiance(&blocked));
    assert!(bright.x > dark.x + 0.05, "{bright} vs {dark}");
    assert!((shadowed.x - dark.x).abs() < 0.02, "{shadowed} vs {dark}");
}

#[test]
fn camera_samples_match_primary_rays_and_only_their_object() {
    let s = scene(chrome(0.2));
    let camera = psao_scene::Camera::look_at(Vec3::new(0.3, 0.2, 2.0), Vec3::ZERO, 50.0);
    let (w, h) = (24u32, 16u32);
    for t in tracers(&s) {
        let tracer = CorrectionTracer::new(&s, &t, &PerInstance, TraceSettings::default());
        let mut on_slab = 0;
        for y in 0..h as i32 {
            for x in 0..w as i32 {
                let object = tracer.object_at(&camera, w, h, x, y);
                // The slab (instance 0) is the only non-diffuse object.
                assert!(object == 0 || object == 1);
                let sample = tracer.camera_sample(&camera, w, h, x, y, 1, 2, 5);
                assert_eq!(sample.is_some(), object == 1, "pixel {x}, {y}");
                assert!(tracer.camera_sample(&camera, w, h, x, y, 2, 2, 5).is_none());
                let Some(sample) = sample else { continue };
                on_slab += 1;
                let dir = camera.ray_direction(x as f32 + 0.5, y as f32 + 0.5, w, h);
                let pixel = (y as u32 * w + x as u32) as u64;
                let (color, hit) = tracer.primary(camera.position, dir, 5, pixel);
                assert_eq!(sample.color, color.to_array());
                assert_eq!(hit.unwrap(), (sample.position, sample.normal));
                assert!(sample.position.z.abs() < 0.02);
                assert!(sample.ndotv > 0.0 && sample.ndotv <= 1.0);
                assert_eq!((sample.level, sample.age, sample.object), (2, 5, 1));
            }
        }
        assert!(on_slab > 20, "{on_slab} pixels on the slab");
        assert!(tracer
            .camera_sample(&camera, w, h, -1, 0, 1, 1, 0)
            .is_none());
        assert!(tracer
            .camera_sample(&camera, w, h, 0, h as i32, 1, 1, 0)
            .is_none());
    }
}

#[test]
fn a_posed_tracer_sees_skinned_vertices_like_a_scene_built_in_that_pose() {
    // The mirror slab deformed (tilted 25° about y, pushed back) as a skinned pose would.
    let s = scene(chrome(0.0));
    let tilt = glam::Quat::from_rotation_y(0.44);
    let geometry = psao_scene::SkinnedGeometry {
        positions: (s.meshes[0].positions.iter())
            .map(|&p| tilt * p - Vec3::new(0.0, 0.0, 0.3))
            .collect(),
        normals: s.meshes[0].normals.iter().map(|&n| tilt * n).collect(),
    };
    let pose = psao_scene::ScenePose {
        time: 1.0,
        nodes: Vec::new(),
        transforms: s.instances.iter().map(|i| i.transform).collect(),
        skinned: vec![Some(geometry.clone()), None, None],
    };
    let motion = [
        psao_scene::Motion::Skinned,
        psao_scene::Motion::Static,
        psao_scene::Motion::Static,
    ];
    let mut built = s.clone();
    built.meshes[0].positions = geometry.positions;
    built.meshes[0].normals = geometry.normals;
    let camera = psao_scene::Camera::look_at(Vec3::new(0.3, 0.2, 2.0), Vec3::ZERO, 50.0);
    let (w, h) = (24u32, 16u32);
    for backend in Backend::compiled() {
        let mut posed_tracer = Tracer::new(backend, &s, GeometryMode::Primary).unwrap();
        posed_tracer.apply_pose(&s, &motion, &pose).unwrap();
        let built_tracer = Tracer::new(backend, &built, GeometryMode::Primary).unwrap();
        let rest_tracer = Tracer::new(backend, &s, GeometryMode::Primary).unwrap();
        let settings = TraceSettings::default();
        let posed = CorrectionTracer::new(&s, &posed_tracer, &PerInstance, settings).posed(&pose);
        let reference = CorrectionTracer::new(&built, &built_tracer, &PerInstance, settings);
        let rest = CorrectionTracer::new(&s, &rest_tracer, &PerInstance, settings);
        let (mut on_slab, mut moved) = (0, 0);
        for y in 0..h as i32 {
            for x in 0..w as i32 {
                let sample = |t: &CorrectionTracer| t.camera_sample(&camera, w, h, x, y, 1, 1, 0);
                let got = sample(&posed);
                assert_eq!(got, sample(&reference), "pixel ({x}, {y}) on {backend:?}");
                on_slab += usize::from(got.is_some());
                moved += usize::from(got != sample(&rest));
            }
        }
        assert!(on_slab > 20, "{on_slab} pixels show the slab");
        assert!(
            moved * 2 > on_slab,
            "the pose changes {moved} of {on_slab} samples"
        );
    }
}

/// Without the own diffuse part (a lit base), a sample of a glossy dielectric is its full
/// radiance minus `diffuse_weight × the client's shading` at its surface: what is left is
/// the view-dependent part. A diffuse-looking grazing view keeps less of the base.
#[test]
fn a_view_dependent_sample_leaves_out_exactly_the_diffuse_part_of_its_own_surface() {
    let lacquer = Material {
        name: "lacquer".into(),
        base_color: Vec4::new(0.8, 0.1, 0.1, 1.0),
        roughness: 0.0,
        ..Material::default()
    };
    let s = scene(lacquer.clone());
    for t in tracers(&s) {
        let full = CorrectionTracer::new(&s, &t, &PerInstance, TraceSettings::default());
        let view_dependent = CorrectionTracer::new(
            &s,
            &t,
            &PerInstance,
            TraceSettings {
                own_diffuse: false,
                ..TraceSettings::default()
            },
        );
        let dir = Vec3::new(0.1, 0.05, -1.0);
        let (l_full, hit) = full.primary(EYE, dir, 0, 9);
        let (l_view, _) = view_dependent.primary(EYE, dir, 0, 9);
        let (p, n) = hit.unwrap();
        let kd = diffuse_weight(&lacquer, n.dot((EYE - p).normalize()));
        assert!(kd > 0.9 && kd < 1.0, "{kd}");
        // The slab's diffuse shading is instance 0's grey.
        let expected = l_full - kd * Vec3::splat(0.3);
        assert!(
            (l_view - expected).length() < 1e-5,
            "{l_view} vs {expected}"
        );
        // A mirror reflection of the grey wall in front remains (Fresnel at normal incidence).
        assert!(l_view.min_element() > 0.0);
    }
    assert!(diffuse_weight(&lacquer, 0.1) < diffuse_weight(&lacquer, 1.0));
    assert_eq!(diffuse_weight(&chrome(0.2), 1.0), 0.0);
}
