//! Every compiled backend on the real Sponza geometry: hits map back to the right instance and
//! triangle, `occluded` agrees with `intersect`, and a rough single-thread throughput print.

mod common;

use psao_trace::{sort_rays_spatially, Backend, GeometryMode, Tracer};

#[test]
fn sponza_hits_map_back_to_scene_triangles() {
    let Some(path) = common::data_file("scenes/dabrovic_sponza.obj") else {
        return;
    };
    let scene = common::obj::load(&path);
    assert_eq!(scene.instances.len(), 33);
    assert_eq!(scene.instanced_triangle_count(), 66_447);
    let rays = common::surface_ao_rays(&scene, 100_000, 11, 0.6);
    let sorted = sort_rays_spatially(&rays);
    let identity: Vec<u32> = (0..rays.len() as u32).collect();
    for backend in Backend::compiled() {
        let start = std::time::Instant::now();
        let tracer = Tracer::new(backend, &scene, GeometryMode::Occlusion).unwrap();
        let build = start.elapsed();
        let (occ, occ_rate) = common::timed_occluded(&tracer, &rays, &sorted);
        let (_, unsorted_rate) = common::timed_occluded(&tracer, &rays, &identity);
        let (hits, hit_rate) = common::timed_intersect(&tracer, &rays, &sorted);
        println!(
            "{backend}: build {build:.2?}; occluded {occ_rate:.2} Mrays/s sorted, \
             {unsorted_rate:.2} unsorted; intersect {hit_rate:.2} Mrays/s sorted (1 thread)"
        );
        let hit_count = hits.iter().filter(|h| h.is_some()).count();
        assert!(hit_count > rays.len() / 10 && hit_count < rays.len() * 9 / 10);
        let consistent = occ
            .iter()
            .zip(&hits)
            .filter(|(o, h)| **o == h.is_some())
            .count();
        assert!(
            consistent as f64 >= 0.999 * rays.len() as f64,
            "{backend}: {consistent}"
        );
        let mut on_triangle = 0;
        for (ray, hit) in rays.iter().zip(&hits) {
            let Some(hit) = hit else { continue };
            assert!(hit.t > 0.0 && hit.t < ray.tmax);
            let expected = ray.origin + ray.dir * hit.t;
            let p = common::hit_point(&scene, hit);
            if (p - expected).length() <= 1e-3 * (1.0 + expected.abs().max_element()) {
                on_triangle += 1;
            }
        }
        assert!(
            on_triangle as f64 >= 0.999 * hit_count as f64,
            "{backend}: {on_triangle}/{hit_count}"
        );
    }
}
