//! The [`Server`]: one authoritative point state, stepped once per server frame.

use std::sync::Arc;
use std::time::Instant;

use glam::{Affine3A, Vec3};
use psao_delta::{InstanceDelta, InstanceInfo, Update};
use psao_points::pack::unpack_ao;
use psao_points::MirrorGrid;
use psao_scene::{Motion, Scene};
use psao_trace::ao::Medium;
use psao_trace::{GeometryMode, Tracer};
use rayon::prelude::*;

use crate::changes::changed_after;
use crate::clients::Clients;
use crate::dynamics::{Dynamics, Restarted};
use crate::instance::InstanceState;
use crate::light::{charge, LightSums, Lighting};
use crate::publish::{apply, republish};
use crate::trace::{cull, select};
use crate::StartPoints;
use crate::{ClientId, Frustum, ServerConfig, ServerError, View};

mod scale;
pub use scale::{PointRecord, PointState};

/// What one [`Server::step`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepStats {
    /// Stored points inside the extended frustum of some view (converged ones included).
    pub visible_points: usize,
    /// Points that received new samples.
    pub traced_points: usize,
    /// Rays traced.
    pub rays: u64,
    /// Points whose published record changed.
    pub published_points: usize,
    /// Instances that moved or deformed since the previous step.
    pub moved_instances: usize,
    /// Points whose AO accumulation restarted because geometry near them moved.
    pub invalidated_points: usize,
    /// Traced points among this step's restarted ones, and the rays they got.
    pub retraced_points: usize,
    pub retrace_rays: u64,
    /// Light paths traced (with lighting), and the rays they took (closest-hit and shadow).
    pub light_paths: u64,
    pub light_rays: u64,
    /// Points whose irradiance restarted because a keyed sun turned past
    /// [`crate::SUN_TOLERANCE_DEG`].
    pub relit_points: usize,
    /// Milliseconds of the step spent posing the scene, updating the tracer, moving skinned
    /// points and invalidating (included in `ms`).
    pub animate_ms: f64,
    /// Milliseconds of the step spent culling to the frusta (included in `ms`).
    pub cull_ms: f64,
    /// Milliseconds spent selecting, tracing and accumulating (included in `ms`).
    pub trace_ms: f64,
    /// Milliseconds spent publishing, until [`Server::step_beside`]'s work beside it ended
    /// too (included in `ms`).
    pub publish_ms: f64,
    /// Wall time of the step in milliseconds.
    pub ms: f64,
}

/// The server's view of one point (for inspection, tests and evaluation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointInfo {
    /// Instance-local position.
    pub position: Vec3,
    /// Instance-local unit normal.
    pub normal: Vec3,
    /// Whether the point is stored in the grid (false: dropped by overflow).
    pub stored: bool,
    /// AO samples accumulated so far.
    pub samples: u32,
    /// Current AO estimate (mean of the samples), if any.
    pub ao: Option<f32>,
    /// The last published record, if the point was ever published.
    pub published: Option<u32>,
}

impl PointInfo {
    /// AO as last published (what clients see), if published.
    pub fn published_ao(&self) -> Option<f32> {
        self.published.map(unpack_ao)
    }
}

/// The PSAO server for one scene: generates the points, plays the scene's animation at the
/// server's scene time, accumulates ray-traced AO for what the clients see within a
/// per-frame ray budget, publishes changes past the thresholds into per-instance hash grids,
/// and hands each client what it has not seen yet.
pub struct Server {
    config: ServerConfig,
    radius: f32,
    tracer: Tracer,
    medium: Option<Arc<dyn Medium>>,
    instances: Vec<InstanceState>,
    dynamics: Dynamics,
    clients: Clients,
    frame: u64,
    /// Frames of change lists kept: a client further behind gets its delta by a scan.
    history_frames: u64,
    /// Where culling starts searching this frame's selection cut (see [`cull`]).
    cut_guess: u16,
    buried_points: usize,
    /// The partitions traced here, on a trace node (docs/SCALE-OUT.md).
    held: Option<scale::Held>,
    /// Diffuse irradiance at the points, when configured.
    lighting: Option<Lighting>,
}

/// Server frames whose changed buckets and cells are listed (2 s at 30 Hz): a client that
/// last received an update longer ago gets its delta by scanning every stamp instead.
const CHANGE_HISTORY_FRAMES: u64 = 64;

impl Server {
    /// Generate the points of every instance (in parallel; none on alpha-masked-out texels,
    /// see [`Scene::opaque_at`]), build the tracer (AO rays skip alpha-masked geometry), drop
    /// buried points when [`ServerConfig::cull_buried`] is set, and lay out the grids of the
    /// rest.
    pub fn new(scene: &Scene, config: ServerConfig) -> Result<Server, ServerError> {
        Server::with_medium(scene, config, None)
    }

    /// [`Server::new`] with AO rays passing through a participating `medium` (a volume in the
    /// scene): each sample's distance is weighted by the medium's transmittance
    /// ([`psao_trace::ao::sample_value`]).
    pub fn with_medium(
        scene: &Scene,
        config: ServerConfig,
        medium: Option<Arc<dyn Medium>>,
    ) -> Result<Server, ServerError> {
        let radius = Self::checked_radius(scene, &config)?;
        let tracer = Tracer::new(config.backend, scene, GeometryMode::Occlusion)?;
        let start = StartPoints::generate_with(scene, &config, &tracer)?;
        Self::assemble(scene, config, medium, tracer, radius, start)
    }

