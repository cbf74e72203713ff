//! Low-rank matrix completion of partial track tables (tracks enter and leave the frame).
//!
//! # Model and objective
//!
//! `W` is the 2F×N measurement matrix (row `2f` = x, `2f+1` = y of frame `f`), of which only
//! the entries of visible (frame, track) pairs are known (x and y of a pair are observed
//! together). Two models are fitted:
//!
//! * [`CompletionModel::Affine`]: `W ≈ M S + t 1ᵀ` with cameras `M` (2F×3), points `S`
//!   (3×N) and an explicit per-row translation `t ∈ R^{2F}` — a rank-4 factorization
//!   `[M t] [S; 1ᵀ]` whose 4th row of the right factor is fixed to ones (the affine camera).
//! * [`CompletionModel::Free`] `{ rank: r }`: `W ≈ U Vᵀ` with `U` 2F×r, `V` N×r and no
//!   translation (the literature's "rank 4" benchmark).
//!
//! Both minimise the unweighted, unregularised sum of squares over observed scalars
//!
//! ```text
//!   f(M, t, S) = Σ_{(f,p) observed} Σ_{i ∈ {2f, 2f+1}} (m_iᵀ s_p + t_i − w_ip)²,
//! ```
//!
//! and report `RMS = sqrt(f / #observed scalars)` (x and y counted separately).
//!
//! # Solvers
//!
//! * [`Wiberg`] (default, [`CompletionSolverKind::Wiberg`]): damped Wiberg / variable
//!   projection (VarPro). `S` is eliminated in closed form, Levenberg–Marquardt runs on the
//!   camera parameters `(M, t)` only. See [`wiberg`](Wiberg) for the ingredients.
//! * [`Als`] ([`CompletionSolverKind::Als`]): alternating least squares, for comparison;
//!   it is known to flat-line far from the optimum on these problems (Buchanan & Fitzgibbon
//!   2005), which it detects and reports as [`SolverStatus::Stalled`].
//!
//! Both solvers minimise the same reduced cost `f(M, t) = min_S f(M, t, S)`, so their
//! iteration costs are comparable. The solver's ending (converged, iteration cap, stalled)
//! is reported in [`SolverReport`], never as an error.
//!
//! # Gauge
//!
//! The model is invariant to `M → M A`, `S → A⁻¹ S` (and, for the affine model,
//! `t → t + M b`, `S → S − b 1ᵀ`). During the iterations `M` is kept with orthonormal
//! columns (and `t ⊥ range(M)`). The returned [`Completion`] uses, for the affine model, the
//! Tomasi–Kanade gauge: `M` orthonormal and the points centred (`Σ_p s_p = 0`, so `t` is
//! the centroid of the completed rows); for the free model `U` has orthonormal columns.
//!
//! # Sparsity and complexity
//!
//! With `n_obs` observed (frame, track) pairs, `r` the rank and `q = r + 1` (affine) or `r`
//! (free) camera parameters per row: one point solve over all tracks costs
//! `O(n_obs r² + N r³)`; one ALS iteration `O(n_obs q² + (F + N) q³)`; one Wiberg iteration
//! assembles the camera normal matrix from per-track blocks in `O(Σ_p (2 k_p)² q²)`
//! (`k_p` = frames observing track `p`) and factorises the dense `(2F q)²` camera system in
//! `O((2F q)³ / 3)` — fine for F up to a few hundred frames. Nothing is ever `O(F N)`
//! except the optional [`Completion::predict`] and the [`Init::Auto`] start (one dense
//! thin SVD of the row-mean-filled matrix).
//!
//! # References
//!
//! * A. M. Buchanan and A. W. Fitzgibbon, "Damped Newton algorithms for matrix factorization
//!   with missing data", CVPR 2005.
//! * T. Okatani and K. Deguchi, "On the Wiberg algorithm for matrix factorization in the
//!   presence of missing components", IJCV 72(3), 2007.
//! * J. H. Hong and A. Fitzgibbon, "Secrets of matrix factorization: approximations,
//!   numerics, manifold optimization and random restarts", ICCV 2015.
//! * J. H. Hong, C. Zach and A. Fitzgibbon, "Revisiting the variable projection method for
//!   separable nonlinear least squares problems", CVPR 2017.
//! * G. H. Golub and V. Pereyra, "The differentiation of pseudo-inverses and nonlinear least
//!   squares problems whose variables separate", SIAM J. Numer. Anal. 10(2), 1973;
//!   L. Kaufman, "A variable projection method for solving separable nonlinear least squares
//!   problems", BIT 15, 1975.

mod als;
pub(crate) mod linalg;
mod wiberg;

use std::time::Instant;

use faer::{Mat, MatRef};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

pub use als::Als;
pub use wiberg::{VarProJacobian, Wiberg};

use crate::{Error, Event, Measurements, Observer, Result, SolverReport, SolverStatus};

/// Which low-rank model is fitted to the observed entries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CompletionModel {
    /// `W ≈ M S + t 1ᵀ`: affine cameras (2F×3), 3D points (3×N) and explicit translation.
    Affine,
    /// `W ≈ U Vᵀ` of rank `rank`, no translation.
    Free { rank: usize },
}

impl CompletionModel {
    /// Rank of the `M S` part (3 for affine).
    pub fn rank(&self) -> usize {
        match self {
            CompletionModel::Affine => 3,
            CompletionModel::Free { rank } => *rank,
        }
    }

    /// Whether the model has an explicit translation.
    pub fn is_affine(&self) -> bool {
        matches!(self, CompletionModel::Affine)
    }
}

/// Which completion algorithm runs. Serialised as `"als"` / `"wiberg"`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum CompletionSolverKind {
    /// Alternating least squares (`"als"`).
    Als,
    /// Damped Wiberg / variable projection (`"wiberg"`, the default).
    #[default]
    Wiberg,
}

impl CompletionSolverKind {
    /// The serialised name (`"als"` or `"wiberg"`).
    pub fn name(&self) -> &'static str {
        match self {
            CompletionSolverKind::Als => "als",
            CompletionSolverKind::Wiberg => "wiberg",
        }
    }
}

impl std::str::FromStr for CompletionSolverKind {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "als" => Ok(CompletionSolverKind::Als),
            "wiberg" => Ok(CompletionSolverKind::Wiberg),
            _ => Err(Error::InvalidConfig {
                field: "solver",
                message: format!("unknown completion solver `{s}` (expected `als` or `wiberg`)"),
            }),
        }
    }
}

/// How the cameras are initialised.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Init {
    /// Entries of `M` i.i.d. standard Gaussian (seeded), `t = 0`: the random-start protocol
    /// of Hong, Zach & Fitzgibbon (CVPR 2017). Every run uses a different stream.
    Random,
    /// Data-driven first run: missing entries filled with their row's observed mean, `t` =
    /// those row means (affine), `M` = the leading `r` left singular vectors of the filled
    /// (affine: row-centred) matrix, refined by `impute_iterations` hard-impute sweeps
    /// ([`CompletionProblem::auto_start`]). Further runs (`runs > 1`) start at random.
    #[default]
    Auto,
}

