//! One viewer's correction state across frames: the region queue ([`Planner`], the server's
//! half in the split), the sample cache (the client's half) and the bookkeeping that ties them
//! to camera changes. The frame loop is: on a camera change
//! [`Corrector::camera_changed`] (aging); every analysis period [`Corrector::analyze`];
//! [`Corrector::plan`] the frame's positions within its sample budget; trace them (the caller,
//! e.g. in parallel); [`Corrector::add`] the samples; [`Corrector::splat`] onto the base frame.

use crate::attention::ObjectRegion;
use crate::cache::{AgingStats, CacheConfig, CacheError, SampleCache};
use crate::schedule::{Job, RegionQueue};
use crate::schedule::{RegionOrder, DEFAULT_ORDER};
use crate::screen::ScreenView;
use crate::splat::{Sample, SplatTarget};
use crate::sqrt5::{Hierarchy, PixelRect};

/// A pixel to trace: position, object and level.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Planned {
    /// Pixel column.
    pub x: i32,
    /// Pixel row.
    pub y: i32,
    /// Object id at the pixel.
    pub object: u32,
    /// √5 level of the position.
    pub level: u8,
}

/// The scheduling half of the correction state (where the split puts it on the server): the
/// region queue and which objects were finished since the last camera change.
#[derive(Clone, Debug)]
pub struct Planner {
    hierarchy: Hierarchy,
    queue: RegionQueue,
    /// Camera age at the last analysis.
    analyzed_age: Option<u32>,
    /// Regions (object, rectangle) whose every level was planned since the last camera change.
    finished: Vec<(u32, PixelRect)>,
    /// The regions of the last analysis.
    last: Vec<ObjectRegion>,
    /// The viewer's current camera age, when told.
    camera_age: Option<u32>,
    /// Whether the analyses' priorities order the queue.
    order: RegionOrder,
}

impl Planner {
    /// An empty queue over `hierarchy`'s levels, ordered by [`DEFAULT_ORDER`].
    pub fn new(hierarchy: Hierarchy, job_size: u64, decay: f32) -> Self {
        Self {
            hierarchy,
            queue: RegionQueue::new(hierarchy, job_size, decay),
            analyzed_age: None,
            finished: Vec::new(),
            last: Vec::new(),
            camera_age: None,
            order: DEFAULT_ORDER,
        }
    }

    /// How the queue orders the regions of later analyses.
    pub fn set_order(&mut self, order: RegionOrder) {
        self.order = order;
    }

    /// The √5 hierarchy.
    pub fn hierarchy(&self) -> &Hierarchy {
        &self.hierarchy
    }

    /// A new analysis (regions with their priorities) of a frame seen at `camera_age`.
    pub fn analyze(&mut self, regions: &[ObjectRegion], camera_age: u32) {
        let changed = self.analyzed_age != Some(camera_age);
        if changed {
            self.finished.clear();
        }
        let mut regions = regions.to_vec();
        if self.order == RegionOrder::Uniform {
            for r in &mut regions {
                r.priority = 1.0;
            }
        }
        self.queue.submit(&regions, changed, &self.finished);
        self.analyzed_age = Some(camera_age);
        self.last = regions;
    }

    /// The viewer's camera age now. Once the queue has run dry while the camera moved
    /// since the last analysis, every cached sample shows an older view and the budget would
    /// idle until the next analysis: the next job then starts that analysis's regions again
    /// at level 1 for this camera age, as a new analysis of the same regions would. A camera
    /// that has not moved never retraces a pixel.
    pub fn set_camera_age(&mut self, camera_age: u32) {
        self.camera_age = Some(camera_age);
    }

    /// Whether the dry queue would start again (see [`Self::set_camera_age`]).
    fn can_restart(&self) -> bool {
        self.queue.is_empty()
            && !self.last.is_empty()
            && self.analyzed_age.is_some()
            && self.camera_age.is_some()
            && self.camera_age != self.analyzed_age
    }

    /// True when the queue holds work.
    pub fn has_work(&self) -> bool {
        !self.queue.is_empty() || self.can_restart()
    }

    /// The next job of at most `max_len` positions (the remainder stays queued); a job that
    /// ends its region's last level marks the object finished.
    pub fn take_job(&mut self, max_len: u64) -> Option<Job> {
        if let (true, Some(age)) = (self.can_restart(), self.camera_age) {
            let last = std::mem::take(&mut self.last);
            self.analyze(&last, age);
        }
        let (job, done) = self.queue.take(max_len)?;
        if done {
            self.finished.push((job.object, job.rect));
        }
        Some(job)
    }

