//! Iterated Sturm–Triggs projective factorization of a complete track table.
//!
//! With projective depths `λ_fp`, the rescaled measurement matrix
//! `A = [λ_fp x_fp; λ_fp y_fp; λ_fp]` (3F×N) equals `P X` (rank 4) for the true depths. Starting
//! from `λ = 1` (the affine camera), each iteration balances `A` (columns, then each
//! frame's three rows, to unit norm: Sturm & Triggs 1996, §3; twice), truncates it to rank 4
//! by SVD (`P = U₄Σ₄`, `X = V₄ᵀ`) and sets `λ_fp = (P_f X_p)₃` (Triggs 1996; Mahamud & Hebert
//! 2000 show the iteration monotone in the balanced algebraic error). Stops when `σ₅/σ₄`
//! improves by less than 0.1 % in an iteration (the iteration converges linearly; the bundle
//! adjustment that follows finishes the job), or after the iteration cap.
//!
//! Cost per iteration: `O(F N)` for the balancing plus one rank-5 truncated SVD of the
//! 3F×N matrix ([`crate::svd`], randomized for large matrices). Complete data only:
//! the matrix is as large as the observations.

use faer::Mat;

use super::bundle::Graph;
use crate::svd::{TruncatedSvdConfig, truncated_svd};
use crate::{Error, Result, SolverStatus};

pub(super) struct SturmTriggs {
    /// 12 per frame (row-major 3×4).
    pub cameras: Vec<f64>,
    /// 4 per track.
    pub points: Vec<f64>,
    pub status: SolverStatus,
    pub iterations: usize,
}

pub(super) fn run(g: &Graph, iterations: usize) -> Result<SturmTriggs> {
    let (nf, np) = (g.n_cams, g.n_pts);
    if g.n_obs() != nf * np {
        return Err(Error::MissingData {
            observed: g.n_obs(),
            total: nf * np,
            message: "the Sturm–Triggs start needs every track in every frame".into(),
        });
    }
    // Dense measurements, frame-major: w[f * np + p].
    let mut w = vec![[0.0; 2]; nf * np];
    for p in 0..np {
        for o in g.track(p) {
            w[g.cam[o] * np + p] = g.w[o];
        }
    }
    let mut lam = vec![1.0; nf * np];
    let cfg = TruncatedSvdConfig::default();
    let mut status = SolverStatus::MaxIterations;
    let mut last_ratio = f64::NAN;
    let mut cams = vec![0.0; 12 * nf];
    let mut pts = vec![0.0; 4 * np];
    let mut done = 0;
    for it in 0..iterations.max(1) {
        done = it + 1;
        balance(&mut lam, &w, nf, np);
        let a = Mat::from_fn(3 * nf, np, |r, p| {
            let (f, k) = (r / 3, r % 3);
            let l = lam[f * np + p];
            if k == 2 { l } else { l * w[f * np + p][k] }
        });
        let svd = truncated_svd(a.as_ref(), 5.min(np).min(3 * nf), &cfg)?;
        if svd.s.len() < 4 || !(svd.s[3] > 0.0) {
            return Err(Error::Degenerate(format!(
                "the rescaled measurement matrix has rank < 4 (singular values {:?}): the \
                 tracks do not determine a projective reconstruction",
                svd.s
            )));
        }
        for f in 0..nf {
            for r in 0..3 {
                for k in 0..4 {
                    cams[12 * f + 4 * r + k] = svd.u[(3 * f + r, k)] * svd.s[k];
                }
            }
        }
        for p in 0..np {
            for k in 0..4 {
                pts[4 * p + k] = svd.v[(p, k)];
            }
        }
        let ratio = if svd.s.len() > 4 {
            svd.s[4] / svd.s[3]
        } else {
            0.0
        };
        // λ_fp = argmin_λ ‖λ w̃_fp − P_f X_p‖ = w̃ᵀ(P_f X_p) / ‖w̃‖², w̃ = (x, y, 1).
        for f in 0..nf {
            let c = &cams[12 * f..12 * f + 12];
            for p in 0..np {
                let x = &pts[4 * p..4 * p + 4];
                let q: [f64; 3] = std::array::from_fn(|r| {
                    c[4 * r] * x[0]
                        + c[4 * r + 1] * x[1]
                        + c[4 * r + 2] * x[2]
                        + c[4 * r + 3] * x[3]
                });
                let wp = w[f * np + p];
                lam[f * np + p] =
                    (wp[0] * q[0] + wp[1] * q[1] + q[2]) / (wp[0] * wp[0] + wp[1] * wp[1] + 1.0);
            }
        }
        // The iteration converges linearly; stop once it no longer pays.
        if ratio == 0.0 || !(last_ratio - ratio > 1e-3 * last_ratio) && it > 0 {
            status = SolverStatus::Converged;
            break;
        }
        last_ratio = ratio;
    }
    Ok(SturmTriggs {
        cameras: cams,
        points: pts,
        status,
        iterations: done,
    })
}

/// Two passes of: every column of `A` to unit norm, then every frame's three rows jointly
/// to unit norm (multiplicative updates of the depths).
fn balance(lam: &mut [f64], w: &[[f64; 2]], nf: usize, np: usize) {
    let sq = |l: f64, w: [f64; 2]| l * l * (w[0] * w[0] + w[1] * w[1] + 1.0);
    for _ in 0..2 {
        for p in 0..np {
            let n: f64 = (0..nf)
                .map(|f| sq(lam[f * np + p], w[f * np + p]))
                .sum::<f64>()
                .sqrt();
            if n > 0.0 && n.is_finite() {
                for f in 0..nf {
                    lam[f * np + p] /= n;
                }
            }
        }
        for f in 0..nf {
            let n: f64 = (0..np)
                .map(|p| sq(lam[f * np + p], w[f * np + p]))
                .sum::<f64>()
                .sqrt();
            if n > 0.0 && n.is_finite() {
                for p in 0..np {
                    lam[f * np + p] /= n;
                }
            }
        }
    }
}
