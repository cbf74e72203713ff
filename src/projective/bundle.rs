//! Sparse Levenberg–Marquardt on a camera–point graph, with the points eliminated by the
//! Schur complement: the one engine behind every projective stage (pOSE, projective bundle
//! adjustment) and meant for the metric perspective model too.
//!
//! # Objective
//!
//! With cameras `c_f` and points `x_p`, and one residual block `r(c_f, x_p; w_fp) ∈ Rᵐ` per
//! observed pair (a [`BundleModel`] says what it is),
//!
//! ```text
//!   minimise  E(c, x) = Σ_{(f,p) observed} ‖r(c_f, x_p; w_fp)‖².
//! ```
//!
//! Parameters may live on a manifold: a model gives a tangent basis `B` at each camera or
//! point (e.g. the unit sphere for a homogeneous `P_f ∈ R¹²` or `X_p ∈ R⁴`, where scale is
//! a gauge freedom) and the update is `v ← normalise(v + B δ)`.
//!
//! # Step
//!
//! The Gauss–Newton matrix has the arrow structure `[U W; Wᵀ V]` with `U` block-diagonal
//! over cameras, `V` block-diagonal over points and `W_fp = J_cᵀ J_x` one block per
//! observation. With damping `λ D` on the cameras (and on the points unless
//! [`LmConfig::damp_points`] is false), the points are eliminated:
//!
//! ```text
//!   S = U + λD − Σ_p W_p V_p*⁻¹ W_pᵀ,    S δc = −g_c + Σ_p W_p V_p*⁻¹ g_p,
//!   δx_p = V_p*⁻¹ (−g_p − W_pᵀ δc).
//! ```
//!
//! `S` (the reduced camera system) is sparse: block `(f, g)` is non-zero only when frames
//! `f` and `g` share a track, so for a video it is banded. It is factorised by faer's sparse
//! Cholesky (fill-reducing AMD ordering, supernodal or simplicial by its own flop rule);
//! the symbolic analysis is done once per problem, and the numeric factor's
//! storage and workspace once per adjustment (`Factor`).
//!
//! **Long tracks: `S` never formed** ([`implicit`], [`LmConfig::linear_solver`]). Where
//! every frame shares tracks with most others, `S` and its factor are dense (`(cF)²/2`
//! numbers each, `O((cF)³)` per factorization). Where they would hold more than
//! [`ITERATIVE_FILL`] times the linearization's numbers, the step is found instead by
//! preconditioned conjugate gradients on `S` applied observation by observation, with
//! memory linear in the observations whatever the camera graph.
//!
//! **Variable projection** ([`LmConfig::resolve_points`] with `damp_points = false`): after
//! every camera step the points are replaced by their optimum for the new cameras (a few
//! damped Gauss–Newton iterations per point; one is exact for a bilinear model). For
//! bilinear problems this is Kaufman's VarPro / the damped Wiberg step; for the nonlinear
//! projective residual it is the "VarPro for BA" of Hong, Zach, Fitzgibbon & Cipolla (ECCV
//! 2016), which widens the basin of convergence from poor starts.
//!
//! **Gauge.** A model may name gauge directions ([`BundleModel::gauge_pins`]); they get a
//! spring of the data's stiffness, so that no exact null space is left and the damping can
//! fall as low as the soft modes of a long sequence need (they are what limits a damped
//! step's progress there).
//!
//! The damping falls fivefold after a step whose gain ratio `ρ` (actual over predicted
//! decrease) exceeds 1/4 and is kept after a smaller gain; a failed step multiplies it by
//! `ν` and doubles `ν` (Nielsen). `D = diag(U)` floored at `10⁻⁹ · mean diag(U)`. Nielsen's
//! smooth decrease (`λ·max(1/3, 1 − (2ρ − 1)³)`) kept λ near 1e-8 on a 300-frame sequence
//! whose gains stayed between 1/4 and 3/4, and took 34 solves where this rule takes 15
//! (docs/results.md). After a rejected step, the damping at which a step is then accepted is
//! kept for the next step rather than lowered: along a long sequence's soft modes the
//! steps alternated *accepted at λ, rejected at λ/5, rejected at 2λ/5, accepted at 8λ/5*
//! (three solves per accepted step; measured, docs/results.md).
//!
//! **When `S` fails to factorize.** In exact arithmetic `S` is positive definite for any
//! `λ > 0` (with the gauge springs); in floating point a point whose block `V_p` is nearly
//! singular can make it indefinite at small `λ` (`V_p⁻¹` is accurate only to
//! `cond(V_p)·ε`). The first failure raises the point blocks' regularisation from `10⁻¹²`
//! to `√ε` of their mean diagonal for the rest of the run and retries the same `λ`
//! (`POINT_BLOCK_FLOOR`); a later failure multiplies `λ` by `ν`, and `λ` is not lowered
//! again below twice the largest damping that failed (each failure costs a factorization).
//! Measured on the 10 000-frame projective corridor: 23 of 42 solves failed before, 4 of
//! 24 with this rule, and the final RMS is 0.466074287 px against 0.466074903
//! (docs/results.md).
//!
//! # Complexity
//!
//! With `n_obs` observations, `k_p` the number of frames seeing track `p`, camera tangent
//! dimension `c` and point dimension `d`: linearisation `O(n_obs (c + d) m)`; forming `S`
//! `O(Σ_p k_p² c² d)` (at most 4 times that where runs of tracks are multiplied as dense
//! blocks, at the speed of a matrix product); its factorisation depends on the fill of the
//! camera graph — `O(F b² c³)` for a banded graph of half-bandwidth `b` (a video),
//! `O((cF)³)` only when every frame shares tracks with every other — or, on the iterative
//! path, `O(n_obs m (c + d))` per conjugate-gradient product and no `S`. Memory:
//! `O(n_obs m (c + d))` for the residuals and the camera and point Jacobians (`m (c + 1 + d)` numbers per observation:
//! 30 for the projective model, 20 for a 6-parameter affine camera; the blocks
//! `W = J_cᵀ J_x` are formed where they are used, not stored) plus the non-zeros of `S`
//! and of its factor; nothing is `O(F·N)`. Tracks are linearised in
//! parallel, then the camera blocks in parallel over cameras.
//!
//! # References
//!
//! * B. Triggs, P. McLauchlan, R. Hartley and A. Fitzgibbon, "Bundle adjustment — a modern
//!   synthesis", Vision Algorithms 1999 (the Schur complement, §6).
//! * J. H. Hong, C. Zach, A. Fitzgibbon and R. Cipolla, "Projective bundle adjustment from
//!   arbitrary initialization using the variable projection method", ECCV 2016.
//! * H. B. Nielsen, "Damping parameter in Marquardt's method", IMM-REP-1999-05, DTU.

use std::time::Instant;

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::matmul::triangular::{self, BlockStructure};
use faer::sparse::linalg::cholesky::{LltRef, SymbolicCholesky, factorize_symbolic_cholesky};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMat};
use faer::{Accum, Mat, MatMut, MatRef, Par, Side};
use rayon::prelude::*;

use crate::completion::linalg;
use crate::{Event, Observer, SolverReport, SolverStatus};

pub mod implicit;

/// A residual model: what one observation contributes, and the parameter manifolds.
///
/// Jacobians are row-major, with respect to the *stored* parameters; the engine maps them
/// to the tangent space with [`BundleModel::cam_basis`] / [`BundleModel::pt_basis`].
pub trait BundleModel: Sync {
    /// Stored parameters per camera.
    fn cam_len(&self) -> usize;
    /// Tangent dimension per camera (`≤ cam_len`).
    fn cam_dim(&self) -> usize;
    /// Stored parameters per point.
    fn pt_len(&self) -> usize;
    /// Tangent dimension per point.
    fn pt_dim(&self) -> usize;
    /// Residuals per observation.
    fn res_dim(&self) -> usize;
    /// Parameters shared by every observation (e.g. one focal length for all frames),
    /// Euclidean. Default 0.
    fn glob_len(&self) -> usize {
        0
    }
    /// Residual `r` (length `res_dim`) of an observation `w`, and optionally the Jacobians
    /// (`∂r/∂cam`: res_dim × cam_len, `∂r/∂pt`: res_dim × pt_len, `∂r/∂glob`: res_dim ×
    /// glob_len, all row-major).
    fn eval(
        &self,
        cam: &[f64],
        pt: &[f64],
        glob: &[f64],
        w: [f64; 2],
        r: &mut [f64],
        jac: Option<Jacobians<'_>>,
    );
    /// Tangent basis at a camera (`cam_len × cam_dim`, row-major) into `out`; returns false
    /// when the parameters are Euclidean (basis = identity; `out` untouched).
    fn cam_basis(&self, _cam: &[f64], _out: &mut [f64]) -> bool {
        false
    }
    /// Tangent basis at a point, as [`BundleModel::cam_basis`].
    fn pt_basis(&self, _pt: &[f64], _out: &mut [f64]) -> bool {
        false
    }
    /// Maps a camera back onto its manifold after an update (e.g. unit norm).
    fn normalize_cam(&self, _cam: &mut [f64]) {}
    /// Maps a point back onto its manifold after an update.
    fn normalize_pt(&self, _pt: &mut [f64]) {}
    /// Gauge anchors: `(camera, directions)` in stored-parameter space along which the
    /// cost is invariant (the gauge), to be held by a spring of stiffness comparable to the
    /// data's (the mean diagonal of the camera blocks). Removing the exact null space lets
    /// the damping go to zero, which the soft (non-gauge) modes of a long sequence need.
    /// Default: none.
    fn gauge_pins(&self, _cams: &[f64], _n_cams: usize) -> Vec<(usize, Vec<Vec<f64>>)> {
        Vec::new()
    }
    /// Whether the residuals are affine in a point's tangent coordinates (for fixed
    /// cameras) with the identity as the point's basis — a point's optimum is then one
    /// linear least-squares solve, which [`solve_points`] takes directly. Default false.
    fn points_linear(&self) -> bool {
        false
    }
}

/// The Jacobians [`BundleModel::eval`] fills (row-major, stored-parameter space).
pub struct Jacobians<'a> {
    /// `∂r/∂cam`, res_dim × cam_len.
    pub cam: &'a mut [f64],
    /// `∂r/∂pt`, res_dim × pt_len.
    pub pt: &'a mut [f64],
    /// `∂r/∂glob`, res_dim × glob_len (empty when the model has no shared parameters).
    pub glob: &'a mut [f64],
}

/// Orthonormal basis of the tangent space of the unit sphere at `v` (`n × (n−1)`,
/// row-major): the Householder reflection taking `v` to `±e_k` (`k = argmax |v_k|`),
/// with its `k`-th column removed.
pub fn sphere_basis(v: &[f64], out: &mut [f64]) {
    let n = v.len();
    let k = (0..n)
        .max_by(|&a, &b| v[a].abs().total_cmp(&v[b].abs()))
        .unwrap_or(0);
    let mut u = v.to_vec();
    u[k] += if v[k] >= 0.0 { 1.0 } else { -1.0 };
    let uu: f64 = u.iter().map(|x| x * x).sum();
    let d = n - 1;
    for i in 0..n {
        let mut c = 0;
        for j in 0..n {
            if j == k {
                continue;
            }
            let h = if i == j { 1.0 } else { 0.0 } - 2.0 * u[i] * u[j] / uu;
            out[i * d + c] = h;
            c += 1;
        }
    }
}

/// Normalises a vector to unit Euclidean norm (left unchanged if zero or not finite).
pub fn normalize(v: &mut [f64]) {
    let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
    if n > 0.0 && n.is_finite() {
        v.iter_mut().for_each(|x| *x /= n);
    }
}

/// The observations as a bipartite graph, stored by track: observation `o` of track `p`
/// for `o in pt_ptr[p]..pt_ptr[p+1]`, in increasing frame order.
#[derive(Debug, Clone)]
pub struct Graph {
    pub n_cams: usize,
    pub n_pts: usize,
    pub pt_ptr: Vec<usize>,
    pub cam: Vec<usize>,
    pub w: Vec<[f64; 2]>,
}

impl Graph {
    /// Number of observations.
    pub fn n_obs(&self) -> usize {
        self.cam.len()
    }

    /// Observations of track `p` (a range into `cam` / `w`).
    pub fn track(&self, p: usize) -> std::ops::Range<usize> {
        self.pt_ptr[p]..self.pt_ptr[p + 1]
    }

    /// Per frame, the tracks it sees (CSR: `(ptr, tracks)`).
    pub fn by_camera(&self) -> (Vec<usize>, Vec<usize>) {
        let mut ptr = vec![0usize; self.n_cams + 1];
        for &c in &self.cam {
            ptr[c + 1] += 1;
        }
        for f in 0..self.n_cams {
            ptr[f + 1] += ptr[f];
        }
        let mut fill = ptr.clone();
        let mut pts = vec![0usize; self.n_obs()];
        for p in 0..self.n_pts {
            for o in self.track(p) {
                let c = self.cam[o];
                pts[fill[c]] = p;
                fill[c] += 1;
            }
        }
        (ptr, pts)
    }
}

