//! The whole resident size of a serving process, item by item (`psao bench step`): every
//! structure that counts its heap bytes, the tracer's own count, the executable's pages, the
//! heap in use that no structure claims, and what is left (the allocator's slack), so that
//! the items add up to the resident size exactly.

use std::collections::HashSet;
use std::sync::Arc;

use psao_net::process_memory::{MallocStats, Resident};
use psao_scene::{Environment, Scene};

/// One item of the resident size.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Item {
    /// What it holds.
    pub name: String,
    /// Bytes.
    pub bytes: u64,
}

/// Heap bytes of `scene`: meshes (positions, normals, texture coordinates, indices, skin
/// weights), alpha textures (each shared image once), the environment map's pixels, nodes,
/// skins and animation keys (allocated capacity; names and other small parts left out).
pub fn scene_heap_bytes(scene: &Scene) -> u64 {
    fn bytes<T>(v: &Vec<T>) -> u64 {
        (v.capacity() * std::mem::size_of::<T>()) as u64
    }
    let meshes: u64 = scene
        .meshes
        .iter()
        .map(|m| {
            bytes(&m.positions)
                + bytes(&m.normals)
                + bytes(&m.uvs)
                + bytes(&m.indices)
                + bytes(&m.joints)
                + bytes(&m.weights)
        })
        .sum();
    let mut images = HashSet::new();
    let textures: u64 = scene
        .materials
        .iter()
        .filter_map(|m| m.alpha_texture.as_ref())
        .filter(|t| images.insert(Arc::as_ptr(&t.image)))
        .map(|t| u64::from(t.image.width()) * u64::from(t.image.height()))
        .sum();
    let environment = match &scene.environment {
        Environment::Map { map, .. } => std::mem::size_of_val(map.pixels()) as u64,
        Environment::Constant(_) => 0,
    };
    let animation: u64 = scene
        .animations
        .iter()
        .flat_map(|a| &a.channels)
        .map(|c| bytes(&c.times) + bytes(&c.values))
        .sum();
    let skins: u64 = scene
        .skins
        .iter()
        .map(|s| bytes(&s.joints) + bytes(&s.inverse_bind))
        .sum();
    meshes
        + textures
        + environment
        + animation
        + skins
        + bytes(&scene.meshes)
        + bytes(&scene.materials)
        + bytes(&scene.nodes)
        + bytes(&scene.instances)
}

/// The whole resident size as items that add up to `resident.bytes`:
/// * the executable and libraries (file-backed resident pages);
/// * `heap`: structures counting their own heap bytes (allocated through malloc);
/// * `tracer`: the tracer's own count of its memory, of which `tracer_in_heap` bytes went
///   through malloc (Embree's vertex and index buffers; its BVH nodes are mapped apart);
/// * the heap in use no structure claims (malloc's bytes in use minus the above: small
///   structures, the C libraries' buffers), when malloc can tell (`malloc`);
/// * the remainder, the allocator's slack: resident pages of freed blocks, arenas' spare
///   room, thread stacks.
pub fn itemise(
    resident: Resident,
    malloc: Option<MallocStats>,
    heap: Vec<Item>,
    tracer: Option<(u64, u64)>,
) -> Vec<Item> {
    let item = |name: &str, bytes| Item {
        name: name.to_string(),
        bytes,
    };
    let claimed: u64 = heap.iter().map(|i| i.bytes).sum();
    let mut items = vec![item("executable and libraries (file pages)", resident.file)];
    items.extend(heap);
    let (tracer_bytes, tracer_in_heap) = tracer.unwrap_or((0, 0));
    if tracer.is_some() {
        items.push(item("tracer (Embree's count: BVHs, buffers)", tracer_bytes));
    }
    if let Some(m) = malloc {
        let other = m.in_use.saturating_sub(claimed + tracer_in_heap);
        items.push(item(
            "other heap in use (small structures, C libraries)",
            other,
        ));
    }
    let listed: u64 = items.iter().map(|i| i.bytes).sum();
    items.push(item(
        "allocator slack (resident − items above)",
        resident.bytes.saturating_sub(listed),
    ));
    items
}

#[cfg(test)]
mod tests {
    use super::*;

    fn resident(bytes: u64) -> Resident {
        Resident {
            bytes,
            peak: bytes,
            file: 10,
        }
    }

    #[test]
    fn items_add_up_to_the_resident_size() {
        let heap = vec![
            Item {
                name: "a".into(),
                bytes: 300,
            },
            Item {
                name: "b".into(),
                bytes: 200,
            },
        ];
        let malloc = MallocStats {
            in_use: 560,
            free: 99,
        };
        let items = itemise(resident(1000), Some(malloc), heap, Some((150, 40)));
        let total: u64 = items.iter().map(|i| i.bytes).sum();
        assert_eq!(total, 1000);
        let bytes = |name: &str| {
            items
                .iter()
                .find(|i| i.name.starts_with(name))
                .unwrap()
                .bytes
        };
        assert_eq!(bytes("other heap"), 560 - 500 - 40);
        assert_eq!(bytes("allocator slack"), 1000 - 10 - 500 - 150 - 20);
        let without = itemise(resident(1000), None, Vec::new(), None);
        assert_eq!(without.len(), 2);
        assert_eq!(without[1].bytes, 990);
    }

    #[test]
    fn the_builtin_scene_counts_its_meshes() {
        let scene = psao_scene::builtin::default_scene();
        let positions: usize = scene.meshes.iter().map(|m| m.positions.len()).sum();
        assert!(scene_heap_bytes(&scene) >= 12 * positions as u64);
    }
}
