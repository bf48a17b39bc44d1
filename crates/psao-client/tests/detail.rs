//! The screen-space detail term: off at strength 0, no change on open flat ground, darker
//! along contact lines, deterministic.

mod common;

use glam::Vec3;
use psao_client::{apply_detail, reconstruct, ClientState, DetailSettings, ReconstructSettings};
use psao_raster::{rasterize, RasterOptions};

fn setup(scene: &psao_scene::Scene) -> ClientState {
    let points = common::points(scene, 1024.0, 5);
    let grids: Vec<_> = common::grids(&points, |_| 0.5)
        .into_iter()
        .map(|(g, _)| g)
        .collect();
    let mut state = ClientState::new(&common::table(&points, &grids));
    state
        .apply(&common::snapshot(1, &grids, common::transforms(scene)))
        .unwrap();
    state
}

#[test]
fn detail_darkens_contact_lines_only() {
    let scene = common::scene(2.0, 2);
    let state = setup(&scene);
    let camera = common::camera();
    let g = rasterize(&scene, &camera, &RasterOptions::new(640, 480));
    let base = reconstruct(&state, &g, &ReconstructSettings::default());
    let settings = DetailSettings::default();

    let mut off = base.clone();
    apply_detail(
        &state,
        &g,
        &camera,
        &DetailSettings {
            strength: 0.0,
            ..settings
        },
        &mut off,
    );
    assert_eq!(off, base);

    let mut ao = base.clone();
    apply_detail(&state, &g, &camera, &settings, &mut ao);
    let mut again = base.clone();
    apply_detail(&state, &g, &camera, &settings, &mut again);
    assert_eq!(ao, again, "deterministic");

    let cubes: Vec<Vec3> = scene.instances[1..]
        .iter()
        .map(|i| i.transform.translation.into())
        .collect();
    let ground_distance = |p: Vec3| {
        cubes
            .iter()
            .map(|c| Vec3::new(p.x - c.x, 0.0, p.z - c.z).length())
            .fold(f32::INFINITY, f32::min)
    };
    let (mut open, mut darker) = (0, 0);
    for i in (0..g.len()).filter(|&i| g.covered(i) && g.instance[i] == 0) {
        let d = ground_distance(g.position[i]);
        if d > 1.3 {
            assert_eq!(ao[i], base[i], "open ground pixel {i} changed");
            open += 1;
        } else if d < 0.75 && ao[i] < base[i] - 0.01 {
            darker += 1;
        }
        assert!((0.0..=1.0).contains(&ao[i]));
    }
    assert!(open > 4000, "{open}");
    assert!(darker > 10, "{darker}");
}
