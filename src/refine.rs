//! Metric refinement: orthographic / scaled-orthographic bundle adjustment by
//! Levenberg–Marquardt with a Schur-complement (reduced camera) solve.
//!
//! Runs after the linear metric upgrade of the Tomasi–Kanade factorization and minimizes the
//! reprojection error of the [`MetricModel`] over the observed entries:
//!
//! ```text
//! min  Σ_{(f,p) observed} ‖ s_f · R_f[rows 0..2] · X_p + t_f − w_fp ‖²
//! over R_f ∈ SO(3), t_f ∈ R², s_f > 0 (scaled orthography only), X_p ∈ R³.
//! ```
//!
//! See [`refine`] for the algorithm and [`fix_gauge`] for re-fixing the gauge afterwards.
//!
//! References: K. Levenberg, "A method for the solution of certain non-linear problems in
//! least squares", Q. Appl. Math. 2, 1944; D. W. Marquardt, "An algorithm for least-squares
//! estimation of nonlinear parameters", SIAM J. Appl. Math. 11(2), 1963; H. B. Nielsen,
//! "Damping parameter in Marquardt's method", IMM-REP-1999-05, DTU, 1999 (damping update);
//! B. Triggs, P. McLauchlan, R. Hartley, A. Fitzgibbon, "Bundle adjustment — a modern
//! synthesis", Vision Algorithms 1999, LNCS 1883 (Schur complement / reduced camera system);
//! C. Tomasi and T. Kanade, IJCV 9(2), 1992; C. J. Poelman and T. Kanade, PAMI 19(3), 1997
//! (camera models).

use std::time::Instant;

use faer::Mat;
use faer::linalg::matmul::triangular::BlockStructure;
use faer::linalg::solvers::Solve;
use nalgebra::{Matrix3, Rotation3, SMatrix, SVector, Vector2, Vector3};

use crate::{
    CameraModel, Error, Event, Measurements, MetricModel, Observer, SolverReport, SolverStatus,
};

/// Maximum number of camera parameters per frame (rotation 3, translation 2, log-scale 1).
const NC: usize = 6;
type M66 = SMatrix<f64, NC, NC>;
type M63 = SMatrix<f64, NC, 3>;
type V6 = SVector<f64, NC>;

/// Smallest damping used (relative, Marquardt scaling); keeps the gauge directions damped.
const MIN_LAMBDA: f64 = 1e-12;
/// Relative floor of the Marquardt scaling diagonal (per parameter type, relative to the
/// largest diagonal entry of that type) so that parameters with a zero diagonal — e.g. the
/// depth of a point seen in one frame — are still damped.
const DIAG_FLOOR_REL: f64 = 1e-10;
/// Absolute floor of the Marquardt scaling diagonal.
const DIAG_FLOOR_ABS: f64 = 1e-12;
/// Upper bound on the entries of one dense chunk in the dense Schur accumulation.
const DENSE_CHUNK_ENTRIES: usize = 1 << 22;

/// Configuration of [`refine`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RefineConfig {
    /// Maximum number of LM iterations (each iteration is one damped linear solve and one
    /// cost evaluation, whether the step is accepted or not). Default 100.
    pub max_iterations: usize,
    /// Converged when an accepted step decreases the cost by less than
    /// `function_tolerance · cost` (relative decrease). Default 1e-12.
    pub function_tolerance: f64,
    /// Converged when an accepted step satisfies `‖δ‖ ≤ parameter_tolerance · (‖x‖ +
    /// parameter_tolerance)`, with `x` the points, translations and log-scales. Default 1e-10.
    pub parameter_tolerance: f64,
    /// Converged when the gradient `Jᵀr` (pixels² per unit parameter) has max-norm at most
    /// this. Default 1e-10.
    pub gradient_tolerance: f64,
    /// Initial damping λ (relative to the diagonal of `JᵀJ`, Marquardt scaling). Default 1e-4.
    pub initial_lambda: f64,
    /// Stalled when λ would exceed this without a successful step. Default 1e12.
    pub max_lambda: f64,
    /// The pipeline skips the refinement when the metric model's RMS exceeds the affine
    /// fit's by less than this fraction of the latter: the affine model contains every
    /// metric one, so its optimum bounds what refining can reach, and the refinement could
    /// not gain more. (It took 57 s of a 77 s run on a 1000 × 20 000 table to move the RMS
    /// by 2·10⁻⁶ px.) 0 always refines. Default 1e-3.
    #[serde(default = "default_min_relative_gain")]
    pub min_relative_gain: f64,
}

fn default_min_relative_gain() -> f64 {
    1e-3
}

impl Default for RefineConfig {
    fn default() -> Self {
        Self {
            max_iterations: 100,
            function_tolerance: 1e-12,
            parameter_tolerance: 1e-10,
            gradient_tolerance: 1e-10,
            initial_lambda: 1e-4,
            max_lambda: 1e12,
            min_relative_gain: default_min_relative_gain(),
        }
    }
}

/// Outcome of [`refine`].
#[derive(Debug, Clone, PartialEq)]
pub struct RefineResult {
    /// How the solver ended; costs are sums of squared residuals (pixels²).
    pub report: SolverReport,
    /// RMS reprojection error over observed scalars before refinement (pixels).
    pub rms_before: f64,
    /// RMS reprojection error over observed scalars after refinement (pixels).
    pub rms_after: f64,
}

/// How the reduced camera matrix `S = U − W V⁻¹ Wᵀ` is accumulated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum SchurMode {
    /// Dense when the observation pattern is dense enough, sparse otherwise.
    Auto,
    /// Blocked dense matrix products (faer GEMM): O((cF)²·3N) flops.
    Dense,
    /// Per-point scatter over pairs of frames: O(Σ_p k_p² · c²·3) flops.
    Sparse,
}

