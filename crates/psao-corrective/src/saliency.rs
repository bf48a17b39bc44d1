//! Bottom-up saliency after Itti, Koch and Niebur (1998), simplified as in the paper §3:
//! intensity and red–green / blue–yellow double-opponent colour channels (no orientation
//! channel; the paper found no difference in its predictions and drops it for speed), Gaussian
//! pyramids, centre–surround differences across scales, the map normalisation operator `N(·)`,
//! conspicuity maps summed across scales, and their normalised mean as the saliency map.
//!
//! With 9 pyramid levels (images of at least 256 pixels on the short side) the centres are
//! levels 2, 3, 4 and the surrounds centre + 3 and + 4, as in Itti's model; smaller images shift
//! the scales down so the coarsest surround stays the last level.

use rayon::prelude::*;

/// A linear RGB image, row-major, top row first.
#[derive(Clone, Debug, PartialEq)]
pub struct RgbImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `width × height` colours.
    pub pixels: Vec<[f32; 3]>,
}

/// A single-channel map, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct Map {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `width × height` values.
    pub values: Vec<f32>,
}

impl Map {
    fn zeros(width: usize, height: usize) -> Self {
        Self {
            width,
            height,
            values: vec![0.0; width * height],
        }
    }

    /// Largest value (0 for an empty map).
    pub fn max(&self) -> f32 {
        self.values.iter().copied().fold(0.0, f32::max)
    }

    /// Value at (`x`, `y`).
    pub fn at(&self, x: usize, y: usize) -> f32 {
        self.values[y * self.width + x]
    }

    /// Bilinear resampling to `width × height` (pixel centres aligned).
    pub fn resized(&self, width: usize, height: usize) -> Map {
        if width == self.width && height == self.height {
            return self.clone();
        }
        let sx = self.width as f32 / width as f32;
        let sy = self.height as f32 / height as f32;
        let mut out = Map::zeros(width, height);
        out.values
            .par_chunks_mut(width.max(1))
            .enumerate()
            .for_each(|(y, row)| {
                let fy = ((y as f32 + 0.5) * sy - 0.5).clamp(0.0, (self.height - 1) as f32);
                let y0 = fy.floor() as usize;
                let y1 = (y0 + 1).min(self.height - 1);
                let ty = fy - y0 as f32;
                for (x, v) in row.iter_mut().enumerate() {
                    let fx = ((x as f32 + 0.5) * sx - 0.5).clamp(0.0, (self.width - 1) as f32);
                    let x0 = fx.floor() as usize;
                    let x1 = (x0 + 1).min(self.width - 1);
                    let tx = fx - x0 as f32;
                    let top = self.at(x0, y0) * (1.0 - tx) + self.at(x1, y0) * tx;
                    let bottom = self.at(x0, y1) * (1.0 - tx) + self.at(x1, y1) * tx;
                    *v = top * (1.0 - ty) + bottom * ty;
                }
            });
        out
    }

    /// Blur with the 5-tap binomial filter (clamped edges) and keep every second pixel.
    fn reduce(&self) -> Map {
        const K: [f32; 5] = [1.0 / 16.0, 4.0 / 16.0, 6.0 / 16.0, 4.0 / 16.0, 1.0 / 16.0];
        let (w, h) = (self.width, self.height);
        let tap = |i: usize, d: usize, n: usize| (i + d).saturating_sub(2).min(n - 1);
        let mut rows = Map::zeros(w.div_ceil(2), h);
        for y in 0..h {
            for x in 0..rows.width {
                let cx = 2 * x;
                rows.values[y * rows.width + x] =
                    (0..5).map(|d| K[d] * self.at(tap(cx, d, w), y)).sum();
            }
        }
        let mut out = Map::zeros(rows.width, h.div_ceil(2));
        for y in 0..out.height {
            let cy = 2 * y;
            for x in 0..out.width {
                out.values[y * out.width + x] =
                    (0..5).map(|d| K[d] * rows.at(x, tap(cy, d, h))).sum();
            }
        }
        out
    }

    /// The Gaussian pyramid: level 0 is the map itself, each next level half the size.
    fn pyramid(self, levels: usize) -> Vec<Map> {
        let mut out = vec![self];
        while out.len() < levels {
            let next = out.last().expect("non-empty").reduce();
            out.push(next);
        }
        out
    }

    fn add_assign(&mut self, other: &Map) {
        for (a, b) in self.values.iter_mut().zip(&other.values) {
            *a += b;
        }
    }
}

