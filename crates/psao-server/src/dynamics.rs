//! Animation on the server (DESIGN §3 "Server update" and "CPU server"): the scene is posed at
//! the server's scene time, the tracer follows (top level for rigid motion, refit/rebuild for
//! skinned meshes), skinned points follow their triangles through the hash grid, and
//! **proximity invalidation** re-traces exactly the points whose surroundings moved.
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
//! Boxes are grown by `R + tolerance` to cover that drift. Deformation always counts.
//! Candidates are found per cell (the boxes in the instance's grid coordinates), then tested
//! point by point; static converged points are never touched.
//!
//! # What an invalidated point forgets
//!
//! An invalidated point keeps the fraction `tolerance / (tolerance + δ)` of its samples,
//! where δ is how far the geometry near it moved since they were traced (the two instances'
//! displacements since their reference poses; a skinned instance's largest vertex
//! displacement). Under the same first-order model, a sample that saw an occluder δ away from
//! where it is now is off by about δ/R, so forgetting at this rate keeps the running
//! estimate's bias under steady motion near the publishing threshold, while a jump far
//! beyond the tolerance (an object lifted away) restarts the point, and its contact shadow
//! follows within one server frame. Points near moving geometry therefore average over the
//! last few server frames instead of starting from nothing each time, and since points the
//! tracer skipped keep losing samples, they move up the tracer's priority (fewest samples
//! first): under a tight ray budget every invalidated point is re-traced in turn, none is
//! starved by the fixed tie-break.

use glam::{Affine3A, UVec3, Vec3};
use psao_points::vec_bytes;
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
    /// World positions of the mesh's vertices at the instance's reference pose.
    reference: Vec<Vec3>,
}

/// The server's animation state.
pub(crate) struct Dynamics {
    animator: Animator,
    pose: ScenePose,
    /// Scene time of `pose` (`None` before the first pose).
    time: Option<f32>,
    /// Per instance: world bounds of its geometry in the current pose.
    bounds: Vec<Option<(Vec3, Vec3)>>,
    /// Per instance: mesh-space bounds of its geometry in the current pose.
    mesh_bounds: Vec<Option<(Vec3, Vec3)>>,
    /// Per instance: transform and world bounds when it last invalidated points (its
    /// surroundings' AO was last made consistent with this pose).
    reference: Vec<(Affine3A, Option<(Vec3, Vec3)>)>,
    /// Per instance: mesh-space bounds at its reference pose.
    reference_mesh_bounds: Vec<Option<(Vec3, Vec3)>>,
    /// Per instance: its binding when it is skinned.
    skins: Vec<Option<SkinBinding>>,
    invalidation: Invalidation,
}