/// Refines a metric reconstruction by Levenberg–Marquardt bundle adjustment.
///
/// **Objective.** `min Σ_{(f,p) observed} ‖s_f R_f[0..2] X_p + t_f − w_fp‖²` over rotations,
/// image translations, scales (only for [`CameraModel::ScaledOrthographic`]; for
/// [`CameraModel::Orthographic`] the scales of `model` are kept fixed — normally all 1) and
/// points. Observed entries are those with `meas.visible` set.
///
/// **Parameterization.** Rotations are updated on the manifold, `R_f ← exp([δ_f]×) R_f`
/// (nalgebra `Rotation3::new(δ_f)`); scales through their logarithm, `s_f ← s_f·exp(δ)`, so
/// they stay positive; translations and points additively. That gives `c = 6` parameters per
/// frame (scaled orthography) or `c = 5` (orthography), and 3 per point.
///
/// **Step.** The damped normal equations `(JᵀJ + λ D) h = −Jᵀr`, with `D` the diagonal of
/// `JᵀJ` floored at a small relative/absolute value (Marquardt's scaling), are solved by
/// eliminating the 3×3 point blocks (Schur complement): the reduced camera system
/// `(U − W V⁻¹ Wᵀ) h_c = −g_c + W V⁻¹ g_x` (cF×cF) is solved densely with faer (Cholesky,
/// falling back to LU; a step whose solve fails or is not finite counts as rejected), then
/// the points by back-substitution. Steps are accepted only if they decrease the cost; λ
/// follows Nielsen's rule (`λ ← λ·max(1/3, 1 − (2ρ−1)³)` on success, `λ ← λ·ν, ν ← 2ν` on
/// failure, with ρ the gain ratio).
///
/// **Gauge.** The global rotation (3), the global 3D translation (3: depth is unobservable
/// under orthography, the other two trade off against `t_f`) and, for scaled orthography,
/// the global scale (1) make `JᵀJ` singular. They are *not* fixed here: the damping keeps the
/// system non-singular and the gradient has no component along them. Call [`fix_gauge`]
/// afterwards. Points seen in fewer than two frames (or from a single viewing direction)
/// stay finite for the same reason.
///
/// **Stopping.** `Converged` when the gradient max-norm, the relative cost decrease of an
/// accepted step or the size of an accepted step falls below its tolerance (or the cost is
/// exactly zero); `MaxIterations` after `cfg.max_iterations` iterations; `Stalled` when λ
/// exceeds `cfg.max_lambda` without a successful step. The cost never increases: `model`
/// holds the best parameters found. Each iteration (accepted or rejected) emits
/// `Event::Iteration { solver: "lm-refine", run: 0, iteration, cost, rms, lambda }` with
/// `iteration` counted from 1, `cost`/`rms` those of the current (best) model after the
/// iteration, and `lambda` the damping used for that iteration's step.
///
/// **Complexity** (per iteration; F frames, N points, `n_obs` observations, `k_p` frames
/// seeing point p, c ∈ {5, 6}):
/// - linearization, cost, point eliminations and back-substitution: O(n_obs·c²);
/// - reduced camera matrix: O(Σ_p k_p²·3c²/2) scattered per point over the pairs of frames
///   that share it (O(Σ_f Σ_{g sharing points with f} …), at most O(F²·N·c²)); when
///   Σ_p k_p² ≥ F²N/4 the same matrix is built with blocked dense GEMM (O((cF)²·3N/2)
///   flops in chunks of bounded memory), the fast path for (nearly) complete data;
/// - reduced solve (dense Cholesky): O((cF)³/3).
///
/// Memory O(n_obs·3c + (cF)²).
///
/// # Errors
/// [`Error::Dimension`] when `meas` and `model` disagree in frames or points or the model's
/// per-frame vectors differ in length; [`Error::InvalidConfig`] for non-finite model
/// parameters or observed measurements, non-positive scales, or an invalid `cfg`.
pub fn refine(
    meas: &Measurements,
    model: &mut MetricModel,
    camera: CameraModel,
    cfg: &RefineConfig,
    observer: &mut dyn Observer,
) -> Result<RefineResult, Error> {
    refine_impl(meas, model, camera, cfg, observer, SchurMode::Auto)
}

/// [`refine`] by the sparse engine ([`crate::projective::bundle`], the scaled orthographic
/// residual of [`crate::sparse::ScaledOrthographic`], each camera pivoted about the points
/// it sees, variable projection): the same objective and parameterization, for tables
/// whose dense `(cF)²` reduced camera matrix would outgrow the observations.
///
/// The engine solves its reduced system by sparse Cholesky or, where that system would be
/// dense (tracks spanning much of a long sequence), by conjugate gradients on its implicit
/// form ([`crate::projective::bundle::LinearSolver::Auto`]). Settings:
/// [`crate::sparse::SparseConfig::default`]'s adjustment with `cfg.max_iterations`. The
/// gauge is held by springs during the solve, not fixed: call [`fix_gauge`] afterwards, as
/// for [`refine`]. Iterations are reported as `Event::Iteration { solver:
/// "sparse-varpro", … }`.
///
/// **Complexity.** `O(n_obs)` per product or linearization (see the engine); memory
/// `O(n_obs + F + N)` on the iterative path, plus the reduced system's non-zeros on the
/// direct one (bounded by a constant times the observations). Nothing is `O(F·N)` beyond
/// `meas` itself, or `O(F²)`.
///
/// # Errors
/// As [`refine`]; [`Error::Numerical`] when the engine cannot analyse the system.
pub fn refine_sparse(
    meas: &Measurements,
    model: &mut MetricModel,
    camera: CameraModel,
    cfg: &RefineConfig,
    observer: &mut dyn Observer,
) -> Result<RefineResult, Error> {
    validate(meas, model, cfg)?;
    let nf = meas.n_frames();
    // The graph in normalized coordinates `(w − c) / σ`, `c` the observations' centroid and
    // `σ` their RMS spread per coordinate (1 for the orthographic camera, whose unit scale
    // is in pixels), as the sparse pipeline normalizes its tables.
    let (centre, scale) = crate::sparse::centre_and_spread(
        || {
            meas.observed_pairs()
                .map(|(f, p)| [meas.w[(2 * f, p)], meas.w[(2 * f + 1, p)]])
        },
        camera != CameraModel::Orthographic,
    );
    let norm = crate::projective::Normalization {
        centre,
        scale: 1.0 / scale,
    };
    let prob = crate::sparse::SparseProblem {
        graph: crate::projective::graph(meas, &norm),
        centre,
        scale,
    };
    // Cameras `[R (9, row-major), s, t (2)]` in normalized units: `s/σ`, `(t − c)/σ`.
    let mut cams = Vec::with_capacity(12 * nf);
    for f in 0..nf {
        let r = model.rotations[f].matrix();
        for i in 0..3 {
            for j in 0..3 {
                cams.push(r[(i, j)]);
            }
        }
        cams.push(model.scales[f] / scale);
        cams.push((model.translations[f][0] - centre[0]) / scale);
        cams.push((model.translations[f][1] - centre[1]) / scale);
    }
    let mut pts: Vec<f64> = model
        .points
        .iter()
        .flat_map(|x| [x[0], x[1], x[2]])
        .collect();
    let n_scalars = 2 * prob.graph.n_obs();
    let rms_of = |cost: f64| {
        if n_scalars == 0 {
            0.0
        } else {
            (cost / n_scalars as f64).sqrt()
        }
    };
    let initial_cost = cost(meas, &Structure::new(meas), model);
    let mut sparse_cfg = crate::sparse::SparseConfig::default();
    sparse_cfg.lm.max_iterations = cfg.max_iterations.max(1);
    let lm = prob.adjust(&mut cams, &mut pts, &sparse_cfg, camera, 0, observer)?;
    let final_cost = lm.report.final_cost * scale * scale;
    // Keep the start when the engine did not improve it (the cost never increases).
    if final_cost.is_finite() && final_cost <= initial_cost {
        for f in 0..nf {
            let c = &cams[12 * f..12 * f + 12];
            let m = Matrix3::from_row_slice(&c[..9]);
            model.rotations[f] = Rotation3::from_matrix_unchecked(m);
            if camera != CameraModel::Orthographic {
                model.scales[f] = c[9] * scale;
            }
            model.translations[f] =
                Vector2::new(c[10] * scale + centre[0], c[11] * scale + centre[1]);
        }
        for (x, p) in model.points.iter_mut().zip(pts.chunks_exact(3)) {
            *x = Vector3::new(p[0], p[1], p[2]);
        }
    }
    let current = cost(meas, &Structure::new(meas), model);
    Ok(RefineResult {
        report: SolverReport {
            status: lm.report.status,
            iterations: lm.report.iterations,
            initial_cost,
            final_cost: current,
            seconds: lm.report.seconds,
        },
        rms_before: rms_of(initial_cost),
        rms_after: rms_of(current),
    })
}

