//! The reduced camera system solved by preconditioned conjugate gradients, never formed.
//!
//! # Objective
//!
//! The damped reduced system of one Levenberg–Marquardt step (module docs of
//! [`super`]),
//!
//! ```text
//!   S_λ δc = b,   S_λ = U + λD + K − Σ_p W_p V_p*⁻¹ W_pᵀ,   b = −g_c + Σ_p W_p V_p*⁻¹ g_p,
//! ```
//!
//! is solved by conjugate gradients with `S_λ` applied as a product, observation by
//! observation: `S_λ x = (U + λD + K) x − Σ_p W_p z_p` with `z_p = V_p*⁻¹ W_pᵀ x` and
//! `W_fp = J_cᵀ J_x` applied as `J_cᵀ (J_x ·)` and `J_xᵀ (J_c ·)` from the stored
//! Jacobians (`K`: the gauge springs and the fixed cameras' springs; the shared parameters,
//! when the model has some, are unknowns after the cameras, coupled through `U_gf` and
//! `W_g`). The preconditioner is block Jacobi on `S_λ` itself (Ceres' "Schur–Jacobi"): the
//! camera blocks `S_ff = U_f + λD_f + K_f − Σ_{p ∋ f} W_fp V_p*⁻¹ W_fpᵀ` and the shared
//! block, each inverted once per damping.
//!
//! CG starts from `x₀ = 0` and stops when `‖b − S_λ x‖ ≤ η ‖b‖`
//! ([`LmConfig::cg_tolerance`](super::LmConfig::cg_tolerance)) or after
//! [`LmConfig::cg_max_iterations`](super::LmConfig::cg_max_iterations) products. From
//! `x₀ = 0` each iterate `x_k` minimises the quadratic model over its Krylov space, so
//! `x_kᵀ S_λ x_k = x_kᵀ b` holds at any `k` (the residual is orthogonal to the space): the
//! engine's predicted decrease `−gᵀδ + λ δᵀDδ` stays exact for a truncated step, and the
//! gain ratio that steers the damping means what it does for a direct solve. A truncated
//! step is an inexact Newton step (Dembo, Eisenstat & Steihaug 1982); the outer iteration
//! still converges, with more linearizations where `η` is loose.
//!
//! Positive definiteness is checked on the way: a product with `pᵀ S_λ p ≤ 0`, or a
//! camera block whose Cholesky factorization fails, is reported as a failure, which the
//! engine treats as a failed factorization of the direct path.
//!
//! # Complexity
//!
//! One product: `O(n_obs m (c + d) + N d² + F c²)` time, reading each observation's
//! Jacobians twice; the preconditioner: `O(n_obs (m c d + c² d) + F c³)` per linearization
//! and `O(F c³)` per damping. Memory: `O(F c² + N d)` beyond the engine's linearization
//! (`O(n_obs m (c + d))`) — linear in the observations, whatever the camera graph. The
//! direct path stores the non-zeros of `S` and its factor, `(cF)²/2` each when every frame
//! shares tracks with every other (long tracks), and factorizes in `O((cF)³)`.
//!
//! # References
//!
//! * S. Agarwal, N. Snavely, S. M. Seitz and R. Szeliski, "Bundle adjustment in the
//!   large", ECCV 2010 (CG on the implicit Schur complement, block-Jacobi preconditioning).
//! * R. S. Dembo, S. C. Eisenstat and T. Steihaug, "Inexact Newton methods", SIAM J. Numer.
//!   Anal. 19(2), 1982.
//! * M. R. Hestenes and E. Stiefel, "Methods of conjugate gradients for solving linear
//!   systems", J. Res. NBS 49(6), 1952.

use rayon::prelude::*;

use super::{Graph, TrackLin, obs_parts, w_block};
use crate::completion::linalg;

