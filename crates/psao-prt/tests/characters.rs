//! Tests on the real skinned characters in the shared data folder (skipped when missing).

use std::path::PathBuf;

use psao_prt::character::Character;
use psao_prt::fit::fit_lobes;
use psao_prt::model::{model_error, train, Sample};
use psao_prt::visibility::{visibility_sh, SelfTracer};
use psao_prt::PrtError;

fn data(rel: &str) -> Option<PathBuf> {
    let p = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data")).join(rel);
    if p.exists() {
        Some(p)
    } else {
        eprintln!("note: {} missing, test skipped", p.display());
        None
    }
}

fn fox(clip: &str) -> Option<Character> {
    let scene = psao_scene::load_scene(&data("characters/Fox.glb")?).unwrap();
    Some(Character::new(scene, Some(clip)).unwrap())
}

#[test]
fn clips_are_chosen_by_name_or_index_and_unknown_ones_refused() {
    let Some(path) = data("characters/Fox.glb") else {
        return;
    };
    let scene = psao_scene::load_scene(&path).unwrap();
    let c = Character::new(scene.clone(), Some("Run")).unwrap();
    assert_eq!(c.clip_name(), "Run");
    assert_eq!(
        Character::new(scene.clone(), Some("2"))
            .unwrap()
            .clip_name(),
        "Run"
    );
    let err = Character::new(scene, Some("Dance")).err().unwrap();
    assert!(matches!(err, PrtError::UnknownClip { .. }));
    assert!(err.to_string().contains("Survey"), "{err}");
}

#[test]
fn a_scene_without_a_skin_is_refused() {
    let Some(path) = data("scenes/2CylinderEngine.glb") else {
        return;
    };
    let scene = psao_scene::load_scene(&path).unwrap();
    assert!(matches!(Character::new(scene, None), Err(PrtError::NoSkin)));
}

#[test]
fn visibility_is_deterministic_and_in_range() {
    let Some(fox) = fox("Walk") else { return };
    let pose = fox.pose(0.3);
    let mut tracer = SelfTracer::new(fox.occluder_mesh()).unwrap();
    tracer.set_pose(&pose).unwrap();
    let a = visibility_sh(&tracer, &pose, 64, 7);
    let b = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| visibility_sh(&tracer, &pose, 64, 7));
    assert_eq!(a, b);
    let c = visibility_sh(&tracer, &pose, 64, 8);
    assert_ne!(a, c);
    // Visible fraction v0 / (2√π) in [½, 1] (the lower hemisphere counts as visible); the
    // body blocks part of the upper hemisphere at many vertices.
    let fractions: Vec<f32> = a
        .iter()
        .map(|v| v[0] / (2.0 * std::f32::consts::PI.sqrt()))
        .collect();
    assert!(fractions.iter().all(|f| (0.5 - 1e-4..=1.0001).contains(f)));
    let mean = fractions.iter().sum::<f32>() / fractions.len() as f32;
    assert!((0.6..0.97).contains(&mean), "mean visible fraction {mean}");
    // Occluders lie above the tangent plane, so on average visibility leans to −z.
    let mean_z = a.iter().map(|v| v[2]).sum::<f32>() / a.len() as f32;
    assert!(mean_z < -0.05, "mean band-1 z {mean_z}");
}

#[test]
fn two_lobes_fit_better_than_one_and_the_model_predicts_held_out_frames() {
    let Some(fox) = fox("Walk") else { return };
    let mut tracer = SelfTracer::new(fox.occluder_mesh()).unwrap();
    let mut sample = |t: f32| {
        let pose = fox.pose(t);
        tracer.set_pose(&pose).unwrap();
        Sample {
            visibility: visibility_sh(&tracer, &pose, 48, 1),
            joint_rotations: pose.joint_rotations,
        }
    };
    let d = fox.duration();
    let train_set: Vec<Sample> = (0..8).map(|i| sample(d * i as f32 / 8.0)).collect();
    let validate: Vec<Sample> = (0..4)
        .map(|i| sample(d * (2 * i + 1) as f32 / 8.0 + 0.01))
        .collect();
    let mean_fit = |lobes: usize| {
        let s = &train_set[0].visibility;
        s.iter().map(|v| fit_lobes(v, lobes, None).1).sum::<f32>() / s.len() as f32
    };
    let (e1, e2) = (mean_fit(1), mean_fit(2));
    assert!(e2 < e1, "two lobes {e2} vs one {e1}");
    let (model, report) = train("Fox", &train_set, &validate, 2, &|_, _| {}).unwrap();
    assert_eq!(model.vertices, fox.vertex_count());
    assert!(!model.active.is_empty());
    assert!(report.ridge_errors.len() > 1);
    // The model's error on held-out frames is well below doing nothing (the mean visibility).
    let (err, _) = model_error(&model, &validate);
    let unit = psao_prt::shade::unit_visibility();
    let baseline: f32 = validate
        .iter()
        .flat_map(|s| {
            s.visibility
                .iter()
                .map(|v| psao_prt::fit::rms_difference(v, &unit))
        })
        .sum::<f32>()
        / (validate.len() * fox.vertex_count()) as f32;
    assert!(err < 0.5 * baseline, "model {err} vs unshadowed {baseline}");
}

