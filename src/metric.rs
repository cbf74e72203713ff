//! Metric upgrade: from an affine factorization `W ≈ M̂ Ŝ` to metric cameras.
//!
//! Any invertible `Q` gives another factorization `(M̂Q)(Q⁻¹Ŝ)`. The metric one makes each
//! frame's camera rows `i_f = Qᵀî_f`, `j_f = Qᵀĵ_f` orthonormal (orthographic) or orthogonal
//! with equal norms (scaled orthographic). With `L = QQᵀ` (symmetric, 6 unknowns
//! `l = [L00, L01, L02, L11, L12, L22]`) every constraint `aᵀ L b` is linear in `l`:
//!
//! `aᵀLb = a0b0·L00 + (a0b1+a1b0)·L01 + (a0b2+a2b0)·L02 + a1b1·L11 + (a1b2+a2b1)·L12 + a2b2·L22`.
//!
//! * **Orthographic** (Tomasi & Kanade 1992): per frame `îᵀLî = 1`, `ĵᵀLĵ = 1`, `îᵀLĵ = 0`;
//!   `min ‖A l − b‖²` over the 3F rows by linear least squares (QR). At least 3 frames:
//!   two orthographic views leave a one-parameter family of structures (Ullman, "The
//!   interpretation of visual motion", MIT Press 1979), and their 6 equations in the 6
//!   unknowns of `L` are dependent.
//! * **Scaled orthographic** (Poelman & Kanade 1997, §4): per frame `îᵀLî − ĵᵀLĵ = 0`,
//!   `îᵀLĵ = 0`, plus one normalization `(1/2F) Σ_f (îᵀLî + ĵᵀLĵ) = 1` (mean squared scale
//!   1); `min ‖A l‖²` subject to that equality, solved through its KKT system.
//!
//! `L` must be positive definite. Noise, too few frames or near-degenerate motion can make
//! the least-squares `L` indefinite; then (smallest eigenvalue below `pd_tolerance` times
//! the largest) the same objective is minimized subject to `L ⪰ 0` as a semidefinite
//! program ([`crate::sdp`], Clarabel). The path taken and the least-squares `L`'s
//! eigenvalues are reported. `Q = U_L Λ^{1/2}` from `L`'s eigendecomposition (eigenvalues
//! floored at `pd_tolerance·λ_max` so `Q` stays invertible when the SDP returns a boundary
//! point).
//!
//! Cost: O(F) to assemble, O(F) for the 6-unknown least squares, O(1) SDP size (3×3 cone).

use faer::MatRef;
use faer::linalg::solvers::SolveLstsq;
use nalgebra::{Matrix2x3, Matrix3, Rotation3, SymmetricEigen, Vector3};
use serde::{Deserialize, Serialize};

use crate::sdp::{SdpSettings, bilinear_row, params_from_sym, psd_least_squares, sym_from_params};
use crate::{CameraModel, Error, Result};

/// Settings of the metric upgrade.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct MetricConfig {
    /// `L` counts as positive definite when `λ_min > pd_tolerance · λ_max`. Default 1e-6.
    pub pd_tolerance: f64,
    /// Force the SDP path even when least squares gives a PD `L` (for comparison).
    /// Default false.
    pub force_sdp: bool,
    /// Settings of the SDP solver.
    pub sdp: SdpSettings,
}

impl Default for MetricConfig {
    fn default() -> Self {
        Self {
            pd_tolerance: 1e-6,
            force_sdp: false,
            sdp: SdpSettings::default(),
        }
    }
}

/// Which path solved for `L`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum UpgradeMethod {
    /// Linear least squares gave a positive definite `L`.
    LeastSquares,
    /// The PSD-constrained semidefinite program.
    Sdp,
}

/// Result of the metric upgrade.
#[derive(Debug, Clone, Serialize)]
pub struct MetricUpgrade {
    pub method: UpgradeMethod,
    /// Smallest eigenvalue of the least-squares `L` (negative or tiny → SDP path).
    pub min_eigenvalue_ls: f64,
    /// Eigenvalues of the least-squares `L`, ascending.
    pub eigenvalues_ls: [f64; 3],
    /// Eigenvalues of the `L` used, ascending.
    pub eigenvalues: [f64; 3],
    /// The `L` used (row-major 3×3).
    pub l: [[f64; 3]; 3],
    /// RMS of the constraint residuals `A l − b` at the `L` used.
    pub constraint_rms: f64,
    /// SDP solver status and iterations, when the SDP ran.
    pub sdp_status: Option<String>,
    pub sdp_iterations: Option<u32>,
    #[serde(skip)]
    pub q: Matrix3<f64>,
}

