//! Where a corrected frame that is worse than its base lost: the change in squared error
//! against the reference (8-bit sRGB) split by the kind of non-diffuse pixel it happened at.

use serde::Serialize;

/// Linear radiance above which a reference or corrected pixel counts as a highlight (some
/// channel brighter than the display's white, as [`psao_corrective::splat::HIGHLIGHT`]).
const HIGHLIGHT: f32 = psao_corrective::splat::HIGHLIGHT;

/// Change of the summed squared error (8-bit units, over the three channels) from the base
/// frame to the corrected frame, per kind of pixel: positive where the corrections added
/// error. Diffuse pixels are not corrected, so they do not appear.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ErrorChange {
    /// Non-diffuse pixels next to another object or a diffuse pixel (4-neighbourhood): where
    /// footprints end.
    pub edge: f64,
    /// Other non-diffuse pixels that are highlights in the reference or the corrected frame.
    pub highlight: f64,
    /// The remaining (interior) non-diffuse pixels.
    pub interior: f64,
    /// Pixels of each kind whose error grew.
    pub edge_worse: usize,
    pub highlight_worse: usize,
    pub interior_worse: usize,
}

/// The images one frame's change is measured on (`width × height`, row-major).
pub struct Compared<'a> {
    /// Reference, 8-bit sRGB and linear.
    pub reference_srgb: &'a [u8],
    pub reference: &'a [[f32; 3]],
    /// Base and corrected frames, linear.
    pub base: &'a [[f32; 3]],
    pub corrected: &'a [[f32; 3]],
    /// Object id per pixel (0: diffuse).
    pub ids: &'a [u32],
    pub width: usize,
}

/// The change of squared error from base to corrected, by pixel kind.
pub fn error_change(c: &Compared<'_>) -> ErrorChange {
    let base = psao_client::composite_srgb8(c.base);
    let corrected = psao_client::composite_srgb8(c.corrected);
    let sq = |img: &[u8], i: usize| -> f64 {
        (0..3)
            .map(|k| (f64::from(img[3 * i + k]) - f64::from(c.reference_srgb[3 * i + k])).powi(2))
            .sum()
    };
    let w = c.width;
    let mut out = ErrorChange::default();
    for (i, &id) in c.ids.iter().enumerate() {
        if id == 0 {
            continue;
        }
        let (x, y) = (i % w, i / w);
        let neighbours = [
            (x > 0).then(|| i - 1),
            (x + 1 < w).then(|| i + 1),
            (y > 0).then(|| i - w),
            (i + w < c.ids.len()).then(|| i + w),
        ];
        let edge = neighbours.into_iter().flatten().any(|j| c.ids[j] != id);
        let bright = |p: &[f32; 3]| p.iter().any(|&v| v > HIGHLIGHT);
        let delta = sq(&corrected, i) - sq(&base, i);
        let worse = usize::from(delta > 0.0);
        if edge {
            out.edge += delta;
            out.edge_worse += worse;
        } else if bright(&c.reference[i]) || bright(&c.corrected[i]) {
            out.highlight += delta;
            out.highlight_worse += worse;
        } else {
            out.interior += delta;
            out.interior_worse += worse;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn changes_are_split_by_edge_highlight_and_interior() {
        // A 5×3 image: object 2 in the left 3×3 block (its centre (1, 1) is interior, its
        // right column borders diffuse pixels), diffuse elsewhere.
        let (w, h) = (5usize, 3usize);
        let mut ids = vec![2u32; w * h];
        for y in 0..h {
            ids[y * w + 3] = 0;
            ids[y * w + 4] = 0;
        }
        let reference = vec![[0.5f32; 3]; w * h];
        let reference_srgb = psao_client::composite_srgb8(&reference);
        let base = reference.clone();
        let mut corrected = reference.clone();
        corrected[w + 1] = [0.7; 3]; // the interior pixel, worse
        corrected[2] = [0.6; 3]; // (2, 0), an edge pixel, worse
        let mut bright_ref = reference.clone();
        bright_ref[w + 1] = [2.0; 3];
        let c = Compared {
            reference_srgb: &reference_srgb,
            reference: &reference,
            base: &base,
            corrected: &corrected,
            ids: &ids,
            width: w,
        };
        let e = error_change(&c);
        assert!(e.interior > 0.0 && e.edge > 0.0 && e.highlight == 0.0);
        assert_eq!(
            (e.edge_worse, e.interior_worse, e.highlight_worse),
            (1, 1, 0)
        );
        // The same pixel counts as a highlight when the reference is brighter than white
        // there (its error is measured on the 8-bit reference either way).
        let e = error_change(&Compared {
            reference: &bright_ref,
            ..c
        });
        assert_eq!((e.interior_worse, e.highlight_worse), (0, 1));
        // An unchanged frame changes nothing.
        let same = error_change(&Compared {
            corrected: &base,
            ..c
        });
        assert_eq!(same, ErrorChange::default());
    }
}
