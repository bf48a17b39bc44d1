//! The flat 5-4-3 tree (thesis §4.2): per frame one L1 node with 32³ children, L2 nodes with
//! 16³ children and L3 nodes covering 8³ voxels. Each node has a child bitmask and a single
//! index: the children of a node are stored contiguously and found by rank (popcount of the
//! mask bits before the child, helped by per-word prefix counts). An L3 node holds the index
//! of its brick in the shared pool and a reference to its coded activity mask (full masks
//! need none), so frames of an animation share one brick pool (flip book).

use crate::error::{Result, VolumeError};
use crate::grid::{Leaf, BRICK};
use crate::mask;
use glam::IVec3;

/// Voxels spanned by one L1 child (an L2 node).
pub const L2_SPAN: i32 = 128;
/// Voxels spanned by the L1 node.
pub const L1_SPAN: i32 = 4096;

/// Top node of one frame: 32³ child bits.
#[derive(Clone, Debug)]
pub struct L1Node {
    /// Index-space origin of the frame (multiple of 128).
    pub origin: IVec3,
    /// Child mask, bit `x + 32 (y + 32 z)`.
    pub mask: Vec<u64>,
    /// Set bits in the words before each word (at most 32768 - 64, so 16 bits suffice).
    pub prefix: Vec<u16>,
    /// Index of the first child in [`FlatTree::l2`].
    pub first: u32,
}

/// Middle node: 16³ child bits.
#[derive(Clone, Debug)]
pub struct L2Node {
    /// Child mask, bit `x + 16 (y + 16 z)`.
    pub mask: [u64; 64],
    /// Set bits in the words before each word.
    pub prefix: [u16; 64],
    /// Index of the first child in [`FlatTree::l3`].
    pub first: u32,
    /// Byte offset in [`FlatTree::masks`] of the first coded mask of its children (the masks
    /// of the children follow in child order).
    pub mask_first: u32,
}

/// Leaf node, 4 bytes: its brick index, with the top bit set when its activity mask is not
/// full (the coded mask then sits in the mask table, found from the parent's `mask_first`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct L3Node(pub u32);

/// Top bit of an L3 node: the node has a coded (not full) mask.
const HAS_MASK: u32 = 1 << 31;

impl L3Node {
    /// A node for `brick` (below 2³¹) with or without a coded mask.
    pub fn new(brick: u32, coded_mask: bool) -> Self {
        L3Node(brick | if coded_mask { HAS_MASK } else { 0 })
    }

    /// Brick index in the shared pool.
    #[inline]
    pub fn brick(self) -> u32 {
        self.0 & !HAS_MASK
    }

    /// Points the node at another brick.
    pub fn set_brick(&mut self, brick: u32) {
        self.0 = (self.0 & HAS_MASK) | brick;
    }

    /// Whether the mask is coded in the table (else all voxels are active).
    #[inline]
    pub fn has_mask(self) -> bool {
        self.0 & HAS_MASK != 0
    }
}

/// Where an index-space voxel falls in the tree.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Locate {
    /// Outside the frame's L1 node.
    Outside,
    /// Inside an empty 128³ L1 cell with this origin.
    EmptyL2(IVec3),
    /// Inside an empty 8³ L2 cell with this origin.
    EmptyL3(IVec3),
    /// Inside L3 node `index` (into [`FlatTree::l3`]) whose origin is given.
    Leaf(u32, IVec3),
}

/// Node counts and bytes per level (thesis Table 3).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TreeStats {
    /// Frames (= L1 nodes).
    pub l1_nodes: usize,
    /// Bytes of the L1 level.
    pub l1_bytes: usize,
    /// L2 nodes.
    pub l2_nodes: usize,
    /// Bytes of the L2 level.
    pub l2_bytes: usize,
    /// L3 nodes.
    pub l3_nodes: usize,
    /// Bytes of the L3 level (without masks).
    pub l3_bytes: usize,
    /// L3 nodes whose mask is full (no table entry).
    pub full_masks: usize,
    /// Bytes of the coded mask table.
    pub mask_bytes: usize,
}

