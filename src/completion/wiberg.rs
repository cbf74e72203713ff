//! Damped Wiberg / variable projection (VarPro) for low-rank completion.
//!
//! # Objective
//!
//! The points are eliminated in closed form: for cameras `U = [M t]` (affine) or `U = M`
//! (free), each track's point is the (tiny-ridge) least-squares solution
//! `s_p(U) = (M̃_pᵀ M̃_p + μI)⁻¹ M̃_pᵀ (w̃_p − t̃_p)` over its observed rows (`~` = rows
//! restricted to the frames that see track `p`), leaving the reduced cost
//!
//! ```text
//!   f(U) = Σ_p ‖r_p‖²,   r_p = M̃_p s_p(U) + t̃_p − w̃_p = −P_p (w̃_p − t̃_p),
//!   P_p = I − M̃_p (M̃_pᵀ M̃_p)⁻¹ M̃_pᵀ,
//! ```
//!
//! minimised by Levenberg–Marquardt over the camera parameters only.
//!
//! # Jacobian and normal matrix
//!
//! For a camera perturbation `δU` the residual changes by
//! `δr_p = P_p δŨ_p s̄_p − M̃_p (M̃_pᵀM̃_p)⁻¹ δM̃_pᵀ r_p` with `s̄_p = [s_p; 1]` (affine) or
//! `s_p` (Golub & Pereyra 1973). The gradient is exact either way:
//! `Jᵀr = Σ_p r_p ⊗ s̄_p` (restricted rows). Since `P_p M̃_p = 0`, the two terms are
//! orthogonal and the Gauss–Newton matrix splits into per-track Kronecker blocks
//!
//! ```text
//!   JᵀJ = Σ_p [ P_p ⊗ s̄_p s̄_pᵀ  +  (r_p r_pᵀ) ⊗ (M̃_pᵀM̃_p)⁻¹ ]   (second term: Full only)
//! ```
//!
//! [`VarProJacobian::Kaufman`] keeps the first term (Kaufman 1975; the approximation that
//! Hong & Fitzgibbon 2015 / Hong, Zach & Fitzgibbon 2017 found as reliable as the full
//! Jacobian, and cheaper per iteration); [`VarProJacobian::Full`] adds the second.
//!
//! # Reliability ingredients (Hong & Fitzgibbon, ICCV 2015; Hong, Zach & Fitzgibbon, CVPR 2017)
//!
//! * Levenberg damping `λ · mean(diag JᵀJ) · I` on the camera parameters, ×10 on a
//!   rejected step, ÷10 on an accepted one (Levenberg's identity damping, not Marquardt's
//!   diagonal scaling, as Hong & Fitzgibbon recommend). For the affine model the
//!   translation entries get `translation_damping` (default 10) times that damping, so
//!   early steps mostly turn the camera subspace and the translation follows. This is an
//!   empirical choice of rank3: with random starts on dino_trimmed (affine, 2000
//!   iterations) the success rate was 87/100 with a factor 1, 86/100 with 5, 94/100 with 10,
//!   91/100 with 30; Marquardt scaling per parameter class gave 17/30, starting `t` at the
//!   row means instead of 0 gave 18/30, scaling λ by the median instead of the mean
//!   diagonal 82/100, dividing λ by 3 instead of 10 on success 67/100.
//! * Gauge handling: the reduced cost is invariant to `M → MA` (and `t → t + Mb`), so
//!   `JᵀJ` is singular along those directions. The step is projected orthogonally to the
//!   gauge orbit (`δM ← (I − MMᵀ) δM`, `δt ← (I − MMᵀ) δt`), and every candidate is
//!   retracted by re-orthonormalising `M` (QR) and re-projecting `t ⊥ range(M)`
//!   (a Grassmann-manifold retraction for the free model).
//! * A tiny ridge `μ` on each point's normal matrix so that weakly observed tracks stay
//!   finite.
//! * Ridge continuation against escaping points (default first stage `μ₀ = 1e-6`, then
//!   `μ = 1e-12`). The failure mode of random starts on dino_trimmed is a creeping descent
//!   along a valley in which the cameras become nearly rank-deficient on most tracks and the
//!   eliminated points run off (median ‖s_p‖ ~ 2e5 against ~ 2e3 at the optimum). Because
//!   the Kaufman normal matrix scales with ‖s̄_p‖², the relative Levenberg damping then
//!   freezes the translation, which feeds the escape. A first stage minimising
//!   `Σ r² + μ₀ Σ_p ‖s_p‖²` (cameras orthonormal, so `μ₀` is relative to O(1) camera
//!   entries: the penalty is ~1 per track at the optimum, small against the data cost,
//!   but ~1e4 for a point 100× too far out) keeps the points bounded; the final stage drops
//!   to the (essentially) unregularised objective. Optional geometric continuation
//!   (`point_damping_decrease`).
//! * Creep switch: when the objective fell by less than `creep_tolerance` (relative) over
//!   `creep_window` iterations, the run switches from Kaufman's to the full Golub–Pereyra
//!   normal matrix, whose extra term `(r_p r_pᵀ) ⊗ (M̃_pᵀM̃_p)⁻¹` is large precisely on the
//!   ill-conditioned tracks along such valleys.
//!
//! Measured with random starts (500 iterations; success = RMS within 1e-6 relative of the
//! best known; seeds 0–99 are the `completion_benchmark` ones, 100–199 held out):
//!
//! | variant | dino affine 0–99 / 100–199 | house affine 0–99 / 100–199 | dino free rank 4 (0–99) |
//! |---|---|---|---|
//! | Kaufman, `μ₀` off, no switch (previous default) | 93 / 93 | 100 / – | 28 |
//! | full Jacobian throughout | 71 / – | – | 20 |
//! | creep switch only | 94 / – | 100 / – | – |
//! | `μ₀` = 1e-5 | 65 / – | – | – |
//! | `μ₀` = 1e-6, no switch | 97 / – | 99 / – | – |
//! | `μ₀` = 1e-6 + switch (default) | 97 / 94 | 99 / 100 | 39 |
//! | `μ₀` = 1e-6, ρ = 0.01 continuation + switch | 97 (no switch) / 92 | 99 / – | – |
//! | `μ₀` = 1e-7 + switch | 188/200 pooled | 200/200 pooled | – |
//! | `μ₀` = 1e-8 + switch | 97 / 90 | 100 / 100 | 34 |
//! | exact minimisation over `t` before every step | 78 / 78 | 100 / 100 | – |
//!
//! The differences between the ridge variants (93–95.5 % pooled) are within the binomial
//! noise of 200 starts (±1.7 %); the remaining failures start into a spurious basin
//! (RMS ≈ 4.6) during the first ~50 iterations, before escaping points matter.
//!
//! # Complexity per iteration
//!
//! Point elimination `O(n_obs r² + N r³)`; assembling `JᵀJ` from per-track blocks
//! `O(Σ_p (2k_p)² q²)` (`k_p` frames see track `p`, `q` = parameters per camera row); the
//! dense `(2Fq)²` Cholesky `O((2Fq)³/3)`. A rejected step re-uses `JᵀJ` and only
//! re-factorises. Never `O(F N)`.
//!
//! # References
//!
//! T. Okatani and K. Deguchi, IJCV 2007; J. H. Hong and A. Fitzgibbon, ICCV 2015;
//! J. H. Hong, C. Zach and A. Fitzgibbon, CVPR 2017; G. H. Golub and V. Pereyra, SIAM J.
//! Numer. Anal. 1973; L. Kaufman, BIT 1975.

