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
