//! Animation on the server (DESIGN §3 "Server update" and "CPU server"): the scene is posed at
//! the server's scene time, the tracer follows (top level for rigid motion, refit/rebuild for
//! skinned meshes), skinned points follow their triangles through the hash grid, and
//! **proximity invalidation** restarts the AO of exactly the points whose surroundings moved.
//!
//! # Which points are invalidated
//!
//! A point's AO depends only on the geometry within the AO radius `R` of it, *as seen from
//! the point's own instance* (points and their AO live in instance-local space). So a point of
//! instance `j` is invalidated when, for some instance `k`, all of these hold:
//! - `k` moved relative to `j` this server frame: `k` deformed (skinning), or the relative
//!   transform `T_j⁻¹·T_k` changed (so `j` moving over static `k` counts, and two parts moving
//!   together do not);
//! - the point lies within `R` of `k`'s world bounds in the previous pose (its accumulated AO
//!   saw `k` there) or in the current pose (its AO must now see `k` here), both boxes taken
//!   into `j`'s local space at the matching pose of `j`.
//!
//! Consequently a rigid object's own points keep their local-space AO under its own motion
//! only where nothing else is within `R` of them; its points near the floor it rolls over are
//! re-traced, its top is not. `k = j` matters only when `j` deforms, and a deforming
//! instance's points all moved, so they are all invalidated.
//!
//! Rigid motion counts once it is large enough to matter: an instance's "previous pose" is
//! its *reference* pose, the pose at which it last invalidated points, and it invalidates
//! again only when its bounds' corners moved more than a tolerance since then (the server
//! uses `R × ao threshold`: moving an occluder by δ changes a ray's `min(t, R)/R` by about
//! δ/R, so slower drifts stay below the publishing threshold of 8/255 until they add up).
//! Boxes are grown by `R + tolerance` to cover that drift. Deformation always counts. Candidates are found per cell
//! (the boxes in the instance's grid coordinates), then tested point by point. Invalidated
//! points restart their accumulation (0 samples), which also gives them the tracer's highest
//! priority (fewest samples first); static converged points are never touched.

use glam::{Affine3A, UVec3, Vec3};
use psao_points::InstancePoints;
use psao_scene::affine::{box_corners, invert_or_identity as inverse, transformed_box};
use psao_scene::{Animator, Motion, ScenePose, SkinnedGeometry};
use psao_trace::{Tracer, DEFAULT_MAX_COST_RATIO};
use rayon::prelude::*;

use crate::instance::{InstanceState, NONE};
use crate::ServerError;

/// How the server decides which points to re-trace after something moved.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Invalidation {
    /// Points near geometry that moved relative to them (module [`crate`] docs, DESIGN §3).
    #[default]
    Proximity,
    /// Every point restarts whenever anything moved: every visible point is re-traced each
    /// server frame (the published system's approach; for comparisons).
    Everything,
}

/// What posing the scene at a new time did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MotionStats {
    /// Instances whose transform changed or that deformed.
    pub moved_instances: usize,
    /// Points whose accumulated AO was restarted.
    pub invalidated_points: usize,
    /// Skinned points that changed cell.
    pub changed_cell: usize,
}

/// The points one [`Dynamics::advance`] restarted.
#[derive(Debug, Default)]
pub(crate) struct Restarted {
    /// Every point of every instance (no lists kept).
    pub all: bool,
    /// Otherwise per instance the restarted points, sorted (empty when nothing moved).
    pub lists: Vec<Vec<u32>>,
}

impl Restarted {
    /// Whether point `index` of `instance` was restarted.
    pub fn contains(&self, instance: u32, index: u32) -> bool {
        self.all
            || self
                .lists
                .get(instance as usize)
                .is_some_and(|l| l.binary_search(&index).is_ok())
    }
}

/// Everything one [`Dynamics::advance`] did.
#[derive(Debug, Default)]
pub(crate) struct Advanced {
    /// Counts.
    pub stats: MotionStats,
    /// (instance, point) pairs that moved with their triangles: candidates for publishing.
    pub moved: Vec<(u32, u32)>,
    /// The restarted points.
    pub restarted: Restarted,
}

/// How the points of one skinned instance sit on its mesh.
struct SkinBinding {
    mesh: usize,
    indices: Vec<[u32; 3]>,
    triangle: Vec<u32>,
    bary: Vec<Vec3>,
    back_face: Vec<bool>,
}