use std::time::Instant;

use faer::linalg::solvers::Solve;
use faer::{Mat, MatRef, Side};
use serde::{Deserialize, Serialize};

use super::{CompletionConfig, CompletionProblem, CompletionRun, CompletionSolver, report};
use crate::{Observer, SolverStatus};

/// Gauss–Newton matrix used by [`Wiberg`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum VarProJacobian {
    /// Kaufman's approximation: `Σ_p P_p ⊗ s̄_p s̄_pᵀ` (default).
    #[default]
    Kaufman,
    /// Golub–Pereyra: adds `Σ_p (r_p r_pᵀ) ⊗ (M̃_pᵀM̃_p)⁻¹`.
    Full,
}

/// Damped Wiberg / VarPro solver (see the module documentation).
#[derive(Debug, Clone)]
pub struct Wiberg {
    pub max_iterations: usize,
    pub function_tolerance: f64,
    pub gradient_tolerance: f64,
    /// Initial damping relative to the mean diagonal of `JᵀJ`.
    pub initial_lambda: f64,
    /// Ridge on the point normal matrices (final stage).
    pub point_damping: f64,
    /// Ridge of the first stage (skipped unless larger than `point_damping`).
    pub point_damping_initial: f64,
    /// Shrink factor of the continuation ridge between stages (0: a single first stage).
    pub point_damping_decrease: f64,
    /// Damping on the translation parameters, as a multiple of that on `M`.
    pub translation_damping: f64,
    pub jacobian: VarProJacobian,
    /// Creep window (iterations; 0: never switch to the full Jacobian).
    pub creep_window: usize,
    /// Relative objective decrease over `creep_window` below which the run is creeping.
    pub creep_tolerance: f64,
}

/// Damping beyond which the solver gives up (relative to the mean diagonal).
const LAMBDA_MAX: f64 = 1e12;
/// Smallest damping (relative).
const LAMBDA_MIN: f64 = 1e-12;

