//! The fast render paths (per-node sampling, level-set bounds, shared sampler caches) give the
//! images of the straightforward algorithms they replaced, on every generated volume kind and
//! on small images (speed is measured by `psao volume bench`, not here).

use glam::Vec3;
use psao_volume::render::{self, DenseGrid};
use psao_volume::trace::{march, step_length, IndexRay};
use psao_volume::{
    BrickFormat, Camera, GridClass, Image, Procedural, RenderMode, RenderSettings, Sampler, Volume,
};

/// Fog as rendered before the fast paths: every sample through the tree-searching trilinear.
fn reference_fog(vol: &Volume, cam: &Camera, st: &RenderSettings) -> Image {
    let mut s = Sampler::new(vol, 0);
    let dt = step_length(vol);
    let pixels = (0..st.height)
        .flat_map(|y| (0..st.width).map(move |x| (x, y)))
        .map(|(x, y)| {
            let ray = IndexRay::from_world(vol, cam.eye, cam.ray_dir(x, y, st.width, st.height));
            let mut tau = 0.0;
            march(vol, 0, &ray, 0.0, f32::INFINITY, |seg| {
                if vol.majorant(seg.leaf) <= 0.0 {
                    return true;
                }
                let n = ((seg.t1 - seg.t0) / dt).ceil().max(1.0);
                let h = (seg.t1 - seg.t0) / n;
                let mut t = seg.t0 + 0.5 * h;
                for _ in 0..n as usize {
                    tau += s.trilinear(ray.at(t)).max(0.0) * h;
                    t += h;
                }
                true
            });
            1.0 - (-st.density_scale * tau).exp()
        })
        .collect();
    Image {
        width: st.width,
        height: st.height,
        pixels,
    }
}

/// The level-set hit as found before the bounds: steps of max(½ voxel, 0.8 v) from the start
/// of every node whose minimum is not positive.
fn reference_level_set(vol: &Volume, cam: &Camera, st: &RenderSettings) -> Vec<Option<f32>> {
    let mut s = Sampler::new(vol, 0);
    let dt = step_length(vol);
    (0..st.height)
        .flat_map(|y| (0..st.width).map(move |x| (x, y)))
        .map(|(x, y)| {
            let ray = IndexRay::from_world(vol, cam.eye, cam.ray_dir(x, y, st.width, st.height));
            let (mut hit, mut prev, mut last_end) = (None, None, f32::NEG_INFINITY);
            march(vol, 0, &ray, 0.0, f32::INFINITY, |seg| {
                if seg.t0 > last_end + 1e-3 {
                    prev = None;
                }
                last_end = seg.t1;
                if vol.minorant(seg.leaf) > 0.0 {
                    prev = Some((seg.t1, vol.minorant(seg.leaf)));
                    return true;
                }
                let mut t = seg.t0 + 0.5 * dt;
                while t < seg.t1 {
                    let v = s.trilinear(ray.at(t));
                    if let Some((tp, vp)) = prev {
                        if vp > 0.0 && v <= 0.0 {
                            hit = Some(tp + (t - tp) * vp / (vp - v));
                            return false;
                        }
                    }
                    prev = Some((t, v));
                    t += dt.max(0.8 * v);
                }
                true
            });
            hit
        })
        .collect()
}

fn cases() -> Vec<(Procedural, Volume, Volume)> {
    Procedural::ALL
        .into_iter()
        .map(|kind| {
            let g = kind.generate(48, 5).unwrap();
            let f32v = Volume::build(std::slice::from_ref(&g), BrickFormat::F32, None)
                .unwrap()
                .0;
            let bc7v = Volume::build(&[g], BrickFormat::Bc7, None).unwrap().0;
            (kind, f32v, bc7v)
        })
        .collect()
}

