//! Visibility pass: bins screen triangles into horizontal bands and scan-converts one band into
//! a (nearest depth, triangle id) buffer.

use crate::mask::MaskTest;
use crate::setup::SetupTri;

/// Rows per band; each band is rasterized by one task that owns its pixels.
pub(crate) const BAND_ROWS: u32 = 16;

/// Triangles overlapping each band, in submission order.
#[derive(Default)]
pub(crate) struct Bins {
    /// `items[starts[b]..starts[b + 1]]` are the triangles of band `b`.
    starts: Vec<usize>,
    /// Indices into the triangle list.
    items: Vec<u32>,
}

impl Bins {
    /// Bins `tris` into `bands` bands of [`BAND_ROWS`] rows, reusing the storage.
    pub fn rebuild(&mut self, tris: &[SetupTri], bands: usize) {
        let range = |t: &SetupTri| {
            (u32::from(t.min_y) / BAND_ROWS) as usize..=(u32::from(t.max_y) / BAND_ROWS) as usize
        };
        self.starts.clear();
        self.starts.resize(bands + 1, 0);
        for t in tris {
            for b in range(t) {
                self.starts[b + 1] += 1;
            }
        }
        for b in 0..bands {
            self.starts[b + 1] += self.starts[b];
        }
        self.items.resize(self.starts[bands], 0);
        // Fill using starts[b] as the cursor of band b, then restore.
        for (i, t) in tris.iter().enumerate() {
            for b in range(t) {
                self.items[self.starts[b]] = i as u32;
                self.starts[b] += 1;
            }
        }
        for b in (1..=bands).rev() {
            self.starts[b] = self.starts[b - 1];
        }
        self.starts[0] = 0;
    }

    /// Triangle indices of band `b`.
    pub fn band(&self, b: usize) -> &[u32] {
        &self.items[self.starts[b]..self.starts[b + 1]]
    }
}

/// Nearest-surface buffer of one band: per pixel a packed visibility key (see [`pack`]).
#[derive(Default)]
pub(crate) struct VisibilityBand {
    /// Largest key so far; 0 where nothing is covered.
    pub key: Vec<u64>,
}

impl VisibilityBand {
    /// Global triangle id at pixel `p` of the band, `None` where nothing is covered.
    pub fn id(&self, p: usize) -> Option<u32> {
        let key = self.key[p];
        (key != 0).then(|| u32::MAX - key as u32)
    }
}

/// Packs a fragment's 1/depth (positive, as f32 bits, whose integer order matches numeric
/// order) above `u32::MAX − id`, so that the largest key is the nearest fragment and, among
/// equal depths, the lowest id. Valid keys are never 0.
fn pack(inv_depth: f64, id: u32) -> u64 {
    (u64::from((inv_depth as f32).to_bits()) << 32) | u64::from(u32::MAX - id)
}

/// Scan-converts `tris[items]` into `vis`, the band of `rows` rows starting at row `y0` of a
/// `width`-pixel-wide image, keeping the nearest fragment (lowest id on ties) that is not
/// beyond the far plane (`inv_far` = 1/far) nor cut out by its alpha mask (`masks`).
pub(crate) fn rasterize_band(
    tris: &[SetupTri],
    items: &[u32],
    (y0, rows, width): (u32, u32, u32),
    (inv_far, masks): (f64, &MaskTest<'_>),
    vis: &mut VisibilityBand,
) {
    vis.key.clear();
    vis.key.resize((rows * width) as usize, 0);
    for &i in items {
        let t = &tris[i as usize];
        let mask = if t.masked { masks.triangle(t.id) } else { None };
        let (step_x, step_y) = t.steps();
        let (min_x, min_y) = (u32::from(t.min_x), u32::from(t.min_y));
        let ys = min_y.max(y0)..=u32::from(t.max_y).min(y0 + rows - 1);
        for y in ys {
            let dy = i64::from(y - min_y);
            let e = [0, 1, 2].map(|k| t.edge[k] + step_y[k] * dy);
            let len = i64::from(t.max_x - t.min_x);
            let span = if len < NARROW {
                row_span_by_stepping(e, step_x, len)
            } else {
                row_span(e, step_x, len)
            };
            let Some((lo, hi)) = span else {
                continue;
            };
            let row = ((y - y0) * width) as usize;
            let [a, b, c] = t.inv_depth;
            let row_inv = b * y as f64 + c;
            let (x0, x1) = (min_x as usize + lo as usize, min_x as usize + hi as usize);
            let keys = (x0..=x1).zip(&mut vis.key[row + x0..=row + x1]);
            match &mask {
                None => {
                    for (x, key) in keys {
                        let inv = a * x as f64 + row_inv;
                        // Also rejects negative and NaN values, whose f32 bits would sort wrongly.
                        let k = if inv >= inv_far { pack(inv, t.id) } else { 0 };
                        *key = (*key).max(k);
                    }
                }
                Some(m) => {
                    for (x, key) in keys {
                        let inv = a * x as f64 + row_inv;
                        if inv >= inv_far {
                            let k = pack(inv, t.id);
                            if k > *key && m.keeps(x as u32, y) {
                                *key = k;
                            }
                        }
                    }
                }
            }
        }
    }
}

/// Bounding boxes narrower than this many pixels are scanned pixel by pixel; wider ones
/// compute each row's span by division.
const NARROW: i64 = 12;

/// [`row_span`] by evaluating every pixel (cheaper than dividing for short rows).
fn row_span_by_stepping(mut e: [i64; 3], step: [i64; 3], len: i64) -> Option<(i64, i64)> {
    let mut span: Option<(i64, i64)> = None;
    for k in 0..=len {
        if (e[0] | e[1] | e[2]) >= 0 {
            span = Some((span.map_or(k, |s| s.0), k));
        } else if span.is_some() {
            break;
        }
        for i in 0..3 {
            e[i] += step[i];
        }
    }
    span
}

/// Range of pixel offsets `k` in `0..=len` where every `e[i] + step[i]·k ≥ 0`.
fn row_span(e: [i64; 3], step: [i64; 3], len: i64) -> Option<(i64, i64)> {
    let (mut lo, mut hi) = (0i64, len);
    for i in 0..3 {
        let (e, s) = (e[i], step[i]);
        if s > 0 {
            if e < 0 {
                lo = lo.max((-e + s - 1) / s);
            }
        } else if e < 0 {
            return None;
        } else if s < 0 {
            hi = hi.min(e / -s);
        }
    }
    (lo <= hi).then_some((lo, hi))
}

#[cfg(test)]
mod tests {
    use super::{row_span, row_span_by_stepping};

    #[test]
    fn row_span_matches_brute_force() {
        let cases = [
            ([-700, 300, 5], [256, -128, 0], 10),
            ([0, 0, 0], [0, 0, 0], 4),
            ([-1, 5, 5], [0, 1, 1], 4),
            ([10, 2000, 7], [-3, -1000, 256], 20),
            ([-5000, 9000, 1], [256, -256, 0], 64),
        ];
        for (e, s, len) in cases {
            let brute: Vec<i64> = (0..=len)
                .filter(|&k| (0..3).all(|i| e[i] + s[i] * k >= 0))
                .collect();
            let expected = brute.first().map(|&lo| (lo, *brute.last().unwrap_or(&lo)));
            assert_eq!(row_span(e, s, len), expected, "{e:?} {s:?}");
            assert_eq!(row_span_by_stepping(e, s, len), expected, "{e:?} {s:?}");
        }
    }
}