/// One linearization's reduced camera system, held as the pieces its product needs.
pub(super) struct Implicit<'a> {
    pub g: &'a Graph,
    /// The linearization: per observation `J_c`, `r`, `J_g`, `J_x` ([`obs_parts`]).
    pub lin: &'a [f64],
    pub stride: usize,
    /// `(c, d, k, m)`: camera and point tangent sizes, shared parameters, residuals.
    pub dims: (usize, usize, usize, usize),
    pub lins: &'a [TrackLin],
    /// `V_p*⁻¹` per track (`d × d`).
    pub vinv: &'a [Vec<f64>],
    /// Observations by camera (CSR).
    pub cam_ptr: &'a [usize],
    pub cam_obs: &'a [usize],
    /// The track of each observation.
    pub obs_pt: &'a [usize],
    /// Per camera, `U_f + K_f` (full `c × c`, symmetric): the camera block before the
    /// damping and the Schur correction.
    pub ucam: &'a [f64],
    /// Per camera, `U_gf` (`k × c`, in slots of `kc`).
    pub ugf: &'a [f64],
    pub kc: usize,
    /// `U_gg` (full `k × k`).
    pub ugg: &'a [f64],
    /// The diagonal the damping scales (cameras, shared parameters).
    pub dcam: &'a [f64],
    pub dglob: &'a [f64],
}

/// The undamped diagonal blocks of `S` (per camera `c × c`, then the shared `k × k`): the
/// preconditioner before its damping. `O(n_obs (m c d + c² d))`.
pub(super) struct BlockDiagonal {
    cams: Vec<f64>,
    glob: Vec<f64>,
}

/// How a CG solve ended.
pub(super) struct CgOutcome {
    /// The step `δ` (cameras then shared parameters).
    pub x: Vec<f64>,
    /// Products with `S_λ` taken.
    pub iterations: usize,
}