    /// The pixel positions of `job`, in iteration order.
    pub fn positions(&self, job: &Job) -> Vec<(i32, i32)> {
        self.hierarchy
            .level_samples(job.level, job.rect)
            .map(|s| s.iter_from(job.start).take(job.len as usize).collect())
            .unwrap_or_default()
    }

    /// Positions to trace: jobs in priority order until `budget` positions satisfy `on_object`
    /// (`(x, y, object)` → whether the pixel shows the object), the queue runs dry, or
    /// `examine` positions were looked at (never more: the last job is cut to what is left).
    pub fn plan(
        &mut self,
        budget: usize,
        examine: usize,
        mut on_object: impl FnMut(i32, i32, u32) -> bool,
    ) -> Vec<Planned> {
        let mut out = Vec::with_capacity(budget.min(examine));
        let mut examined = 0usize;
        while out.len() < budget && examined < examine {
            let left = (budget - out.len()).min(examine - examined);
            let Some(job) = self.take_job(left as u64) else {
                break;
            };
            for (x, y) in self.positions(&job) {
                examined += 1;
                if on_object(x, y, job.object) {
                    out.push(Planned {
                        x,
                        y,
                        object: job.object,
                        level: job.level,
                    });
                }
            }
        }
        out
    }
}

/// Correction state of one viewer in one place: the planner and the sample cache.
#[derive(Clone, Debug)]
pub struct Corrector {
    planner: Planner,
    cache: SampleCache,
}

impl Corrector {
    /// A fresh state.
    pub fn new(
        hierarchy: Hierarchy,
        cache: CacheConfig,
        job_size: u64,
        decay: f32,
    ) -> Result<Self, CacheError> {
        Ok(Self {
            planner: Planner::new(hierarchy, job_size, decay),
            cache: SampleCache::new(cache, hierarchy)?,
        })
    }

    /// How the queue orders the regions of later analyses ([`Planner::set_order`]).
    pub fn set_order(&mut self, order: RegionOrder) {
        self.planner.set_order(order);
    }

    /// The sample cache.
    pub fn cache(&self) -> &SampleCache {
        &self.cache
    }

    /// The √5 hierarchy.
    pub fn hierarchy(&self) -> &Hierarchy {
        self.planner.hierarchy()
    }

    /// The camera changed: age the cache (the camera age goes up by one).
    pub fn camera_changed(&mut self, view: &ScreenView) -> AgingStats {
        let stats = self.cache.camera_changed(view);
        self.planner.set_camera_age(self.cache.camera_age());
        stats
    }

    /// The view of the current camera age (see [`SampleCache::set_view`]).
    pub fn set_view(&mut self, view: &ScreenView) {
        self.cache.set_view(view);
    }

    /// Per object, the largest turn of its samples' view direction (see
    /// [`SampleCache::set_view_tolerances`]).
    pub fn set_view_tolerances(&mut self, tolerances: std::collections::HashMap<u32, f32>) {
        self.cache.set_view_tolerances(tolerances);
    }

    /// Drop the cached samples of moving objects.
    pub fn drop_objects(&mut self, moving: impl Fn(u32) -> bool) -> usize {
        self.cache.drop_objects(moving)
    }

    /// A new analysis of the current frame (regions with their priorities).
    pub fn analyze(&mut self, regions: &[ObjectRegion]) {
        self.planner.analyze(regions, self.cache.camera_age());
    }

    /// Positions to trace this frame: jobs in priority order until `budget` positions lie on
    /// their objects (`ids`, row-major with `width` columns) or the queue runs dry.
    pub fn plan(&mut self, ids: &[u32], width: usize, budget: usize) -> Vec<Planned> {
        let height = ids.len().checked_div(width).unwrap_or(0);
        self.planner.plan(budget, usize::MAX, |x, y, object| {
            let on_screen = x >= 0 && y >= 0 && (x as usize) < width && (y as usize) < height;
            on_screen && ids[y as usize * width + x as usize] == object
        })
    }

    /// Store traced samples.
    pub fn add(&mut self, samples: &[Sample]) -> Result<(), CacheError> {
        self.cache.insert(samples)
    }