fn row3(m: MatRef<'_, f64>, r: usize) -> Vector3<f64> {
    Vector3::new(m[(r, 0)], m[(r, 1)], m[(r, 2)])
}

fn sorted_eigs(l: &Matrix3<f64>) -> [f64; 3] {
    let mut e: Vec<f64> = SymmetricEigen::new(*l)
        .eigenvalues
        .iter()
        .copied()
        .collect();
    e.sort_by(|a, b| a.total_cmp(b));
    [e[0], e[1], e[2]]
}

/// Solves for `L = QQᵀ` from the affine motion `M̂` (2F×3, rows `2f` = î_f, `2f+1` = ĵ_f)
/// and returns it with `Q`. See the module documentation for the objective.
pub fn upgrade(
    m_hat: MatRef<'_, f64>,
    camera: CameraModel,
    cfg: &MetricConfig,
) -> Result<MetricUpgrade> {
    if m_hat.ncols() != 3 || m_hat.nrows() % 2 != 0 {
        return Err(Error::Dimension {
            context: "metric upgrade",
            expected: "2F×3 affine motion".into(),
            got: format!("{}×{}", m_hat.nrows(), m_hat.ncols()),
        });
    }
    let f = m_hat.nrows() / 2;
    // Every model needs 3 frames: two orthographic views leave a one-parameter family of
    // structures (module documentation); two scaled orthographic views leave more.
    let needed = 3;
    if f < needed {
        return Err(Error::TooFew {
            what: "frames for the metric upgrade",
            needed,
            have: f,
        });
    }
    // Normalize M̂ so its entries are O(1): L scales by 1/c², undone below.
    let c = {
        let mut ss = 0.0;
        for r in 0..2 * f {
            ss += row3(m_hat, r).norm_squared();
        }
        (ss / (2 * f) as f64).sqrt()
    };
    if !(c.is_finite() && c > 0.0) {
        return Err(Error::Degenerate(
            "the affine motion is zero or not finite (no image motion?)".into(),
        ));
    }
    let rows: Vec<(Vector3<f64>, Vector3<f64>)> = (0..f)
        .map(|k| (row3(m_hat, 2 * k) / c, row3(m_hat, 2 * k + 1) / c))
        .collect();

    let mut a: Vec<[f64; 6]> = Vec::with_capacity(3 * f);
    let mut b: Vec<f64> = Vec::with_capacity(3 * f);
    let mut equality = None;
    match camera {
        CameraModel::Orthographic => {
            for (i, j) in &rows {
                a.push(bilinear_row(i, i));
                b.push(1.0);
                a.push(bilinear_row(j, j));
                b.push(1.0);
                a.push(bilinear_row(i, j));
                b.push(0.0);
            }
        }
        CameraModel::ScaledOrthographic
        | CameraModel::Projective
        | CameraModel::Perspective
        | CameraModel::Auto => {
            let mut norm = [0.0; 6];
            for (i, j) in &rows {
                let ii = bilinear_row(i, i);
                let jj = bilinear_row(j, j);
                a.push(std::array::from_fn(|k| ii[k] - jj[k]));
                b.push(0.0);
                a.push(bilinear_row(i, j));
                b.push(0.0);
                for k in 0..6 {
                    norm[k] += (ii[k] + jj[k]) / (2 * f) as f64;
                }
            }
            equality = Some((norm, 1.0));
        }
    }

    let l_ls = solve_ls(&a, &b, equality)?;
    let big_l_ls = sym_from_params(&l_ls);
    let eig_ls = sorted_eigs(&big_l_ls);
    let is_pd = eig_ls[0] > cfg.pd_tolerance * eig_ls[2].abs() && eig_ls[2] > 0.0;

    let (method, l, sdp_status, sdp_iterations) = if is_pd && !cfg.force_sdp {
        (UpgradeMethod::LeastSquares, l_ls, None, None)
    } else {
        let sol = psd_least_squares(&a, &b, equality, &cfg.sdp)?;
        let l = params_from_sym(&sol.l);
        (
            UpgradeMethod::Sdp,
            l,
            Some(format!("{:?}", sol.status)),
            Some(sol.iterations),
        )
    };
    let big_l = sym_from_params(&l);
    let constraint_rms = {
        let ss: f64 = a
            .iter()
            .zip(&b)
            .map(|(row, bi)| {
                let v: f64 = (0..6).map(|k| row[k] * l[k]).sum::<f64>() - bi;
                v * v
            })
            .sum();
        (ss / a.len() as f64).sqrt()
    };

    let eig = SymmetricEigen::new(big_l);
    let lmax = eig.eigenvalues.max();
    if !(lmax.is_finite() && lmax > 0.0) {
        return Err(Error::Degenerate(format!(
            "the metric constraints admit no positive semidefinite solution with a positive \
             eigenvalue (eigenvalues {:?}); the motion does not determine a metric frame",
            eig.eigenvalues.as_slice()
        )));
    }
    let floor = cfg.pd_tolerance.max(1e-12) * lmax;
    let mut q = eig.eigenvectors;
    for k in 0..3 {
        let s = eig.eigenvalues[k].max(floor).sqrt();
        for r in 0..3 {
            q[(r, k)] *= s;
        }
    }
    // Undo the normalization: L for the original M̂ is L'/c², Q is Q'/c.
    let q = q / c;
    let scale2 = 1.0 / (c * c);
    let to_arr = |m: &Matrix3<f64>| -> [[f64; 3]; 3] {
        std::array::from_fn(|r| std::array::from_fn(|k| m[(r, k)] * scale2))
    };
    let eigs = sorted_eigs(&big_l);
    Ok(MetricUpgrade {
        method,
        min_eigenvalue_ls: eig_ls[0] * scale2,
        eigenvalues_ls: eig_ls.map(|e| e * scale2),
        eigenvalues: eigs.map(|e| e * scale2),
        l: to_arr(&big_l),
        constraint_rms,
        sdp_status,
        sdp_iterations,
        q,
    })
}