impl Dynamics {
    /// Heap bytes of the skin bindings (per skinned point: its triangle and barycentrics;
    /// per vertex: its reference position). The animator's pose is not counted.
    pub fn heap_bytes(&self) -> u64 {
        self.skins
            .iter()
            .flatten()
            .map(|s| {
                vec_bytes(&s.indices)
                    + vec_bytes(&s.triangle)
                    + vec_bytes(&s.bary)
                    + vec_bytes(&s.back_face)
                    + vec_bytes(&s.reference)
            })
            .sum()
    }

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
        let mesh_bounds: Vec<_> = (0..scene.instances.len())
            .map(|i| animator.mesh_bounds(&rest, i))
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
                    reference: scene.meshes[inst.mesh]
                        .positions
                        .iter()
                        .map(|&v| inst.transform.transform_point3(v))
                        .collect(),
                })
            })
            .collect();
        Ok(Self {
            animator,
            pose: rest,
            time: None,
            bounds,
            reference_mesh_bounds: mesh_bounds.clone(),
            mesh_bounds,
            reference,
            skins,
            invalidation,
        })
    }

    /// How each instance moves.
    pub fn motion(&self) -> &[Motion] {
        self.animator.motion()
    }

    /// The current pose (the stored one before the first).
    pub fn pose(&self) -> &ScenePose {
        &self.pose
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
            self.mesh_bounds[i] = self.animator.mesh_bounds(&self.pose, i);
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
                if let Some(light) = &mut inst.points.light {
                    light.clear();
                }
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
        // How far each instance's geometry moved since its reference pose, and whether that
        // matters (an event).
        let shift: Vec<f32> = (0..n)
            .map(|i| match (&self.skins[i], &self.pose.skinned[i]) {
                _ if first => f32::INFINITY,
                (Some(skin), Some(geo)) if deformed[i] => {
                    skin_displacement(skin, geo, &instances[i].transform)
                }
                _ if moved[i] => displacement(&self.reference[i], &instances[i].transform),
                _ => 0.0,
            })
            .collect();
        let event: Vec<bool> = (0..n)
            .map(|i| first || deformed[i] || (moved[i] && shift[i] > tolerance))
            .collect();
        let prev_transforms: Vec<Affine3A> = self.reference.iter().map(|r| r.0).collect();
        let prev_bounds: Vec<Option<(Vec3, Vec3)>> = self.reference.iter().map(|r| r.1).collect();
        let moves = Moves {
            prev_transforms: &prev_transforms,
            prev_bounds: &prev_bounds,
            bounds: &self.bounds,
            prev_mesh_bounds: &self.reference_mesh_bounds,
            mesh_bounds: &self.mesh_bounds,
            moved: &event,
            deformed: &deformed,
            shift: &shift,
            // Instances without an event may have drifted by up to `tolerance`.
            radius: radius + tolerance,
        };
        let now: &[InstanceState] = instances;
        let invalid: Vec<Vec<(u32, f32)>> = (0..now.len())
            .into_par_iter()
            .map(|j| moves.invalidated(j, now))
            .collect();
        for (inst, points) in instances.iter_mut().zip(&invalid) {
            for &(i, motion) in points {
                let i = i as usize;
                let count = inst.points.samples(i);
                let kept = (count as f32 * kept_fraction(motion, tolerance)) as u32;
                // Irradiance follows the same rule as AO (docs/LIGHTING.md).
                if let Some(light) = &mut inst.points.light {
                    light.keep_as_ao(i, kept);
                }
                inst.points.sum[i] = if count == 0 {
                    0.0
                } else {
                    inst.points.sum[i] * kept as f32 / count as f32
                };
                inst.points.set_samples(i, kept);
            }
            stats.invalidated_points += points.len();
        }
        for (i, e) in event.iter().enumerate() {
            if *e {
                self.reference[i] = (instances[i].transform, self.bounds[i]);
                self.reference_mesh_bounds[i] = self.mesh_bounds[i];
                if let (Some(skin), Some(geo)) = (&mut self.skins[i], &self.pose.skinned[i]) {
                    let t = instances[i].transform;
                    skin.reference.clear();
                    skin.reference
                        .extend(geo.positions.iter().map(|&v| t.transform_point3(v)));
                }
            }
        }
        let restarted = Restarted {
            all: false,
            lists: invalid
                .into_iter()
                .map(|l| l.into_iter().map(|(i, _)| i).collect())
                .collect(),
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
        let slot = inst.slot_of(i);
        inst.points.position[i] = position;
        inst.points.normal[i] = normal;
        let coord = layout.cell_coord(position);
        if let Some(s) = slot {
            if coord.is_some() && coord == inst.slot_coord(s) {
                continue;
            }
            changed += 1;
        }
        inst.rehome(i, slot, position);
    }
    changed
}