/// The server's animation state.
pub(crate) struct Dynamics {
    animator: Animator,
    pose: ScenePose,
    /// Scene time of `pose` (`None` before the first pose).
    time: Option<f32>,
    /// Per instance: world bounds of its geometry in the current pose.
    bounds: Vec<Option<(Vec3, Vec3)>>,
    /// Per instance: transform and world bounds when it last invalidated points (its
    /// surroundings' AO was last made consistent with this pose).
    reference: Vec<(Affine3A, Option<(Vec3, Vec3)>)>,
    /// Per instance: its binding when it is skinned.
    skins: Vec<Option<SkinBinding>>,
    invalidation: Invalidation,
}

impl Dynamics {
    /// The animation state of `scene` (points as generated, in the stored pose).
    pub fn new(
        scene: &psao_scene::Scene,
        points: &[InstancePoints],
        invalidation: Invalidation,
    ) -> Result<Self, ServerError> {
        let animator = Animator::new(scene)?;
        let rest = ScenePose {
            time: 0.0,
            nodes: Vec::new(),
            transforms: scene.instances.iter().map(|i| i.transform).collect(),
            skinned: vec![None; scene.instances.len()],
        };
        let bounds: Vec<_> = (0..scene.instances.len())
            .map(|i| animator.world_bounds(&rest, i))
            .collect();
        let reference = rest
            .transforms
            .iter()
            .copied()
            .zip(bounds.clone())
            .collect();
        let skins = animator
            .motion()
            .iter()
            .zip(&scene.instances)
            .zip(points)
            .map(|((m, inst), p)| {
                (*m == Motion::Skinned).then(|| SkinBinding {
                    mesh: inst.mesh,
                    indices: scene.meshes[inst.mesh].indices.clone(),
                    triangle: p.points.iter().map(|s| s.triangle).collect(),
                    bary: p.points.iter().map(|s| s.bary).collect(),
                    back_face: p.points.iter().map(|s| s.back_face).collect(),
                })
            })
            .collect();
        Ok(Self {
            animator,
            pose: rest,
            time: None,
            bounds,
            reference,
            skins,
            invalidation,
        })
    }

    /// How each instance moves.
    pub fn motion(&self) -> &[Motion] {
        self.animator.motion()
    }

    /// Scene time of the current pose (`None` before the first).
    pub fn time(&self) -> Option<f32> {
        self.time
    }

    /// Pose the scene at `time`: update the tracer and the instances' transforms, move skinned
    /// points (returning the points to consider for publishing), and invalidate the points
    /// whose surroundings moved. Rigid motion is accumulated per instance until it displaces
    /// the instance's bounds by more than `tolerance` since its last invalidation (see the
    /// module docs). Nothing happens for a static scene or an unchanged time.
    pub fn advance(
        &mut self,
        time: f32,
        tracer: &mut Tracer,
        instances: &mut [InstanceState],
        radius: f32,
        tolerance: f32,
    ) -> Result<Advanced, ServerError> {
        let mut stats = MotionStats::default();
        if !self.animator.is_dynamic() || self.time == Some(time) {
            return Ok(Advanced {
                stats,
                ..Advanced::default()
            });
        }
        let first = self.time.is_none();
        self.time = Some(time);
        self.animator.pose_into(time, &mut self.pose);
        let n = instances.len();
        let mut moved = vec![false; n];
        let mut deformed = vec![false; n];
        for (i, motion) in self.animator.motion().iter().enumerate() {
            if *motion == Motion::Static {
                continue;
            }
            let transform = self.pose.transforms[i];
            if transform != instances[i].transform || first {
                tracer.set_instance_transform(i, transform);
                instances[i].set_transform(transform);
                moved[i] = true;
            }
            if let (Some(skin), Some(geo)) = (&self.skins[i], &self.pose.skinned[i]) {
                tracer.update_deforming_mesh(skin.mesh, &geo.positions, DEFAULT_MAX_COST_RATIO)?;
                moved[i] = true;
                deformed[i] = true;
            }
            self.bounds[i] = self.animator.world_bounds(&self.pose, i);
        }
        stats.moved_instances = moved.iter().filter(|&&m| m).count();
        if stats.moved_instances == 0 {
            return Ok(Advanced {
                stats,
                ..Advanced::default()
            });
        }
        tracer.commit();

        let mut publish = Vec::new();
        for (i, inst) in instances.iter_mut().enumerate() {
            if let (true, Some(skin), Some(geo)) =
                (deformed[i], &self.skins[i], &self.pose.skinned[i])
            {
                stats.changed_cell += follow_triangles(inst, skin, geo);
                publish.extend((0..inst.points.position.len() as u32).map(|p| (i as u32, p)));
            }
            if deformed[i] {
                inst.refresh_cull_bounds();
            } else if moved[i] {
                inst.refresh_world_bounds();
            }
        }

        if self.invalidation == Invalidation::Everything {
            for inst in instances.iter_mut() {
                inst.points.sum.fill(0.0);
                inst.points.count.fill(0);
                stats.invalidated_points += inst.points.count.len();
            }
            let all = Restarted {
                all: true,
                lists: Vec::new(),
            };
            return Ok(Advanced {
                stats,
                moved: publish,
                restarted: all,
            });
        }
        // Instances whose motion since their reference pose matters.
        let event: Vec<bool> = (0..n)
            .map(|i| {
                first
                    || deformed[i]
                    || (moved[i]
                        && displacement(&self.reference[i], &instances[i].transform) > tolerance)
            })
            .collect();
        let prev_transforms: Vec<Affine3A> = self.reference.iter().map(|r| r.0).collect();
        let prev_bounds: Vec<Option<(Vec3, Vec3)>> = self.reference.iter().map(|r| r.1).collect();
        let moves = Moves {
            prev_transforms: &prev_transforms,
            prev_bounds: &prev_bounds,
            bounds: &self.bounds,
            moved: &event,
            deformed: &deformed,
            // Instances without an event may have drifted by up to `tolerance`.
            radius: radius + tolerance,
        };
        let now: &[InstanceState] = instances;
        let invalid: Vec<Vec<u32>> = (0..now.len())
            .into_par_iter()
            .map(|j| moves.invalidated(j, now))
            .collect();
        for (inst, points) in instances.iter_mut().zip(&invalid) {
            for &i in points {
                inst.points.sum[i as usize] = 0.0;
                inst.points.count[i as usize] = 0;
            }
            stats.invalidated_points += points.len();
        }
        for (i, e) in event.iter().enumerate() {
            if *e {
                self.reference[i] = (instances[i].transform, self.bounds[i]);
            }
        }
        let restarted = Restarted {
            all: false,
            lists: invalid,
        };
        Ok(Advanced {
            stats,
            moved: publish,
            restarted,
        })
    }
}

