//! Thresholded publishing into the authoritative grids (DESIGN §3 "Server update").

use psao_points::pack::{unpack_ao, unpack_normal, POSITION_STEPS};
use psao_points::{Bucket, Cell, CELL_POINTS};
use rayon::prelude::*;

use crate::instance::InstanceState;
use crate::Thresholds;

/// The record point `i` should be published with now, or `None` when what clients have is
/// still good enough: never-traced and unstored points stay unpublished; a point is
/// (re)published when it was never published, changed cell, or its AO, normal or position
/// moved past the thresholds since it was last published, or (with lighting, then with its
/// published AO record unchanged) its irradiance moved perceptibly from its published record.
/// A point whose accumulation was restarted (invalidated, no samples yet) keeps its published
/// AO and irradiance.
pub(crate) fn republish(inst: &InstanceState, i: usize, t: &Thresholds) -> Option<u32> {
    let p = &inst.points;
    let (count, old) = (p.samples(i), p.published[i]);
    if count == 0 && old == 0 {
        return None;
    }
    let slot = inst.slot_of(i)?;
    let layout = inst.layout();
    let ao = if count > 0 {
        p.sum[i] / count as f32
    } else {
        unpack_ao(old)
    };
    let bits = layout.pack(inst.slot_coord(slot)?, p.position[i], p.normal[i], ao);
    if old == 0 || !p.published_here.get(i) {
        return Some(bits);
    }
    let step = layout.cell_size / POSITION_STEPS as f32;
    let moved = inst
        .slot_coord(slot)
        .map(|c| layout.unpack_position(c, old))
        .is_none_or(|q| (p.position[i] - q).abs().max_element() > t.position_steps * step);
    let changed = (ao - unpack_ao(old)).abs() > t.ao
        || p.normal[i].dot(unpack_normal(old)) < t.normal_cos
        || moved;
    if changed {
        return Some(bits);
    }
    // Only the irradiance moved: the AO record stays as published.
    inst.light_changed(i, t.irradiance).then_some(old)
}

