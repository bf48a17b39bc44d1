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