impl TreeStats {
    /// All tree bytes.
    pub fn total_bytes(&self) -> usize {
        self.l1_bytes + self.l2_bytes + self.l3_bytes + self.mask_bytes
    }
}

/// The flat tree of all frames.
#[derive(Clone, Debug, Default)]
pub struct FlatTree {
    /// One top node per frame.
    pub l1: Vec<L1Node>,
    /// All L2 nodes.
    pub l2: Vec<L2Node>,
    /// All L3 nodes.
    pub l3: Vec<L3Node>,
    /// Coded activity masks (see [`crate::mask`]).
    pub masks: Vec<u8>,
}

#[inline]
fn rank(mask: &[u64], prefix_of_word: u32, bit: usize) -> u32 {
    let w = mask[bit / 64];
    prefix_of_word + (w & ((1u64 << (bit % 64)) - 1)).count_ones()
}

#[inline]
fn test(mask: &[u64], bit: usize) -> bool {
    mask[bit / 64] >> (bit % 64) & 1 == 1
}

fn prefixes(mask: &[u64]) -> Vec<u16> {
    let mut acc = 0u32;
    mask.iter()
        .map(|w| {
            let p = acc as u16;
            acc += w.count_ones();
            p
        })
        .collect()
}

impl FlatTree {
    /// Adds one frame whose leaves use bricks `first_brick..first_brick + leaves.len()` (in
    /// the order given), plus fully active cells given as (origin, brick) — the cells of
    /// constant tiles, which share bricks. Returns the frame index.
    pub fn push_frame(
        &mut self,
        leaves: &[Leaf],
        first_brick: u32,
        cells: &[(IVec3, u32)],
    ) -> Result<usize> {
        let origins = leaves.iter().map(|l| l.origin);
        let origins = origins.chain(cells.iter().map(|c| c.0));
        let (lo, hi) = origins
            .clone()
            .fold(None, |acc: Option<(IVec3, IVec3)>, o| {
                let e = o + IVec3::splat(BRICK as i32);
                Some(acc.map_or((o, e), |(a, b)| (a.min(o), b.max(e))))
            })
            .ok_or(VolumeError::Empty)?;
        let origin = IVec3::new(
            lo.x.div_euclid(L2_SPAN),
            lo.y.div_euclid(L2_SPAN),
            lo.z.div_euclid(L2_SPAN),
        ) * L2_SPAN;
        let extent = hi - origin;
        if extent.max_element() > L1_SPAN {
            return Err(VolumeError::TooLarge((hi - lo).to_array()));
        }
        // Sort leaves by (L1 child, L2 child) so that children are contiguous in rank order.
        let key = |o: IVec3| {
            let l = o - origin;
            let c1 = l / L2_SPAN;
            let c2 = (l / BRICK as i32) % 16;
            let b1 = (c1.x + 32 * (c1.y + 32 * c1.z)) as usize;
            let b2 = (c2.x + 16 * (c2.y + 16 * c2.z)) as usize;
            (b1, b2)
        };
        // Entry i < leaves.len() is leaf i, else cell i − leaves.len().
        let mut order: Vec<(usize, usize, usize)> = origins
            .enumerate()
            .map(|(i, o)| {
                let (b1, b2) = key(o);
                (b1, b2, i)
            })
            .collect();
        order.sort_unstable();
        if order
            .windows(2)
            .any(|w| w[0].0 == w[1].0 && w[0].1 == w[1].1)
        {
            return Err(VolumeError::InvalidParameter(
                "two leaves at the same position".into(),
            ));
        }
        let mut l1_mask = vec![0u64; 512];
        let l1_first = self.l2.len() as u32;
        let mut current_l2: Option<usize> = None;
        for &(b1, b2, i) in &order {
            if current_l2 != Some(b1) {
                l1_mask[b1 / 64] |= 1 << (b1 % 64);
                let mask_first = u32::try_from(self.masks.len()).map_err(|_| {
                    VolumeError::InvalidParameter("mask table exceeds 4 GiB".into())
                })?;
                self.l2.push(L2Node {
                    mask: [0; 64],
                    prefix: [0; 64],
                    first: self.l3.len() as u32,
                    mask_first,
                });
                current_l2 = Some(b1);
            }
            let node = self.l2.last_mut().expect("pushed above");
            node.mask[b2 / 64] |= 1 << (b2 % 64);
            let (brick, coded) = match leaves.get(i) {
                Some(leaf) => {
                    let coded = !mask::is_full(&leaf.mask);
                    if coded {
                        mask::encode(&leaf.mask, &mut self.masks);
                    }
                    (first_brick + i as u32, coded)
                }
                None => (cells[i - leaves.len()].1, false),
            };
            if brick >= HAS_MASK {
                return Err(VolumeError::InvalidParameter(
                    "more than 2^31 bricks".into(),
                ));
            }
            self.l3.push(L3Node::new(brick, coded));
        }
        for node in &mut self.l2[l1_first as usize..] {
            let p = prefixes(&node.mask);
            for (d, s) in node.prefix.iter_mut().zip(p) {
                *d = s;
            }
        }
        let prefix = prefixes(&l1_mask);
        self.l1.push(L1Node {
            origin,
            mask: l1_mask,
            prefix,
            first: l1_first,
        });
        Ok(self.l1.len() - 1)
    }

