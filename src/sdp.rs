//! PSD-constrained linear least squares for the metric upgrade of an affine factorization.
//!
//! The metric upgrade looks for the symmetric 3×3 matrix `L = Q Qᵀ` (Q the affine-to-metric
//! correction) that makes every camera's rows orthonormal: for each frame's affine rows
//! `i`, `j`, `iᵀ L i = 1`, `jᵀ L j = 1`, `iᵀ L j = 0` (orthographic; Tomasi & Kanade 1992,
//! §3.3) or `iᵀ L i − jᵀ L j = 0`, `iᵀ L j = 0` with one normalisation (scaled orthographic;
//! Poelman & Kanade 1997). These are linear in `L`; solved by plain least squares the
//! estimate can come out indefinite on noisy data, so that `Q` does not exist. Here the
//! least-squares problem is solved over the PSD cone instead.
//!
//! # Parameterisation
//!
//! `L` is represented by the 6-vector `l = [L00, L01, L02, L11, L12, L22]` (upper triangle,
//! row by row). A constraint `aᵀ L b` has the coefficient row
//! `[a0b0, a0b1 + a1b0, a0b2 + a2b0, a1b1, a1b2 + a2b1, a2b2]` (see [`bilinear_row`]).

use std::time::Instant;

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettings, DefaultSolver, IPSolver, PSDTriangleConeT, SolverStatus, SupportedConeT,
    ZeroConeT,
};
use nalgebra::{DMatrix, Matrix3, SymmetricEigen, Vector3};

use crate::error::{Error, Result};

/// Settings of [`psd_least_squares`]. All tolerances refer to the internally rescaled
/// problem (see [`psd_least_squares`]), where the objective and the unknown are O(1).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SdpSettings {
    /// Absolute duality-gap tolerance. Default `1e-10`.
    pub tol_gap_abs: f64,
    /// Relative duality-gap tolerance. Default `1e-10`.
    pub tol_gap_rel: f64,
    /// Primal/dual feasibility tolerance. Default `1e-10`.
    pub tol_feas: f64,
    /// Maximum number of interior-point iterations. Default `100`.
    pub max_iter: u32,
    /// Print clarabel's iteration log to stdout. Default `false`.
    pub verbose: bool,
}

impl Default for SdpSettings {
    fn default() -> Self {
        SdpSettings {
            tol_gap_abs: 1e-10,
            tol_gap_rel: 1e-10,
            tol_feas: 1e-10,
            max_iter: 100,
            verbose: false,
        }
    }
}

/// How the interior-point solver ended. Not an error: the returned `L` is the last iterate
/// (projected onto the PSD cone) in every case.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SdpStatus {
    /// Converged to the requested tolerances.
    Solved,
    /// Converged to clarabel's reduced ("almost") tolerances.
    AlmostSolved,
    /// Hit [`SdpSettings::max_iter`].
    MaxIterations,
    /// Anything else (infeasible equality constraint, numerical trouble, …): clarabel's
    /// status name.
    Other(String),
}

/// Result of [`psd_least_squares`].
#[derive(Debug, Clone)]
pub struct PsdLsqSolution {
    /// The symmetric PSD estimate of `L`.
    pub l: Matrix3<f64>,
    /// `‖A l − b‖²` at the returned `l`, evaluated on the original (unscaled) data.
    pub objective: f64,
    /// How the solver ended.
    pub status: SdpStatus,
    /// Interior-point iterations.
    pub iterations: u32,
    /// Wall-clock seconds spent in this call.
    pub seconds: f64,
}

/// Coefficient row of the bilinear form `aᵀ L b` in the parameterisation
/// `l = [L00, L01, L02, L11, L12, L22]`.
pub fn bilinear_row(a: &Vector3<f64>, b: &Vector3<f64>) -> [f64; 6] {
    [
        a[0] * b[0],
        a[0] * b[1] + a[1] * b[0],
        a[0] * b[2] + a[2] * b[0],
        a[1] * b[1],
        a[1] * b[2] + a[2] * b[1],
        a[2] * b[2],
    ]
}