/// Re-fixes the gauge of a metric reconstruction without changing any projection.
///
/// 1. Rotates the world so that frame 0's rotation is the identity:
///    `R_f ← R_f R_0ᵀ`, `X_p ← R_0 X_p`.
/// 2. Translates the points so that their centroid `c` is at the origin, compensating in the
///    image translations: `X_p ← X_p − c`, `t_f ← t_f + s_f R_f[0..2] c`.
/// 3. Scaled orthography only: rescales so that `s_0 = 1`: `X_p ← s_0 X_p`, `s_f ← s_f / s_0`.
///
/// Does nothing for an empty model. Complexity O(F + N).
pub fn fix_gauge(model: &mut MetricModel, camera: CameraModel) {
    if let Some(r0) = model.rotations.first().copied() {
        let r0t = r0.inverse();
        for r in &mut model.rotations {
            *r *= r0t;
        }
        for x in &mut model.points {
            *x = r0 * *x;
        }
    }
    if !model.points.is_empty() {
        let c = model.points.iter().fold(Vector3::zeros(), |acc, x| acc + x)
            / model.points.len() as f64;
        for x in &mut model.points {
            *x -= c;
        }
        for f in 0..model.rotations.len() {
            let rc = model.rotations[f] * c;
            model.translations[f] += model.scales[f] * Vector2::new(rc[0], rc[1]);
        }
    }
    if camera == CameraModel::ScaledOrthographic
        && let Some(&s0) = model.scales.first()
        && s0 > 0.0
        && s0.is_finite()
    {
        for x in &mut model.points {
            *x *= s0;
        }
        for s in &mut model.scales {
            *s /= s0;
        }
    }
}

fn validate(meas: &Measurements, model: &MetricModel, cfg: &RefineConfig) -> Result<(), Error> {
    let f = meas.n_frames();
    let n = meas.n_points();
    let dim = |context: &'static str, expected: usize, got: usize| Error::Dimension {
        context,
        expected: expected.to_string(),
        got: got.to_string(),
    };
    if model.aspect != 1.0 {
        return Err(Error::InvalidConfig {
            field: "aspect",
            message: format!(
                "the refinement works in square pixels (aspect 1), got {}: divide the \
                 measurements' x by the aspect ratio first (Config::aspect_ratio does)",
                model.aspect
            ),
        });
    }
    if model.rotations.len() != f {
        return Err(dim(
            "refine: model rotations vs. measurement frames",
            f,
            model.rotations.len(),
        ));
    }
    if model.translations.len() != f {
        return Err(dim(
            "refine: model translations vs. measurement frames",
            f,
            model.translations.len(),
        ));
    }
    if model.scales.len() != f {
        return Err(dim(
            "refine: model scales vs. measurement frames",
            f,
            model.scales.len(),
        ));
    }
    if model.points.len() != n {
        return Err(dim(
            "refine: model points vs. measurement tracks",
            n,
            model.points.len(),
        ));
    }
    if meas.visible.len() != f * n {
        return Err(dim(
            "refine: visibility mask (F·N)",
            f * n,
            meas.visible.len(),
        ));
    }
    let bad = |field: &'static str, message: String| Err(Error::InvalidConfig { field, message });
    for (i, r) in model.rotations.iter().enumerate() {
        if !r.matrix().iter().all(|v| v.is_finite()) {
            return bad(
                "model.rotations",
                format!("rotation of frame {i} is not finite"),
            );
        }
    }
    for (i, t) in model.translations.iter().enumerate() {
        if !t.iter().all(|v| v.is_finite()) {
            return bad(
                "model.translations",
                format!("translation of frame {i} is not finite"),
            );
        }
    }
    for (i, &s) in model.scales.iter().enumerate() {
        if !(s.is_finite() && s > 0.0) {
            return bad(
                "model.scales",
                format!("scale of frame {i} is {s}; must be finite and > 0"),
            );
        }
    }
    for (i, x) in model.points.iter().enumerate() {
        if !x.iter().all(|v| v.is_finite()) {
            return bad("model.points", format!("point {i} is not finite"));
        }
    }
    for (fi, p) in meas.observed_pairs() {
        if !(meas.w[(2 * fi, p)].is_finite() && meas.w[(2 * fi + 1, p)].is_finite()) {
            return bad(
                "measurements",
                format!("observed entry (frame {fi}, track {p}) is not finite"),
            );
        }
    }
    let nonneg = |v: f64| v.is_finite() && v >= 0.0;
    if !nonneg(cfg.function_tolerance) {
        return bad(
            "function_tolerance",
            format!("{} must be finite and ≥ 0", cfg.function_tolerance),
        );
    }
    if !nonneg(cfg.parameter_tolerance) {
        return bad(
            "parameter_tolerance",
            format!("{} must be finite and ≥ 0", cfg.parameter_tolerance),
        );
    }
    if !nonneg(cfg.gradient_tolerance) {
        return bad(
            "gradient_tolerance",
            format!("{} must be finite and ≥ 0", cfg.gradient_tolerance),
        );
    }
    if !(cfg.initial_lambda.is_finite() && cfg.initial_lambda > 0.0) {
        return bad(
            "initial_lambda",
            format!("{} must be finite and > 0", cfg.initial_lambda),
        );
    }
    if !(cfg.max_lambda.is_finite() && cfg.max_lambda >= cfg.initial_lambda) {
        return bad(
            "max_lambda",
            format!(
                "{} must be finite and ≥ initial_lambda ({})",
                cfg.max_lambda, cfg.initial_lambda
            ),
        );
    }
    Ok(())
}

/// Point-major observation index: frames of point `p` are `frame[start[p]..start[p+1]]`,
/// ascending.
struct Structure {
    start: Vec<usize>,
    frame: Vec<usize>,
}