impl Wiberg {
    /// Takes the Wiberg-relevant fields of `cfg`.
    pub fn from_config(cfg: &CompletionConfig) -> Self {
        Self {
            max_iterations: cfg.max_iterations,
            function_tolerance: cfg.function_tolerance,
            gradient_tolerance: cfg.gradient_tolerance,
            initial_lambda: cfg.initial_lambda,
            point_damping: cfg.point_damping,
            point_damping_initial: cfg.point_damping_initial,
            point_damping_decrease: cfg.point_damping_decrease,
            translation_damping: cfg.translation_damping,
            jacobian: cfg.jacobian,
            creep_window: cfg.creep_window,
            creep_tolerance: cfg.creep_tolerance,
        }
    }

    /// Assembles `JᵀJ` (column-major n×n into `h`, full symmetric) from per-track blocks.
    fn assemble(
        &self,
        problem: &CompletionProblem,
        u: &[f64],
        ps: &super::PointSolve,
        h: &mut [f64],
        jacobian: VarProJacobian,
    ) {
        let (q, r) = (problem.q(), problem.rank);
        let n = 2 * problem.n_frames * q;
        let full = jacobian == VarProJacobian::Full;
        h.iter_mut().for_each(|x| *x = 0.0);
        let mut rows: Vec<usize> = Vec::new();
        let mut mt: Vec<f64> = Vec::new(); // M̃, 2k×r
        let mut cm: Vec<f64> = Vec::new(); // C = M̃ A⁻¹, 2k×r
        let mut pm: Vec<f64> = Vec::new(); // P, 2k×2k
        let mut ss = vec![0.0; q * q];
        let mut sbar = vec![0.0; q];
        let ainv_all = &ps.ainv;
        for p in 0..problem.n_points {
            let (lo, hi) = (problem.col_ptr[p], problem.col_ptr[p + 1]);
            let m2 = 2 * (hi - lo);
            rows.clear();
            for o in lo..hi {
                let f = problem.col_frame[o];
                rows.push(2 * f);
                rows.push(2 * f + 1);
            }
            let ainv = &ainv_all[p * r * r..(p + 1) * r * r];
            mt.clear();
            for &i in &rows {
                mt.extend_from_slice(&u[i * q..i * q + r]);
            }
            cm.clear();
            cm.resize(m2 * r, 0.0);
            for a in 0..m2 {
                for c in 0..r {
                    let mut v = 0.0;
                    for c2 in 0..r {
                        v += mt[a * r + c2] * ainv[c2 * r + c];
                    }
                    cm[a * r + c] = v;
                }
            }
            pm.clear();
            pm.resize(m2 * m2, 0.0);
            for a in 0..m2 {
                for b in 0..=a {
                    let mut v = if a == b { 1.0 } else { 0.0 };
                    for c in 0..r {
                        v -= cm[a * r + c] * mt[b * r + c];
                    }
                    pm[a * m2 + b] = v;
                    pm[b * m2 + a] = v;
                }
            }
            sbar[..r].copy_from_slice(&ps.s[p * r..(p + 1) * r]);
            if problem.affine {
                sbar[r] = 1.0;
            }
            for c in 0..q {
                for c2 in 0..q {
                    ss[c * q + c2] = sbar[c] * sbar[c2];
                }
            }
            let res = &ps.res[2 * lo..2 * hi];
            for b in 0..m2 {
                let colbase = rows[b] * q;
                for a in 0..m2 {
                    let rowbase = rows[a] * q;
                    let pab = pm[a * m2 + b];
                    let rab = res[a] * res[b];
                    for c2 in 0..q {
                        let col =
                            &mut h[(colbase + c2) * n + rowbase..(colbase + c2) * n + rowbase + q];
                        for c in 0..q {
                            col[c] += pab * ss[c * q + c2];
                        }
                        if full && c2 < r {
                            for c in 0..r {
                                col[c] += rab * ainv[c * r + c2];
                            }
                        }
                    }
                }
            }
        }
    }
}