/// `min ‖A l − b‖²`, optionally subject to `c·l = d` (KKT system), for 6 unknowns.
fn solve_ls(a: &[[f64; 6]], b: &[f64], equality: Option<([f64; 6], f64)>) -> Result<[f64; 6]> {
    let mut ata = nalgebra::SMatrix::<f64, 6, 6>::zeros();
    let mut atb = nalgebra::SVector::<f64, 6>::zeros();
    for (row, bi) in a.iter().zip(b) {
        let r = nalgebra::SVector::<f64, 6>::from_row_slice(row);
        ata += r * r.transpose();
        atb += r * *bi;
    }
    let sol: Vec<f64> = match equality {
        None => {
            // QR on A (3F×6) is better conditioned than normal equations.
            let m = faer::Mat::from_fn(a.len(), 6, |i, k| a[i][k]);
            let rhs = faer::Mat::from_fn(a.len(), 1, |i, _| b[i]);
            let x = m.qr().solve_lstsq(&rhs);
            (0..6).map(|k| x[(k, 0)]).collect()
        }
        Some((c, d)) => {
            let mut kkt = nalgebra::SMatrix::<f64, 7, 7>::zeros();
            let mut rhs = nalgebra::SVector::<f64, 7>::zeros();
            kkt.fixed_view_mut::<6, 6>(0, 0).copy_from(&(ata * 2.0));
            for k in 0..6 {
                kkt[(k, 6)] = c[k];
                kkt[(6, k)] = c[k];
            }
            rhs[6] = d;
            let svd = kkt.svd(true, true);
            let x = svd
                .solve(&rhs, 1e-13 * svd.singular_values.max())
                .map_err(|e| Error::Numerical {
                    stage: "metric upgrade",
                    message: e.to_string(),
                })?;
            (0..6).map(|k| x[k]).collect()
        }
    };
    if sol.iter().any(|v| !v.is_finite()) {
        return Err(Error::Numerical {
            stage: "metric upgrade",
            message: "least-squares solution for L is not finite".into(),
        });
    }
    Ok(std::array::from_fn(|k| sol[k]))
}