/// Settings of [`minimize`]. Every field has a documented default.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LmConfig {
    /// Cap on linear solves (accepted or rejected steps). Default 300. 0 takes no step:
    /// the start is evaluated — its points re-solved first when `resolve_points` — and
    /// returned (the long path's metric reference uses that); [`Self::validate`] refuses 0
    /// in user settings.
    pub max_iterations: usize,
    /// Converged when an accepted step lowers the cost by less than this, relative.
    /// Default 1e-12.
    pub function_tolerance: f64,
    /// Converged when the step is this small relative to the parameters. Default 1e-12.
    pub parameter_tolerance: f64,
    /// Converged when the cost per residual falls below this (noise-free data). Default
    /// 1e-28 (an RMS of 1e-14 in the model's units).
    pub absolute_tolerance: f64,
    /// Initial damping, relative to the diagonal. Default 1e-4.
    pub initial_lambda: f64,
    /// After an accepted step whose gain ratio exceeds 0.25 (and no rejection since the
    /// last accepted one), the damping is divided by this. Default 5.
    #[serde(default = "default_lambda_decrease")]
    pub lambda_decrease: f64,
    /// Damp the point blocks too (joint LM); false = variable projection. Default false.
    pub damp_points: bool,
    /// Replace the points by their optimum for the new cameras after each step (VarPro).
    /// Default true.
    pub resolve_points: bool,
    /// Damped Gauss–Newton iterations per point when re-solving. Default 10.
    pub point_iterations: usize,
    /// Geodesic acceleration (Transtrum & Sethna 2012) bound `α`: each damped step `δ` is
    /// corrected by `a/2`, `a = −(JᵀJ + λD)⁻¹ Jᵀ r″` with `r″` the directional second
    /// derivative of the residuals along `δ` (finite difference at `0.1 δ`; the same
    /// Cholesky factor), when `2‖a‖ ≤ α‖δ‖`. 0 disables it. Default 0.
    #[serde(default)]
    pub geodesic_acceleration: f64,
    /// Extension of an accepted step along its path `x(α) = x + α δ + α² a/2` (`δ` the
    /// Gauss–Newton step, `a/2` its geodesic correction, if any): when the cost along the
    /// path is concave at `α = 1` (it fell by more than its slope predicts) or its
    /// parabola through `f(0)`, `f′(0)` and `f(1)` has its minimum beyond `α = 1.5`, the
    /// step is tried at that minimum, or doubled while the cost keeps falling, at most
    /// this many extra cost evaluations (each a point re-solve). Where Gauss–Newton
    /// converges linearly — along soft modes whose curvature is mostly the residuals'
    /// own, which `JᵀJ` leaves out — each step covers a small fraction of the way and
    /// the extension takes the rest. 0 disables it. Default 0.
    #[serde(default)]
    pub extension_trials: usize,
    /// Convergence at the noise level: converged when the last `noise_window` accepted
    /// steps together lowered the cost by less than this many noise variances, `σ̂² = E /
    /// (#residuals − #parameters)` (a change of the cost by `σ̂²` is one unit of `χ²`: a
    /// parameter moving by one standard error along its direction). 0 disables it.
    /// Default 0.01 (measured: docs/results.md).
    #[serde(default = "default_noise_tolerance")]
    pub noise_tolerance: f64,
    /// See `noise_tolerance`. Default 10.
    #[serde(default = "default_noise_window")]
    pub noise_window: usize,
    /// Convergence of a long tail: converged when the last `noise_window` accepted steps
    /// together lowered the cost by less than this fraction of it. On a large problem the
    /// noise-level rule asks for a precision no one can use (at 10 000 frames, 3.3·10⁶
    /// residuals, the adjustment lowered χ² by ~0.05 per solve for over 80 solves while the
    /// RMS moved in its seventh digit); this rule stops where the RMS is settled to about
    /// `½·10⁻⁶` of itself, the precision at which the projective benchmarks judge a run
    /// (final RMS within 10⁻⁶ relative of the optimum). 0 disables it. Default 1e-6
    /// (measured: docs/results.md).
    #[serde(default = "default_window_relative_tolerance")]
    pub window_relative_tolerance: f64,
    /// Convergence by the Gauss–Newton decrement: converged when an accepted step that
    /// was nearly undamped (`λ ≤ 10⁻⁶` of the diagonal) and whose gain agreed with its
    /// model (gain ratio ≥ 0.25) was predicted to lower the cost by less than this
    /// fraction of it. The predicted decrease of such a step, `δᵀJᵀJδ`, is the quadratic
    /// model's own estimate of what is left to gain — the Newton decrement's stopping rule
    /// (Boyd & Vandenberghe, *Convex Optimization*, 2004, §9.5.1) with the Gauss–Newton
    /// Hessian — where the `noise_window` rules wait for ten more accepted steps to
    /// confirm it. Along soft modes Gauss–Newton converges linearly and the last steps
    /// gain up to about twice their prediction with a step ratio ≈ 0.96, so what is left
    /// can be ~50 predictions: at 10⁻⁸ the cost is then within ~5·10⁻⁷ of its limit and
    /// the RMS within ~2.5·10⁻⁷, inside the 10⁻⁶ at which the projective benchmarks
    /// judge a run. 0 disables it. Default 1e-8 (measured: docs/results.md).
    #[serde(default = "default_decrement_tolerance")]
    pub decrement_tolerance: f64,
    /// Form the reduced camera system's Schur update by dense matrix products over runs of
    /// up to 64 tracks that share most of their frames, where that is cheaper than track
    /// by track (see `schur_columns`); false: track by track everywhere. The same sums up
    /// to rounding. Default true (measured: docs/results.md, fourteenth session).
    #[serde(default = "default_dense_schur")]
    pub dense_schur: bool,
    /// How the reduced camera system is solved: `direct` (sparse Cholesky), `iterative`
    /// (conjugate gradients on the system applied observation by observation, never
    /// formed; [`implicit`]) or `auto`, iterative when the system or its factor would
    /// outgrow the linearization ([`ITERATIVE_FILL`]). Default `auto`.
    #[serde(default)]
    pub linear_solver: LinearSolver,
    /// Conjugate gradients stop when the reduced system's residual is this fraction of
    /// its right-hand side (`η` of an inexact Newton step). Default 1e-6 (measured:
    /// docs/results.md).
    #[serde(default = "default_cg_tolerance")]
    pub cg_tolerance: f64,
    /// Cap on conjugate-gradient products per solve. Default 500.
    #[serde(default = "default_cg_max_iterations")]
    pub cg_max_iterations: usize,
}

/// How [`minimize`] solves the reduced camera system ([`LmConfig::linear_solver`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LinearSolver {
    /// Iterative when the system's or its Cholesky factor's non-zeros would exceed
    /// [`ITERATIVE_FILL`] times the linearization's numbers and
    /// [`ITERATIVE_MIN_NONZEROS`], direct otherwise.
    #[default]
    Auto,
    /// Sparse Cholesky of the formed system (fill-reducing ordering).
    Direct,
    /// Preconditioned conjugate gradients on the implicit system ([`implicit`]).
    Iterative,
}

/// [`LinearSolver::Auto`] goes iterative when the reduced system's non-zeros (lower
/// triangle, estimated from the camera graph before anything is formed) or its Cholesky
/// factor's exceed this many times the numbers the linearization stores (`n_obs · m (c +
/// 1 + k + d)`). So the direct path's memory stays within a constant times the
/// observations', and it is kept where it is fast: where the factor is small next to
/// the linearization, a factorization costs less than the tens to hundreds of products
/// (each reading the linearization twice) that conjugate gradients take per solve.
/// Measured (docs/results.md): at a ratio of 2.4 (Wilshire, 190 frames with long
/// tracks) the iterative solver took 3 times as long per start, at 4.5 (a 400-frame
/// handheld arc) 0.86 times.
pub const ITERATIVE_FILL: f64 = 3.0;

/// [`LinearSolver::Auto`] stays direct while the reduced system or its factor holds at
/// most this many numbers (8 MB), whatever the ratio to the linearization: a small system
/// — a short window, a few tracks per frame — factorizes in milliseconds and its memory
/// does not matter, and the direct step is exact.
pub const ITERATIVE_MIN_NONZEROS: f64 = 1e6;

fn default_cg_tolerance() -> f64 {
    1e-6
}

fn default_cg_max_iterations() -> usize {
    500
}

fn default_lambda_decrease() -> f64 {
    5.0
}

fn default_decrement_tolerance() -> f64 {
    1e-8
}

/// The damping (relative to the diagonal) at or below which a step counts as undamped for
/// [`LmConfig::decrement_tolerance`]: a damped step's predicted decrease understates what
/// an undamped one would gain along the directions whose curvature is below `λ` times the
/// diagonal, so only nearly Gauss–Newton steps may stop a run. At 10⁻⁶ those are the soft
/// modes of long sequences, whose tails gain more than 10⁻⁸ of the cost per step where
/// they are still moving (measured: docs/results.md), so the rule does not end them early;
/// a window's fit or a small adjustment converges quadratically at `λ` ≈ 10⁻⁶–10⁻⁷.
const UNDAMPED: f64 = 1e-6;

fn default_dense_schur() -> bool {
    true
}

fn default_window_relative_tolerance() -> f64 {
    1e-6
}

fn default_noise_window() -> usize {
    10
}

fn default_noise_tolerance() -> f64 {
    0.01
}

impl LmConfig {
    /// A typed error naming `field` for settings the solver cannot run with: no solves,
    /// a damping that is not positive, or a decrease that does not decrease.
    pub fn validate(&self, field: &'static str) -> crate::Result<()> {
        let bad = |message: String| Err(crate::Error::InvalidConfig { field, message });
        if self.max_iterations == 0 {
            return bad("max_iterations must be at least 1".into());
        }
        if !(self.initial_lambda > 0.0 && self.initial_lambda.is_finite()) {
            return bad(format!(
                "initial_lambda {} is not positive",
                self.initial_lambda
            ));
        }
        if !(self.lambda_decrease > 1.0 && self.lambda_decrease.is_finite()) {
            return bad(format!(
                "lambda_decrease {} is not above 1",
                self.lambda_decrease
            ));
        }
        if !(self.cg_tolerance > 0.0 && self.cg_tolerance < 1.0) {
            return bad(format!(
                "cg_tolerance {} is not in (0, 1)",
                self.cg_tolerance
            ));
        }
        if self.cg_max_iterations == 0 {
            return bad("cg_max_iterations must be at least 1".into());
        }
        Ok(())
    }

    /// These settings with geodesic acceleration `alpha` where they have none
    /// (`geodesic_acceleration` = 0): for an adjustment whose start is known to leave a
    /// long, curved tail (a chain of metric windows), while an explicit setting wins.
    pub(crate) fn or_geodesic(&self, alpha: f64) -> LmConfig {
        let mut c = self.clone();
        if c.geodesic_acceleration == 0.0 && alpha > 0.0 {
            c.geodesic_acceleration = alpha;
        }
        c
    }
}

impl Default for LmConfig {
    fn default() -> Self {
        Self {
            max_iterations: 300,
            function_tolerance: 1e-12,
            parameter_tolerance: 1e-12,
            absolute_tolerance: 1e-28,
            initial_lambda: 1e-4,
            lambda_decrease: default_lambda_decrease(),
            damp_points: false,
            resolve_points: true,
            point_iterations: 10,
            geodesic_acceleration: 0.0,
            extension_trials: 0,
            noise_tolerance: 0.01,
            noise_window: 10,
            window_relative_tolerance: 1e-6,
            decrement_tolerance: default_decrement_tolerance(),
            dense_schur: true,
            linear_solver: LinearSolver::Auto,
            cg_tolerance: default_cg_tolerance(),
            cg_max_iterations: default_cg_max_iterations(),
        }
    }
}

/// A caller's stopping test ([`Progress::stop`]): cameras, points, cost → stop?
pub type StopTest<'s> = dyn FnMut(&[f64], &[f64], f64) -> bool + 's;

/// How [`minimize`] reports its iterations to an observer.
pub struct Progress<'a> {
    pub observer: &'a mut dyn Observer,
    /// Solver name in [`Event::Iteration`].
    pub name: &'static str,
    pub run: usize,
    /// Multiplies `sqrt(cost / #residuals)` to give the RMS reported (pixels per model
    /// unit, and `1/sqrt(m/2)`-style factors for models with extra residual terms).
    pub rms_scale: f64,
    /// The caller's stopping test, asked after each accepted step with the cameras, the
    /// points and the cost: `true` ends the run, reported as converged. An escape
    /// ([`super::ProjectiveConfig::escapes`]) stops once it is back in the basin of the
    /// model it left. `None`: no such test.
    pub stop: Option<&'a mut StopTest<'a>>,
}

/// The reduced camera system's fixed sparsity pattern (lower triangle, CSC) and its
/// symbolic Cholesky factorisation.
struct Pattern {
    c: usize,
    /// Per camera `g`, the cameras `f > g` that share a track with it (sorted).
    nbrs: Vec<Vec<usize>>,
    col_ptr: Vec<usize>,
    /// The tracks with observations, by their first camera (stably): the Schur update
    /// visits them in this order, so that consecutive tracks write to nearby columns of
    /// the reduced system (in the input's order a long sequence's tracks may jump along
    /// it, each a walk over cold memory).
    order: Vec<usize>,
    /// `order` cut into runs of consecutive tracks (see [`Chunk`]), in order.
    chunks: Vec<Chunk>,
    /// The chunks' camera sets, one after the other (each sorted).
    chunk_cams: Vec<usize>,
    symbolic: SymbolicSparseColMat<usize>,
    llt: SymbolicCholesky<usize>,
}

/// The numeric Cholesky factor of the reduced camera system and the workspace of its
/// factorization and solves, allocated once per adjustment and reused by every solve.
/// (faer's `Llt::try_new_with_symbolic` allocates and zero-fills both on each call: on
/// Wilshire, 190 frames with a nearly dense reduced system, 7 % of the adjustment's time
/// went to page faults and memset.) Memory: `nnz(L)` values plus the factorization's
/// workspace, as before, but held for the adjustment's duration.
struct Factor {
    values: Vec<f64>,
    work: MemBuffer,
    /// The parallelism the workspace was sized for (faer's global setting at the start).
    par: Par,
}

impl Factor {
    fn new(symbolic: &SymbolicCholesky<usize>) -> Result<Self, String> {
        let par = faer::get_global_parallelism();
        let req = StackReq::or(
            symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default()),
            symbolic.solve_in_place_scratch::<f64>(1, par),
        );
        let work = MemBuffer::try_new(req)
            .map_err(|e| format!("workspace of the reduced camera system's Cholesky: {e:?}"))?;
        let mut values = Vec::new();
        values
            .try_reserve_exact(symbolic.len_val())
            .map_err(|e| format!("Cholesky factor of the reduced camera system: {e}"))?;
        values.resize(symbolic.len_val(), 0.0);
        Ok(Self { values, work, par })
    }

    /// Factorizes `mat` (lower triangle); `false` when it is not numerically positive
    /// definite (the values are then meaningless until the next success). The values need
    /// no clearing between calls: faer's supernodal factorization zeroes them itself and
    /// the simplicial one writes every entry before reading it.
    fn factorize(
        &mut self,
        symbolic: &SymbolicCholesky<usize>,
        mat: SparseColMatRef<'_, usize, f64>,
    ) -> bool {
        symbolic
            .factorize_numeric_llt::<f64>(
                &mut self.values,
                mat,
                Side::Lower,
                Default::default(),
                self.par,
                MemStack::new(&mut self.work),
                Default::default(),
            )
            .is_ok()
    }

    /// Solves `S x = rhs` in place with the last successful factorization.
    fn solve(&mut self, symbolic: &SymbolicCholesky<usize>, rhs: MatMut<'_, f64>) {
        LltRef::new(symbolic, &self.values).solve_in_place_with_conj(
            faer::Conj::No,
            rhs,
            self.par,
            MemStack::new(&mut self.work),
        );
    }
}

/// Per camera `g`, the cameras `f > g` that share a track with it (sorted): the
/// off-diagonal blocks of the reduced system's lower triangle; `None` as soon as there are
/// more than `limit` of them. `O(Σ_p k_p²)` time at most (the scan stops at the limit),
/// `O(F)` beyond the output.
fn neighbours(g: &Graph, limit: usize) -> Option<Vec<Vec<usize>>> {
    let (cptr, cpts) = g.by_camera();
    let mut mark = vec![usize::MAX; g.n_cams];
    let mut nbrs = vec![Vec::new(); g.n_cams];
    let mut pairs = 0usize;
    for cam in 0..g.n_cams {
        for &p in &cpts[cptr[cam]..cptr[cam + 1]] {
            for o in g.track(p) {
                let f = g.cam[o];
                if f > cam && mark[f] != cam {
                    mark[f] = cam;
                    nbrs[cam].push(f);
                }
            }
        }
        pairs += nbrs[cam].len();
        if pairs > limit {
            return None;
        }
        nbrs[cam].sort_unstable();
    }
    Some(nbrs)
}

impl Pattern {
    fn new(
        g: &Graph,
        nbrs: Vec<Vec<usize>>,
        c: usize,
        k: usize,
        dense: bool,
    ) -> Result<Self, String> {
        let n = g.n_cams * c + k;
        let mut col_ptr = Vec::with_capacity(n + 1);
        let mut row_idx = Vec::new();
        col_ptr.push(0);
        for cam in 0..g.n_cams {
            for col in 0..c {
                for r in col..c {
                    row_idx.push(cam * c + r);
                }
                for &f in &nbrs[cam] {
                    for r in 0..c {
                        row_idx.push(f * c + r);
                    }
                }
                for r in 0..k {
                    row_idx.push(g.n_cams * c + r);
                }
                col_ptr.push(row_idx.len());
            }
        }
        for col in 0..k {
            for r in col..k {
                row_idx.push(g.n_cams * c + r);
            }
            col_ptr.push(row_idx.len());
        }
        let mut order: Vec<usize> = (0..g.n_pts).filter(|&p| !g.track(p).is_empty()).collect();
        order.sort_by_key(|&p| g.cam[g.pt_ptr[p]]);
        let (mut chunks, chunk_cams) = chunks(g, &order);
        if !dense {
            chunks.iter_mut().for_each(|c| c.dense = false);
        }
        let symbolic = SymbolicSparseColMat::new_checked(n, n, col_ptr.clone(), None, row_idx);
        let llt = factorize_symbolic_cholesky(
            symbolic.as_ref(),
            Side::Lower,
            Default::default(),
            Default::default(),
        )
        .map_err(|e| format!("symbolic Cholesky of the reduced camera system: {e:?}"))?;
        Ok(Self {
            c,
            nbrs,
            col_ptr,
            order,
            chunks,
            chunk_cams,
            symbolic,
            llt,
        })
    }

