//! Voxel sampling that decodes compressed bricks on the fly, one 4³ block (one BC7 block) at
//! a time: a sampler keeps a set-associative cache of decoded L3 nodes, each a 9³ copy of the
//! node's brick with the first voxel layer of its +x/+y/+z neighbours, so a trilinear sample
//! anywhere in the node reads one slot. A block is decoded once per ray segment, and usually
//! once per tile of neighbouring rays. `f32` bricks are read in place.

use crate::codec::BrickFormat;
use crate::grid::{floor_ivec, voxel_index, BRICK_VOXELS};
use crate::tree::Locate;
use crate::volume::{Volume, NO_LEAF};
use glam::{IVec3, Vec3};

/// Most nodes kept per sampler (log2); their 4³ blocks are decoded when first needed. A small
/// pool gets a power of two near twice its size, so a render of a small volume does not
/// allocate (and fault in) a 3 MiB cache per sampler.
const MAX_SLOT_BITS: u32 = 10;
/// The cache is set-associative: a node may sit in any of the `WAYS` slots of the set its
/// hashed index picks (a direct-mapped cache made nodes that a tile's rays all cross evict
/// each other over and over; the oldest node of a set is replaced).
const WAY_BITS: u32 = 2;
const WAYS: usize = 1 << WAY_BITS;
/// Located cells remembered per sampler.
const CELLS: usize = 4;
/// Edge of a cached node: its 8³ voxels plus one layer from its +x, +y and +z neighbours.
const PAD: usize = 9;
/// Values per cached node.
const PADDED_VOXELS: usize = PAD * PAD * PAD;
/// Offsets of the eight trilinear corners in a cached node (bit 0: +x, 1: +y, 2: +z).
const PADDED_CORNERS: [usize; 8] = [
    0,
    1,
    PAD,
    PAD + 1,
    PAD * PAD,
    PAD * PAD + 1,
    PAD * PAD + PAD,
    PAD * PAD + PAD + 1,
];

/// Index of (x, y, z) (each 0..9) in a cached node.
#[inline(always)]
fn padded_index(x: usize, y: usize, z: usize) -> usize {
    x + PAD * (y + PAD * z)
}

/// Per set of crossed axes `c` (bit 0: x, 1: y, 2: z): the neighbour layers a sample crossing
/// them reads, as bits `d` for every non-empty subset `d` of `c`.
const LAYERS_OF_CROSS: [u8; 8] = {
    let mut t = [0u8; 8];
    let mut c = 0;
    while c < 8 {
        let mut d = 1;
        while d < 8 {
            if d & !c == 0 {
                t[c] |= 1 << d;
            }
            d += 1;
        }
        c += 1;
    }
    t
};

/// The 4³ block (0..8) of voxel (x, y, z) of a brick.
#[inline]
fn block_of(x: usize, y: usize, z: usize) -> usize {
    (x >> 2) | ((y >> 2) << 1) | ((z >> 2) << 2)
}

/// The set of blocks `x + 2 y + 4 z` for x, y, z in the given 2-bit sets of halves.
#[inline]
fn spread(xs: u8, ys: u8, zs: u8) -> u8 {
    let row = xs | xs << 2; // x halves for y = 0 and y = 1
    let plane = row & (if ys & 1 != 0 { 0b0011 } else { 0 } | if ys & 2 != 0 { 0b1100 } else { 0 });
    (if zs & 1 != 0 { plane } else { 0 }) | (if zs & 2 != 0 { plane << 4 } else { 0 })
}

