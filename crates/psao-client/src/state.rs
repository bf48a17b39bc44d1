//! The client's mirror of the server state: one point grid per instance, built only from
//! applied updates, plus the instance transforms that came with them (DESIGN §3 "Client
//! reconstruction", §4). With lighting (DESIGN §12, docs/LIGHTING.md) also the points'
//! irradiance records, stored per cell slot beside the cells.

use glam::{Affine3A, Vec3};
use psao_delta::{InstanceDelta, InstanceInfo, Update};
use psao_points::{GridLayout, MirrorGrid, MirrorMemory, Paged, CELL_POINTS, MAX_DIM};

use crate::error::ClientError;
use crate::hash::lit_state_hash_of;

/// The irradiance records (RGB9E5, `psao_points::irradiance`) of one cell slot's points, in
/// the order of the cell's point records; zeros where none were received.
pub type CellLights = [u32; CELL_POINTS];

/// What the client knows: per instance a grid mirror ([`MirrorGrid`]: stored for what it
/// holds, answering the wire's bucket and slot addresses; `None` when the table's layout was
/// unusable), its irradiance records and the transform of the latest update that carried
/// one.
#[derive(Clone, Debug)]
pub struct ClientState {
    grids: Vec<Option<MirrorGrid>>,
    /// Per instance, the irradiance records by cell slot: paged like the cells, so an AO-only
    /// mirror allocates no page for them.
    lights: Vec<Paged<CellLights>>,
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
                .map(|info| layout_is_usable(&info.layout).then(|| MirrorGrid::new(info.layout)))
                .collect(),
            lights: vec![Paged::new(0); table.len()],
            transforms: vec![None; table.len()],
            last_frame: None,
        }
    }

    /// Apply one server update. The whole update is validated first (instance indices,
    /// finite transforms, bucket indices, bucket entries, cell slots); on error nothing
    /// changes. A snapshot first resets every grid to empty and forgets every transform and
    /// irradiance record. Transforms not named by a delta keep their previous value. A cell
    /// received without irradiance records (an update without lighting) has none (zeros).
    pub fn apply(&mut self, update: &Update) -> Result<(), ClientError> {
        self.validate(update)?;
        if update.snapshot {
            for grid in self.grids.iter_mut().flatten() {
                *grid = MirrorGrid::new(*grid.layout());
            }
            self.lights.fill(Paged::new(0));
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
            let lights = &mut self.lights[instance as usize];
            for (k, (slot, _)) in delta.cells.iter().enumerate() {
                let (slot, records) = (*slot as usize, delta.lights.get(k).copied());
                let records = records.unwrap_or_default();
                // Zeros past the stored slots are implied: an AO-only mirror stores nothing.
                if records != CellLights::default() {
                    lights.grow(slot + 1);
                }
                if slot < lights.len() {
                    lights.set(slot, records);
                }
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

    /// Fingerprint of all buckets, cells and irradiance records, instance by instance (see
    /// [`lit_state_hash_of`]; without records it is [`crate::state_hash_of`]'s); equal to the
    /// server's when the mirror is exact.
    pub fn state_hash(&self) -> u64 {
        lit_state_hash_of(self.grids.iter().map(Option::as_ref), |i, s| {
            self.cell_lights(i, s)
        })
    }

    /// The irradiance records of `instance`'s cell slot `slot` (zeros where none).
    pub fn cell_lights(&self, instance: usize, slot: u32) -> CellLights {
        self.lights
            .get(instance)
            .map_or([0; CELL_POINTS], |l| l.value(slot as usize))
    }

    /// `instance`'s irradiance records by cell slot (`None` out of range).
    #[cfg(feature = "render")]
    pub(crate) fn light_cells(&self, instance: usize) -> Option<&Paged<CellLights>> {
        self.lights.get(instance)
    }

    /// Whether any irradiance record was received since the last snapshot (the server has
    /// lighting on).
    pub fn has_lights(&self) -> bool {
        self.lights.iter().any(|l| l.page_bytes() > 0)
    }

    /// Local-to-world transform of `instance` from the latest update carrying one.
    pub fn transform(&self, instance: usize) -> Option<Affine3A> {
        self.transforms.get(instance).copied().flatten()
    }

    /// The grid mirror of `instance` (`None` out of range or when its layout was unusable).
    pub fn grid(&self, instance: usize) -> Option<&MirrorGrid> {
        self.grids.get(instance)?.as_ref()
    }

    /// Heap bytes of the mirror's grids (allocated capacity of their tables).
    pub fn heap_bytes(&self) -> u64 {
        let grids: u64 = self
            .grids
            .iter()
            .flatten()
            .map(MirrorGrid::heap_bytes)
            .sum();
        grids + self.lights.iter().map(Paged::heap_bytes).sum::<u64>()
    }

    /// Where the mirror's heap bytes go, summed over its grids.
    pub fn memory_parts(&self) -> MirrorMemory {
        let mut parts = MirrorMemory::default();
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
            .map(MirrorGrid::point_count)
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

/// The checks of [`MirrorGrid::set_bucket`] and [`MirrorGrid::set_cell`], up front.
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
        let used = || content.entries.iter().filter(|e| e.key != 0);
        for (k, e) in used().enumerate() {
            check_slot(e.slot)?;
            let id = e.key - 1;
            let duplicate = used().take(k).any(|d| d.key == e.key);
            if duplicate
                || layout.coord_of_id(id).is_none()
                || layout.bucket_of(id) != *bucket as usize
            {
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
    if !delta.lights.is_empty() && delta.lights.len() != delta.cells.len() {
        return Err(ClientError::LightsMismatch {
            instance,
            lights: delta.lights.len(),
            cells: delta.cells.len(),
        });
    }
    Ok(())
}