    /// [`Server::with_medium`] from points generated earlier for the same scene and settings
    /// ([`StartPoints::generate`], e.g. stored as bytes between runs): the same server,
    /// without generating and burial-testing the points again. Points made for another
    /// scene or settings ([`StartPoints::key`]) are refused.
    pub fn with_start_points(
        scene: &Scene,
        config: ServerConfig,
        medium: Option<Arc<dyn Medium>>,
        start: StartPoints,
    ) -> Result<Server, ServerError> {
        let radius = Self::checked_radius(scene, &config)?;
        let expected = StartPoints::key(scene, &config);
        if start.key != expected {
            return Err(ServerError::StartPoints(format!(
                "made for key {:016x}, not {expected:016x} (another scene or settings)",
                start.key
            )));
        }
        let tracer = Tracer::new(config.backend, scene, GeometryMode::Occlusion)?;
        Self::assemble(scene, config, medium, tracer, radius, start)
    }

    /// The AO radius of a server for `scene` with `config`, after checking both.
    pub(crate) fn checked_radius(scene: &Scene, config: &ServerConfig) -> Result<f32, ServerError> {
        config.validate()?;
        let radius = config.ao_radius.unwrap_or(scene.ao_radius);
        if !(radius.is_finite() && radius > 0.0) {
            return Err(ServerError::InvalidConfig(format!(
                "AO radius {radius} must be finite and > 0"
            )));
        }
        if u32::try_from(scene.instances.len()).is_err() {
            return Err(ServerError::TooManyInstances(scene.instances.len()));
        }
        Ok(radius)
    }

    /// The server over `start`'s points.
    fn assemble(
        scene: &Scene,
        config: ServerConfig,
        medium: Option<Arc<dyn Medium>>,
        tracer: Tracer,
        radius: f32,
        start: StartPoints,
    ) -> Result<Server, ServerError> {
        let (points, buried_points) = (start.instances, start.buried);
        let dynamics = Dynamics::new(scene, &points, config.invalidation)?;
        let lighting = config.lighting.map(|l| Lighting::new(scene, l));
        let motion = dynamics.motion();
        let mut instances = points
            .par_iter()
            .zip(&scene.instances)
            .zip(motion)
            .enumerate()
            .map(|(i, ((p, inst), m))| {
                let deforming = *m == Motion::Skinned;
                let (index, seed) = (i as u32, config.seed);
                InstanceState::new(
                    p,
                    inst.transform,
                    index,
                    seed,
                    deforming,
                    config.max_samples,
                )
            })
            .collect::<Result<Vec<InstanceState>, _>>()?;
        if let Some(l) = &config.lighting {
            for inst in &mut instances {
                let n = inst.points.position.len();
                inst.points.light = Some(LightSums::new(n, config.rays_per_point, l));
            }
        }
        let server = Server {
            config,
            radius,
            tracer,
            medium,
            instances,
            dynamics,
            clients: Clients::default(),
            frame: 0,
            history_frames: CHANGE_HISTORY_FRAMES,
            cut_guess: 0,
            buried_points,
            held: None,
            lighting,
        };
        let (overflow_cells, overflow_points) = server.overflow();
        tracing::info!(
            points = server.point_count(),
            buried = server.buried_points,
            overflow_cells,
            overflow_points,
            "server grids built"
        );
        Ok(server)
    }

    /// What a joining client needs: per instance its grid layout, Poisson radius and
    /// number of stored points.
    pub fn instance_table(&self) -> Vec<InstanceInfo> {
        self.instances
            .iter()
            .map(|inst| InstanceInfo {
                layout: *inst.layout(),
                poisson_radius: inst.poisson_radius,
                point_count: inst.alloc.point_count() as u32,
            })
            .collect()
    }

    /// Register a client; its first [`Server::update_for`] is a full snapshot.
    pub fn add_client(&mut self) -> ClientId {
        self.clients.add()
    }

    /// Forget a client (unknown ids are ignored).
    pub fn remove_client(&mut self, id: ClientId) {
        self.clients.remove(id);
    }

    /// Make the client's next update a full snapshot (e.g. after it reconnected or lost
    /// an update).
    pub fn resync(&mut self, id: ClientId) {
        if let Some(c) = self.clients.get_mut(id) {
            c.needs_snapshot = true;
        }
    }

    /// Number of registered clients.
    pub fn client_count(&self) -> usize {
        self.clients.len()
    }

    /// One server frame for the union of `views` at the current scene time (the time of the
    /// last [`Server::step_at`], 0 before the first; a static scene has no time): see
    /// [`Server::step_at`]. Only the very first pose of an animated scene can fail (non-finite
    /// skinned vertices); such a step does nothing and reports empty statistics.
    pub fn step(&mut self, views: &[View]) -> StepStats {
        let time = self.dynamics.time().unwrap_or(0.0);
        self.step_at(views, time).unwrap_or_default()
    }

    /// One server frame for the union of `views` at scene time `time` (seconds): pose the
    /// scene (tracer, instance transforms, skinned points; proximity invalidation, see
    /// [`crate::Invalidation`]), cull points to the extended frusta, spend the ray budget on
    /// the visible points with the fewest samples (invalidated points have none), accumulate,
    /// and publish what moved past the thresholds. With lighting, a keyed sun that turned
    /// relights first, and each selected point also takes its light paths (the budget
    /// charges both, see `light.rs`). Errors only when the tracer rejects a skinned pose
    /// (non-finite vertices).
    pub fn step_at(&mut self, views: &[View], time: f32) -> Result<StepStats, ServerError> {
        self.step_beside(views, time, || ()).0
    }