/// Configuration of [`complete`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct CompletionConfig {
    /// Algorithm. Default [`CompletionSolverKind::Wiberg`].
    pub solver: CompletionSolverKind,
    /// Model. Default [`CompletionModel::Affine`].
    pub model: CompletionModel,
    /// Initialisation. Default [`Init::Auto`].
    pub init: Init,
    /// Seed of the random starts. Default 0.
    pub seed: u64,
    /// Number of starts; the run with the lowest final cost is kept. Default 1.
    pub runs: usize,
    /// Iteration cap per run (Wiberg: linear solves, ALS: sweeps). Default 500.
    pub max_iterations: usize,
    /// Converged when the relative cost decrease of an (accepted) iteration falls below
    /// this. Default 1e-10.
    pub function_tolerance: f64,
    /// Converged when the relative gradient `‖∇f‖ / (‖w‖ ‖[S; 1]‖_F)` of the reduced cost,
    /// with `M` orthonormal, falls below this. Default 1e-12.
    pub gradient_tolerance: f64,
    /// ALS: damping `λ` added, relative to the mean diagonal, to each small normal matrix
    /// (`A + λ tr(A)/n I`). Default 0 (exact alternation).
    pub als_damping: f64,
    /// ALS: stalled when the relative decrease stayed below `stall_tolerance` for
    /// `stall_window` consecutive sweeps while the relative gradient is not below
    /// `gradient_tolerance`. Default 1e-7.
    pub stall_tolerance: f64,
    /// See `stall_tolerance`. Default 20.
    pub stall_window: usize,
    /// Wiberg: initial Levenberg damping, relative to the mean diagonal of the camera
    /// normal matrix. Default 1e-4.
    pub initial_lambda: f64,
    /// Wiberg: damping added to each point's normal matrix (cameras are orthonormal, so
    /// this is relative to O(1) entries) so that under-observed tracks stay finite; the
    /// iterations then minimise `Σ r² + μ Σ_p ‖s_p‖²` exactly (the final points are
    /// solved without it). Default 1e-12.
    pub point_damping: f64,
    /// Wiberg: ridge of a first continuation stage (the objective is then
    /// `Σ r² + μ₀ Σ_p ‖s_p‖²`), run to a loose tolerance before the final stage with
    /// `point_damping`. Keeps weakly observed points from escaping to infinity (a common
    /// cause of spurious minima). Not run when ≤ `point_damping`. Default 1e-6 (see
    /// [`Wiberg`] for the measurements behind it; 1e-5 and larger hurt on dino_trimmed).
    pub point_damping_initial: f64,
    /// Wiberg: factor by which the continuation ridge shrinks from one stage to the next
    /// (`μ₀, μ₀ρ, μ₀ρ², …` while above `point_damping`, then `point_damping`). A value
    /// of 0 jumps from `point_damping_initial` straight to `point_damping`. Default 0.
    pub point_damping_decrease: f64,
    /// Wiberg, affine model: damping on the translation parameters as a multiple of the
    /// damping on `M` (see [`Wiberg`]). Default 10.
    pub translation_damping: f64,
    /// Wiberg: Gauss–Newton matrix of the reduced problem. Default [`VarProJacobian::Kaufman`].
    pub jacobian: VarProJacobian,
    /// Wiberg: creep detection. When the objective decreased by less than
    /// `creep_tolerance` (relative) over the last `creep_window` iterations while not
    /// converged, the solver switches from Kaufman's to the full (Golub–Pereyra)
    /// Gauss–Newton matrix for the rest of the run. 0 disables the switch. Default 20.
    pub creep_window: usize,
    /// See `creep_window`. Default 1e-3.
    pub creep_tolerance: f64,
    /// Wiberg: geodesic acceleration (Transtrum & Sethna 2012). Each Levenberg step `δ` is
    /// corrected by half the second-order term `a` (from a finite-difference directional
    /// second derivative of the reduced residual, solved with the same damped normal
    /// matrix) when `2‖a‖ ≤ α‖δ‖`, with `α` this value; 0 disables it. Default 0.75
    /// (Transtrum & Sethna's recommendation). It keeps the iterates on the curved valley
    /// of the objective instead of drifting into the escaped-point directions; see
    /// [`Wiberg`] for the measurements.
    pub geodesic_acceleration: f64,
    /// [`Init::Auto`]: hard-impute (EM) sweeps refining the data-driven start before the
    /// solver runs: the missing entries are replaced by the current rank-`r` (+ translation)
    /// reconstruction and the subspace is re-estimated (Troyanskaya et al. 2001;
    /// Mazumder, Hastie & Tibshirani 2010 without shrinkage). 0 keeps the plain row-mean
    /// start. Default 10: with the plain start the affine Wiberg run ends in a spurious
    /// minimum on dino_trimmed (RMS 4.088 after 500 iterations) and on the hotel tracks
    /// with 70 % hidden; 3 sweeps fix dino only, 5–30 fix both (measured; 200 sweeps drift
    /// into a poor basin again on the hotel case).
    pub impute_iterations: usize,
    /// Wiberg: when one of its iterations would cost more than this many floating-point
    /// operations (estimated as `Σ_p (2 k_p q)² r + (2Fq)³/3`, the reduced camera system's
    /// assembly over tracks seen in `k_p` frames plus its Cholesky factorisation; `O(F N k)`
    /// for tracks as long as the sequence), alternating least squares runs first from the
    /// same start (`O(n_obs q²)` per sweep), and the Wiberg iterations continue from where
    /// it ended only when it did not converge (stalled or hit the cap). `f64::INFINITY`:
    /// the Wiberg solver alone. Default `1e10` (about one second per Wiberg iteration on
    /// two cores): every data set of docs/results.md below 300 × 10 000 runs Wiberg alone;
    /// on 300 × 10 000 with 40 % missing (6·10¹⁰ per iteration, 4.6 s) ALS converges to the
    /// same RMS in 15 sweeps, 4.7 s in all against 42 s (docs/results.md).
    pub als_first_flops: f64,
}

impl Default for CompletionConfig {
    fn default() -> Self {
        Self {
            solver: CompletionSolverKind::Wiberg,
            model: CompletionModel::Affine,
            init: Init::Auto,
            seed: 0,
            runs: 1,
            max_iterations: 500,
            function_tolerance: 1e-10,
            gradient_tolerance: 1e-12,
            als_damping: 0.0,
            stall_tolerance: 1e-7,
            stall_window: 20,
            initial_lambda: 1e-4,
            point_damping: 1e-12,
            point_damping_initial: 1e-6,
            point_damping_decrease: 0.0,
            translation_damping: 10.0,
            jacobian: VarProJacobian::Kaufman,
            creep_window: 20,
            creep_tolerance: 1e-3,
            geodesic_acceleration: 0.75,
            impute_iterations: 10,
            als_first_flops: 1e10,
        }
    }
}

