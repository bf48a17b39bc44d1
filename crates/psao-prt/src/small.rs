//! Tiny dense solves (at most 16 unknowns) done inline per vertex: a general library call
//! (faer) costs more in setup than these few dozen flops, so they are written here.

/// Solves the symmetric positive (semi)definite system `a · x = b` of size `n` (row-major
/// `a`, n×n) by Cholesky after adding `ridge` to the diagonal; `None` when it stays singular.
pub fn solve_spd(a: &mut [f64], b: &mut [f64], n: usize, ridge: f64) -> Option<()> {
    for i in 0..n {
        a[i * n + i] += ridge;
    }
    // In-place Cholesky: lower triangle holds L.
    for j in 0..n {
        let mut d = a[j * n + j];
        for k in 0..j {
            d -= a[j * n + k] * a[j * n + k];
        }
        if d <= 0.0 || !d.is_finite() {
            return None;
        }
        let d = d.sqrt();
        a[j * n + j] = d;
        for i in j + 1..n {
            let mut s = a[i * n + j];
            for k in 0..j {
                s -= a[i * n + k] * a[j * n + k];
            }
            a[i * n + j] = s / d;
        }
    }
    for i in 0..n {
        let mut s = b[i];
        for k in 0..i {
            s -= a[i * n + k] * b[k];
        }
        b[i] = s / a[i * n + i];
    }
    for i in (0..n).rev() {
        let mut s = b[i];
        for k in i + 1..n {
            s -= a[k * n + i] * b[k];
        }
        b[i] = s / a[i * n + i];
    }
    Some(())
}

/// The Moore–Penrose inverse `(YᵀY)⁻¹Yᵀ` of a full-column-rank `rows`×`cols` matrix
/// (row-major), as a `cols`×`rows` row-major matrix; `None` when rank-deficient.
pub fn pseudo_inverse(y: &[f64], rows: usize, cols: usize) -> Option<Vec<f64>> {
    let mut out = vec![0.0; cols * rows];
    for r in 0..rows {
        let mut gram = vec![0.0; cols * cols];
        for i in 0..cols {
            for j in 0..cols {
                gram[i * cols + j] = (0..rows).map(|k| y[k * cols + i] * y[k * cols + j]).sum();
            }
        }
        let mut rhs: Vec<f64> = (0..cols).map(|i| y[r * cols + i]).collect();
        solve_spd(&mut gram, &mut rhs, cols, 0.0)?;
        for i in 0..cols {
            out[i * rows + r] = rhs[i];
        }
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_a_small_system() {
        let mut a = vec![4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0];
        let a0 = a.clone();
        let mut b = vec![1.0, 2.0, 3.0];
        solve_spd(&mut a, &mut b, 3, 0.0).unwrap();
        for i in 0..3 {
            let r: f64 = (0..3).map(|j| a0[i * 3 + j] * b[j]).sum();
            assert!((r - [1.0, 2.0, 3.0][i]).abs() < 1e-12);
        }
        let mut singular = vec![1.0, 1.0, 1.0, 1.0];
        assert!(solve_spd(&mut singular, &mut [1.0, 1.0], 2, 0.0).is_none());
    }

    #[test]
    fn pseudo_inverse_inverts_on_the_left() {
        let y = [1.0, 2.0, 0.0, 1.0, 3.0, -1.0];
        let p = pseudo_inverse(&y, 3, 2).unwrap();
        for i in 0..2 {
            for j in 0..2 {
                let v: f64 = (0..3).map(|k| p[i * 3 + k] * y[k * 2 + j]).sum();
                assert!((v - if i == j { 1.0 } else { 0.0 }).abs() < 1e-12);
            }
        }
    }
}