    /// Value index of entry `(r, col)` of block `(f, g)`, `f ≥ g` (and `r ≥ col` when
    /// `f == g`).
    #[inline]
    fn pos(&self, f: usize, g: usize, r: usize, col: usize) -> usize {
        let c = self.c;
        let base = self.col_ptr[g * c + col];
        if f == g {
            base + r - col
        } else {
            let k = self.nbrs[g]
                .binary_search(&f)
                .unwrap_or_else(|_| unreachable!());
            self.off_diagonal(g, col, k) + r
        }
    }

    /// Value index of the first row of column `col` of block `(nbrs[g][k], g)`: column
    /// `col` of camera `g` holds the diagonal block's rows `col..c`, then `c` rows per
    /// neighbour in order.
    #[inline]
    fn off_diagonal(&self, g: usize, col: usize, k: usize) -> usize {
        self.col_ptr[g * self.c + col] + (self.c - col) + k * self.c
    }

    /// Value index of the shared-unknown row `r` in column `col` of camera `g`.
    #[inline]
    fn glob_in_cam(&self, g: usize, col: usize, r: usize) -> usize {
        let c = self.c;
        self.col_ptr[g * c + col] + (c - col) + self.nbrs[g].len() * c + r
    }

    /// Value index of entry `(r, col)`, `r ≥ col`, of the shared-unknown block.
    #[inline]
    fn glob(&self, n_cams: usize, r: usize, col: usize) -> usize {
        self.col_ptr[n_cams * self.c + col] + r - col
    }

    fn nnz(&self) -> usize {
        *self.col_ptr.last().unwrap_or(&0)
    }
}

/// A run of consecutive tracks of [`Pattern::order`] whose Schur update is done as one
/// dense product when `dense` (see [`schur_columns`]): `tracks` indexes `order`, `cams`
/// indexes [`Pattern::chunk_cams`] (the sorted union of the tracks' cameras).
struct Chunk {
    tracks: std::ops::Range<usize>,
    cams: std::ops::Range<usize>,
    dense: bool,
}

/// At most this many tracks per chunk: `CHUNK_TRACKS · d` is the inner dimension of the
/// chunk's product (192 for `d = 3`), where faer's kernels run near their peak.
const CHUNK_TRACKS: usize = 64;
/// A chunk stops growing when its padded product, `|U|² · |T|` for `|T|` tracks over the
/// union `U` of their cameras, would exceed this multiple of the exact work `Σ k_p²`
/// (zeros where a track does not see a camera of the union): the dense kernels are about
/// ten times faster per operation than the blocked loop (docs/results.md).
const CHUNK_PADDING: usize = 4;
/// Chunks with fewer tracks than this, or fewer cameras, take the per-track loop.
const CHUNK_MIN_TRACKS: usize = 8;
const CHUNK_MIN_CAMS: usize = 4;

/// Cuts `order` greedily into [`Chunk`]s: each takes the next tracks while it has fewer
/// than [`CHUNK_TRACKS`] and its padded work stays within [`CHUNK_PADDING`] times the
/// exact. The cut depends on the graph only (not on the number of threads). `O(n_obs)`
/// plus the sorting of each chunk's cameras.
fn chunks(g: &Graph, order: &[usize]) -> (Vec<Chunk>, Vec<usize>) {
    let mut stamp = vec![usize::MAX; g.n_cams];
    let mut chunks = Vec::new();
    let mut cams = Vec::new();
    let mut i = 0;
    while i < order.len() {
        let (start, cam_start) = (i, cams.len());
        let mut exact = 0usize;
        while i < order.len() {
            let range = g.track(order[i]);
            let k = range.len();
            let new = range.clone().filter(|&o| stamp[g.cam[o]] != start).count();
            let (t, u) = (i - start + 1, cams.len() - cam_start + new);
            if t > 1 && (t > CHUNK_TRACKS || u * u * t > CHUNK_PADDING * (exact + k * k)) {
                break;
            }
            for o in range {
                let f = g.cam[o];
                if stamp[f] != start {
                    stamp[f] = start;
                    cams.push(f);
                }
            }
            exact += k * k;
            i += 1;
        }
        cams[cam_start..].sort_unstable();
        chunks.push(Chunk {
            tracks: start..i,
            cams: cam_start..cams.len(),
            dense: i - start >= CHUNK_MIN_TRACKS && cams.len() - cam_start >= CHUNK_MIN_CAMS,
        });
    }
    (chunks, cams)
}

/// Outcome of [`minimize`].
#[derive(Debug, Clone)]
pub struct LmResult {
    pub report: SolverReport,
    /// Cost after each accepted step (first entry: the starting cost).
    pub costs: Vec<f64>,
    /// Non-zeros of the reduced camera system (lower triangle), for the memory figures; 0
    /// on the iterative path (never formed).
    pub schur_nnz: usize,
    /// Accepted steps that were extended along their path (`extension_trials`).
    pub extensions: usize,
    /// The solver the reduced systems took (`Direct` or `Iterative`, never `Auto`).
    pub linear_solver: LinearSolver,
    /// Conjugate-gradient products over the run (0 for the direct solver).
    pub cg_iterations: usize,
}

/// Cost `Σ ‖r‖²` of the current parameters (per-track sums in parallel, added in track
/// order so that the result does not depend on the thread schedule).
pub fn cost<M: BundleModel>(model: &M, g: &Graph, cams: &[f64], pts: &[f64], glob: &[f64]) -> f64 {
    let (cl, pl, m) = (model.cam_len(), model.pt_len(), model.res_dim());
    (0..g.n_pts)
        .into_par_iter()
        .map(|p| {
            let mut r = vec![0.0; m];
            let x = &pts[p * pl..(p + 1) * pl];
            let mut s = 0.0;
            for o in g.track(p) {
                let f = g.cam[o];
                model.eval(&cams[f * cl..(f + 1) * cl], x, glob, g.w[o], &mut r, None);
                s += r.iter().map(|v| v * v).sum::<f64>();
            }
            s
        })
        .collect::<Vec<_>>()
        .iter()
        .sum()
}

/// Per-track cost `Σ_f ‖r‖²` of track `p`.
pub fn track_cost<M: BundleModel>(
    model: &M,
    g: &Graph,
    cams: &[f64],
    glob: &[f64],
    x: &[f64],
    p: usize,
) -> f64 {
    let cl = model.cam_len();
    let mut r = vec![0.0; model.res_dim()];
    let mut s = 0.0;
    for o in g.track(p) {
        let f = g.cam[o];
        model.eval(&cams[f * cl..(f + 1) * cl], x, glob, g.w[o], &mut r, None);
        s += r.iter().map(|v| v * v).sum::<f64>();
    }
    s
}

/// Optimises every point for fixed cameras (`iterations` damped Gauss–Newton steps each,
/// in parallel over tracks). Returns the new total cost (added in track order).
/// `O(n_obs)` per iteration.
pub fn solve_points<M: BundleModel>(
    model: &M,
    g: &Graph,
    cams: &[f64],
    glob: &[f64],
    pts: &mut [f64],
    iterations: usize,
) -> f64 {
    let pl = model.pt_len();
    pts.par_chunks_mut(pl)
        .enumerate()
        .map(|(p, x)| solve_point(model, g, cams, glob, x, p, iterations))
        .collect::<Vec<_>>()
        .iter()
        .sum()
}

/// The Gauss–Newton normal equations of track `p`'s point for fixed cameras, in its tangent
/// space (`basis`, `pt_len × pt_dim`, when `has_basis`; else the stored coordinates):
/// `A = Σ J_tᵀ J_t` (lower triangle filled, row-major `pt_dim × pt_dim`) and `b = −Σ J_tᵀ r`.
/// One pass over the track's observations.
#[allow(clippy::too_many_arguments)]
fn point_normal_equations<M: BundleModel>(
    model: &M,
    g: &Graph,
    cams: &[f64],
    glob: &[f64],
    x: &[f64],
    p: usize,
    basis: &[f64],
    has_basis: bool,
) -> (Vec<f64>, Vec<f64>) {
    let (cl, pl, pd, m) = (
        model.cam_len(),
        model.pt_len(),
        model.pt_dim(),
        model.res_dim(),
    );
    let mut r = vec![0.0; m];
    let mut jc = vec![0.0; m * cl];
    let mut jp = vec![0.0; m * pl];
    let mut jg = vec![0.0; m * model.glob_len()];
    let mut jt = vec![0.0; m * pd];
    let mut a = vec![0.0; pd * pd];
    let mut b = vec![0.0; pd];
    for o in g.track(p) {
        let f = g.cam[o];
        model.eval(
            &cams[f * cl..(f + 1) * cl],
            x,
            glob,
            g.w[o],
            &mut r,
            Some(Jacobians {
                cam: &mut jc,
                pt: &mut jp,
                glob: &mut jg,
            }),
        );
        tangent(&jp, basis, has_basis, m, pl, pd, &mut jt);
        for i in 0..m {
            let row = &jt[i * pd..(i + 1) * pd];
            for a1 in 0..pd {
                b[a1] -= row[a1] * r[i];
                for a2 in 0..=a1 {
                    a[a1 * pd + a2] += row[a1] * row[a2];
                }
            }
        }
    }
    (a, b)
}

/// A point whose residuals are affine in it ([`BundleModel::points_linear`]): its optimum
/// `x + (Σ J_xᵀ J_x)⁻¹ (−Σ J_xᵀ r)` by one Cholesky solve, and its cost there; `None` (and
/// `x` untouched) when the normal matrix is not positive definite, left to the damped
/// iterations. Two passes over the track's observations.
fn solve_linear_point<M: BundleModel>(
    model: &M,
    g: &Graph,
    cams: &[f64],
    glob: &[f64],
    x: &mut [f64],
    p: usize,
) -> Option<f64> {
    let pl = model.pt_len();
    if model.pt_dim() != pl {
        return None;
    }
    let (mut a, mut b) = point_normal_equations(model, g, cams, glob, x, p, &[], false);
    let mean_diag = (0..pl).map(|i| a[i * pl + i]).sum::<f64>() / pl as f64;
    for i in 0..pl {
        for j in 0..i {
            a[j * pl + i] = a[i * pl + j];
        }
        a[i * pl + i] += 1e-15 * mean_diag;
    }
    if !(mean_diag > 0.0 && mean_diag.is_finite() && linalg::cholesky(&mut a, pl)) {
        return None;
    }
    linalg::chol_solve(&a, pl, &mut b);
    if !b.iter().all(|v| v.is_finite()) {
        return None;
    }
    for (xi, d) in x.iter_mut().zip(&b) {
        *xi += d;
    }
    model.normalize_pt(x);
    Some(track_cost(model, g, cams, glob, x, p))
}

/// One track's point optimum for fixed cameras; returns its cost.
fn solve_point<M: BundleModel>(
    model: &M,
    g: &Graph,
    cams: &[f64],
    glob: &[f64],
    x: &mut [f64],
    p: usize,
    iterations: usize,
) -> f64 {
    let (pl, pd) = (model.pt_len(), model.pt_dim());
    if model.points_linear()
        && let Some(c) = solve_linear_point(model, g, cams, glob, x, p)
    {
        return c;
    }
    let mut basis = vec![0.0; pl * pd];
    let mut cost = track_cost(model, g, cams, glob, x, p);
    let mut lambda = 1e-6;
    let mut trial = x.to_vec();
    let mut it = 0;
    while it < iterations {
        it += 1;
        let has_basis = model.pt_basis(x, &mut basis);
        let (a, b) = point_normal_equations(model, g, cams, glob, x, p, &basis, has_basis);
        let gnorm = b.iter().map(|v| v * v).sum::<f64>().sqrt();
        if gnorm == 0.0 || !gnorm.is_finite() {
            break;
        }
        let mean_diag = (0..pd).map(|i| a[i * pd + i]).sum::<f64>() / pd as f64;
        let mut improved = false;
        for _ in 0..20 {
            let mut h = a.clone();
            for i in 0..pd {
                for j in 0..i {
                    h[j * pd + i] = h[i * pd + j];
                }
                h[i * pd + i] += lambda * (h[i * pd + i] + 1e-9 * mean_diag) + 1e-15 * mean_diag;
            }
            let mut d = b.clone();
            if !linalg::cholesky(&mut h, pd) {
                lambda *= 10.0;
                continue;
            }
            linalg::chol_solve(&h, pd, &mut d);
            trial.copy_from_slice(x);
            apply(&mut trial, &d, &basis, has_basis, pl, pd);
            model.normalize_pt(&mut trial);
            let c2 = track_cost(model, g, cams, glob, &trial, p);
            if c2 <= cost {
                let rel = (cost - c2) / cost.max(f64::MIN_POSITIVE);
                x.copy_from_slice(&trial);
                cost = c2;
                lambda = (lambda / 10.0).max(1e-12);
                improved = true;
                if rel < 1e-14 {
                    it = iterations;
                }
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    cost
}

/// Frame ranges `[a, b)` covering `0..nf`, at most `parts` of them, with about equal
/// numbers of reduced-system entries in their columns (the Schur update's work follows
/// them).
fn frame_ranges(pattern: &Pattern, nf: usize, cd: usize, parts: usize) -> Vec<(usize, usize)> {
    let parts = parts.clamp(1, nf.max(1));
    let total = pattern.col_ptr[nf * cd].max(1);
    let mut ranges = Vec::with_capacity(parts);
    let mut a = 0;
    for t in 1..=parts {
        let target = total * t / parts;
        let mut b = a;
        while b < nf && (t == parts || pattern.col_ptr[(b + 1) * cd] <= target || b == a) {
            b += 1;
        }
        if b > a {
            ranges.push((a, b));
        }
        a = b;
    }
    if let Some(last) = ranges.last_mut() {
        last.1 = nf;
    } else {
        ranges.push((0, nf));
    }
    ranges
}

/// The Schur complement's share of the cameras `a..b`: for every track seen in one of
/// them, `S_{fi,fj} −= W_{fi} V⁻¹ W_{fj}ᵀ` for the pairs with `fj` in `a..b` (lower
/// triangle, `fi ≥ fj`), the shared-parameter coupling `S_{g,fj} −= Y_g W_{fj}ᵀ`, and
/// `rhs_f += W_f V⁻¹ g_p` for `f` in `a..b`. `vals` holds the CSC values from `offset` on
/// (the columns of the range), `rhs` the range's right-hand side; `ygs` holds `Y_g = W_g V⁻¹`
/// per track (empty without shared parameters). `O(Σ_p k_p² c² d)` over the range's tracks.
///
/// The block sizes of the models in use (`d = 3`, `c` = 5, 6, 7, 11, 12) get their own
/// copies of the loops with the sizes known at compile time (unrolled and vectorized: the
/// adjustment of a 2 000-frame corridor, 19 solves, 13.6 → 7.9 s, docs/results.md); other
/// sizes take the general loops. On CPUs with AVX2 the loops run in a copy compiled for it
/// (the same sums in the same order), and the tracks are visited by their first camera
/// (`Pattern::order`) so that consecutive tracks write to nearby columns (both measured in
/// docs/results.md, "thirteenth session").
///
/// **Dense products over runs of tracks** ([`Chunk`], with [`LmConfig::dense_schur`]): for
/// up to [`CHUNK_TRACKS`] consecutive tracks over the union `U` of their frames, the
/// update of every block at once is `P = Y Wᵀ`, `Y` (`|U|c × |T|d`) holding each track's
/// `Y_i` in its frames' rows and zeros elsewhere, `W` the same for `W_i` over the range's
/// frames; `P`'s lower part (faer's matrix product, one thread per range) is then
/// subtracted block by block where the pattern has a block (the others are zero: no track
/// of the run sees both frames). The runs are cut so that the padded work stays within
/// [`CHUNK_PADDING`] times the exact; faer's kernels run 5–10 times faster per operation
/// than the blocked loop (a complete 150 × 400 projective problem: 0.55 → 0.07–0.13 s per
/// assembly; docs/results.md, fourteenth session).
fn schur_columns(
    inp: &SchurInput<'_>,
    range: (usize, usize),
    vals: &mut [f64],
    offset: usize,
    rhs: &mut [f64],
) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (checked at run time just above).
        return unsafe { schur_columns_avx2(inp, range, vals, offset, rhs) };
    }
    schur_columns_any(inp, range, vals, offset, rhs)
}

/// [`schur_columns_any`] compiled with AVX2 enabled (4-lane loops over a block's rows; the
/// same sums in the same order, so the same values to the bit).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn schur_columns_avx2(
    inp: &SchurInput<'_>,
    range: (usize, usize),
    vals: &mut [f64],
    offset: usize,
    rhs: &mut [f64],
) {
    schur_columns_any(inp, range, vals, offset, rhs)
}