/// Nearest camera to the rows `i`, `j` (2×3): `R` with orthonormal first two rows
/// (polar factor `U Vᵀ` of the 2×3 matrix, so `‖[i; j] − s R[0..2]‖_F` is minimal) and
/// `k = i × j`, plus the scale `s = (σ1 + σ2)/2`. Returns `None` when `[i; j]` is rank
/// deficient.
pub fn nearest_camera(i: &Vector3<f64>, j: &Vector3<f64>) -> Option<(Rotation3<f64>, f64)> {
    let m = Matrix2x3::from_rows(&[i.transpose(), j.transpose()]);
    let svd = m.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let s = svd.singular_values;
    if !(s[1] > 1e-12 * s[0].max(1e-300)) {
        return None;
    }
    let p = u * vt; // 2×3 with orthonormal rows
    let r0: Vector3<f64> = p.row(0).transpose();
    let r1: Vector3<f64> = p.row(1).transpose();
    let r2 = r0.cross(&r1);
    let rm = Matrix3::from_rows(&[r0.transpose(), r1.transpose(), r2.transpose()]);
    Some((Rotation3::from_matrix_unchecked(rm), 0.5 * (s[0] + s[1])))
}

/// Depth-reversal (Necker) convention. Under (scaled) orthography a reconstruction and its
/// mirror image `X → D X`, `R_f → D R_f D` with `D = diag(1, 1, −1)` (in frame 0's camera
/// coordinates, after the gauge puts `R_0 = I`) project identically. rank3 returns the one
/// in which the out-of-image-plane part of the rotation to the frame that turns farthest
/// from frame 0 is a positive turn: writing that rotation as an axis-angle vector `ω`,
/// the larger in magnitude of `ω_x`, `ω_y` is positive. Returns whether it mirrored.
pub fn apply_necker_convention(model: &mut crate::MetricModel) -> bool {
    let mut best = (0.0f64, 0.0f64);
    for r in &model.rotations {
        let w = r.scaled_axis();
        let out = w[0].hypot(w[1]);
        if out > best.0 {
            best = (out, if w[0].abs() >= w[1].abs() { w[0] } else { w[1] });
        }
    }
    if best.1 >= 0.0 {
        return false;
    }
    let d = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0));
    for r in model.rotations.iter_mut() {
        *r = Rotation3::from_matrix_unchecked(d * r.matrix() * d);
    }
    for p in model.points.iter_mut() {
        p[2] = -p[2];
    }
    true
}