impl Implicit<'_> {
    fn n(&self) -> usize {
        let (cd, _, k, _) = self.dims;
        self.g.n_cams * cd + k
    }

    /// `out_f = Σ_{o ∈ f} J_cᵀ (J_x z_p(o))` per camera and `out_g = Σ_p W_gp z_p`: the
    /// product `W z` of the point-space vector `z` (`N × d`). In parallel over cameras.
    fn gather(&self, z: &[f64], out: &mut [f64]) {
        let (cd, pd, k, m) = self.dims;
        let nf = self.g.n_cams;
        let (cam_out, glob_out) = out.split_at_mut(nf * cd);
        cam_out.par_chunks_mut(cd).enumerate().for_each(|(f, yf)| {
            yf.iter_mut().for_each(|v| *v = 0.0);
            for &o in &self.cam_obs[self.cam_ptr[f]..self.cam_ptr[f + 1]] {
                let p = self.obs_pt[o];
                let zp = &z[p * pd..(p + 1) * pd];
                let (jc, _, _, jx) =
                    obs_parts(&self.lin[o * self.stride..(o + 1) * self.stride], self.dims);
                for row in 0..m {
                    let jxr = &jx[row * pd..(row + 1) * pd];
                    let s: f64 = (0..pd).map(|d| jxr[d] * zp[d]).sum();
                    let jcr = &jc[row * cd..(row + 1) * cd];
                    for c in 0..cd {
                        yf[c] += jcr[c] * s;
                    }
                }
            }
        });
        for (k1, v) in glob_out.iter_mut().enumerate().take(k) {
            *v = (0..self.g.n_pts)
                .map(|p| {
                    let wg = &self.lins[p].wg;
                    (0..pd)
                        .map(|d| wg[k1 * pd + d] * z[p * pd + d])
                        .sum::<f64>()
                })
                .sum();
        }
    }

    /// `z_p = V_p*⁻¹ W_pᵀ x` per track (in parallel over tracks).
    fn scatter(&self, x: &[f64], z: &mut [f64]) {
        let (cd, pd, k, m) = self.dims;
        let nf = self.g.n_cams;
        let xg = &x[nf * cd..];
        z.par_chunks_mut(pd.max(1)).enumerate().for_each(|(p, zp)| {
            let mut t = vec![0.0; pd];
            for o in self.g.track(p) {
                let f = self.g.cam[o];
                let xf = &x[f * cd..(f + 1) * cd];
                let (jc, _, _, jx) =
                    obs_parts(&self.lin[o * self.stride..(o + 1) * self.stride], self.dims);
                for row in 0..m {
                    let jcr = &jc[row * cd..(row + 1) * cd];
                    let s: f64 = (0..cd).map(|c| jcr[c] * xf[c]).sum();
                    let jxr = &jx[row * pd..(row + 1) * pd];
                    for d in 0..pd {
                        t[d] += jxr[d] * s;
                    }
                }
            }
            let wg = &self.lins[p].wg;
            for (k1, &xk) in xg.iter().enumerate().take(k) {
                for d in 0..pd {
                    t[d] += wg[k1 * pd + d] * xk;
                }
            }
            let vi = &self.vinv[p];
            for d1 in 0..pd {
                zp[d1] = (0..pd).map(|d2| vi[d1 * pd + d2] * t[d2]).sum();
            }
        });
    }

    /// `y = S_λ x`. `z` is workspace (`N × d`).
    fn apply(&self, lambda: f64, x: &[f64], y: &mut [f64], z: &mut [f64]) {
        let (cd, _, k, _) = self.dims;
        let nf = self.g.n_cams;
        self.scatter(x, z);
        self.gather(z, y);
        let kc = self.kc;
        let xg = &x[nf * cd..];
        let (ycam, yglob) = y.split_at_mut(nf * cd);
        ycam.par_chunks_mut(cd).enumerate().for_each(|(f, yf)| {
            let uf = &self.ucam[f * cd * cd..(f + 1) * cd * cd];
            let xf = &x[f * cd..(f + 1) * cd];
            for c1 in 0..cd {
                let mut s = lambda * self.dcam[f * cd + c1] * xf[c1];
                for c2 in 0..cd {
                    s += uf[c1 * cd + c2] * xf[c2];
                }
                for (k1, &xk) in xg.iter().enumerate().take(k) {
                    s += self.ugf[f * kc + k1 * cd + c1] * xk;
                }
                yf[c1] = s - yf[c1];
            }
        });
        for k1 in 0..k {
            let mut s = lambda * self.dglob[k1] * xg[k1];
            for k2 in 0..k {
                s += self.ugg[k1 * k + k2] * xg[k2];
            }
            for f in 0..nf {
                for c1 in 0..cd {
                    s += self.ugf[f * kc + k1 * cd + c1] * x[f * cd + c1];
                }
            }
            yglob[k1] = s - yglob[k1];
        }
    }

    /// The reduced right-hand side `b = −g + W V*⁻¹ g_p` (cameras, then shared
    /// parameters), with `gc`, `gglob` the cameras' and shared parameters' gradients; the
    /// rows of fixed cameras are zero.
    pub fn rhs(&self, gc: &[f64], gglob: &[f64], fixed: impl Fn(usize) -> bool) -> Vec<f64> {
        let (cd, pd, _, _) = self.dims;
        let mut z = vec![0.0; self.g.n_pts * pd];
        z.par_chunks_mut(pd.max(1)).enumerate().for_each(|(p, zp)| {
            let (vi, gp) = (&self.vinv[p], &self.lins[p].gp);
            for d1 in 0..pd {
                zp[d1] = (0..pd).map(|d2| vi[d1 * pd + d2] * gp[d2]).sum();
            }
        });
        let mut b = vec![0.0; self.n()];
        self.gather(&z, &mut b);
        for (bi, gi) in b.iter_mut().zip(gc.iter().chain(gglob)) {
            *bi -= gi;
        }
        for f in (0..self.g.n_cams).filter(|&f| fixed(f)) {
            b[f * cd..(f + 1) * cd].iter_mut().for_each(|v| *v = 0.0);
        }
        b
    }

    /// The undamped diagonal blocks of `S`: `U_f + K_f − Σ_{p ∋ f} W_fp V_p*⁻¹ W_fpᵀ` per
    /// camera (in parallel) and `U_gg − Σ_p W_gp V_p*⁻¹ W_gpᵀ`.
    pub fn block_diagonal(&self) -> BlockDiagonal {
        let (cd, pd, k, _) = self.dims;
        let nf = self.g.n_cams;
        let mut cams = self.ucam[..nf * cd * cd].to_vec();
        cams.par_chunks_mut(cd * cd)
            .enumerate()
            .for_each(|(f, sf)| {
                let mut w = vec![0.0; cd * pd];
                let mut y = vec![0.0; cd * pd];
                for &o in &self.cam_obs[self.cam_ptr[f]..self.cam_ptr[f + 1]] {
                    let p = self.obs_pt[o];
                    w_block(
                        &self.lin[o * self.stride..(o + 1) * self.stride],
                        self.dims,
                        &mut w,
                    );
                    let vi = &self.vinv[p];
                    for c in 0..cd {
                        for d2 in 0..pd {
                            y[c * pd + d2] =
                                (0..pd).map(|d1| w[c * pd + d1] * vi[d1 * pd + d2]).sum();
                        }
                    }
                    for c1 in 0..cd {
                        for c2 in 0..cd {
                            sf[c1 * cd + c2] -= (0..pd)
                                .map(|d| y[c1 * pd + d] * w[c2 * pd + d])
                                .sum::<f64>();
                        }
                    }
                }
            });
        let mut glob = self.ugg[..k * k].to_vec();
        for p in 0..self.g.n_pts {
            let (wg, vi) = (&self.lins[p].wg, &self.vinv[p]);
            for k1 in 0..k {
                for k2 in 0..k {
                    let mut s = 0.0;
                    for d1 in 0..pd {
                        for d2 in 0..pd {
                            s += wg[k1 * pd + d1] * vi[d1 * pd + d2] * wg[k2 * pd + d2];
                        }
                    }
                    glob[k1 * k + k2] -= s;
                }
            }
        }
        BlockDiagonal { cams, glob }
    }

    /// Solves `S_λ x = b` by preconditioned conjugate gradients (module docs) to
    /// `‖b − S_λ x‖ ≤ tol ‖b‖` or `max_iterations` products; `None` when `S_λ` is found not
    /// positive definite (a diagonal block or a search direction).
    pub fn solve(
        &self,
        blocks: &BlockDiagonal,
        lambda: f64,
        b: &[f64],
        tol: f64,
        max_iterations: usize,
    ) -> Option<CgOutcome> {
        let (cd, pd, k, _) = self.dims;
        let (nf, n) = (self.g.n_cams, self.n());
        // The damped blocks' inverses.
        let mut inv = vec![0.0; nf * cd * cd];
        let ok = inv.par_chunks_mut(cd * cd).enumerate().all(|(f, out)| {
            let mut h = blocks.cams[f * cd * cd..(f + 1) * cd * cd].to_vec();
            for c in 0..cd {
                h[c * cd + c] += lambda * self.dcam[f * cd + c];
            }
            linalg::cholesky(&mut h, cd) && {
                linalg::chol_inverse(&h, cd, out);
                true
            }
        });
        let mut ginv = vec![0.0; k * k];
        let ok = ok && {
            let mut h = blocks.glob.clone();
            for k1 in 0..k {
                h[k1 * k + k1] += lambda * self.dglob[k1];
            }
            k == 0 || {
                linalg::cholesky(&mut h, k) && {
                    linalg::chol_inverse(&h, k, &mut ginv);
                    true
                }
            }
        };
        if !ok {
            return None;
        }
        let precondition = |r: &[f64], z: &mut [f64]| {
            let (zc, zg) = z.split_at_mut(nf * cd);
            zc.par_chunks_mut(cd).enumerate().for_each(|(f, zf)| {
                let a = &inv[f * cd * cd..(f + 1) * cd * cd];
                let rf = &r[f * cd..(f + 1) * cd];
                for c1 in 0..cd {
                    zf[c1] = (0..cd).map(|c2| a[c1 * cd + c2] * rf[c2]).sum();
                }
            });
            let rg = &r[nf * cd..];
            for k1 in 0..k {
                zg[k1] = (0..k).map(|k2| ginv[k1 * k + k2] * rg[k2]).sum();
            }
        };
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let mut x = vec![0.0; n];
        let bnorm = dot(b, b).sqrt();
        if bnorm == 0.0 {
            return Some(CgOutcome { x, iterations: 0 });
        }
        let mut r = b.to_vec();
        let mut z = vec![0.0; n];
        precondition(&r, &mut z);
        let mut p = z.clone();
        let mut q = vec![0.0; n];
        let mut work = vec![0.0; self.g.n_pts * pd];
        let mut rz = dot(&r, &z);
        let mut iterations = 0;
        while iterations < max_iterations {
            self.apply(lambda, &p, &mut q, &mut work);
            iterations += 1;
            let pq = dot(&p, &q);
            if !(pq > 0.0 && pq.is_finite()) {
                return None;
            }
            let alpha = rz / pq;
            for i in 0..n {
                x[i] += alpha * p[i];
                r[i] -= alpha * q[i];
            }
            if dot(&r, &r).sqrt() <= tol * bnorm {
                break;
            }
            precondition(&r, &mut z);
            let rz_new = dot(&r, &z);
            let beta = rz_new / rz;
            rz = rz_new;
            for i in 0..n {
                p[i] = z[i] + beta * p[i];
            }
        }
        Some(CgOutcome { x, iterations })
    }
}
