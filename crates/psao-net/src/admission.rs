//! Which connections a server takes: at most [`Admission::total`] open at once, and at most
//! `per_source` from one source (an IPv4 address, or an IPv6 /64: one host's usual share),
//! so that one peer cannot take every slot. A [`Permit`] lives as long as its connection,
//! through a WebSocket upgrade and the session after it.

use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::{Arc, Mutex};

/// Connections open at once, all sources together.
pub const MAX_CONNECTIONS: usize = 1024;
/// Default most connections from one source: a browser opens a handful, and `psao bench
/// serve --clients 32` (the largest documented load from one machine) needs 33.
pub const DEFAULT_MAX_PER_SOURCE: usize = 64;

/// What a connection counts against.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Source {
    /// One IPv4 address.
    V4([u8; 4]),
    /// The first 64 bits of an IPv6 address (an IPv4-mapped address counts as IPv4).
    V6([u8; 8]),
}

impl From<IpAddr> for Source {
    fn from(ip: IpAddr) -> Self {
        match ip {
            IpAddr::V4(v4) => Source::V4(v4.octets()),
            IpAddr::V6(v6) => match v6.to_ipv4_mapped() {
                Some(v4) => Source::V4(v4.octets()),
                None => {
                    let o = v6.octets();
                    Source::V6([o[0], o[1], o[2], o[3], o[4], o[5], o[6], o[7]])
                }
            },
        }
    }
}

/// Why a connection was not admitted.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum Refused {
    /// Every slot is taken.
    #[error("{0} connections open")]
    Full(usize),
    /// The source has its share.
    #[error("{0} connections open from this source")]
    SourceFull(usize),
}

/// Counts open connections, in total and per source.
#[derive(Debug)]
pub struct Admission {
    total: usize,
    per_source: usize,
    open: Mutex<Counts>,
}

#[derive(Debug, Default)]
struct Counts {
    total: usize,
    by_source: HashMap<Source, usize>,
}

/// One admitted connection's slot, given back on drop (shared by clones).
#[derive(Clone, Debug)]
pub struct Permit {
    _slot: Arc<Slot>,
}

#[derive(Debug)]
struct Slot {
    admission: Arc<Admission>,
    source: Source,
}

impl Drop for Slot {
    fn drop(&mut self) {
        let mut open = self.admission.lock();
        open.total -= 1;
        if let Some(n) = open.by_source.get_mut(&self.source) {
            *n -= 1;
            if *n == 0 {
                open.by_source.remove(&self.source);
            }
        }
    }
}

impl Admission {
    /// At most `total` connections, `per_source` of them from one source (both ≥ 1).
    pub fn new(total: usize, per_source: usize) -> Arc<Self> {
        Arc::new(Self {
            total: total.max(1),
            per_source: per_source.max(1),
            open: Mutex::new(Counts::default()),
        })
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Counts> {
        // The counts stay consistent even if a holder panicked: every update is one step.
        self.open.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// A slot for a connection from `ip`, or why there is none.
    pub fn admit(self: &Arc<Self>, ip: IpAddr) -> Result<Permit, Refused> {
        let source = Source::from(ip);
        let mut open = self.lock();
        if open.total >= self.total {
            return Err(Refused::Full(open.total));
        }
        let n = open.by_source.entry(source).or_insert(0);
        if *n >= self.per_source {
            return Err(Refused::SourceFull(*n));
        }
        *n += 1;
        open.total += 1;
        drop(open);
        Ok(Permit {
            _slot: Arc::new(Slot {
                admission: self.clone(),
                source,
            }),
        })
    }

    /// Connections open now.
    pub fn open(&self) -> usize {
        self.lock().total
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ip(s: &str) -> IpAddr {
        s.parse().unwrap()
    }

    #[test]
    fn one_source_cannot_take_every_slot() {
        let a = Admission::new(10, 3);
        let held: Vec<Permit> = (0..3).map(|_| a.admit(ip("127.0.0.2")).unwrap()).collect();
        assert_eq!(
            a.admit(ip("127.0.0.2")).unwrap_err(),
            Refused::SourceFull(3)
        );
        let other = a.admit(ip("127.0.0.1")).unwrap();
        assert_eq!(a.open(), 4);
        drop(held);
        assert_eq!(a.open(), 1);
        a.admit(ip("127.0.0.2")).unwrap();
        drop(other);
    }

    #[test]
    fn the_total_is_capped_and_slots_come_back_when_the_last_clone_drops() {
        let a = Admission::new(2, 2);
        let p = a.admit(ip("10.0.0.1")).unwrap();
        let q = a.admit(ip("10.0.0.2")).unwrap();
        assert_eq!(a.admit(ip("10.0.0.3")).unwrap_err(), Refused::Full(2));
        let p2 = p.clone();
        drop(p);
        assert!(
            a.admit(ip("10.0.0.3")).is_err(),
            "a clone still holds the slot"
        );
        drop(p2);
        a.admit(ip("10.0.0.3")).unwrap();
        drop(q);
    }

    #[test]
    fn ipv6_sources_are_their_slash_64_and_mapped_v4_is_v4() {
        assert_eq!(
            Source::from(ip("2001:db8::1")),
            Source::from(ip("2001:db8::ffff:1234"))
        );
        assert_ne!(
            Source::from(ip("2001:db8::1")),
            Source::from(ip("2001:db8:0:1::1"))
        );
        assert_eq!(
            Source::from(ip("::ffff:127.0.0.2")),
            Source::from(ip("127.0.0.2"))
        );
    }
}
