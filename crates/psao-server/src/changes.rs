//! Which published buckets and cells changed in recent server frames, so a client's delta
//! costs O(changed) instead of a scan of the whole grid.

use psao_points::vec_bytes;
use std::collections::VecDeque;

/// A frame number as kept per published bucket and cell: exact below `u32::MAX`, saturated
/// from there on (2³² − 1 frames are over four years at 30 Hz).
pub(crate) fn stamp(frame: u64) -> u32 {
    u32::try_from(frame).unwrap_or(u32::MAX)
}

/// Whether an entry stamped `stamp` may have changed after frame `since`: exact for
/// unsaturated stamps, and always true for a saturated one (resending an unchanged entry
/// costs bytes, never correctness).
pub(crate) fn changed_after(stamp: u32, since: u64) -> bool {
    stamp == u32::MAX || u64::from(stamp) > since
}

/// The buckets and cells stamped in one server frame.
struct FrameChanges {
    frame: u64,
    buckets: Vec<u32>,
    cells: Vec<u32>,
}

/// Per-instance log of the buckets and cells changed in the frames not yet forgotten.
/// Invariant: every bucket or cell stamped at a frame after `forgotten_through` is listed
/// under that frame.
#[derive(Default)]
pub(crate) struct ChangeLog {
    /// Ascending by frame; at most one entry per frame.
    frames: VecDeque<FrameChanges>,
    /// Changes stamped at or before this frame are no longer listed.
    forgotten_through: u64,
}

/// The sorted, deduplicated buckets and cells changed after some frame.
#[derive(Debug, Default, PartialEq, Eq)]
pub(crate) struct Changed {
    pub buckets: Vec<u32>,
    pub cells: Vec<u32>,
}

impl ChangeLog {
    /// Heap bytes of the listed changes.
    pub fn heap_bytes(&self) -> u64 {
        let lists: u64 = self
            .frames
            .iter()
            .map(|f| vec_bytes(&f.buckets) + vec_bytes(&f.cells))
            .sum();
        lists + (self.frames.capacity() * std::mem::size_of::<FrameChanges>()) as u64
    }

    /// The entry of `frame`, created when it is newer than the last one.
    fn entry(&mut self, frame: u64) -> &mut FrameChanges {
        if self.frames.back().is_none_or(|f| f.frame < frame) {
            self.frames.push_back(FrameChanges {
                frame,
                buckets: Vec::new(),
                cells: Vec::new(),
            });
        }
        self.frames.back_mut().expect("just pushed")
    }

    /// Note that bucket `b` was stamped with `frame` (frames never decrease).
    pub fn bucket(&mut self, frame: u64, b: u32) {
        self.entry(frame).buckets.push(b);
    }

    /// Note that cell slot `slot` was stamped with `frame` (frames never decrease).
    pub fn cell(&mut self, frame: u64, slot: u32) {
        self.entry(frame).cells.push(slot);
    }

    /// Drop the lists of frames up to and including `frame`.
    pub fn forget_through(&mut self, frame: u64) {
        while self.frames.front().is_some_and(|f| f.frame <= frame) {
            self.frames.pop_front();
        }
        self.forgotten_through = self.forgotten_through.max(frame);
    }

    /// Everything stamped after frame `since`, or `None` when some of it was forgotten
    /// (the caller then scans the stamps).
    pub fn since(&self, since: u64) -> Option<Changed> {
        if since < self.forgotten_through {
            return None;
        }
        let mut out = Changed::default();
        for f in self.frames.iter().filter(|f| f.frame > since) {
            out.buckets.extend_from_slice(&f.buckets);
            out.cells.extend_from_slice(&f.cells);
        }
        for v in [&mut out.buckets, &mut out.cells] {
            v.sort_unstable();
            v.dedup();
        }
        Some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stamps_are_exact_below_saturation_and_conservative_after() {
        for frame in [0, 1, 77, u64::from(u32::MAX) - 1] {
            let t = stamp(frame);
            assert_eq!(u64::from(t), frame);
            assert!(changed_after(t, frame.wrapping_sub(1)) || frame == 0);
            assert!(!changed_after(t, frame));
        }
        let late = u64::from(u32::MAX) + 5;
        assert_eq!(stamp(late), u32::MAX);
        assert!(changed_after(stamp(late), late - 1));
        assert!(
            changed_after(stamp(late), late),
            "saturated stamps always resend"
        );
    }

    #[test]
    fn unions_recent_frames_and_refuses_forgotten_ones() {
        let mut log = ChangeLog::default();
        log.cell(1, 5);
        log.bucket(1, 2);
        log.cell(2, 3);
        log.cell(2, 5);
        log.cell(4, 9);
        log.bucket(4, 2);
        let all = log.since(0).unwrap();
        assert_eq!((all.buckets, all.cells), (vec![2], vec![3, 5, 9]));
        assert_eq!(log.since(2).unwrap().cells, vec![9]);
        assert_eq!(log.since(4).unwrap(), Changed::default());
        log.forget_through(2);
        assert_eq!(log.since(1), None, "frame 2 was forgotten");
        assert_eq!(log.since(2).unwrap().cells, vec![9]);
        log.forget_through(6);
        assert_eq!(log.since(5), None);
        assert_eq!(log.since(6).unwrap(), Changed::default());
    }
}
