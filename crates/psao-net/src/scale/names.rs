//! The NATS subjects, stream and bucket of one scene.

/// A scene name reduced to a NATS subject token: characters outside `[A-Za-z0-9_-]` become
/// `_`; empty names become `scene`.
pub fn scene_id(name: &str) -> String {
    let id: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect();
    if id.is_empty() {
        "scene".into()
    } else {
        id
    }
}

/// Where one scene's messages go.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Names {
    id: String,
}

impl Names {
    /// The names for scene `name` (see [`scene_id`]).
    pub fn new(name: &str) -> Self {
        Self { id: scene_id(name) }
    }

    /// Record batches of partition `k`.
    pub fn records(&self, k: u32) -> String {
        format!("psao.{}.rec.{k}", self.id)
    }

    /// The partition whose record batches `subject` carries (`None`: no records subject of
    /// this scene).
    pub fn records_partition(&self, subject: &str) -> Option<u32> {
        subject
            .strip_prefix(&format!("psao.{}.rec.", self.id))
            .and_then(|k| k.parse().ok())
    }

    /// Every partition's record batches.
    pub fn records_wildcard(&self) -> String {
        format!("psao.{}.rec.*", self.id)
    }

    /// Snapshot chunk `c` of partition `k`.
    pub fn snapshot(&self, k: u32, c: u32) -> String {
        format!("psao.{}.snap.{k}.{c}", self.id)
    }

    /// Snapshot marks of partition `k` (see [`super::wire::SnapshotMark`]).
    pub fn snapshot_mark(&self, k: u32) -> String {
        format!("psao.{}.snap.{k}.mark", self.id)
    }

    /// Every snapshot chunk and mark.
    pub fn snapshots_wildcard(&self) -> String {
        format!("psao.{}.snap.>", self.id)
    }

    /// View sets of edge `edge`.
    pub fn views(&self, edge: &str) -> String {
        format!("psao.{}.views.{}", self.id, scene_id(edge))
    }

    /// Every edge's view sets.
    pub fn views_wildcard(&self) -> String {
        format!("psao.{}.views.*", self.id)
    }

    /// The JetStream stream keeping the record batches.
    pub fn stream(&self) -> String {
        format!("PSAO_{}", self.id)
    }

    /// The JetStream stream keeping the latest snapshot chunks.
    pub fn snapshot_stream(&self) -> String {
        format!("PSAO_{}_SNAP", self.id)
    }

    /// The key-value bucket of the partition leases and the clock's epoch.
    pub fn leases(&self) -> String {
        format!("psao_{}_leases", self.id)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_valid_subject_tokens() {
        assert_eq!(scene_id("Sponza.glb"), "Sponza_glb");
        assert_eq!(scene_id("a b*>c"), "a_b__c");
        assert_eq!(scene_id(""), "scene");
        let n = Names::new("room.obj");
        assert_eq!(n.records(3), "psao.room_obj.rec.3");
        assert_eq!(n.views("edge 1"), "psao.room_obj.views.edge_1");
        assert_eq!(n.stream(), "PSAO_room_obj");
        assert_eq!(n.snapshot(2, 5), "psao.room_obj.snap.2.5");
        assert_eq!(n.snapshot_mark(2), "psao.room_obj.snap.2.mark");
        assert_eq!(n.snapshot_stream(), "PSAO_room_obj_SNAP");
        assert_eq!(n.leases(), "psao_room_obj_leases");
    }
}