impl CompletionConfig {
    /// Checks ranges; returns [`Error::InvalidConfig`] naming the field.
    pub fn validate(&self) -> Result<()> {
        let bad =
            |field: &'static str, message: String| Err(Error::InvalidConfig { field, message });
        if let CompletionModel::Free { rank } = self.model
            && rank == 0
        {
            return bad("model", "free rank must be at least 1".into());
        }
        if self.runs == 0 {
            return bad("runs", "need at least one run".into());
        }
        if self.max_iterations == 0 {
            return bad("max_iterations", "must be at least 1".into());
        }
        for (field, v) in [
            ("function_tolerance", self.function_tolerance),
            ("gradient_tolerance", self.gradient_tolerance),
            ("als_damping", self.als_damping),
            ("stall_tolerance", self.stall_tolerance),
            ("point_damping", self.point_damping),
            ("point_damping_initial", self.point_damping_initial),
            ("creep_tolerance", self.creep_tolerance),
            ("geodesic_acceleration", self.geodesic_acceleration),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(field, format!("must be finite and non-negative, got {v}"));
            }
        }
        if self.als_first_flops.is_nan() || self.als_first_flops < 0.0 {
            return bad(
                "als_first_flops",
                format!(
                    "must be non-negative (infinity: never), got {}",
                    self.als_first_flops
                ),
            );
        }
        if !(self.point_damping_decrease.is_finite()
            && (0.0..1.0).contains(&self.point_damping_decrease))
        {
            return bad(
                "point_damping_decrease",
                format!("must be in [0, 1), got {}", self.point_damping_decrease),
            );
        }
        if !(self.translation_damping.is_finite() && self.translation_damping > 0.0) {
            return bad(
                "translation_damping",
                format!(
                    "must be finite and positive, got {}",
                    self.translation_damping
                ),
            );
        }
        if !(self.initial_lambda.is_finite() && self.initial_lambda > 0.0) {
            return bad(
                "initial_lambda",
                format!("must be finite and positive, got {}", self.initial_lambda),
            );
        }
        if self.stall_window == 0 {
            return bad("stall_window", "must be at least 1".into());
        }
        Ok(())
    }
}

/// Result of [`complete`]: the factors of the best run.
#[derive(Debug, Clone)]
pub struct Completion {
    /// Cameras, 2F×r (orthonormal columns).
    pub m: Mat<f64>,
    /// Points, r×N (centred for the affine model).
    pub s: Mat<f64>,
    /// Translation per row, length 2F (zeros for the free model).
    pub t: Vec<f64>,
    pub model: CompletionModel,
    pub solver: CompletionSolverKind,
    /// RMS over observed scalars of the best run.
    pub rms: f64,
    /// Report of the best run (`seconds`: that run's wall time).
    pub report: SolverReport,
    /// Reports of all runs, in run order.
    pub runs: Vec<SolverReport>,
    /// Index of the best run in `runs`.
    pub best_run: usize,
    /// ALS sweeps of the best run before its solver ([`CompletionConfig::als_first_flops`]);
    /// 0 when the solver ran alone. When they converged, the solver ran no iteration.
    pub als_sweeps_first: usize,
}

impl Completion {
    /// The filled-in matrix `M S + t 1ᵀ` (2F×N, every entry).
    pub fn predict(&self) -> Mat<f64> {
        let mut p = &self.m * &self.s;
        for i in 0..p.nrows() {
            for j in 0..p.ncols() {
                p[(i, j)] += self.t[i];
            }
        }
        p
    }

    /// Predicted position `(x, y)` of track `p` in frame `f`.
    pub fn predict_point(&self, f: usize, p: usize) -> [f64; 2] {
        let mut out = [self.t[2 * f], self.t[2 * f + 1]];
        for (k, o) in out.iter_mut().enumerate() {
            for c in 0..self.m.ncols() {
                *o += self.m[(2 * f + k, c)] * self.s[(c, p)];
            }
        }
        out
    }
}

/// Camera parameters and the outcome of one solver run.
#[derive(Debug, Clone)]
pub struct CompletionRun {
    /// Cameras 2F×r.
    pub m: Mat<f64>,
    /// Translation (length 2F; zeros for the free model).
    pub t: Vec<f64>,
    pub report: SolverReport,
}

/// A completion algorithm: improves cameras `(M, t)` for the reduced cost
/// `f(M, t) = min_S Σ_observed (m_iᵀ s_p + t_i − w_ip)²`.
pub trait CompletionSolver {
    /// Short name, used in [`Event::Iteration`] (`"wiberg"`, `"als"`).
    fn name(&self) -> &'static str;
    /// Runs from the initial cameras `m0` (2F×r) and `t0` (length 2F; ignored and zero for
    /// the free model). `run` labels the emitted events.
    fn solve(
        &self,
        problem: &CompletionProblem,
        m0: MatRef<'_, f64>,
        t0: &[f64],
        run: usize,
        observer: &mut dyn Observer,
    ) -> CompletionRun;
}

/// Validated, sparse form of the observations for one model: per-track and per-frame lists
/// of observed entries. Building it checks that the model is determined (see
/// [`CompletionProblem::new`]).
#[derive(Debug, Clone)]
pub struct CompletionProblem {
    n_frames: usize,
    n_points: usize,
    rank: usize,
    affine: bool,
    /// Per track `p`: observations `col_ptr[p]..col_ptr[p+1]` into `col_frame`, `col_w`.
    col_ptr: Vec<usize>,
    col_frame: Vec<usize>,
    col_w: Vec<[f64; 2]>,
    /// Per frame `f`: observations `row_ptr[f]..row_ptr[f+1]` into `row_track`, `row_w`.
    row_ptr: Vec<usize>,
    row_track: Vec<usize>,
    row_w: Vec<[f64; 2]>,
    /// Norm of the observed data.
    w_norm: f64,
}

/// Per-track results of eliminating the points for given cameras.
#[derive(Debug, Clone)]
pub(crate) struct PointSolve {
    /// Points, N×r row-major.
    pub s: Vec<f64>,
    /// Residuals `pred − w`, two per observation, in per-track (`col_*`) order.
    pub res: Vec<f64>,
    /// Inverse point normal matrices `(M̃ᵀM̃ + μI)⁻¹`, N×r×r (only when requested).
    pub ainv: Vec<f64>,
    /// Data cost `Σ r²`.
    pub cost: f64,
    /// Regulariser `Σ_p ridge_p ‖s_p‖²` of the damped point solves.
    pub reg: f64,
}

impl PointSolve {
    /// The objective the damped point solves minimise exactly: `cost + reg`.
    pub fn objective(&self) -> f64 {
        self.cost + self.reg
    }
}