    /// [`Server::step_at`], running `beside` on the rayon pool at the same time as the
    /// publishing phase, whose work is partly serial, rather than beside the tracing, which
    /// keeps every core busy: how a caller overlaps the previous frame's encoding and sending
    /// with a step. `beside` runs whether or not the step succeeds.
    pub fn step_beside<R: Send>(
        &mut self,
        views: &[View],
        time: f32,
        beside: impl FnOnce() -> R + Send,
    ) -> (Result<StepStats, ServerError>, R) {
        let start = Instant::now();
        let crate::dynamics::Advanced {
            stats: motion,
            moved,
            restarted,
        } = match self.pose(time) {
            Ok(advanced) => advanced,
            Err(e) => return (Err(e), beside()),
        };
        let relit_points = self.relight(time);
        let animate_ms = start.elapsed().as_secs_f64() * 1e3;
        self.frame += 1;
        let c = &self.config;
        let lights = self
            .lighting
            .as_ref()
            .map(|l| (&l.config, l.lights().len()));
        let max_points =
            usize::try_from(c.ray_budget / charge(c.rays_per_point, lights)).unwrap_or(usize::MAX);
        let frusta: Vec<Frustum> = views
            .iter()
            .map(|v| Frustum::new(v, c.frustum_margin))
            .collect();
        let culled = cull(&self.instances, &frusta, max_points, self.cut_guess);
        self.cut_guess = culled.cut;
        let visible = culled.visible;
        let t_cull = Instant::now();
        let selected = select(culled.candidates, max_points);
        let scale::TracedFrame {
            traced,
            rays,
            light_paths,
            light_rays,
        } = self.trace_held(&selected);
        let (mut retraced_points, mut retrace_rays) = (0, 0u64);
        for t in &traced {
            if restarted.contains(t.instance, t.index) {
                retraced_points += 1;
                retrace_rays += u64::from(t.rays);
            }
            let p = &mut self.instances[t.instance as usize].points;
            let i = t.index as usize;
            p.sum[i] += t.sum;
            p.set_samples(i, p.samples(i) + t.rays);
            if let Some(light) = &mut p.light {
                light.sum[i] += t.light.sum;
                light.count[i] += t.light.paths;
            }
        }
        // `traced` is in (instance, index) order.
        let changed = runs_of(traced.iter().map(|t| (t.instance, t.index)));
        per_instance(&mut self.instances, changed, |inst, list| {
            inst.refresh_summaries(list)
        });
        let t_trace = Instant::now();
        // Traced points and points that moved with their triangles may need publishing.
        let mut candidates: Vec<(u32, u32)> =
            traced.iter().map(|t| (t.instance, t.index)).collect();
        if !moved.is_empty() {
            candidates.extend(moved);
            candidates.par_sort_unstable();
            candidates.dedup();
        }
        self.retain_held(&mut candidates);
        let (published, beside) = rayon::join(|| self.publish(&candidates), beside);
        let cull_ms = (t_cull - start).as_secs_f64() * 1e3 - animate_ms;
        let trace_ms = (t_trace - t_cull).as_secs_f64() * 1e3;
        let publish_ms = t_trace.elapsed().as_secs_f64() * 1e3;
        tracing::debug!(
            frame = self.frame,
            visible,
            traced = traced.len(),
            cull_ms,
            trace_ms,
            publish_ms,
            "step"
        );
        let stats = StepStats {
            visible_points: visible,
            traced_points: traced.len(),
            rays,
            published_points: published,
            moved_instances: motion.moved_instances,
            invalidated_points: motion.invalidated_points,
            retraced_points,
            retrace_rays,
            light_paths,
            light_rays,
            relit_points,
            animate_ms,
            cull_ms,
            trace_ms,
            publish_ms,
            ms: start.elapsed().as_secs_f64() * 1e3,
        };
        (Ok(stats), beside)
    }

    /// Pose the scene at `time` (tracer, instance transforms, skinned points, proximity
    /// invalidation) and bring the block summaries up to date: the start of every frame.
    fn pose(&mut self, time: f32) -> Result<crate::dynamics::Advanced, ServerError> {
        let advanced = self.dynamics.advance(
            time,
            &mut self.tracer,
            &mut self.instances,
            self.radius,
            self.radius * self.config.thresholds.ao,
        )?;
        self.refresh_summaries(&advanced.restarted, &advanced.moved);
        Ok(advanced)
    }

    /// Bring the lights to scene time `time` (a keyed sun that turned past the tolerance
    /// restarts the irradiance of the points it lights, see `light.rs`) and the block
    /// summaries of the restarted points up to date. Returns how many points restarted.
    fn relight(&mut self, time: f32) -> usize {
        let Some(restarted) =
            (self.lighting.as_mut()).and_then(|l| l.relight(time, &mut self.instances))
        else {
            return 0;
        };
        self.instances
            .par_iter_mut()
            .zip(restarted)
            .map(|(inst, list)| match list {
                None => {
                    inst.rebuild_summaries();
                    inst.points.position.len()
                }
                Some(list) => {
                    inst.refresh_summaries(&list);
                    list.len()
                }
            })
            .sum()
    }

    /// Bring the block summaries up to date after posing: the `restarted` points lost their
    /// samples and the `moved` ones may have changed storage.
    fn refresh_summaries(&mut self, restarted: &Restarted, moved: &[(u32, u32)]) {
        if restarted.all {
            self.instances
                .par_iter_mut()
                .for_each(InstanceState::rebuild_summaries);
        } else {
            self.instances
                .par_iter_mut()
                .zip(&restarted.lists)
                .for_each(|(inst, list)| inst.refresh_summaries(list));
        }
        // `moved` comes in runs of one instance.
        per_instance(
            &mut self.instances,
            runs_of(moved.iter().copied()),
            |inst, list| inst.refresh_summaries(list),
        );
    }

