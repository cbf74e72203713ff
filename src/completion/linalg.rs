//! Tiny dense kernels for the per-track and per-frame r×r systems (r ≤ a few), where a
//! general-purpose factorisation would cost more in overhead than in flops.

/// In-place Cholesky `A = L Lᵀ` of a row-major n×n SPD matrix (lower triangle used and
/// overwritten with `L`). Returns false if a pivot is not positive. `O(n³/6)`.
pub(crate) fn cholesky(a: &mut [f64], n: usize) -> bool {
    for j in 0..n {
        let mut d = a[j * n + j];
        for k in 0..j {
            d -= a[j * n + k] * a[j * n + k];
        }
        if !(d > 0.0 && d.is_finite()) {
            return false;
        }
        let d = d.sqrt();
        a[j * n + j] = d;
        for i in j + 1..n {
            let mut v = a[i * n + j];
            for k in 0..j {
                v -= a[i * n + k] * a[j * n + k];
            }
            a[i * n + j] = v / d;
        }
    }
    true
}

/// Solves `L Lᵀ x = b` in place given the factor from [`cholesky`].
pub(crate) fn chol_solve(l: &[f64], n: usize, b: &mut [f64]) {
    for i in 0..n {
        let mut v = b[i];
        for k in 0..i {
            v -= l[i * n + k] * b[k];
        }
        b[i] = v / l[i * n + i];
    }
    for i in (0..n).rev() {
        let mut v = b[i];
        for k in i + 1..n {
            v -= l[k * n + i] * b[k];
        }
        b[i] = v / l[i * n + i];
    }
}

/// `A⁻¹` (row-major n×n) from the Cholesky factor.
pub(crate) fn chol_inverse(l: &[f64], n: usize, inv: &mut [f64]) {
    let mut e = vec![0.0; n];
    for j in 0..n {
        e.iter_mut().for_each(|x| *x = 0.0);
        e[j] = 1.0;
        chol_solve(l, n, &mut e);
        for i in 0..n {
            inv[i * n + j] = e[i];
        }
    }
}

/// Solves the SPD system `A x = b` in place (`a` row-major, overwritten by its Cholesky
/// factor). If `A` is not numerically positive definite, a growing ridge
/// (1e-12, 1e-9, 1e-6 times the mean diagonal) is added. Returns false (x unspecified)
/// if even that fails, e.g. for non-finite input.
pub(crate) fn spd_solve_robust(a: &mut [f64], n: usize, b: &mut [f64]) -> bool {
    let orig: Vec<f64> = a[..n * n].to_vec();
    if cholesky(a, n) {
        chol_solve(a, n, b);
        return true;
    }
    let mean_diag = ((0..n).map(|i| orig[i * n + i].abs()).sum::<f64>() / n.max(1) as f64)
        .max(f64::MIN_POSITIVE);
    for ridge in [1e-12, 1e-9, 1e-6] {
        a[..n * n].copy_from_slice(&orig);
        for i in 0..n {
            a[i * n + i] += ridge * mean_diag;
        }
        if cholesky(a, n) {
            chol_solve(a, n, b);
            return true;
        }
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_and_inverts_spd_system() {
        // A = Bᵀ B + I for a fixed B.
        let b = [1.0, 2.0, 0.5, -1.0, 0.3, 2.0, 0.0, 1.5, -0.7];
        let n = 3;
        let mut a = vec![0.0; 9];
        for i in 0..n {
            for j in 0..n {
                a[i * n + j] = (0..n).map(|k| b[k * n + i] * b[k * n + j]).sum::<f64>()
                    + if i == j { 1.0 } else { 0.0 };
            }
        }
        let x_true = [0.3, -1.2, 2.5];
        let mut rhs: Vec<f64> = (0..n)
            .map(|i| (0..n).map(|j| a[i * n + j] * x_true[j]).sum())
            .collect();
        let mut f = a.clone();
        assert!(spd_solve_robust(&mut f, n, &mut rhs));
        for i in 0..n {
            assert!((rhs[i] - x_true[i]).abs() < 1e-12);
        }
        let mut inv = vec![0.0; 9];
        chol_inverse(&f, n, &mut inv);
        for i in 0..n {
            for j in 0..n {
                let v: f64 = (0..n).map(|k| a[i * n + k] * inv[k * n + j]).sum();
                assert!((v - if i == j { 1.0 } else { 0.0 }).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn singular_system_gets_a_ridge_and_stays_finite() {
        let mut a = vec![1.0, 1.0, 1.0, 1.0];
        let mut b = vec![2.0, 2.0];
        assert!(spd_solve_robust(&mut a, 2, &mut b));
        assert!(b.iter().all(|x| x.is_finite()));
        // The ridge solution of the consistent system x0 + x1 = 2 is close to (1, 1).
        assert!((b[0] - 1.0).abs() < 1e-3 && (b[1] - 1.0).abs() < 1e-3);
    }
}