impl CompletionProblem {
    /// Validates `meas` for `model` and builds the sparse structure.
    ///
    /// Requirements (each a typed error):
    /// * at least one frame and one track ([`Error::TooFew`]);
    /// * observed values finite ([`Error::Degenerate`]);
    /// * affine: every track seen in ≥ 2 frames (4 scalars for 3 unknowns), every frame
    ///   seeing ≥ 4 tracks (a 2×4 affine camera has 4 unknowns per row);
    /// * free rank `r`: every track seen in ≥ ⌈r/2⌉ frames (≥ r scalars for its r unknowns),
    ///   every frame seeing ≥ r tracks (r unknowns per camera row); `r ≤ min(2F, N)`;
    /// * the bipartite frame–track graph is connected ([`Error::Disconnected`]). This is
    ///   necessary, not sufficient, for a unique completion.
    ///
    /// `Error::TooFew::what` says which count failed; `have` is the smallest count found
    /// (the first offending index is named in the message of [`complete`]'s warning event).
    pub fn new(meas: &Measurements, model: CompletionModel) -> Result<Self> {
        Self::new_with_culprit(meas, model).map_err(|(e, _)| e)
    }

    fn new_with_culprit(
        meas: &Measurements,
        model: CompletionModel,
    ) -> std::result::Result<Self, (Error, Option<String>)> {
        let (nf, np) = (meas.n_frames(), meas.n_points());
        let rank = model.rank();
        if rank == 0 {
            return Err((
                Error::InvalidConfig {
                    field: "model",
                    message: "free rank must be at least 1".into(),
                },
                None,
            ));
        }
        if nf == 0 {
            return Err((
                Error::TooFew {
                    what: "frames",
                    needed: 1,
                    have: 0,
                },
                None,
            ));
        }
        if np == 0 {
            return Err((
                Error::TooFew {
                    what: "tracks",
                    needed: 1,
                    have: 0,
                },
                None,
            ));
        }
        if meas.visible.len() != nf * np {
            return Err((
                Error::Dimension {
                    context: "visibility mask",
                    expected: format!("{} entries (F×N)", nf * np),
                    got: meas.visible.len().to_string(),
                },
                None,
            ));
        }
        if !model.is_affine() && rank > (2 * nf).min(np) {
            return Err((
                Error::InvalidConfig {
                    field: "model",
                    message: format!("free rank {rank} exceeds min(2F, N) = {}", (2 * nf).min(np)),
                },
                None,
            ));
        }
        let (need_track, need_frame) = match model {
            CompletionModel::Affine => (2, 4),
            CompletionModel::Free { rank } => (rank.div_ceil(2), rank),
        };
        // Counts.
        let mut track_len = vec![0usize; np];
        let mut frame_len = vec![0usize; nf];
        for (k, _) in meas.visible.iter().enumerate().filter(|(_, v)| **v) {
            let (f, p) = (k / np, k % np);
            {
                {
                    let (x, y) = (meas.w[(2 * f, p)], meas.w[(2 * f + 1, p)]);
                    if !(x.is_finite() && y.is_finite()) {
                        return Err((
                            Error::Degenerate(format!(
                                "observed value of track {p} in frame {f} is not finite \
                                 ({x}, {y})"
                            )),
                            None,
                        ));
                    }
                    track_len[p] += 1;
                    frame_len[f] += 1;
                }
            }
        }
        if let Some((p, &have)) = track_len.iter().enumerate().min_by_key(|(_, l)| **l)
            && have < need_track
        {
            return Err((
                Error::TooFew {
                    what: "frames observing a track",
                    needed: need_track,
                    have,
                },
                Some(format!(
                    "track {p} is observed in {have} frame(s); the model needs {need_track}"
                )),
            ));
        }
        if let Some((f, &have)) = frame_len.iter().enumerate().min_by_key(|(_, l)| **l)
            && have < need_frame
        {
            return Err((
                Error::TooFew {
                    what: "tracks observed in a frame",
                    needed: need_frame,
                    have,
                },
                Some(format!(
                    "frame {f} observes {have} track(s); the model needs {need_frame}"
                )),
            ));
        }
        // Connectivity of the bipartite frame–track graph (union–find, frames 0..F, tracks F..).
        let mut parent: Vec<usize> = (0..nf + np).collect();
        for f in 0..nf {
            for p in 0..np {
                if meas.visible[f * np + p] {
                    let (a, b) = (
                        crate::table::find_root(&mut parent, f),
                        crate::table::find_root(&mut parent, nf + p),
                    );
                    if a != b {
                        parent[a] = b;
                    }
                }
            }
        }
        let mut comp_frames = vec![0usize; nf + np];
        let mut comp_tracks = vec![0usize; nf + np];
        for f in 0..nf {
            let r = crate::table::find_root(&mut parent, f);
            comp_frames[r] += 1;
        }
        for p in 0..np {
            let r = crate::table::find_root(&mut parent, nf + p);
            comp_tracks[r] += 1;
        }
        let roots: Vec<usize> = (0..nf + np)
            .filter(|&i| comp_frames[i] + comp_tracks[i] > 0)
            .collect();
        if roots.len() > 1 {
            let big = roots
                .iter()
                .copied()
                .max_by_key(|&r| (comp_frames[r] + comp_tracks[r], comp_frames[r]))
                .unwrap_or(roots[0]);
            return Err((
                Error::Disconnected {
                    components: roots.len(),
                    largest_frames: comp_frames[big],
                    largest_tracks: comp_tracks[big],
                },
                None,
            ));
        }
        // Sparse structure.
        let mut col_ptr = Vec::with_capacity(np + 1);
        let mut col_frame = Vec::new();
        let mut col_w = Vec::new();
        col_ptr.push(0);
        for p in 0..np {
            for f in 0..nf {
                if meas.visible[f * np + p] {
                    col_frame.push(f);
                    col_w.push([meas.w[(2 * f, p)], meas.w[(2 * f + 1, p)]]);
                }
            }
            col_ptr.push(col_frame.len());
        }
        let mut row_ptr = Vec::with_capacity(nf + 1);
        let mut row_track = Vec::new();
        let mut row_w = Vec::new();
        row_ptr.push(0);
        for f in 0..nf {
            for p in 0..np {
                if meas.visible[f * np + p] {
                    row_track.push(p);
                    row_w.push([meas.w[(2 * f, p)], meas.w[(2 * f + 1, p)]]);
                }
            }
            row_ptr.push(row_track.len());
        }
        let w_norm = col_w
            .iter()
            .map(|w| w[0] * w[0] + w[1] * w[1])
            .sum::<f64>()
            .sqrt()
            .max(f64::MIN_POSITIVE);
        Ok(Self {
            w_norm,
            n_frames: nf,
            n_points: np,
            rank,
            affine: model.is_affine(),
            col_ptr,
            col_frame,
            col_w,
            row_ptr,
            row_track,
            row_w,
        })
    }

