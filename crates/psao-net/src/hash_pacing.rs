//! How often a full state hash is taken outside lockstep.
//!
//! A state hash reads every bucket and cell of every grid, so its cost grows with the scene's
//! points: on a large hall it costs tens of milliseconds on the server and more on a client,
//! whose mirror is made compact rather than fast to walk. Taken at every update it would
//! slow the server's frames and, on a client holding a large state, take the whole client
//! (docs/SECURITY.md, "Corrections"). Outside lockstep a hash is therefore taken only when
//! its cost stays within [`HASH_SHARE`] of the wall-clock time since the previous one: a
//! small state is still hashed at every update, a large one as often as that share allows.
//! Lockstep sessions (tests, evaluations) hash every update: there each round waits for
//! every client anyway, and exactness is the point.

use std::time::{Duration, Instant};

/// Share of wall-clock time state hashing may take outside lockstep.
pub const HASH_SHARE: f64 = 0.1;

/// When the next state hash is due.
#[derive(Clone, Copy, Debug, Default)]
pub struct HashPacing {
    next: Option<Instant>,
}

impl HashPacing {
    /// Whether a hash taken at `now` stays within [`HASH_SHARE`] (the first always does).
    pub fn due(&self, now: Instant) -> bool {
        self.next.is_none_or(|next| now >= next)
    }

    /// A hash started at `started` took `took`: the next is due once `took / HASH_SHARE`
    /// has passed since `started`.
    pub fn taken(&mut self, started: Instant, took: Duration) {
        self.next = Some(started + took.div_f64(HASH_SHARE));
    }

    /// Run `hash` if it is due at `now` (or `always`), recording its cost.
    pub fn hash_if_due(&mut self, always: bool, hash: impl FnOnce() -> u64) -> Option<u64> {
        let started = Instant::now();
        if !always && !self.due(started) {
            return None;
        }
        let h = hash();
        self.taken(started, started.elapsed());
        Some(h)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_hash_is_due_again_once_its_cost_is_a_tenth_of_the_time_since() {
        let t0 = Instant::now();
        let mut p = HashPacing::default();
        assert!(p.due(t0), "the first hash is always due");
        p.taken(t0, Duration::from_millis(40));
        assert!(!p.due(t0 + Duration::from_millis(399)));
        assert!(p.due(t0 + Duration::from_millis(400)));
    }

    #[test]
    fn a_cheap_hash_is_due_at_every_frame() {
        let t0 = Instant::now();
        let mut p = HashPacing::default();
        // 0.1 ms hashes at 30 Hz: due again after 1 ms, well before the next frame.
        p.taken(t0, Duration::from_micros(100));
        assert!(p.due(t0 + Duration::from_millis(33)));
    }

    #[test]
    fn lockstep_hashes_whatever_the_pacing() {
        let mut p = HashPacing::default();
        p.taken(Instant::now(), Duration::from_secs(3600));
        assert_eq!(p.hash_if_due(false, || 7), None);
        assert_eq!(p.hash_if_due(true, || 7), Some(7));
    }
}