/// The motion of one server frame, for the invalidation tests.
struct Moves<'a> {
    prev_transforms: &'a [Affine3A],
    prev_bounds: &'a [Option<(Vec3, Vec3)>],
    bounds: &'a [Option<(Vec3, Vec3)>],
    prev_mesh_bounds: &'a [Option<(Vec3, Vec3)>],
    mesh_bounds: &'a [Option<(Vec3, Vec3)>],
    moved: &'a [bool],
    deformed: &'a [bool],
    /// Per instance: how far its geometry moved since its reference pose.
    shift: &'a [f32],
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

    /// The points of instance `j` of `now` whose surroundings moved, each with how far the
    /// nearby geometry moved relative to it (sorted by point, unique).
    fn invalidated(&self, j: usize, now: &[InstanceState]) -> Vec<(u32, f32)> {
        let inst = &now[j];
        // Local-space boxes (grown by R) of the geometry that moved relative to j, in the
        // previous pose (under j's previous transform) and the current one, each with the
        // motion between the two.
        let prev_to_local = inverse(&self.prev_transforms[j]);
        let to_local = inverse(&inst.transform);
        let sources: Box<dyn Iterator<Item = usize>> = if self.moved[j] {
            Box::new(0..now.len())
        } else {
            Box::new((0..now.len()).filter(|&k| self.moved[k]))
        };
        let mut boxes = Vec::new();
        for k in sources.filter(|&k| k != j && self.moved_relative(j, k, now)) {
            let motion = self.shift[j] + self.shift[k];
            let poses = [
                (
                    self.prev_bounds[k],
                    self.prev_mesh_bounds[k],
                    &prev_to_local,
                    &self.prev_transforms[k],
                    &self.prev_transforms[j],
                ),
                (
                    self.bounds[k],
                    self.mesh_bounds[k],
                    &to_local,
                    &now[k].transform,
                    &inst.transform,
                ),
            ];
            for (world, mesh, into_j, t_k, t_j) in poses {
                if let Some(b) = world {
                    boxes.push(Near {
                        cells: map_box(b, self.radius, into_j),
                        exact: mesh.map(|m| ExactBox::new(m, self.radius, t_k, t_j)),
                        motion,
                    });
                }
            }
        }
        let layout = inst.layout();
        let grid_hi = layout.origin + layout.dims.as_vec3() * layout.cell_size;
        boxes.retain(|b| b.cells.0.cmple(grid_hi).all() && b.cells.1.cmpge(layout.origin).all());
        // The largest motion among the geometry within reach of `p`.
        let motion_at = |p: Vec3| {
            boxes
                .iter()
                .filter(|b| b.reaches(p))
                .map(|b| b.motion)
                .reduce(f32::max)
        };
        if self.deformed[j] {
            // Every point moved with the mesh.
            let own = self.shift[j];
            return (0..inst.points.position.len())
                .map(|i| {
                    let near = motion_at(inst.points.position[i]).unwrap_or(0.0);
                    (i as u32, own.max(near))
                })
                .collect();
        }
        if boxes.is_empty() {
            return Vec::new();
        }
        // The slots of the cells any box overlaps, each once (enumerated by cell range, or by
        // slot when some box spans more cells than there are slots).
        let slots = inst.alloc.slot_count();
        let ranges: Vec<(UVec3, UVec3)> = boxes
            .iter()
            .map(|b| cell_range(layout, b.cells.0, b.cells.1))
            .collect();
        let span = |(c0, c1): &(UVec3, UVec3)| {
            let d = (*c1 - *c0 + UVec3::ONE).as_u64vec3();
            d.x * d.y * d.z
        };
        let hit: Vec<u32> = if ranges.iter().any(|r| span(r) > slots as u64) {
            (0..slots as u32)
                .filter(|&s| {
                    inst.slot_coord(s).is_some_and(|c| {
                        ranges
                            .iter()
                            .any(|(c0, c1)| c.cmpge(*c0).all() && c.cmple(*c1).all())
                    })
                })
                .collect()
        } else {
            let mut hit = Vec::new();
            for (c0, c1) in &ranges {
                for z in c0.z..=c1.z {
                    for y in c0.y..=c1.y {
                        for x in c0.x..=c1.x {
                            hit.extend(inst.alloc.find_cell(UVec3::new(x, y, z)));
                        }
                    }
                }
            }
            hit.sort_unstable();
            hit.dedup();
            hit
        };
        let mut out = Vec::new();
        for s in hit {
            push_members(inst, s, &motion_at, &mut out);
        }
        // A point is a member of one slot: no duplicates.
        out.sort_unstable_by_key(|&(i, _)| i);
        out
    }
}

/// Geometry of one instance in one pose, as seen from the instance whose points are tested.
struct Near {
    /// Local-space box (in the tested instance) of the geometry's bounds grown by the reach:
    /// a superset of the points within reach, for finding candidate cells.
    cells: (Vec3, Vec3),
    /// The exact test, when the geometry's transform allows it.
    exact: Option<ExactBox>,
    /// How far the geometry moved relative to the tested instance.
    motion: f32,
}