    /// Number of frames F.
    pub fn n_frames(&self) -> usize {
        self.n_frames
    }
    /// Number of tracks N.
    pub fn n_points(&self) -> usize {
        self.n_points
    }
    /// Rank r of `M S`.
    pub fn rank(&self) -> usize {
        self.rank
    }
    /// Whether the model has an explicit translation.
    pub fn is_affine(&self) -> bool {
        self.affine
    }
    /// Number of observed (frame, track) pairs.
    pub fn n_observed(&self) -> usize {
        self.col_frame.len()
    }
    /// Estimated floating-point operations of one Wiberg iteration: the reduced camera
    /// system's assembly, `Σ_p (2 k_p q)² r` over tracks seen in `k_p` frames, plus its
    /// dense Cholesky factorisation, `(2Fq)³/3`. `O(N)`.
    pub fn wiberg_iteration_flops(&self) -> f64 {
        let (q, r) = (self.q() as f64, self.rank as f64);
        let assembly: f64 = self
            .col_ptr
            .windows(2)
            .map(|w| {
                let k = (w[1] - w[0]) as f64;
                (2.0 * k * q).powi(2) * r
            })
            .sum();
        assembly + (2.0 * self.n_frames as f64 * q).powi(3) / 3.0
    }

    /// Camera parameters per matrix row: `r + 1` (affine) or `r`.
    pub(crate) fn q(&self) -> usize {
        self.rank + usize::from(self.affine)
    }
    /// RMS for a cost (sum of squares).
    pub fn rms_of_cost(&self, cost: f64) -> f64 {
        (cost / (2 * self.n_observed()).max(1) as f64).sqrt()
    }

    /// Packs `(M, t)` into the internal row-major 2F×q layout `[m_i, t_i]`.
    pub(crate) fn pack(&self, m: MatRef<'_, f64>, t: &[f64]) -> Vec<f64> {
        let (q, r) = (self.q(), self.rank);
        let mut u = vec![0.0; 2 * self.n_frames * q];
        for i in 0..2 * self.n_frames {
            for c in 0..r {
                u[i * q + c] = m[(i, c)];
            }
            if self.affine {
                u[i * q + r] = t.get(i).copied().unwrap_or(0.0);
            }
        }
        u
    }

    /// Unpacks the internal layout into `(M, t)`.
    pub(crate) fn unpack(&self, u: &[f64]) -> (Mat<f64>, Vec<f64>) {
        let (q, r) = (self.q(), self.rank);
        let rows = 2 * self.n_frames;
        let m = Mat::from_fn(rows, r, |i, c| u[i * q + c]);
        let t = (0..rows)
            .map(|i| if self.affine { u[i * q + r] } else { 0.0 })
            .collect();
        (m, t)
    }

    /// Gauge fixing (retraction): `M ← Q` of a QR of `M` (Gram–Schmidt, twice), and for
    /// the affine model `t ← t − M Mᵀ t`. The reduced cost is unchanged.
    pub(crate) fn normalize(&self, u: &mut [f64]) {
        let (q, r) = (self.q(), self.rank);
        let rows = 2 * self.n_frames;
        for c in 0..r {
            for _pass in 0..2 {
                for c2 in 0..c {
                    let d: f64 = (0..rows).map(|i| u[i * q + c] * u[i * q + c2]).sum();
                    for i in 0..rows {
                        u[i * q + c] -= d * u[i * q + c2];
                    }
                }
            }
            let mut nrm = (0..rows).map(|i| u[i * q + c].powi(2)).sum::<f64>().sqrt();
            // A (numerically) dependent column: replace it by a coordinate vector made
            // orthogonal to the previous ones.
            let mut k = 0;
            while (nrm <= 1e-10 || nrm.is_nan()) && k < rows {
                for i in 0..rows {
                    u[i * q + c] = if i == (c + k) % rows { 1.0 } else { 0.0 };
                }
                for _pass in 0..2 {
                    for c2 in 0..c {
                        let d: f64 = (0..rows).map(|i| u[i * q + c] * u[i * q + c2]).sum();
                        for i in 0..rows {
                            u[i * q + c] -= d * u[i * q + c2];
                        }
                    }
                }
                nrm = (0..rows).map(|i| u[i * q + c].powi(2)).sum::<f64>().sqrt();
                k += 1;
            }
            if nrm > 0.0 {
                for i in 0..rows {
                    u[i * q + c] /= nrm;
                }
            }
        }
        if self.affine {
            for _pass in 0..2 {
                for c in 0..r {
                    let d: f64 = (0..rows).map(|i| u[i * q + r] * u[i * q + c]).sum();
                    for i in 0..rows {
                        u[i * q + r] -= d * u[i * q + c];
                    }
                }
            }
        }
    }

    /// Eliminates the points: for each track `p`, `s_p = (M̃ᵀM̃ + μI)⁻¹ M̃ᵀ (w̃ − t̃)` over its
    /// observed rows. Cost `O(n_obs r² + N r³)`.
    ///
    /// The damping added to each normal matrix `A` is `mu + mu_rel · tr(A)/r`.
    pub(crate) fn solve_points(
        &self,
        u: &[f64],
        mu: f64,
        mu_rel: f64,
        want_inverse: bool,
    ) -> PointSolve {
        let r = self.rank;
        let np = self.n_points;
        let mut s = vec![0.0; np * r];
        let mut res = vec![0.0; 2 * self.n_observed()];
        let mut ainv = if want_inverse {
            vec![0.0; np * r * r]
        } else {
            Vec::new()
        };
        // Tracks are independent: blocks of them in parallel, each block writing its own
        // slices; the block sums are added in block order (the result does not depend on
        // the number of threads).
        let blocks: Vec<(usize, usize)> = (0..np)
            .step_by(POINT_BLOCK)
            .map(|lo| (lo, (lo + POINT_BLOCK).min(np)))
            .collect();
        let mut res_parts = Vec::with_capacity(blocks.len());
        let mut rest = res.as_mut_slice();
        for &(lo, hi) in &blocks {
            let (head, tail) = rest.split_at_mut(2 * (self.col_ptr[hi] - self.col_ptr[lo]));
            res_parts.push(head);
            rest = tail;
        }
        let mut ainv_parts: Vec<&mut [f64]> = if want_inverse {
            ainv.chunks_mut(POINT_BLOCK * r * r).collect()
        } else {
            blocks.iter().map(|_| <&mut [f64]>::default()).collect()
        };
        let sums: Vec<(f64, f64)> = s
            .par_chunks_mut(POINT_BLOCK * r)
            .zip(res_parts.par_iter_mut())
            .zip(ainv_parts.par_iter_mut())
            .zip(blocks.par_iter())
            .map(|(((s_blk, res_blk), ainv_blk), &(lo, hi))| {
                self.solve_point_block(u, mu, mu_rel, lo, hi, s_blk, res_blk, ainv_blk)
            })
            .collect();
        let (cost, reg) = sums
            .iter()
            .fold((0.0, 0.0), |(c, g), (c2, g2)| (c + c2, g + g2));
        PointSolve {
            s,
            res,
            ainv,
            cost,
            reg,
        }
    }

