//! The planar fit of the reconstruction: exact on planar AO, bounded, and the mean where a
//! plane is not determined.

use glam::Vec3;
use psao_points::LinearFit;

/// Offsets on a small jittered lattice in the plane z = 0.
fn offsets() -> Vec<Vec3> {
    (0..25)
        .map(|k| {
            let (i, j) = ((k % 5) as f32 - 2.0, (k / 5) as f32 - 2.0);
            Vec3::new(0.01 * i + 0.001 * j, 0.01 * j - 0.0007 * i, 0.0)
        })
        .collect()
}

#[test]
fn planar_ao_is_reproduced_where_the_mean_is_biased() {
    let n = Vec3::Z;
    let ao = |d: Vec3| 0.5 + 8.0 * d.x - 3.0 * d.y;
    let mut fit = LinearFit::new(n);
    let (mut w_sum, mut ao_sum) = (0.0, 0.0);
    // One-sided weights (more weight at +x) bias the weighted mean but not the fit.
    for d in offsets() {
        let w = 1.0 + 40.0 * d.x.max(0.0);
        fit.add(w, d, ao(d));
        w_sum += w;
        ao_sum += w * ao(d);
    }
    let fitted = fit.solve(0.0).unwrap();
    assert!((fitted - 0.5).abs() < 1e-4, "fit {fitted}");
    assert!(
        (ao_sum / w_sum - 0.5).abs() > 0.01,
        "mean {}",
        ao_sum / w_sum
    );
    // A ridge pulls the fit towards the mean but stays between the two.
    let damped = fit.solve(0.02).unwrap();
    assert!(damped > fitted && damped < ao_sum / w_sum, "{damped}");
}

#[test]
fn the_fit_stays_within_the_values_it_was_given() {
    let mut fit = LinearFit::new(Vec3::Y);
    // All points on one side, steep values: the extrapolated plane would leave [0.2, 0.9].
    for (k, ao) in [0.2, 0.5, 0.9].into_iter().enumerate() {
        let x = 0.01 + 0.01 * k as f32;
        fit.add(1.0, Vec3::new(x, 0.0, 0.0), ao);
        fit.add(1.0, Vec3::new(x, 0.0, 0.01), ao);
    }
    let v = fit.solve(0.0).unwrap();
    assert!((0.2..=0.9).contains(&v), "{v}");
}

#[test]
fn collinear_points_without_ridge_give_the_weighted_mean_and_no_points_give_none() {
    assert_eq!(LinearFit::new(Vec3::Z).solve(0.5), None);
    let mut fit = LinearFit::new(Vec3::Z);
    fit.add(1.0, Vec3::ZERO, 0.3);
    fit.add(3.0, Vec3::ZERO, 0.7);
    let v = fit.solve(0.0).unwrap();
    assert!((v - 0.6).abs() < 1e-6, "{v}");
}
