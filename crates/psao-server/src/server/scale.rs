//! The [`Server`] split over several processes (docs/SCALE-OUT.md): a *trace node* steps
//! the whole scene's selection but traces and publishes only the points of the partitions
//! it holds, handing out [`PointRecord`]s; a *replica* (an edge) traces nothing and builds
//! the published grids from every partition's records with the same publishing code, so its
//! grids, stamps and client updates equal those of one server stepping alone.

use psao_points::pack::unpack_ao;

use super::Server;
use crate::light::LightSample;
use crate::partition::Owners;
use crate::publish::apply;
use crate::trace::{trace, Candidate, Traced};
use crate::{ServerError, StepStats};

/// One point's newly published record: what a trace node tells the edges.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct PointRecord {
    /// Instance index.
    pub instance: u32,
    /// Point index within the instance (generation order).
    pub index: u32,
    /// The packed record (never 0).
    pub bits: u32,
}

/// A published point and its sample count: what a trace node's snapshot says of one point,
/// so that a node starting later restarts it from there instead of from zero.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct PointState {
    /// The point and its published record.
    pub record: PointRecord,
    /// AO samples the point had.
    pub samples: u32,
}

/// What one frame's tracing did: the new samples of every selected point (on a trace node
/// those of other nodes' points counted, not traced) and the rays and paths traced here.
#[derive(Default)]
pub(super) struct TracedFrame {
    pub traced: Vec<Traced>,
    /// AO rays traced.
    pub rays: u64,
    /// Light paths traced and the rays they took.
    pub light_paths: u64,
    pub light_rays: u64,
}

/// What a trace node holds: the owners of every point and the partitions it traces.
pub(crate) struct Held {
    owners: Owners,
    held: Vec<bool>,
    /// Records published by the last step.
    records: Vec<PointRecord>,
}

impl Held {
    /// Whether point `index` of `instance` is traced here.
    fn owns(&self, instance: u32, index: u32) -> bool {
        self.held[self.owners.owner(instance, index) as usize]
    }
}

impl Server {
    /// The owners of every point when the scene is split into `count` partitions
    /// ([`crate::partition::balanced_runs`] over the culling blocks, in (instance, block)
    /// order). `count` is clamped to 1..=[`crate::partition::MAX_PARTITIONS`].
    pub fn owners(&self, count: u32) -> Owners {
        let count = count.clamp(1, crate::partition::MAX_PARTITIONS);
        let owned: Vec<Vec<Vec<u32>>> = self
            .instances
            .iter()
            .map(|inst| {
                let b = &inst.blocks;
                b.blocks
                    .iter()
                    .map(|blk| {
                        b.order
                            .range(blk.start as usize..blk.end as usize)
                            .collect()
                    })
                    .collect()
            })
            .collect();
        let blocks: Vec<Vec<&[u32]>> = owned
            .iter()
            .map(|inst| inst.iter().map(Vec::as_slice).collect())
            .collect();
        let points: Vec<usize> = self
            .instances
            .iter()
            .map(|i| i.points.position.len())
            .collect();
        Owners::from_blocks(&blocks, &points, count)
    }

    /// Trace and publish only the points of the partitions `held` of `owners` from now on
    /// (a trace node). The other points' sample counts still advance as if traced, so every
    /// node selects the same points as one whole server would.
    pub fn hold_partitions(&mut self, owners: Owners, held: &[u32]) {
        let mut flags = vec![false; owners.count() as usize];
        for &k in held {
            if let Some(f) = flags.get_mut(k as usize) {
                *f = true;
            }
        }
        self.held = Some(Held {
            owners,
            held: flags,
            records: Vec::new(),
        });
    }

    /// Take over partition `k` (its node died): its points restart from their published
    /// AO (as many samples as counted, each worth the published mean) instead of from zero.
    /// Returns the points adopted; 0 when this server holds no partitions.
    pub fn adopt_partition(&mut self, k: u32) -> usize {
        let Some(held) = self.held.as_mut() else {
            return 0;
        };
        let Some(flag) = held.held.get_mut(k as usize) else {
            return 0;
        };
        *flag = true;
        let mut adopted = 0;
        for (i, inst) in self.instances.iter_mut().enumerate() {
            let p = &mut inst.points;
            for j in 0..p.position.len() {
                if held.owners.owner(i as u32, j as u32) == k {
                    p.sum[j] = if p.published[j] == 0 {
                        0.0
                    } else {
                        unpack_ao(p.published[j]) * p.samples(j) as f32
                    };
                    adopted += 1;
                }
            }
        }
        adopted
    }