/// [`schur_columns`] for any CPU: dispatches on the block sizes.
#[inline(always)]
fn schur_columns_any(
    inp: &SchurInput<'_>,
    range: (usize, usize),
    vals: &mut [f64],
    offset: usize,
    rhs: &mut [f64],
) {
    macro_rules! sized {
        ($($c:literal),*) => {
            match (inp.dims.0, inp.dims.1) {
                $(($c, 3) => schur_columns_sized::<$c, 3>(inp, range, vals, offset, rhs),)*
                _ => schur_columns_sized::<0, 0>(inp, range, vals, offset, rhs),
            }
        };
    }
    sized!(5, 6, 7, 11, 12)
}

/// What every range of [`schur_columns`] reads: the graph and the system's pattern, the
/// sizes `(c, d, k, m)`, the per-observation blocks `lin` (`stride` values each), the
/// tracks' linearizations, their `V⁻¹` and `Y_g`.
#[derive(Clone, Copy)]
struct SchurInput<'a> {
    g: &'a Graph,
    pattern: &'a Pattern,
    dims: (usize, usize, usize, usize),
    lin: &'a [f64],
    stride: usize,
    lins: &'a [TrackLin],
    vinv: &'a [Vec<f64>],
    ygs: &'a [f64],
}

impl SchurInput<'_> {
    /// The camera and point tangent sizes: `CD`, `PD` when fixed at compile time (non-zero),
    /// else those of `dims`.
    #[inline(always)]
    fn sizes<const CD: usize, const PD: usize>(&self) -> (usize, usize) {
        (
            if CD > 0 { CD } else { self.dims.0 },
            if PD > 0 { PD } else { self.dims.1 },
        )
    }
}

/// [`schur_columns`] with the camera and point tangent sizes `CD`, `PD` fixed at compile
/// time (`0`: read from `dims` at run time).
#[inline(always)]
fn schur_columns_sized<const CD: usize, const PD: usize>(
    inp: &SchurInput<'_>,
    (a, b): (usize, usize),
    vals: &mut [f64],
    offset: usize,
    rhs: &mut [f64],
) {
    let (g, pattern) = (inp.g, inp.pattern);
    let (cd, pd) = inp.sizes::<CD, PD>();
    let mut ys: Vec<f64> = Vec::new();
    let mut ws: Vec<f64> = Vec::new();
    let (mut ybuf, mut wbuf, mut pbuf) = (Vec::new(), Vec::new(), Vec::new());
    for ch in &pattern.chunks {
        let tracks = &pattern.order[ch.tracks.clone()];
        // The tracks come by their first frame.
        if g.cam[g.pt_ptr[tracks[0]]] >= b {
            break;
        }
        let cams = &pattern.chunk_cams[ch.cams.clone()];
        if cams[cams.len() - 1] < a {
            continue;
        }
        if !ch.dense {
            for &p in tracks {
                if track_blocks::<CD, PD>(inp, p, (a, b), rhs, vals, offset, &mut ys, &mut ws) {
                    track_pairs::<CD, PD>(inp, p, (a, b), vals, offset, &ys, &ws);
                }
            }
            continue;
        }
        // The chunk's cameras from `a` on are the rows of its product, those in `a..b` its
        // columns: `P = Y Wᵀ` with `Y` (rows: camera u, component c1; columns: track t,
        // component d) holding `Y_i = W_i V⁻¹` where track t sees camera u and zeros
        // elsewhere, and `W` the same for `W_i` over the columns' cameras.
        let v0 = cams.partition_point(|&f| f < a);
        let v1 = cams.partition_point(|&f| f < b);
        if v0 == v1 {
            // No track of the chunk is seen in `a..b` (they span the range with a gap):
            // nothing of theirs goes to the range's columns or right-hand side.
            continue;
        }
        let (rows, cols, inner) = ((cams.len() - v0) * cd, (v1 - v0) * cd, tracks.len() * pd);
        ybuf.clear();
        ybuf.resize(rows * inner, 0.0);
        wbuf.clear();
        wbuf.resize(cols * inner, 0.0);
        for (t, &p) in tracks.iter().enumerate() {
            if !track_blocks::<CD, PD>(inp, p, (a, b), rhs, vals, offset, &mut ys, &mut ws) {
                continue;
            }
            let mut u = v0;
            for (i, o) in g.track(p).enumerate() {
                let f = g.cam[o];
                if f < a {
                    continue;
                }
                while cams[u] < f {
                    u += 1;
                }
                let r0 = (u - v0) * cd;
                let (y, w) = (
                    &ys[i * cd * pd..(i + 1) * cd * pd],
                    &ws[i * cd * pd..(i + 1) * cd * pd],
                );
                for d in 0..pd {
                    let col = (t * pd + d) * rows + r0;
                    ybuf[col..col + cd].copy_from_slice(&y[d * cd..(d + 1) * cd]);
                    if f < b {
                        let col = (t * pd + d) * cols + r0;
                        for c1 in 0..cd {
                            wbuf[col + c1] = w[c1 * pd + d];
                        }
                    }
                }
            }
        }
        pbuf.clear();
        pbuf.resize(rows * cols, 0.0);
        {
            let y = MatRef::from_column_major_slice(&ybuf, rows, inner);
            let w = MatRef::from_column_major_slice(&wbuf, cols, inner);
            let prod = MatMut::from_column_major_slice_mut(&mut pbuf, rows, cols);
            let (top, bottom) = prod.split_at_row_mut(cols);
            let (y_top, y_bottom) = y.split_at_row(cols);
            triangular::matmul(
                top,
                BlockStructure::TriangularLower,
                Accum::Replace,
                y_top,
                BlockStructure::Rectangular,
                w.transpose(),
                BlockStructure::Rectangular,
                1.0,
                Par::Seq,
            );
            faer::linalg::matmul::matmul(
                bottom,
                Accum::Replace,
                y_bottom,
                w.transpose(),
                1.0,
                Par::Seq,
            );
        }
        // Scatter: block (fi, fj) of the product into S where the pattern has it (the other
        // blocks are zero: no track of the chunk sees both frames).
        for v in 0..v1 - v0 {
            let fj = cams[v0 + v];
            let cols_fj = &pattern.col_ptr[fj * cd..(fj + 1) * cd];
            let nbrs = &pattern.nbrs[fj];
            for c2 in 0..cd {
                let base = cols_fj[c2] - offset;
                let pc = &pbuf[(v * cd + c2) * rows..(v * cd + c2 + 1) * rows];
                for (out, x) in vals[base..base + cd - c2]
                    .iter_mut()
                    .zip(&pc[v * cd + c2..(v + 1) * cd])
                {
                    *out -= x;
                }
            }
            let mut kk = 0;
            for u in v + 1..cams.len() - v0 {
                let fi = cams[v0 + u];
                while kk < nbrs.len() && nbrs[kk] < fi {
                    kk += 1;
                }
                if kk == nbrs.len() {
                    break;
                }
                if nbrs[kk] != fi {
                    continue;
                }
                for c2 in 0..cd {
                    let base = pattern.off_diagonal(fj, c2, kk) - offset;
                    let pc =
                        &pbuf[(v * cd + c2) * rows + u * cd..(v * cd + c2) * rows + (u + 1) * cd];
                    for (out, x) in vals[base..base + cd].iter_mut().zip(pc) {
                        *out -= x;
                    }
                }
            }
        }
    }
}

/// The blocks of track `p` that [`schur_columns`] needs for the cameras `a..b`: `W_i =
/// J_cᵀ J_x` (row-major, `c × d`, in `ws`) and `Y_i = W_i V⁻¹` (stored by columns,
/// `ys[d·c + c1]`, so that a column of a block `Y_i W_jᵀ` is a contiguous run of `c`
/// values) for every observation of the track; also adds the track's share of the
/// right-hand side, `W_f V⁻¹ g_p`, and of the shared-parameter coupling `S_{g,f} −= Y_g
/// W_fᵀ` for its frames in `a..b`. `false` (and nothing done) when the track has no
/// frame from `a` on or none before `b` (it then has no pair in the range's columns).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn track_blocks<const CD: usize, const PD: usize>(
    inp: &SchurInput<'_>,
    p: usize,
    (a, b): (usize, usize),
    rhs: &mut [f64],
    vals: &mut [f64],
    offset: usize,
    ys: &mut Vec<f64>,
    ws: &mut Vec<f64>,
) -> bool {
    let SchurInput {
        g,
        pattern,
        dims: (_, _, k, m),
        lin,
        stride,
        lins,
        vinv,
        ygs,
    } = *inp;
    let (cd, pd) = inp.sizes::<CD, PD>();
    let range = g.track(p);
    // Frames increase along a track.
    let (first, last) = (g.cam[range.start], g.cam[range.end - 1]);
    if first >= b || last < a {
        return false;
    }
    let vi = &vinv[p];
    let gp = &lins[p].gp;
    ys.resize(range.len() * cd * pd, 0.0);
    ws.resize(range.len() * cd * pd, 0.0);
    for (i, o) in range.clone().enumerate() {
        let wb = &mut ws[i * cd * pd..(i + 1) * cd * pd];
        w_block(&lin[o * stride..(o + 1) * stride], (cd, pd, k, m), wb);
        let wb = &ws[i * cd * pd..(i + 1) * cd * pd];
        let y = &mut ys[i * cd * pd..(i + 1) * cd * pd];
        for c1 in 0..cd {
            for d2 in 0..pd {
                let mut s = 0.0;
                for d1 in 0..pd {
                    s += wb[c1 * pd + d1] * vi[d1 * pd + d2];
                }
                y[d2 * cd + c1] = s;
            }
        }
        let f = g.cam[o];
        if (a..b).contains(&f) {
            for c1 in 0..cd {
                let mut s = 0.0;
                for d in 0..pd {
                    s += y[d * cd + c1] * gp[d];
                }
                rhs[(f - a) * cd + c1] += s;
            }
        }
    }
    if k > 0 {
        let yg = &ygs[p * k * pd..(p + 1) * k * pd];
        for (i, o) in range.clone().enumerate() {
            let f = g.cam[o];
            if !(a..b).contains(&f) {
                continue;
            }
            let wb = &ws[i * cd * pd..(i + 1) * cd * pd];
            for c1 in 0..cd {
                for k1 in 0..k {
                    let s: f64 = (0..pd).map(|d| yg[k1 * pd + d] * wb[c1 * pd + d]).sum();
                    vals[pattern.glob_in_cam(f, c1, k1) - offset] -= s;
                }
            }
        }
    }
    true
}

/// The pairs of track `p` in the columns of the cameras `a..b`, one at a time: `S_{fi,fj}
/// −= Y_i W_jᵀ` for its observations `i`, `j` with `fj` in `a..b` and `fi ≥ fj` (from
/// the blocks [`track_blocks`] left in `ys`, `ws`).
#[inline(always)]
fn track_pairs<const CD: usize, const PD: usize>(
    inp: &SchurInput<'_>,
    p: usize,
    (a, b): (usize, usize),
    vals: &mut [f64],
    offset: usize,
    ys: &[f64],
    ws: &[f64],
) {
    let (g, pattern) = (inp.g, inp.pattern);
    let (cd, pd) = inp.sizes::<CD, PD>();
    let range = g.track(p);
    // Column blocks (fj in a..b), rows fi ≥ fj: the later observations of the track.
    let n = range.len();
    for j in 0..n {
        let oj = range.start + j;
        let fj = g.cam[oj];
        if fj < a {
            continue;
        }
        if fj >= b {
            break;
        }
        let wj = &ws[j * cd * pd..(j + 1) * cd * pd];
        let cols = &pattern.col_ptr[fj * cd..(fj + 1) * cd];
        let nbrs = &pattern.nbrs[fj];
        // Column c2 of block (fj, fj) holds rows c2..cd from cols[c2]; of block
        // (fi, fj), fi > fj, rows 0..cd from `Pattern::off_diagonal(fj, c2, kk)`, kk the
        // place of fi among fj's neighbours (increasing with i: a forward scan).
        let mut kk = 0;
        for i in j..n {
            let fi = g.cam[range.start + i];
            let yi = &ys[i * cd * pd..(i + 1) * cd * pd];
            if fi == fj {
                for c2 in 0..cd {
                    let base = cols[c2] - offset;
                    let w2 = &wj[c2 * pd..(c2 + 1) * pd];
                    let out = &mut vals[base..base + (cd - c2)];
                    for (r, v) in out.iter_mut().enumerate() {
                        let c1 = c2 + r;
                        let mut s = 0.0;
                        for d in 0..pd {
                            s += yi[d * cd + c1] * w2[d];
                        }
                        *v -= s;
                    }
                }
            } else {
                while nbrs[kk] < fi {
                    kk += 1;
                }
                debug_assert_eq!(nbrs[kk], fi);
                for c2 in 0..cd {
                    let base = pattern.off_diagonal(fj, c2, kk) - offset;
                    let w2 = &wj[c2 * pd..(c2 + 1) * pd];
                    sub_column(&mut vals[base..base + cd], yi, w2, cd, pd);
                }
            }
        }
    }
}

/// `out[c1] −= Σ_d y[d·c + c1] w[d]` for `c1` in `0..c`: one column of an off-diagonal
/// block `Y_i W_jᵀ` of the Schur update, `y` stored by columns (`c` = `out.len()`, `d` =
/// `w.len()`). The slices are cut to their lengths first so that, with the sizes known
/// at compile time, the loop over `c1` runs without bounds checks, in vector lanes.
#[inline(always)]
fn sub_column(out: &mut [f64], y: &[f64], w: &[f64], cd: usize, pd: usize) {
    let out = &mut out[..cd];
    let y = &y[..cd * pd];
    let w = &w[..pd];
    match pd {
        3 => {
            let (y0, rest) = y.split_at(cd);
            let (y1, y2) = rest.split_at(cd);
            let (w0, w1, w2) = (w[0], w[1], w[2]);
            for (((v, a), b), c) in out.iter_mut().zip(y0).zip(y1).zip(&y2[..cd]) {
                let mut s = 0.0;
                s += a * w0;
                s += b * w1;
                s += c * w2;
                *v -= s;
            }
        }
        _ => {
            for (c1, v) in out.iter_mut().enumerate() {
                let mut s = 0.0;
                for d in 0..pd {
                    s += y[d * cd + c1] * w[d];
                }
                *v -= s;
            }
        }
    }
}