    /// Publish the candidate (instance, point) pairs that need it (see
    /// [`Server::publish_runs`]); returns how many points were published.
    fn publish(&mut self, candidates: &[(u32, u32)]) -> usize {
        let thresholds = self.config.thresholds;
        // `candidates` is sorted by (instance, index): split it per instance.
        let groups = runs_of(candidates.iter().copied());
        let order: Vec<u32> = groups.iter().map(|g| g.0).collect();
        let updates = per_instance(&mut self.instances, groups, |inst, list| {
            list.par_iter()
                .filter_map(|&i| republish(inst, i as usize, &thresholds).map(|b| (i, b)))
                .collect::<Vec<(u32, u32)>>()
        });
        self.publish_runs(order.into_iter().zip(updates).collect())
    }

    /// Store new published records into the grids, stamped with the current frame: `runs`
    /// holds (instance, (point, record) pairs), at most one run per instance. Then refresh
    /// the cells and buckets points moved out of and forget change history older than the
    /// kept frames. A trace node also keeps the records for [`Server::take_records`].
    /// Returns how many points were published. The one publishing path of a server step
    /// and of a replica's ([`Server::step_replica`]).
    fn publish_runs(&mut self, runs: Vec<(u32, Vec<(u32, u32)>)>) -> usize {
        let frame = self.frame;
        for (instance, updates) in &runs {
            self.record(*instance, updates);
        }
        let published = per_instance(&mut self.instances, runs, |inst, updates| {
            apply(inst, updates, frame)
        })
        .into_iter()
        .sum();
        for inst in &mut self.instances {
            if !inst.pending_cells.is_empty() {
                apply(inst, &[], frame);
            }
        }
        let forget = frame.saturating_sub(self.history_frames);
        for inst in &mut self.instances {
            inst.changes.forget_through(forget);
        }
        published
    }

    /// Everything the client has not received yet: the buckets and cells changed since its
    /// last update (or, for its first update or after [`Server::resync`], a snapshot of every
    /// non-empty bucket and cell), plus all instance transforms. An unknown id gets a
    /// snapshot without being registered.
    pub fn update_for(&mut self, id: ClientId) -> psao_delta::Update {
        let (snapshot, since) = self.take_pending(id);
        self.update_since(snapshot, since)
    }

    /// [`Server::update_for`] for several clients at once: clients due the same update (each
    /// a snapshot, or each last updated at the same frame) share one. Returns the groups, in
    /// the order of their first member in `ids`, members in the order of `ids`.
    pub fn updates_for(&mut self, ids: &[ClientId]) -> Vec<(Vec<ClientId>, psao_delta::Update)> {
        let mut groups: Vec<((bool, u64), Vec<ClientId>)> = Vec::new();
        for &id in ids {
            let key = self.pending(id);
            match groups.iter_mut().find(|g| g.0 == key) {
                Some(g) => g.1.push(id),
                None => groups.push((key, vec![id])),
            }
        }
        groups
            .into_iter()
            .map(|((snapshot, since), members)| {
                for &m in &members {
                    self.take_pending(m);
                }
                (members, self.update_since(snapshot, since))
            })
            .collect()
    }

    /// (snapshot, frame of the last update) the client is due; unknown ids get snapshots.
    fn pending(&self, id: ClientId) -> (bool, u64) {
        match self.clients.get(id) {
            Some(c) if !c.needs_snapshot => (false, c.last_sent),
            _ => (true, 0),
        }
    }

    /// [`Server::pending`], recording that the client is sent an update of this frame.
    fn take_pending(&mut self, id: ClientId) -> (bool, u64) {
        let due = self.pending(id);
        if let Some(c) = self.clients.get_mut(id) {
            c.needs_snapshot = false;
            c.last_sent = self.frame;
        }
        due
    }

    /// The update of a client last updated at frame `since` (or due a snapshot).
    fn update_since(&self, snapshot: bool, since: u64) -> psao_delta::Update {
        let instances = self
            .instances
            .par_iter()
            .enumerate()
            .filter(|(_, inst)| inst.max_stamp > if snapshot { 0 } else { since })
            .map(|(i, inst)| delta(i as u32, inst, snapshot, since))
            .filter(|d| !d.buckets.is_empty() || !d.cells.is_empty())
            .collect();
        Update {
            frame: self.frame,
            snapshot,
            transforms: self.transforms(),
            instances,
        }
    }

    /// (instance, local-to-world transform) of every instance.
    pub fn transforms(&self) -> Vec<(u32, Affine3A)> {
        self.instances
            .iter()
            .enumerate()
            .map(|(i, inst)| (i as u32, inst.transform))
            .collect()
    }

    /// Points stored in the grids (overflowed points excluded).
    pub fn point_count(&self) -> usize {
        self.instances.iter().map(|i| i.alloc.point_count()).sum()
    }

    /// Overflow summed over the instances: (cell allocations refused because a bucket was
    /// full, points dropped).
    pub fn overflow(&self) -> (u64, u64) {
        self.instances.iter().fold((0, 0), |(c, p), i| {
            (c + i.alloc.overflow_cells(), p + i.alloc.overflow_points())
        })
    }

    /// Generated points dropped by the burial test ([`ServerConfig::cull_buried`]).
    pub fn buried_points(&self) -> usize {
        self.buried_points
    }

    /// Heap bytes of the server's per-instance structures and skin bindings, by kind (the
    /// tracer's acceleration structures and the scene are not included).
    pub fn memory_use(&self) -> Vec<crate::MemoryPart> {
        crate::memory::memory_parts(&self.instances, self.dynamics.heap_bytes())
    }