impl Structure {
    fn new(meas: &Measurements) -> Self {
        let (nf, n) = (meas.n_frames(), meas.n_points());
        let mut start = Vec::with_capacity(n + 1);
        let mut frame = Vec::new();
        start.push(0);
        for p in 0..n {
            for f in 0..nf {
                if meas.visible[f * n + p] {
                    frame.push(f);
                }
            }
            start.push(frame.len());
        }
        Self { start, frame }
    }

    fn n_points(&self) -> usize {
        self.start.len() - 1
    }
}

/// Sum of squared residuals over observed entries.
fn cost(meas: &Measurements, st: &Structure, model: &MetricModel) -> f64 {
    let mut ss = 0.0;
    for p in 0..st.n_points() {
        for &f in &st.frame[st.start[p]..st.start[p + 1]] {
            let q = model.project(f, p);
            let dx = q[0] - meas.w[(2 * f, p)];
            let dy = q[1] - meas.w[(2 * f + 1, p)];
            ss += dx * dx + dy * dy;
        }
    }
    ss
}

/// Undamped normal-equation blocks at the current model.
struct Linearization {
    /// Camera blocks `U_f = Σ_p J_cᵀ J_c` (only the leading c×c part is used).
    u: Vec<M66>,
    /// Camera gradients `Σ_p J_cᵀ r`.
    gc: Vec<V6>,
    /// Point blocks `V_p = Σ_f J_xᵀ J_x`.
    v: Vec<Matrix3<f64>>,
    /// Point gradients `Σ_f J_xᵀ r`.
    gx: Vec<Vector3<f64>>,
    /// Coupling blocks `W_fp = J_cᵀ J_x`, one per observation (point-major order).
    w: Vec<M63>,
}

fn linearize(meas: &Measurements, st: &Structure, model: &MetricModel, c: usize) -> Linearization {
    let nf = model.n_frames();
    let n = st.n_points();
    let mut lin = Linearization {
        u: vec![M66::zeros(); nf],
        gc: vec![V6::zeros(); nf],
        v: vec![Matrix3::zeros(); n],
        gx: vec![Vector3::zeros(); n],
        w: Vec::with_capacity(st.frame.len()),
    };
    for p in 0..n {
        let x = model.points[p];
        for &f in &st.frame[st.start[p]..st.start[p + 1]] {
            let r = model.rotations[f].matrix();
            let s = model.scales[f];
            let y = r * x;
            let res = [
                s * y[0] + model.translations[f][0] - meas.w[(2 * f, p)],
                s * y[1] + model.translations[f][1] - meas.w[(2 * f + 1, p)],
            ];
            // Camera Jacobian rows: d/dδ (left rotation increment), d/dt, d/dlog s.
            let mut jc = SMatrix::<f64, 2, NC>::zeros();
            jc[(0, 1)] = s * y[2];
            jc[(0, 2)] = -s * y[1];
            jc[(1, 0)] = -s * y[2];
            jc[(1, 2)] = s * y[0];
            jc[(0, 3)] = 1.0;
            jc[(1, 4)] = 1.0;
            if c == 6 {
                jc[(0, 5)] = s * y[0];
                jc[(1, 5)] = s * y[1];
            }
            let jx = SMatrix::<f64, 2, 3>::from_fn(|i, j| s * r[(i, j)]);
            let rv = Vector2::new(res[0], res[1]);
            lin.u[f] += jc.transpose() * jc;
            lin.gc[f] += jc.transpose() * rv;
            lin.v[p] += jx.transpose() * jx;
            lin.gx[p] += jx.transpose() * rv;
            lin.w.push(jc.transpose() * jx);
        }
    }
    lin
}

/// Damping diagonals (Marquardt scaling with floors) for cameras and points.
struct Scaling {
    dc: Vec<V6>,
    dx: Vec<Vector3<f64>>,
}

fn scaling(lin: &Linearization, c: usize) -> Scaling {
    let max_c = lin
        .u
        .iter()
        .flat_map(|u| (0..c).map(move |i| u[(i, i)]))
        .fold(0.0f64, f64::max);
    let max_x = lin
        .v
        .iter()
        .flat_map(|v| (0..3).map(move |i| v[(i, i)]))
        .fold(0.0f64, f64::max);
    let floor_c = (DIAG_FLOOR_REL * max_c).max(DIAG_FLOOR_ABS);
    let floor_x = (DIAG_FLOOR_REL * max_x).max(DIAG_FLOOR_ABS);
    Scaling {
        dc: lin
            .u
            .iter()
            .map(|u| V6::from_fn(|i, _| if i < c { u[(i, i)].max(floor_c) } else { 0.0 }))
            .collect(),
        dx: lin
            .v
            .iter()
            .map(|v| Vector3::from_fn(|i, _| v[(i, i)].max(floor_x)))
            .collect(),
    }
}

/// A damped step: camera increments (c per frame, stored in V6) and point increments.
struct Step {
    hc: Vec<V6>,
    hx: Vec<Vector3<f64>>,
}

/// Lower-triangular inverse of a damped 3×3 point block's Cholesky factor, so that
/// `V*⁻¹ = Lᵀ⁻¹ L⁻¹ = Linvᵀ Linv`.
fn point_linv(v: &Matrix3<f64>, d: &Vector3<f64>, lambda: f64) -> Option<Matrix3<f64>> {
    let mut vd = *v;
    for i in 0..3 {
        vd[(i, i)] += lambda * d[i];
    }
    let mut extra = 0.0;
    for _ in 0..4 {
        let mut m = vd;
        for i in 0..3 {
            m[(i, i)] += extra;
        }
        if let Some(ch) = m.cholesky()
            && let Some(linv) = ch.l().try_inverse()
            && linv.iter().all(|x| x.is_finite())
        {
            return Some(linv);
        }
        extra = if extra == 0.0 {
            1e-12 * vd.trace().abs().max(1e-300)
        } else {
            extra * 1e3
        };
    }
    None
}