    /// The partitions this server traces (empty when it traces everything).
    pub fn held_partitions(&self) -> Vec<u32> {
        self.held.as_ref().map_or_else(Vec::new, |h| {
            (0..h.held.len() as u32)
                .filter(|&k| h.held[k as usize])
                .collect()
        })
    }

    /// The owners in use on a trace node.
    pub fn partition_owners(&self) -> Option<&Owners> {
        self.held.as_ref().map(|h| &h.owners)
    }

    /// The records the last [`Server::step_at`] published, in (instance, index) order
    /// (empty unless partitions are held).
    pub fn take_records(&mut self) -> Vec<PointRecord> {
        self.held
            .as_mut()
            .map(|h| std::mem::take(&mut h.records))
            .unwrap_or_default()
    }

    /// Note records another node published (a trace node keeps every point's published
    /// record, so that it can adopt a dead node's partition): the published values only,
    /// stamped with the current frame. Malformed records are refused as in
    /// [`Server::step_replica`].
    pub fn note_records(&mut self, records: &[PointRecord]) -> Result<(), ServerError> {
        self.validate_records(records)?;
        let frame = self.frame;
        for run in records.chunk_by(|a, b| a.instance == b.instance) {
            let inst = &mut self.instances[run[0].instance as usize];
            let updates: Vec<(u32, u32)> = run.iter().map(|r| (r.index, r.bits)).collect();
            apply(inst, &updates, frame);
        }
        Ok(())
    }

    /// One server frame of a replica at scene time `time`: pose the scene as
    /// [`Server::step_at`] does, then publish `records` (every partition's records of this
    /// frame) into the grids. Nothing is traced. Records naming a point that does not exist
    /// or (once posed: points move) is not stored, or a zero record, are refused before
    /// anything is published or the frame counted.
    pub fn step_replica(
        &mut self,
        time: f32,
        records: &[PointRecord],
    ) -> Result<StepStats, ServerError> {
        self.check_records(records)?;
        let start = std::time::Instant::now();
        let advanced = self.pose(time)?;
        self.validate_records(records)?;
        self.frame += 1;
        let published = self.publish_runs(runs(records));
        Ok(StepStats {
            published_points: published,
            moved_instances: advanced.stats.moved_instances,
            publish_ms: start.elapsed().as_secs_f64() * 1e3,
            ms: start.elapsed().as_secs_f64() * 1e3,
            ..StepStats::default()
        })
    }

    /// The published records of partition `k`'s stored points with their sample counts, in
    /// (instance, index) order, cut into chunks of `chunk_points` of the partition's points
    /// each (published or not, so a chunk names the same points every time, see
    /// [`Owners::chunks`]): a trace node's snapshot of the partition. Empty when this server
    /// holds no partitions.
    pub fn partition_records(&self, k: u32, chunk_points: usize) -> Vec<Vec<PointState>> {
        let Some(held) = &self.held else {
            return Vec::new();
        };
        let chunk_points = chunk_points.max(1);
        let mut chunks: Vec<Vec<PointState>> = Vec::new();
        let mut ordinal = 0usize;
        for (i, inst) in self.instances.iter().enumerate() {
            let p = &inst.points;
            for j in 0..p.position.len() {
                if held.owners.owner(i as u32, j as u32) != k {
                    continue;
                }
                if ordinal.is_multiple_of(chunk_points) {
                    chunks.push(Vec::new());
                }
                ordinal += 1;
                if p.published[j] != 0 && p.stored.get(j) {
                    chunks.last_mut().expect("pushed above").push(PointState {
                        record: PointRecord {
                            instance: i as u32,
                            index: j as u32,
                            bits: p.published[j],
                        },
                        samples: p.samples(j),
                    });
                }
            }
        }
        chunks
    }