    /// Number of frames.
    pub fn frames(&self) -> usize {
        self.l1.len()
    }

    /// Finds the deepest node containing index-space voxel `p` in `frame`.
    #[inline]
    pub fn locate(&self, frame: usize, p: IVec3) -> Locate {
        let top = &self.l1[frame];
        let l = p - top.origin;
        if l.min_element() < 0 || l.max_element() >= L1_SPAN {
            return Locate::Outside;
        }
        let c1: IVec3 = l >> 7i32;
        let b1 = (c1.x + 32 * (c1.y + 32 * c1.z)) as usize;
        if !test(&top.mask, b1) {
            return Locate::EmptyL2(top.origin + c1 * L2_SPAN);
        }
        let n2 = &self.l2[(top.first + rank(&top.mask, top.prefix[b1 / 64] as u32, b1)) as usize];
        let c2: IVec3 = (l >> 3i32) & 15i32;
        let b2 = (c2.x + 16 * (c2.y + 16 * c2.z)) as usize;
        let cell = top.origin + (l >> 3i32) * BRICK as i32;
        if !test(&n2.mask, b2) {
            return Locate::EmptyL3(cell);
        }
        Locate::Leaf(
            n2.first + rank(&n2.mask, n2.prefix[b2 / 64] as u32, b2),
            cell,
        )
    }

    /// Like [`FlatTree::locate`] for a point known to lie in L2 node `n2` whose origin is
    /// `origin` (skips the L1 level).
    #[inline]
    pub fn locate_in_l2(&self, n2: usize, origin: IVec3, p: IVec3) -> Locate {
        let node = &self.l2[n2];
        let c2: IVec3 = (p - origin) >> 3i32;
        let b2 = (c2.x + 16 * (c2.y + 16 * c2.z)) as usize;
        let cell = origin + c2 * BRICK as i32;
        if !test(&node.mask, b2) {
            return Locate::EmptyL3(cell);
        }
        Locate::Leaf(
            node.first + rank(&node.mask, node.prefix[b2 / 64] as u32, b2),
            cell,
        )
    }

    /// The L3 node of cell `c2` (each coordinate 0..16) of L2 node `n2`, if any.
    #[inline]
    pub fn leaf_in_l2(&self, n2: usize, c2: IVec3) -> Option<u32> {
        let node = &self.l2[n2];
        let b2 = (c2.x + 16 * (c2.y + 16 * c2.z)) as usize;
        test(&node.mask, b2).then(|| node.first + rank(&node.mask, node.prefix[b2 / 64] as u32, b2))
    }

