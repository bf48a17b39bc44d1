//! What the server's structures hold in memory, by kind: the per-structure figures behind
//! `psao bench step`'s bytes per point.

use psao_points::vec_bytes;

use crate::instance::InstanceState;

/// Heap bytes of one kind of server structure, summed over the instances.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MemoryPart {
    /// What the bytes hold.
    pub name: &'static str,
    /// Allocated heap bytes.
    pub bytes: u64,
}

/// The parts of `instances` plus the skin bindings (`skins` bytes).
pub(crate) fn memory_parts(instances: &[InstanceState], skins: u64) -> Vec<MemoryPart> {
    let sum = |f: &dyn Fn(&InstanceState) -> u64| instances.iter().map(f).sum::<u64>();
    let part = |name, bytes| MemoryPart { name, bytes };
    vec![
        part(
            "positions and normals",
            sum(&|i| vec_bytes(&i.points.position) + vec_bytes(&i.points.normal)),
        ),
        part(
            "AO accumulators",
            sum(&|i| vec_bytes(&i.points.sum) + vec_bytes(&i.points.count)),
        ),
        part(
            "published records and slots",
            sum(&|i| {
                vec_bytes(&i.points.slot)
                    + vec_bytes(&i.points.published)
                    + i.points.published_here.heap_bytes()
            }),
        ),
        part("allocation grid", sum(&|i| i.alloc.heap_bytes())),
        part("published grid", sum(&|i| i.grid.heap_bytes())),
        part(
            "change stamps and logs",
            sum(&|i| {
                vec_bytes(&i.bucket_stamp)
                    + vec_bytes(&i.cell_stamp)
                    + i.changes.heap_bytes()
                    + vec_bytes(&i.pending_cells)
                    + vec_bytes(&i.pending_buckets)
            }),
        ),
        part(
            "culling blocks and summaries",
            sum(&|i| i.blocks.heap_bytes() + i.summaries.heap_bytes()),
        ),
        part("skin bindings", skins),
    ]
}