#[test]
fn fog_images_are_those_of_the_plain_sampler() {
    for (kind, f32v, bc7v) in cases() {
        let cam = Camera::framing(f32v.world_bounds(0), 40.0);
        let st = RenderSettings::new(&f32v, 40, 32, RenderMode::Fog);
        for vol in [&f32v, &bc7v] {
            let fast = render::render(vol, &cam, &st).unwrap();
            let plain = reference_fog(vol, &cam, &st);
            let d = fast.mean_abs_diff(&plain);
            assert!(d <= 1e-5, "{kind:?} {:?}: {d}", vol.pool.format);
            assert!(
                fast.pixels.iter().any(|&p| p > 0.01),
                "{kind:?}: empty image"
            );
        }
        // And the BC7 pool renders what the f32 pool does, up to its coding error.
        let a = render::render(&f32v, &cam, &st).unwrap();
        let b = render::render(&bc7v, &cam, &st).unwrap();
        assert!(
            a.mean_abs_diff(&b) <= 0.01,
            "{kind:?}: {}",
            a.mean_abs_diff(&b)
        );
    }
}

#[test]
fn level_set_images_match_the_plain_steps_and_the_dense_march() {
    for (kind, vol, _) in cases() {
        if vol.class != GridClass::LevelSet {
            continue;
        }
        // The framing view and one from inside the bounds' corner region.
        let (lo, hi) = vol.world_bounds(0);
        let framed = Camera::framing((lo, hi), 40.0);
        let close = Camera {
            eye: lo + (hi - lo) * Vec3::new(0.05, 0.9, 0.1),
            target: (lo + hi) * 0.5,
            ..framed
        };
        for cam in [framed, close] {
            let st = RenderSettings::new(&vol, 48, 40, RenderMode::LevelSet);
            let fast = render::render(&vol, &cam, &st).unwrap();
            let dense =
                render::render_dense_level_set(&vol, &DenseGrid::from_volume(&vol, 0), &cam, &st)
                    .unwrap();
            let plain = reference_level_set(&vol, &cam, &st);
            let hits = fast.pixels.iter().filter(|&&p| p > 0.0).count();
            assert!(hits > 100, "{kind:?}: {hits} hits");
            // Same pixels hit as the plain steps; shading (depth) within 0.002 on average.
            let plain_hits = plain.iter().filter(|h| h.is_some()).count();
            assert_eq!(hits, plain_hits, "{kind:?}");
            let d = fast.mean_abs_diff(&dense);
            assert!(d <= 0.002, "{kind:?}: vs dense {d}");
        }
    }
}

/// A BC7 volume of some hundred bricks (under the 1024 slots) fits one sampler's brick cache:
/// however often the rays cross it, each 4³ block is decoded once (bricks must not evict each
/// other, as they did in a direct-mapped cache: 5384 decodes of 651 cloud bricks).
#[test]
fn one_sampler_decodes_each_block_once_when_the_volume_fits() {
    for kind in [Procedural::Torus, Procedural::Cloud] {
        let g = kind.generate(96, 3).unwrap();
        let vol = Volume::build(&[g], BrickFormat::Bc7, None).unwrap().0;
        let bricks = vol.pool.len() as u64;
        assert!((300..=800).contains(&bricks), "{kind:?}: {bricks} bricks");
        let cam = Camera::framing(vol.world_bounds(0), 40.0);
        let mut s = Sampler::new(&vol, 0);
        for _ in 0..2 {
            for y in 0..48 {
                for x in 0..48 {
                    let ray = IndexRay::from_world(&vol, cam.eye, cam.ray_dir(x, y, 48, 48));
                    psao_volume::trace::optical_depth(&mut s, &ray, f32::INFINITY);
                }
            }
        }
        assert!(s.decodes > bricks, "{kind:?}: {} decodes", s.decodes);
        assert!(
            s.decodes <= 8 * bricks,
            "{kind:?}: {} decodes of {bricks} bricks",
            s.decodes
        );
    }
}

