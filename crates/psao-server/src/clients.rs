//! Per-client bookkeeping: what each client has already received.

use std::collections::BTreeMap;

/// Identifies a client of a [`crate::Server`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct ClientId(pub u32);

/// What one client has.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ClientState {
    /// Server frame of the last update sent (changes stamped later are new to the client).
    pub last_sent: u64,
    /// The next update must be a full snapshot.
    pub needs_snapshot: bool,
}

/// The connected clients.
#[derive(Default)]
pub(crate) struct Clients {
    next: u32,
    states: BTreeMap<u32, ClientState>,
}

impl Clients {
    /// Register a client; its first update is a snapshot.
    pub fn add(&mut self) -> ClientId {
        let id = self.next;
        self.next = self.next.wrapping_add(1);
        self.states.insert(
            id,
            ClientState {
                last_sent: 0,
                needs_snapshot: true,
            },
        );
        ClientId(id)
    }

    /// Forget a client.
    pub fn remove(&mut self, id: ClientId) {
        self.states.remove(&id.0);
    }

    /// State of a client.
    pub fn get(&self, id: ClientId) -> Option<&ClientState> {
        self.states.get(&id.0)
    }

    /// Mutable state of a client.
    pub fn get_mut(&mut self, id: ClientId) -> Option<&mut ClientState> {
        self.states.get_mut(&id.0)
    }

    /// Number of clients.
    pub fn len(&self) -> usize {
        self.states.len()
    }
}
