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

/// The parts of `instances` plus the skin bindings (`skins` bytes); irradiance
/// accumulators only when the server computes lighting.
pub(crate) fn memory_parts(instances: &[InstanceState], skins: u64) -> Vec<MemoryPart> {
    let sum = |f: &dyn Fn(&InstanceState) -> u64| instances.iter().map(f).sum::<u64>();
    let part = |name, bytes| MemoryPart { name, bytes };
    let lit = instances.iter().any(|i| i.points.light.is_some());
    let light = lit.then(|| {
        part(
            "irradiance accumulators and published records",
            sum(&|i| {
                i.points.light.as_ref().map_or(0, |l| l.heap_bytes()) + vec_bytes(&i.light_cells)
            }),
        )
    });
    let mut parts = vec![
        part(
            "positions and normals",
            sum(&|i| vec_bytes(&i.points.position) + vec_bytes(&i.points.normal)),
        ),
        part(
            "AO accumulators",
            sum(&|i| vec_bytes(&i.points.sum) + vec_bytes(&i.points.count)),
        ),
        part(
            "published records, stored and published-here bits",
            sum(&|i| {
                vec_bytes(&i.points.published)
                    + i.points.stored.heap_bytes()
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
    ];
    parts.extend(light);
    parts
}

#[cfg(test)]
mod tests {
    use std::alloc::{GlobalAlloc, Layout, System};
    use std::cell::Cell;

    use glam::{Affine3A, Vec3};
    use psao_points::{generate_instance_points, GenerateParams};
    use psao_scene::{Material, Mesh};

    use super::*;
    use crate::publish::{apply, republish};
    use crate::Thresholds;

    /// The system allocator, counting per thread the bytes allocated and not yet freed.
    struct Counting;

    thread_local! {
        static LIVE: Cell<i64> = const { Cell::new(0) };
    }

    fn live() -> i64 {
        LIVE.with(Cell::get)
    }

    unsafe impl GlobalAlloc for Counting {
        unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
            LIVE.with(|c| c.set(c.get() + layout.size() as i64));
            // SAFETY: forwarded unchanged.
            unsafe { System.alloc(layout) }
        }

        unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
            LIVE.with(|c| c.set(c.get() - layout.size() as i64));
            // SAFETY: forwarded unchanged.
            unsafe { System.dealloc(ptr, layout) }
        }
    }

    #[global_allocator]
    static COUNTING: Counting = Counting;

    /// A folded strip of quads: points on three planes, many cells.
    fn points() -> psao_points::InstancePoints {
        let mut mesh = Mesh::default();
        for k in 0..3u32 {
            let y = k as f32 * 0.7;
            mesh.positions.extend([
                Vec3::new(0.0, y, 0.0),
                Vec3::new(2.0, y, 0.0),
                Vec3::new(2.0, y + 0.3, 1.5),
                Vec3::new(0.0, y + 0.3, 1.5),
            ]);
            let b = 4 * k;
            mesh.indices.extend([[b, b + 2, b + 1], [b, b + 3, b + 2]]);
        }
        let params = GenerateParams {
            density: 512.0,
            seed: 3,
        };
        let transform = Affine3A::IDENTITY;
        generate_instance_points(&mesh, &Material::default(), &transform, &params, None).unwrap()
    }

    /// Build an instance, publish every stored point, move some to other cells and publish
    /// again: the state with every structure in use.
    fn busy_state(points: &psao_points::InstancePoints) -> InstanceState {
        let mut s = InstanceState::new(points, Affine3A::IDENTITY, 0, 7, false, 64).unwrap();
        let t = Thresholds::default();
        let n = s.points.position.len();
        for i in 0..n {
            s.points.count[i] = 4;
            s.points.sum[i] = (i % 5) as f32;
        }
        let publish = |s: &mut InstanceState, frame| {
            let updates: Vec<(u32, u32)> = (0..n)
                .filter_map(|i| republish(s, i, &t).map(|b| (i as u32, b)))
                .collect();
            apply(s, &updates, frame);
        };
        publish(&mut s, 1);
        let shift = Vec3::X * s.layout().cell_size * 1.5;
        for i in (0..n).step_by(3) {
            let old = s.slot_of(i);
            let p = s.points.position[i] + shift;
            s.points.position[i] = p;
            s.rehome(i, old, p);
        }
        publish(&mut s, 2);
        s
    }

    #[test]
    fn parts_add_up_to_what_an_instance_holds() {
        let points = points();
        // One worker thread, so every allocation of the state is counted on it.
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let (held, parts) = pool.install(|| {
            drop(busy_state(&points)); // warm up the pool's own allocations
            let before = live();
            let s = busy_state(&points);
            let held = live() - before;
            let parts = memory_parts(std::slice::from_ref(&s), 0);
            (held, parts)
        });
        let total: u64 = parts.iter().map(|p| p.bytes).sum();
        assert!(total > 0 && parts.iter().filter(|p| p.bytes > 0).count() >= 6);
        assert_eq!(total as i64, held, "{parts:?}");
    }
}