    /// Server frames stepped so far (the frame number of the latest update).
    pub fn frame(&self) -> u64 {
        self.frame
    }

    /// The configuration.
    pub fn config(&self) -> &ServerConfig {
        &self.config
    }

    /// The AO ray length in use.
    pub fn ao_radius(&self) -> f32 {
        self.radius
    }

    /// Scene time of the current pose (`None` before the first [`Server::step_at`] of an
    /// animated scene, and always for a static one).
    pub fn scene_time(&self) -> Option<f32> {
        self.dynamics.time()
    }

    /// The tracer (AO geometry: alpha-masked meshes skipped).
    pub fn tracer(&self) -> &Tracer {
        &self.tracer
    }

    /// Point `index` of `instance`'s irradiance: its mean linear RGB irradiance (zero before
    /// the first path) and the number of light paths it averages. `None` without lighting
    /// ([`ServerConfig::lighting`]) or for a point that does not exist.
    pub fn irradiance(&self, instance: usize, index: usize) -> Option<(Vec3, u32)> {
        let light = self.instances.get(instance)?.points.light.as_ref()?;
        let (sum, count) = (*light.sum.get(index)?, light.count[index]);
        let mean = if count == 0 {
            Vec3::ZERO
        } else {
            sum / count as f32
        };
        Some((mean, count))
    }

    /// Point `index` of `instance`'s irradiance as last published (what clients have: the
    /// pooled irradiance of docs/LIGHTING.md, "Pooling", in its RGB9E5 record). `None`
    /// without lighting, for a point never published or one that does not exist.
    pub fn published_irradiance(&self, instance: usize, index: usize) -> Option<Vec3> {
        let inst = self.instances.get(instance)?;
        let record = *inst.points.light.as_ref()?.published.get(index)?;
        (inst.points.published[index] != 0).then(|| psao_points::irradiance::unpack_rgb9e5(record))
    }

    /// The lights the points' light paths are traced with (the scene's lights at the time of
    /// the last relighting; empty without lighting).
    pub fn lights(&self) -> &[psao_scene::Light] {
        self.lighting.as_ref().map_or(&[], |l| l.lights())
    }

    /// The participating medium AO rays pass through, if any.
    pub fn medium(&self) -> Option<&dyn Medium> {
        self.medium.as_deref()
    }

    /// Number of instances.
    pub fn instance_count(&self) -> usize {
        self.instances.len()
    }

    /// The published irradiance records of `instance`'s cell `slot`, aligned with the
    /// published cell's points (what clients mirror beside the grid; zeros without lighting,
    /// out of range, or where none were published).
    pub fn light_cell(&self, instance: usize, slot: u32) -> [u32; psao_points::CELL_POINTS] {
        self.instances
            .get(instance)
            .map_or_else(Default::default, |i| i.light_cell(slot))
    }

    /// The published (authoritative) grid of an instance: what clients mirror.
    pub fn grid(&self, instance: usize) -> Option<&MirrorGrid> {
        self.instances.get(instance).map(|i| &i.grid)
    }

    /// Every kept point of an instance (generated, not buried), in generation order (empty
    /// when out of range).
    pub fn points(&self, instance: usize) -> impl Iterator<Item = PointInfo> + '_ {
        let inst = self.instances.get(instance);
        let n = inst.map_or(0, |i| i.points.position.len());
        (0..n).filter_map(move |i| {
            let p = &inst?.points;
            Some(PointInfo {
                position: p.position[i],
                normal: p.normal[i],
                stored: p.stored.get(i),
                samples: p.samples(i),
                ao: (p.samples(i) > 0).then(|| p.sum[i] / p.samples(i) as f32),
                published: (p.published[i] != 0).then_some(p.published[i]),
            })
        })
    }
}

/// The point lists of each instance in (instance, point) pairs that come in runs of one
/// instance (each instance in one run).
fn runs_of(pairs: impl Iterator<Item = (u32, u32)>) -> Vec<(u32, Vec<u32>)> {
    let mut runs: Vec<(u32, Vec<u32>)> = Vec::new();
    for (instance, point) in pairs {
        match runs.last_mut() {
            Some(run) if run.0 == instance => run.1.push(point),
            _ => runs.push((instance, vec![point])),
        }
    }
    runs
}

/// `f` on each instance of `runs` (at most one run per instance) with its list, in
/// parallel over the instances; results in the order of `runs`.
fn per_instance<T: Send, R: Send>(
    instances: &mut [InstanceState],
    runs: Vec<(u32, Vec<T>)>,
    f: impl Fn(&mut InstanceState, &[T]) -> R + Sync,
) -> Vec<R> {
    debug_assert!(
        runs.windows(2).all(|w| w[0].0 != w[1].0),
        "one run per instance"
    );
    let mut free: Vec<Option<&mut InstanceState>> = instances.iter_mut().map(Some).collect();
    let jobs: Vec<(&mut InstanceState, Vec<T>)> = runs
        .into_iter()
        .filter_map(|(i, list)| Some((free.get_mut(i as usize)?.take()?, list)))
        .collect();
    jobs.into_par_iter()
        .map(|(inst, list)| f(inst, &list))
        .collect()
}

