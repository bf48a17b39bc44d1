//! Compositing: AO scales exactly the ambient term, the lit composite is the Lambertian
//! radiance of direct + reconstructed irradiance, the background is sky grey, and the sRGB
//! encoding matches the transfer function.

mod common;

use glam::Vec3;
use psao_client::{composite, composite_lit, composite_srgb8, encode_srgb, Shading, SKY_GREY};
use psao_raster::{rasterize, RasterOptions};

#[test]
fn ao_scales_exactly_the_ambient_term() {
    let scene = common::scene(2.0, 2);
    let g = rasterize(&scene, &common::camera(), &RasterOptions::new(120, 90));
    let shading = Shading::default();
    let n = g.len();
    let lit = composite(&scene, &g, &vec![1.0; n], &shading);
    let dark = composite(&scene, &g, &vec![0.0; n], &shading);
    let half = composite(&scene, &g, &vec![0.5; n], &shading);
    assert_eq!(lit.len(), n);
    let (mut covered, mut sunlit) = (0, 0);
    for i in 0..n {
        if !g.covered(i) {
            assert_eq!(lit[i], SKY_GREY);
            assert_eq!(dark[i], SKY_GREY);
            continue;
        }
        covered += 1;
        let m = g.material(&scene, i).unwrap();
        let base = scene.materials[m].base_color.truncate();
        let diff = Vec3::from(lit[i]) - Vec3::from(dark[i]);
        assert!(
            (diff - base * shading.ambient).abs().max_element() < 1e-6,
            "pixel {i}: {diff} vs {}",
            base * shading.ambient
        );
        let mid = (Vec3::from(lit[i]) + Vec3::from(dark[i])) * 0.5;
        assert!((Vec3::from(half[i]) - mid).abs().max_element() < 1e-6);
        let direct = Vec3::from(dark[i]);
        let expected =
            base * shading.light * g.normal[i].dot(shading.light_dir.normalize()).max(0.0);
        assert!((direct - expected).abs().max_element() < 1e-6, "pixel {i}");
        if direct.max_element() > 0.0 {
            sunlit += 1;
        }
    }
    assert!(covered > 1000 && sunlit > 1000, "{covered} {sunlit}");
    // Missing AO values count as 1; a missing G-buffer attribute as uncovered.
    assert_eq!(composite(&scene, &g, &[], &shading), lit);
    let mut short = g.clone();
    short.normal.truncate(10);
    let image = composite(&scene, &short, &vec![1.0; n], &shading);
    assert_eq!(image.len(), n);
    assert!(image[10..].iter().all(|&c| c == SKY_GREY));
}

#[test]
fn srgb_encoding() {
    assert_eq!(encode_srgb(0.0), 0);
    assert_eq!(encode_srgb(1.0), 255);
    assert_eq!(encode_srgb(2.0), 255);
    assert_eq!(encode_srgb(-1.0), 0);
    assert_eq!(encode_srgb(f32::NAN), 0);
    // 0.5 linear ≈ 0.7354 sRGB → 188; 0.002 is on the linear segment: 12.92 · 0.002 · 255.
    assert_eq!(encode_srgb(0.5), 188);
    assert_eq!(encode_srgb(0.002), 7);
    assert_eq!(encode_srgb(0.18), 118);
    let bytes = composite_srgb8(&[[0.0, 0.5, 1.0], [0.18, 0.0, 0.0]]);
    assert_eq!(bytes, vec![0, 188, 255, 118, 0, 0]);
    // Monotone.
    let codes: Vec<u8> = (0..=1000).map(|i| encode_srgb(i as f32 / 1000.0)).collect();
    assert!(codes.windows(2).all(|w| w[0] <= w[1]));
}

#[test]
fn lit_composite_is_the_radiance_of_direct_plus_irradiance() {
    let scene = common::scene(2.0, 2);
    let g = rasterize(&scene, &common::camera(), &RasterOptions::new(120, 90));
    let n = g.len();
    // Per-pixel fields that differ between pixels and channels.
    let e: Vec<Vec3> = (0..n)
        .map(|i| Vec3::new(0.5, 1.0, 2.0) * (1.0 + (i % 7) as f32))
        .collect();
    let d: Vec<Vec3> = (0..n)
        .map(|i| Vec3::new(3.0, 0.0, 1.0) * (i % 5) as f32)
        .collect();
    let zero = vec![Vec3::ZERO; n];
    let both = composite_lit(&scene, &g, &e, &d);
    let only_e = composite_lit(&scene, &g, &e, &zero);
    let only_d = composite_lit(&scene, &g, &zero, &d);
    let black = composite_lit(&scene, &g, &zero, &zero);
    assert_eq!(both.len(), n);
    let mut covered = 0;
    for i in 0..n {
        if !g.covered(i) {
            assert_eq!(both[i], SKY_GREY);
            continue;
        }
        covered += 1;
        let base = scene.materials[g.material(&scene, i).unwrap()]
            .base_color
            .truncate();
        let expected = base * (e[i] + d[i]) / std::f32::consts::PI;
        let got = Vec3::from(both[i]);
        assert!(
            (got - expected).abs().max_element() < 1e-5,
            "pixel {i}: {got} vs {expected}"
        );
        // Additive in the two terms; no light, no radiance (AO plays no part).
        let sum = Vec3::from(only_e[i]) + Vec3::from(only_d[i]);
        assert!((got - sum).abs().max_element() < 1e-5, "pixel {i}");
        assert_eq!(black[i], [0.0; 3]);
    }
    assert!(covered > 1000, "{covered}");
    // Missing values count as no light.
    assert_eq!(composite_lit(&scene, &g, &e, &[]), only_e);
    assert_eq!(composite_lit(&scene, &g, &[], &[]), black);
}
