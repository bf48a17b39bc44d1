//! Top-down task importance per non-diffuse object and its combination with bottom-up saliency
//! (paper §3): the distance of the object's screen box centre to the image centre over half the
//! image diagonal, and the object's coverage of the image.
//!
//! Our combination rule (the paper gives none): `importance = ½·(1 − d) + ½·√coverage`, where
//! the square root lifts the small coverages typical of objects (1 % → 0.1); a region's
//! priority is `w·saliency + (1 − w)·importance` with `saliency` the mean of the normalised
//! saliency map over the object's pixels and `w` the user's balance (0.5 by default: the
//! paper found roughly balanced weights best).

use crate::saliency::Map;
use crate::sqrt5::PixelRect;

/// The default balance between bottom-up saliency and top-down importance.
pub const DEFAULT_SALIENCY_WEIGHT: f32 = 0.5;

/// One non-diffuse object on screen, with its attention measures.
#[derive(Clone, Debug, PartialEq)]
pub struct ObjectRegion {
    /// The object id (non-zero).
    pub id: u32,
    /// Screen bounding rectangle of the object's pixels.
    pub rect: PixelRect,
    /// Number of the object's pixels.
    pub pixels: u32,
    /// Mean bottom-up saliency over the object's pixels, in [0, 1].
    pub saliency: f32,
    /// Top-down task importance, in [0, 1].
    pub importance: f32,
    /// Combined priority, in [0, 1].
    pub priority: f32,
}

/// Find the non-diffuse objects in an id buffer (`0` = diffuse) and rate them.
///
/// `weight` is clamped to [0, 1]. Regions come out sorted by id.
///
/// # Panics
/// When `ids` is not `width × height` or `saliency` is not the same size (a caller bug).
pub fn analyze(
    ids: &[u32],
    width: usize,
    height: usize,
    saliency: &Map,
    weight: f32,
) -> Vec<ObjectRegion> {
    assert_eq!(ids.len(), width * height, "id buffer size");
    assert_eq!(saliency.values.len(), ids.len(), "saliency map size");
    let weight = weight.clamp(0.0, 1.0);
    let mut acc: std::collections::BTreeMap<u32, (PixelRect, u32, f64)> = Default::default();
    for y in 0..height {
        for x in 0..width {
            let i = y * width + x;
            let id = ids[i];
            if id == 0 {
                continue;
            }
            let (xi, yi) = (x as i32, y as i32);
            let e = acc.entry(id).or_insert((
                PixelRect {
                    x0: xi,
                    y0: yi,
                    x1: xi + 1,
                    y1: yi + 1,
                },
                0,
                0.0,
            ));
            e.0.x0 = e.0.x0.min(xi);
            e.0.y0 = e.0.y0.min(yi);
            e.0.x1 = e.0.x1.max(xi + 1);
            e.0.y1 = e.0.y1.max(yi + 1);
            e.1 += 1;
            e.2 += saliency.values[i] as f64;
        }
    }
    let total = (width * height).max(1) as f32;
    let half_diag = 0.5 * ((width * width + height * height) as f32).sqrt();
    let (cx, cy) = (width as f32 * 0.5, height as f32 * 0.5);
    acc.into_iter()
        .map(|(id, (rect, pixels, sal_sum))| {
            let bx = 0.5 * (rect.x0 + rect.x1) as f32;
            let by = 0.5 * (rect.y0 + rect.y1) as f32;
            let d = ((bx - cx).hypot(by - cy) / half_diag.max(1e-6)).min(1.0);
            let coverage = pixels as f32 / total;
            let importance = 0.5 * (1.0 - d) + 0.5 * coverage.sqrt();
            let saliency = (sal_sum / pixels as f64) as f32;
            ObjectRegion {
                id,
                rect,
                pixels,
                saliency,
                importance,
                priority: weight * saliency + (1.0 - weight) * importance,
            }
        })
        .collect()
}

/// The tile side for regions of a `width × height` image: two cells of its saliency map
/// ([`crate::saliency::cell_size`]), the shortest period over which the (resampled) map can
/// rise and fall again, so tiles separate its features without cutting one feature's area
/// into pieces of the same saliency.
pub fn tile_size(width: usize, height: usize) -> usize {
    2 * crate::saliency::cell_size(width, height)
}

/// [`analyze`], then each object cut along a grid of square tiles of [`tile_size`] (aligned to
/// the image origin) into regions: the object's pixels inside one tile, with their bounding
/// rectangle and mean saliency, and the object's importance (the paper's task importance is
/// per object). So the saliency within a large object steers which of its parts are sampled
/// first. When that makes more than `max_regions` regions, the tile side doubles until they
/// fit. Regions come out sorted by object id, then tile row, then tile column.
///
/// # Panics
/// As [`analyze`].
pub fn analyze_tiles(
    ids: &[u32],
    width: usize,
    height: usize,
    saliency: &Map,
    weight: f32,
    max_regions: usize,
) -> Vec<ObjectRegion> {
    let objects = analyze(ids, width, height, saliency, weight);
    let weight = weight.clamp(0.0, 1.0);
    let mut tile = tile_size(width, height);
    loop {
        let regions = cut(&objects, ids, width, saliency, weight, tile);
        if regions.len() <= max_regions || tile >= width.max(height) {
            return regions;
        }
        tile *= 2;
    }
}

