//! `psao bench trace --dynamic`: the cost of keeping the ray-tracing structure in step with
//! an animated scene (top-level updates for moving instances, refits and rebuilds of skinned
//! meshes) and the AO ray throughput after refits versus after rebuilds.

use super::{time_case, BenchTraceArgs};
use crate::scene_source::SceneInput;
use anyhow::{bail, Context, Result};
use psao_raster::{rasterize_posed, InstancePose, RasterOptions};
use psao_scene::path::CameraPath;
use psao_scene::{Animator, Motion, ScenePose};
use psao_trace::{ao, Backend, GeometryMode, Ray, Tracer};
use serde::Serialize;
use std::time::Instant;

/// Server frame rate the animation is stepped at.
const SERVER_HZ: f32 = 15.0;

/// One backend's dynamic measurements.
#[derive(Serialize, Debug)]
struct DynamicCase {
    backend: &'static str,
    frames: usize,
    rigid_instances: usize,
    skinned_instances: usize,
    /// Animation sampling plus skinning, per frame.
    animate_ms: f64,
    /// Setting every moving instance's transform plus the top-level commit, per frame.
    top_level_ms: f64,
    /// Mean and worst refit time of one skinned mesh.
    refit_ms_mean: f64,
    refit_ms_max: f64,
    /// Mean rebuild time of one skinned mesh (at the last frame's pose).
    rebuild_ms_mean: f64,
    /// Largest SAH cost ratio (refit vs last build) seen over the frames and meshes.
    cost_ratio_max: Option<f32>,
    /// With the server's policy (refit, rebuild past `--max-cost-ratio`): rebuilds over all
    /// frames and meshes, and the mean update time of one skinned mesh.
    policy_rebuilds: usize,
    policy_update_ms_mean: f64,
    /// AO rays from the visible surfaces: Mrays/s after refits and after rebuilding.
    view_mrays_refit: f64,
    view_mrays_rebuilt: f64,
    /// AO rays from the skinned characters' surfaces: Mrays/s after refits / rebuilding.
    character_mrays_refit: f64,
    character_mrays_rebuilt: f64,
}

/// Runs the dynamic benchmark and prints its table (or JSON).
pub(super) fn run(args: &BenchTraceArgs, input: &SceneInput, path: &CameraPath) -> Result<()> {
    let scene = &input.scene;
    let animator = Animator::new(scene).context("the scene's animation cannot be played")?;
    let motion = animator.motion();
    let moving: Vec<usize> = (0..motion.len())
        .filter(|&i| motion[i] != Motion::Static)
        .collect();
    let skinned: Vec<usize> = (0..motion.len())
        .filter(|&i| motion[i] == Motion::Skinned)
        .collect();
    if moving.is_empty() {
        bail!("{} has no moving instances", input.name);
    }
    let mut meshes: Vec<usize> = skinned.iter().map(|&i| scene.instances[i].mesh).collect();
    meshes.sort_unstable();
    meshes.dedup();
    if meshes.len() != skinned.len() {
        bail!("skinned instances share meshes: the tracer holds one deformation per mesh");
    }
    let frames = args.frames.max(1);
    let mut cases = Vec::new();
    for backend in Backend::compiled() {
        let case = run_backend(args, input, path, &animator, backend, &moving, &skinned)?;
        tracing::info!("{case:?}");
        cases.push(case);
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&cases)?);
        return Ok(());
    }
    println!(
        "{}: {} rigid + {} skinned moving instances, {frames} frames at {SERVER_HZ} Hz, rebuild past cost ratio {}",
        input.name,
        cases[0].rigid_instances,
        cases[0].skinned_instances,
        args.max_cost_ratio
    );
    println!("| backend | animate ms/frame | top level ms/frame | refit ms/mesh (mean / max) | rebuild ms/mesh | max cost ratio | policy: rebuilds, ms/mesh | view Mrays/s refit / rebuilt | character Mrays/s refit / rebuilt |");
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    for c in &cases {
        let ratio = c
            .cost_ratio_max
            .map_or_else(|| "n/a".to_string(), |r| format!("{r:.3}"));
        println!(
            "| {} | {:.3} | {:.3} | {:.3} / {:.3} | {:.3} | {ratio} | {}, {:.3} | {:.2} / {:.2} | {:.2} / {:.2} |",
            c.backend,
            c.animate_ms,
            c.top_level_ms,
            c.refit_ms_mean,
            c.refit_ms_max,
            c.rebuild_ms_mean,
            c.policy_rebuilds,
            c.policy_update_ms_mean,
            c.view_mrays_refit,
            c.view_mrays_rebuilt,
            c.character_mrays_refit,
            c.character_mrays_rebuilt
        );
    }
    Ok(())
}