    /// Splat the cache onto `target` ([`crate::splat`]); returns the samples drawn.
    pub fn splat(&self, view: &ScreenView, target: &mut SplatTarget<'_>) -> usize {
        self.cache.splat(view, target)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plans_cover_each_object_pixel_once_within_the_budget() {
        let (w, h) = (64usize, 40usize);
        let mut ids = vec![0u32; w * h];
        for y in 5..30 {
            for x in 3..20 {
                ids[y * w + x] = 1;
            }
            for x in (30 + y / 3)..(50 + y / 4) {
                ids[y * w + x] = 2;
            }
        }
        let regions = crate::attention::analyze(
            &ids,
            w,
            h,
            &crate::saliency::Map {
                width: w,
                height: h,
                values: vec![0.0; w * h],
            },
            0.0,
        );
        let hierarchy = Hierarchy::new(5).unwrap();
        let mut c = Corrector::new(hierarchy, CacheConfig::default(), 16, 0.15).unwrap();
        c.analyze(&regions);
        let mut seen = std::collections::HashSet::new();
        for frame in 0.. {
            // Re-analysis without a camera change keeps the progress.
            if frame % 3 == 0 {
                c.analyze(&regions);
            }
            let plan = c.plan(&ids, w, 37);
            assert!(plan.len() <= 37);
            if plan.is_empty() {
                break;
            }
            for p in plan {
                assert_eq!(ids[p.y as usize * w + p.x as usize], p.object);
                assert!(seen.insert((p.x, p.y)));
            }
        }
        assert_eq!(seen.len(), ids.iter().filter(|&&i| i != 0).count());
    }

    #[test]
    fn planning_a_missing_objects_region_examines_no_more_than_allowed() {
        // The largest region a client may send (16384², psao-wire's MAX_REGION_IMAGE_SIDE) of
        // an object no pixel shows.
        let side = 16_384;
        let region = ObjectRegion {
            id: 99,
            rect: PixelRect {
                x0: 0,
                y0: 0,
                x1: side,
                y1: side,
            },
            pixels: 0,
            saliency: 0.0,
            importance: 0.0,
            priority: 1.0,
        };
        let mut p = Planner::new(Hierarchy::for_spacing(side as f32 / 4.0), 64, 0.8);
        p.analyze(&[region], 0);
        let mut examined = 0;
        for budget in [50, 1, 64, 65, 1000] {
            let before = examined;
            let plan = p.plan(budget, budget, |_, _, _| {
                examined += 1;
                false
            });
            assert!(plan.is_empty());
            assert_eq!(examined - before, budget, "budget {budget}");
        }
    }

    #[test]
    fn a_dry_queue_starts_again_only_after_the_camera_moved() {
        let rect = PixelRect {
            x0: 0,
            y0: 0,
            x1: 12,
            y1: 9,
        };
        let region = ObjectRegion {
            id: 1,
            rect,
            pixels: 108,
            saliency: 0.0,
            importance: 0.0,
            priority: 0.5,
        };
        let mut p = Planner::new(Hierarchy::new(3).unwrap(), 1000, 0.8);
        let drain = |p: &mut Planner| {
            let mut n = 0;
            while let Some(job) = p.take_job(u64::MAX) {
                n += job.len;
            }
            n
        };
        // Dry before any analysis: nothing to start again.
        p.set_camera_age(0);
        assert!(!p.has_work());
        p.analyze(std::slice::from_ref(&region), 0);
        assert_eq!(drain(&mut p), rect.area());
        // Same camera: the queue stays dry.
        p.set_camera_age(0);
        assert!(!p.has_work());
        // The camera moved: the last analysis's region is traced again, from level 1, once.
        p.set_camera_age(1);
        assert!(p.has_work());
        assert_eq!(p.take_job(1).unwrap().level, 1);
        assert_eq!(1 + drain(&mut p), rect.area());
        assert!(!p.has_work());
        // A later analysis at that age keeps the progress (nothing is traced twice).
        p.analyze(&[region], 1);
        assert!(!p.has_work());
    }

    #[test]
    fn a_uniform_order_ignores_the_priorities_and_goes_breadth_first() {
        let region = |id: u32, x0: i32, priority: f32| ObjectRegion {
            id,
            rect: PixelRect {
                x0,
                y0: 0,
                x1: x0 + 40,
                y1: 40,
            },
            pixels: 1600,
            saliency: priority,
            importance: 0.0,
            priority,
        };
        let regions = [region(1, 0, 1.0), region(2, 50, 0.1)];
        // The (object, level) of each job until object 2 gets its first one.
        let jobs_until_object_2 = |order: RegionOrder| {
            let mut p = Planner::new(Hierarchy::new(3).unwrap(), 10_000, 0.8);
            p.set_order(order);
            p.analyze(&regions, 0);
            let mut jobs = Vec::new();
            while let Some(job) = p.take_job(u64::MAX) {
                jobs.push((job.object, job.level));
                if job.object == 2 {
                    break;
                }
            }
            jobs
        };
        // By priority, object 1 is refined (0.2 after its first level) before object 2 (0.1)
        // gets a first coarse level; uniform, both get level 1 first.
        assert_eq!(
            jobs_until_object_2(RegionOrder::Priority),
            vec![(1, 1), (1, 2), (2, 1)]
        );
        assert_eq!(
            jobs_until_object_2(RegionOrder::Uniform),
            vec![(1, 1), (2, 1)]
        );
    }
}
