//! The priority queue of sample regions (paper §4.4): entries hold a region's rectangle, its
//! priority, the √5 level and the iterator position inside that level. A worker takes the
//! entry of highest priority and at most `N_job` positions from it; the remainder of the level
//! goes back with the same priority, a finished level comes back as the next level with the
//! priority reduced by the decay ([`DEFAULT_DECAY`]), so other objects get a rough correction
//! before the first one is refined.

use crate::attention::ObjectRegion;
use crate::sqrt5::{Hierarchy, PixelRect};
use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// Default job size `N_job` (positions per job).
pub const DEFAULT_JOB_SIZE: u64 = 64;

/// Default priority decay per finished level: 0.8 = 1 − 1/5, the share of area a sample
/// stops covering from one √5 level to the next (a level-ℓ+1 sample's footprint is a fifth of
/// a level-ℓ one's), so an entry's priority stays proportional to the (saliency-weighted)
/// image area each of its samples corrects. The paper's 10–20 % let the most salient object
/// run through several levels before objects of half its priority got a first coarse splat,
/// which lost to equal priorities on saliency-weighted FLIP (docs/CORRECTIVE.md).
pub const DEFAULT_DECAY: f32 = 0.8;

/// How a queue orders the regions an analysis gives it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RegionOrder {
    /// By the regions' priorities (the paper: bottom-up saliency blended with task
    /// importance, [`crate::attention`]).
    Priority,
    /// All regions equal: breadth-first over the regions, coarse levels first.
    Uniform,
}

/// The default order: uniform. On camera paths generated through `scenes/corrective.toml`
/// and `scenes/sponza_glossy.toml` (5 seeds each) the saliency ordering did not beat equal
/// priorities on plain FLIP over the non-diffuse pixels by more than the spread over seeds
/// (docs/CORRECTIVE.md, *Saliency against uniform ordering*), so the queue ignores the
/// analyses' priorities unless told otherwise ([`crate::session::Planner::set_order`]); the
/// analyses still say which regions to correct.
pub const DEFAULT_ORDER: RegionOrder = RegionOrder::Uniform;

/// A piece of work: `len` positions of one level of one region, from position `start` on.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Job {
    /// Object id of the region.
    pub object: u32,
    /// The region's screen rectangle.
    pub rect: PixelRect,
    /// √5 level.
    pub level: u8,
    /// First position (iterator index within the level).
    pub start: u64,
    /// Number of positions.
    pub len: u64,
    /// Priority the job was taken at.
    pub priority: f32,
}

#[derive(Clone, Copy, Debug)]
struct Entry {
    priority: f32,
    object: u32,
    rect: PixelRect,
    level: u8,
    start: u64,
}

impl PartialEq for Entry {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Entry {}
impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Entry {
    /// Highest priority first; ties go to the coarser level, then the smaller object id.
    fn cmp(&self, other: &Self) -> Ordering {
        self.priority
            .total_cmp(&other.priority)
            .then(other.level.cmp(&self.level))
            .then(other.object.cmp(&self.object))
    }
}

/// The priority queue of regions.
#[derive(Clone, Debug)]
pub struct RegionQueue {
    hierarchy: Hierarchy,
    job_size: u64,
    decay: f32,
    heap: BinaryHeap<Entry>,
}

impl RegionQueue {
    /// An empty queue; `job_size` is at least 1 and `decay` is clamped to [0, 1).
    pub fn new(hierarchy: Hierarchy, job_size: u64, decay: f32) -> Self {
        Self {
            hierarchy,
            job_size: job_size.max(1),
            decay: decay.clamp(0.0, 0.999),
            heap: BinaryHeap::new(),
        }
    }

    /// Number of queued entries.
    pub fn len(&self) -> usize {
        self.heap.len()
    }

    /// True when no work is queued.
    pub fn is_empty(&self) -> bool {
        self.heap.is_empty()
    }

    /// A new analysis. After a camera change every region restarts at level 1 with its
    /// priority; otherwise queued regions keep their level and position, take the new
    /// priority (decayed by their level), and only objects not queued yet are added at level 1
    /// — objects whose regions were finished are not resubmitted. Either way, objects the
    /// analysis no longer lists (gone from view, or moving) leave the queue.
    pub fn submit(
        &mut self,
        regions: &[ObjectRegion],
        camera_changed: bool,
        finished: &[(u32, PixelRect)],
    ) {
        if camera_changed {
            self.heap = regions
                .iter()
                .map(|r| Entry {
                    priority: r.priority,
                    object: r.id,
                    rect: r.rect,
                    level: 1,
                    start: 0,
                })
                .collect();
            return;
        }
        let mut entries: Vec<Entry> = std::mem::take(&mut self.heap).into_vec();
        entries.retain(|e| regions.iter().any(|r| (r.id, r.rect) == (e.object, e.rect)));
        for r in regions {
            if let Some(e) = entries
                .iter_mut()
                .find(|e| (e.object, e.rect) == (r.id, r.rect))
            {
                e.priority = r.priority * (1.0 - self.decay).powi(e.level as i32 - 1);
            } else if !finished.contains(&(r.id, r.rect)) {
                entries.push(Entry {
                    priority: r.priority,
                    object: r.id,
                    rect: r.rect,
                    level: 1,
                    start: 0,
                });
            }
        }
        self.heap = entries.into();
    }