/// Animates `args.frames` server frames on one backend, refitting skinned meshes, then
/// measures throughput, rebuilds them and measures again.
fn run_backend(
    args: &BenchTraceArgs,
    input: &SceneInput,
    path: &CameraPath,
    animator: &Animator,
    backend: Backend,
    moving: &[usize],
    skinned: &[usize],
) -> Result<DynamicCase> {
    let scene = &input.scene;
    let frames = args.frames.max(1);
    let mut tracer = Tracer::new(backend, scene, GeometryMode::Occlusion)
        .with_context(|| format!("cannot build the {} backend", backend.name()))?;
    let mut pose = ScenePose::default();
    let (mut animate, mut top, mut refit_sum, mut refit_max) = (0.0, 0.0, 0.0, 0.0f64);
    let mut ratio_max: Option<f32> = None;
    for f in 0..frames {
        let start = Instant::now();
        animator.pose_into(f as f32 / SERVER_HZ, &mut pose);
        animate += seconds(start);
        for &i in skinned {
            let g = pose.skinned[i].as_ref().context("skinned pose missing")?;
            let start = Instant::now();
            tracer.update_mesh_positions(scene.instances[i].mesh, &g.positions)?;
            let s = seconds(start);
            refit_sum += s;
            refit_max = refit_max.max(s);
            if let Some(r) = tracer.mesh_cost_ratio(scene.instances[i].mesh) {
                ratio_max = Some(ratio_max.map_or(r, |m| m.max(r)));
            }
        }
        let start = Instant::now();
        for &i in moving {
            tracer.set_instance_transform(i, pose.transforms[i]);
        }
        tracer.commit();
        top += seconds(start);
    }
    let view = view_rays(input, path, &pose, args)?;
    let character = character_rays(scene, &pose, skinned, args.rays);
    let repeat = args.repeat.max(1);
    let throughput = |t: &Tracer, rays: &[Ray]| -> Result<f64> {
        if rays.is_empty() {
            return Ok(0.0);
        }
        Ok(rays.len() as f64 / time_case(t, rays, 2, "occluded", repeat)? / 1e6)
    };
    let view_refit = throughput(&tracer, &view)?;
    let character_refit = throughput(&tracer, &character)?;
    let mut rebuild_sum = 0.0;
    for &i in skinned {
        let g = pose.skinned[i].as_ref().context("skinned pose missing")?;
        let start = Instant::now();
        tracer.rebuild_mesh_positions(scene.instances[i].mesh, &g.positions)?;
        rebuild_sum += seconds(start);
    }
    tracer.commit();
    let per_mesh = |sum: f64, n: usize| 1e3 * sum / n.max(1) as f64;
    let (policy_rebuilds, policy_sum) = policy_pass(args, input, animator, backend, skinned)?;
    Ok(DynamicCase {
        backend: backend.name(),
        frames,
        rigid_instances: moving.len() - skinned.len(),
        skinned_instances: skinned.len(),
        animate_ms: 1e3 * animate / frames as f64,
        top_level_ms: 1e3 * top / frames as f64,
        refit_ms_mean: per_mesh(refit_sum, frames * skinned.len()),
        refit_ms_max: 1e3 * refit_max,
        rebuild_ms_mean: per_mesh(rebuild_sum, skinned.len()),
        cost_ratio_max: ratio_max,
        policy_rebuilds,
        policy_update_ms_mean: per_mesh(policy_sum, frames * skinned.len()),
        view_mrays_refit: view_refit,
        view_mrays_rebuilt: throughput(&tracer, &view)?,
        character_mrays_refit: character_refit,
        character_mrays_rebuilt: throughput(&tracer, &character)?,
    })
}