/// The parts of one observation's block of the linearization, `(J_c, r, J_g, J_x)`: the
/// camera Jacobian (`m × c`, tangent space), the residual (`m`), the shared-parameter
/// Jacobian (`m × k`) and the point Jacobian (`m × d`, tangent space), stored in that
/// order (the linearization writes them); `dims` = `(c, d, k, m)`.
#[inline(always)]
fn obs_parts(
    blk: &[f64],
    (cd, pd, k, m): (usize, usize, usize, usize),
) -> (&[f64], &[f64], &[f64], &[f64]) {
    let (jc, rest) = blk.split_at(m * cd);
    let (r, rest) = rest.split_at(m);
    let (jg, rest) = rest.split_at(m * k);
    (jc, r, jg, &rest[..m * pd])
}

/// `W = J_cᵀ J_x` (`c × d`, row-major) of one observation from its block of the
/// linearization ([`obs_parts`] has the layout). `O(m c d)`.
#[inline(always)]
fn w_block(blk: &[f64], dims: (usize, usize, usize, usize), out: &mut [f64]) {
    let (cd, pd, _, m) = dims;
    let (jc, _, _, jx) = obs_parts(blk, dims);
    out[..cd * pd].iter_mut().for_each(|w| *w = 0.0);
    for row in 0..m {
        let a = &jc[row * cd..(row + 1) * cd];
        let b = &jx[row * pd..(row + 1) * pd];
        for c1 in 0..cd {
            for d in 0..pd {
                out[c1 * pd + d] += a[c1] * b[d];
            }
        }
    }
}

/// `buf` (`per_obs` values per observation, in observation order) split into one slice
/// per track, for filling in parallel over tracks.
fn by_track<'a>(buf: &'a mut [f64], g: &Graph, per_obs: usize) -> Vec<&'a mut [f64]> {
    let mut pieces = Vec::with_capacity(g.n_pts);
    let mut rest = buf;
    for p in 0..g.n_pts {
        let (head, tail) = rest.split_at_mut(g.track(p).len() * per_obs);
        pieces.push(head);
        rest = tail;
    }
    pieces
}

/// `out = J B` (m × d) or a copy of `J` when the basis is the identity.
#[inline]
fn tangent(
    j: &[f64],
    basis: &[f64],
    has_basis: bool,
    m: usize,
    n: usize,
    d: usize,
    out: &mut [f64],
) {
    if !has_basis {
        out[..m * d].copy_from_slice(&j[..m * d]);
        return;
    }
    // The models' shapes with sizes known at compile time (unrolled and vectorized; the
    // sums run in the same order, so the results are the same bits): the pivoted scaled
    // orthographic camera, the metric perspective camera (shared and per-frame focal
    // length), the projective camera and point.
    match (m, n, d) {
        (2, 15, 6) => tangent_fixed::<2, 15, 6>(j, basis, out),
        (2, 12, 6) => tangent_fixed::<2, 12, 6>(j, basis, out),
        (2, 13, 7) => tangent_fixed::<2, 13, 7>(j, basis, out),
        (2, 12, 11) => tangent_fixed::<2, 12, 11>(j, basis, out),
        (2, 4, 3) => tangent_fixed::<2, 4, 3>(j, basis, out),
        _ => {
            for i in 0..m {
                for c in 0..d {
                    let mut s = 0.0;
                    for k in 0..n {
                        s += j[i * n + k] * basis[k * d + c];
                    }
                    out[i * d + c] = s;
                }
            }
        }
    }
}

/// [`tangent`] for an `M × N` Jacobian and an `N × D` basis.
#[inline(always)]
fn tangent_fixed<const M: usize, const N: usize, const D: usize>(
    j: &[f64],
    basis: &[f64],
    out: &mut [f64],
) {
    let (j, basis, out) = (&j[..M * N], &basis[..N * D], &mut out[..M * D]);
    for i in 0..M {
        let mut acc = [0.0; D];
        for k in 0..N {
            let a = j[i * N + k];
            let row = &basis[k * D..k * D + D];
            for c in 0..D {
                acc[c] += a * row[c];
            }
        }
        out[i * D..i * D + D].copy_from_slice(&acc);
    }
}

/// `v += B δ` (or `v += δ` for the identity basis).
#[inline]
fn apply(v: &mut [f64], delta: &[f64], basis: &[f64], has_basis: bool, n: usize, d: usize) {
    if !has_basis {
        for k in 0..d {
            v[k] += delta[k];
        }
        return;
    }
    for k in 0..n {
        let mut s = 0.0;
        for c in 0..d {
            s += basis[k * d + c] * delta[c];
        }
        v[k] += s;
    }
}

/// The point part of a Schur step from its camera and shared parts:
/// `δx_p = V_p*⁻¹ (−g_p − Σ_f W_fpᵀ δc_f − W_gpᵀ δg)`, in parallel over tracks, `g_p` given by
/// `gp(p)` (the gradient, or another right-hand side with the same factor). `dims` =
/// (camera, point, shared) tangent dimensions and the residual size; `W_fpᵀ δc_f` is
/// formed as `J_xᵀ (J_c δc_f)`. `O(observations · m (c + d))`.
#[allow(clippy::too_many_arguments)]
fn back_substitute<'a>(
    g: &Graph,
    lin: &[f64],
    stride: usize,
    (cd, pd, k, m): (usize, usize, usize, usize),
    lins: &[TrackLin],
    vinv: &[Vec<f64>],
    gp: impl Fn(usize) -> &'a [f64] + Sync,
    dc: &[f64],
    dg: &[f64],
) -> Vec<f64> {
    (0..g.n_pts)
        .into_par_iter()
        .flat_map_iter(|p| {
            let mut b = gp(p).iter().map(|v| -v).collect::<Vec<_>>();
            for o in g.track(p) {
                let f = g.cam[o];
                let (jc, _, _, jx) = obs_parts(&lin[o * stride..(o + 1) * stride], (cd, pd, k, m));
                for row in 0..m {
                    let jc = &jc[row * cd..(row + 1) * cd];
                    let jdc: f64 = (0..cd).map(|c1| jc[c1] * dc[f * cd + c1]).sum();
                    for d in 0..pd {
                        b[d] -= jx[row * pd + d] * jdc;
                    }
                }
            }
            let wg = &lins[p].wg;
            for k1 in 0..k {
                for d in 0..pd {
                    b[d] -= wg[k1 * pd + d] * dg[k1];
                }
            }
            let vi = &vinv[p];
            (0..pd).map(move |d1| (0..pd).map(|d2| vi[d1 * pd + d2] * b[d2]).sum::<f64>())
        })
        .collect()
}

/// A step `(δc, δg, δx)` in the tangent spaces of the cameras, the shared parameters and
/// the points.
type Step<'s> = (&'s [f64], &'s [f64], &'s [f64]);

/// Parameters `(cameras, points, shared)` being written.
type ParamsMut<'s> = (&'s mut [f64], &'s mut [f64], &'s mut [f64]);

/// The trial parameters of a step from the current ones: cameras and points moved along
/// their tangent bases and mapped back onto their manifolds, the points then re-solved for
/// the new cameras (variable projection) when `resolve_points`. `O(n_obs)` per trial.
struct Stepper<'a, M: BundleModel> {
    model: &'a M,
    g: &'a Graph,
    cams: &'a [f64],
    pts: &'a [f64],
    glob: &'a [f64],
    cam_basis: &'a [f64],
    cam_has_basis: &'a [bool],
    point_iterations: usize,
    resolve_points: bool,
}

impl<M: BundleModel> Stepper<'_, M> {
    /// The parameters moved by `step` into `out`; returns their cost.
    fn trial(&self, (dc, dg, dp): Step<'_>, (tc, tp, tg): ParamsMut<'_>) -> f64 {
        let m = self.model;
        let (cl, cd, pl, pd) = (m.cam_len(), m.cam_dim(), m.pt_len(), m.pt_dim());
        tc.copy_from_slice(self.cams);
        tp.copy_from_slice(self.pts);
        tg.copy_from_slice(self.glob);
        for (t, d) in tg.iter_mut().zip(dg) {
            *t += d;
        }
        for f in 0..self.g.n_cams {
            let c = &mut tc[f * cl..(f + 1) * cl];
            apply(
                c,
                &dc[f * cd..(f + 1) * cd],
                &self.cam_basis[f * cl * cd..(f + 1) * cl * cd],
                self.cam_has_basis[f],
                cl,
                cd,
            );
            m.normalize_cam(c);
        }
        let mut pb = vec![0.0; pl * pd];
        for p in 0..self.g.n_pts {
            let x = &mut tp[p * pl..(p + 1) * pl];
            let has = m.pt_basis(x, &mut pb);
            apply(x, &dp[p * pd..(p + 1) * pd], &pb, has, pl, pd);
            m.normalize_pt(x);
        }
        if self.resolve_points {
            solve_points(m, self.g, tc, tg, tp, self.point_iterations)
        } else {
            cost(m, self.g, tc, tp, tg)
        }
    }

    /// The extension of an accepted step along its path `x(α) = x + α δ + α² (δ̃ − δ)`
    /// (`δ` = `raw`, the Gauss–Newton step; `δ̃` = `corrected`, with its geodesic correction
    /// `a/2`), given the cost `f0` at `α = 0`, its slope there (`2 gᵀδ`) and `f1` at
    /// `α = 1`, whose parameters `best` holds. When the cost is concave along the path
    /// (`f1 − f0 < slope`), `α = 2, 4, …` while the cost keeps falling; otherwise the
    /// parabola's minimum `α* = −slope / 2(f1 − f0 − slope)` when it lies beyond 1.5. At
    /// most `trials` cost evaluations, `α ≤ 2^trials`. When a trial beats `f1`, `best` holds
    /// the best one's parameters and `(α, cost)` is returned.
    fn extend(
        &self,
        raw: Step<'_>,
        corrected: Step<'_>,
        (f0, slope, f1): (f64, f64, f64),
        trials: usize,
        best: ParamsMut<'_>,
    ) -> Option<(f64, f64)> {
        let curvature = f1 - f0 - slope;
        if !(slope < 0.0 && curvature.is_finite()) || trials == 0 {
            return None;
        }
        let concave = curvature <= 0.0;
        let cap = 2f64.powi(trials.min(30) as i32);
        let mut alpha = if concave {
            2.0
        } else {
            (-slope / (2.0 * curvature)).min(cap)
        };
        if !(alpha > 1.5) {
            return None;
        }
        let path = |a: f64, r: &[f64], d: &[f64]| -> Vec<f64> {
            r.iter()
                .zip(d)
                .map(|(r, d)| a * r + a * a * (d - r))
                .collect()
        };
        let mut work = (
            vec![0.0; self.cams.len()],
            vec![0.0; self.pts.len()],
            vec![0.0; self.glob.len()],
        );
        let mut found = None;
        let mut best_cost = f1;
        for _ in 0..trials {
            let (sc, sg, sp) = (
                path(alpha, raw.0, corrected.0),
                path(alpha, raw.1, corrected.1),
                path(alpha, raw.2, corrected.2),
            );
            let c = self.trial((&sc, &sg, &sp), (&mut work.0, &mut work.1, &mut work.2));
            if !(c < best_cost) {
                break;
            }
            best_cost = c;
            best.0.swap_with_slice(&mut work.0);
            best.1.swap_with_slice(&mut work.1);
            best.2.swap_with_slice(&mut work.2);
            found = Some((alpha, c));
            if !concave || alpha >= cap {
                break;
            }
            alpha *= 2.0;
        }
        found
    }
}

/// What the geodesic acceleration of one damped step needs from the iteration.
struct Accel<'a, M: BundleModel, F: Fn(usize) -> bool> {
    model: &'a M,
    g: &'a Graph,
    cams: &'a [f64],
    pts: &'a [f64],
    glob: &'a [f64],
    cam_basis: &'a [f64],
    cam_has_basis: &'a [bool],
    /// Per observation: `J_c`, `r`, `J_g`, `J_x` (see the linearisation).
    lin: &'a [f64],
    stride: usize,
    lins: &'a [TrackLin],
    vinv: &'a [Vec<f64>],
    cam_ptr: &'a [usize],
    cam_obs: &'a [usize],
    is_fixed: &'a F,
}