    /// Give the points of `states` their sample counts, each sample worth the point's
    /// published AO (a trace node restored with [`Server::restore_replica`] from snapshots
    /// continues their sampling instead of restarting it). Counts above the configured
    /// maximum are clamped; points without a published record keep no samples. Refuses
    /// points that do not exist.
    pub fn restore_samples(&mut self, states: &[PointState]) -> Result<usize, ServerError> {
        let records: Vec<PointRecord> = states.iter().map(|s| s.record).collect();
        self.check_records(&records)?;
        let max = self.config.max_samples;
        let mut restored = 0;
        for s in states {
            let p = &mut self.instances[s.record.instance as usize].points;
            let j = s.record.index as usize;
            if p.published[j] == 0 {
                continue;
            }
            p.set_samples(j, s.samples.min(max));
            p.sum[j] = unpack_ao(p.published[j]) * p.samples(j) as f32;
            restored += 1;
        }
        for inst in &mut self.instances {
            inst.rebuild_summaries();
        }
        Ok(restored)
    }

    /// Start a fresh replica (or trace node) at server frame `frame` (scene time `time`)
    /// from the published `records` of every point at that frame (the snapshots of every
    /// partition and the batches after them): pose the scene, publish them, and continue
    /// with [`Server::step_replica`] (or [`Server::step_at`]) for `frame + 1`.
    /// Refuses a replica that stepped already, and malformed records.
    pub fn restore_replica(
        &mut self,
        frame: u64,
        time: f32,
        records: &[PointRecord],
    ) -> Result<usize, ServerError> {
        if self.frame != 0 {
            return Err(ServerError::Records(format!(
                "a snapshot restores a fresh replica, not one at frame {}",
                self.frame
            )));
        }
        self.check_records(records)?;
        self.pose(time)?;
        self.validate_records(records)?;
        self.frame = frame;
        let published = self.publish_runs(runs(records));
        // On a trace node these are not this frame's records to send.
        if let Some(held) = &mut self.held {
            held.records.clear();
        }
        Ok(published)
    }

    /// Refuses records naming a point that does not exist or is not stored in the current
    /// pose, zero records, and a point named twice.
    pub fn validate_records(&self, records: &[PointRecord]) -> Result<(), ServerError> {
        self.check_records(records)?;
        for r in records {
            if !self.instances[r.instance as usize]
                .points
                .stored
                .get(r.index as usize)
            {
                return Err(ServerError::Records(format!(
                    "instance {} point {}: not stored in the grid",
                    r.instance, r.index
                )));
            }
        }
        Ok(())
    }

    /// Refuses records naming a point that does not exist, zero records, and a point named
    /// twice: what can be checked whatever the pose (an edge checks batches on arrival).
    pub fn check_records(&self, records: &[PointRecord]) -> Result<(), ServerError> {
        for r in records {
            let ok = self
                .instances
                .get(r.instance as usize)
                .is_some_and(|inst| (r.index as usize) < inst.points.position.len())
                && r.bits != 0;
            if !ok {
                return Err(ServerError::Records(format!(
                    "instance {} point {} record {:#x}: no such point, or an empty record",
                    r.instance, r.index, r.bits
                )));
            }
        }
        let mut ids: Vec<(u32, u32)> = records.iter().map(|r| (r.instance, r.index)).collect();
        ids.sort_unstable();
        if ids.windows(2).any(|w| w[0] == w[1]) {
            return Err(ServerError::Records(
                "a point published twice in one frame".into(),
            ));
        }
        Ok(())
    }