/// The frames again on a fresh structure with [`Tracer::update_deforming_mesh`]: (rebuilds,
/// total seconds spent updating skinned meshes).
fn policy_pass(
    args: &BenchTraceArgs,
    input: &SceneInput,
    animator: &Animator,
    backend: Backend,
    skinned: &[usize],
) -> Result<(usize, f64)> {
    let scene = &input.scene;
    let mut tracer = Tracer::new(backend, scene, GeometryMode::Occlusion)?;
    let mut pose = ScenePose::default();
    let (mut rebuilds, mut total) = (0, 0.0);
    for f in 0..args.frames.max(1) {
        animator.pose_into(f as f32 / SERVER_HZ, &mut pose);
        for &i in skinned {
            let g = pose.skinned[i].as_ref().context("skinned pose missing")?;
            let start = Instant::now();
            let update = tracer.update_deforming_mesh(
                scene.instances[i].mesh,
                &g.positions,
                args.max_cost_ratio,
            )?;
            total += seconds(start);
            rebuilds += usize::from(update.rebuilt);
        }
    }
    Ok((rebuilds, total))
}

fn seconds(start: Instant) -> f64 {
    start.elapsed().as_secs_f64()
}

/// About `args.rays` AO rays from the surfaces visible along the path, scene posed as in `pose`.
fn view_rays(
    input: &SceneInput,
    path: &CameraPath,
    pose: &ScenePose,
    args: &BenchTraceArgs,
) -> Result<Vec<Ray>> {
    let poses: Vec<InstancePose<'_>> = input
        .scene
        .instances
        .iter()
        .enumerate()
        .map(|(i, inst)| {
            pose.instance(i).map_or_else(
                || InstancePose::rest(inst),
                |p| InstancePose {
                    transform: p.transform,
                    positions: p.positions,
                    normals: p.normals,
                },
            )
        })
        .collect();
    let opts = RasterOptions::new(args.res.width, args.res.height);
    let frames = path.frame_count();
    let mut points = Vec::new();
    for k in 0..super::SEED_FRAMES {
        let camera = path.camera_at_frame(k * (frames - 1) / (super::SEED_FRAMES - 1).max(1));
        let g = rasterize_posed(&input.scene, &poses, &camera, &opts)?;
        points.extend(
            (0..g.depth.len())
                .filter(|&i| g.covered(i))
                .map(|i| (g.position[i], g.normal[i])),
        );
    }
    Ok(rays_from(&points, input.scene.ao_radius, args.rays))
}

/// About `count` AO rays from the skinned instances' vertices in `pose`.
fn character_rays(
    scene: &psao_scene::Scene,
    pose: &ScenePose,
    skinned: &[usize],
    count: usize,
) -> Vec<Ray> {
    let mut points = Vec::new();
    for &i in skinned {
        let Some(g) = &pose.skinned[i] else { continue };
        let t = pose.transforms[i];
        let normal_matrix = t.matrix3.inverse().transpose();
        points.extend(g.positions.iter().zip(&g.normals).map(|(p, n)| {
            (
                t.transform_point3(*p),
                (normal_matrix * glam::Vec3A::from(*n)).normalize().into(),
            )
        }));
    }
    rays_from(&points, scene.ao_radius, count)
}

/// Seeded AO rays, as evenly spread over `points` as `count` allows.
fn rays_from(points: &[(glam::Vec3, glam::Vec3)], radius: f32, count: usize) -> Vec<Ray> {
    if points.is_empty() {
        return Vec::new();
    }
    let spp = count.div_ceil(points.len()) as u32;
    let mut rays = Vec::with_capacity(points.len() * spp as usize);
    for (i, &(x, n)) in points.iter().enumerate() {
        ao::ao_rays(x, n, radius, spp, 11, i as u64, &mut rays);
    }
    rays.truncate(count);
    rays
}
