//! The client's mirror of the server state: one point grid per instance, built only from
//! applied updates, plus the instance transforms that came with them (DESIGN §3 "Client
//! reconstruction", §4).

use glam::{Affine3A, Vec3};
use psao_delta::{InstanceDelta, InstanceInfo, Update};
use psao_points::{GridLayout, InstanceGrid, MAX_DIM};

use crate::error::ClientError;
use crate::hash::state_hash_of;

/// What the client knows: per instance a grid mirror (or `None` when the table's layout was
/// unusable) and the transform of the latest update that carried one.
#[derive(Clone, Debug)]
pub struct ClientState {
    grids: Vec<Option<InstanceGrid>>,
    transforms: Vec<Option<Affine3A>>,
    last_frame: Option<u64>,
}

impl ClientState {
    /// An empty mirror for the server's instance table (from the welcome): every grid empty,
    /// no transforms, no frame. Instances whose layout is unusable (see
    /// [`layout_is_usable`]) get no grid: they reconstruct as unoccluded and updates naming
    /// them are rejected. Memory is proportional to the layouts' bucket counts, so callers
    /// receiving the table from the network bound those first.
    pub fn new(table: &[InstanceInfo]) -> Self {
        Self {
            grids: table
                .iter()
                .map(|info| layout_is_usable(&info.layout).then(|| InstanceGrid::new(info.layout)))
                .collect(),
            transforms: vec![None; table.len()],
            last_frame: None,
        }
    }

    /// Apply one server update. The whole update is validated first (instance indices,
    /// finite transforms, bucket indices, bucket entries, cell slots); on error nothing
    /// changes. A snapshot first resets every grid to empty and forgets every transform.
    /// Transforms not named by a delta keep their previous value.
    pub fn apply(&mut self, update: &Update) -> Result<(), ClientError> {
        self.validate(update)?;
        if update.snapshot {
            for grid in self.grids.iter_mut().flatten() {
                *grid = InstanceGrid::new(*grid.layout());
            }
            self.transforms.fill(None);
        }
        for &(instance, transform) in &update.transforms {
            self.transforms[instance as usize] = Some(transform);
        }
        for delta in &update.instances {
            let instance = delta.instance;
            let grid = self.grids[instance as usize]
                .as_mut()
                .ok_or(ClientError::NoGrid { instance })?;
            let fail = |source| ClientError::Grid { instance, source };
            for (bucket, content) in &delta.buckets {
                grid.set_bucket(*bucket as usize, *content).map_err(fail)?;
            }
            for (slot, cell) in &delta.cells {
                grid.set_cell(*slot, *cell).map_err(fail)?;
            }
        }
        self.last_frame = Some(update.frame);
        Ok(())
    }

    /// Checks everything [`Self::apply`] will do, without changing anything.
    fn validate(&self, update: &Update) -> Result<(), ClientError> {
        let count = self.grids.len();
        let in_range = |instance: u32| {
            if (instance as usize) < count {
                Ok(())
            } else {
                Err(ClientError::InstanceOutOfRange { instance, count })
            }
        };
        for (instance, transform) in &update.transforms {
            in_range(*instance)?;
            if !transform_is_finite(transform) {
                return Err(ClientError::NonFiniteTransform {
                    instance: *instance,
                });
            }
        }
        for delta in &update.instances {
            in_range(delta.instance)?;
            let grid = self.grids[delta.instance as usize]
                .as_ref()
                .ok_or(ClientError::NoGrid {
                    instance: delta.instance,
                })?;
            validate_delta(grid.layout(), delta)?;
        }
        Ok(())
    }

    /// Server frame number of the last applied update.
    pub fn last_frame(&self) -> Option<u64> {
        self.last_frame
    }

    /// Number of instances in the table.
    pub fn instance_count(&self) -> usize {
        self.grids.len()
    }

    /// Fingerprint of all buckets and cells, instance by instance (see [`state_hash_of`]);
    /// equal to the server's when the mirror is exact.
    pub fn state_hash(&self) -> u64 {
        state_hash_of(self.grids.iter().map(Option::as_ref))
    }

    /// Local-to-world transform of `instance` from the latest update carrying one.
    pub fn transform(&self, instance: usize) -> Option<Affine3A> {
        self.transforms.get(instance).copied().flatten()
    }

    /// The grid mirror of `instance` (`None` out of range or when its layout was unusable).
    pub fn grid(&self, instance: usize) -> Option<&InstanceGrid> {
        self.grids.get(instance)?.as_ref()
    }

    /// Heap bytes of the mirror's grids (allocated capacity of their tables).
    pub fn heap_bytes(&self) -> u64 {
        self.grids
            .iter()
            .flatten()
            .map(InstanceGrid::heap_bytes)
            .sum()
    }

    /// Where the mirror's heap bytes go, summed over its grids.
    pub fn memory_parts(&self) -> psao_points::GridMemory {
        let mut parts = psao_points::GridMemory::default();
        for grid in self.grids.iter().flatten() {
            parts += grid.memory_parts();
        }
        parts
    }

    /// Number of valid points over all instances.
    pub fn point_count(&self) -> usize {
        self.grids
            .iter()
            .flatten()
            .map(InstanceGrid::point_count)
            .sum()
    }
}

/// True when a layout can address a grid safely: finite origin, finite positive cell size,
/// finite non-negative Poisson radius, 1..=[`MAX_DIM`] cells per axis with ids that fit in
/// 64 bits, and a power-of-two bucket count.
pub fn layout_is_usable(layout: &GridLayout) -> bool {
    let dims = [layout.dims.x, layout.dims.y, layout.dims.z];
    let ids_fit =
        31u128 * dims.iter().map(|&d| u128::from(d)).product::<u128>() < u128::from(u64::MAX);
    layout.origin.is_finite()
        && layout.cell_size.is_finite()
        && layout.cell_size > 0.0
        && layout.poisson_radius.is_finite()
        && layout.poisson_radius >= 0.0
        && dims.iter().all(|&d| (1..=MAX_DIM).contains(&d))
        && ids_fit
        && layout.bucket_count.is_power_of_two()
}

fn transform_is_finite(t: &Affine3A) -> bool {
    let m = t.matrix3;
    [m.x_axis, m.y_axis, m.z_axis, t.translation]
        .iter()
        .all(|c| Vec3::from(*c).is_finite())
}

/// The checks of [`InstanceGrid::set_bucket`] and [`InstanceGrid::set_cell`], up front.
fn validate_delta(layout: &GridLayout, delta: &InstanceDelta) -> Result<(), ClientError> {
    let instance = delta.instance;
    let max = layout.max_cells();
    let check_slot = |slot: u32| {
        if (slot as usize) < max {
            Ok(())
        } else {
            Err(ClientError::CellSlotOutOfRange {
                instance,
                slot,
                max,
            })
        }
    };
    for (bucket, content) in &delta.buckets {
        if *bucket >= layout.bucket_count {
            return Err(ClientError::BucketOutOfRange {
                instance,
                bucket: *bucket,
                count: layout.bucket_count,
            });
        }
        for e in content.entries.iter().filter(|e| e.key != 0) {
            check_slot(e.slot)?;
            let id = e.key - 1;
            if layout.coord_of_id(id).is_none() || layout.bucket_of(id) != *bucket as usize {
                return Err(ClientError::InvalidBucketEntry {
                    instance,
                    bucket: *bucket,
                    key: e.key,
                });
            }
        }
    }
    for (slot, _) in &delta.cells {
        check_slot(*slot)?;
    }
    Ok(())
}