    /// [`Self::solve_points`] for tracks `lo..hi`, writing their points, residuals and
    /// (when `ainv` is not empty) inverse normal matrices into the block's slices. Returns
    /// the block's `(cost, reg)`.
    #[allow(clippy::too_many_arguments)]
    fn solve_point_block(
        &self,
        u: &[f64],
        mu: f64,
        mu_rel: f64,
        lo: usize,
        hi: usize,
        s: &mut [f64],
        res: &mut [f64],
        ainv: &mut [f64],
    ) -> (f64, f64) {
        let (q, r) = (self.q(), self.rank);
        let want_inverse = !ainv.is_empty();
        let o0 = self.col_ptr[lo];
        let mut a = vec![0.0; r * r];
        let mut b = vec![0.0; r];
        let mut cost = 0.0;
        let mut reg = 0.0;
        for p in lo..hi {
            a.iter_mut().for_each(|x| *x = 0.0);
            b.iter_mut().for_each(|x| *x = 0.0);
            let (olo, ohi) = (self.col_ptr[p], self.col_ptr[p + 1]);
            for o in olo..ohi {
                let f = self.col_frame[o];
                for k in 0..2 {
                    let row = &u[(2 * f + k) * q..(2 * f + k + 1) * q];
                    let y = self.col_w[o][k] - if self.affine { row[r] } else { 0.0 };
                    for c in 0..r {
                        b[c] += row[c] * y;
                        for c2 in 0..=c {
                            a[c * r + c2] += row[c] * row[c2];
                        }
                    }
                }
            }
            let ridge = mu + mu_rel * (0..r).map(|c| a[c * r + c]).sum::<f64>() / r as f64;
            for c in 0..r {
                for c2 in 0..c {
                    a[c2 * r + c] = a[c * r + c2];
                }
                a[c * r + c] += ridge;
            }
            let sp = &mut s[(p - lo) * r..(p - lo + 1) * r];
            sp.copy_from_slice(&b);
            let ok = linalg::spd_solve_robust(&mut a, r, sp);
            if !ok {
                sp.iter_mut().for_each(|x| *x = 0.0);
            }
            reg += ridge * sp.iter().map(|x| x * x).sum::<f64>();
            if want_inverse {
                // `a` now holds the Cholesky factor (or garbage if !ok).
                let inv = &mut ainv[(p - lo) * r * r..(p - lo + 1) * r * r];
                if ok {
                    linalg::chol_inverse(&a, r, inv);
                }
            }
            for o in olo..ohi {
                let f = self.col_frame[o];
                for k in 0..2 {
                    let row = &u[(2 * f + k) * q..(2 * f + k + 1) * q];
                    let mut pred = if self.affine { row[r] } else { 0.0 };
                    for c in 0..r {
                        pred += row[c] * sp[c];
                    }
                    let d = pred - self.col_w[o][k];
                    res[2 * (o - o0) + k] = d;
                    cost += d * d;
                }
            }
        }
        (cost, reg)
    }

    /// Gradient (half of it: `Jᵀ r`) of the reduced cost with respect to the packed camera
    /// parameters, and the relative gradient `‖Jᵀr‖ / (‖w‖ ‖[S; 1]‖_F)` (`‖w‖` = norm of
    /// the observed data, so that zero-residual problems converge too).
    pub(crate) fn gradient(&self, ps: &PointSolve) -> (Vec<f64>, f64) {
        let r = self.rank;
        let g = self.jt_sbar(ps, &ps.res);
        let s_norm2: f64 = (0..self.n_points)
            .map(|p| {
                let sp = &ps.s[p * r..(p + 1) * r];
                sp.iter().map(|x| x * x).sum::<f64>() + if self.affine { 1.0 } else { 0.0 }
            })
            .sum();
        let gn = g.iter().map(|x| x * x).sum::<f64>().sqrt();
        let denom = self.w_norm * s_norm2.sqrt();
        let rel = if denom > 0.0 { gn / denom } else { 0.0 };
        (g, rel)
    }

    /// `Σ_p v_p ⊗ s̄_p` for a residual-space vector `v` (two entries per observation, in
    /// track order), `s̄_p = [s_p; 1]` (affine) or `s_p`: the camera-space image of `v`
    /// under the transposed Jacobian's first term. O(observations · r).
    pub(crate) fn jt_sbar(&self, ps: &PointSolve, v: &[f64]) -> Vec<f64> {
        let (q, r) = (self.q(), self.rank);
        let mut g = vec![0.0; 2 * self.n_frames * q];
        for p in 0..self.n_points {
            let sp = &ps.s[p * r..(p + 1) * r];
            for o in self.col_ptr[p]..self.col_ptr[p + 1] {
                let f = self.col_frame[o];
                for k in 0..2 {
                    let e = v[2 * o + k];
                    let gi = &mut g[(2 * f + k) * q..(2 * f + k + 1) * q];
                    for c in 0..r {
                        gi[c] += e * sp[c];
                    }
                    if self.affine {
                        gi[r] += e;
                    }
                }
            }
        }
        g
    }

    /// Random start (Hong, Zach & Fitzgibbon 2017 protocol): `M` i.i.d. N(0, 1), `t = 0`.
    pub fn random_start(&self, rng: &mut StdRng) -> (Mat<f64>, Vec<f64>) {
        let rows = 2 * self.n_frames;
        let m = Mat::from_fn(rows, self.rank, |_, _| rng.sample::<f64, _>(StandardNormal));
        (m, vec![0.0; rows])
    }

    /// Data-driven start: fill missing entries with the row's observed mean, take
    /// `t` = row means (affine; zero for the free model) and `M` = leading `r` left singular
    /// vectors of the filled (affine: centred) matrix; then `impute_iterations` hard-impute
    /// sweeps: missing entries ← `M Σ Vᵀ (+ t 1ᵀ)` of the current rank-`r` SVD, `t` ← row
    /// means of the filled matrix, SVD again. Each sweep is an EM step for a rank-`r`
    /// model with missing data: it never increases the fit to the filled matrix and, unlike
    /// the row means, it does not bias the start toward the frames' visible subsets (which
    /// shift with the camera when tracks enter and leave).
    ///
    /// Dense: `O(F N r)` time per sweep with the randomized truncated SVD
    /// ([`crate::svd`]), or `O(F² N)` by the Gram matrix for up to 256 rows (faster
    /// there; see `GRAM_START_MAX_ROWS`), `impute_iterations + 1` SVDs in all,
    /// once per completion; memory one 2F×N matrix.
    pub fn auto_start(&self, impute_iterations: usize) -> Result<(Mat<f64>, Vec<f64>)> {
        let rows = 2 * self.n_frames;
        let mut mean = vec![0.0; rows];
        for f in 0..self.n_frames {
            let (lo, hi) = (self.row_ptr[f], self.row_ptr[f + 1]);
            let n = (hi - lo).max(1) as f64;
            for k in 0..2 {
                mean[2 * f + k] = self.row_w[lo..hi].iter().map(|w| w[k]).sum::<f64>() / n;
            }
        }
        // The filled matrix, column-major (a column per track): observed entries centred
        // by the row means and missing ones 0 (affine); the free model factors the filled
        // matrix itself (observed entries as they are, missing = row mean).
        let mut a = vec![0.0; rows * self.n_points];
        if rows > 0 {
            a.par_chunks_mut(rows).enumerate().for_each(|(p, col)| {
                if !self.affine {
                    col.copy_from_slice(&mean);
                }
                for o in self.col_ptr[p]..self.col_ptr[p + 1] {
                    let f = self.col_frame[o];
                    for k in 0..2 {
                        let centre = if self.affine { mean[2 * f + k] } else { 0.0 };
                        col[2 * f + k] = self.col_w[o][k] - centre;
                    }
                }
            });
        }
        self.impute(a, mean, impute_iterations)
    }