    /// Index of the L2 node at L1 child `c1` (each coordinate 0..32) of `frame`, if any.
    #[inline]
    pub fn l2_child(&self, frame: usize, c1: IVec3) -> Option<usize> {
        let top = &self.l1[frame];
        let b1 = (c1.x + 32 * (c1.y + 32 * c1.z)) as usize;
        test(&top.mask, b1)
            .then(|| (top.first + rank(&top.mask, top.prefix[b1 / 64] as u32, b1)) as usize)
    }

    /// Index of the L2 node containing `p` in `frame`, if any.
    pub fn l2_index(&self, frame: usize, p: IVec3) -> Option<usize> {
        let top = &self.l1[frame];
        let l = p - top.origin;
        if l.min_element() < 0 || l.max_element() >= L1_SPAN {
            return None;
        }
        let c1: IVec3 = l >> 7i32;
        let b1 = (c1.x + 32 * (c1.y + 32 * c1.z)) as usize;
        test(&top.mask, b1)
            .then(|| (top.first + rank(&top.mask, top.prefix[b1 / 64] as u32, b1)) as usize)
    }

    /// Whether index-space voxel `p` of `frame` is active. Walks the coded masks of the
    /// preceding siblings (rendering never needs this, so the tree stays small).
    pub fn is_active(&self, frame: usize, p: IVec3) -> bool {
        let Some(n2) = self.l2_index(frame, p) else {
            return false;
        };
        let Locate::Leaf(index, origin) = self.locate(frame, p) else {
            return false;
        };
        let node = &self.l2[n2];
        if !self.l3[index as usize].has_mask() {
            return true;
        }
        let mut at = node.mask_first as usize;
        for sibling in &self.l3[node.first as usize..index as usize] {
            if sibling.has_mask() {
                match self.masks.get(at..).and_then(mask::coded_len) {
                    Some(n) => at += n,
                    None => return false,
                }
            }
        }
        let l = p - origin;
        mask::is_active(&self.masks[at..], l.x as usize, l.y as usize, l.z as usize)
    }

    /// Iterates over (frame, L3 index, origin) of all leaves.
    pub fn leaves(&self) -> impl Iterator<Item = (usize, u32, IVec3)> + '_ {
        self.l1.iter().enumerate().flat_map(move |(f, top)| {
            let mut out = Vec::new();
            for b1 in 0..32 * 32 * 32usize {
                if !test(&top.mask, b1) {
                    continue;
                }
                let c1 = IVec3::new(
                    (b1 % 32) as i32,
                    ((b1 / 32) % 32) as i32,
                    (b1 / 1024) as i32,
                );
                let n2i = top.first + rank(&top.mask, top.prefix[b1 / 64] as u32, b1);
                let n2 = &self.l2[n2i as usize];
                for b2 in 0..4096usize {
                    if test(&n2.mask, b2) {
                        let c2 = IVec3::new(
                            (b2 % 16) as i32,
                            ((b2 / 16) % 16) as i32,
                            (b2 / 256) as i32,
                        );
                        let o = top.origin + c1 * L2_SPAN + c2 * BRICK as i32;
                        out.push((
                            f,
                            n2.first + rank(&n2.mask, n2.prefix[b2 / 64] as u32, b2),
                            o,
                        ));
                    }
                }
            }
            out
        })
    }

    /// Node counts and bytes per level. An L1 node costs its 4 KiB mask, 1 KiB of word
    /// prefixes and a 4-byte index; an L2 node 512 + 128 + 8 bytes
    /// (mask, prefixes, child index, mask-table index); an L3 node 4 bytes.
    pub fn stats(&self) -> TreeStats {
        TreeStats {
            l1_nodes: self.l1.len(),
            l1_bytes: self.l1.len() * (4096 + 1024 + 4),
            l2_nodes: self.l2.len(),
            l2_bytes: self.l2.len() * (512 + 128 + 8),
            l3_nodes: self.l3.len(),
            l3_bytes: self.l3.len() * 4,
            full_masks: self.l3.iter().filter(|n| !n.has_mask()).count(),
            mask_bytes: self.masks.len(),
        }
    }
}