impl<M: BundleModel, F: Fn(usize) -> bool + Sync> Accel<'_, M, F> {
    /// The second-order correction `a` of the step `δ = (dc, dg, dp)` (tangent
    /// coordinates), or `None` when a residual is not finite. `r″ ≈ (2/h)((r(x ⊕ hδ) −
    /// r(x))/h − Jδ)` with `h = 0.1`; `a` solves the damped normal equations with right-hand
    /// side `−Jᵀr″` through the same Schur complement (`solve` applies the factor of `S` in
    /// place). Cost: one residual evaluation, one `Jᵀv`, one reduced right-hand side and
    /// one pair of triangular solves: `O(n_obs (c + d) m + nnz(L))`.
    fn correction(
        &self,
        dc: &[f64],
        dg: &[f64],
        dp: &[f64],
        solve: impl FnOnce(&mut Mat<f64>),
    ) -> Option<(Vec<f64>, Vec<f64>, Vec<f64>)> {
        const H: f64 = 0.1;
        let model = self.model;
        let (cl, cd, pl, pd, m, k) = (
            model.cam_len(),
            model.cam_dim(),
            model.pt_len(),
            model.pt_dim(),
            model.res_dim(),
            model.glob_len(),
        );
        let g = self.g;
        let (nf, np) = (g.n_cams, g.n_pts);
        let stride = self.stride;
        let mut cams_h = self.cams.to_vec();
        for f in 0..nf {
            let c = &mut cams_h[f * cl..(f + 1) * cl];
            let d: Vec<f64> = dc[f * cd..(f + 1) * cd].iter().map(|v| H * v).collect();
            apply(
                c,
                &d,
                &self.cam_basis[f * cl * cd..(f + 1) * cl * cd],
                self.cam_has_basis[f],
                cl,
                cd,
            );
            model.normalize_cam(c);
        }
        let glob_h: Vec<f64> = self.glob.iter().zip(dg).map(|(v, d)| v + H * d).collect();
        // Per track (in parallel): r″ of each observation (in observation order, `m` per
        // observation) and the point and shared parts of Jᵀr″ (`pd` and `k` per track).
        let kk = k.max(1);
        let mut rpp = vec![0.0; g.n_obs() * m];
        let mut gps = vec![0.0; np * pd];
        let mut ggs = vec![0.0; np * kk];
        by_track(&mut rpp, g, m)
            .into_par_iter()
            .zip(gps.par_chunks_mut(pd.max(1)))
            .zip(ggs.par_chunks_mut(kk))
            .enumerate()
            .for_each(|(p, ((rpp, gp), gg))| {
                let mut x = self.pts[p * pl..(p + 1) * pl].to_vec();
                let mut pb = vec![0.0; pl * pd];
                let has = model.pt_basis(&x, &mut pb);
                let d: Vec<f64> = dp[p * pd..(p + 1) * pd].iter().map(|v| H * v).collect();
                apply(&mut x, &d, &pb, has, pl, pd);
                model.normalize_pt(&mut x);
                let mut r = vec![0.0; m];
                for (i, o) in g.track(p).enumerate() {
                    let f = g.cam[o];
                    model.eval(
                        &cams_h[f * cl..(f + 1) * cl],
                        &x,
                        &glob_h,
                        g.w[o],
                        &mut r,
                        None,
                    );
                    let (jct, r0, jg, jpt) =
                        obs_parts(&self.lin[o * stride..(o + 1) * stride], (cd, pd, k, m));
                    for row in 0..m {
                        let mut jd = 0.0;
                        for c in 0..cd {
                            jd += jct[row * cd + c] * dc[f * cd + c];
                        }
                        for c in 0..pd {
                            jd += jpt[row * pd + c] * dp[p * pd + c];
                        }
                        for c in 0..k {
                            jd += jg[row * k + c] * dg[c];
                        }
                        let v = (2.0 / H) * ((r[row] - r0[row]) / H - jd);
                        rpp[i * m + row] = v;
                        for c in 0..pd {
                            gp[c] += jpt[row * pd + c] * v;
                        }
                        for c in 0..k {
                            gg[c] += jg[row * k + c] * v;
                        }
                    }
                }
            });
        if rpp.iter().any(|v| !v.is_finite()) {
            return None;
        }
        // Camera part of Jᵀr″ (in parallel over cameras).
        let ga_c: Vec<f64> = (0..nf)
            .into_par_iter()
            .flat_map_iter(|f| {
                let mut out = vec![0.0; cd];
                for &o in &self.cam_obs[self.cam_ptr[f]..self.cam_ptr[f + 1]] {
                    let (jct, _, _, _) =
                        obs_parts(&self.lin[o * stride..(o + 1) * stride], (cd, pd, k, m));
                    for row in 0..m {
                        for c in 0..cd {
                            out[c] += jct[row * cd + c] * rpp[o * m + row];
                        }
                    }
                }
                out
            })
            .collect();
        // Reduced right-hand side: −g_c + Σ_p W_p V_p⁻¹ g_p (and the shared rows).
        let ns = nf * cd + k;
        let mut rhs = Mat::<f64>::zeros(ns, 1);
        for i in 0..nf * cd {
            rhs[(i, 0)] = -ga_c[i];
        }
        for k1 in 0..k {
            rhs[(nf * cd + k1, 0)] = -(0..np).map(|p| ggs[p * kk + k1]).sum::<f64>();
        }
        let mut vg = vec![0.0; pd];
        for p in 0..np {
            let vi = &self.vinv[p];
            let gp = &gps[p * pd..(p + 1) * pd];
            for d1 in 0..pd {
                vg[d1] = (0..pd).map(|d2| vi[d1 * pd + d2] * gp[d2]).sum();
            }
            // W V⁻¹ g_p = J_cᵀ (J_x V⁻¹ g_p).
            for o in g.track(p) {
                let f = g.cam[o];
                let (jc, _, _, jx) =
                    obs_parts(&self.lin[o * stride..(o + 1) * stride], (cd, pd, k, m));
                for row in 0..m {
                    let t: f64 = (0..pd).map(|d| jx[row * pd + d] * vg[d]).sum();
                    for c1 in 0..cd {
                        rhs[(f * cd + c1, 0)] += jc[row * cd + c1] * t;
                    }
                }
            }
            let wg = &self.lins[p].wg;
            for k1 in 0..k {
                rhs[(nf * cd + k1, 0)] += (0..pd).map(|d| wg[k1 * pd + d] * vg[d]).sum::<f64>();
            }
        }
        for f in (0..nf).filter(|&f| (self.is_fixed)(f)) {
            for c1 in 0..cd {
                rhs[(f * cd + c1, 0)] = 0.0;
            }
        }
        solve(&mut rhs);
        let ac: Vec<f64> = (0..nf * cd)
            .map(|i| {
                if (self.is_fixed)(i / cd) {
                    0.0
                } else {
                    rhs[(i, 0)]
                }
            })
            .collect();
        let ag: Vec<f64> = (0..k).map(|i| rhs[(nf * cd + i, 0)]).collect();
        let ap = back_substitute(
            g,
            self.lin,
            stride,
            (cd, pd, k, m),
            self.lins,
            self.vinv,
            |p| &gps[p * pd..(p + 1) * pd],
            &ac,
            &ag,
        );
        if ac.iter().chain(&ag).chain(&ap).any(|v| !v.is_finite()) {
            return None;
        }
        Some((ac, ag, ap))
    }
}

/// One linearization's reduced camera system, apart from its damping: the point blocks'
/// inverses, the right-hand side and the diagonal the damping scales (cameras, shared
/// parameters).
struct Assembled {
    vinv: Vec<Vec<f64>>,
    rhs: Mat<f64>,
    dcam: Vec<f64>,
    dglob: Vec<f64>,
    /// The iterative path's pieces of the system (`None` on the direct path).
    implicit: Option<ImplicitParts>,
}

/// The camera and shared blocks of the iterative path's system before the Schur
/// correction and the damping (full, symmetric), and its undamped block diagonal.
struct ImplicitParts {
    ucam: Vec<f64>,
    ugg: Vec<f64>,
    blocks: implicit::BlockDiagonal,
}

/// Per-track linearisation: `V_p`, `g_p` and the `W` block of each observation.
struct TrackLin {
    v: Vec<f64>,
    gp: Vec<f64>,
    /// `Σ J_gᵀ J_x` over the track's observations (glob_len × pt_dim).
    wg: Vec<f64>,
    /// The track's share of `J_gᵀ J_g` (lower triangle) and of `J_gᵀ r`.
    ugg: Vec<f64>,
    gg: Vec<f64>,
}

/// Minimises `Σ ‖r‖²` over cameras and points from the given start (updated in place).
///
/// `cams`: `F × cam_len`, `pts`: `N × pt_len`, both flat. Errors only for a problem whose
/// reduced camera system cannot be analysed (returned as a message); how the iterations
/// ended is in the report. See the module documentation for the step and its cost.
pub fn minimize<M: BundleModel>(
    model: &M,
    g: &Graph,
    cams: &mut [f64],
    pts: &mut [f64],
    cfg: &LmConfig,
    progress: &mut Progress<'_>,
) -> Result<LmResult, String> {
    minimize_fixed(model, g, cams, pts, &[], cfg, progress)
}

/// [`minimize`] with the cameras `f` where `fixed[f]` is true held where they are (their
/// steps are zero; a stiff spring in the reduced system tells the other unknowns so).
/// `fixed` may be empty (nothing fixed) or have one entry per camera.
pub fn minimize_fixed<M: BundleModel>(
    model: &M,
    g: &Graph,
    cams: &mut [f64],
    pts: &mut [f64],
    fixed: &[bool],
    cfg: &LmConfig,
    progress: &mut Progress<'_>,
) -> Result<LmResult, String> {
    minimize_shared(model, g, cams, pts, &mut [], fixed, cfg, progress)
}

/// The point blocks' fallback regularisation, relative to their mean diagonal: `V_p +
/// φ·mean diag(V_p)·I` with φ = √ε ≈ 1.5·10⁻⁸ once the reduced system has failed to
/// factorize (10⁻¹² until then). A point whose depth the data hardly fix (short baseline,
/// few frames) has a nearly singular `V_p`; its inverse is then accurate only to
/// `cond(V_p)·ε`, and `S = U − W V⁻¹ Wᵀ` — positive semidefinite in exact arithmetic — loses
/// definiteness by rounding. With φ, `cond(V_p) ≤ 1/φ` and each point's share of `S` is
/// accurate to about √ε of itself. φ is a Tikhonov damping of the point step along the
/// directions the data do not fix (the fixed point, a zero gradient, is unchanged), which
/// slows the descent where those directions matter (a scaled orthographic corridor took 42
/// solves instead of 13 with it from the start), so it is a fallback, not the default.
/// Measured (docs/results.md, § Projective camera): at 10 000 frames with 10⁻¹² throughout,
/// 23 of 42 solves were failed factorizations at λ ≈ 10⁻⁸.
const POINT_BLOCK_FLOOR: f64 = 1.4901161193847656e-8;

/// Raises the damping after a failed factorization or a rejected step (`λ ← λν`, `ν ← 2ν`;
/// Nielsen). Returns whether `λ` now exceeds `10¹⁶`: no step can be found, the run has
/// stalled.
fn raise_damping(lambda: &mut f64, nu: &mut f64) -> bool {
    *lambda *= *nu;
    *nu *= 2.0;
    *lambda > 1e16
}