/// Record new published values and refresh the affected cells and buckets of the published
/// grid, stamping what changed with `frame`. `updates` are (point, record) pairs. Returns the
/// number of points published.
pub(crate) fn apply(inst: &mut InstanceState, updates: &[(u32, u32)], frame: u64) -> usize {
    let mut dirty_cells = std::mem::take(&mut inst.pending_cells);
    // The irradiance records (pooled over the neighbours) first, in parallel.
    let view: &InstanceState = inst;
    let light_records: Vec<Option<u32>> = updates
        .par_iter()
        .map(|&(i, _)| view.light_record(i as usize))
        .collect();
    for (&(i, bits), light_record) in updates.iter().zip(light_records) {
        let i = i as usize;
        // Only stored points are republished.
        dirty_cells.extend(inst.slot_of(i));
        let p = &mut inst.points;
        // A point that changed cell had its flag cleared and its old cell queued (rehome).
        p.published_here.set(i, true);
        p.published[i] = bits;
        if let (Some(light), Some(record)) = (&mut p.light, light_record) {
            light.published[i] = record;
        }
    }
    dirty_cells.par_sort_unstable();
    dirty_cells.dedup();
    let mut dirty_buckets = std::mem::take(&mut inst.pending_buckets);
    // The new contents are read in parallel, then stored where they changed.
    let view: &InstanceState = inst;
    type Content = (u32, Cell, Option<[u32; CELL_POINTS]>);
    let cells: Vec<Content> = dirty_cells
        .par_iter()
        .map(|&slot| {
            let light = view.published_light_cell(slot);
            (slot, view.published_cell(slot), light)
        })
        .collect();
    for (slot, cell, light) in cells {
        let light_changed = light.is_some_and(|l| l != inst.light_cell(slot));
        if inst.grid.cell(slot) != cell || light_changed {
            inst.publish_cell(slot, cell, frame);
        }
        if let (true, Some(light)) = (light_changed, light) {
            let s = slot as usize;
            if inst.light_cells.len() <= s {
                inst.light_cells.resize(s + 1, [0; CELL_POINTS]);
            }
            inst.light_cells[s] = light;
        }
        dirty_buckets.push(inst.slot_bucket(slot));
    }
    dirty_buckets.par_sort_unstable();
    dirty_buckets.dedup();
    let view: &InstanceState = inst;
    let buckets: Vec<(usize, Bucket)> = dirty_buckets
        .par_iter()
        .map(|&b| (b, view.published_bucket(b)))
        .filter(|(b, bucket)| view.grid.bucket(*b) != *bucket)
        .collect();
    for (b, bucket) in buckets {
        inst.publish_bucket(b, bucket, frame);
    }
    updates.len()
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::instance::NONE;
    use glam::{Affine3A, Quat, Vec3};
    use psao_points::{generate_instance_points, GenerateParams};
    use psao_scene::{Material, Mesh};

    /// A 1 m floor quad's points at 256 per m² (seed 1), identity transform.
    pub(crate) fn state() -> InstanceState {
        let mesh = Mesh {
            positions: vec![
                Vec3::ZERO,
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(1.0, 0.0, 1.0),
                Vec3::new(0.0, 0.0, 1.0),
            ],
            indices: vec![[0, 2, 1], [0, 3, 2]],
            ..Default::default()
        };
        let params = GenerateParams {
            density: 256.0,
            seed: 1,
        };
        let points = generate_instance_points(
            &mesh,
            &Material::default(),
            &Affine3A::IDENTITY,
            &params,
            None,
        )
        .unwrap();
        InstanceState::new(&points, Affine3A::IDENTITY, 0, 0, false, 256).unwrap()
    }

    /// A stored point whose x lies in the middle of its cell (room to move 4 steps).
    fn central_point(s: &InstanceState) -> usize {
        let l = s.layout();
        (0..s.points.position.len())
            .find(|&i| {
                let f = l.grid_coords(s.points.position[i]).x.fract();
                s.points.stored.get(i) && (0.35..0.65).contains(&f)
            })
            .unwrap()
    }

    #[test]
    fn thresholds_decide_republishing() {
        let mut s = state();
        let t = Thresholds::default();
        let i = central_point(&s);
        assert_eq!(republish(&s, i, &t), None, "never traced");
        s.points.count[i] = 16;
        s.points.sum[i] = 8.0;
        let bits = republish(&s, i, &t).expect("first publish");
        assert_eq!(apply(&mut s, &[(i as u32, bits)], 1), 1);
        assert_eq!(republish(&s, i, &t), None, "unchanged");
        s.points.sum[i] = 16.0 * (0.5 + 7.0 / 255.0);
        assert_eq!(republish(&s, i, &t), None, "AO change below 8/255");
        s.points.sum[i] = 16.0 * (0.5 + 9.0 / 255.0);
        assert!(republish(&s, i, &t).is_some(), "AO change above 8/255");
        s.points.sum[i] = 8.0;

        let n = s.points.normal[i];
        s.points.normal[i] = Quat::from_rotation_x(30f32.to_radians()) * n;
        assert_eq!(republish(&s, i, &t), None, "normal turned 30°");
        s.points.normal[i] = Quat::from_rotation_x(60f32.to_radians()) * n;
        assert!(republish(&s, i, &t).is_some(), "normal turned 60°");
        s.points.normal[i] = n;

        let p = s.points.position[i];
        let step = s.layout().cell_size / 32.0;
        s.points.position[i] = p + Vec3::X * 2.0 * step;
        assert_eq!(republish(&s, i, &t), None, "moved 2 steps");
        s.points.position[i] = p + Vec3::X * 4.0 * step;
        assert!(republish(&s, i, &t).is_some(), "moved 4 steps");
        s.points.position[i] = p;

        // What rehoming into another cell does to the flag.
        s.points.published_here.set(i, false);
        assert!(republish(&s, i, &t).is_some(), "changed cell");
        s.points.published_here.set(i, true);
        assert_eq!(republish(&s, i, &t), None);
    }

    #[test]
    fn apply_keeps_cells_and_buckets_compact_and_stamps_changes() {
        let mut s = state();
        let t = Thresholds::default();
        // Publish the second member of a cell with at least two, then the first.
        let slot = (0..s.alloc.slot_count())
            .find(|&c| s.alloc.members(c as u32)[1] != NONE)
            .unwrap();
        let members = s.alloc.members(slot as u32);
        let [a, b] = [members[0], members[1]].map(|m| m as usize);
        for &m in &[a, b] {
            s.points.count[m] = 4;
            s.points.sum[m] = 2.0;
        }
        let bits_b = republish(&s, b, &t).unwrap();
        apply(&mut s, &[(b as u32, bits_b)], 1);
        let bucket = s.slot_bucket(slot as u32);
        assert_eq!(s.grid.cell(slot as u32).points[..2], [bits_b, 0]);
        assert_eq!(s.grid.bucket(bucket).len(), 1);
        assert_eq!((s.cell_stamp[slot], s.bucket_stamp[bucket]), (1, 1));

        let bits_a = republish(&s, a, &t).unwrap();
        apply(&mut s, &[(a as u32, bits_a)], 2);
        // Members keep their allocation order once both are published.
        assert_eq!(s.grid.cell(slot as u32).points[..3], [bits_a, bits_b, 0]);
        assert_eq!(s.cell_stamp[slot], 2);
        assert_eq!(s.bucket_stamp[bucket], 1, "bucket unchanged");
        assert_eq!(s.max_stamp, 2);
        // Unpublished cells stay out of the published grid.
        let published_slots = s.grid.buckets().map(|b| b.len()).sum::<usize>();
        assert_eq!(published_slots, 1);
    }
}