/// The symmetric matrix with parameter vector `l = [L00, L01, L02, L11, L12, L22]`.
pub fn sym_from_params(l: &[f64; 6]) -> Matrix3<f64> {
    Matrix3::new(l[0], l[1], l[2], l[1], l[3], l[4], l[2], l[4], l[5])
}

/// The parameter vector `[L00, L01, L02, L11, L12, L22]` of a symmetric matrix (upper
/// triangle is read).
pub fn params_from_sym(m: &Matrix3<f64>) -> [f64; 6] {
    [
        m[(0, 0)],
        m[(0, 1)],
        m[(0, 2)],
        m[(1, 1)],
        m[(1, 2)],
        m[(2, 2)],
    ]
}

/// Solves `min_l ‖A l − b‖²` subject to `L(l) ⪰ 0` and, optionally, `c·l = d`.
///
/// `a` holds the rows of `A` (m×6) in the parameterisation
/// `l = [L00, L01, L02, L11, L12, L22]`; `b` has length m. `equality = Some((c, d))` adds
/// the linear constraint `c·l = d` (the normalisation of the scaled-orthographic upgrade,
/// where `b = 0`). The 3×3 case of [`psd_least_squares_sym`], which documents the method.
///
/// Errors: [`Error::TooFew`] if `a` is empty, [`Error::Dimension`] if `b.len() != a.len()`,
/// [`Error::Degenerate`] for non-finite input, [`Error::InvalidConfig`] for bad settings,
/// [`Error::Numerical`] if clarabel rejects the assembled problem. How the solver ended is
/// reported in [`PsdLsqSolution::status`].
pub fn psd_least_squares(
    a: &[[f64; 6]],
    b: &[f64],
    equality: Option<([f64; 6], f64)>,
    settings: &SdpSettings,
) -> Result<PsdLsqSolution> {
    let rows: Vec<Vec<f64>> = a.iter().map(|r| r.to_vec()).collect();
    let eq = equality.as_ref().map(|(c, d)| (&c[..], *d));
    let sol = psd_least_squares_sym(3, &rows, b, eq, settings)?;
    Ok(PsdLsqSolution {
        l: Matrix3::from_fn(|i, j| sol.l[(i, j)]),
        objective: sol.objective,
        status: sol.status,
        iterations: sol.iterations,
        seconds: sol.seconds,
    })
}

/// Result of [`psd_least_squares_sym`].
#[derive(Debug, Clone)]
pub struct SymPsdSolution {
    /// The symmetric PSD estimate (n×n).
    pub l: DMatrix<f64>,
    /// `‖A l − b‖²` at the returned `l`, on the original (unscaled) data.
    pub objective: f64,
    /// How the solver ended.
    pub status: SdpStatus,
    /// Interior-point iterations.
    pub iterations: u32,
    /// Wall-clock seconds spent in this call.
    pub seconds: f64,
}

/// `(row, col)` of each parameter of a symmetric n×n matrix: the upper triangle, row by
/// row (`n = 3`: `[L00, L01, L02, L11, L12, L22]`; `n = 4` is the absolute dual quadric's
/// 10-vector).
pub fn sym_index(n: usize) -> Vec<(usize, usize)> {
    (0..n).flat_map(|i| (i..n).map(move |j| (i, j))).collect()
}

/// Coefficient row of the bilinear form `aᵀ L b` in the parameterisation of [`sym_index`].
pub fn bilinear_row_n(a: &[f64], b: &[f64]) -> Vec<f64> {
    sym_index(a.len())
        .into_iter()
        .map(|(i, j)| {
            if i == j {
                a[i] * b[i]
            } else {
                a[i] * b[j] + a[j] * b[i]
            }
        })
        .collect()
}

