//! The serving side of corrective splatting: each client that asked for corrections
//! ([`capabilities::CORRECTIVE`]) and whose server has them ([`Serve::with_corrections`])
//! gets a [`RemoteCorrections`]; its regions and cameras update it, and at every lockstep
//! round (before the round's answer) or server frame its samples are traced within its budget
//! and queued on its connection as a `Samples` message.

use std::sync::Arc;

use psao_wire::{capabilities, encode_frame, Message, RegionsMsg};

use super::{Serve, Session, Simulation};
use crate::corrective::{CorrectionEngine, RemoteCorrections};

/// The server's corrections: the tracing engine and every client's sample budget.
#[derive(Clone)]
pub struct Corrections {
    /// Scene and tracers.
    pub engine: Arc<CorrectionEngine>,
    /// Samples per second per client.
    pub samples_per_second: u32,
}

impl Serve {
    /// Serve corrections to the clients that ask for them.
    pub fn with_corrections(mut self, corrections: Corrections) -> Self {
        self.corrections = Some(corrections);
        self
    }
}

/// A new session's correction state, when both ends want corrections.
pub(super) fn session_state(
    corrections: Option<&Corrections>,
    client_capabilities: u32,
) -> Option<RemoteCorrections> {
    let c = corrections?;
    (client_capabilities & capabilities::CORRECTIVE != 0)
        .then(|| RemoteCorrections::new(c.samples_per_second))
}

/// A client's regions (ignored when the session has no corrections).
pub(super) fn regions(session: &mut Session, msg: &RegionsMsg) {
    match &mut session.corrective {
        Some(c) => c.regions(msg),
        None => tracing::debug!("client {} sent regions without corrections", session.id.0),
    }
}

impl Simulation {
    /// Trace and queue every corrective session's samples for one tick of a clock at `hz`.
    /// Lockstep: only sessions with a camera awaiting its answer, each message carrying that
    /// camera's frame and sent waiting for room; otherwise a session without room skips the
    /// tick (its budget is not carried over).
    pub(super) fn corrections(&mut self, hz: u32, lockstep: bool) {
        let Some(c) = self.corrections.clone() else {
            return;
        };
        for s in self.sessions.values_mut() {
            let Some(state) = &mut s.corrective else {
                continue;
            };
            let budget = state.next_budget(hz);
            if lockstep && s.pending.is_none() || !lockstep && s.out.capacity() == 0 {
                continue;
            }
            let client_frame = if lockstep { s.pending } else { None };
            let Some(msg) = state.trace(&c.engine, budget, client_frame) else {
                continue;
            };
            s.stats.samples += msg.samples.len() as u64;
            let Ok(bytes) = encode_frame(&Message::Samples(msg)) else {
                continue;
            };
            s.stats.bytes += bytes.len() as u64;
            if lockstep {
                let _ = self.rt.block_on(s.out.send(bytes));
            } else {
                let _ = s.out.try_send(bytes);
            }
        }
    }
}
