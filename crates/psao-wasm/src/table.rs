//! The instance table as the TypeScript hands it over: [`TABLE_WORDS`] numbers (f64) per
//! instance, in the order of the welcome's `InstanceEntry` fields.

use glam::{UVec3, Vec3};
use psao_delta::{GridLayout, InstanceInfo};

/// Numbers per instance: origin x, y, z, cell size, dims x, y, z, the layout's Poisson
/// radius, bucket count, the instance's Poisson radius, point count.
pub const TABLE_WORDS: usize = 11;

/// The table of `words` (a trailing partial entry is ignored). A count that is not a u32
/// (negative, fractional, too large, NaN) becomes 0, which makes the layout unusable (that
/// instance gets no grid) rather than a different usable one.
pub fn table_of(words: &[f64]) -> Vec<InstanceInfo> {
    words
        .chunks_exact(TABLE_WORDS)
        .map(|w| InstanceInfo {
            layout: GridLayout {
                origin: Vec3::new(w[0] as f32, w[1] as f32, w[2] as f32),
                cell_size: w[3] as f32,
                dims: UVec3::new(count(w[4]), count(w[5]), count(w[6])),
                poisson_radius: w[7] as f32,
                bucket_count: count(w[8]),
            },
            poisson_radius: w[9] as f32,
            point_count: count(w[10]),
        })
        .collect()
}

/// `x` when it is a u32, else 0.
fn count(x: f64) -> u32 {
    if x >= 0.0 && x <= f64::from(u32::MAX) && x.fract() == 0.0 {
        x as u32
    } else {
        0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn entries_map_field_by_field_and_bad_counts_become_zero() {
        let words = [
            1.0,
            2.0,
            3.0,
            0.5,
            4.0,
            5.0,
            6.0,
            0.1,
            64.0,
            0.2,
            99.0, // a good entry
            0.0,
            0.0,
            0.0,
            1.0,
            -1.0,
            2.5,
            f64::NAN,
            0.1,
            1e12,
            0.2,
            7.0, // bad counts
            9.0, // a partial entry
        ];
        let table = table_of(&words);
        assert_eq!(table.len(), 2);
        let l = &table[0].layout;
        assert_eq!(l.origin, Vec3::new(1.0, 2.0, 3.0));
        assert_eq!(
            (l.cell_size, l.dims, l.bucket_count),
            (0.5, UVec3::new(4, 5, 6), 64)
        );
        assert_eq!((l.poisson_radius, table[0].poisson_radius), (0.1, 0.2));
        assert_eq!(table[0].point_count, 99);
        assert_eq!(table[1].layout.dims, UVec3::ZERO);
        assert_eq!(table[1].layout.bucket_count, 0);
    }
}