/// A BC7 volume larger than a sampler's cache (bricks are evicted and decoded again) still
/// renders the plain sampler's image, with the render's samplers and with one.
#[test]
fn fog_through_a_cache_overflowing_volume_is_that_of_the_plain_sampler() {
    let g = Procedural::Cloud.generate(128, 2).unwrap();
    let vol = Volume::build(&[g], BrickFormat::Bc7, None).unwrap().0;
    assert!(vol.pool.len() > 1024, "{} bricks", vol.pool.len());
    let cam = Camera::framing(vol.world_bounds(0), 40.0);
    let st = RenderSettings::new(&vol, 64, 48, RenderMode::Fog);
    let fast = render::render(&vol, &cam, &st).unwrap();
    let plain = reference_fog(&vol, &cam, &st);
    let d = fast.mean_abs_diff(&plain);
    assert!(d <= 1e-5, "{d}");
    let mut s = Sampler::new(&vol, 0);
    let mut max_diff = 0.0f32;
    for (k, p) in plain.pixels.iter().enumerate() {
        let (x, y) = (k as u32 % st.width, k as u32 / st.width);
        let ray = IndexRay::from_world(&vol, cam.eye, cam.ray_dir(x, y, st.width, st.height));
        let tau = psao_volume::trace::optical_depth(&mut s, &ray, f32::INFINITY);
        max_diff = max_diff.max((1.0 - (-st.density_scale * tau).exp() - p).abs());
    }
    assert!(max_diff <= 1e-5, "one sampler: {max_diff}");
}

/// The level-set bounds' split at the narrow band's clamp holds: wherever the trilinear field
/// of a node exceeds `linear_max`, its partial derivatives lie within the clamp cells' slope
/// bounds (checked by finite differences along each axis at points all over the nodes of the
/// generated box and torus, both of which have cells where the field turns from clamped to
/// linear).
#[test]
fn level_set_slopes_above_the_linear_part_stay_within_the_clamp_bounds() {
    use psao_volume::tree::Locate;
    for kind in [Procedural::Box, Procedural::Torus] {
        let g = kind.generate(48, 2).unwrap();
        let vol = Volume::build(&[g], BrickFormat::F32, None).unwrap().0;
        let mut s = Sampler::new(&vol, 0);
        let (lo, hi) = vol.index_bounds(0);
        let (mut checked, mut slower) = (0, 0);
        let h = 0.05;
        for z in lo.z * 4..hi.z * 4 - 1 {
            for y in lo.y * 4..hi.y * 4 - 1 {
                for x in lo.x * 4..hi.x * 4 - 1 {
                    let p = Vec3::new(x as f32, y as f32, z as f32) * 0.25 + 0.1;
                    let Locate::Leaf(i, origin) = vol.tree.locate(0, p.floor().as_ivec3()) else {
                        continue;
                    };
                    let lb = vol.level_set_bounds(i).unwrap();
                    let v = s.trilinear(p);
                    for axis in 0..3 {
                        let q = p + Vec3::AXES[axis] * h;
                        if q[axis] >= (origin[axis] + 8) as f32 {
                            continue;
                        }
                        let w = s.trilinear(q);
                        if v.min(w) <= lb.linear_max {
                            continue;
                        }
                        let d = (w - v) / h;
                        let tol = 1e-3 * vol.background;
                        assert!(
                            d >= lb.edge_slope_min[axis] - tol
                                && d <= lb.edge_slope_max[axis] + tol,
                            "{kind:?} at {p}: slope {d} outside {}..{}",
                            lb.edge_slope_min[axis],
                            lb.edge_slope_max[axis]
                        );
                        checked += 1;
                        slower += (lb.edge_slope_min[axis] > lb.slope_min[axis]) as u32;
                    }
                }
            }
        }
        // The split is used (points above the linear part exist) and tightens the bound.
        assert!(
            checked > 1000 && slower > 100,
            "{kind:?}: {checked} {slower}"
        );
    }
}