impl CompletionSolver for Wiberg {
    fn name(&self) -> &'static str {
        "wiberg"
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
        let (q, r) = (problem.q(), problem.rank);
        let nrows = 2 * problem.n_frames;
        let n = nrows * q;
        let mut u = problem.pack(m0, t0);
        problem.normalize(&mut u);
        // Continuation on the point ridge: a first stage with a larger ridge keeps weakly
        // constrained points from running off to infinity, the last stage uses the final one.
        let mut stages = Vec::with_capacity(4);
        let mut mu_stage = self.point_damping_initial;
        while mu_stage > self.point_damping && stages.len() < 64 {
            stages.push(mu_stage);
            mu_stage *= self.point_damping_decrease;
        }
        stages.push(self.point_damping);
        let mut ps = problem.solve_points(&u, stages[0], 0.0, true);
        let initial_cost = ps.cost;
        let mut h = vec![0.0; n * n];
        let mut g: Vec<f64> = Vec::new();
        let mut mean_diag = 1.0;
        let mut status = SolverStatus::MaxIterations;
        let mut it = 0;
        let mut lambda = self.initial_lambda;
        let mut jacobian = self.jacobian;
        // Objective after each iteration (for creep detection).
        let mut history: Vec<f64> = Vec::new();
        problem.emit(observer, self.name(), run, 0, ps.cost, lambda);
        for (stage, &mu) in stages.iter().enumerate() {
            let last = stage + 1 == stages.len();
            if stage > 0 {
                ps = problem.solve_points(&u, mu, 0.0, true);
            }
            let ftol = if last {
                self.function_tolerance
            } else {
                self.function_tolerance.max(1e-6)
            };
            let gtol = if last {
                self.gradient_tolerance
            } else {
                self.gradient_tolerance.max(1e-5)
            };
            let mut need_assembly = true;
            status = SolverStatus::MaxIterations;
            while it < self.max_iterations {
                if need_assembly {
                    let (grad, rel) = problem.gradient(&ps);
                    if rel <= gtol || ps.cost <= 0.0 {
                        status = SolverStatus::Converged;
                        break;
                    }
                    g = grad;
                    self.assemble(problem, &u, &ps, &mut h, jacobian);
                    mean_diag = (0..n).map(|i| h[i * n + i]).sum::<f64>() / n as f64;
                    if !(mean_diag > 0.0 && mean_diag.is_finite()) {
                        mean_diag = 1.0;
                    }
                    need_assembly = false;
                }
                it += 1;
                let damp = |i: usize| {
                    if problem.affine && i % q == r {
                        self.translation_damping * lambda * mean_diag
                    } else {
                        lambda * mean_diag
                    }
                };
                let a = Mat::from_fn(n, n, |i, j| {
                    h[j * n + i] + if i == j { damp(i) } else { 0.0 }
                });
                let step = a.llt(Side::Lower).ok().map(|llt| {
                    let mut rhs = Mat::from_fn(n, 1, |i, _| -g[i]);
                    llt.solve_in_place(rhs.as_mut());
                    rhs
                });
                let mut accepted = false;
                let mut converged = false;
                if let Some(step) = step {
                    let mut delta: Vec<f64> = (0..n).map(|i| step[(i, 0)]).collect();
                    project_out_gauge(&u, &mut delta, nrows, q, r);
                    let mut cand: Vec<f64> = u.iter().zip(&delta).map(|(a, b)| a + b).collect();
                    problem.normalize(&mut cand);
                    let ps_new = problem.solve_points(&cand, mu, 0.0, true);
                    let (old, new) = (ps.objective(), ps_new.objective());
                    if new.is_finite() && new < old {
                        let rel_dec = (old - new) / old.max(f64::MIN_POSITIVE);
                        converged = rel_dec < ftol && lambda <= 1.0;
                        u = cand;
                        ps = ps_new;
                        accepted = true;
                    }
                }
                if accepted {
                    lambda = (lambda / 10.0).max(LAMBDA_MIN);
                    need_assembly = true;
                } else {
                    lambda *= 10.0;
                }
                problem.emit(observer, self.name(), run, it, ps.cost, lambda);
                if converged {
                    status = SolverStatus::Converged;
                    break;
                }
                history.push(ps.objective());
                let w = self.creep_window;
                if w > 0 && jacobian == VarProJacobian::Kaufman && history.len() > w {
                    let (then, now) = (history[history.len() - 1 - w], ps.objective());
                    if then - now < self.creep_tolerance * then {
                        jacobian = VarProJacobian::Full;
                        need_assembly = true;
                    }
                }
                if lambda > LAMBDA_MAX {
                    let (_, rel) = problem.gradient(&ps);
                    status = if rel <= gtol.sqrt() {
                        SolverStatus::Converged
                    } else {
                        SolverStatus::Stalled
                    };
                    lambda = self.initial_lambda;
                    break;
                }
            }
            if it >= self.max_iterations && status == SolverStatus::MaxIterations {
                break;
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

/// Removes the gauge component of a step: with `M` orthonormal, `δM ← δM − M(MᵀδM)` and
/// (affine) `δt ← δt − M(Mᵀδt)`.
fn project_out_gauge(u: &[f64], delta: &mut [f64], nrows: usize, q: usize, r: usize) {
    for col in 0..q {
        for c in 0..r {
            let d: f64 = (0..nrows).map(|i| u[i * q + c] * delta[i * q + col]).sum();
            for i in 0..nrows {
                delta[i * q + col] -= d * u[i * q + c];
            }
        }
    }
}