/// Solves the damped normal equations by the Schur complement on the point blocks.
/// Returns `None` when a linear solve fails or produces non-finite values.
fn solve_step(
    st: &Structure,
    lin: &Linearization,
    sc: &Scaling,
    lambda: f64,
    c: usize,
    mode: SchurMode,
) -> Option<Step> {
    let nf = lin.u.len();
    let n = st.n_points();
    let dim = c * nf;

    // Per point: Linv_p, z_p = Linv_p g_x; per observation: B_fp = W_fp Linv_pᵀ.
    let mut linv = Vec::with_capacity(n);
    let mut z = Vec::with_capacity(n);
    let mut b = Vec::with_capacity(st.frame.len());
    for p in 0..n {
        let li = point_linv(&lin.v[p], &sc.dx[p], lambda)?;
        b.extend(
            lin.w[st.start[p]..st.start[p + 1]]
                .iter()
                .map(|wk| wk * li.transpose()),
        );
        z.push(li * lin.gx[p]);
        linv.push(li);
    }

    // Reduced camera matrix S (full symmetric) and right-hand side.
    let mut s = Mat::<f64>::zeros(dim, dim);
    let mode = match mode {
        SchurMode::Auto => {
            let pairs: f64 = (0..n)
                .map(|p| ((st.start[p + 1] - st.start[p]) as f64).powi(2))
                .sum();
            if pairs >= 0.25 * (nf as f64).powi(2) * n as f64 {
                SchurMode::Dense
            } else {
                SchurMode::Sparse
            }
        }
        m => m,
    };
    if mode == SchurMode::Dense {
        let chunk = (DENSE_CHUNK_ENTRIES / (3 * dim.max(1))).max(1);
        let par = faer::get_global_parallelism();
        let mut p0 = 0;
        while p0 < n {
            let p1 = (p0 + chunk).min(n);
            let mut bc = Mat::<f64>::zeros(dim, 3 * (p1 - p0));
            for p in p0..p1 {
                let (k0, k1) = (st.start[p], st.start[p + 1]);
                for (bk, &f) in b[k0..k1].iter().zip(&st.frame[k0..k1]) {
                    for i in 0..c {
                        for j in 0..3 {
                            bc[(c * f + i, 3 * (p - p0) + j)] = bk[(i, j)];
                        }
                    }
                }
            }
            // Lower triangle only: S −= B Bᵀ.
            faer::linalg::matmul::triangular::matmul(
                s.as_mut(),
                BlockStructure::TriangularLower,
                faer::Accum::Add,
                bc.as_ref(),
                BlockStructure::Rectangular,
                bc.transpose(),
                BlockStructure::Rectangular,
                -1.0,
                par,
            );
            p0 = p1;
        }
    } else {
        // Lower block triangle (frame fb ≥ fa).
        for p in 0..n {
            let (k0, k1) = (st.start[p], st.start[p + 1]);
            for kb in k0..k1 {
                let fb = st.frame[kb];
                for ka in k0..=kb {
                    let fa = st.frame[ka];
                    let blk = b[kb] * b[ka].transpose();
                    for i in 0..c {
                        for j in 0..c {
                            s[(c * fb + i, c * fa + j)] -= blk[(i, j)];
                        }
                    }
                }
            }
        }
    }
    let mut rhs = Mat::<f64>::zeros(dim, 1);
    for f in 0..nf {
        for i in 0..c {
            for j in 0..c {
                s[(c * f + i, c * f + j)] += lin.u[f][(i, j)];
            }
            s[(c * f + i, c * f + i)] += lambda * sc.dc[f][i];
            rhs[(c * f + i, 0)] = -lin.gc[f][i];
        }
    }
    for (p, zp) in z.iter().enumerate() {
        let (k0, k1) = (st.start[p], st.start[p + 1]);
        for (bk, &f) in b[k0..k1].iter().zip(&st.frame[k0..k1]) {
            let add = bk * zp;
            for i in 0..c {
                rhs[(c * f + i, 0)] += add[i];
            }
        }
    }
    // Mirror the lower triangle (the LU fallback reads the full matrix).
    for col in 0..dim {
        for row in col + 1..dim {
            s[(col, row)] = s[(row, col)];
        }
    }

    let sol = match s.llt(faer::Side::Lower) {
        Ok(llt) => llt.solve(&rhs),
        Err(_) => s.partial_piv_lu().solve(&rhs),
    };
    if !(0..dim).all(|i| sol[(i, 0)].is_finite()) {
        return None;
    }
    let hc: Vec<V6> = (0..nf)
        .map(|f| V6::from_fn(|i, _| if i < c { sol[(c * f + i, 0)] } else { 0.0 }))
        .collect();

    // Back-substitution: h_x = V*⁻¹ (−g_x − Σ_f W_fpᵀ h_c,f).
    let mut hx = Vec::with_capacity(n);
    for (p, li) in linv.iter().enumerate() {
        let mut acc = -lin.gx[p];
        let (k0, k1) = (st.start[p], st.start[p + 1]);
        for (wk, &f) in lin.w[k0..k1].iter().zip(&st.frame[k0..k1]) {
            acc -= wk.transpose() * hc[f];
        }
        let h = li.transpose() * (li * acc);
        if !h.iter().all(|v| v.is_finite()) {
            return None;
        }
        hx.push(h);
    }
    Some(Step { hc, hx })
}

fn apply_step(model: &MetricModel, step: &Step, c: usize) -> MetricModel {
    let mut out = model.clone();
    for (f, h) in step.hc.iter().enumerate() {
        let delta = Vector3::new(h[0], h[1], h[2]);
        out.rotations[f] = Rotation3::new(delta) * out.rotations[f];
        out.translations[f] += Vector2::new(h[3], h[4]);
        if c == 6 {
            out.scales[f] *= h[5].exp();
        }
    }
    for (x, h) in out.points.iter_mut().zip(&step.hx) {
        *x += h;
    }
    out
}