/// The changed (or, for a snapshot, non-empty) buckets and cells of one instance: from
/// the change log when it reaches back to `since`, else by scanning the stamps.
fn delta(index: u32, inst: &InstanceState, snapshot: bool, since: u64) -> InstanceDelta {
    match (snapshot, inst.changes.since(since)) {
        (false, Some(changed)) => {
            let grid = &inst.grid;
            let cells: Vec<(u32, psao_points::Cell)> =
                changed.cells.iter().map(|&s| (s, grid.cell(s))).collect();
            InstanceDelta {
                instance: index,
                buckets: changed
                    .buckets
                    .iter()
                    .map(|&b| (b, grid.bucket(b as usize)))
                    .collect(),
                lights: lights_of(inst, &cells),
                cells,
            }
        }
        _ => scan_delta(index, inst, snapshot, since),
    }
}

/// [`delta`] by scanning every bucket and cell of the instance.
fn scan_delta(index: u32, inst: &InstanceState, snapshot: bool, since: u64) -> InstanceDelta {
    let grid = &inst.grid;
    let buckets = grid
        .buckets()
        .enumerate()
        .filter(|&(b, bucket)| {
            if snapshot {
                !bucket.is_empty()
            } else {
                changed_after(inst.bucket_stamp[b], since)
            }
        })
        .map(|(b, bucket)| (b as u32, bucket))
        .collect();
    let cells: Vec<(u32, psao_points::Cell)> = grid
        .cells()
        .enumerate()
        .filter(|&(s, cell)| {
            if snapshot {
                cell.points[0] != 0
            } else {
                inst.cell_stamp
                    .get(s)
                    .is_some_and(|&t| changed_after(t, since))
            }
        })
        .map(|(s, cell)| (s as u32, cell))
        .collect();
    InstanceDelta {
        instance: index,
        buckets,
        lights: lights_of(inst, &cells),
        cells,
    }
}