    /// Take the next job of at most `max_len` positions (and at most the job size); the
    /// remainder goes back. Returns the job and, when it finished the region's last level,
    /// that fact as `true`.
    pub fn take(&mut self, max_len: u64) -> Option<(Job, bool)> {
        let e = self.heap.pop()?;
        let count = self
            .hierarchy
            .level_samples(e.level, e.rect)
            .map_or(0, |s| s.count());
        let len = self
            .job_size
            .min(max_len.max(1))
            .min(count.saturating_sub(e.start));
        let job = Job {
            object: e.object,
            rect: e.rect,
            level: e.level,
            start: e.start,
            len,
            priority: e.priority,
        };
        let mut finished = false;
        if e.start + len < count {
            self.heap.push(Entry {
                start: e.start + len,
                ..e
            });
        } else if e.level < self.hierarchy.levels() {
            self.heap.push(Entry {
                priority: e.priority * (1.0 - self.decay),
                level: e.level + 1,
                start: 0,
                ..e
            });
        } else {
            finished = true;
        }
        Some((job, finished))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn region(id: u32, priority: f32, rect: PixelRect) -> ObjectRegion {
        ObjectRegion {
            id,
            rect,
            pixels: rect.area() as u32,
            saliency: 0.0,
            importance: 0.0,
            priority,
        }
    }

    const A: PixelRect = PixelRect {
        x0: 0,
        y0: 0,
        x1: 30,
        y1: 20,
    };
    const B: PixelRect = PixelRect {
        x0: 40,
        y0: 5,
        x1: 60,
        y1: 25,
    };

    #[test]
    fn jobs_cover_every_position_of_every_level_once() {
        let h = Hierarchy::new(4).unwrap();
        let mut q = RegionQueue::new(h, 7, 0.15);
        q.submit(&[region(1, 0.9, A), region(2, 0.5, B)], true, &[]);
        let mut seen = std::collections::HashSet::new();
        let mut finished = Vec::new();
        while let Some((job, done)) = q.take(u64::MAX) {
            assert!(job.len <= 7);
            let s = h.level_samples(job.level, job.rect).unwrap();
            for p in s.iter_from(job.start).take(job.len as usize) {
                assert!(seen.insert((job.object, p)), "{p:?} twice");
            }
            if done {
                finished.push(job.object);
            }
        }
        assert_eq!(seen.len() as u64, A.area() + B.area());
        finished.sort_unstable();
        assert_eq!(finished, [1, 2]);
    }

    #[test]
    fn the_higher_priority_goes_first_and_decays_per_level() {
        let h = Hierarchy::new(3).unwrap();
        let mut q = RegionQueue::new(h, 1000, 0.2);
        q.submit(&[region(1, 1.0, A), region(2, 0.9, B)], true, &[]);
        let order: Vec<(u32, u8)> = std::iter::from_fn(|| q.take(u64::MAX))
            .map(|(j, _)| (j.object, j.level))
            .collect();
        // 1.0, then 0.9 (B level 1) beats 0.8 (A level 2), then A level 2 beats B level 2 (0.72).
        assert_eq!(&order[..4], &[(1, 1), (2, 1), (1, 2), (2, 2)]);
    }

    #[test]
    fn a_static_camera_keeps_progress_and_does_not_redo_finished_regions() {
        let h = Hierarchy::new(2).unwrap();
        let mut q = RegionQueue::new(h, 1_000_000, 0.15);
        q.submit(&[region(1, 1.0, A), region(2, 0.5, B)], true, &[]);
        let (first, _) = q.take(u64::MAX).unwrap();
        assert_eq!((first.object, first.level), (1, 1));
        // Re-analysis without camera change: object 1 continues at level 2.
        q.submit(&[region(1, 1.0, A), region(2, 0.5, B)], false, &[]);
        let (next, _) = q.take(u64::MAX).unwrap();
        assert_eq!((next.object, next.level), (1, 2));
        q.submit(&[region(1, 1.0, A), region(2, 0.5, B)], false, &[(1, A)]);
        let rest: Vec<_> = std::iter::from_fn(|| q.take(u64::MAX))
            .map(|(j, _)| j.object)
            .collect();
        assert!(rest.iter().all(|&o| o == 2));
        // An object the analysis no longer lists leaves the queue.
        q.submit(&[region(1, 1.0, A), region(2, 0.5, B)], true, &[]);
        q.submit(&[region(2, 0.5, B)], false, &[]);
        assert!(std::iter::from_fn(|| q.take(u64::MAX)).all(|(j, _)| j.object == 2));
        // A camera change restarts everything at level 1.
        q.submit(&[region(1, 1.0, A)], true, &[(1, A)]);
        assert_eq!(q.take(u64::MAX).unwrap().0.level, 1);
    }

    #[test]
    fn the_budget_limits_a_job_and_the_rest_stays_queued() {
        let h = Hierarchy::new(1).unwrap();
        let mut q = RegionQueue::new(h, 100, 0.15);
        q.submit(&[region(1, 1.0, A)], true, &[]);
        let (j, done) = q.take(10).unwrap();
        assert_eq!((j.start, j.len, done), (0, 10, false));
        let (j, _) = q.take(1000).unwrap();
        assert_eq!((j.start, j.len), (10, 100));
    }
}