impl Near {
    /// Whether local point `p` (of the tested instance) may lie within reach of the geometry.
    fn reaches(&self, p: Vec3) -> bool {
        let (lo, hi) = self.cells;
        p.cmpge(lo).all() && p.cmple(hi).all() && self.exact.as_ref().is_none_or(|e| e.reaches(p))
    }
}

/// The geometry's mesh-space bounds with the map from the tested instance's local space into
/// that mesh space, for a Euclidean distance test: tighter than growing world-space boxes
/// by the reach along the axes, above all for rotated instances.
struct ExactBox {
    /// Tested instance's local space → the geometry's mesh space.
    to_mesh: Affine3A,
    lo: Vec3,
    hi: Vec3,
    /// The reach in mesh-space units: the world reach divided by the transform's smallest
    /// stretch, so at least the reach in any direction.
    reach: f32,
}

impl ExactBox {
    /// The test for mesh bounds `(lo, hi)` under world transform `t_k`, from points in the
    /// local space of the instance with world transform `t_j`, with world-space `reach`. The
    /// reach is converted with a lower bound of `t_k`'s smallest stretch, so the test never
    /// misses a point within reach.
    fn new((lo, hi): (Vec3, Vec3), reach: f32, t_k: &Affine3A, t_j: &Affine3A) -> Self {
        Self {
            to_mesh: inverse(t_k) * *t_j,
            lo,
            hi,
            reach: reach / min_stretch(t_k),
        }
    }

    fn reaches(&self, p: Vec3) -> bool {
        let q = self.to_mesh.transform_point3(p);
        let outside = (self.lo - q).max(q - self.hi).max(Vec3::ZERO);
        outside.length_squared() <= self.reach * self.reach
    }
}

/// A lower bound of the factor by which `t` shortens any vector: the shortest column when the
/// columns are orthogonal (rotation and scale), else `1 / ‖t⁻¹‖_F`. Zero for a singular
/// transform (which makes the reach infinite: the exact test then accepts everything).
fn min_stretch(t: &Affine3A) -> f32 {
    let m = t.matrix3;
    let (x, y, z) = (
        Vec3::from(m.x_axis),
        Vec3::from(m.y_axis),
        Vec3::from(m.z_axis),
    );
    let scale = x.length().max(y.length()).max(z.length());
    let tolerance = 1e-4 * scale * scale;
    let orthogonal =
        x.dot(y).abs() <= tolerance && y.dot(z).abs() <= tolerance && x.dot(z).abs() <= tolerance;
    let stretch = if orthogonal {
        x.length().min(y.length()).min(z.length())
    } else {
        let inv = m.inverse();
        let norm = (inv.x_axis.length_squared()
            + inv.y_axis.length_squared()
            + inv.z_axis.length_squared())
        .sqrt();
        1.0 / norm
    };
    if stretch.is_finite() {
        stretch
    } else {
        0.0
    }
}

/// Append the members of slot `s` that lie in some box (`motion_at` gives the motion there).
fn push_members(
    inst: &InstanceState,
    s: u32,
    motion_at: &impl Fn(Vec3) -> Option<f32>,
    out: &mut Vec<(u32, f32)>,
) {
    for &m in inst.alloc.members(s) {
        if m != NONE {
            if let Some(motion) = motion_at(inst.points.position[m as usize]) {
                out.push((m, motion));
            }
        }
    }
}

/// The fraction of its accumulated samples a point keeps when geometry within `R` of it
/// moved by `motion` since those samples were traced: `tolerance / (tolerance + motion)`.
/// Moving an occluder by δ biases an old sample by about δ/R (module docs); with samples
/// forgotten at this rate, the bias of the running estimate under steady motion stays near
/// `tolerance / R`, the publishing threshold. A jump far beyond the tolerance restarts the
/// point (contact shadows follow within one server frame); a zero tolerance always does.
fn kept_fraction(motion: f32, tolerance: f32) -> f32 {
    if motion <= 0.0 {
        1.0
    } else if motion.is_finite() {
        tolerance / (tolerance + motion)
    } else {
        0.0
    }
}

