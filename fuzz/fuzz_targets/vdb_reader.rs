//! Fuzzes the OpenVDB reader: any bytes give a grid or a typed error, never a panic, an
//! abort or a huge allocation; a small grid read builds into a volume.
#![no_main]

use libfuzzer_sys::fuzz_target;
use psao_volume::{vdb, BrickFormat, Volume};

/// Grids with at most this many 8³ cells are also built into a volume.
const BUILD_CELLS: u64 = 4096;

fuzz_target!(|data: &[u8]| {
    if let Ok(grid) = vdb::read_vdb_bytes(data, "fuzz", None) {
        let cells = grid.leaves.len() as u64 + grid.tiles.iter().map(|t| t.cells()).sum::<u64>();
        if cells <= BUILD_CELLS {
            let _ = Volume::build(&[grid], BrickFormat::F32, None);
        }
    }
});