fn refine_impl(
    meas: &Measurements,
    model: &mut MetricModel,
    camera: CameraModel,
    cfg: &RefineConfig,
    observer: &mut dyn Observer,
    mode: SchurMode,
) -> Result<RefineResult, Error> {
    validate(meas, model, cfg)?;
    let start = Instant::now();
    let c = match camera {
        CameraModel::Orthographic => 5,
        CameraModel::ScaledOrthographic
        | CameraModel::Projective
        | CameraModel::Perspective
        | CameraModel::Auto => 6,
    };
    let st = Structure::new(meas);
    let n_scalars = 2 * st.frame.len();
    let rms_of = |cost: f64| {
        if n_scalars == 0 {
            0.0
        } else {
            (cost / n_scalars as f64).sqrt()
        }
    };

    let initial_cost = cost(meas, &st, model);
    let mut current = initial_cost;
    let mut lambda = cfg.initial_lambda;
    let mut nu = 2.0;
    let mut iterations = 0;
    let mut status = SolverStatus::MaxIterations;
    let mut lin = linearize(meas, &st, model, c);
    let mut sc = scaling(&lin, c);
    let grad_small = |lin: &Linearization| {
        let gmax = lin
            .gc
            .iter()
            .flat_map(|g| g.iter().take(c).copied())
            .chain(lin.gx.iter().flat_map(|g| g.iter().copied()))
            .fold(0.0f64, |m, v| m.max(v.abs()));
        gmax <= cfg.gradient_tolerance
    };

    if current == 0.0 || grad_small(&lin) {
        status = SolverStatus::Converged;
    } else {
        while iterations < cfg.max_iterations {
            iterations += 1;
            let lambda_used = lambda;
            let mut accepted = false;
            let mut converged = false;
            if let Some(step) = solve_step(&st, &lin, &sc, lambda, c, mode) {
                // Predicted decrease of ‖r‖²: hᵀ(λ D h − g).
                let mut predicted = 0.0;
                for f in 0..step.hc.len() {
                    for i in 0..c {
                        let h = step.hc[f][i];
                        predicted += h * (lambda * sc.dc[f][i] * h - lin.gc[f][i]);
                    }
                }
                for p in 0..step.hx.len() {
                    for i in 0..3 {
                        let h = step.hx[p][i];
                        predicted += h * (lambda * sc.dx[p][i] * h - lin.gx[p][i]);
                    }
                }
                let candidate = apply_step(model, &step, c);
                let new_cost = cost(meas, &st, &candidate);
                if new_cost.is_finite() && new_cost < current {
                    accepted = true;
                    let rho = if predicted > 0.0 {
                        (current - new_cost) / predicted
                    } else {
                        1.0
                    };
                    let rel_decrease = (current - new_cost) / current;
                    let step_norm = step
                        .hc
                        .iter()
                        .map(|h| h.norm_squared())
                        .chain(step.hx.iter().map(|h| h.norm_squared()))
                        .sum::<f64>()
                        .sqrt();
                    let mut x_sq: f64 = candidate
                        .points
                        .iter()
                        .map(|x| x.norm_squared())
                        .chain(candidate.translations.iter().map(|t| t.norm_squared()))
                        .sum();
                    if c == 6 {
                        x_sq += candidate.scales.iter().map(|s| s.ln().powi(2)).sum::<f64>();
                    }
                    let x_norm = x_sq.sqrt();
                    *model = candidate;
                    current = new_cost;
                    lambda = (lambda * (1.0f64 / 3.0).max(1.0 - (2.0 * rho - 1.0).powi(3)))
                        .max(MIN_LAMBDA);
                    nu = 2.0;
                    lin = linearize(meas, &st, model, c);
                    sc = scaling(&lin, c);
                    converged = current == 0.0
                        || rel_decrease <= cfg.function_tolerance
                        || step_norm
                            <= cfg.parameter_tolerance * (x_norm + cfg.parameter_tolerance)
                        || grad_small(&lin);
                }
            }
            if !accepted {
                lambda *= nu;
                nu *= 2.0;
            }
            observer.on_event(&Event::Iteration {
                solver: "lm-refine",
                run: 0,
                iteration: iterations,
                cost: current,
                rms: rms_of(current),
                lambda: lambda_used,
            });
            if converged {
                status = SolverStatus::Converged;
                break;
            }
            if !accepted && lambda > cfg.max_lambda {
                status = SolverStatus::Stalled;
                break;
            }
        }
    }

    Ok(RefineResult {
        report: SolverReport {
            status,
            iterations,
            initial_cost,
            final_cost: current,
            seconds: start.elapsed().as_secs_f64(),
        },
        rms_before: rms_of(initial_cost),
        rms_after: rms_of(current),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::NoopObserver;
    use rand::prelude::*;
    use rand_distr::{Distribution, Normal};

    /// Ground-truth scene: points in a ±100 px cube, F frames with random (or turntable)
    /// rotations, translations around (320, 240), and scales in [0.8, 1.2] for the scaled
    /// model.
    fn scene(
        rng: &mut StdRng,
        nf: usize,
        n: usize,
        camera: CameraModel,
        turntable: bool,
    ) -> MetricModel {
        let rotations = (0..nf)
            .map(|f| {
                if turntable {
                    let tilt = Rotation3::from_axis_angle(&Vector3::x_axis(), 0.3);
                    let yaw =
                        Rotation3::from_axis_angle(&Vector3::y_axis(), 1.5 * f as f64 / nf as f64);
                    tilt * yaw
                } else {
                    let axis = Vector3::new(
                        rng.random_range(-1.0..1.0),
                        rng.random_range(-1.0..1.0),
                        rng.random_range(-1.0..1.0),
                    );
                    Rotation3::new(axis * 1.5)
                }
            })
            .collect();
        let translations = (0..nf)
            .map(|_| {
                Vector2::new(
                    320.0 + rng.random_range(-50.0..50.0),
                    240.0 + rng.random_range(-50.0..50.0),
                )
            })
            .collect();
        let scales = (0..nf)
            .map(|_| match camera {
                CameraModel::Orthographic => 1.0,
                CameraModel::ScaledOrthographic
                | CameraModel::Projective
                | CameraModel::Perspective
                | CameraModel::Auto => rng.random_range(0.8..1.2),
            })
            .collect();
        let points = (0..n)
            .map(|_| {
                Vector3::new(
                    rng.random_range(-100.0..100.0),
                    rng.random_range(-100.0..100.0),
                    rng.random_range(-100.0..100.0),
                )
            })
            .collect();
        MetricModel {
            rotations,
            translations,
            scales,
            points,
            aspect: 1.0,
        }
    }

    /// Measurements of `truth` with Gaussian noise `sigma`, each entry visible with
    /// probability `p_visible`.
    fn observe(rng: &mut StdRng, truth: &MetricModel, sigma: f64, p_visible: f64) -> Measurements {
        let (nf, n) = (truth.n_frames(), truth.n_points());
        let noise = Normal::new(0.0, sigma.max(1e-300)).unwrap();
        let mut w = truth.predict();
        if sigma > 0.0 {
            for r in 0..2 * nf {
                for p in 0..n {
                    w[(r, p)] += noise.sample(rng);
                }
            }
        }
        let visible = (0..nf * n)
            .map(|_| rng.random::<f64>() < p_visible)
            .collect();
        Measurements::new(w, visible)
    }

    /// Perturbs rotations by ~`deg`°, points by ~3 px (3 % of the scene size), translations by
    /// ~2 px and (scaled model) scales by ~2 %.
    fn perturb(
        rng: &mut StdRng,
        truth: &MetricModel,
        deg: f64,
        camera: CameraModel,
    ) -> MetricModel {
        let g = Normal::new(0.0, 1.0).unwrap();
        let mut m = truth.clone();
        for r in &mut m.rotations {
            let axis = Vector3::new(g.sample(rng), g.sample(rng), g.sample(rng)).normalize();
            *r = Rotation3::new(axis * deg.to_radians()) * *r;
        }
        for x in &mut m.points {
            *x += Vector3::new(g.sample(rng), g.sample(rng), g.sample(rng)) * 3.0;
        }
        for t in &mut m.translations {
            *t += Vector2::new(g.sample(rng), g.sample(rng)) * 2.0;
        }
        if camera == CameraModel::ScaledOrthographic {
            for s in &mut m.scales {
                *s *= 1.0 + 0.02 * g.sample(rng);
            }
        }
        m
    }

    #[derive(Default)]
    struct Recorder {
        events: Vec<(usize, f64, f64, f64)>,
    }

    impl Observer for Recorder {
        fn on_event(&mut self, e: &Event<'_>) {
            if let Event::Iteration {
                solver,
                run,
                iteration,
                cost,
                rms,
                lambda,
            } = e
            {
                assert_eq!(*solver, "lm-refine");
                assert_eq!(*run, 0);
                self.events.push((*iteration, *cost, *rms, *lambda));
            }
        }
    }

    #[test]
    fn noise_free_orthographic_converges_to_zero() {
        let mut rng = StdRng::seed_from_u64(1);
        let cam = CameraModel::Orthographic;
        let truth = scene(&mut rng, 20, 120, cam, true);
        let meas = observe(&mut rng, &truth, 0.0, 0.85);
        let mut model = perturb(&mut rng, &truth, 5.0, cam);
        let res = refine(
            &meas,
            &mut model,
            cam,
            &RefineConfig::default(),
            &mut NoopObserver,
        )
        .unwrap();
        assert!(
            res.rms_before > 1.0,
            "perturbation too small: {}",
            res.rms_before
        );
        assert!(res.rms_after < 1e-9, "rms after {}", res.rms_after);
        assert_eq!(res.report.status, SolverStatus::Converged);
        assert!((model.rms(&meas) - res.rms_after).abs() < 1e-12);
        assert!(res.report.final_cost <= res.report.initial_cost);
    }

    #[test]
    fn noisy_scaled_reaches_noise_floor() {
        let mut rng = StdRng::seed_from_u64(2);
        let cam = CameraModel::ScaledOrthographic;
        let (nf, n, sigma) = (20, 150, 0.5);
        let truth = scene(&mut rng, nf, n, cam, false);
        let meas = observe(&mut rng, &truth, sigma, 0.8);
        let mut model = perturb(&mut rng, &truth, 5.0, cam);
        let res = refine(
            &meas,
            &mut model,
            cam,
            &RefineConfig::default(),
            &mut NoopObserver,
        )
        .unwrap();
        assert!(res.rms_after <= res.rms_before);
        // The truth is a feasible point, so the optimum is at least as good.
        let truth_cost = truth.rms(&meas).powi(2) * 2.0 * meas.n_observed() as f64;
        assert!(res.report.final_cost <= truth_cost * (1.0 + 1e-9));
        // Expected RMS at the optimum: σ·sqrt((m − n_eff)/m), with m observed scalars and
        // n_eff = c·F + Σ_p min(3, 2 k_p) − 7 (gauge: rotation 3, translation 3, scale 1).
        // cost/σ² ~ χ²(m − n_eff), so the RMS has relative sd ≈ 1/sqrt(2(m − n_eff)) ≈ 1 %;
        // ±5 % is a ~5 sd band.
        let m = 2 * meas.n_observed();
        let n_eff: usize = 6 * nf
            + (0..n)
                .map(|p| (2 * (0..nf).filter(|&f| meas.is_visible(f, p)).count()).min(3))
                .sum::<usize>()
            - 7;
        let expected = sigma * ((m - n_eff) as f64 / m as f64).sqrt();
        assert!(
            (res.rms_after / expected - 1.0).abs() < 0.05,
            "rms {} vs expected {expected}",
            res.rms_after
        );
    }

    /// Every frame's scale relative to frame 0's is the truth's, to 1e-6.
    fn assert_scale_ratios(model: &MetricModel, truth: &MetricModel) {
        for f in 0..truth.n_frames() {
            let got = model.scales[f] / model.scales[0];
            let want = truth.scales[f] / truth.scales[0];
            assert!((got - want).abs() < 1e-6, "frame {f}: {got} vs {want}");
        }
    }

    /// Noise-free, the dense refinement and the sparse engine's fit exactly and recover the
    /// truth's scale ratios.
    #[test]
    fn scaled_recovers_scale_ratios() {
        let mut rng = StdRng::seed_from_u64(3);
        let cam = CameraModel::ScaledOrthographic;
        let truth = scene(&mut rng, 15, 80, cam, false);
        let meas = observe(&mut rng, &truth, 0.0, 0.9);
        let start = perturb(&mut rng, &truth, 5.0, cam);
        for (sparse, tol) in [(false, 1e-9), (true, 1e-8)] {
            let mut model = start.clone();
            let cfg = RefineConfig::default();
            let res = if sparse {
                refine_sparse(&meas, &mut model, cam, &cfg, &mut NoopObserver)
            } else {
                refine(&meas, &mut model, cam, &cfg, &mut NoopObserver)
            }
            .unwrap();
            assert!(
                res.rms_after < tol,
                "sparse {sparse}: rms after {}",
                res.rms_after
            );
            assert_scale_ratios(&model, &truth);
        }
    }

    #[test]
    fn dense_and_sparse_schur_agree() {
        let mut rng = StdRng::seed_from_u64(4);
        let cam = CameraModel::ScaledOrthographic;
        let truth = scene(&mut rng, 10, 40, cam, false);
        let meas = observe(&mut rng, &truth, 0.5, 0.7);
        let start = perturb(&mut rng, &truth, 5.0, cam);
        let cfg = RefineConfig {
            max_iterations: 5,
            ..Default::default()
        };
        let mut a = start.clone();
        let mut b = start.clone();
        let ra = refine_impl(
            &meas,
            &mut a,
            cam,
            &cfg,
            &mut NoopObserver,
            SchurMode::Dense,
        )
        .unwrap();
        let rb = refine_impl(
            &meas,
            &mut b,
            cam,
            &cfg,
            &mut NoopObserver,
            SchurMode::Sparse,
        )
        .unwrap();
        assert_eq!(ra.report.iterations, rb.report.iterations);
        assert!((ra.report.final_cost - rb.report.final_cost).abs() <= 1e-9 * ra.report.final_cost);
        let (pa, pb) = (a.predict(), b.predict());
        for r in 0..pa.nrows() {
            for p in 0..pa.ncols() {
                assert!((pa[(r, p)] - pb[(r, p)]).abs() < 1e-6);
            }
        }
    }

    /// The sparse engine's refinement reaches the dense one's optimum (the same objective),
    /// for both camera models, on noisy partial tables (noise-free: `scaled_recovers_scale_ratios`).
    #[test]
    fn the_sparse_engine_refinement_reaches_the_dense_optimum() {
        for (seed, cam) in [
            (21, CameraModel::ScaledOrthographic),
            (22, CameraModel::Orthographic),
        ] {
            let mut rng = StdRng::seed_from_u64(seed);
            let truth = scene(&mut rng, 20, 120, cam, false);
            let meas = observe(&mut rng, &truth, 0.5, 0.8);
            let start = perturb(&mut rng, &truth, 3.0, cam);
            let (mut a, mut b) = (start.clone(), start.clone());
            let cfg = RefineConfig::default();
            let ra = refine(&meas, &mut a, cam, &cfg, &mut NoopObserver).unwrap();
            let rb = refine_sparse(&meas, &mut b, cam, &cfg, &mut NoopObserver).unwrap();
            assert!(
                ra.rms_after > 0.3 && ra.rms_after < 0.6,
                "{cam:?}: {}",
                ra.rms_after
            );
            assert!(
                (ra.rms_after - rb.rms_after).abs() <= 1e-6 * ra.rms_after,
                "{cam:?}: dense {} vs sparse {}",
                ra.rms_after,
                rb.rms_after
            );
            assert!((rb.rms_before - ra.rms_before).abs() <= 1e-12 * ra.rms_before);
            let (pa, pb) = (a.predict(), b.predict());
            for (f, p) in meas.observed_pairs() {
                for r in [2 * f, 2 * f + 1] {
                    assert!((pa[(r, p)] - pb[(r, p)]).abs() < 1e-3, "{cam:?} ({f}, {p})");
                }
            }
            if cam == CameraModel::Orthographic {
                assert!(b.scales.iter().all(|&s| s == 1.0));
            }
        }
    }

    #[test]
    fn degenerate_points_stay_finite() {
        let mut rng = StdRng::seed_from_u64(5);
        let cam = CameraModel::Orthographic;
        let truth = scene(&mut rng, 12, 60, cam, true);
        let mut meas = observe(&mut rng, &truth, 0.5, 0.9);
        // Point 0 seen in one frame only, point 1 in none.
        let n = meas.n_points();
        for f in 0..meas.n_frames() {
            meas.visible[f * n] = f == 3;
            meas.visible[f * n + 1] = false;
        }
        let mut model = perturb(&mut rng, &truth, 3.0, cam);
        let res = refine(
            &meas,
            &mut model,
            cam,
            &RefineConfig::default(),
            &mut NoopObserver,
        )
        .unwrap();
        assert!(model.points.iter().all(|x| x.iter().all(|v| v.is_finite())));
        assert!(res.rms_after <= res.rms_before);
        assert!(res.rms_after < 0.6, "rms {}", res.rms_after);
    }

    #[test]
    fn dimension_mismatch_and_bad_parameters_are_errors() {
        let mut rng = StdRng::seed_from_u64(6);
        let cam = CameraModel::ScaledOrthographic;
        let truth = scene(&mut rng, 5, 10, cam, false);
        let meas = observe(&mut rng, &truth, 0.0, 1.0);
        let cfg = RefineConfig::default();
        let run = |m: &mut MetricModel| refine(&meas, m, cam, &cfg, &mut NoopObserver);

        let mut m = truth.clone();
        m.points.pop();
        assert!(matches!(run(&mut m), Err(Error::Dimension { .. })));
        let mut m = truth.clone();
        m.rotations.pop();
        assert!(matches!(run(&mut m), Err(Error::Dimension { .. })));
        let mut m = truth.clone();
        m.scales.push(1.0);
        assert!(matches!(run(&mut m), Err(Error::Dimension { .. })));
        let mut m = truth.clone();
        m.scales[2] = -1.0;
        assert!(matches!(
            run(&mut m),
            Err(Error::InvalidConfig {
                field: "model.scales",
                ..
            })
        ));
        let mut m = truth.clone();
        m.points[3][1] = f64::NAN;
        assert!(matches!(
            run(&mut m),
            Err(Error::InvalidConfig {
                field: "model.points",
                ..
            })
        ));
        let bad_cfg = RefineConfig {
            initial_lambda: 0.0,
            ..Default::default()
        };
        let mut m = truth.clone();
        assert!(matches!(
            refine(&meas, &mut m, cam, &bad_cfg, &mut NoopObserver),
            Err(Error::InvalidConfig {
                field: "initial_lambda",
                ..
            })
        ));
        // Failed validation leaves the model untouched.
        assert_eq!(m, truth);
    }

    #[test]
    fn observer_sees_non_increasing_cost() {
        let mut rng = StdRng::seed_from_u64(7);
        let cam = CameraModel::ScaledOrthographic;
        let truth = scene(&mut rng, 12, 60, cam, false);
        let meas = observe(&mut rng, &truth, 0.5, 0.8);
        let mut model = perturb(&mut rng, &truth, 5.0, cam);
        let mut rec = Recorder::default();
        let res = refine(&meas, &mut model, cam, &RefineConfig::default(), &mut rec).unwrap();
        assert_eq!(rec.events.len(), res.report.iterations);
        assert!(!rec.events.is_empty());
        let mut prev = res.report.initial_cost;
        for (k, &(it, c, rms, lambda)) in rec.events.iter().enumerate() {
            assert_eq!(it, k + 1);
            assert!(c <= prev, "cost increased at iteration {it}: {prev} -> {c}");
            assert!(lambda > 0.0);
            assert!((rms - (c / (2 * meas.n_observed()) as f64).sqrt()).abs() < 1e-12);
            prev = c;
        }
        assert_eq!(prev, res.report.final_cost);
        assert!(res.report.final_cost < res.report.initial_cost);
    }

    #[test]
    fn max_iterations_is_reported() {
        let mut rng = StdRng::seed_from_u64(8);
        let cam = CameraModel::Orthographic;
        let truth = scene(&mut rng, 10, 40, cam, false);
        let meas = observe(&mut rng, &truth, 0.5, 1.0);
        let mut model = perturb(&mut rng, &truth, 10.0, cam);
        let cfg = RefineConfig {
            max_iterations: 2,
            ..Default::default()
        };
        let res = refine(&meas, &mut model, cam, &cfg, &mut NoopObserver).unwrap();
        assert_eq!(res.report.status, SolverStatus::MaxIterations);
        assert_eq!(res.report.iterations, 2);
    }

    #[test]
    fn fix_gauge_keeps_projections() {
        let mut rng = StdRng::seed_from_u64(9);
        for cam in [CameraModel::Orthographic, CameraModel::ScaledOrthographic] {
            let mut model = scene(&mut rng, 8, 30, cam, false);
            for s in &mut model.scales {
                *s *= 1.7;
            }
            let before = model.predict();
            fix_gauge(&mut model, cam);
            let after = model.predict();
            for r in 0..before.nrows() {
                for p in 0..before.ncols() {
                    assert!((before[(r, p)] - after[(r, p)]).abs() < 1e-9);
                }
            }
            assert!((model.rotations[0].matrix() - Matrix3::identity()).norm() < 1e-12);
            let c: Vector3<f64> =
                model.points.iter().sum::<Vector3<f64>>() / model.n_points() as f64;
            assert!(c.norm() < 1e-9);
            if cam == CameraModel::ScaledOrthographic {
                assert!((model.scales[0] - 1.0).abs() < 1e-15);
            } else {
                assert!((model.scales[0] - 1.7).abs() < 1e-15);
            }
        }
    }
}