    /// `sweeps` hard-impute sweeps on the filled matrix `a` (column-major, 2F×N; affine:
    /// centred, with row means `mean`), then `M` = its leading left singular vectors,
    /// `t` = `mean`.
    ///
    /// A sweep rebuilds each column `p` as `t + U Σ v_p` (`O(F r)`), puts the track's
    /// observations back and accumulates the column into the new row means, a column of
    /// `a` at a time on every core (contiguous reads and writes); the affine model then
    /// subtracts the new means in a second pass. The per-block sums are added in block
    /// order, so the result does not depend on the number of threads.
    fn impute(
        &self,
        mut a: Vec<f64>,
        mut mean: Vec<f64>,
        sweeps: usize,
    ) -> Result<(Mat<f64>, Vec<f64>)> {
        const BLOCK: usize = 64;
        let rows = 2 * self.n_frames;
        let n = self.n_points;
        let r = self.rank;
        let svd_cfg = crate::svd::TruncatedSvdConfig::default();
        let mut sweep = 0;
        loop {
            let view = MatRef::from_column_major_slice(&a, rows, n);
            let svd = if gram_start(rows, n) {
                crate::svd::leading_by_gram(view, r)?
            } else {
                crate::svd::truncated_svd(view, r, &svd_cfg)?
            };
            let k = svd.s.len().min(r);
            if sweep >= sweeps || rows == 0 {
                let m = Mat::from_fn(rows, r, |i, c| if c < k { svd.u[(i, c)] } else { 0.0 });
                let t = if self.affine { mean } else { vec![0.0; rows] };
                return Ok((m, t));
            }
            sweep += 1;
            // a ← rank-r reconstruction (+ t) with the observed entries put back.
            let us: Vec<f64> = (0..k)
                .flat_map(|c| (0..rows).map(move |i| (c, i)))
                .map(|(c, i)| svd.u[(i, c)] * svd.s[c])
                .collect();
            let shift = if self.affine {
                mean.clone()
            } else {
                vec![0.0; rows]
            };
            let v = &svd.v;
            let block_sums: Vec<Vec<f64>> = a
                .par_chunks_mut(rows * BLOCK)
                .enumerate()
                .map(|(b, block)| {
                    let mut sum = vec![0.0; if self.affine { rows } else { 0 }];
                    for (j, col) in block.chunks_mut(rows).enumerate() {
                        let p = b * BLOCK + j;
                        col.copy_from_slice(&shift);
                        for c in 0..k {
                            let vc = v[(p, c)];
                            for (x, u) in col.iter_mut().zip(&us[c * rows..(c + 1) * rows]) {
                                *x += u * vc;
                            }
                        }
                        for o in self.col_ptr[p]..self.col_ptr[p + 1] {
                            let f = self.col_frame[o];
                            col[2 * f..2 * f + 2].copy_from_slice(&self.col_w[o]);
                        }
                        for (s, x) in sum.iter_mut().zip(col.iter()) {
                            *s += x;
                        }
                    }
                    sum
                })
                .collect();
            if self.affine {
                mean.fill(0.0);
                for sum in &block_sums {
                    for (m, s) in mean.iter_mut().zip(sum) {
                        *m += s;
                    }
                }
                let inv = 1.0 / n.max(1) as f64;
                mean.iter_mut().for_each(|m| *m *= inv);
                a.par_chunks_mut(rows).for_each(|col| {
                    for (x, m) in col.iter_mut().zip(&mean) {
                        *x -= m;
                    }
                });
            }
        }
    }

    /// Points (r×N) and translation in the output gauge (affine: centred points).
    fn finish(&self, u: &[f64], mu: f64) -> (Mat<f64>, Mat<f64>, Vec<f64>, f64) {
        let ps = self.solve_points(u, mu, 0.0, false);
        let (m, mut t) = self.unpack(u);
        let r = self.rank;
        let mut s = Mat::from_fn(r, self.n_points, |c, p| ps.s[p * r + c]);
        if self.affine && self.n_points > 0 {
            let mean: Vec<f64> = (0..r)
                .map(|c| (0..self.n_points).map(|p| s[(c, p)]).sum::<f64>() / self.n_points as f64)
                .collect();
            for c in 0..r {
                for p in 0..self.n_points {
                    s[(c, p)] -= mean[c];
                }
            }
            for (i, ti) in t.iter_mut().enumerate() {
                *ti += (0..r).map(|c| m[(i, c)] * mean[c]).sum::<f64>();
            }
        }
        (m, s, t, ps.cost)
    }

    /// Emits an iteration event.
    pub(crate) fn emit(
        &self,
        observer: &mut dyn Observer,
        solver: &str,
        run: usize,
        iteration: usize,
        cost: f64,
        lambda: f64,
    ) {
        observer.on_event(&Event::Iteration {
            solver,
            run,
            iteration,
            cost,
            rms: self.rms_of_cost(cost),
            lambda,
        });
    }
}

/// Builds the solver selected by `cfg`.
pub fn solver_for(cfg: &CompletionConfig) -> Box<dyn CompletionSolver> {
    match cfg.solver {
        CompletionSolverKind::Als => Box::new(Als::from_config(cfg)),
        CompletionSolverKind::Wiberg => Box::new(Wiberg::from_config(cfg)),
    }
}

/// Completes a partial measurement matrix with the model, solver and starts of `cfg`,
/// keeping the run with the lowest final cost.
///
/// Errors: [`Error::InvalidConfig`] for a bad configuration, and the input errors of
/// [`CompletionProblem::new`] ([`Error::TooFew`], [`Error::Disconnected`], …; the offending
/// track/frame is named in an [`Event::Warning`]). How the runs ended is in the reports.
///
/// Run `k` uses an RNG seeded with `cfg.seed` and `k` (reproducible). Cost: `runs` times
/// the solver's cost (see the module documentation).
pub fn complete(
    meas: &Measurements,
    cfg: &CompletionConfig,
    observer: &mut dyn Observer,
) -> Result<Completion> {
    complete_impl(meas, cfg, None, observer)
}

