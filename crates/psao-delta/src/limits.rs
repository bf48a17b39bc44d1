//! What a client accepts from a server's instance table, and how many bytes one update for
//! that table may decode to: shared by psao-net's clients and the browser viewer's decoder
//! (crates/psao-wasm).

use crate::InstanceInfo;

/// Most hash buckets over all instances a client accepts from a welcome (128 bytes each:
/// 1 GiB of grid tables). The decode limit of the largest table accepted stays under the
/// codecs' ceiling ([`crate::MAX_DECODE_LIMIT`]; tested in psao-net), so every accepted table
/// gets the whole limit it needs.
pub const MAX_TOTAL_BUCKETS: u64 = 1 << 23;

/// Hash buckets over all instances of `table` (compare with [`MAX_TOTAL_BUCKETS`]).
pub fn total_buckets(table: &[InstanceInfo]) -> u64 {
    table.iter().map(|i| u64::from(i.layout.bucket_count)).sum()
}

/// Most bytes one decoded update can legitimately take for this table (a snapshot of every
/// bucket and every addressable cell, with generous per-record overhead).
pub fn decode_limit(table: &[InstanceInfo]) -> u64 {
    let per_instance: u64 = table
        .iter()
        .map(|i| {
            let cells = i.layout.max_cells() as u64;
            64 + u64::from(i.layout.bucket_count) * 110 + cells * 40
        })
        .sum();
    4096 + per_instance
}