/// A client relighting the Fox from its joint transforms and skinned vertices gets what
/// shading the model's prediction at the character's own pose and frames gives.
#[test]
fn a_client_frame_shades_like_the_characters_own_pose() {
    use psao_prt::model::{PoseModel, LOBE_DIM};
    use psao_prt::runtime::{FramePose, Relighter};
    use psao_prt::shade::{Mode, Shader, ShadingGeometry, Visibility};
    let Some(fox) = fox("Survey") else { return };
    let (vertices, joints) = (fox.vertex_count(), fox.joint_count());
    let out = vertices * 2 * LOBE_DIM;
    // Weights that make the lobes depend on every joint (values arbitrary but fixed).
    let weights = (0..(1 + 3 * joints) * out)
        .map(|i| ((i * 2_654_435_761usize) % 1000) as f32 / 1000.0 - 0.5)
        .collect();
    let model = PoseModel {
        character: "Fox".into(),
        vertices,
        joints,
        lobes: 2,
        active: (0..joints as u32).collect(),
        weights,
        limits: Default::default(),
    };
    let mode = Mode::Phong { alpha: 8.0 };
    let mut relighter =
        Relighter::new(model.clone(), Shader::new(mode).unwrap(), fox.rig()).unwrap();
    let mut light = psao_prt::shade::unit_visibility();
    light[1] = 0.7;
    light[6] = -0.4;
    let eye = glam::Vec3::new(0.0, 80.0, 300.0);
    for t in [0.3, 1.7] {
        let pose = fox.pose(t);
        let frame = FramePose {
            joint_local: &pose.joint_local,
            positions: &pose.positions,
            normals: &pose.normals,
            transform: pose.transform,
        };
        let client = relighter.shade(&frame, &[light], eye).unwrap();
        let mut raw = Vec::new();
        model.predict_raw(&model.pose_vector(&pose.joint_rotations), &mut raw);
        let direct = Shader::new(mode)
            .unwrap()
            .shade(
                Visibility::Model(&model, &raw),
                ShadingGeometry {
                    positions: &pose.positions,
                    frames: &pose.frames,
                    transform: pose.transform,
                },
                &[light],
                eye,
            )
            .unwrap();
        assert_eq!(client.len(), vertices);
        let worst = client
            .iter()
            .zip(&direct)
            .map(|(a, b)| (a - b).abs() / b.abs().max(1.0))
            .fold(0.0f32, f32::max);
        // The relighter interpolates the lighting's transfer from a table (runtime.rs):
        // within 5e-3 of the direct shading even for these arbitrary, far from unit lobes.
        assert!(worst < 5e-3, "t = {t}: worst relative difference {worst}");
    }
}

/// A trained model relit frame by frame as a client does (compacted model, tabulated
/// lighting) shades like the model's direct prediction shaded by `Shader::shade`, in every
/// mode, on training and held-out poses: the differences, relative to the frame's brightest
/// vertex, stay within 2e-3 (worst vertex) and 2e-4 (mean).
#[test]
fn a_trained_model_relights_like_its_direct_shading() {
    use psao_prt::fade::FadeRule;
    use psao_prt::runtime::{FramePose, Relighter};
    use psao_prt::shade::{Mode, Shader, ShadingGeometry, Visibility};
    let Some(fox) = fox("Walk") else { return };
    let mut tracer = SelfTracer::new(fox.occluder_mesh()).unwrap();
    let d = fox.duration();
    let train_set: Vec<Sample> = (0..8)
        .map(|i| {
            let pose = fox.pose(d * i as f32 / 8.0);
            tracer.set_pose(&pose).unwrap();
            Sample {
                visibility: visibility_sh(&tracer, &pose, 48, 1),
                joint_rotations: pose.joint_rotations,
            }
        })
        .collect();
    let (model, _) = train("Fox", &train_set, &[], 2, &|_, _| {}).unwrap();
    // A sky with every band: brighter above, tinted per channel.
    let lights: Vec<_> = (0..3)
        .map(|c| {
            let mut l = psao_prt::shade::unit_visibility();
            for (i, x) in l.iter_mut().enumerate().skip(1) {
                *x = 0.6 * (((i * 7 + c * 3) % 11) as f32 / 10.0 - 0.5) / (1 + i / 4) as f32;
            }
            l[2] = 0.9;
            l
        })
        .collect();
    let eye = glam::Vec3::new(40.0, 90.0, 280.0);
    for mode in [
        Mode::Diffuse,
        Mode::Phong { alpha: 16.0 },
        Mode::Translucent { transmission: 0.3 },
    ] {
        let mut relighter =
            Relighter::new(model.clone(), Shader::new(mode).unwrap(), fox.rig()).unwrap();
        let (mut worst, mut sum, mut count) = (0.0f32, 0.0f32, 0usize);
        // Training poses and poses between them.
        for t in [0.0, 0.37 * d, d * 3.0 / 8.0, 0.81 * d] {
            let pose = fox.pose(t);
            let frame = FramePose {
                joint_local: &pose.joint_local,
                positions: &pose.positions,
                normals: &pose.normals,
                transform: pose.transform,
            };
            let client = relighter.shade(&frame, &lights, eye).unwrap();
            let mut raw = Vec::new();
            let fade = FadeRule::of_mode(mode);
            psao_prt::fade::predict(&model, fade, &pose.joint_rotations, &mut raw);
            let direct = Shader::new(mode)
                .unwrap()
                .shade(
                    Visibility::Model(&model, &raw),
                    ShadingGeometry {
                        positions: &pose.positions,
                        frames: &pose.frames,
                        transform: pose.transform,
                    },
                    &lights,
                    eye,
                )
                .unwrap();
            let brightest = direct.iter().fold(0.0f32, |a, b| a.max(b.abs()));
            for (a, b) in client.iter().zip(&direct) {
                let e = (a - b).abs() / brightest;
                worst = worst.max(e);
                sum += e;
                count += 1;
            }
        }
        let mean = sum / count as f32;
        eprintln!("{mode:?}: worst {worst:.2e}, mean {mean:.2e}");
        assert!(
            worst < 2e-3 && mean < 2e-4,
            "{mode:?}: worst {worst}, mean {mean}"
        );
    }
}