/// A per-thread sampler of one frame of a volume.
pub struct Sampler<'a> {
    vol: &'a Volume,
    frame: usize,
    /// Per slot: the L3 node it holds (`u32::MAX`: none).
    keys: Vec<u32>,
    /// log2 of the slot count.
    slot_bits: u32,
    /// Per slot: which of the node's eight 4³ blocks are decoded.
    valid: Vec<u8>,
    /// Per slot: which neighbour layers are copied in (bit `d` for neighbour offset `d`,
    /// 1..8, as in [`LAYERS_OF_CROSS`]).
    layers: Vec<u8>,
    /// Per set: the way filled next (the oldest one).
    next_way: Vec<u8>,
    /// Per slot: the node's values ([`padded_index`] layout; only decoded parts are valid).
    slots: Vec<[f32; PADDED_VOXELS]>,
    /// Recently located 8³ cells and their L3 nodes (round robin).
    cells: [(IVec3, Option<u32>); CELLS],
    next_cell: usize,
    /// The node whose slot holds all its blocks and was used last, and that slot (compressed
    /// formats; runs of samples in one node skip the cache lookup).
    current: (u32, usize),
    /// Blocks decoded so far (for statistics).
    pub decodes: u64,
}

impl<'a> Sampler<'a> {
    /// A sampler of `frame` of `vol`.
    pub fn new(vol: &'a Volume, frame: usize) -> Self {
        let decoded = vol.pool.format != BrickFormat::F32;
        // Twice the pool, so its bricks rarely crowd one set; at least two sets.
        let slot_bits = ((2 * vol.pool.len()).next_power_of_two().trailing_zeros())
            .clamp(WAY_BITS + 1, MAX_SLOT_BITS);
        let slots = if decoded { 1usize << slot_bits } else { 0 };
        Sampler {
            vol,
            frame,
            keys: vec![u32::MAX; slots],
            slot_bits,
            valid: vec![0; slots],
            layers: vec![0; slots],
            next_way: vec![0; slots / WAYS],
            slots: vec![[0.0; PADDED_VOXELS]; slots],
            cells: [(IVec3::MAX, None); CELLS],
            next_cell: 0,
            current: (u32::MAX, 0),
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

    /// Value of voxel (x, y, z) (each 0..8) of L3 node `leaf`.
    #[inline(always)]
    pub fn leaf_value(&mut self, leaf: u32, x: usize, y: usize, z: usize) -> f32 {
        if self.slots.is_empty() {
            let brick = self.vol.tree.l3[leaf as usize].brick();
            let at = brick as usize * 2048 + voxel_index(x, y, z) * 4;
            let d = &self.vol.pool.data[at..at + 4];
            return f32::from_le_bytes([d[0], d[1], d[2], d[3]]);
        }
        let s = self.slot(leaf, 1 << block_of(x, y, z), usize::MAX);
        self.slots[s][padded_index(x, y, z)]
    }

    /// The cache slot of L3 node `leaf` with at least the blocks in bit set `need` decoded
    /// (compressed formats only); a node not cached replaces the oldest of its set, but never
    /// the node in slot `keep`.
    #[inline(always)]
    fn slot(&mut self, leaf: u32, need: u8, keep: usize) -> usize {
        let set = ((leaf.wrapping_mul(0x9E37_79B9) >> (32 - self.slot_bits + WAY_BITS)) as usize)
            << WAY_BITS;
        for s in set..set + WAYS {
            if self.keys[s] == leaf {
                if need & !self.valid[s] == 0 {
                    return s;
                }
                return self.fill(s, leaf, need);
            }
        }
        let way = &mut self.next_way[set >> WAY_BITS];
        let mut s = set + *way as usize;
        if s == keep {
            *way = ((*way as usize + 1) % WAYS) as u8;
            s = set + *way as usize;
        }
        *way = ((*way as usize + 1) % WAYS) as u8;
        self.fill(s, leaf, need)
    }

    /// Makes slot `s` hold L3 node `leaf` with the blocks in `need` decoded.
    #[inline(never)]
    fn fill(&mut self, s: usize, leaf: u32, need: u8) -> usize {
        if self.keys[s] != leaf {
            self.keys[s] = leaf;
            self.valid[s] = 0;
            self.layers[s] = 0;
            if self.current.1 == s {
                self.current.0 = u32::MAX;
            }
        }
        let brick = self.vol.tree.l3[leaf as usize].brick();
        let mut missing = need & !self.valid[s];
        let mut block = [0.0f32; 64];
        while missing != 0 {
            let g = missing.trailing_zeros() as usize;
            self.vol.pool.decode_block(brick, g, &mut block);
            let (x0, y0, z0) = ((g & 1) * 4, ((g >> 1) & 1) * 4, (g >> 2) * 4);
            let slot = &mut self.slots[s];
            for dz in 0..4 {
                for dy in 0..4 {
                    let row = padded_index(x0, y0 + dy, z0 + dz);
                    slot[row..row + 4]
                        .copy_from_slice(&block[16 * dz + 4 * dy..16 * dz + 4 * dy + 4]);
                }
            }
            self.decodes += 1;
            missing &= missing - 1;
        }
        self.valid[s] |= need;
        s
    }

    /// Copies into slot `s` (holding L3 node `leaf`) the neighbour layers in bit set `layers`
    /// (bits `d` as in [`LAYERS_OF_CROSS`]): from each neighbour's own slot, decoding only the
    /// blocks that touch the layer; the background where there is no neighbour.
    #[inline(never)]
    fn fill_layers(&mut self, s: usize, leaf: u32, layers: u8) {
        let mut missing = layers & !self.layers[s];
        while missing != 0 {
            let d = missing.trailing_zeros() as usize;
            missing &= missing - 1;
            // Along the axes of `d` the layer is the node's coordinate 8, the neighbour's 0.
            let range = |axis: usize| if d >> axis & 1 == 1 { 8..9 } else { 0..8 };
            let n = self.vol.next_leaf(leaf, d);
            if n == NO_LEAF {
                let bg = self.vol.background;
                let dst = &mut self.slots[s];
                for z in range(2) {
                    for y in range(1) {
                        for x in range(0) {
                            dst[padded_index(x, y, z)] = bg;
                        }
                    }
                }
                continue;
            }
            let halves = |axis: usize| if d >> axis & 1 == 1 { 0b01 } else { 0b11 };
            let from = self.slot(n, spread(halves(0), halves(1), halves(2)), s);
            let (src, dst) = if from < s {
                let (a, b) = self.slots.split_at_mut(s);
                (&a[from], &mut b[0])
            } else {
                let (a, b) = self.slots.split_at_mut(from);
                (&b[0], &mut a[s])
            };
            for z in range(2) {
                for y in range(1) {
                    for x in range(0) {
                        dst[padded_index(x, y, z)] = src[padded_index(x & 7, y & 7, z & 7)];
                    }
                }
            }
        }
        self.layers[s] |= layers;
    }

    /// The eight corners of a trilinear sample with base voxel `l` (each 0..8, local to
    /// `leaf`) from the node's cached 9³ copy (compressed formats only).
    #[inline(always)]
    fn corners_cached(&mut self, leaf: u32, l: IVec3, c: &mut [f32; 8]) {
        let s = if self.current.0 == leaf {
            self.current.1
        } else {
            // The whole node: the next samples along the ray mostly fall in it too.
            let s = self.slot(leaf, 0xff, usize::MAX);
            self.current = (leaf, s);
            s
        };
        let cross = (l.x == 7) as usize | ((l.y == 7) as usize) << 1 | ((l.z == 7) as usize) << 2;
        let layers = LAYERS_OF_CROSS[cross];
        if layers & !self.layers[s] != 0 {
            self.fill_layers(s, leaf, layers);
        }
        let i0 = padded_index(l.x as usize, l.y as usize, l.z as usize);
        let d = &self.slots[s];
        for (k, o) in PADDED_CORNERS.iter().enumerate() {
            c[k] = d[i0 + o];
        }
    }

    /// Value of index-space voxel `p` (the background outside the leaves).
    #[inline]
    pub fn voxel(&mut self, p: IVec3) -> f32 {
        match self.leaf_at(p) {
            Some(leaf) => {
                let l: IVec3 = p & 7i32;
                self.leaf_value(leaf, l.x as usize, l.y as usize, l.z as usize)
            }
            None => self.vol.background,
        }
    }

    /// Trilinear value at index-space point `p` whose floor lies in L3 node `leaf` with origin
    /// `origin` (as on a [`crate::trace::Segment`]): the same value as
    /// [`Sampler::trilinear`] without searching the tree; corners past the node's +faces are
    /// read through its neighbour table.
    #[inline(always)]
    pub fn trilinear_in(&mut self, leaf: u32, origin: IVec3, p: Vec3) -> f32 {
        let b = floor_ivec(p);
        let l = b - origin;
        if (l.x as u32) >= 8 || (l.y as u32) >= 8 || (l.z as u32) >= 8 {
            // Rounding put the point just outside the node.
            return self.trilinear(p);
        }
        let f = p - b.as_vec3();
        let mut c = [0.0f32; 8];
        if !self.slots.is_empty() {
            self.corners_cached(leaf, l, &mut c);
        } else if l.x < 7 && l.y < 7 && l.z < 7 {
            let i0 = voxel_index(l.x as usize, l.y as usize, l.z as usize);
            self.corners_in_brick(leaf, i0, &mut c);
        } else {
            self.corners_across(leaf, l, &mut c);
        }
        lerp8(&c, f)
    }

    /// The eight corners of a trilinear sample with base voxel `l` (local to `leaf`) on its
    /// +x, +y or +z border layer, read in place from the f32 pool: each neighbour brick is
    /// found once from the neighbour table (a sample on one border layer, the common case,
    /// reads four corners from its own brick and four from one neighbour).
    #[inline(always)]
    fn corners_across(&mut self, leaf: u32, l: IVec3, c: &mut [f32; 8]) {
        let vol = self.vol;
        let cross = (l.x == 7) as usize | ((l.y == 7) as usize) << 1 | ((l.z == 7) as usize) << 2;
        let brick = |n: u32| f32_brick(vol, vol.tree.l3[n as usize].brick());
        let own = brick(leaf);
        let i0 = voxel_index(l.x as usize, l.y as usize, l.z as usize);
        if cross.is_power_of_two() {
            // One neighbour: the corners across read its layer 0 (the base voxel's index
            // with the crossed coordinate 7 → 0).
            let stride = [1, BRICK_ROW, BRICK_ROW * BRICK_ROW][cross.trailing_zeros() as usize];
            let n = vol.next_leaf(leaf, cross);
            let other = (n != NO_LEAF).then(|| brick(n));
            for (k, v) in c.iter_mut().enumerate() {
                let o = CORNER_OFFSETS[k & !cross];
                *v = if k & cross == 0 {
                    f32_at(own, i0 + o)
                } else {
                    match other {
                        Some(b) => f32_at(b, i0 - 7 * stride + o),
                        None => vol.background,
                    }
                };
            }
            return;
        }
        // Per neighbour offset d (a subset of `cross`): its brick, or a bit of `missing`.
        let mut src = [own; 8];
        let mut missing = 0u8;
        for (d, b) in src.iter_mut().enumerate().skip(1) {
            if d & !cross == 0 {
                match vol.next_leaf(leaf, d) {
                    NO_LEAF => missing |= 1 << d,
                    n => *b = brick(n),
                }
            }
        }
        for (k, v) in c.iter_mut().enumerate() {
            let d = k & cross;
            let q: IVec3 =
                (l + IVec3::new((k & 1) as i32, ((k >> 1) & 1) as i32, (k >> 2) as i32)) & 7i32;
            let value = f32_at(
                src[d],
                voxel_index(q.x as usize, q.y as usize, q.z as usize),
            );
            *v = if missing >> d & 1 != 0 {
                vol.background
            } else {
                value
            };
        }
    }

    /// The eight corners `i0 + OFF` of a trilinear sample whose cell lies inside the brick of
    /// `leaf`, read in place from the f32 pool.
    #[inline(always)]
    fn corners_in_brick(&mut self, leaf: u32, i0: usize, c: &mut [f32; 8]) {
        const OFF: [usize; 8] = CORNER_OFFSETS;
        let data = f32_brick(self.vol, self.vol.tree.l3[leaf as usize].brick());
        for (k, o) in OFF.iter().enumerate() {
            c[k] = f32_at(data, i0 + o);
        }
    }

    /// Trilinear value at index-space point `p` (voxel centres at integer coordinates).
    #[inline]
    pub fn trilinear(&mut self, p: Vec3) -> f32 {
        let b = floor_ivec(p);
        let f = p - b.as_vec3();
        let l: IVec3 = b & 7i32;
        let mut c = [0.0f32; 8];
        let compressed = !self.slots.is_empty();
        if compressed || (l.x < 7 && l.y < 7 && l.z < 7) {
            match self.leaf_at(b) {
                Some(leaf) if compressed => self.corners_cached(leaf, l, &mut c),
                Some(leaf) => {
                    // All eight corners in one brick.
                    let i0 = voxel_index(l.x as usize, l.y as usize, l.z as usize);
                    self.corners_in_brick(leaf, i0, &mut c);
                }
                None if l.x < 7 && l.y < 7 && l.z < 7 => return self.vol.background,
                None => self.corners_located(b, l, &mut c),
            }
        } else {
            self.corners_located(b, l, &mut c);
        }
        lerp8(&c, f)
    }

    /// The eight corners of a trilinear sample with base voxel `b` (`l` = `b` & 7) on a brick
    /// border, each distinct brick located once in the tree.
    fn corners_located(&mut self, b: IVec3, l: IVec3, c: &mut [f32; 8]) {
        let cross = (l.x == 7) as usize | ((l.y == 7) as usize) << 1 | ((l.z == 7) as usize) << 2;
        let mut leaves = [None; 8];
        for (k, v) in c.iter_mut().enumerate() {
            let d = IVec3::new((k & 1) as i32, ((k >> 1) & 1) as i32, (k >> 2) as i32);
            let p = b + d;
            let key = k & cross;
            if key == k {
                leaves[k] = self.leaf_at(p);
            }
            let q: IVec3 = p & 7i32;
            // Read at once: a later corner's brick may take this one's cache slot.
            *v = match leaves[key] {
                Some(leaf) => self.leaf_value(leaf, q.x as usize, q.y as usize, q.z as usize),
                None => self.vol.background,
            };
        }
    }
}

/// Voxels per brick row (x) and, squared, per brick slice.
const BRICK_ROW: usize = 8;

/// Offsets in a brick ([`voxel_index`] layout) of the eight trilinear corners (bit 0: +x,
/// 1: +y, 2: +z).
const CORNER_OFFSETS: [usize; 8] = [0, 1, 8, 9, 64, 65, 72, 73];

/// Voxel `i` (below 512) of an f32 brick (its 2048 little-endian bytes, see [`f32_brick`]).
#[inline(always)]
fn f32_at(brick: &[u8; 2048], i: usize) -> f32 {
    // The mask keeps a valid index as it is and lets the compiler drop the bounds checks.
    let at = 4 * (i & (BRICK_VOXELS - 1));
    f32::from_le_bytes([brick[at], brick[at + 1], brick[at + 2], brick[at + 3]])
}

/// The bytes of brick `brick` of an f32 pool.
#[inline(always)]
fn f32_brick(vol: &Volume, brick: u32) -> &[u8; 2048] {
    let at = brick as usize * 2048;
    vol.pool.data[at..at + 2048].try_into().expect("2048 bytes")
}

/// Trilinear interpolation of corners `c` (bit 0: +x, 1: +y, 2: +z) at fractions `f`.
#[inline(always)]
fn lerp8(c: &[f32; 8], f: Vec3) -> f32 {
    let x0 = c[0] + (c[1] - c[0]) * f.x;
    let x1 = c[2] + (c[3] - c[2]) * f.x;
    let x2 = c[4] + (c[5] - c[4]) * f.x;
    let x3 = c[6] + (c[7] - c[6]) * f.x;
    let y0 = x0 + (x1 - x0) * f.y;
    let y1 = x2 + (x3 - x2) * f.y;
    y0 + (y1 - y0) * f.z
}