/// The metric cameras of an affine factorization: frame `f`'s rows `Qᵀî_f`, `Qᵀĵ_f` (of
/// `M̂Q`) projected onto the nearest scaled rotation ([`nearest_camera`]; scale 1 for the
/// orthographic camera), translations `t` (2F), no points. A frame whose two rows are
/// linearly dependent is [`Error::Degenerate`]. `O(F)`.
pub fn cameras(
    m_hat: MatRef<'_, f64>,
    q: &Matrix3<f64>,
    t: &[f64],
    camera: CameraModel,
) -> Result<crate::MetricModel> {
    let f = m_hat.nrows() / 2;
    let mut model = crate::MetricModel {
        rotations: Vec::with_capacity(f),
        translations: Vec::with_capacity(f),
        scales: Vec::with_capacity(f),
        points: Vec::new(),
        aspect: 1.0,
    };
    for k in 0..f {
        let i = q.transpose() * row3(m_hat, 2 * k);
        let j = q.transpose() * row3(m_hat, 2 * k + 1);
        let (r, s) = nearest_camera(&i, &j).ok_or_else(|| {
            Error::Degenerate(format!(
                "frame {k}: the metric camera rows are linearly dependent (the frame's \
                 image motion is degenerate)"
            ))
        })?;
        model.rotations.push(r);
        model.scales.push(match camera {
            CameraModel::Orthographic => 1.0,
            CameraModel::ScaledOrthographic
            | CameraModel::Projective
            | CameraModel::Perspective
            | CameraModel::Auto => s,
        });
        model
            .translations
            .push(nalgebra::Vector2::new(t[2 * k], t[2 * k + 1]));
    }
    Ok(model)
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::Mat;
    use rand::{RngExt, SeedableRng, rngs::StdRng};

    fn random_rotation(rng: &mut StdRng) -> Rotation3<f64> {
        let v = Vector3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        );
        Rotation3::new(v * 1.2)
    }

    /// M̂ = M_true Q⁻¹ for random rotations (and scales) and a random invertible Q.
    fn affine_motion(f: usize, scaled: bool, seed: u64) -> (Mat<f64>, Vec<f64>) {
        let mut rng = StdRng::seed_from_u64(seed);
        let qinv =
            Matrix3::from_fn(|r, c| (if r == c { 2.0 } else { 0.0 }) + rng.random_range(-1.0..1.0));
        let mut m = Mat::zeros(2 * f, 3);
        let mut scales = Vec::new();
        for k in 0..f {
            let r = random_rotation(&mut rng);
            let s = if scaled {
                rng.random_range(0.5..2.0)
            } else {
                1.0
            };
            scales.push(s);
            for row in 0..2 {
                let v = (r.matrix().row(row) * s) * qinv;
                for c in 0..3 {
                    m[(2 * k + row, c)] = v[c] * 37.0;
                }
            }
        }
        (m, scales)
    }

    fn check_orthonormal(m: &Mat<f64>, q: &Matrix3<f64>, scaled: bool, scales: &[f64]) {
        let f = m.nrows() / 2;
        let s0 = {
            let i = Vector3::new(m[(0, 0)], m[(0, 1)], m[(0, 2)]);
            (q.transpose() * i).norm()
        };
        for k in 0..f {
            let i = q.transpose() * Vector3::new(m[(2 * k, 0)], m[(2 * k, 1)], m[(2 * k, 2)]);
            let j = q.transpose()
                * Vector3::new(m[(2 * k + 1, 0)], m[(2 * k + 1, 1)], m[(2 * k + 1, 2)]);
            assert!(i.dot(&j).abs() < 1e-8 * i.norm() * j.norm());
            if scaled {
                assert!((i.norm() / j.norm() - 1.0).abs() < 1e-8);
                assert!((i.norm() / s0 - scales[k] / scales[0]).abs() < 1e-8);
            } else {
                assert!((i.norm() - 1.0).abs() < 1e-8, "{}", i.norm());
                assert!((j.norm() - 1.0).abs() < 1e-8);
            }
        }
    }

    #[test]
    fn orthographic_least_squares_exact() {
        let (m, s) = affine_motion(12, false, 1);
        let up = upgrade(
            m.as_ref(),
            CameraModel::Orthographic,
            &MetricConfig::default(),
        )
        .unwrap();
        assert_eq!(up.method, UpgradeMethod::LeastSquares);
        assert!(up.min_eigenvalue_ls > 0.0);
        check_orthonormal(&m, &up.q, false, &s);
    }

    #[test]
    fn scaled_orthographic_least_squares_exact() {
        let (m, s) = affine_motion(12, true, 2);
        let up = upgrade(
            m.as_ref(),
            CameraModel::ScaledOrthographic,
            &MetricConfig::default(),
        )
        .unwrap();
        assert_eq!(up.method, UpgradeMethod::LeastSquares);
        check_orthonormal(&m, &up.q, true, &s);
    }

    #[test]
    fn bad_shapes_and_too_few_frames_are_errors() {
        let m = Mat::<f64>::zeros(4, 2);
        assert!(matches!(
            upgrade(
                m.as_ref(),
                CameraModel::Orthographic,
                &MetricConfig::default()
            ),
            Err(Error::Dimension { .. })
        ));
        let (m, _) = affine_motion(2, true, 3);
        assert!(matches!(
            upgrade(
                m.as_ref(),
                CameraModel::ScaledOrthographic,
                &MetricConfig::default()
            ),
            Err(Error::TooFew { .. })
        ));
        let m = Mat::<f64>::zeros(6, 3);
        assert!(matches!(
            upgrade(
                m.as_ref(),
                CameraModel::Orthographic,
                &MetricConfig::default()
            ),
            Err(Error::Degenerate(_))
        ));
    }

    #[test]
    fn nearest_camera_recovers_rotation_and_scale() {
        let mut rng = StdRng::seed_from_u64(5);
        for _ in 0..20 {
            let r = random_rotation(&mut rng);
            let s = rng.random_range(0.1..10.0);
            let i: Vector3<f64> = r.matrix().row(0).transpose() * s;
            let j: Vector3<f64> = r.matrix().row(1).transpose() * s;
            let (r2, s2) = nearest_camera(&i, &j).unwrap();
            assert!((r2.matrix() - r.matrix()).norm() < 1e-12);
            assert!((s2 - s).abs() < 1e-12 * s);
        }
        assert!(nearest_camera(&Vector3::x(), &(Vector3::x() * 2.0)).is_none());
    }
}
