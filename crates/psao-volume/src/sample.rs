//! Voxel sampling that decodes bricks on the fly: a sampler keeps a small direct-mapped cache
//! of decoded bricks (keyed by L3 node), so a compressed brick is decoded once per ray segment
//! (and usually once per tile of neighbouring rays). `f32` bricks are read in place.

use crate::codec::BrickFormat;
use crate::grid::{floor_ivec, voxel_index, BRICK_VOXELS};
use crate::tree::Locate;
use crate::volume::Volume;
use glam::{IVec3, Vec3};

/// Decoded bricks kept per sampler (direct-mapped by brick index).
const SLOTS: usize = 256;
/// Located cells remembered per sampler.
const CELLS: usize = 4;

/// A per-thread sampler of one frame of a volume.
pub struct Sampler<'a> {
    vol: &'a Volume,
    frame: usize,
    keys: [u32; SLOTS],
    slots: Vec<[f32; BRICK_VOXELS]>,
    /// Recently located 8³ cells and their L3 nodes (round robin).
    cells: [(IVec3, Option<u32>); CELLS],
    next_cell: usize,
    /// Bricks decoded so far (for statistics).
    pub decodes: u64,
}

impl<'a> Sampler<'a> {
    /// A sampler of `frame` of `vol`.
    pub fn new(vol: &'a Volume, frame: usize) -> Self {
        let decoded = vol.pool.format != BrickFormat::F32;
        Sampler {
            vol,
            frame,
            keys: [u32::MAX; SLOTS],
            slots: if decoded {
                vec![[0.0; BRICK_VOXELS]; SLOTS]
            } else {
                Vec::new()
            },
            cells: [(IVec3::MAX, None); CELLS],
            next_cell: 0,
            decodes: 0,
        }
    }

    /// The volume sampled.
    pub fn volume(&self) -> &'a Volume {
        self.vol
    }

    /// The frame sampled.
    pub fn frame(&self) -> usize {
        self.frame
    }

    /// L3 node containing voxel `p`, if any (the last few answers are remembered, so
    /// trilinear samples across a brick border do not search the tree each time).
    #[inline]
    pub fn leaf_at(&mut self, p: IVec3) -> Option<u32> {
        let cell: IVec3 = p >> 3i32;
        if let Some(&(_, leaf)) = self.cells.iter().find(|(c, _)| *c == cell) {
            return leaf;
        }
        let leaf = match self.vol.tree.locate(self.frame, p) {
            Locate::Leaf(i, _) => Some(i),
            _ => None,
        };
        self.cells[self.next_cell] = (cell, leaf);
        self.next_cell = (self.next_cell + 1) % CELLS;
        leaf
    }

    /// Value of voxel `v` (0..512) of L3 node `leaf`.
    #[inline]
    pub fn leaf_value(&mut self, leaf: u32, v: usize) -> f32 {
        let brick = self.vol.tree.l3[leaf as usize].brick();
        if self.slots.is_empty() {
            let at = brick as usize * 2048 + v * 4;
            let d = &self.vol.pool.data[at..at + 4];
            return f32::from_le_bytes([d[0], d[1], d[2], d[3]]);
        }
        self.decoded(brick)[v]
    }

    /// The decoded values of `brick` (compressed formats only).
    #[inline]
    fn decoded(&mut self, brick: u32) -> &[f32; BRICK_VOXELS] {
        let s = brick as usize % SLOTS;
        if self.keys[s] != brick {
            self.vol.pool.decode(brick, &mut self.slots[s]);
            self.keys[s] = brick;
            self.decodes += 1;
        }
        &self.slots[s]
    }

    /// Value of index-space voxel `p` (the background outside the leaves).
    #[inline]
    pub fn voxel(&mut self, p: IVec3) -> f32 {
        match self.leaf_at(p) {
            Some(leaf) => {
                let l: IVec3 = p & 7i32;
                self.leaf_value(leaf, voxel_index(l.x as usize, l.y as usize, l.z as usize))
            }
            None => self.vol.background,
        }
    }

    /// Trilinear value at index-space point `p` (voxel centres at integer coordinates).
    #[inline]
    pub fn trilinear(&mut self, p: Vec3) -> f32 {
        let b = floor_ivec(p);
        let f = p - b.as_vec3();
        let l: IVec3 = b & 7i32;
        let mut c = [0.0f32; 8];
        if l.x < 7 && l.y < 7 && l.z < 7 {
            // All eight corners in one brick.
            match self.leaf_at(b) {
                None => return self.vol.background,
                Some(leaf) => {
                    let i0 = voxel_index(l.x as usize, l.y as usize, l.z as usize);
                    const OFF: [usize; 8] = [0, 1, 8, 9, 64, 65, 72, 73];
                    if self.slots.is_empty() {
                        let brick = self.vol.tree.l3[leaf as usize].brick() as usize;
                        let data = &self.vol.pool.data[brick * 2048..brick * 2048 + 2048];
                        for (k, o) in OFF.iter().enumerate() {
                            let at = (i0 + o) * 4;
                            c[k] = f32::from_le_bytes([
                                data[at],
                                data[at + 1],
                                data[at + 2],
                                data[at + 3],
                            ]);
                        }
                    } else {
                        let brick = self.vol.tree.l3[leaf as usize].brick();
                        let d = self.decoded(brick);
                        for (k, o) in OFF.iter().enumerate() {
                            c[k] = d[i0 + o];
                        }
                    }
                }
            }
        } else {
            // Corners in up to eight bricks: locate each distinct brick once.
            let cross =
                (l.x == 7) as usize | ((l.y == 7) as usize) << 1 | ((l.z == 7) as usize) << 2;
            let mut leaves = [None; 8];
            for (k, v) in c.iter_mut().enumerate() {
                let d = IVec3::new((k & 1) as i32, ((k >> 1) & 1) as i32, (k >> 2) as i32);
                let p = b + d;
                let key = k & cross;
                if key == k {
                    leaves[k] = self.leaf_at(p);
                }
                *v = match leaves[key] {
                    Some(leaf) => {
                        let q: IVec3 = p & 7i32;
                        self.leaf_value(leaf, voxel_index(q.x as usize, q.y as usize, q.z as usize))
                    }
                    None => self.vol.background,
                };
            }
        }
        let x0 = c[0] + (c[1] - c[0]) * f.x;
        let x1 = c[2] + (c[3] - c[2]) * f.x;
        let x2 = c[4] + (c[5] - c[4]) * f.x;
        let x3 = c[6] + (c[7] - c[6]) * f.x;
        let y0 = x0 + (x1 - x0) * f.y;
        let y1 = x2 + (x3 - x2) * f.y;
        y0 + (y1 - y0) * f.z
    }
}