/// Solves `min_l ‖A l − b‖²` subject to `L(l) ⪰ 0` (n×n symmetric, parameters as in
/// [`sym_index`]) and, optionally, `c·l = d`.
///
/// Method: the quadratic cone program
/// `min ½ xᵀPx + qᵀx  s.t.  svec(L(x)) ∈ Sⁿ₊ (, c·x = d)` with `P = 2AᵀA`, `q = −2Aᵀb`,
/// solved by clarabel's primal-dual interior-point method (Goulden, Stellato & Banjac,
/// "Clarabel: an interior-point solver for conic programs with quadratic objectives",
/// arXiv:2405.12762, 2024), PSD cone in the scaled-triangle (svec) convention
/// (upper triangle column by column, off-diagonal entries times √2). Before solving, the
/// problem is rescaled: a congruence `L = T Ľ T` with `T = diag(t)`, `t_k = ‖A[:, kk]‖^{-1/2}`
/// (unit-norm diagonal columns, preserves the cone), the unknown is divided by an estimate
/// `ρ` of its magnitude and the objective by the mean squared column norm, so that `P`, `q`
/// and the solution are O(1) whatever the magnitude of the rows; the answer is mapped back.
/// The returned `L` is symmetrised and, if the solver stopped slightly outside the cone,
/// projected onto it (negative eigenvalues clamped).
///
/// Complexity: O(m p²) to form `AᵀA` (`p = n(n+1)/2` unknowns), then a fixed-size conic
/// solve (each interior-point iteration is O(p³), independent of m; typically 10–30
/// iterations).
///
/// Errors as [`psd_least_squares`]; [`Error::Dimension`] also when a row's length is not
/// `n(n+1)/2`.
pub fn psd_least_squares_sym(
    n: usize,
    a: &[Vec<f64>],
    b: &[f64],
    equality: Option<(&[f64], f64)>,
    settings: &SdpSettings,
) -> Result<SymPsdSolution> {
    let start = Instant::now();
    let ij = sym_index(n);
    let np = ij.len();
    validate(np, a, b, equality, settings)?;
    #[cfg(feature = "builtin-lapack")]
    crate::lapack_shim::ensure_linked();

    // Normal equations: M = AᵀA, v = Aᵀb.
    let mut m = vec![vec![0.0f64; np]; np];
    let mut v = vec![0.0f64; np];
    for (row, &bi) in a.iter().zip(b) {
        for p in 0..np {
            v[p] += row[p] * bi;
            for q in p..np {
                m[p][q] += row[p] * row[q];
            }
        }
    }
    for p in 0..np {
        for q in 0..p {
            m[p][q] = m[q][p];
        }
    }
    let diag_param: Vec<usize> = (0..n)
        .map(|i| ij.iter().position(|&(r, c)| r == i && c == i).unwrap_or(0))
        .collect();

    // Congruence scaling t (unit diagonal columns), τ_k = t_i t_j for parameter k = (i, j).
    let diag_norms: Vec<f64> = diag_param.iter().map(|&k| m[k][k].sqrt()).collect();
    let positive: Vec<f64> = diag_norms.iter().copied().filter(|x| *x > 0.0).collect();
    let fallback = if positive.is_empty() {
        1.0
    } else {
        positive
            .iter()
            .product::<f64>()
            .powf(1.0 / positive.len() as f64)
    };
    let t: Vec<f64> = diag_norms
        .iter()
        .map(|&nm| 1.0 / if nm > 0.0 { nm } else { fallback }.sqrt())
        .collect();
    let tau: Vec<f64> = ij.iter().map(|&(i, j)| t[i] * t[j]).collect();
    // Scaled normal equations: M̃ = D M D, ṽ = D v with D = diag(τ).
    let ms: Vec<Vec<f64>> = (0..np)
        .map(|p| (0..np).map(|q| tau[p] * m[p][q] * tau[q]).collect())
        .collect();
    let vs: Vec<f64> = (0..np).map(|p| tau[p] * v[p]).collect();
    let sigma = {
        let tr: f64 = (0..np).map(|p| ms[p][p]).sum::<f64>() / np as f64;
        if tr > 0.0 && tr.is_finite() { tr } else { 1.0 }
    };
    let bnorm = b.iter().map(|x| x * x).sum::<f64>().sqrt();
    // Magnitude of the unknown in scaled coordinates: ‖b‖/√σ (LS scale), or |d|/‖c̃‖.
    let ceq: Option<(Vec<f64>, f64)> =
        equality.map(|(c, d)| ((0..np).map(|k| c[k] * tau[k]).collect(), d));
    let rho = if bnorm > 0.0 {
        bnorm / sigma.sqrt()
    } else if let Some((cs, d)) = &ceq {
        let cn = cs.iter().map(|x| x * x).sum::<f64>().sqrt();
        if *d != 0.0 && cn > 0.0 {
            d.abs() / cn
        } else {
            1.0
        }
    } else {
        1.0
    };

    // z = x̃ / ρ; objective (‖Ã ρ z − b‖² − ‖b‖²) / (ρ² σ) = zᵀ(M̃/σ)z − 2 (ṽ/(ρσ))ᵀz.
    let mut colptr = Vec::with_capacity(np + 1);
    let mut rowval = Vec::new();
    let mut nzval = Vec::new();
    colptr.push(0);
    for q in 0..np {
        for (p, row) in ms.iter().enumerate().take(q + 1) {
            rowval.push(p);
            nzval.push(2.0 * row[q] / sigma);
        }
        colptr.push(rowval.len());
    }
    let p_mat = CscMatrix::new(np, np, colptr, rowval, nzval);
    let q_vec: Vec<f64> = vs.iter().map(|x| -2.0 * x / (rho * sigma)).collect();

    // Constraints A_c z + s = b_c: s = svec(Ľ) ∈ Sⁿ₊ → rows −svec map; equality row c̃.
    let r2 = std::f64::consts::SQRT_2;
    let n_rows = if ceq.is_some() { np + 1 } else { np };
    let mut trip_i = Vec::with_capacity(np + 1);
    let mut trip_j = Vec::with_capacity(np + 1);
    let mut trip_v = Vec::with_capacity(np + 1);
    for (k, &(i, j)) in ij.iter().enumerate() {
        // svec position of (i, j), i ≤ j: upper triangle column by column.
        trip_i.push(j * (j + 1) / 2 + i);
        trip_j.push(k);
        trip_v.push(if i == j { -1.0 } else { -r2 });
    }
    let mut b_c = vec![0.0; np];
    let mut cones: Vec<SupportedConeT<f64>> = vec![PSDTriangleConeT(n)];
    if let Some((cs, d)) = &ceq {
        let cn = cs.iter().map(|x| x * x).sum::<f64>().sqrt();
        let cn = if cn > 0.0 { cn } else { 1.0 };
        for (k, ck) in cs.iter().enumerate() {
            if *ck != 0.0 {
                trip_i.push(np);
                trip_j.push(k);
                trip_v.push(ck / cn);
            }
        }
        b_c.push(d / (rho * cn));
        cones.push(ZeroConeT(1));
    }
    let a_mat = CscMatrix::new_from_triplets(n_rows, np, trip_i, trip_j, trip_v);

    let cl_settings = DefaultSettings {
        max_iter: settings.max_iter,
        verbose: settings.verbose,
        tol_gap_abs: settings.tol_gap_abs,
        tol_gap_rel: settings.tol_gap_rel,
        tol_feas: settings.tol_feas,
        ..DefaultSettings::default()
    };
    let mut solver = DefaultSolver::new(&p_mat, &q_vec, &a_mat, &b_c, &cones, cl_settings)
        .map_err(|e| Error::Numerical {
            stage: "psd_least_squares (clarabel setup)",
            message: format!("{e:?}"),
        })?;
    solver.solve();
    let sol = &solver.solution;
    let status = match sol.status {
        SolverStatus::Solved => SdpStatus::Solved,
        SolverStatus::AlmostSolved => SdpStatus::AlmostSolved,
        SolverStatus::MaxIterations => SdpStatus::MaxIterations,
        other => SdpStatus::Other(format!("{other:?}")),
    };

    let mut l = DMatrix::<f64>::zeros(n, n);
    for (k, &(i, j)) in ij.iter().enumerate() {
        let zk = sol.x.get(k).copied().unwrap_or(0.0);
        let val = if zk.is_finite() {
            zk * rho * tau[k]
        } else {
            0.0
        };
        l[(i, j)] = val;
        l[(j, i)] = val;
    }
    let l = project_psd_n(&l);
    let lp: Vec<f64> = ij.iter().map(|&(i, j)| l[(i, j)]).collect();
    let objective: f64 = a
        .iter()
        .zip(b)
        .map(|(row, bi)| {
            let r: f64 = row.iter().zip(&lp).map(|(x, y)| x * y).sum::<f64>() - bi;
            r * r
        })
        .sum();
    Ok(SymPsdSolution {
        l,
        objective,
        status,
        iterations: sol.iterations,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// [`project_psd`] for an n×n matrix.
pub fn project_psd_n(m: &DMatrix<f64>) -> DMatrix<f64> {
    let sym = (m + m.transpose()) * 0.5;
    let eig = sym.clone().symmetric_eigen();
    if eig.eigenvalues.iter().all(|&x| x >= 0.0) {
        return sym;
    }
    let clamped = eig.eigenvalues.map(|x| x.max(0.0));
    let p = &eig.eigenvectors * DMatrix::from_diagonal(&clamped) * eig.eigenvectors.transpose();
    (&p + p.transpose()) * 0.5
}

/// Projection onto the PSD cone in the Frobenius norm (negative eigenvalues set to zero);
/// returns the input unchanged when it is already PSD.
pub fn project_psd(m: &Matrix3<f64>) -> Matrix3<f64> {
    let sym = (m + m.transpose()) * 0.5;
    let eig = SymmetricEigen::new(sym);
    if eig.eigenvalues.iter().all(|&x| x >= 0.0) {
        return sym;
    }
    let clamped = eig.eigenvalues.map(|x| x.max(0.0));
    let p = eig.eigenvectors * Matrix3::from_diagonal(&clamped) * eig.eigenvectors.transpose();
    (p + p.transpose()) * 0.5
}

fn validate(
    np: usize,
    a: &[Vec<f64>],
    b: &[f64],
    equality: Option<(&[f64], f64)>,
    settings: &SdpSettings,
) -> Result<()> {
    if a.is_empty() {
        return Err(Error::TooFew {
            what: "least-squares rows",
            needed: 1,
            have: 0,
        });
    }
    if b.len() != a.len() {
        return Err(Error::Dimension {
            context: "psd_least_squares: rows of A vs length of b",
            expected: a.len().to_string(),
            got: b.len().to_string(),
        });
    }
    if let Some(r) = a.iter().position(|row| row.len() != np) {
        return Err(Error::Dimension {
            context: "psd_least_squares: length of a row of A",
            expected: np.to_string(),
            got: a[r].len().to_string(),
        });
    }
    if let Some((c, _)) = equality
        && c.len() != np
    {
        return Err(Error::Dimension {
            context: "psd_least_squares: length of the equality row",
            expected: np.to_string(),
            got: c.len().to_string(),
        });
    }
    if let Some(r) = a.iter().position(|row| row.iter().any(|x| !x.is_finite())) {
        return Err(Error::Degenerate(format!(
            "psd_least_squares: row {r} of A has a non-finite entry"
        )));
    }
    if let Some(r) = b.iter().position(|x| !x.is_finite()) {
        return Err(Error::Degenerate(format!(
            "psd_least_squares: entry {r} of b is not finite"
        )));
    }
    if let Some((c, d)) = equality {
        if c.iter().any(|x| !x.is_finite()) || !d.is_finite() {
            return Err(Error::Degenerate(
                "psd_least_squares: the equality constraint has a non-finite entry".into(),
            ));
        }
        if c.iter().all(|x| *x == 0.0) {
            return Err(Error::Degenerate(
                "psd_least_squares: the equality constraint has an all-zero coefficient row".into(),
            ));
        }
    }
    for (field, value) in [
        ("tol_gap_abs", settings.tol_gap_abs),
        ("tol_gap_rel", settings.tol_gap_rel),
        ("tol_feas", settings.tol_feas),
    ] {
        if !(value.is_finite() && value > 0.0) {
            return Err(Error::InvalidConfig {
                field,
                message: format!("must be a positive finite number, got {value}"),
            });
        }
    }
    if settings.max_iter == 0 {
        return Err(Error::InvalidConfig {
            field: "max_iter",
            message: "must be at least 1".into(),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix6, Rotation3, UnitQuaternion, Vector6};
    use rand::rngs::StdRng;
    use rand::{RngExt, SeedableRng};
    use rand_distr::StandardNormal;

    fn random_rows(rng: &mut StdRng, m: usize, scale: f64) -> Vec<[f64; 6]> {
        (0..m)
            .map(|_| std::array::from_fn(|_| scale * rng.sample::<f64, _>(StandardNormal)))
            .collect()
    }

    fn apply(a: &[[f64; 6]], l: &[f64; 6]) -> Vec<f64> {
        a.iter()
            .map(|r| r.iter().zip(l).map(|(x, y)| x * y).sum())
            .collect()
    }

    fn objective(a: &[[f64; 6]], b: &[f64], l: &[f64; 6]) -> f64 {
        apply(a, l)
            .iter()
            .zip(b)
            .map(|(x, y)| (x - y).powi(2))
            .sum()
    }

    /// Unconstrained least squares by the normal equations.
    fn ls(a: &[[f64; 6]], b: &[f64]) -> [f64; 6] {
        let mut m = Matrix6::zeros();
        let mut v = Vector6::zeros();
        for (r, bi) in a.iter().zip(b) {
            let r = Vector6::from_column_slice(r);
            m += r * r.transpose();
            v += r * *bi;
        }
        let x = m.cholesky().expect("full column rank").solve(&v);
        std::array::from_fn(|k| x[k])
    }

    fn min_max_eig(m: &Matrix3<f64>) -> (f64, f64) {
        let e = SymmetricEigen::new(*m).eigenvalues;
        (e.min(), e.iter().fold(0.0f64, |acc, x| acc.max(x.abs())))
    }

    fn random_rotation(rng: &mut StdRng) -> Rotation3<f64> {
        let q = nalgebra::Quaternion::new(
            rng.sample::<f64, _>(StandardNormal),
            rng.sample(StandardNormal),
            rng.sample(StandardNormal),
            rng.sample(StandardNormal),
        );
        UnitQuaternion::from_quaternion(q).to_rotation_matrix()
    }

    fn rel_err(a: &Matrix3<f64>, b: &Matrix3<f64>) -> f64 {
        (a - b).norm() / b.norm()
    }

    #[test]
    fn interior_solution_equals_least_squares() {
        let mut rng = StdRng::seed_from_u64(11);
        // Rows of large magnitude to exercise the rescaling.
        let a = random_rows(&mut rng, 15, 300.0);
        let truth = params_from_sym(&Matrix3::new(2.0, 0.3, -0.2, 0.3, 1.5, 0.1, -0.2, 0.1, 0.8));
        let mut b = apply(&a, &truth);
        for x in b.iter_mut() {
            *x += 0.5 * rng.sample::<f64, _>(StandardNormal);
        }
        let l_ls = ls(&a, &b);
        assert!(
            min_max_eig(&sym_from_params(&l_ls)).0 > 0.1,
            "LS solution must be PD"
        );
        let sol = psd_least_squares(&a, &b, None, &SdpSettings::default()).unwrap();
        assert_eq!(sol.status, SdpStatus::Solved);
        let want = sym_from_params(&l_ls);
        assert!(
            rel_err(&sol.l, &want) < 1e-7,
            "rel err {}",
            rel_err(&sol.l, &want)
        );
        let f_ls = objective(&a, &b, &l_ls);
        assert!((sol.objective - f_ls).abs() <= 1e-9 * f_ls.max(1.0));
    }

    #[test]
    fn indefinite_least_squares_is_projected_optimally() {
        let mut rng = StdRng::seed_from_u64(12);
        let a = random_rows(&mut rng, 12, 1.0);
        let r = random_rotation(&mut rng);
        let truth_m = r * Matrix3::from_diagonal(&Vector3::new(2.0, 1.0, -0.7)) * r.transpose();
        let b = apply(&a, &params_from_sym(&truth_m));
        let sol = psd_least_squares(&a, &b, None, &SdpSettings::default()).unwrap();
        assert!(matches!(
            sol.status,
            SdpStatus::Solved | SdpStatus::AlmostSolved
        ));
        let (lo, hi) = min_max_eig(&sol.l);
        assert!(lo >= -1e-8 * hi, "min eig {lo}");
        // No worse than projecting the (here exact, indefinite) LS solution onto the cone.
        let clamped = params_from_sym(&project_psd(&truth_m));
        let f_clamped = objective(&a, &b, &clamped);
        assert!(
            sol.objective <= f_clamped * (1.0 + 1e-9),
            "{} > {f_clamped}",
            sol.objective
        );
        assert!(
            sol.objective > 1e-3,
            "an indefinite target cannot be fitted exactly"
        );
        // KKT: G = ½∇f as a symmetric matrix must be PSD and complementary to L.
        let l = params_from_sym(&sol.l);
        let res: Vec<f64> = apply(&a, &l).iter().zip(&b).map(|(x, y)| x - y).collect();
        let grad: [f64; 6] = std::array::from_fn(|k| {
            2.0 * a.iter().zip(&res).map(|(row, ri)| row[k] * ri).sum::<f64>()
        });
        let g = Matrix3::new(
            grad[0],
            grad[1] / 2.0,
            grad[2] / 2.0,
            grad[1] / 2.0,
            grad[3],
            grad[4] / 2.0,
            grad[2] / 2.0,
            grad[4] / 2.0,
            grad[5],
        );
        let (glo, ghi) = min_max_eig(&g);
        assert!(glo >= -1e-6 * ghi, "dual not PSD: {glo}");
        let compl = (g.component_mul(&sol.l)).sum();
        assert!(
            compl.abs() <= 1e-6 * g.norm() * sol.l.norm(),
            "⟨G, L⟩ = {compl}"
        );
        assert!(
            glo.abs() < 1e-6 * ghi && lo.abs() < 1e-6 * hi,
            "rank-deficient pair"
        );
    }

    /// Rows of the scaled-orthographic metric constraints for affine rows (î, ĵ):
    /// îᵀLî − ĵᵀLĵ = 0 and îᵀLĵ = 0.
    fn scaled_orthographic_rows(ih: &Vector3<f64>, jh: &Vector3<f64>) -> [[f64; 6]; 2] {
        let ii = bilinear_row(ih, ih);
        let jj = bilinear_row(jh, jh);
        [std::array::from_fn(|k| ii[k] - jj[k]), bilinear_row(ih, jh)]
    }

    /// Affine rows (î, ĵ) per frame and the true L.
    type Instance = (Vec<(Vector3<f64>, Vector3<f64>)>, Matrix3<f64>);

    /// Random metric-upgrade instance: F rotations, true L = Q Qᵀ, affine rows Q⁻ᵀ i (times a
    /// per-frame scale `s_f` when `scaled`). Returns (frames' affine rows, true L).
    fn upgrade_instance(rng: &mut StdRng, frames: usize, scaled: bool) -> Instance {
        let q = loop {
            let q = Matrix3::from_fn(|_, _| rng.sample::<f64, _>(StandardNormal));
            if q.determinant().abs() > 0.2 {
                break q * 3.0;
            }
        };
        let q_inv_t = q.try_inverse().unwrap().transpose();
        let rows = (0..frames)
            .map(|_| {
                let r = random_rotation(rng);
                let s = if scaled {
                    rng.random_range(0.5..2.0)
                } else {
                    1.0
                };
                let i: Vector3<f64> = r.matrix().row(0).transpose() * s;
                let j: Vector3<f64> = r.matrix().row(1).transpose() * s;
                (q_inv_t * i, q_inv_t * j)
            })
            .collect();
        (rows, q * q.transpose())
    }

    #[test]
    fn equality_constrained_scaled_orthographic_upgrade() {
        let mut rng = StdRng::seed_from_u64(13);
        let (rows, truth) = upgrade_instance(&mut rng, 10, true);
        let a: Vec<[f64; 6]> = rows
            .iter()
            .flat_map(|(i, j)| scaled_orthographic_rows(i, j))
            .collect();
        let b = vec![0.0; a.len()];
        // Normalisation: the first frame's î has îᵀLî = (its true value).
        let c = bilinear_row(&rows[0].0, &rows[0].0);
        let d = (rows[0].0.transpose() * truth * rows[0].0)[(0, 0)];
        let sol = psd_least_squares(&a, &b, Some((c, d)), &SdpSettings::default()).unwrap();
        assert!(matches!(
            sol.status,
            SdpStatus::Solved | SdpStatus::AlmostSolved
        ));
        let l = params_from_sym(&sol.l);
        let cl: f64 = c.iter().zip(&l).map(|(x, y)| x * y).sum();
        assert!((cl - d).abs() <= 1e-8 * d.abs(), "c·l = {cl}, d = {d}");
        assert!(
            rel_err(&sol.l, &truth) < 1e-6,
            "rel err {}",
            rel_err(&sol.l, &truth)
        );
        // Without the normalisation every multiple of the truth is a minimiser (objective 0):
        // the answer must lie on that ray.
        let free = psd_least_squares(&a, &b, None, &SdpSettings::default()).unwrap();
        let n = free.l.norm();
        let cos = free.l.component_mul(&truth).sum() / (n * truth.norm()).max(f64::MIN_POSITIVE);
        assert!(n < 1e-9 || 1.0 - cos < 1e-8, "|L| = {n}, cos = {cos}");
    }

    #[test]
    fn orthographic_metric_upgrade_recovers_l() {
        let mut rng = StdRng::seed_from_u64(14);
        let (rows, truth) = upgrade_instance(&mut rng, 20, false);
        let mut a = Vec::new();
        let mut b = Vec::new();
        for (i, j) in &rows {
            a.extend([bilinear_row(i, i), bilinear_row(j, j), bilinear_row(i, j)]);
            b.extend([1.0, 1.0, 0.0]);
        }
        let sol = psd_least_squares(&a, &b, None, &SdpSettings::default()).unwrap();
        assert_eq!(sol.status, SdpStatus::Solved);
        assert!(
            rel_err(&sol.l, &truth) < 1e-6,
            "rel err {}",
            rel_err(&sol.l, &truth)
        );
        assert!(sol.objective < 1e-10 * a.len() as f64);
        assert!(sol.iterations > 0 && sol.seconds >= 0.0);
    }

    #[test]
    fn bad_input_is_an_error() {
        let s = SdpSettings::default();
        assert!(matches!(
            psd_least_squares(&[], &[], None, &s),
            Err(Error::TooFew { .. })
        ));
        let a = [[1.0; 6]; 2];
        assert!(matches!(
            psd_least_squares(&a, &[1.0], None, &s),
            Err(Error::Dimension { .. })
        ));
        let mut bad = a;
        bad[1][3] = f64::NAN;
        assert!(matches!(
            psd_least_squares(&bad, &[1.0, 1.0], None, &s),
            Err(Error::Degenerate(_))
        ));
        assert!(matches!(
            psd_least_squares(&a, &[1.0, f64::INFINITY], None, &s),
            Err(Error::Degenerate(_))
        ));
        assert!(matches!(
            psd_least_squares(&a, &[1.0, 1.0], Some(([0.0; 6], 1.0)), &s),
            Err(Error::Degenerate(_))
        ));
        let zero_iter = SdpSettings {
            max_iter: 0,
            ..SdpSettings::default()
        };
        assert!(matches!(
            psd_least_squares(&a, &[1.0, 1.0], None, &zero_iter),
            Err(Error::InvalidConfig {
                field: "max_iter",
                ..
            })
        ));
    }

    #[test]
    fn max_iterations_is_reported_as_status() {
        let mut rng = StdRng::seed_from_u64(15);
        let a = random_rows(&mut rng, 10, 1.0);
        let b: Vec<f64> = (0..10).map(|_| rng.sample(StandardNormal)).collect();
        let s = SdpSettings {
            max_iter: 1,
            ..SdpSettings::default()
        };
        let sol = psd_least_squares(&a, &b, None, &s).unwrap();
        assert_eq!(sol.status, SdpStatus::MaxIterations);
        assert!(min_max_eig(&sol.l).0 >= 0.0);
    }
}