/// Each object's region cut into the parts inside tiles of side `tile`.
fn cut(
    objects: &[ObjectRegion],
    ids: &[u32],
    width: usize,
    saliency: &Map,
    weight: f32,
    tile: usize,
) -> Vec<ObjectRegion> {
    let tile = tile.max(1) as i32;
    let mut out = Vec::new();
    for o in objects {
        let mut ty = o.rect.y0.div_euclid(tile) * tile;
        while ty < o.rect.y1 {
            let mut tx = o.rect.x0.div_euclid(tile) * tile;
            while tx < o.rect.x1 {
                let mut rect: Option<PixelRect> = None;
                let (mut pixels, mut sum) = (0u32, 0.0f64);
                for y in ty.max(o.rect.y0)..(ty + tile).min(o.rect.y1) {
                    for x in tx.max(o.rect.x0)..(tx + tile).min(o.rect.x1) {
                        let i = y as usize * width + x as usize;
                        if ids[i] != o.id {
                            continue;
                        }
                        pixels += 1;
                        sum += saliency.values[i] as f64;
                        let r = rect.get_or_insert(PixelRect {
                            x0: x,
                            y0: y,
                            x1: x + 1,
                            y1: y + 1,
                        });
                        r.x0 = r.x0.min(x);
                        r.y0 = r.y0.min(y);
                        r.x1 = r.x1.max(x + 1);
                        r.y1 = r.y1.max(y + 1);
                    }
                }
                if let Some(rect) = rect {
                    let mean = (sum / pixels as f64) as f32;
                    out.push(ObjectRegion {
                        id: o.id,
                        rect,
                        pixels,
                        saliency: mean,
                        importance: o.importance,
                        priority: weight * mean + (1.0 - weight) * o.importance,
                    });
                }
                tx += tile;
            }
            ty += tile;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ids_with(w: usize, h: usize, boxes: &[(u32, usize, usize, usize)]) -> Vec<u32> {
        let mut ids = vec![0; w * h];
        for &(id, x0, y0, s) in boxes {
            for y in y0..y0 + s {
                for x in x0..x0 + s {
                    ids[y * w + x] = id;
                }
            }
        }
        ids
    }

    #[test]
    fn central_and_larger_objects_matter_more() {
        let (w, h) = (100, 60);
        let flat = Map {
            width: w,
            height: h,
            values: vec![0.0; w * h],
        };
        let ids = ids_with(w, h, &[(1, 45, 25, 10), (2, 0, 0, 10), (3, 80, 40, 20)]);
        let r = analyze(&ids, w, h, &flat, 0.0);
        assert_eq!(r.iter().map(|o| o.id).collect::<Vec<_>>(), [1, 2, 3]);
        assert_eq!(r[0].pixels, 100);
        assert_eq!(
            r[0].rect,
            PixelRect {
                x0: 45,
                y0: 25,
                x1: 55,
                y1: 35
            }
        );
        assert!(r[0].importance > r[1].importance);
        // Same distance class, but object 3 covers four times the pixels of object 2.
        assert!(r[2].importance > r[1].importance);
        assert!(r.iter().all(|o| o.priority == o.importance));
    }

    #[test]
    fn tiles_partition_an_object_and_follow_saliency_within_it() {
        let (w, h) = (64, 48);
        let tile = tile_size(w, h);
        assert!(tile >= 2);
        // One object spanning several tiles; saliency only on its left part.
        let ids = ids_with(w, h, &[(5, 3, 3, 4 * tile)]);
        let mut sal = Map {
            width: w,
            height: h,
            values: vec![0.0; w * h],
        };
        for y in 0..h {
            for x in 0..tile {
                sal.values[y * w + x] = 1.0;
            }
        }
        let regions = analyze_tiles(&ids, w, h, &sal, 0.5, usize::MAX);
        assert!(regions.len() > 1);
        // Every pixel of the object lies in exactly one region, and each region's rectangle
        // stays inside one tile.
        for y in 0..h as i32 {
            for x in 0..w as i32 {
                let n = regions.iter().filter(|r| r.rect.contains(x, y)).count();
                let on = ids[y as usize * w + x as usize] == 5;
                assert_eq!(n, usize::from(on), "pixel ({x}, {y})");
            }
        }
        for r in &regions {
            assert_eq!(r.rect.x0 / tile as i32, (r.rect.x1 - 1) / tile as i32);
            assert_eq!(r.rect.y0 / tile as i32, (r.rect.y1 - 1) / tile as i32);
            assert_eq!(r.pixels as u64, r.rect.area());
        }
        let total: u32 = regions.iter().map(|r| r.pixels).sum();
        assert_eq!(total as usize, 16 * tile * tile);
        // The salient column of tiles comes first; all share the object's importance.
        let best = regions
            .iter()
            .max_by(|a, b| a.priority.total_cmp(&b.priority))
            .unwrap();
        assert!(best.rect.x0 < tile as i32);
        assert!(regions
            .iter()
            .all(|r| r.importance == regions[0].importance));
        // Too many regions: the tiles grow until they fit.
        let few = analyze_tiles(&ids, w, h, &sal, 0.5, 4);
        assert!(few.len() <= 4 && few.len() < regions.len());
        let total: u32 = few.iter().map(|r| r.pixels).sum();
        assert_eq!(total as usize, 16 * tile * tile);
    }

    #[test]
    fn the_weight_blends_saliency_and_importance() {
        let (w, h) = (50, 50);
        let ids = ids_with(w, h, &[(7, 0, 0, 5)]);
        let mut sal = Map {
            width: w,
            height: h,
            values: vec![0.0; w * h],
        };
        for y in 0..5 {
            for x in 0..5 {
                sal.values[y * w + x] = 0.8;
            }
        }
        let r = analyze(&ids, w, h, &sal, 1.0);
        assert!((r[0].priority - 0.8).abs() < 1e-6);
        let half = analyze(&ids, w, h, &sal, 0.5);
        assert!((half[0].priority - 0.5 * (0.8 + half[0].importance)).abs() < 1e-6);
    }
}
