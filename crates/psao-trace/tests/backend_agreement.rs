//! obvhs and Embree must answer the same on real geometry (feature `embree` only).
#![cfg(feature = "embree")]

mod common;

use psao_trace::{sort_rays_spatially, Backend, GeometryMode, Tracer};

#[test]
fn obvhs_and_embree_agree_on_sponza_ao_rays() {
    let Some(path) = common::data_file("scenes/dabrovic_sponza.obj") else {
        return;
    };
    let scene = common::obj::load(&path);
    let rays = common::surface_ao_rays(&scene, 200_000, 2024, 0.6);
    let order = sort_rays_spatially(&rays);
    let obvhs = Tracer::new(Backend::Obvhs, &scene, GeometryMode::Occlusion).unwrap();
    let embree = Tracer::new(Backend::Embree, &scene, GeometryMode::Occlusion).unwrap();
    let (occ_o, rate_o) = common::timed_occluded(&obvhs, &rays, &order);
    let (occ_e, rate_e) = common::timed_occluded(&embree, &rays, &order);
    let (hit_o, irate_o) = common::timed_intersect(&obvhs, &rays, &order);
    let (hit_e, irate_e) = common::timed_intersect(&embree, &rays, &order);
    println!(
        "sorted AO rays, Mrays/s per core: occluded obvhs {rate_o:.2}, embree {rate_e:.2}; \
         intersect obvhs {irate_o:.2}, embree {irate_e:.2}"
    );

    let n = rays.len() as f64;
    let occluded = occ_o.iter().filter(|&&o| o).count();
    assert!(
        occluded as f64 > 0.2 * n && (occluded as f64) < 0.8 * n,
        "{occluded}"
    );
    let same_occ = occ_o.iter().zip(&occ_e).filter(|(a, b)| a == b).count();
    assert!(
        same_occ as f64 >= 0.999 * n,
        "occluded agrees on {same_occ} of {n}"
    );

    let (mut both, mut same_t, mut same_id) = (0usize, 0usize, 0usize);
    for (a, b) in hit_o.iter().zip(&hit_e) {
        if let (Some(a), Some(b)) = (a, b) {
            both += 1;
            if (a.t - b.t).abs() <= 1e-3 * a.t.max(b.t) {
                same_t += 1;
            }
            if (a.instance, a.triangle) == (b.instance, b.triangle) {
                same_id += 1;
            }
        }
    }
    let hits = hit_o.iter().filter(|h| h.is_some()).count();
    println!(
        "agreement: occluded {:.4}%, both hit {both} of {hits}, t {:.4}%, ids {:.4}%",
        100.0 * same_occ as f64 / n,
        100.0 * same_t as f64 / both as f64,
        100.0 * same_id as f64 / both as f64
    );
    assert!(
        both as f64 >= 0.999 * hits as f64,
        "both hit on {both} of {hits}"
    );
    assert!(
        same_t as f64 >= 0.999 * both as f64,
        "t agrees on {same_t} of {both}"
    );
    // Ties (a shared edge, coplanar faces) may pick different triangles, rarely.
    assert!(
        same_id as f64 >= 0.99 * both as f64,
        "ids agree on {same_id} of {both}"
    );
}