    /// Trace the `selected` points this server holds (all of them when it holds no
    /// partitions); the others only count the samples they would have got. Returns the
    /// samples in (instance, index) order with the rays and light paths actually traced.
    pub(super) fn trace_held(&self, selected: &[Candidate]) -> TracedFrame {
        let c = &self.config;
        let run = |selected: &[Candidate]| {
            let mut traced = trace(
                &self.tracer,
                self.medium.as_deref(),
                &self.instances,
                selected,
                self.radius,
                c.rays_per_point,
                c.max_samples,
                c.seed,
            );
            if let Some(lighting) = &self.lighting {
                let pose = self.dynamics.pose();
                let light = lighting.trace(
                    &self.tracer,
                    pose,
                    &self.instances,
                    selected,
                    c.max_samples,
                    c.seed,
                );
                // Both are in the order of `selected`.
                for (t, l) in traced.iter_mut().zip(light) {
                    t.light = l;
                }
            }
            let mut frame = TracedFrame::default();
            for t in &traced {
                frame.rays += u64::from(t.rays);
                frame.light_paths += u64::from(t.light.paths);
                frame.light_rays += t.light.rays;
            }
            frame.traced = traced;
            frame
        };
        let Some(held) = &self.held else {
            return run(selected);
        };
        let (mine, others): (Vec<Candidate>, Vec<Candidate>) = selected
            .iter()
            .partition(|s| held.owns(s.instance, s.index));
        let mut frame = run(&mine);
        frame.traced.extend(others.iter().map(|s| {
            let p = &self.instances[s.instance as usize].points;
            let count = p.samples(s.index as usize);
            // The paths the owner traces, so that selection stays in step across nodes.
            let paths =
                (self.lighting.as_ref().zip(p.light.as_ref())).map_or(0, |(lighting, sums)| {
                    let max = sums.max_paths(c.max_samples);
                    lighting.paths_for(sums.count[s.index as usize], max)
                });
            Traced {
                instance: s.instance,
                index: s.index,
                sum: 0.0,
                rays: c.rays_per_point.min(c.max_samples.saturating_sub(count)),
                light: LightSample {
                    paths,
                    ..LightSample::default()
                },
            }
        }));
        frame.traced.sort_unstable_by_key(|t| (t.instance, t.index));
        frame
    }

    /// Keep only the publishing candidates this server holds.
    pub(super) fn retain_held(&self, candidates: &mut Vec<(u32, u32)>) {
        if let Some(held) = &self.held {
            candidates.retain(|&(i, p)| held.owns(i, p));
        }
    }

    /// Remember what a step published, on a trace node.
    pub(super) fn record(&mut self, instance: u32, updates: &[(u32, u32)]) {
        if let Some(held) = &mut self.held {
            held.records
                .extend(updates.iter().map(|&(index, bits)| PointRecord {
                    instance,
                    index,
                    bits,
                }));
        }
    }
}