/// The normalisation operator `N(·)`: scale to [0, 1], then multiply by `(1 − m̄)²` where `m̄`
/// is the mean of the other local maxima, promoting maps with few strong peaks.
pub fn normalize(map: &Map) -> Map {
    let max = map.max();
    let mut out = map.clone();
    if max <= 0.0 {
        out.values.iter_mut().for_each(|v| *v = 0.0);
        return out;
    }
    out.values.iter_mut().for_each(|v| *v /= max);
    let (w, h) = (out.width, out.height);
    let mut sum = 0.0f64;
    let mut count = 0usize;
    let mut global_seen = false;
    for y in 0..h {
        for x in 0..w {
            let v = out.at(x, y);
            if v <= 0.0 {
                continue;
            }
            let is_max = (y.saturating_sub(1)..(y + 2).min(h))
                .all(|ny| (x.saturating_sub(1)..(x + 2).min(w)).all(|nx| out.at(nx, ny) <= v));
            if !is_max {
                continue;
            }
            if v >= 1.0 && !global_seen {
                global_seen = true;
                continue;
            }
            sum += v as f64;
            count += 1;
        }
    }
    let mean = if count == 0 {
        0.0
    } else {
        (sum / count as f64) as f32
    };
    let weight = (1.0 - mean) * (1.0 - mean);
    out.values.iter_mut().for_each(|v| *v *= weight);
    out
}

/// Opponent channels of one image: intensity, red–green and blue–yellow (Itti 1998 §2.1).
struct Channels {
    intensity: Map,
    red_green: Map,
    blue_yellow: Map,
}

fn channels(image: &RgbImage) -> Channels {
    let (w, h) = (image.width, image.height);
    let intensity: Vec<f32> = image
        .pixels
        .iter()
        .map(|p| (p[0] + p[1] + p[2]) / 3.0)
        .collect();
    let max_i = intensity.iter().copied().fold(0.0, f32::max);
    let mut rg = Vec::with_capacity(w * h);
    let mut by = Vec::with_capacity(w * h);
    for (p, &i) in image.pixels.iter().zip(&intensity) {
        // Hue is decoupled from intensity where the intensity is above a tenth of its maximum.
        if i <= 0.1 * max_i || i <= 0.0 {
            rg.push(0.0);
            by.push(0.0);
            continue;
        }
        let [r, g, b] = p.map(|c| c / i);
        let red = (r - (g + b) / 2.0).max(0.0);
        let green = (g - (r + b) / 2.0).max(0.0);
        let blue = (b - (r + g) / 2.0).max(0.0);
        let yellow = ((r + g) / 2.0 - (r - g).abs() / 2.0 - b).max(0.0);
        rg.push(red - green);
        by.push(blue - yellow);
    }
    let map = |values| Map {
        width: w,
        height: h,
        values,
    };
    Channels {
        intensity: map(intensity),
        red_green: map(rg),
        blue_yellow: map(by),
    }
}

/// Centre and surround levels for a pyramid of `depth` levels.
fn scales(depth: usize) -> Vec<(usize, usize)> {
    let first = depth.saturating_sub(7);
    (first..first + 3)
        .flat_map(|c| [(c, c + 3), (c, c + 4)])
        .filter(|&(_, s)| s < depth)
        .collect()
}

/// `Σ_scales N(|C(c) ⊖ S(s)|)` resampled to `width × height`.
fn conspicuity(pyramid: &[Map], pairs: &[(usize, usize)], width: usize, height: usize) -> Map {
    let mut sum = Map::zeros(width, height);
    for &(c, s) in pairs {
        let centre = &pyramid[c];
        let surround = pyramid[s].resized(centre.width, centre.height);
        let diff = Map {
            width: centre.width,
            height: centre.height,
            values: centre
                .values
                .iter()
                .zip(&surround.values)
                .map(|(a, b)| (a - b).abs())
                .collect(),
        };
        sum.add_assign(&normalize(&diff).resized(width, height));
    }
    sum
}

/// The pyramid depth and centre–surround pairs for a `width × height` image.
fn layout(width: usize, height: usize) -> (usize, Vec<(usize, usize)>) {
    let depth = (usize::BITS - width.min(height).leading_zeros()) as usize;
    let depth = depth.min(9);
    (depth, scales(depth))
}

/// The side in pixels of one cell of the saliency map of a `width × height` image: the map
/// is computed at the middle centre scale and resampled to the image, so it holds one
/// independent value per cell (1 when the image is too small for a map).
pub fn cell_size(width: usize, height: usize) -> usize {
    let (_, pairs) = layout(width, height);
    pairs.get(pairs.len() / 2).map_or(1, |&(c, _)| 1 << c)
}

