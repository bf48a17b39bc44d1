//! What an applied update changed, as the u32 words the viewer's textures (web/src/grids.ts)
//! are patched from, read in place from wasm memory. Records follow each other:
//!
//! * [`RESET`]: the update was a snapshot; forget everything (the records after it hold every
//!   bucket with entries and every cell slot with a non-zero point word or record);
//! * [`BUCKET`], instance, bucket, n, then n × (key low, key high, cell slot): a bucket's used
//!   entries in order (n = 0: now empty);
//! * [`CELL`], instance, slot, then the cell's [`CELL_POINTS`] point words (its valid points
//!   first, in order, as updates carry them), then its [`CELL_POINTS`] irradiance records
//!   (RGB9E5, `psao_points::irradiance`; zeros where the server sent none, as the client
//!   state keeps them).

use psao_client::{CellLights, ClientState};
use psao_delta::Update;
use psao_points::{Bucket, Cell, MirrorGrid, CELL_POINTS};

/// Record tag: a bucket's entries.
pub const BUCKET: u32 = 0;
/// Record tag: a cell slot's points.
pub const CELL: u32 = 1;
/// Record tag: everything before is void (a snapshot).
pub const RESET: u32 = 2;

/// The records of `update`, just applied to `state`, into `out` (cleared first).
pub fn write_changes(state: &ClientState, update: &Update, out: &mut Vec<u32>) {
    out.clear();
    if update.snapshot {
        out.push(RESET);
        for instance in 0..state.instance_count() {
            if let Some(grid) = state.grid(instance) {
                write_grid(state, instance, grid, out);
            }
        }
        return;
    }
    for delta in &update.instances {
        let Some(grid) = state.grid(delta.instance as usize) else {
            continue;
        };
        for (bucket, _) in &delta.buckets {
            write_bucket(delta.instance, *bucket, &grid.bucket(*bucket as usize), out);
        }
        for (slot, _) in &delta.cells {
            let lights = state.cell_lights(delta.instance as usize, *slot);
            write_cell(delta.instance, *slot, &grid.cell(*slot), &lights, out);
        }
    }
}

/// Every bucket with entries and every cell slot with a non-zero point word or record of
/// `instance`'s `grid`.
fn write_grid(state: &ClientState, instance: usize, grid: &MirrorGrid, out: &mut Vec<u32>) {
    let id = instance as u32;
    for (index, bucket) in grid.buckets().enumerate() {
        if bucket.entries.iter().any(|e| e.key != 0) {
            write_bucket(id, index as u32, &bucket, out);
        }
    }
    for (slot, cell) in grid.cells().enumerate() {
        let lights = state.cell_lights(instance, slot as u32);
        if cell.points.iter().chain(&lights).any(|&w| w != 0) {
            write_cell(id, slot as u32, &cell, &lights, out);
        }
    }
}

fn write_bucket(instance: u32, index: u32, bucket: &Bucket, out: &mut Vec<u32>) {
    let used = || bucket.entries.iter().filter(|e| e.key != 0);
    out.extend([BUCKET, instance, index, used().count() as u32]);
    for e in used() {
        out.extend([e.key as u32, (e.key >> 32) as u32, e.slot]);
    }
}

fn write_cell(instance: u32, slot: u32, cell: &Cell, lights: &CellLights, out: &mut Vec<u32>) {
    out.extend([CELL, instance, slot]);
    out.extend_from_slice(&cell.points[..CELL_POINTS]);
    out.extend_from_slice(lights);
}