/// How far the vertices of a skinned instance moved since its reference pose (world space).
fn skin_displacement(skin: &SkinBinding, geo: &SkinnedGeometry, transform: &Affine3A) -> f32 {
    if skin.reference.len() != geo.positions.len() {
        return f32::INFINITY;
    }
    geo.positions
        .iter()
        .zip(&skin.reference)
        .map(|(&v, &r)| (transform.transform_point3(v) - r).length())
        .fold(0.0, f32::max)
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

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Mat3, Quat};

    /// The smallest singular value of `m`, by brute force over directions.
    fn brute_min_stretch(m: Mat3) -> f32 {
        let mut best = f32::INFINITY;
        for a in 0..90 {
            for b in 0..180 {
                let (t, p) = (
                    a as f32 * 2.0_f32.to_radians(),
                    b as f32 * 2.0_f32.to_radians(),
                );
                let d = Vec3::new(t.sin() * p.cos(), t.cos(), t.sin() * p.sin());
                best = best.min((m * d).length());
            }
        }
        best
    }

    #[test]
    fn min_stretch_is_a_lower_bound_and_exact_for_rotation_and_scale() {
        let rotated = Affine3A::from_scale_rotation_translation(
            Vec3::new(2.0, 3.0, 4.0),
            Quat::from_rotation_y(0.7),
            Vec3::ONE,
        );
        assert!((min_stretch(&rotated) - 2.0).abs() < 1e-5);
        let sheared = Affine3A::from_mat3(Mat3::from_cols(
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.9, 1.0, 0.0),
            Vec3::new(0.0, 0.3, 0.5),
        ));
        let bound = min_stretch(&sheared);
        assert!(bound > 0.0 && bound <= brute_min_stretch(sheared.matrix3.into()) + 1e-4);
        assert_eq!(
            min_stretch(&Affine3A::from_scale(Vec3::new(1.0, 0.0, 1.0))),
            0.0
        );
    }

    #[test]
    fn the_exact_box_test_is_tight_for_a_rotated_box_and_never_misses() {
        // A unit cube turned 45° about y, 2× scaled; points in the world frame (t_j = I).
        let t_k = Affine3A::from_scale_rotation_translation(
            Vec3::splat(2.0),
            Quat::from_rotation_y(std::f32::consts::FRAC_PI_4),
            Vec3::ZERO,
        );
        let reach = 0.5;
        let exact = ExactBox::new((Vec3::ZERO, Vec3::ONE), reach, &t_k, &Affine3A::IDENTITY);
        // World distance to the turned cube, by dense sampling of its surface.
        let distance = |p: Vec3| {
            let n = 24;
            let mut best = f32::INFINITY;
            for a in 0..=n {
                for b in 0..=n {
                    let (u, v) = (a as f32 / n as f32, b as f32 / n as f32);
                    for q in [
                        Vec3::new(0.0, u, v),
                        Vec3::new(1.0, u, v),
                        Vec3::new(u, 0.0, v),
                        Vec3::new(u, 1.0, v),
                        Vec3::new(u, v, 0.0),
                        Vec3::new(u, v, 1.0),
                    ] {
                        best = best.min((t_k.transform_point3(q) - p).length());
                    }
                }
            }
            best
        };
        let mut rng = 12345u64;
        let mut next = || {
            rng = rng
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (rng >> 40) as f32 / (1u64 << 24) as f32
        };
        let (mut inside_box, mut rejected) = (0, 0);
        for _ in 0..400 {
            let p = Vec3::new(next() * 5.0 - 2.5, next() * 3.0 - 0.5, next() * 5.0 - 2.5);
            let d = distance(p);
            if d <= reach * 0.98 {
                assert!(exact.reaches(p), "missed {p} at {d}");
            }
            if d > reach * 1.02 {
                // Outside the reach but maybe inside the grown world box.
                let (lo, hi) = transformed_box(&t_k, Vec3::ZERO, Vec3::ONE);
                let grown = p.cmpge(lo - reach).all() && p.cmple(hi + reach).all();
                inside_box += usize::from(grown);
                rejected += usize::from(grown && !exact.reaches(p));
            }
        }
        assert!(
            inside_box > 20 && rejected > inside_box / 2,
            "{rejected} of {inside_box}"
        );
    }
}