/// `records` sorted and grouped per instance as (point, record) pairs.
fn runs(records: &[PointRecord]) -> Vec<(u32, Vec<(u32, u32)>)> {
    let mut sorted = records.to_vec();
    sorted.sort_unstable();
    sorted
        .chunk_by(|a, b| a.instance == b.instance)
        .map(|run| {
            (
                run[0].instance,
                run.iter().map(|r| (r.index, r.bits)).collect(),
            )
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{ServerConfig, View};
    use glam::{Affine3A, Vec3};
    use psao_scene::{Camera, Instance, Material, Mesh, Scene};

    /// A floor, a wall standing on it and a box-like second wall: three instances.
    fn scene() -> Scene {
        let quad = |a: Vec3, b: Vec3, c: Vec3, d: Vec3| Mesh {
            positions: vec![a, b, c, d],
            indices: vec![[0, 2, 1], [0, 3, 2]],
            ..Default::default()
        };
        let v = Vec3::new;
        let meshes = vec![
            quad(
                v(-2., 0., -2.),
                v(2., 0., -2.),
                v(2., 0., 2.),
                v(-2., 0., 2.),
            ),
            quad(v(-1., 0., 0.), v(-1., 2., 0.), v(1., 2., 0.), v(1., 0., 0.)),
            quad(
                v(0.5, 0., -1.),
                v(0.5, 1., -1.),
                v(0.5, 1., 1.),
                v(0.5, 0., 1.),
            ),
        ];
        let instances = (0..3)
            .map(|mesh| Instance {
                mesh,
                node: None,
                transform: Affine3A::IDENTITY,
                skin: None,
            })
            .collect();
        Scene {
            meshes,
            materials: vec![Material::default()],
            instances,
            ao_radius: 0.6,
            ..Default::default()
        }
    }

    fn view(frame: u32) -> View {
        let a = frame as f32 * 0.4;
        let eye = Vec3::new(3.0 * a.cos(), 1.5, 3.0 * a.sin());
        View {
            camera: Camera::look_at(eye, Vec3::new(0.0, 0.3, 0.0), 50.0),
            aspect: 1.5,
        }
    }

    fn config() -> ServerConfig {
        ServerConfig {
            density: 256.0,
            ray_budget: 1500,
            rays_per_point: 4,
            max_samples: 16,
            ..ServerConfig::default()
        }
    }

    fn same_grids(a: &Server, b: &Server) -> bool {
        (0..a.instance_count()).all(|i| {
            let (x, y) = (a.grid(i).unwrap(), b.grid(i).unwrap());
            x.cells().eq(y.cells()) && x.buckets().eq(y.buckets())
        })
    }

    /// One server per partition of `owners`, each holding only its own.
    fn trace_nodes(scene: &Scene, owners: &Owners) -> Vec<Server> {
        (0..owners.count())
            .map(|k| {
                let mut s = Server::new(scene, config()).unwrap();
                s.hold_partitions(owners.clone(), &[k]);
                s
            })
            .collect()
    }

    #[test]
    fn trace_nodes_and_a_replica_equal_one_server() {
        let scene = scene();
        let mut whole = Server::new(&scene, config()).unwrap();
        let mut replica = Server::new(&scene, config()).unwrap();
        let owners = whole.owners(2);
        let per = owners.points_per_partition();
        assert!(per.iter().all(|&n| n > 0), "{per:?}");
        let mut nodes = trace_nodes(&scene, &owners);
        let (c_whole, c_replica) = (whole.add_client(), replica.add_client());
        let mut node_rays = 0;
        let mut whole_rays = 0;
        for frame in 0..14u32 {
            let views = [view(frame), view(frame + 7)];
            whole_rays += whole.step_at(&views, 0.0).unwrap().rays;
            let mut records = Vec::new();
            for node in &mut nodes {
                node_rays += node.step_at(&views, 0.0).unwrap().rays;
                let mine = node.take_records();
                assert!(mine
                    .iter()
                    .all(|r| node.held_partitions() == [owners.owner(r.instance, r.index)]));
                records.extend(mine);
            }
            replica.step_replica(0.0, &records).unwrap();
            assert_eq!(replica.frame(), whole.frame());
            if frame % 3 == 2 {
                assert_eq!(replica.update_for(c_replica), whole.update_for(c_whole));
            }
        }
        assert!(whole_rays > 0);
        assert_eq!(node_rays, whole_rays, "the nodes share the rays");
        assert!(same_grids(&whole, &replica));
        assert!(whole.grid(0).unwrap().buckets().any(|b| !b.is_empty()));
    }

    #[test]
    fn an_adopted_partition_continues_from_its_published_state() {
        let scene = scene();
        let probe = Server::new(&scene, config()).unwrap();
        let owners = probe.owners(2);
        let mut nodes = trace_nodes(&scene, &owners);
        let mut replica = Server::new(&scene, config()).unwrap();
        for frame in 0..6u32 {
            let views = [view(frame)];
            let mut all = Vec::new();
            for node in &mut nodes {
                node.step_at(&views, 0.0).unwrap();
                all.push(node.take_records());
            }
            // Each node keeps the other's published records.
            nodes[0].note_records(&all[1]).unwrap();
            nodes[1].note_records(&all[0]).unwrap();
            replica.step_replica(0.0, &all.concat()).unwrap();
        }
        // Node 1 dies; node 0 adopts its partition from the published records.
        let mut survivor = nodes.swap_remove(0);
        let adopted = survivor.adopt_partition(1);
        assert_eq!(adopted as u64, owners.points_per_partition()[1]);
        assert_eq!(survivor.held_partitions(), vec![0, 1]);
        for inst in 0..survivor.instance_count() {
            let theirs = survivor.points(inst).enumerate().filter(|(j, p)| {
                owners.owner(inst as u32, *j as u32) == 1 && p.ao.is_some() && p.published.is_some()
            });
            for (_, p) in theirs {
                let (ao, published) = (p.ao.unwrap(), p.published_ao().unwrap());
                assert!((ao - published).abs() < 1e-6, "{ao} vs {published}");
            }
        }
        for frame in 6..20u32 {
            survivor.step_at(&[view(frame)], 0.0).unwrap();
            let records = survivor.take_records();
            replica.step_replica(0.0, &records).unwrap();
        }
        // The replica shows what the survivor published for both partitions.
        assert!(same_grids(&survivor, &replica));
    }

    #[test]
    fn a_replica_restored_from_snapshots_equals_one_that_saw_every_frame() {
        let scene = scene();
        let probe = Server::new(&scene, config()).unwrap();
        let owners = probe.owners(2);
        let mut nodes = trace_nodes(&scene, &owners);
        let mut full = Server::new(&scene, config()).unwrap();
        let mut late = Server::new(&scene, config()).unwrap();
        let step = |nodes: &mut Vec<Server>, frame: u32| {
            let mut all = Vec::new();
            for node in nodes.iter_mut() {
                node.step_at(&[view(frame)], 0.0).unwrap();
                all.extend(node.take_records());
            }
            all
        };
        for frame in 0..8u32 {
            full.step_replica(0.0, &step(&mut nodes, frame)).unwrap();
        }
        // Chunks of 5 points: each partition's points split over several chunks.
        let chunks: Vec<Vec<PointState>> = (0..2)
            .flat_map(|k| nodes[k as usize].partition_records(k, 5))
            .collect();
        let per = owners.points_per_partition();
        assert_eq!(chunks.len() as u64, per[0].div_ceil(5) + per[1].div_ceil(5));
        assert!(chunks.iter().all(|c| c.len() <= 5));
        let states = chunks.concat();
        let records: Vec<PointRecord> = states.iter().map(|s| s.record).collect();
        assert!(!records.is_empty());
        // A trace node starting now restores the published records and their samples.
        let mut fresh = Server::new(&scene, config()).unwrap();
        fresh.hold_partitions(owners.clone(), &[0]);
        fresh.restore_replica(8, 0.0, &records).unwrap();
        assert!(
            fresh.take_records().is_empty(),
            "nothing to send for the restore"
        );
        assert_eq!(fresh.restore_samples(&states).unwrap(), records.len());
        assert!(same_grids(&full, &fresh));
        for inst in 0..fresh.instance_count() {
            let theirs = nodes[0].points(inst);
            for (mine, theirs) in fresh.points(inst).zip(theirs) {
                if let Some(bits) = mine.published {
                    assert_eq!(mine.samples, theirs.samples);
                    let ao = psao_points::pack::unpack_ao(bits);
                    assert!((mine.ao.unwrap_or(ao) - ao).abs() < 1e-6);
                } else {
                    assert_eq!(mine.samples, 0);
                }
            }
        }
        late.restore_replica(8, 0.0, &records).unwrap();
        assert!(same_grids(&full, &late), "restored at frame 8");
        let e = late.restore_replica(8, 0.0, &records).unwrap_err();
        assert!(e.to_string().contains("fresh replica"), "{e}");
        for frame in 8..12u32 {
            let records = step(&mut nodes, frame);
            full.step_replica(0.0, &records).unwrap();
            late.step_replica(0.0, &records).unwrap();
        }
        assert_eq!(late.frame(), full.frame());
        assert!(same_grids(&full, &late), "and after the live frames");
    }

    #[test]
    fn malformed_records_are_refused_before_anything_changes() {
        let scene = scene();
        let mut replica = Server::new(&scene, config()).unwrap();
        let good = PointRecord {
            instance: 0,
            index: 0,
            bits: 1,
        };
        let bad = [
            PointRecord {
                instance: 9,
                ..good
            },
            PointRecord {
                index: u32::MAX,
                ..good
            },
            PointRecord { bits: 0, ..good },
        ];
        for b in bad {
            let e = replica.step_replica(0.0, &[b]).unwrap_err();
            assert!(e.to_string().contains("point records"), "{e}");
        }
        let e = replica.step_replica(0.0, &[good, good]).unwrap_err();
        assert!(e.to_string().contains("twice"), "{e}");
        assert_eq!(replica.frame(), 0, "nothing stepped");
        replica.step_replica(0.0, &[good]).unwrap();
        assert_eq!(replica.frame(), 1);
    }
}
