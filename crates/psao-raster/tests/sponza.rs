//! Real-scene check: rasterized primary visibility in the Dabrovic Sponza atrium agrees with
//! ray casting through pixel centres; plus a printed 1280×720 timing.

mod common;

use std::sync::{Mutex, MutexGuard, OnceLock};
use std::time::Instant;

use common::{data_dir, load_obj, pixel_ray, scene_of, Bvh};
use glam::Vec3;
use psao_raster::{rasterize, GBuffer, RasterOptions, Rasterizer};
use psao_scene::{Camera, Scene};

/// The Sponza scene and its triangle list.
type Sponza = (Scene, Vec<[Vec3; 3]>);

/// The scene (loaded once) and a lock that keeps the tests from running concurrently, so that
/// the printed timing is not disturbed by the other test.
fn sponza() -> Option<(MutexGuard<'static, ()>, &'static Sponza)> {
    static SERIAL: Mutex<()> = Mutex::new(());
    static SCENE: OnceLock<Option<Sponza>> = OnceLock::new();
    let guard = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let loaded = SCENE.get_or_init(|| {
        let path = data_dir()?.join("scenes/dabrovic_sponza.obj");
        let tris = load_obj(path.to_str()?)?;
        Some((scene_of(&tris), tris))
    });
    Some((guard, loaded.as_ref()?))
}

fn cameras() -> [Camera; 3] {
    [
        // Down the nave from one end.
        Camera::look_at(Vec3::new(-13.0, 2.0, 0.5), Vec3::new(10.0, 4.0, -0.5), 60.0),
        // Across the atrium towards the arcades, looking slightly up.
        Camera::look_at(Vec3::new(3.0, 1.5, -4.5), Vec3::new(-2.0, 6.0, 6.0), 75.0),
        // From the upper gallery down onto the floor and columns.
        Camera::look_at(Vec3::new(8.0, 7.5, 5.0), Vec3::new(-4.0, 0.0, -2.0), 55.0),
    ]
}

#[test]
fn sponza_visibility_matches_ray_casting() {
    let Some((_serial, (scene, tris))) = sponza() else {
        return;
    };
    assert_eq!(tris.len(), 66_447);
    let bvh = Bvh::new(tris.clone());
    let (w, h) = (320, 180);
    for cam in cameras() {
        let g = rasterize(scene, &cam, &RasterOptions::new(w, h));
        let o = cam.position.as_dvec3();
        let (mut agree, mut ties, mut hits) = (0usize, 0usize, 0usize);
        for y in 0..h {
            for x in 0..w {
                let i = g.index(x, y);
                let r = bvh.two_nearest(o, pixel_ray(&cam, x, y, w, h), cam.near as f64);
                let ray_tri = r.first.map_or(GBuffer::NONE, |f| f.1);
                hits += usize::from(r.first.is_some());
                let tie = match (r.first, r.second) {
                    (Some(a), Some(b)) => b.0 - a.0 <= 1e-4 * a.0,
                    _ => false,
                };
                if ray_tri == g.triangle[i] {
                    agree += 1;
                    if let Some((t, _)) = r.first {
                        assert!(
                            (g.depth[i] as f64 - t).abs() <= 1e-3 * t,
                            "depth {} vs {t}",
                            g.depth[i]
                        );
                    }
                } else if tie {
                    ties += 1;
                }
            }
        }
        let n = (w * h) as usize;
        let rate = (agree + ties) as f64 / n as f64;
        println!(
            "camera at {}: {hits} ray hits, {agree} agree, {ties} ties, {} differ ({:.3}%)",
            cam.position,
            n - agree - ties,
            100.0 * rate
        );
        assert!(hits > n / 2, "camera should see mostly geometry: {hits}");
        assert!(rate >= 0.995, "agreement {rate}");
    }
}

#[test]
fn sponza_1280x720_timing() {
    let Some((_serial, (scene, _))) = sponza() else {
        return;
    };
    let opts = RasterOptions::new(1280, 720);
    let mut rasterizer = Rasterizer::new();
    let mut g = GBuffer::empty(0, 0);
    for cam in cameras() {
        let start = Instant::now();
        let fresh = rasterize(scene, &cam, &opts);
        let one_shot = start.elapsed().as_secs_f64() * 1e3;
        let runs = 5;
        let start = Instant::now();
        for _ in 0..runs {
            rasterizer.rasterize(scene, &cam, &opts, &mut g);
        }
        let ms = start.elapsed().as_secs_f64() * 1e3 / runs as f64;
        println!(
            "1280x720, {} triangles, {} threads: {ms:.1} ms per G-buffer reusing buffers, \
             {one_shot:.1} ms one-shot ({} pixels covered)",
            scene.instanced_triangle_count(),
            rayon::current_num_threads(),
            g.covered_count()
        );
        assert!(g == fresh, "reused buffers give the same G-buffer");
        assert!(g.covered_count() > g.len() / 2);
    }
}