/// [`complete`] with its first run started at the given cameras `m0` (2F×r) and
/// translations `t0` (length 2F; ignored by the free model) instead of `cfg.init`: a warm
/// start, e.g. from a neighbouring, overlapping problem already solved. Further runs
/// (`runs > 1`) start at random. The start need not be normalized (orthonormal `M`);
/// the solver's gauge handling does that.
///
/// Errors: those of [`complete`], and [`Error::InvalidConfig`] (field `start`) when the
/// start's shape does not match the measurements or it is not finite.
pub fn complete_with_start(
    meas: &Measurements,
    cfg: &CompletionConfig,
    m0: MatRef<'_, f64>,
    t0: &[f64],
    observer: &mut dyn Observer,
) -> Result<Completion> {
    let rows = 2 * meas.n_frames();
    let finite = (0..m0.ncols()).all(|c| (0..m0.nrows()).all(|r| m0[(r, c)].is_finite()))
        && t0.iter().all(|v| v.is_finite());
    if m0.nrows() != rows || m0.ncols() != cfg.model.rank() || t0.len() != rows || !finite {
        return Err(Error::InvalidConfig {
            field: "start",
            message: format!(
                "the start must be finite, {rows}×{} cameras and {rows} translations; got \
                 {}×{} and {}",
                cfg.model.rank(),
                m0.nrows(),
                m0.ncols(),
                t0.len()
            ),
        });
    }
    complete_impl(meas, cfg, Some((m0, t0)), observer)
}

fn complete_impl(
    meas: &Measurements,
    cfg: &CompletionConfig,
    given: Option<(MatRef<'_, f64>, &[f64])>,
    observer: &mut dyn Observer,
) -> Result<Completion> {
    cfg.validate()?;
    let problem = match CompletionProblem::new_with_culprit(meas, cfg.model) {
        Ok(p) => p,
        Err((e, culprit)) => {
            if let Some(msg) = culprit {
                observer.on_event(&Event::Warning { message: &msg });
            }
            return Err(e);
        }
    };
    // The damped Wiberg solver's Hessian is dense, (2F·q)²: above the memory budget ALS
    // (memory linear in the observations) runs instead, with a warning.
    let n = 2 * problem.n_frames() * problem.q();
    let fallback;
    let cfg = if cfg.solver == CompletionSolverKind::Wiberg
        && crate::budget::matrix_bytes(n, n) > crate::budget::DENSE_MATRIX_BYTES
    {
        let msg = format!(
            "the Wiberg solver would need a dense {n}×{n} matrix ({:.2} GiB, over the {:.2} GiB \
             budget) for {} frames; alternating least squares runs instead",
            crate::budget::matrix_bytes(n, n) as f64 / (1u64 << 30) as f64,
            crate::budget::DENSE_MATRIX_BYTES as f64 / (1u64 << 30) as f64,
            problem.n_frames()
        );
        observer.on_event(&Event::Warning { message: &msg });
        fallback = CompletionConfig {
            solver: CompletionSolverKind::Als,
            ..cfg.clone()
        };
        &fallback
    } else {
        cfg
    };
    let solver = solver_for(cfg);
    // A costly Wiberg iteration: ALS first (see `als_first_flops`).
    let als_first = cfg.solver == CompletionSolverKind::Wiberg
        && problem.wiberg_iteration_flops() > cfg.als_first_flops;
    let mut best_sweeps = 0;
    let mut reports = Vec::with_capacity(cfg.runs);
    let mut best: Option<(usize, Vec<f64>, f64)> = None;
    for run in 0..cfg.runs {
        let start = Instant::now();
        let (m0, t0) = match (given, cfg.init, run) {
            (Some((m, t)), _, 0) => (m.to_owned(), t.to_vec()),
            (None, Init::Auto, 0) => problem.auto_start(cfg.impute_iterations)?,
            _ => {
                let mut rng = StdRng::seed_from_u64(run_seed(cfg.seed, run));
                problem.random_start(&mut rng)
            }
        };
        let (out, sweeps) = if als_first {
            let a = Als::from_config(cfg).solve(&problem, m0.as_ref(), &t0, run, observer);
            let sweeps = a.report.iterations;
            if a.report.status == SolverStatus::Converged {
                let report = SolverReport {
                    iterations: 0,
                    ..a.report
                };
                (CompletionRun { report, ..a }, sweeps)
            } else {
                let mut w = solver.solve(&problem, a.m.as_ref(), &a.t, run, observer);
                w.report.initial_cost = a.report.initial_cost;
                (w, sweeps)
            }
        } else {
            (solver.solve(&problem, m0.as_ref(), &t0, run, observer), 0)
        };
        let mut report = out.report;
        report.seconds = start.elapsed().as_secs_f64();
        let cost = report.final_cost;
        if best.as_ref().is_none_or(|b| cost < b.2 || !b.2.is_finite()) {
            best = Some((run, problem.pack(out.m.as_ref(), &out.t), cost));
            best_sweeps = sweeps;
        }
        reports.push(report);
    }
    let Some((best_run, mut u, _)) = best else {
        return Err(Error::InvalidConfig {
            field: "runs",
            message: "need at least one run".into(),
        });
    };
    problem.normalize(&mut u);
    // Final points: exact least squares (ridge only as a fallback for singular tracks).
    let (m, s, t, cost) = problem.finish(&u, 0.0);
    let mut best_report = reports[best_run].clone();
    best_report.final_cost = cost;
    Ok(Completion {
        m,
        s,
        t,
        model: cfg.model,
        solver: cfg.solver,
        rms: problem.rms_of_cost(cost),
        report: best_report,
        runs: reports,
        best_run,
        als_sweeps_first: best_sweeps,
    })
}

/// Tracks per parallel block of [`CompletionProblem::solve_points`].
const POINT_BLOCK: usize = 256;

/// Seed of run `run` (SplitMix-style mixing of the base seed and the run index).
fn run_seed(seed: u64, run: usize) -> u64 {
    let mut z = seed ^ (run as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Shared end-of-run bookkeeping.
pub(crate) fn report(
    status: SolverStatus,
    iterations: usize,
    initial_cost: f64,
    final_cost: f64,
    start: Instant,
) -> SolverReport {
    SolverReport {
        status,
        iterations,
        initial_cost,
        final_cost,
        seconds: start.elapsed().as_secs_f64(),
    }
}

#[cfg(test)]
mod tests;

/// The hard-impute sweeps of [`CompletionProblem::auto_start`] take the leading subspace
/// from the eigen-decomposition of the filled matrix's Gram matrix
/// ([`crate::svd::leading_by_gram`], `O(rows² N)`, no iteration) when it has at most this
/// many rows (and no more rows than columns), and from the randomized sketch
/// ([`crate::svd::truncated_svd`]) otherwise. The start needs only the leading rank-`r`
/// subspace, not the sketch's accuracy on `σ₄`. Measured (ten sweeps, `auto_start`, 50 %
/// missing, release, 2 vCPUs; docs/results.md): 80 × 1 500 0.092 → 0.015 s, 160 × 3 000
/// 0.22 → 0.077 s, 200 × 5 000 0.39 → 0.17 s, 300 × 5 000 0.46 → 0.33 s, 400 × 5 000
/// 0.57 → 0.52 s, 600 × 5 000 0.69 → 1.12 s (slower).
const GRAM_START_MAX_ROWS: usize = 256;

fn gram_start(rows: usize, n: usize) -> bool {
    rows <= GRAM_START_MAX_ROWS && rows <= n
}