/// Move the points of a skinned instance onto the posed triangles (barycentric position,
/// interpolated normal, flipped on back faces) and re-home those that changed cell in the
/// allocation grid. Returns the number of points that changed cell.
fn follow_triangles(inst: &mut InstanceState, skin: &SkinBinding, geo: &SkinnedGeometry) -> usize {
    let layout = *inst.layout();
    let mut changed = 0;
    for i in 0..inst.points.position.len() {
        let Some(&[a, b, c]) = skin.indices.get(skin.triangle[i] as usize) else {
            continue;
        };
        let [a, b, c] = [a, b, c].map(|v| v as usize);
        let (Some(pa), Some(pb), Some(pc)) = (
            geo.positions.get(a),
            geo.positions.get(b),
            geo.positions.get(c),
        ) else {
            continue;
        };
        let w = skin.bary[i];
        let position = *pa * w.x + *pb * w.y + *pc * w.z;
        let normal = match (geo.normals.get(a), geo.normals.get(b), geo.normals.get(c)) {
            (Some(na), Some(nb), Some(nc)) => {
                (*na * w.x + *nb * w.y + *nc * w.z).normalize_or_zero()
            }
            _ => Vec3::ZERO,
        };
        let normal = if normal == Vec3::ZERO {
            inst.points.normal[i]
        } else if skin.back_face[i] {
            -normal
        } else {
            normal
        };
        inst.points.position[i] = position;
        inst.points.normal[i] = normal;
        let slot = inst.points.slot[i];
        let coord = layout.cell_coord(position);
        if slot != NONE && coord.is_some() && coord == inst.slot_coord(slot) {
            continue;
        }
        if slot != NONE {
            changed += 1;
        }
        inst.rehome(i, position, normal);
    }
    changed
}

/// The motion of one server frame, for the invalidation tests.
struct Moves<'a> {
    prev_transforms: &'a [Affine3A],
    prev_bounds: &'a [Option<(Vec3, Vec3)>],
    bounds: &'a [Option<(Vec3, Vec3)>],
    moved: &'a [bool],
    deformed: &'a [bool],
    radius: f32,
}