/// The bottom-up saliency map of an image at full resolution, in [0, 1] (all zero when nothing
/// stands out, e.g. a uniform image or one too small for the pyramid).
pub fn saliency(image: &RgbImage) -> Map {
    let (w, h) = (image.width, image.height);
    if w == 0 || h == 0 {
        return Map::zeros(w, h);
    }
    let (depth, pairs) = layout(w, h);
    if pairs.is_empty() {
        return Map::zeros(w, h);
    }
    let ch = channels(image);
    // The conspicuity maps live at the middle centre scale (Itti's level 4).
    let mid = pairs[pairs.len() / 2].0;
    let pyramids: Vec<Vec<Map>> = [ch.intensity, ch.red_green, ch.blue_yellow]
        .into_par_iter()
        .map(|m| m.pyramid(depth))
        .collect();
    let (cw, chh) = (pyramids[0][mid].width, pyramids[0][mid].height);
    let intensity = conspicuity(&pyramids[0], &pairs, cw, chh);
    // Double opponency: the RG (BY) centre against the GR (YB) surround is |RG_c − RG_s|.
    let mut colour = conspicuity(&pyramids[1], &pairs, cw, chh);
    colour.add_assign(&conspicuity(&pyramids[2], &pairs, cw, chh));
    let mut s = normalize(&intensity);
    s.add_assign(&normalize(&colour));
    let mut full = s.resized(w, h);
    let max = full.max();
    if max > 0.0 {
        full.values.iter_mut().for_each(|v| *v /= max);
    }
    full
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grey(w: usize, h: usize, v: f32) -> RgbImage {
        RgbImage {
            width: w,
            height: h,
            pixels: vec![[v; 3]; w * h],
        }
    }

    fn paint(img: &mut RgbImage, x0: usize, y0: usize, size: usize, c: [f32; 3]) {
        for y in y0..y0 + size {
            for x in x0..x0 + size {
                img.pixels[y * img.width + x] = c;
            }
        }
    }

    fn argmax(m: &Map) -> (usize, usize) {
        let i = m
            .values
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .map(|(i, _)| i)
            .unwrap();
        (i % m.width, i / m.width)
    }

    fn mean_in(m: &Map, x0: usize, y0: usize, size: usize) -> f32 {
        let mut s = 0.0;
        for y in y0..y0 + size {
            for x in x0..x0 + size {
                s += m.at(x, y);
            }
        }
        s / (size * size) as f32
    }

    #[test]
    fn a_uniform_image_is_flat() {
        for (w, h) in [(160, 90), (300, 300)] {
            let s = saliency(&grey(w, h, 0.4));
            assert_eq!((s.width, s.height), (w, h));
            assert!(s.values.iter().all(|&v| v == 0.0));
        }
    }

    #[test]
    fn a_lone_red_square_on_grey_wins() {
        let mut img = grey(192, 128, 0.5);
        paint(&mut img, 130, 30, 14, [0.9, 0.1, 0.1]);
        let s = saliency(&img);
        let (x, y) = argmax(&s);
        assert!(
            (124..150).contains(&x) && (24..50).contains(&y),
            "peak at ({x}, {y})"
        );
        // Far from the square the map is low.
        assert!(mean_in(&s, 10, 80, 30) < 0.1 * mean_in(&s, 130, 30, 14));
    }

    #[test]
    fn colour_contrast_beats_a_faint_grey_patch() {
        let mut img = grey(256, 160, 0.5);
        paint(&mut img, 30, 60, 16, [0.45, 0.45, 0.45]);
        paint(&mut img, 190, 60, 16, [0.2, 0.3, 0.9]);
        let s = saliency(&img);
        let (x, y) = argmax(&s);
        assert!(
            (184..212).contains(&x) && (54..82).contains(&y),
            "peak at ({x}, {y})"
        );
        // Measured 0.72 against 0.43.
        assert!(mean_in(&s, 190, 60, 16) > 1.3 * mean_in(&s, 30, 60, 16));
    }

    #[test]
    fn normalisation_promotes_a_single_peak_over_many() {
        let mut one = Map::zeros(40, 40);
        one.values[20 * 40 + 20] = 1.0;
        let mut many = Map::zeros(40, 40);
        for i in 0..8 {
            many.values[(4 + 4 * i) * 40 + 4 + 4 * i] = 1.0 - 0.01 * i as f32;
        }
        assert!(normalize(&one).max() > 0.99);
        assert!(normalize(&many).max() < 0.01);
    }

    #[test]
    fn tiny_images_give_a_zero_map() {
        let s = saliency(&grey(5, 3, 0.7));
        assert_eq!(s.values.len(), 15);
        assert!(s.values.iter().all(|&v| v == 0.0));
        assert!(saliency(&grey(0, 0, 0.0)).values.is_empty());
    }
}
