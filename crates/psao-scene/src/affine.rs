//! Small helpers on transforms and axis-aligned boxes that several crates need alike.

use glam::{Affine3A, Vec3};

/// `transform⁻¹`, or the identity when it is singular or non-finite.
pub fn invert_or_identity(transform: &Affine3A) -> Affine3A {
    let det = transform.matrix3.determinant();
    if transform.is_finite() && det.is_normal() {
        transform.inverse()
    } else {
        Affine3A::IDENTITY
    }
}

/// The eight corners of the box (`lo`, `hi`): bit 0 of the index takes x from `hi`, bit 1 y,
/// bit 2 z.
pub fn box_corners(lo: Vec3, hi: Vec3) -> [Vec3; 8] {
    std::array::from_fn(|c| {
        Vec3::new(
            if c & 1 == 0 { lo.x } else { hi.x },
            if c & 2 == 0 { lo.y } else { hi.y },
            if c & 4 == 0 { lo.z } else { hi.z },
        )
    })
}

/// The axis-aligned bounds of the box (`lo`, `hi`) mapped by `transform`.
pub fn transformed_box(transform: &Affine3A, lo: Vec3, hi: Vec3) -> (Vec3, Vec3) {
    box_corners(lo, hi).iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(out_lo, out_hi), &p| {
            let w = transform.transform_point3(p);
            (out_lo.min(w), out_hi.max(w))
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Quat;

    #[test]
    fn corners_and_mapped_boxes() {
        let (lo, hi) = (Vec3::new(-1.0, 0.0, 2.0), Vec3::new(1.0, 3.0, 4.0));
        let c = box_corners(lo, hi);
        assert_eq!((c[0], c[7]), (lo, hi));
        assert_eq!(c[5], Vec3::new(1.0, 0.0, 4.0));
        let turn = Affine3A::from_rotation_translation(
            Quat::from_rotation_z(std::f32::consts::FRAC_PI_2),
            Vec3::X,
        );
        let (a, b) = transformed_box(&turn, lo, hi);
        assert!(a.abs_diff_eq(Vec3::new(-2.0, -1.0, 2.0), 1e-5), "{a}");
        assert!(b.abs_diff_eq(Vec3::new(1.0, 1.0, 4.0), 1e-5), "{b}");
        let singular = Affine3A::from_scale(Vec3::new(1.0, 0.0, 1.0));
        assert_eq!(invert_or_identity(&singular), Affine3A::IDENTITY);
        let t = Affine3A::from_translation(Vec3::Y);
        assert!(invert_or_identity(&t).abs_diff_eq(Affine3A::from_translation(-Vec3::Y), 0.0));
    }

    #[test]
    fn rotated_bounds_grow() {
        let t = Affine3A::from_rotation_z(std::f32::consts::FRAC_PI_4);
        let (lo, hi) = transformed_box(&t, Vec3::splat(-1.0), Vec3::splat(1.0));
        let r = 2f32.sqrt();
        assert!((lo - Vec3::new(-r, -r, -1.0)).length() < 1e-5);
        assert!((hi - Vec3::new(r, r, 1.0)).length() < 1e-5);
    }
}