/// [`minimize_fixed`] for a model with shared parameters ([`BundleModel::glob_len`] of
/// them, in `glob`, updated in place): they are unknowns of the reduced system ordered
/// after the cameras, coupled to every camera (`O(F · glob_len)` more non-zeros in `S`).
#[allow(clippy::too_many_arguments)]
pub fn minimize_shared<M: BundleModel>(
    model: &M,
    g: &Graph,
    cams: &mut [f64],
    pts: &mut [f64],
    glob: &mut [f64],
    fixed: &[bool],
    cfg: &LmConfig,
    progress: &mut Progress<'_>,
) -> Result<LmResult, String> {
    let start = Instant::now();
    let k = model.glob_len();
    if glob.len() != k {
        return Err(format!(
            "{} shared parameters given, the model has {k}",
            glob.len()
        ));
    }
    let is_fixed = |f: usize| fixed.get(f).copied().unwrap_or(false);
    let (cl, cd, pl, pd, m) = (
        model.cam_len(),
        model.cam_dim(),
        model.pt_len(),
        model.pt_dim(),
        model.res_dim(),
    );
    let (nf, np, nobs) = (g.n_cams, g.n_pts, g.n_obs());
    let stride = m * (cd + 1 + k + pd);
    // `Auto`: iterative when the reduced system (its camera pairs counted from the graph
    // before anything is formed, the count stopped at the limit) or its Cholesky factor
    // (from the symbolic analysis) would hold more than `ITERATIVE_FILL` times the
    // linearization's numbers and more than `ITERATIVE_MIN_NONZEROS`.
    let budget = (ITERATIVE_FILL * (nobs * stride) as f64).max(ITERATIVE_MIN_NONZEROS);
    let too_big = |nnz: usize| nnz as f64 > budget;
    let nbrs = match cfg.linear_solver {
        LinearSolver::Direct => neighbours(g, usize::MAX),
        LinearSolver::Iterative => None,
        LinearSolver::Auto => {
            let fixed = (nf * cd * (cd + 1) / 2 + (nf * cd + k) * k) as f64;
            let limit = ((budget - fixed) / (cd * cd).max(1) as f64).max(0.0);
            neighbours(g, limit.min(usize::MAX as f64) as usize)
        }
    };
    // The direct path's pattern; none for the iterative one.
    let mut pattern = match nbrs {
        Some(nbrs) => Some(Pattern::new(g, nbrs, cd, k, cfg.dense_schur)?),
        None => None,
    };
    if cfg.linear_solver == LinearSolver::Auto
        && pattern.as_ref().is_some_and(|p| too_big(p.llt.len_val()))
    {
        pattern = None;
    }
    let iterative = pattern.is_none();
    let mut factor = match pattern.as_ref() {
        Some(p) => Some(Factor::new(&p.llt)?),
        None => None,
    };
    // The track of each observation (the iterative path's products).
    let obs_pt: Vec<usize> = if iterative {
        (0..np).flat_map(|p| g.track(p).map(move |_| p)).collect()
    } else {
        Vec::new()
    };
    let mut cg_iterations = 0;
    let ns = nf * cd + k;
    let n_res = (nobs * m).max(1) as f64;
    let rms = |c: f64| (c / n_res).sqrt() * progress.rms_scale;

    if cfg.resolve_points {
        solve_points(model, g, cams, glob, pts, cfg.point_iterations);
    }
    let mut cur = cost(model, g, cams, pts, glob);
    let initial_cost = cur;
    let mut costs = vec![cur];
    progress.observer.on_event(&Event::Iteration {
        solver: progress.name,
        run: progress.run,
        iteration: 0,
        cost: cur,
        rms: rms(cur),
        lambda: f64::NAN,
    });

    let mut lambda = cfg.initial_lambda;
    let mut nu = 2.0;
    let mut extensions = 0;
    // Twice the largest damping at which the reduced system failed to factorize: λ is not
    // lowered below it again (a failed factorization costs as much as a solve, and on a
    // long sequence the system is indefinite by rounding below some λ ≈ 10⁻¹⁰).
    let mut lambda_floor = 1e-15f64;
    // The point blocks' regularisation, relative to their mean diagonal: 10⁻¹², raised to
    // `POINT_BLOCK_FLOOR` for the rest of the run when the reduced system fails to factorize.
    let mut point_floor = 1e-12;
    // Whether a step was rejected since the last accepted one: the damping that was then
    // accepted is kept for the next step instead of lowered.
    let mut retried = false;
    let mut status = SolverStatus::MaxIterations;
    let mut iterations = 0;
    // Buffers reused across iterations. Per observation: J_c in the tangent space
    // (m × cd), r (m), J_g (m × k) when the model has shared parameters, and J_x in the
    // tangent space (m × pd), the layout `obs_parts` reads. `W = J_cᵀ J_x` is formed
    // where it is used (the Schur complement, the back-substitution): storing it took 18
    // of 38 numbers per observation for a 6-parameter camera.
    let mut lin = vec![0.0; nobs * stride];
    // Observations by camera (for the camera blocks, in parallel over cameras).
    let (cam_ptr, cam_obs) = {
        let mut ptr = vec![0usize; nf + 1];
        for &c in &g.cam {
            ptr[c + 1] += 1;
        }
        for f in 0..nf {
            ptr[f + 1] += ptr[f];
        }
        let mut fill = ptr.clone();
        let mut idx = vec![0usize; nobs];
        for (o, &c) in g.cam.iter().enumerate() {
            idx[fill[c]] = o;
            fill[c] += 1;
        }
        (ptr, idx)
    };
    let mut u = vec![0.0; nf * cd * cd];
    let mut gc = vec![0.0; nf * cd];
    let mut cam_basis = vec![0.0; nf * cl * cd];
    let mut cam_has_basis = vec![false; nf];
    let mut values = vec![0.0; pattern.as_ref().map_or(0, Pattern::nnz)];
    // The undamped reduced camera system of the current linearization (variable projection).
    let mut base_values: Vec<f64> = Vec::new();
    // At least one slot per camera so that the per-camera zip below visits every camera.
    let kc = (k * cd).max(1);
    let mut ugf = vec![0.0; nf * kc];
    let mut trial_cams = cams.to_vec();
    let mut trial_pts = pts.to_vec();
    let mut trial_glob = glob.to_vec();
    if cur <= cfg.absolute_tolerance * n_res {
        status = SolverStatus::Converged;
    }
    'outer: while status != SolverStatus::Converged && iterations < cfg.max_iterations {
        // Linearise.
        for f in 0..nf {
            cam_has_basis[f] = model.cam_basis(
                &cams[f * cl..(f + 1) * cl],
                &mut cam_basis[f * cl * cd..(f + 1) * cl * cd],
            );
        }
        // Per track (in parallel): V_p, g_p and each observation's J_c, r, J_g, J_x.
        let lins: Vec<TrackLin> = by_track(&mut lin, g, stride)
            .into_par_iter()
            .enumerate()
            .map(|(p, out)| {
                let x = &pts[p * pl..(p + 1) * pl];
                let mut pb = vec![0.0; pl * pd];
                let has_pb = model.pt_basis(x, &mut pb);
                let mut r = vec![0.0; m];
                let mut jc = vec![0.0; m * cl];
                let mut jp = vec![0.0; m * pl];
                let mut jpt = vec![0.0; m * pd];
                let mut v = vec![0.0; pd * pd];
                let mut gp = vec![0.0; pd];
                let mut wg = vec![0.0; k * pd];
                let mut ugg = vec![0.0; k * k];
                let mut gg = vec![0.0; k];
                for (i, o) in g.track(p).enumerate() {
                    let f = g.cam[o];
                    let blk = &mut out[i * stride..(i + 1) * stride];
                    let (jct, rest) = blk.split_at_mut(m * cd);
                    let (rb, rest) = rest.split_at_mut(m);
                    let (jg, jps) = rest.split_at_mut(m * k);
                    model.eval(
                        &cams[f * cl..(f + 1) * cl],
                        x,
                        glob,
                        g.w[o],
                        &mut r,
                        Some(Jacobians {
                            cam: &mut jc,
                            pt: &mut jp,
                            glob: jg,
                        }),
                    );
                    tangent(
                        &jc,
                        &cam_basis[f * cl * cd..(f + 1) * cl * cd],
                        cam_has_basis[f],
                        m,
                        cl,
                        cd,
                        jct,
                    );
                    tangent(&jp, &pb, has_pb, m, pl, pd, &mut jpt);
                    jps.copy_from_slice(&jpt);
                    rb.copy_from_slice(&r);
                    for row in 0..m {
                        let b = &jpt[row * pd..(row + 1) * pd];
                        let e = r[row];
                        for d1 in 0..pd {
                            gp[d1] += b[d1] * e;
                            for d2 in 0..=d1 {
                                v[d1 * pd + d2] += b[d1] * b[d2];
                            }
                        }
                        let jgr = &jg[row * k..(row + 1) * k];
                        for k1 in 0..k {
                            gg[k1] += jgr[k1] * e;
                            for d in 0..pd {
                                wg[k1 * pd + d] += jgr[k1] * b[d];
                            }
                            for k2 in 0..=k1 {
                                ugg[k1 * k + k2] += jgr[k1] * jgr[k2];
                            }
                        }
                    }
                }
                for d1 in 0..pd {
                    for d2 in 0..d1 {
                        v[d2 * pd + d1] = v[d1 * pd + d2];
                    }
                }
                TrackLin { v, gp, wg, ugg, gg }
            })
            .collect();
        // Per camera (in parallel): U_f = Σ J_cᵀ J_c (lower triangle), g_f = Σ J_cᵀ r,
        // and the coupling to the shared parameters U_gf = Σ J_gᵀ J_c.
        u.par_chunks_mut(cd * cd)
            .zip(gc.par_chunks_mut(cd))
            .zip(ugf.par_chunks_mut(kc))
            .enumerate()
            .for_each(|(f, ((uf, gf), ug))| {
                uf.iter_mut().for_each(|x| *x = 0.0);
                gf.iter_mut().for_each(|x| *x = 0.0);
                ug.iter_mut().for_each(|x| *x = 0.0);
                for &o in &cam_obs[cam_ptr[f]..cam_ptr[f + 1]] {
                    let (jct, rb, jg, _) =
                        obs_parts(&lin[o * stride..(o + 1) * stride], (cd, pd, k, m));
                    for row in 0..m {
                        let a = &jct[row * cd..(row + 1) * cd];
                        for c1 in 0..cd {
                            gf[c1] += a[c1] * rb[row];
                            for c2 in 0..=c1 {
                                uf[c1 * cd + c2] += a[c1] * a[c2];
                            }
                        }
                        for k1 in 0..k {
                            let jv = jg[row * k + k1];
                            for c1 in 0..cd {
                                ug[k1 * cd + c1] += jv * a[c1];
                            }
                        }
                    }
                }
            });
        // Shared parameters: U_gg and g_g, summed in track order (deterministic).
        let mut ugg = vec![0.0; k * k];
        let mut gglob = vec![0.0; k];
        for l in &lins {
            for i in 0..k * k {
                ugg[i] += l.ugg[i];
            }
            for i in 0..k {
                gglob[i] += l.gg[i];
            }
        }
        let mean_diag_u = (0..nf * cd)
            .map(|i| u[(i / cd) * cd * cd + (i % cd) * cd + i % cd])
            .sum::<f64>()
            / (nf * cd).max(1) as f64;
        let dfloor = 1e-9 * mean_diag_u.max(f64::MIN_POSITIVE);
        // Gauge springs K_f = κ Σ_v (Bᵀv)(Bᵀv)ᵀ / ‖Bᵀv‖², κ = mean diag(U).
        let pins: Vec<(usize, Vec<f64>)> = model
            .gauge_pins(cams, nf)
            .into_iter()
            .map(|(f, dirs)| {
                let b = &cam_basis[f * cl * cd..(f + 1) * cl * cd];
                let mut kf = vec![0.0; cd * cd];
                for v in dirs {
                    let a: Vec<f64> = if cam_has_basis[f] {
                        (0..cd)
                            .map(|c| (0..cl).map(|r| b[r * cd + c] * v[r]).sum())
                            .collect()
                    } else {
                        v[..cd].to_vec()
                    };
                    let n2: f64 = a.iter().map(|x| x * x).sum();
                    if n2 > 1e-12 {
                        for c1 in 0..cd {
                            for c2 in 0..cd {
                                kf[c1 * cd + c2] += mean_diag_u * a[c1] * a[c2] / n2;
                            }
                        }
                    }
                }
                (f, kf)
            })
            .collect();
        let gnorm_inf = gc
            .iter()
            .chain(gglob.iter())
            .chain(lins.iter().flat_map(|l| l.gp.iter()))
            .fold(0.0f64, |a, &b| a.max(b.abs()));
        if gnorm_inf == 0.0 {
            status = SolverStatus::Converged;
            break;
        }

        // The iterative path's view of one linearization (see `implicit`).
        macro_rules! implicit {
            ($vinv:expr, $ucam:expr, $ugg:expr, $dcam:expr, $dglob:expr) => {
                implicit::Implicit {
                    g,
                    lin: &lin,
                    stride,
                    dims: (cd, pd, k, m),
                    lins: &lins,
                    vinv: $vinv,
                    cam_ptr: &cam_ptr,
                    cam_obs: &cam_obs,
                    obs_pt: &obs_pt,
                    ucam: $ucam,
                    ugf: &ugf,
                    kc,
                    ugg: $ugg,
                    dcam: $dcam,
                    dglob: $dglob,
                }
            };
        }
        // Damped solves until a step is accepted.
        let mut assembled: Option<Assembled> = None;
        loop {
            if iterations >= cfg.max_iterations {
                break 'outer;
            }
            iterations += 1;
            // The reduced camera system, undamped; the damping `λD` of the cameras and
            // shared parameters is added below. Under variable projection (points not
            // damped) nothing else depends on λ: the system is assembled once per
            // linearization and a rejected step re-solves a copy with the new damping.
            if cfg.damp_points || assembled.is_none() {
                // Point blocks: V* and its inverse.
                let vinv: Vec<Vec<f64>> = lins
                    .par_iter()
                    .map(|l| {
                        let mut h = l.v.clone();
                        let md = (0..pd).map(|i| h[i * pd + i]).sum::<f64>() / pd as f64;
                        for i in 0..pd {
                            let extra = if cfg.damp_points {
                                lambda * h[i * pd + i].max(1e-9 * md)
                            } else {
                                0.0
                            };
                            h[i * pd + i] += extra + point_floor * md.max(f64::MIN_POSITIVE);
                        }
                        let mut inv = vec![0.0; pd * pd];
                        if linalg::cholesky(&mut h, pd) {
                            linalg::chol_inverse(&h, pd, &mut inv);
                        }
                        inv
                    })
                    .collect();
                // The diagonal the damping scales (cameras, shared parameters).
                let dcam: Vec<f64> = (0..nf * cd)
                    .map(|i| u[(i / cd) * cd * cd + (i % cd) * cd + i % cd].max(dfloor))
                    .collect();
                let dglob: Vec<f64> = (0..k).map(|i| ugg[i * k + i].max(dfloor)).collect();
                if let Some(pattern) = pattern.as_ref() {
                    // Reduced camera system.
                    values.iter_mut().for_each(|x| *x = 0.0);
                    let mut rhs = Mat::<f64>::zeros(ns, 1);
                    for k1 in 0..k {
                        for k2 in 0..=k1 {
                            values[pattern.glob(nf, k1, k2)] += ugg[k1 * k + k2];
                        }
                        rhs[(nf * cd + k1, 0)] = -gglob[k1];
                    }
                    for f in 0..nf {
                        let uf = &u[f * cd * cd..(f + 1) * cd * cd];
                        for c1 in 0..cd {
                            for c2 in 0..=c1 {
                                values[pattern.pos(f, f, c1, c2)] += uf[c1 * cd + c2];
                            }
                            rhs[(f * cd + c1, 0)] = -gc[f * cd + c1];
                            for k1 in 0..k {
                                values[pattern.glob_in_cam(f, c1, k1)] +=
                                    ugf[f * kc + k1 * cd + c1];
                            }
                        }
                    }
                    for (f, kf) in &pins {
                        for c1 in 0..cd {
                            for c2 in 0..=c1 {
                                values[pattern.pos(*f, *f, c1, c2)] += kf[c1 * cd + c2];
                            }
                        }
                    }
                    for f in (0..nf).filter(|&f| is_fixed(f)) {
                        for c1 in 0..cd {
                            values[pattern.pos(f, f, c1, c1)] +=
                                1e8 * mean_diag_u.max(f64::MIN_POSITIVE);
                            rhs[(f * cd + c1, 0)] = 0.0;
                        }
                    }
                    // S −= W V⁻¹ Wᵀ and rhs += W V⁻¹ g_p, track by track. The columns of frames
                    // a..b are one contiguous run of the CSC values, so the frames are split into
                    // ranges, one per thread, each thread adding every track's share to its own
                    // columns (and to its frames' right-hand sides) in track order: the sums are
                    // those of the sequential loop, whatever the number of threads.
                    // Y_g = W_g V⁻¹ per track (models with shared parameters only): the shared
                    // rows' own block and every range's coupling to them use it.
                    let mut ygs = vec![0.0; np * k * pd];
                    if k > 0 {
                        ygs.par_chunks_mut(k * pd).enumerate().for_each(|(p, yg)| {
                            let (vi, wg) = (&vinv[p], &lins[p].wg);
                            for k1 in 0..k {
                                for d2 in 0..pd {
                                    yg[k1 * pd + d2] =
                                        (0..pd).map(|d1| wg[k1 * pd + d1] * vi[d1 * pd + d2]).sum();
                                }
                            }
                        });
                    }
                    let cam_end = pattern.col_ptr[nf * cd];
                    let (cam_values, glob_values) = values.split_at_mut(cam_end);
                    let ranges = frame_ranges(pattern, nf, cd, rayon::current_num_threads());
                    let mut value_parts: Vec<&mut [f64]> = Vec::with_capacity(ranges.len());
                    {
                        let mut rest: &mut [f64] = cam_values;
                        let mut at = 0;
                        for &(_, b) in &ranges {
                            let end = pattern.col_ptr[b * cd];
                            let (head, tail) = rest.split_at_mut(end - at);
                            value_parts.push(head);
                            rest = tail;
                            at = end;
                        }
                    }
                    let schur_input = SchurInput {
                        g,
                        pattern,
                        dims: (cd, pd, k, m),
                        lin: &lin,
                        stride,
                        lins: &lins,
                        vinv: &vinv,
                        ygs: &ygs,
                    };
                    let rhs_parts: Vec<Vec<f64>> = ranges
                        .par_iter()
                        .zip(value_parts.into_par_iter())
                        .map(|(&(a, b), vals)| {
                            let offset = pattern.col_ptr[a * cd];
                            let mut rhs_part = vec![0.0; (b - a) * cd];
                            schur_columns(&schur_input, (a, b), vals, offset, &mut rhs_part);
                            rhs_part
                        })
                        .collect();
                    for (&(a, _), part) in ranges.iter().zip(&rhs_parts) {
                        for (i, v) in part.iter().enumerate() {
                            rhs[(a * cd + i, 0)] += v;
                        }
                    }
                    if k > 0 {
                        // The shared rows' own block: S_gg −= Y_g W_gᵀ, rhs_g += Y_g g_p.
                        for p in 0..np {
                            let (gp, wg) = (&lins[p].gp, &lins[p].wg);
                            let yg = &ygs[p * k * pd..(p + 1) * k * pd];
                            for k1 in 0..k {
                                let s: f64 = (0..pd).map(|d| yg[k1 * pd + d] * gp[d]).sum();
                                rhs[(nf * cd + k1, 0)] += s;
                                for k2 in 0..=k1 {
                                    let s: f64 =
                                        (0..pd).map(|d| yg[k1 * pd + d] * wg[k2 * pd + d]).sum();
                                    glob_values[pattern.glob(nf, k1, k2) - cam_end] -= s;
                                }
                            }
                        }
                    }
                    if !cfg.damp_points {
                        base_values.clone_from(&values);
                    }
                    assembled = Some(Assembled {
                        vinv,
                        rhs,
                        dcam,
                        dglob,
                        implicit: None,
                    });
                } else {
                    // The iterative path: the pieces of the system's product, its
                    // right-hand side and its block diagonal (the preconditioner).
                    let mut ucam = vec![0.0; nf * cd * cd];
                    for f in 0..nf {
                        let uf = &u[f * cd * cd..(f + 1) * cd * cd];
                        let out = &mut ucam[f * cd * cd..(f + 1) * cd * cd];
                        for c1 in 0..cd {
                            for c2 in 0..=c1 {
                                out[c1 * cd + c2] = uf[c1 * cd + c2];
                                out[c2 * cd + c1] = uf[c1 * cd + c2];
                            }
                        }
                        if is_fixed(f) {
                            for c1 in 0..cd {
                                out[c1 * cd + c1] += 1e8 * mean_diag_u.max(f64::MIN_POSITIVE);
                            }
                        }
                    }
                    for (f, kf) in &pins {
                        for i in 0..cd * cd {
                            ucam[f * cd * cd + i] += kf[i];
                        }
                    }
                    let mut ugg_full = vec![0.0; k * k];
                    for k1 in 0..k {
                        for k2 in 0..=k1 {
                            ugg_full[k1 * k + k2] = ugg[k1 * k + k2];
                            ugg_full[k2 * k + k1] = ugg[k1 * k + k2];
                        }
                    }
                    let (rhs_vec, blocks) = {
                        let imp = implicit!(&vinv, &ucam, &ugg_full, &dcam, &dglob);
                        (imp.rhs(&gc, &gglob, is_fixed), imp.block_diagonal())
                    };
                    let rhs = Mat::<f64>::from_fn(ns, 1, |i, _| rhs_vec[i]);
                    assembled = Some(Assembled {
                        vinv,
                        rhs,
                        dcam,
                        dglob,
                        implicit: Some(ImplicitParts {
                            ucam,
                            ugg: ugg_full,
                            blocks,
                        }),
                    });
                }
            } else if pattern.is_some() {
                values.copy_from_slice(&base_values);
            }
            let Some(Assembled {
                vinv,
                rhs,
                dcam,
                dglob,
                implicit: parts,
            }) = assembled.as_ref()
            else {
                unreachable!()
            };
            let mut rhs = rhs.clone();
            // One conjugate-gradient solve of `S_λ x = b` on the iterative path: the step's,
            // and its geodesic correction's.
            let cg_solve = |parts: &ImplicitParts, b: &[f64]| {
                implicit!(vinv, &parts.ucam, &parts.ugg, dcam, dglob).solve(
                    &parts.blocks,
                    lambda,
                    b,
                    cfg.cg_tolerance,
                    cfg.cg_max_iterations,
                )
            };
            let split = |x: &dyn Fn(usize) -> f64| {
                let dc: Vec<f64> = (0..nf * cd)
                    .map(|i| if is_fixed(i / cd) { 0.0 } else { x(i) })
                    .collect();
                let dg: Vec<f64> = (0..k).map(|i| x(nf * cd + i)).collect();
                (dc, dg)
            };
            let solved = match (pattern.as_ref(), factor.as_mut(), parts.as_ref()) {
                (Some(pattern), Some(factor), _) => {
                    for (i, d) in dcam.iter().enumerate() {
                        values[pattern.pos(i / cd, i / cd, i % cd, i % cd)] += lambda * d;
                    }
                    for (k1, d) in dglob.iter().enumerate() {
                        values[pattern.glob(nf, k1, k1)] += lambda * d;
                    }
                    let mat = SparseColMatRef::new(pattern.symbolic.as_ref(), &values);
                    factor.factorize(&pattern.llt, mat).then(|| {
                        factor.solve(&pattern.llt, rhs.as_mut());
                        split(&|i| rhs[(i, 0)])
                    })
                }
                (_, _, Some(parts)) => cg_solve(parts, rhs.col_as_slice(0)).map(|out| {
                    cg_iterations += out.iterations;
                    split(&|i| out.x[i])
                }),
                _ => unreachable!(),
            };
            let solved =
                solved.filter(|(dc, dg)| dc.iter().chain(dg.iter()).all(|v| v.is_finite()));
            // The factorization failed or the step is not finite: `S` is not positive
            // definite at this damping (`POINT_BLOCK_FLOOR` says why).
            let Some((dc, dg)) = solved else {
                if point_floor < POINT_BLOCK_FLOOR {
                    point_floor = POINT_BLOCK_FLOOR;
                    assembled = None;
                    continue;
                }
                lambda_floor = lambda_floor.max(2.0 * lambda);
                if raise_damping(&mut lambda, &mut nu) {
                    status = SolverStatus::Stalled;
                    break 'outer;
                }
                continue;
            };
            // Back-substitute the points.
            let dp = back_substitute(
                g,
                &lin,
                stride,
                (cd, pd, k, m),
                &lins,
                vinv,
                |p| &lins[p].gp,
                &dc,
                &dg,
            );
            // Predicted decrease of `Σ r²` by the linear model: `−gᵀδ + λ δᵀDδ` for the
            // damped normal equations `(JᵀJ + λD) δ = −g`, `g = Jᵀr`.
            let mut pred = 0.0;
            for i in 0..nf * cd {
                pred += -gc[i] * dc[i] + lambda * dcam[i] * dc[i] * dc[i];
            }
            for i in 0..k {
                pred += -gglob[i] * dg[i] + lambda * dglob[i] * dg[i] * dg[i];
            }
            for (f, kf) in &pins {
                let d = &dc[f * cd..(f + 1) * cd];
                for c1 in 0..cd {
                    for c2 in 0..cd {
                        pred += d[c1] * kf[c1 * cd + c2] * d[c2];
                    }
                }
            }
            for p in 0..np {
                for d in 0..pd {
                    pred += -lins[p].gp[d] * dp[p * pd + d];
                    if cfg.damp_points {
                        let vd = lins[p].v[d * pd + d];
                        pred += lambda * vd * dp[p * pd + d] * dp[p * pd + d];
                    }
                }
            }
            // The Gauss–Newton step before its geodesic correction, kept for the extension
            // along the step's path (`extension_trials`).
            let raw = (cfg.extension_trials > 0).then(|| (dc.clone(), dg.clone(), dp.clone()));
            // Geodesic acceleration: `δ ← δ + a/2` when `2‖a‖ ≤ α‖δ‖`.
            let (dc, dg, dp) = if cfg.geodesic_acceleration > 0.0 {
                let acc = Accel {
                    model,
                    g,
                    cams,
                    pts,
                    glob,
                    cam_basis: &cam_basis,
                    cam_has_basis: &cam_has_basis,
                    lin: &lin,
                    stride,
                    lins: &lins,
                    vinv,
                    cam_ptr: &cam_ptr,
                    cam_obs: &cam_obs,
                    is_fixed: &is_fixed,
                };
                match acc.correction(&dc, &dg, &dp, |rhs| {
                    match (pattern.as_ref(), factor.as_mut(), parts.as_ref()) {
                        (Some(pattern), Some(factor), _) => {
                            factor.solve(&pattern.llt, rhs.as_mut())
                        }
                        (_, _, Some(parts)) => {
                            let out = cg_solve(parts, rhs.col_as_slice(0));
                            for i in 0..ns {
                                rhs[(i, 0)] = out.as_ref().map_or(f64::NAN, |o| o.x[i]);
                            }
                            if let Some(o) = out {
                                cg_iterations += o.iterations;
                            }
                        }
                        _ => unreachable!(),
                    }
                }) {
                    Some((ac, ag, ap)) => {
                        let n2 = |a: &[f64], b: &[f64], c: &[f64]| {
                            a.iter()
                                .chain(b)
                                .chain(c)
                                .map(|v| v * v)
                                .sum::<f64>()
                                .sqrt()
                        };
                        if 2.0 * n2(&ac, &ag, &ap) <= cfg.geodesic_acceleration * n2(&dc, &dg, &dp)
                        {
                            let half = |d: &[f64], a: &[f64]| -> Vec<f64> {
                                d.iter().zip(a).map(|(d, a)| d + 0.5 * a).collect()
                            };
                            (half(&dc, &ac), half(&dg, &ag), half(&dp, &ap))
                        } else {
                            (dc, dg, dp)
                        }
                    }
                    None => (dc, dg, dp),
                }
            } else {
                (dc, dg, dp)
            };
            // Trial parameters.
            let mut step2 = dg.iter().chain(&dc).chain(&dp).map(|v| v * v).sum::<f64>();
            let par2 = glob
                .iter()
                .chain(&*cams)
                .chain(&*pts)
                .map(|v| v * v)
                .sum::<f64>();
            let stepper = Stepper {
                model,
                g,
                cams,
                pts,
                glob,
                cam_basis: &cam_basis,
                cam_has_basis: &cam_has_basis,
                point_iterations: cfg.point_iterations,
                resolve_points: cfg.resolve_points,
            };
            let mut new_cost = stepper.trial(
                (&dc, &dg, &dp),
                (&mut trial_cams, &mut trial_pts, &mut trial_glob),
            );
            // The gain ratio of the damped step itself (the damping follows it).
            let rho = (cur - new_cost) / pred.max(f64::MIN_POSITIVE);
            // Extension along the step's path while the cost keeps falling.
            if let Some((rc, rg, rp)) = raw.as_ref()
                && new_cost.is_finite()
                && new_cost < cur
            {
                let slope = 2.0
                    * (gc.iter().zip(rc).map(|(a, b)| a * b).sum::<f64>()
                        + gglob.iter().zip(rg).map(|(a, b)| a * b).sum::<f64>());
                let ext = stepper.extend(
                    (rc, rg, rp),
                    (&dc, &dg, &dp),
                    (cur, slope, new_cost),
                    cfg.extension_trials,
                    (&mut trial_cams, &mut trial_pts, &mut trial_glob),
                );
                if let Some((alpha, c)) = ext {
                    new_cost = c;
                    step2 *= alpha * alpha;
                    extensions += 1;
                }
            }
            if new_cost.is_finite() && new_cost < cur {
                let rel = (cur - new_cost) / cur;
                // The Gauss–Newton decrement of a nearly undamped step the model predicted
                // well: what the quadratic model says is left.
                let decrement_small = cfg.decrement_tolerance > 0.0
                    && lambda <= UNDAMPED
                    && rho >= 0.25
                    && pred < cfg.decrement_tolerance * new_cost;
                cams.copy_from_slice(&trial_cams);
                pts.copy_from_slice(&trial_pts);
                glob.copy_from_slice(&trial_glob);
                cur = new_cost;
                costs.push(cur);
                if rho > 0.25 && !retried {
                    lambda /= cfg.lambda_decrease;
                }
                lambda = lambda.max(lambda_floor);
                nu = 2.0;
                retried = false;
                progress.observer.on_event(&Event::Iteration {
                    solver: progress.name,
                    run: progress.run,
                    iteration: iterations,
                    cost: cur,
                    rms: rms(cur),
                    lambda,
                });
                // The noise level: the last `noise_window` steps moved χ² by less than
                // `noise_tolerance`.
                let dof = n_res - (nf * cd + np * pd + k) as f64;
                let at_noise_level = cfg.noise_tolerance > 0.0
                    && dof > 0.0
                    && costs.len() > cfg.noise_window
                    && costs[costs.len() - 1 - cfg.noise_window] - cur
                        < cfg.noise_tolerance * cur / dof;
                // The long tail: the last `noise_window` steps moved the cost by less than
                // `window_relative_tolerance` of itself.
                let settled = cfg.window_relative_tolerance > 0.0
                    && costs.len() > cfg.noise_window
                    && costs[costs.len() - 1 - cfg.noise_window] - cur
                        < cfg.window_relative_tolerance * cur;
                if rel < cfg.function_tolerance
                    || decrement_small
                    || at_noise_level
                    || settled
                    || step2.sqrt()
                        < cfg.parameter_tolerance * (par2.sqrt() + cfg.parameter_tolerance)
                    || cur <= cfg.absolute_tolerance * n_res
                    || progress
                        .stop
                        .as_mut()
                        .is_some_and(|stop| stop(cams, pts, cur))
                {
                    status = SolverStatus::Converged;
                }
                break;
            }
            // A failed step that promised less than the function tolerance: nothing left to
            // gain at this precision.
            if step2.sqrt() < cfg.parameter_tolerance * (par2.sqrt() + cfg.parameter_tolerance)
                || (pred >= 0.0 && pred < cfg.function_tolerance * cur)
            {
                status = SolverStatus::Converged;
                break 'outer;
            }
            retried = true;
            if raise_damping(&mut lambda, &mut nu) {
                status = SolverStatus::Stalled;
                break 'outer;
            }
        }
    }
    Ok(LmResult {
        report: SolverReport {
            status,
            iterations,
            initial_cost,
            final_cost: cur,
            seconds: start.elapsed().as_secs_f64(),
        },
        costs,
        schur_nnz: pattern.as_ref().map_or(0, Pattern::nnz),
        extensions,
        linear_solver: if iterative {
            LinearSolver::Iterative
        } else {
            LinearSolver::Direct
        },
        cg_iterations,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A graph of `np` tracks over `nf` cameras, track `p` seeing `len(p)` consecutive
    /// cameras from `start(p)`.
    fn graph(
        nf: usize,
        np: usize,
        start: impl Fn(usize) -> usize,
        len: impl Fn(usize) -> usize,
    ) -> Graph {
        let mut pt_ptr = vec![0];
        let mut cam = Vec::new();
        for p in 0..np {
            let a = start(p);
            cam.extend(a..(a + len(p)).min(nf));
            pt_ptr.push(cam.len());
        }
        let w = vec![[0.0; 2]; cam.len()];
        Graph {
            n_cams: nf,
            n_pts: np,
            pt_ptr,
            cam,
            w,
        }
    }

    /// Settings the solver cannot run with are typed errors naming the field; the defaults
    /// and the sparse pipeline's pass.
    #[test]
    fn settings_that_cannot_run_are_named() {
        assert!(LmConfig::default().validate("lm").is_ok());
        assert!(
            crate::sparse::SparseConfig::default()
                .lm
                .validate("sparse.lm")
                .is_ok()
        );
        for bad in [
            LmConfig {
                max_iterations: 0,
                ..LmConfig::default()
            },
            LmConfig {
                initial_lambda: 0.0,
                ..LmConfig::default()
            },
            LmConfig {
                initial_lambda: f64::NAN,
                ..LmConfig::default()
            },
            LmConfig {
                lambda_decrease: 1.0,
                ..LmConfig::default()
            },
            LmConfig {
                lambda_decrease: f64::INFINITY,
                ..LmConfig::default()
            },
            LmConfig {
                cg_tolerance: 0.0,
                ..LmConfig::default()
            },
            LmConfig {
                cg_tolerance: 1.0,
                ..LmConfig::default()
            },
            LmConfig {
                cg_tolerance: f64::NAN,
                ..LmConfig::default()
            },
            LmConfig {
                cg_max_iterations: 0,
                ..LmConfig::default()
            },
        ] {
            match bad.validate("sparse.lm") {
                Err(crate::Error::InvalidConfig { field, .. }) => assert_eq!(field, "sparse.lm"),
                other => panic!("{bad:?}: {other:?}"),
            }
        }
    }

    /// The chunks cover the track order once, in order; each chunk's cameras are the sorted
    /// union of its tracks'; a dense chunk has at least `CHUNK_MIN_TRACKS` tracks and its
    /// padded product is within `CHUNK_PADDING` times the exact work. A complete table
    /// is cut into dense chunks of `CHUNK_TRACKS` tracks over every camera; tracks of
    /// varied lengths along a sequence still go mostly to dense chunks.
    #[test]
    fn chunks_cover_the_tracks_and_bound_the_padding() {
        let check = |g: &Graph| -> (usize, usize) {
            let mut order: Vec<usize> = (0..g.n_pts).collect();
            order.sort_by_key(|&p| g.cam[g.pt_ptr[p]]);
            let (chunks, cams) = chunks(g, &order);
            let mut next = 0;
            let (mut dense_tracks, mut total) = (0, 0);
            for c in &chunks {
                assert_eq!(c.tracks.start, next);
                assert!(c.tracks.end > c.tracks.start);
                next = c.tracks.end;
                let mut union: Vec<usize> = order[c.tracks.clone()]
                    .iter()
                    .flat_map(|&p| g.cam[g.track(p)].to_vec())
                    .collect();
                union.sort_unstable();
                union.dedup();
                assert_eq!(&cams[c.cams.clone()], &union[..]);
                let exact: usize = order[c.tracks.clone()]
                    .iter()
                    .map(|&p| g.track(p).len().pow(2))
                    .sum();
                let t = c.tracks.len();
                total += t;
                if c.dense {
                    dense_tracks += t;
                    assert!((CHUNK_MIN_TRACKS..=CHUNK_TRACKS).contains(&t));
                    assert!(union.len() * union.len() * t <= CHUNK_PADDING * exact);
                }
            }
            assert_eq!(next, order.len());
            (dense_tracks, total)
        };
        let complete = graph(30, 200, |_| 0, |_| 30);
        assert_eq!(check(&complete), (200, 200));
        let mut order: Vec<usize> = (0..200).collect();
        order.sort_by_key(|&p| complete.cam[complete.pt_ptr[p]]);
        let (chunks, _) = chunks(&complete, &order);
        assert_eq!(chunks.len(), 200usize.div_ceil(CHUNK_TRACKS));
        assert!(chunks.iter().all(|c| c.cams.len() == 30));
        // A video: 5 000 tracks of 3–40 frames starting along 1 000 frames.
        let video = graph(1000, 5000, |p| (p * 7919) % 960, |p| 3 + (p * 31) % 38);
        let (dense, total) = check(&video);
        assert_eq!(total, 5000);
        assert!(
            dense * 2 > total,
            "{dense} of {total} tracks in dense chunks"
        );
    }
}