impl Moves<'_> {
    /// Whether instance `k` moved relative to instance `j` (current transforms from `now`).
    fn moved_relative(&self, j: usize, k: usize, now: &[InstanceState]) -> bool {
        if self.deformed[k] {
            return true;
        }
        if !(self.moved[j] || self.moved[k]) {
            return false;
        }
        let before = inverse(&self.prev_transforms[j]) * self.prev_transforms[k];
        let after = inverse(&now[j].transform) * now[k].transform;
        !before.abs_diff_eq(after, 1e-6)
    }

    /// The points of instance `j` of `now` to restart (sorted, unique).
    fn invalidated(&self, j: usize, now: &[InstanceState]) -> Vec<u32> {
        let inst = &now[j];
        if self.deformed[j] {
            return (0..inst.points.position.len() as u32).collect();
        }
        // Local-space boxes (grown by R) of the geometry that moved relative to j, in the
        // previous pose (under j's previous transform) and the current one.
        let prev_to_local = inverse(&self.prev_transforms[j]);
        let to_local = inverse(&inst.transform);
        let sources: Box<dyn Iterator<Item = usize>> = if self.moved[j] {
            Box::new(0..now.len())
        } else {
            Box::new((0..now.len()).filter(|&k| self.moved[k]))
        };
        let mut boxes = Vec::new();
        for k in sources.filter(|&k| k != j && self.moved_relative(j, k, now)) {
            if let Some(b) = self.prev_bounds[k] {
                boxes.push(map_box(b, self.radius, &prev_to_local));
            }
            if let Some(b) = self.bounds[k] {
                boxes.push(map_box(b, self.radius, &to_local));
            }
        }
        let layout = inst.layout();
        let grid_hi = layout.origin + layout.dims.as_vec3() * layout.cell_size;
        boxes.retain(|(lo, hi)| lo.cmple(grid_hi).all() && hi.cmpge(layout.origin).all());
        if boxes.is_empty() {
            return Vec::new();
        }
        let inside = |p: Vec3| {
            boxes
                .iter()
                .any(|(lo, hi)| p.cmpge(*lo).all() && p.cmple(*hi).all())
        };
        let mut out = Vec::new();
        let slots = inst.members.len();
        for &(lo, hi) in &boxes {
            let (c0, c1) = cell_range(layout, lo, hi);
            let span = (c1 - c0 + UVec3::ONE).as_u64vec3();
            if span.x * span.y * span.z <= slots as u64 {
                for z in c0.z..=c1.z {
                    for y in c0.y..=c1.y {
                        for x in c0.x..=c1.x {
                            if let Some(s) = inst.alloc.find_cell(UVec3::new(x, y, z)) {
                                push_members(inst, s, &inside, &mut out);
                            }
                        }
                    }
                }
            } else {
                for s in 0..slots as u32 {
                    let hit = inst
                        .slot_coord(s)
                        .is_some_and(|c| c.cmpge(c0).all() && c.cmple(c1).all());
                    if hit {
                        push_members(inst, s, &inside, &mut out);
                    }
                }
            }
        }
        out.sort_unstable();
        out.dedup();
        out
    }
}

/// Append the members of slot `s` whose position passes `inside`.
fn push_members(inst: &InstanceState, s: u32, inside: &impl Fn(Vec3) -> bool, out: &mut Vec<u32>) {
    for &m in &inst.members[s as usize] {
        if m != NONE && inside(inst.points.position[m as usize]) {
            out.push(m);
        }
    }
}

/// The cells (inclusive range, clamped to the grid) a local box overlaps.
fn cell_range(layout: &psao_points::GridLayout, lo: Vec3, hi: Vec3) -> (UVec3, UVec3) {
    let max = (layout.dims - UVec3::ONE).as_vec3();
    let c = |p: Vec3| {
        layout
            .grid_coords(p)
            .floor()
            .clamp(Vec3::ZERO, max)
            .as_uvec3()
    };
    (c(lo), c(hi))
}

/// How far the corners of an instance's bounds at its reference pose moved under the change
/// from the reference transform to `now`.
fn displacement(reference: &(Affine3A, Option<(Vec3, Vec3)>), now: &Affine3A) -> f32 {
    let Some((lo, hi)) = reference.1 else {
        return 0.0;
    };
    let delta = *now * inverse(&reference.0);
    box_corners(lo, hi)
        .iter()
        .map(|&p| (delta.transform_point3(p) - p).length())
        .fold(0.0, f32::max)
}

/// The axis-aligned box (in the target space) of box `(lo, hi)` grown by `r` and then mapped
/// by `t`.
fn map_box((lo, hi): (Vec3, Vec3), r: f32, t: &Affine3A) -> (Vec3, Vec3) {
    transformed_box(t, lo - Vec3::splat(r), hi + Vec3::splat(r))
}
