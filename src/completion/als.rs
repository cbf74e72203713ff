//! Alternating least squares (ALS) for low-rank completion.
//!
//! # Objective
//!
//! Minimises `Σ_observed (m_iᵀ s_p + t_i − w_ip)²` by alternating two exact linear
//! least-squares updates over observed entries only:
//!
//! * points given cameras, per track `p`: `(M̃_pᵀM̃_p + λ') s_p = M̃_pᵀ (w̃_p − t̃_p)`;
//! * cameras given points, per frame `f` (the x row and the y row share the normal
//!   matrix): `(Σ_{p ∈ f} s̄_p s̄_pᵀ + λ') [m_i; t_i] = Σ_{p ∈ f} s̄_p w_ip`, `s̄_p = [s_p; 1]`
//!   (affine) or `s_p` (free),
//!
//! with optional damping `λ' = λ tr(A)/n` (`als_damping`, default 0). After each camera
//! update `M` is re-orthonormalised (the cost is gauge invariant), so the reported cost is
//! the same reduced cost `f(M, t) = min_S f` that [`super::Wiberg`] minimises.
//!
//! # Stalling
//!
//! ALS decreases the cost monotonically but, on real missing-data problems, it often
//! flat-lines: many sweeps of tiny relative progress along a narrow curved valley, far from
//! a stationary point (Buchanan & Fitzgibbon, CVPR 2005, "Damped Newton algorithms for
//! matrix factorization with missing data"; Hong & Fitzgibbon, ICCV 2015). The run is
//! reported [`SolverStatus::Stalled`] when the relative decrease per sweep stays below
//! `stall_tolerance` for `stall_window` consecutive sweeps while the relative gradient of
//! the reduced cost, `‖∇f‖ / (‖w‖ ‖[S; 1]‖_F)` (`w` = observed data), is still above `√gradient_tolerance`.
//! It is [`SolverStatus::Converged`] when the relative gradient drops below
//! `gradient_tolerance`, or when the relative decrease drops below `function_tolerance`
//! with the relative gradient below `√gradient_tolerance`.
//!
//! # Complexity
//!
//! One sweep costs `O(n_obs q² + (F + N) q³)` (`n_obs` observed pairs, `q` = r or r+1),
//! plus `O(F r²)` for the re-orthonormalisation. Never `O(F N)`. The per-frame and per-track
//! solves run in parallel (rayon).

use std::time::Instant;

use faer::MatRef;
use rayon::prelude::*;

use super::{CompletionConfig, CompletionProblem, CompletionRun, CompletionSolver, linalg, report};
use crate::{Observer, SolverStatus};

/// Alternating least-squares solver (see the module documentation).
#[derive(Debug, Clone)]
pub struct Als {
    pub max_iterations: usize,
    pub function_tolerance: f64,
    pub gradient_tolerance: f64,
    /// Relative damping added to every small normal matrix.
    pub damping: f64,
    pub stall_tolerance: f64,
    pub stall_window: usize,
}

impl Als {
    /// Takes the ALS-relevant fields of `cfg`.
    pub fn from_config(cfg: &CompletionConfig) -> Self {
        Self {
            max_iterations: cfg.max_iterations,
            function_tolerance: cfg.function_tolerance,
            gradient_tolerance: cfg.gradient_tolerance,
            damping: cfg.als_damping,
            stall_tolerance: cfg.stall_tolerance,
            stall_window: cfg.stall_window,
        }
    }

    /// Camera update given points (in place on the packed cameras `u`). Frames are
    /// independent: in parallel.
    fn update_cameras(&self, problem: &CompletionProblem, s: &[f64], u: &mut [f64]) {
        let (q, r) = (problem.q(), problem.rank);
        u.par_chunks_mut(2 * q).enumerate().for_each(|(f, uf)| {
            let mut b = vec![0.0; q * q];
            let mut rhs = [vec![0.0; q], vec![0.0; q]];
            let mut sbar = vec![0.0; q];
            for o in problem.row_ptr[f]..problem.row_ptr[f + 1] {
                let p = problem.row_track[o];
                sbar[..r].copy_from_slice(&s[p * r..(p + 1) * r]);
                if problem.affine {
                    sbar[r] = 1.0;
                }
                for c in 0..q {
                    for c2 in 0..=c {
                        b[c * q + c2] += sbar[c] * sbar[c2];
                    }
                    for (k, rk) in rhs.iter_mut().enumerate() {
                        rk[c] += sbar[c] * problem.row_w[o][k];
                    }
                }
            }
            let ridge = self.damping * (0..q).map(|c| b[c * q + c]).sum::<f64>() / q as f64;
            for c in 0..q {
                for c2 in 0..c {
                    b[c2 * q + c] = b[c * q + c2];
                }
                b[c * q + c] += ridge;
            }
            for (k, rk) in rhs.iter_mut().enumerate() {
                let mut bf = b.clone();
                if linalg::spd_solve_robust(&mut bf, q, rk) {
                    uf[k * q..(k + 1) * q].copy_from_slice(rk);
                }
            }
        });
    }
}

impl CompletionSolver for Als {
    fn name(&self) -> &'static str {
        "als"
    }

    fn solve(
        &self,
        problem: &CompletionProblem,
        m0: MatRef<'_, f64>,
        t0: &[f64],
        run: usize,
        observer: &mut dyn Observer,
    ) -> CompletionRun {
        let start = Instant::now();
        let mut u = problem.pack(m0, t0);
        problem.normalize(&mut u);
        let mut ps = problem.solve_points(&u, 0.0, self.damping, false);
        let initial_cost = ps.cost;
        let mut status = SolverStatus::MaxIterations;
        let mut it = 0;
        let mut flat = 0usize;
        let loose = self.gradient_tolerance.sqrt();
        problem.emit(observer, self.name(), run, 0, ps.cost, f64::NAN);
        while it < self.max_iterations {
            let (_, rel_grad) = problem.gradient(&ps);
            if rel_grad <= self.gradient_tolerance || ps.cost <= 0.0 {
                status = SolverStatus::Converged;
                break;
            }
            it += 1;
            self.update_cameras(problem, &ps.s, &mut u);
            problem.normalize(&mut u);
            let ps_new = problem.solve_points(&u, 0.0, self.damping, false);
            let rel_dec = (ps.cost - ps_new.cost) / ps.cost.max(f64::MIN_POSITIVE);
            if ps_new.cost.is_finite() {
                ps = ps_new;
            }
            problem.emit(observer, self.name(), run, it, ps.cost, self.damping);
            if rel_dec < self.function_tolerance || rel_dec < self.stall_tolerance {
                let (_, rel_grad) = problem.gradient(&ps);
                if rel_grad <= loose && rel_dec < self.function_tolerance {
                    status = SolverStatus::Converged;
                    break;
                }
                if rel_grad > loose {
                    flat += 1;
                    if flat >= self.stall_window {
                        status = SolverStatus::Stalled;
                        break;
                    }
                }
            } else {
                flat = 0;
            }
        }
        let (m, t) = problem.unpack(&u);
        CompletionRun {
            m,
            t,
            report: report(status, it, initial_cost, ps.cost, start),
        }
    }
}
