//! Compact coding of 8³ voxel-activity masks for the L3 nodes' mask table.
//!
//! A mask is coded as a two-level octree: 2 bytes give, for each 4³ octant, whether it is
//! mixed (first byte) and whether it is full (second byte); each mixed octant follows with
//! 2 bytes in the same form for its eight 2³ sub-octants, and each mixed sub-octant with
//! 1 byte of voxel bits. Full masks never reach the table.

use crate::grid::voxel_index;

/// Octant `o` (0..8) of a cube of edge `2 * half` at `base`: its origin.
#[inline]
fn octant(base: [usize; 3], o: usize, half: usize) -> [usize; 3] {
    [
        base[0] + (o & 1) * half,
        base[1] + ((o >> 1) & 1) * half,
        base[2] + (o >> 2) * half,
    ]
}

fn count(bits: &[u64; 8], o: [usize; 3], edge: usize) -> usize {
    let mut n = 0;
    for z in 0..edge {
        for y in 0..edge {
            for x in 0..edge {
                let i = voxel_index(o[0] + x, o[1] + y, o[2] + z);
                n += (bits[i / 64] >> (i % 64) & 1) as usize;
            }
        }
    }
    n
}

/// Appends the code of `bits` (bit `voxel_index` set = active) to `out`.
pub fn encode(bits: &[u64; 8], out: &mut Vec<u8>) {
    let (mut mixed, mut full) = (0u8, 0u8);
    let mut tail = Vec::new();
    for o in 0..8 {
        let c = octant([0; 3], o, 4);
        match count(bits, c, 4) {
            0 => {}
            64 => full |= 1 << o,
            _ => {
                mixed |= 1 << o;
                let (mut m2, mut f2) = (0u8, 0u8);
                let mut leaves = Vec::new();
                for s in 0..8 {
                    let c2 = octant(c, s, 2);
                    match count(bits, c2, 2) {
                        0 => {}
                        8 => f2 |= 1 << s,
                        _ => {
                            m2 |= 1 << s;
                            let mut byte = 0u8;
                            for v in 0..8 {
                                let p = octant(c2, v, 1);
                                let i = voxel_index(p[0], p[1], p[2]);
                                byte |= ((bits[i / 64] >> (i % 64) & 1) as u8) << v;
                            }
                            leaves.push(byte);
                        }
                    }
                }
                tail.extend_from_slice(&[m2, f2]);
                tail.extend_from_slice(&leaves);
            }
        }
    }
    out.extend_from_slice(&[mixed, full]);
    out.extend_from_slice(&tail);
}

/// Length in bytes of the code starting at `code[0]`, or `None` if it is truncated.
pub fn coded_len(code: &[u8]) -> Option<usize> {
    let mixed = *code.first()?;
    let mut at = 2;
    for _ in 0..mixed.count_ones() {
        let m2 = *code.get(at)?;
        at += 2 + m2.count_ones() as usize;
    }
    (at <= code.len()).then_some(at)
}

/// Whether voxel (x, y, z) is active in the mask coded at the start of `code` (which must be
/// a complete code, see [`coded_len`]).
#[inline]
pub fn is_active(code: &[u8], x: usize, y: usize, z: usize) -> bool {
    let o = (x >> 2) | ((y >> 2) << 1) | ((z >> 2) << 2);
    let (mixed, full) = (code[0], code[1]);
    if full >> o & 1 == 1 {
        return true;
    }
    if mixed >> o & 1 == 0 {
        return false;
    }
    let mut at = 2;
    for _ in 0..(mixed & ((1u8 << o) - 1)).count_ones() {
        at += 2 + code[at].count_ones() as usize;
    }
    let s = ((x >> 1) & 1) | (((y >> 1) & 1) << 1) | (((z >> 1) & 1) << 2);
    let (m2, f2) = (code[at], code[at + 1]);
    if f2 >> s & 1 == 1 {
        return true;
    }
    if m2 >> s & 1 == 0 {
        return false;
    }
    let leaf = code[at + 2 + (m2 & ((1u8 << s) - 1)).count_ones() as usize];
    let v = (x & 1) | ((y & 1) << 1) | ((z & 1) << 2);
    leaf >> v & 1 == 1
}

/// Decodes a complete code into a bit mask (bit `voxel_index` set = active).
pub fn decode(code: &[u8]) -> [u64; 8] {
    let mut bits = [0u64; 8];
    for z in 0..8 {
        for y in 0..8 {
            for x in 0..8 {
                if is_active(code, x, y, z) {
                    let i = voxel_index(x, y, z);
                    bits[i / 64] |= 1 << (i % 64);
                }
            }
        }
    }
    bits
}

/// Whether every voxel of `bits` is active.
pub fn is_full(bits: &[u64; 8]) -> bool {
    bits.iter().all(|&w| w == u64::MAX)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pseudo_random_mask(seed: u64) -> [u64; 8] {
        let mut s = seed;
        let mut bits = [0u64; 8];
        for (i, w) in bits.iter_mut().enumerate() {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            // Mix sparse, dense and random words.
            *w = match i % 3 {
                0 => 0,
                1 => u64::MAX,
                _ => s,
            };
        }
        bits
    }

    #[test]
    fn round_trips_masks() {
        for seed in 0..50 {
            let bits = pseudo_random_mask(seed);
            let mut code = Vec::new();
            encode(&bits, &mut code);
            assert_eq!(coded_len(&code), Some(code.len()));
            assert_eq!(decode(&code), bits);
        }
    }

    #[test]
    fn uniform_masks_are_two_bytes() {
        let mut code = Vec::new();
        encode(&[0; 8], &mut code);
        assert_eq!(code, vec![0, 0]);
        assert!(coded_len(&code[..1]).is_none());
    }
}