/// The published irradiance records of `cells` (none without lighting).
fn lights_of(
    inst: &InstanceState,
    cells: &[(u32, psao_points::Cell)],
) -> Vec<[u32; psao_points::CELL_POINTS]> {
    if inst.points.light.is_none() {
        return Vec::new();
    }
    cells.iter().map(|&(s, _)| inst.light_cell(s)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::blocks::PointOrder;
    use crate::Invalidation;
    use psao_points::InstanceGrid;
    use psao_scene::{Camera, Instance, Material, Mesh};

    /// A 4 m floor and a 2 m wall standing on it.
    fn scene() -> Scene {
        let quad = |a: Vec3, b: Vec3, c: Vec3, d: Vec3| Mesh {
            positions: vec![a, b, c, d],
            indices: vec![[0, 2, 1], [0, 3, 2]],
            ..Default::default()
        };
        let floor = quad(
            Vec3::new(-2.0, 0.0, -2.0),
            Vec3::new(2.0, 0.0, -2.0),
            Vec3::new(2.0, 0.0, 2.0),
            Vec3::new(-2.0, 0.0, 2.0),
        );
        let wall = quad(
            Vec3::new(-1.0, 0.0, 0.0),
            Vec3::new(-1.0, 2.0, 0.0),
            Vec3::new(1.0, 2.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
        );
        let instance = |mesh: usize| Instance {
            mesh,
            node: None,
            transform: Affine3A::IDENTITY,
            skin: None,
        };
        Scene {
            meshes: vec![floor, wall],
            materials: vec![Material::default()],
            instances: vec![instance(0), instance(1)],
            ao_radius: 0.6,
            ..Default::default()
        }
    }

    /// A camera circling the scene, looking at a point that wanders over the floor.
    fn view(frame: u32) -> View {
        let a = frame as f32 * 0.4;
        let eye = Vec3::new(3.0 * a.cos(), 1.5, 3.0 * a.sin());
        let target = Vec3::new(0.8 * (a * 1.7).sin(), 0.3, 0.8 * (a * 1.3).cos());
        View {
            camera: Camera::look_at(eye, target, 50.0),
            aspect: 1.5,
        }
    }

    /// The published grids as a client mirrors them.
    fn apply(mirror: &mut [InstanceGrid], update: &Update) {
        for d in &update.instances {
            let grid = &mut mirror[d.instance as usize];
            for &(b, bucket) in &d.buckets {
                grid.set_bucket(b as usize, bucket).unwrap();
            }
            for &(s, cell) in &d.cells {
                grid.set_cell(s, cell).unwrap();
            }
        }
    }

    /// A few points with few samples each, so a handful of frames change the grids.
    fn small_config() -> ServerConfig {
        ServerConfig {
            density: 256.0,
            ray_budget: 2000,
            rays_per_point: 4,
            max_samples: 16,
            ..ServerConfig::default()
        }
    }

    #[test]
    fn points_are_numbered_in_the_order_culling_visits_them() {
        let server = Server::new(&scene(), small_config()).unwrap();
        for inst in &server.instances {
            let n = inst.points.position.len() as u32;
            assert!(n > 0);
            assert!(inst.blocks.order.range(0..n as usize).eq(0..n));
            assert!(
                matches!(inst.blocks.order, PointOrder::Identity(_)),
                "stored as nothing"
            );
        }
    }

    #[test]
    fn change_lists_give_exactly_the_scanned_deltas() {
        let mut server = Server::new(&scene(), small_config()).unwrap();
        server.history_frames = 4;
        // (join frame, frames between updates): the last client falls behind the history.
        let plan = [(0, 1), (2, 2), (5, 3), (1, 7)];
        let mut clients: Vec<Option<(ClientId, Vec<InstanceGrid>)>> = vec![None, None, None, None];
        let (mut from_log, mut scanned) = (0, 0);
        for frame in 0..36u32 {
            for (k, &(join, _)) in plan.iter().enumerate() {
                if frame == join {
                    let mirror = server
                        .instance_table()
                        .iter()
                        .map(|t| InstanceGrid::new(t.layout))
                        .collect();
                    clients[k] = Some((server.add_client(), mirror));
                }
            }
            server.step(&[view(frame), view(frame + 11)]);
            for (k, &(join, every)) in plan.iter().enumerate() {
                let Some((id, mirror)) = clients[k].as_mut() else {
                    continue;
                };
                if (frame - join) % every != 0 {
                    continue;
                }
                let c = *server.clients.get_mut(*id).unwrap();
                let (snapshot, since) = (c.needs_snapshot, c.last_sent);
                let expected: Vec<InstanceDelta> = server
                    .instances
                    .iter()
                    .enumerate()
                    .filter(|(_, inst)| snapshot || inst.max_stamp > since)
                    .map(|(i, inst)| scan_delta(i as u32, inst, snapshot, since))
                    .filter(|d| !d.buckets.is_empty() || !d.cells.is_empty())
                    .collect();
                if !snapshot && !expected.is_empty() {
                    let logged = server
                        .instances
                        .iter()
                        .all(|i| i.changes.since(since).is_some());
                    if logged {
                        from_log += 1;
                    } else {
                        scanned += 1;
                    }
                }
                let update = server.update_for(*id);
                assert_eq!(update.snapshot, snapshot);
                assert_eq!(update.instances, expected, "client {k} at frame {frame}");
                apply(mirror, &update);
                for (i, grid) in mirror.iter().enumerate() {
                    let server_grid = server.grid(i).unwrap();
                    assert!(grid.buckets().eq(server_grid.buckets()));
                    assert!(grid.cells().copied().eq(server_grid.cells()));
                }
            }
        }
        // Both paths were exercised with real changes.
        assert!(
            from_log > 20 && scanned > 2,
            "{from_log} from the log, {scanned} scanned"
        );
    }

    #[test]
    fn clients_due_the_same_update_share_it() {
        let mut server = Server::new(&scene(), small_config()).unwrap();
        let (a, b, c) = (
            server.add_client(),
            server.add_client(),
            server.add_client(),
        );
        server.step(&[view(0)]);
        // All three are due a snapshot.
        let first = server.updates_for(&[a, b, c]);
        assert_eq!(first.len(), 1);
        assert_eq!(first[0].0, vec![a, b, c]);
        assert!(first[0].1.snapshot);
        server.step(&[view(1)]);
        // `b` skips this frame (coalesced), `c` asks for a resync.
        server.resync(c);
        let second = server.updates_for(&[c, a]);
        assert_eq!(second.len(), 2);
        assert_eq!(second[0].0, vec![c]);
        assert!(second[0].1.snapshot);
        assert_eq!(second[1].0, vec![a]);
        assert!(!second[1].1.snapshot);
        server.step(&[view(2)]);
        // `a` and `c` now hold frame 2's predecessor; `b` is a frame further behind.
        let third = server.updates_for(&[a, b, c]);
        assert_eq!(third.len(), 2);
        assert_eq!(third[0].0, vec![a, c]);
        assert_eq!(third[1].0, vec![b]);
        // Each group's update is what `update_for` would have given its members.
        let mut lone = Server::new(&scene(), small_config()).unwrap();
        let (la, lb) = (lone.add_client(), lone.add_client());
        for (f, due) in [(0, vec![la, lb]), (1, vec![la]), (2, vec![la, lb])] {
            lone.step(&[view(f)]);
            let updates: Vec<_> = due.iter().map(|&id| lone.update_for(id)).collect();
            if f == 2 {
                assert_eq!(updates[0], third[0].1);
                assert_eq!(updates[1], third[1].1);
            }
        }
    }

    /// The (visible count, selection) by testing every point against the frusta.
    fn brute_force(
        server: &Server,
        frusta: &[Frustum],
        max_points: usize,
    ) -> (usize, Vec<(u32, u32)>) {
        let max_samples = server.config.max_samples;
        let mut visible = 0;
        let mut keyed = Vec::new();
        for (ii, inst) in server.instances.iter().enumerate() {
            let p = &inst.points;
            for i in 0..p.position.len() {
                let w = inst.transform.transform_point3(p.position[i]);
                if !p.stored.get(i) || !frusta.iter().any(|f| f.contains(w, inst.slack)) {
                    continue;
                }
                visible += 1;
                if p.samples(i) < max_samples {
                    let tie = crate::blocks::tie_of(ii as u32, i as u32, server.config.seed);
                    keyed.push((
                        (u64::from(p.samples(i)) << 32) | u64::from(tie),
                        ii as u32,
                        i as u32,
                    ));
                }
            }
        }
        keyed.sort_unstable();
        let mut ids: Vec<(u32, u32)> = keyed.iter().take(max_points).map(|k| (k.1, k.2)).collect();
        ids.sort_unstable();
        (visible, ids)
    }

    /// Every instance's block summaries equal ones computed afresh from its points.
    fn assert_summaries_current(server: &Server) {
        for (ii, inst) in server.instances.iter().enumerate() {
            let fresh = crate::summary::BlockSummaries::new(
                &inst.blocks,
                &inst.points,
                server.config.max_samples,
            );
            for b in 0..inst.blocks.blocks.len() {
                assert_eq!(
                    inst.summaries.stored(b),
                    fresh.stored(b),
                    "instance {ii} block {b}"
                );
                assert_eq!(
                    inst.summaries.entries(b),
                    fresh.entries(b),
                    "instance {ii} block {b}"
                );
            }
        }
    }

    #[test]
    fn culling_selects_the_same_points_whatever_the_guessed_cut() {
        let config = ServerConfig {
            density: 256.0,
            ray_budget: 4000,
            rays_per_point: 4,
            max_samples: 12,
            ..ServerConfig::default()
        };
        let mut server = Server::new(&scene(), config).unwrap();
        let max_points = 1000;
        let mut cuts = Vec::new();
        for frame in 0..12 {
            let views = [view(frame), view(frame + 5)];
            let frusta: Vec<Frustum> = views
                .iter()
                .map(|v| Frustum::new(v, config.frustum_margin))
                .collect();
            let run = |guess| {
                let c = cull(&server.instances, &frusta, max_points, guess);
                let ids = |s: Vec<crate::trace::Candidate>| -> Vec<(u32, u32)> {
                    s.iter().map(|c| (c.instance, c.index)).collect()
                };
                (c.visible, c.cut, ids(select(c.candidates, max_points)))
            };
            let all = run(u16::MAX);
            assert!(all.0 > max_points && all.2.len() == max_points);
            assert_eq!(
                brute_force(&server, &frusta, max_points),
                (all.0, all.2.clone())
            );
            for guess in [
                0,
                1,
                all.1.saturating_sub(1),
                all.1,
                all.1.saturating_add(3),
            ] {
                assert_eq!(run(guess), all, "frame {frame}, guess {guess}");
            }
            cuts.push(all.1);
            server.step(&views);
        }
        assert!(
            cuts.windows(2).any(|w| w[0] != w[1]),
            "the cut moves: {cuts:?}"
        );
    }

    /// The test scene plus a skinned strip swinging over the floor and the wall sliding
    /// along x, both played from t = 0.
    fn animated_scene() -> Scene {
        use glam::{Mat4, Quat};
        use psao_scene::{AnimatedProperty, Animation, Channel, Interpolation, Node, Skin};
        let mut scene = scene();
        let node = |name: &str, parent: Option<usize>, translation: Vec3| Node {
            name: name.into(),
            parent,
            translation,
            rotation: Quat::IDENTITY,
            scale: Vec3::ONE,
        };
        let mut strip = Mesh::default();
        for y in [0.0f32, 1.0, 2.0] {
            for x in [-0.25f32, 0.25] {
                strip.positions.push(Vec3::new(x, y + 0.2, 0.8));
                strip.normals.push(Vec3::Z);
                strip.joints.push([0, 1, 0, 0]);
                strip.weights.push([1.0 - y / 2.0, y / 2.0, 0.0, 0.0]);
            }
        }
        strip.indices = vec![[0, 1, 3], [0, 3, 2], [2, 3, 5], [2, 5, 4]];
        scene.meshes.push(strip);
        scene.nodes = vec![
            node("wall", None, Vec3::ZERO),
            node("strip", None, Vec3::ZERO),
            node("root", None, Vec3::ZERO),
            node("upper", Some(2), Vec3::new(0.0, 1.2, 0.0)),
        ];
        scene.instances[1].node = Some(0);
        scene.instances.push(Instance {
            mesh: 2,
            node: Some(1),
            transform: Affine3A::IDENTITY,
            skin: Some(0),
        });
        scene.skins.push(Skin {
            name: "strip".into(),
            joints: vec![2, 3],
            inverse_bind: vec![
                Mat4::IDENTITY,
                Mat4::from_translation(Vec3::new(0.0, -1.2, 0.0)),
            ],
        });
        let swing = |a: f32| Quat::from_rotation_z(a).to_array();
        scene.animations.push(Animation {
            name: "move".into(),
            channels: vec![
                Channel {
                    node: 3,
                    property: AnimatedProperty::Rotation,
                    interpolation: Interpolation::Linear,
                    times: vec![0.0, 1.0, 2.0],
                    values: [swing(0.0), swing(1.2), swing(0.0)].concat(),
                },
                Channel {
                    node: 0,
                    property: AnimatedProperty::Translation,
                    interpolation: Interpolation::Linear,
                    times: vec![0.0, 2.0],
                    values: [0.0, 0.0, 0.0, 0.8, 0.0, 0.0].to_vec(),
                },
            ],
        });
        scene.playing.push(0);
        scene
    }

    #[test]
    fn summaries_stay_current_under_tracing_invalidation_and_skinning() {
        for invalidation in [Invalidation::Proximity, Invalidation::Everything] {
            let config = ServerConfig {
                density: 256.0,
                ray_budget: 3000,
                rays_per_point: 4,
                max_samples: 8,
                invalidation,
                ..ServerConfig::default()
            };
            let mut server = Server::new(&animated_scene(), config).unwrap();
            assert_summaries_current(&server);
            let (mut invalidated, mut converged) = (0, 0);
            for frame in 0..24u32 {
                let views = [view(frame), view(frame + 7)];
                // Pause the animation now and then so that points converge.
                let time = (frame.min(6) + frame.saturating_sub(16)) as f32 * 0.1;
                let stats = server.step_at(&views, time).unwrap();
                invalidated += stats.invalidated_points;
                assert_summaries_current(&server);
                let frusta: Vec<Frustum> = views
                    .iter()
                    .map(|v| Frustum::new(v, config.frustum_margin))
                    .collect();
                let c = cull(&server.instances, &frusta, 750, server.cut_guess);
                let ids: Vec<(u32, u32)> = select(c.candidates, 750)
                    .iter()
                    .map(|c| (c.instance, c.index))
                    .collect();
                assert_eq!(
                    brute_force(&server, &frusta, 750),
                    (c.visible, ids),
                    "frame {frame}"
                );
                converged += server
                    .points(0)
                    .filter(|p| p.samples >= config.max_samples)
                    .count();
            }
            assert!(
                invalidated > 0 && converged > 0,
                "{invalidation:?}: {invalidated} {converged}"
            );
        }
    }
}
