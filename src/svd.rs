//! Truncated SVD: the `k` leading singular triplets of a dense matrix.
//!
//! rank3 only needs the three leading singular triplets of the (centred) observation
//! matrix `W` (2F×N) plus `σ₄` for the rank diagnostic `σ₄/σ₃`. A full thin SVD costs
//! `O(mn·min(m,n))` (8.4 s for 2000×5000 on one core); a randomized block-Krylov sketch
//! needs a few matrix products with `k + p` columns (≈0.1 s).
//!
//! # Objective
//!
//! Find `U_k` (m×k), `V_k` (n×k) with orthonormal columns and `σ₁ ≥ … ≥ σ_k ≥ 0` such that
//! `A ≈ U_k diag(σ) V_kᵀ` is the best rank-`k` approximation of `A` (Eckart–Young), i.e.
//! each `(σᵢ, uᵢ, vᵢ)` is a singular triplet of `A`: `A vᵢ = σᵢ uᵢ`, `Aᵀ uᵢ = σᵢ vᵢ`.
//!
//! # Method (randomized block Krylov + Rayleigh–Ritz)
//!
//! With block size `l = k + p` (`p` = [`TruncatedSvdConfig::oversampling`]) and a
//! Gaussian test matrix `Ω` (n×l, seeded from [`TruncatedSvdConfig::seed`]):
//!
//! 1. `Q₀ = orth(A Ω)` (Householder QR).
//! 2. For `j = 0, 1, …`: `Yⱼ = Aᵀ Qⱼ`; Rayleigh–Ritz on `span[Q₀ … Qⱼ]`: since
//!    `B = [Q₀ … Qⱼ]ᵀ A = [Y₀ … Yⱼ]ᵀ` is already known, take the thin SVD
//!    `B = Ũ Σ Ṽᵀ` and set `U = Q Ũ`, `V = Ṽ`. Check accuracy (below); if not yet
//!    accurate, the next block is `Qⱼ₊₁ = orth((I − QQᵀ) A Yⱼ)` (block Gram–Schmidt applied
//!    twice, then QR, then once more), i.e. the Krylov space
//!    `K = span[AΩ, (AAᵀ)AΩ, …, (AAᵀ)^q AΩ]`.
//!
//! This is the block Krylov method of C. Musco and C. Musco, "Randomized block Krylov
//! methods for stronger and faster approximate singular value decomposition", NeurIPS 2015
//! (Algorithm 2), built on the randomized range finder of N. Halko, P.-G. Martinsson and
//! J. A. Tropp, "Finding structure with randomness", SIAM Review 53(2), 2011 (Alg. 4.4 is
//! the subspace-iteration variant, available as [`SketchScheme::SubspaceIteration`]). Block
//! Krylov is the default because its Ritz values converge gap-independently
//! (Musco & Musco Thm. 1: per-vector error `|uᵢᵀAAᵀuᵢ − σᵢ²| ≤ ε σ²_{k+1}` after
//! `q = O(log n / √ε)` iterations), which matters for `σ₄` of a rank-3-plus-noise `W`:
//! `σ₄` sits at the edge of the noise bulk with almost no gap to `σ₅`.
//!
//! # Accuracy check
//!
//! By construction `Aᵀuᵢ = σᵢvᵢ` exactly (up to rounding), so the residual of a triplet is
//! `rᵢ = ‖A vᵢ − σᵢ uᵢ‖`, an extra `A V_k` product per check (`O(mnk)`). A triplet with
//! residual `rᵢ` is an exact singular triplet of some `A + E` with `‖E‖₂ ≤ rᵢ` (backward
//! error), `A` has a singular value within `rᵢ` of `σᵢ`, and the angle between `vᵢ` (resp.
//! the leading subspace ending at a gap) and the true one is at most `≈ rᵢ / gap`
//! (Wedin's sinΘ theorem). The iteration stops when every one of the `k` triplets meets
//!
//! `rᵢ ≤ tol · σ₁`  **or**  (`σᵢ / σᵢ₊₁ < min_gap` **and** `êᵢ ≤ cluster_tol · σᵢ`),
//!
//! where ratios use the Ritz values and `êᵢ` is an Aitken-type estimate of the remaining
//! error of the Ritz value from its last three iterates (`Δⱼ ρ/(1−ρ)`, `ρ = Δⱼ/Δⱼ₋₁`).
//! So a triplet separated from its successor must be resolved as a vector (`tol`
//! relative to `‖A‖`), while a triplet inside a cluster — whose singular *vector* is
//! ill-conditioned for any method, thin SVD included — only needs an accurate singular
//! *value*. The Ritz values of nested Krylov spaces increase monotonically towards the
//! true ones (Cauchy interlacing), so they are lower bounds. This is what makes `k = 4`
//! on a rank-3-plus-noise `W` work: `σ₁..σ₃` and their vectors converge to machine
//! precision within 1–2 iterations (gap `σ₃/σ₄ ≫ 1`), while `σ₄` lies at the edge of the
//! noise bulk (`σ₄/σ₅ ≈ 1.003` for 2000×5000) and converges slowly (≈ 10 iterations to
//! `1e-3`). The guarantee for vectors: for every `j ≤ k` with a gap `σⱼ/σⱼ₊₁ ≥ min_gap`
//! the leading-`j` subspaces are accurate to `≈ tol·σ₁ / (σⱼ − σⱼ₊₁)`.
//!
//! If the check still fails after [`TruncatedSvdConfig::max_power_iterations`] iterations
//! (or when the Krylov basis cannot grow any more), the function falls back to faer's thin
//! SVD and says why in [`TruncatedSvd::fallback_reason`] (which triplet, its residual, the
//! estimated gap).
//!
//! # Cost
//!
//! Time `O(mn·l·(2q+2) + mnk·(q+1))` for the products with `A` and `Aᵀ` (`q` = iterations
//! used, `l = k + p`), plus for block Krylov `O((m+n)·L·l)` per iteration for the
//! re-orthogonalisation and the incremental QR of `Y` and `O(L³)` for the SVD of the small
//! triangular factor, `L = l(j+1) ≤ l(q+1)` the current basis width (subspace iteration:
//! `L = l`). Memory `O((m+n)·l·(q+1))`. The thin-SVD fallback costs `O(mn·min(m,n))`.
//! Measured (see `benches/svd.rs`): on a 2000×5000 rank-3-plus-noise `W` the default needs
//! ≈ 11 iterations, driven by `σ₄`; `σ₁..σ₃` converge after 1–2.
//!
//! # Edge cases
//!
//! `k > min(m,n)` is clamped to `min(m,n)` (the result then has fewer columns; check
//! `s.len()`). `k = 0` or an empty matrix returns empty factors. A zero matrix returns
//! `σ = 0` with coordinate vectors as `U`, `V`. Small matrices
//! (`min(m,n) ≤ small_dense_threshold`) or requests with `2(k+p) > min(m,n)` go straight
//! to the thin SVD (the sketch would not be cheaper). Non-finite entries are an error.
//!
//! # The Gram route (starts only)
//!
//! `leading_by_gram` (crate-internal) takes the leading triplets of a short, wide matrix
//! from the eigen-decomposition of `A Aᵀ`: `O(m² n)`, no iteration, but vectors accurate
//! only to `≈ ε σ₁² / gap²`. The completion's hard-impute start uses it up to 256 rows,
//! where it is 1.4–6× faster than the sketch (docs/results.md, #21).
//!
//! # Threads
//!
//! Called from outside any rayon pool, the products run on a pool of their own (see
//! `faer_pool`); called from a rayon worker (a parallel loop over windows, say), they stay
//! on that worker's pool.

use faer::{Mat, MatRef};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;

use crate::error::{Error, Result};
use crate::observer::{Event, NoopObserver, Observer};

/// How the sketch subspace is built.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SketchScheme {
    /// Block Krylov space `[AΩ, (AAᵀ)AΩ, …]` (Musco & Musco 2015). Default.
    BlockKrylov,
    /// Subspace (power) iteration `(AAᵀ)^q AΩ` with QR between products
    /// (Halko, Martinsson & Tropp 2011, Alg. 4.4).
    SubspaceIteration,
}

/// Settings of [`truncated_svd`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TruncatedSvdConfig {
    /// Extra sketch columns `p` beyond `k`. Default 10.
    pub oversampling: usize,
    /// Maximum number of power / Krylov iterations `q` (each costs two products with `A`)
    /// before falling back to the thin SVD. Default 20.
    pub max_power_iterations: usize,
    /// Accuracy target `tol` of the check (see the module docs): residuals relative to
    /// `σ₁`, Ritz-value changes relative to the value. Default `1e-10`. Must be finite and
    /// positive.
    pub tolerance: f64,
    /// Ratio `σᵢ/σᵢ₊₁` below which a triplet counts as clustered (only its value has to
    /// converge). Default `1.2`. Must be finite and `≥ 1`.
    pub min_gap: f64,
    /// Relative accuracy required of the *value* of a clustered triplet (see `min_gap`),
    /// judged from the convergence of its Ritz value. Default `1e-3`, below the spacing of
    /// the largest noise singular values of a W with 10³–10⁴ columns, which is what `σ₄`
    /// is for rank3. Must be finite and positive.
    pub cluster_tolerance: f64,
    /// Seed of the Gaussian test matrix; the result is deterministic for a given seed
    /// (and thread count). Default 0.
    pub seed: u64,
    /// When `min(m, n)` is at most this, use the thin SVD directly. Default 64.
    pub small_dense_threshold: usize,
    /// Sketch scheme. Default [`SketchScheme::BlockKrylov`].
    pub scheme: SketchScheme,
    /// Fall back to the thin SVD when the check fails. Default `true`; when `false` the
    /// last sketch result is returned with [`TruncatedSvd::converged`] = `false`.
    pub allow_fallback: bool,
}

impl Default for TruncatedSvdConfig {
    fn default() -> Self {
        Self {
            oversampling: 10,
            max_power_iterations: 20,
            tolerance: 1e-10,
            min_gap: 1.2,
            cluster_tolerance: 1e-3,
            seed: 0,
            small_dense_threshold: 64,
            scheme: SketchScheme::BlockKrylov,
            allow_fallback: true,
        }
    }
}

/// Which method produced a [`TruncatedSvd`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SvdMethod {
    /// faer's dense thin SVD (small input, zero matrix, or fallback).
    Thin,
    /// Randomized sketch with `iterations` power/Krylov iterations (`iterations + 1`
    /// blocks for Krylov).
    Randomized {
        scheme: SketchScheme,
        iterations: usize,
    },
    /// The eigen-decomposition of `A Aᵀ` (starts of iterative solvers only; see
    /// `leading_by_gram`).
    Gram,
}

/// The `k` leading singular triplets of a matrix.
#[derive(Debug, Clone)]
pub struct TruncatedSvd {
    /// Left singular vectors, m×k, orthonormal columns.
    pub u: Mat<f64>,
    /// Leading singular values, descending, length k.
    pub s: Vec<f64>,
    /// Right singular vectors, n×k, orthonormal columns.
    pub v: Mat<f64>,
    /// Every singular value computed, descending, at least `k` of them: all `min(m,n)` for
    /// [`SvdMethod::Thin`], the Ritz values of the sketch space otherwise (the ones beyond
    /// `k` are lower bounds of the true ones and less accurate).
    pub singular_values: Vec<f64>,
    /// How the result was computed.
    pub method: SvdMethod,
    /// Why the randomized method was abandoned for the thin SVD, if it was.
    pub fallback_reason: Option<String>,
    /// `maxᵢ ‖A vᵢ − σᵢ uᵢ‖ / σ₁` over the k triplets (0 for a zero matrix; for the thin
    /// SVD it is computed too, ≈ machine precision).
    pub residual: f64,
    /// Whether the accuracy check passed. Always `true` for [`SvdMethod::Thin`]; `false`
    /// only when [`TruncatedSvdConfig::allow_fallback`] is off and the sketch did not
    /// converge (the best sketch result is returned).
    pub converged: bool,
}

/// The `k` leading singular triplets of `a`; see the module documentation for the method,
/// the accuracy check, the fallback and the cost.
///
/// Errors: [`Error::InvalidConfig`] for a bad config, [`Error::Degenerate`] for non-finite
/// entries, [`Error::Numerical`] if faer's SVD does not converge.
pub fn truncated_svd(
    a: MatRef<'_, f64>,
    k: usize,
    cfg: &TruncatedSvdConfig,
) -> Result<TruncatedSvd> {
    truncated_svd_observed(a, k, cfg, &mut NoopObserver)
}

/// [`truncated_svd`] reporting an [`Event::Iteration`] per sketch iteration (solver
/// `"truncated-svd"`, `cost` = largest relative residual, `rms`/`lambda` NaN) and an
/// [`Event::Warning`] when it falls back to the thin SVD.
pub fn truncated_svd_observed(
    a: MatRef<'_, f64>,
    k: usize,
    cfg: &TruncatedSvdConfig,
    observer: &mut dyn Observer,
) -> Result<TruncatedSvd> {
    validate(cfg)?;
    let (m, n) = (a.nrows(), a.ncols());
    let mn = m.min(n);
    let k = k.min(mn);

    let frob2 = finite_frobenius2(a)?;
    if k == 0 {
        return Ok(empty(m, n));
    }
    if frob2 == 0.0 {
        return Ok(TruncatedSvd {
            u: Mat::identity(m, k),
            s: vec![0.0; k],
            v: Mat::identity(n, k),
            singular_values: vec![0.0; mn],
            method: SvdMethod::Thin,
            fallback_reason: None,
            residual: 0.0,
            converged: true,
        });
    }

    let l = k + cfg.oversampling;
    if mn <= cfg.small_dense_threshold || 2 * l > mn {
        return thin(a, k, None);
    }

    // faer's parallel products run on a rayon pool of their own (see [`faer_pool`]); the
    // sketch's iteration events are kept and sent to `observer` from this thread.
    let mut iterations = IterationLog::default();
    let sketched = in_faer_pool(|| sketch(a, k, l, cfg, &mut iterations));
    for &(iteration, cost) in &iterations.0 {
        observer.on_event(&Event::Iteration {
            solver: "truncated-svd",
            run: 0,
            iteration,
            cost,
            rms: f64::NAN,
            lambda: f64::NAN,
        });
    }
    match sketched {
        Ok((result, None)) => Ok(result),
        Ok((best, Some(reason))) if !cfg.allow_fallback => {
            let message = format!("truncated SVD not converged: {reason}");
            observer.on_event(&Event::Warning { message: &message });
            Ok(best)
        }
        Ok((_, Some(reason))) | Err(reason) => {
            observer.on_event(&Event::Warning { message: &reason });
            in_faer_pool(|| thin(a, k, Some(reason)))
        }
    }
}

/// The `k` leading singular triplets of a short, wide `a` (`m ≤ n`) from the symmetric
/// eigen-decomposition of its Gram matrix: `G = A Aᵀ` (m×m), `G uᵢ = σᵢ² uᵢ`,
/// `vᵢ = Aᵀ uᵢ / σᵢ`; a `σᵢ` below `√(ε·max(m, n))·σ₁` is not resolved by `G` and is
/// returned as 0, with `vᵢ = 0`.
///
/// For the starts of iterative solvers (the completion's hard-impute sweeps), not for
/// final answers: forming `G` squares the condition, so a vector is accurate to
/// `≈ ε σ₁² / (σᵢ² − σᵢ₊₁²)` rather than `ε σ₁ / (σᵢ − σᵢ₊₁)`; `σ₄` of a
/// rank-3-plus-noise matrix is not resolved. There is no iteration and no accuracy
/// check ([`TruncatedSvd::converged`] is true, the residual is computed).
///
/// Cost: `O(m² n)` for `G` (one dense product at GEMM speed), `O(m³)` for the
/// eigen-decomposition, `O(mnk)` for `V` and the residual; memory `O(m² + nk)`. Against
/// the randomized sketch's `O(mn(k + p))` per Krylov iteration (and its QRs of n×l
/// blocks) this wins for `m` up to a few hundred: measured on the 80 × ~1 300 windows of
/// the sparse pipeline's start (docs/results.md).
///
/// Errors: [`Error::Degenerate`] for non-finite entries, [`Error::Numerical`] if the
/// eigen-decomposition fails.
pub(crate) fn leading_by_gram(a: MatRef<'_, f64>, k: usize) -> Result<TruncatedSvd> {
    let (m, n) = (a.nrows(), a.ncols());
    let k = k.min(m).min(n);
    finite_frobenius2(a)?;
    if k == 0 {
        return Ok(empty(m, n));
    }
    // Every product on the SVD's own pool, as the sketch's (see `faer_pool`).
    in_faer_pool(|| gram_triplets(a, k))
}

/// The body of [`leading_by_gram`] for a finite `a` and `1 ≤ k ≤ min(m, n)`.
fn gram_triplets(a: MatRef<'_, f64>, k: usize) -> Result<TruncatedSvd> {
    let (m, n) = (a.nrows(), a.ncols());
    let mut g = Mat::<f64>::zeros(m, m);
    faer::linalg::matmul::matmul(
        g.as_mut(),
        faer::Accum::Replace,
        a,
        a.transpose(),
        1.0,
        faer::get_global_parallelism(),
    );
    let evd = g
        .self_adjoint_eigen(faer::Side::Lower)
        .map_err(|e| Error::Numerical {
            stage: "Gram eigen-decomposition",
            message: format!("{e:?}"),
        })?;
    let (vals, vecs) = (evd.S().column_vector(), evd.U());
    // Descending order (rounding can leave tiny negative eigenvalues). An eigenvalue of G
    // is known to ≈ ε·max(m, n)·σ₁², so a singular value below √(ε·max(m, n))·σ₁ is not
    // resolved: reported as 0, with v = 0.
    let top = vals[m - 1].max(0.0);
    let floor = f64::EPSILON * m.max(n) as f64 * top;
    let singular_values: Vec<f64> = (0..m)
        .rev()
        .map(|i| if vals[i] > floor { vals[i].sqrt() } else { 0.0 })
        .collect();
    let u = Mat::from_fn(m, k, |i, c| vecs[(i, m - 1 - c)]);
    let s = singular_values[..k].to_vec();
    let mut v = a.transpose() * &u;
    for (c, &sc) in s.iter().enumerate() {
        let inv = if sc > 0.0 { 1.0 / sc } else { 0.0 };
        for p in 0..n {
            v[(p, c)] *= inv;
        }
    }
    let residual = max_relative_residual(a, u.as_ref(), &s, v.as_ref());
    Ok(TruncatedSvd {
        u,
        s,
        v,
        singular_values,
        method: SvdMethod::Gram,
        fallback_reason: None,
        residual,
        converged: true,
    })
}

/// `‖A‖_F²`, or [`Error::Degenerate`] naming the first non-finite entry (column by column).
fn finite_frobenius2(a: MatRef<'_, f64>) -> Result<f64> {
    let mut frob2 = 0.0;
    for j in 0..a.ncols() {
        for i in 0..a.nrows() {
            let x = a[(i, j)];
            if !x.is_finite() {
                return Err(Error::Degenerate(format!(
                    "truncated SVD: matrix entry ({i}, {j}) is not finite ({x})"
                )));
            }
            frob2 += x * x;
        }
    }
    Ok(frob2)
}

/// The `(iteration, cost)` of the sketch's [`Event::Iteration`]s (sent to the caller's
/// observer afterwards: it need not be `Send`).
#[derive(Default)]
struct IterationLog(Vec<(usize, f64)>);

impl Observer for IterationLog {
    fn on_event(&mut self, event: &Event<'_>) {
        if let Event::Iteration {
            iteration, cost, ..
        } = event
        {
            self.0.push((*iteration, *cost));
        }
    }
}

/// The rayon pool faer's parallel kernels run on here, as many threads as the global
/// pool; `None` if it could not be built (then they run on the global pool).
///
/// Why apart: faer's matrix products hand their threads to `spindle` (through
/// `private-gemm-x86`), whose workers are rayon jobs of the calling pool; after such a
/// product the global pool's own parallel loops ran up to 10 times slower (measured: the
/// ALS camera update of a 300 × 10 000 table with 40 % missing, 0.19–0.23 s per sweep
/// after the completion's start — ten truncated SVDs — against 0.03 s with the SVDs on
/// this pool, and 0.022 s with faer sequential). Run here, the products keep their two
/// cores and leave the global pool as it was.
fn faer_pool() -> Option<&'static rayon::ThreadPool> {
    static POOL: std::sync::OnceLock<Option<rayon::ThreadPool>> = std::sync::OnceLock::new();
    POOL.get_or_init(|| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(rayon::current_num_threads())
            .thread_name(|i| format!("rank3-faer-{i}"))
            .build()
            .ok()
    })
    .as_ref()
}

/// `f` on [`faer_pool`] when called from outside every rayon pool; here, on the calling
/// thread, when there is no such pool or the caller is already a rayon worker.
///
/// A worker that hands `f` to another pool blocks until it is done, and while it waits it
/// runs other jobs of its own pool — in a parallel loop over windows, other windows, each
/// of which blocks on its own SVD in turn: the stack grew by a window per wait, and the
/// 20 000-frame sparse table (a thousand windows) overflowed a worker's stack and
/// aborted. Inside a parallel loop the loop already holds the cores, so `f` runs where
/// it was called (faer's products then use the caller's pool, as a nested rayon job).
fn in_faer_pool<T: Send>(f: impl FnOnce() -> T + Send) -> T {
    match faer_pool() {
        Some(pool) if rayon::current_thread_index().is_none() => pool.install(f),
        _ => f(),
    }
}

/// Result for k = 0.
fn empty(m: usize, n: usize) -> TruncatedSvd {
    TruncatedSvd {
        u: Mat::zeros(m, 0),
        s: Vec::new(),
        v: Mat::zeros(n, 0),
        singular_values: Vec::new(),
        method: SvdMethod::Thin,
        fallback_reason: None,
        residual: 0.0,
        converged: true,
    }
}

fn validate(cfg: &TruncatedSvdConfig) -> Result<()> {
    if !(cfg.tolerance.is_finite() && cfg.tolerance > 0.0) {
        return Err(Error::InvalidConfig {
            field: "tolerance",
            message: format!("must be finite and positive, got {}", cfg.tolerance),
        });
    }
    if !(cfg.cluster_tolerance.is_finite() && cfg.cluster_tolerance > 0.0) {
        return Err(Error::InvalidConfig {
            field: "cluster_tolerance",
            message: format!("must be finite and positive, got {}", cfg.cluster_tolerance),
        });
    }
    if !(cfg.min_gap.is_finite() && cfg.min_gap >= 1.0) {
        return Err(Error::InvalidConfig {
            field: "min_gap",
            message: format!("must be finite and at least 1, got {}", cfg.min_gap),
        });
    }
    Ok(())
}

/// faer's thin SVD, truncated to k.
fn thin(a: MatRef<'_, f64>, k: usize, fallback_reason: Option<String>) -> Result<TruncatedSvd> {
    let svd = a.thin_svd().map_err(|e| Error::Numerical {
        stage: "thin SVD",
        message: format!("{e:?}"),
    })?;
    let sv = svd.S().column_vector();
    let singular_values: Vec<f64> = (0..sv.nrows()).map(|i| sv[i]).collect();
    let u = svd.U().subcols(0, k).to_owned();
    let v = svd.V().subcols(0, k).to_owned();
    let s = singular_values[..k].to_vec();
    let residual = max_relative_residual(a, u.as_ref(), &s, v.as_ref());
    Ok(TruncatedSvd {
        u,
        s,
        v,
        singular_values,
        method: SvdMethod::Thin,
        fallback_reason,
        residual,
        converged: true,
    })
}

/// Residual norms `‖A vᵢ − σᵢ uᵢ‖` of the k triplets.
fn residual_norms(
    a: MatRef<'_, f64>,
    u: MatRef<'_, f64>,
    s: &[f64],
    v: MatRef<'_, f64>,
) -> Vec<f64> {
    let av = a * v;
    (0..s.len())
        .map(|i| {
            let mut r2 = 0.0;
            for row in 0..av.nrows() {
                let d = av[(row, i)] - s[i] * u[(row, i)];
                r2 += d * d;
            }
            r2.sqrt()
        })
        .collect()
}

fn max_relative_residual(
    a: MatRef<'_, f64>,
    u: MatRef<'_, f64>,
    s: &[f64],
    v: MatRef<'_, f64>,
) -> f64 {
    if s.is_empty() || s[0] == 0.0 {
        return 0.0;
    }
    residual_norms(a, u, s, v).into_iter().fold(0.0, f64::max) / s[0]
}

/// Estimated remaining error of the Ritz value `i` from its last three iterates, assuming
/// linear convergence (Aitken): with increments `Δⱼ = σ⁽ʲ⁾ − σ⁽ʲ⁻¹⁾` and rate
/// `ρ = Δⱼ/Δⱼ₋₁ < 1`, the error is `≈ Δⱼ ρ/(1−ρ)`; `max(Δⱼ, ·)` is returned for safety.
/// `None` when there is not enough history or the increments do not shrink.
fn value_error_estimate(history: &[Vec<f64>], i: usize) -> Option<f64> {
    let j = history.len();
    if j < 2 {
        return None;
    }
    let d1 = (history[j - 1][i] - history[j - 2][i]).abs();
    if d1 <= 4.0 * f64::EPSILON * history[j - 1][i] {
        return Some(d1);
    }
    if j < 3 {
        return None;
    }
    let d0 = (history[j - 2][i] - history[j - 3][i]).abs();
    let rho = d1 / d0;
    (rho < 1.0).then(|| d1.max(d1 * rho / (1.0 - rho)))
}

/// Orthonormal basis of the columns of `z` (Householder QR, thin Q).
fn orth(z: MatRef<'_, f64>) -> Mat<f64> {
    z.qr().compute_thin_Q()
}

/// `z ← z − Q (Qᵀ z)`.
fn project_out(q: MatRef<'_, f64>, z: &mut Mat<f64>) {
    if q.ncols() == 0 {
        return;
    }
    let c = q.transpose() * z.as_ref();
    *z -= q * &c;
}

/// Randomized sketch: `Ok((best, Some(reason)))` when the check failed, `Err(reason)` when
/// the sketch itself failed (both lead to the thin-SVD fallback by default).
fn sketch(
    a: MatRef<'_, f64>,
    k: usize,
    l: usize,
    cfg: &TruncatedSvdConfig,
    observer: &mut dyn Observer,
) -> std::result::Result<(TruncatedSvd, Option<String>), String> {
    let (m, n) = (a.nrows(), a.ncols());
    let krylov = cfg.scheme == SketchScheme::BlockKrylov;
    // Krylov basis must fit in R^m (and B has rank ≤ n); cap the number of blocks.
    let max_blocks = if krylov {
        (cfg.max_power_iterations + 1).min(m.min(n) / l).max(1)
    } else {
        1
    };
    let mut q_all = Mat::<f64>::zeros(m, l * max_blocks);
    let mut qy_all = Mat::<f64>::zeros(n, l * max_blocks);
    let mut r_all = Mat::<f64>::zeros(l * max_blocks, l * max_blocks);

    let mut rng = StdRng::seed_from_u64(cfg.seed);
    let omega = Mat::<f64>::from_fn(n, l, |_, _| rng.sample(StandardNormal));
    let q0 = orth((a * &omega).as_ref());
    q_all.subcols_mut(0, l).copy_from(&q0);

    let tol = cfg.tolerance;
    let mut history: Vec<Vec<f64>> = Vec::new(); // leading k Ritz values per iteration
    let mut blocks = 1; // number of filled blocks (Krylov)
    let mut iteration = 0;
    loop {
        // Y_j = Aᵀ Q_j (block `blocks − 1` for Krylov, the only block otherwise).
        let off = if krylov { (blocks - 1) * l } else { 0 };
        let yj = a.transpose() * q_all.subcols(off, l);
        let width = if krylov { blocks * l } else { l };

        // Rayleigh–Ritz: B = Qᵀ A = Yᵀ (width×n). Keep a QR factorisation Y = Q_y R,
        // extended block by block (block Gram–Schmidt, twice); with R = U_r Σ V_rᵀ,
        // B = V_r Σ (Q_y U_r)ᵀ, so u = Q V_r and v = Q_y U_r. Cost O(n·width·l) per block
        // instead of O(n·width²) for a fresh factorisation.
        let mut z = yj.clone();
        if off > 0 {
            let qp = qy_all.subcols(0, off);
            let c1 = qp.transpose() * &z;
            z -= qp * &c1;
            let c2 = qp.transpose() * &z;
            z -= qp * &c2;
            r_all.submatrix_mut(0, off, off, l).copy_from(&(c1 + c2));
        }
        let qr = z.qr();
        let mut qn = qr.compute_thin_Q();
        if off > 0 {
            // Only matters for a (numerically) rank-deficient block, where R_jj ≈ 0.
            project_out(qy_all.subcols(0, off), &mut qn);
            qn = orth(qn.as_ref());
        }
        qy_all.subcols_mut(off, l).copy_from(&qn);
        r_all.submatrix_mut(off, off, l, l).copy_from(qr.thin_R());
        let r_svd = r_all
            .submatrix(0, 0, width, width)
            .thin_svd()
            .map_err(|e| format!("SVD of the sketch failed ({e:?})"))?;
        let sv = r_svd.S().column_vector();
        let values: Vec<f64> = (0..sv.nrows()).map(|i| sv[i]).collect();
        let s = values[..k].to_vec();
        let u = q_all.subcols(0, width) * r_svd.V().subcols(0, k);
        let v = qy_all.subcols(0, width) * r_svd.U().subcols(0, k);

        // Accuracy check.
        let sigma1 = values[0];
        let res = residual_norms(a, u.as_ref(), &s, v.as_ref());
        let rel_res: Vec<f64> = res.iter().map(|r| r / sigma1).collect();
        let max_res = rel_res.iter().copied().fold(0.0, f64::max);
        observer.on_event(&Event::Iteration {
            solver: "truncated-svd",
            run: 0,
            iteration,
            cost: max_res,
            rms: f64::NAN,
            lambda: f64::NAN,
        });
        history.push(s.clone());
        let mut failing = None;
        for i in 0..k {
            if rel_res[i] <= tol {
                continue;
            }
            let next = values.get(i + 1).copied().unwrap_or(0.0);
            let clustered = values[i] < cfg.min_gap * next;
            let value_ok = value_error_estimate(&history, i)
                .is_some_and(|e| e <= cfg.cluster_tolerance * values[i]);
            if !(clustered && value_ok) {
                failing = Some((i, clustered, next));
                break;
            }
        }
        let result = TruncatedSvd {
            u,
            s,
            v,
            singular_values: values.clone(),
            method: SvdMethod::Randomized {
                scheme: cfg.scheme,
                iterations: iteration,
            },
            fallback_reason: None,
            residual: max_res,
            converged: failing.is_none(),
        };
        if let Some((i, clustered, next)) = failing {
            if iteration >= cfg.max_power_iterations || (krylov && blocks >= max_blocks) {
                let gap = if next > 0.0 {
                    values[i] / next
                } else {
                    f64::INFINITY
                };
                let reason = if clustered {
                    format!(
                        "σ{} = {:.6e} is clustered (gap σ{}/σ{} ≈ {gap:.4} < min_gap {}), its \
                         residual ‖Av−σu‖/σ₁ = {:.3e} > tolerance {tol:e} and its value had \
                         not converged to {:e} after {iteration} iterations",
                        i + 1,
                        values[i],
                        i + 1,
                        i + 2,
                        cfg.min_gap,
                        rel_res[i],
                        cfg.cluster_tolerance
                    )
                } else {
                    format!(
                        "triplet {} residual ‖Av−σu‖/σ₁ = {:.3e} > tolerance {tol:e} after \
                         {iteration} iterations (estimated gap σ{}/σ{} ≈ {gap:.4}, min_gap {})",
                        i + 1,
                        rel_res[i],
                        i + 1,
                        i + 2,
                        cfg.min_gap
                    )
                };
                return Ok((result, Some(reason)));
            }
        } else {
            return Ok((result, None));
        }
        iteration += 1;

        // Next block: orth((I − QQᵀ) A orth(Y_j)); orthonormalising Y_j first keeps the
        // small-σ directions from drowning in rounding (HMT 2011, Alg. 4.4).
        let mut z = a * orth(yj.as_ref());
        if krylov {
            let q_prev = q_all.subcols(0, blocks * l);
            project_out(q_prev, &mut z);
            project_out(q_prev, &mut z);
            let mut qn = orth(z.as_ref());
            // A rank-deficient block gives arbitrary Householder columns: re-project them.
            project_out(q_prev, &mut qn);
            let qn = orth(qn.as_ref());
            q_all.subcols_mut(blocks * l, l).copy_from(&qn);
            blocks += 1;
        } else {
            let qn = orth(z.as_ref());
            q_all.subcols_mut(0, l).copy_from(&qn);
        }
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)]
mod tests {
    use super::*;

    /// `U diag(s) Vᵀ` with Haar-like random orthonormal U (m×r), V (n×r), r = s.len().
    fn with_spectrum(m: usize, n: usize, s: &[f64], seed: u64) -> Mat<f64> {
        let mut rng = StdRng::seed_from_u64(seed);
        let r = s.len();
        let gu = Mat::<f64>::from_fn(m, r, |_, _| rng.sample(StandardNormal));
        let gv = Mat::<f64>::from_fn(n, r, |_, _| rng.sample(StandardNormal));
        let u = orth(gu.as_ref());
        let v = orth(gv.as_ref());
        let us = Mat::<f64>::from_fn(m, r, |i, j| u[(i, j)] * s[j]);
        us * v.transpose()
    }

    /// Rank-3 signal (singular values ≈ 100·√(mn)/… scale) plus Gaussian noise `noise`,
    /// rows centred, like a centred observation matrix W.
    fn rank3_plus_noise(m: usize, n: usize, noise: f64, seed: u64) -> Mat<f64> {
        let mut rng = StdRng::seed_from_u64(seed);
        let mm = Mat::<f64>::from_fn(m, 3, |_, _| rng.sample(StandardNormal));
        let ss = Mat::<f64>::from_fn(3, n, |_, _| 100.0 * rng.sample::<f64, _>(StandardNormal));
        let mut w = mm * ss;
        for j in 0..n {
            for i in 0..m {
                w[(i, j)] += noise * rng.sample::<f64, _>(StandardNormal);
            }
        }
        for i in 0..m {
            let mean = (0..n).map(|j| w[(i, j)]).sum::<f64>() / n as f64;
            for j in 0..n {
                w[(i, j)] -= mean;
            }
        }
        w
    }

    /// sin of the largest principal angle between the spans of orthonormal `a` and `b`.
    fn sin_max_angle(a: MatRef<'_, f64>, b: MatRef<'_, f64>) -> f64 {
        let resid = b - a * (a.transpose() * b);
        resid.singular_values().unwrap()[0]
    }

    /// max |XᵀX − I|.
    fn orthonormality_error(x: MatRef<'_, f64>) -> f64 {
        let g = x.transpose() * x;
        let mut e: f64 = 0.0;
        for i in 0..g.nrows() {
            for j in 0..g.ncols() {
                e = e.max((g[(i, j)] - if i == j { 1.0 } else { 0.0 }).abs());
            }
        }
        e
    }

    fn reference(a: &Mat<f64>) -> (Mat<f64>, Vec<f64>, Mat<f64>) {
        let svd = a.thin_svd().unwrap();
        let s = svd.S().column_vector();
        (
            svd.U().to_owned(),
            (0..s.nrows()).map(|i| s[i]).collect(),
            svd.V().to_owned(),
        )
    }

    /// The Gram route's leading triplets against the thin SVD: values to 1e-10, the
    /// rank-3 subspaces (gap σ₃/σ₄ ~ 10²) to the squared-condition bound; a rank-2 matrix
    /// gets σ₃ = 0 and `v = 0` for it; non-finite entries are an error.
    #[test]
    fn gram_route_matches_thin_svd() {
        for (idx, &(m, n)) in [(80, 300), (40, 1500), (7, 7)].iter().enumerate() {
            let a = rank3_plus_noise(m, n, 0.5, 20 + idx as u64);
            let (ur, sr, vr) = reference(&a);
            let t = leading_by_gram(a.as_ref(), 3).unwrap();
            assert_eq!(t.method, SvdMethod::Gram);
            assert_eq!(
                (t.u.ncols(), t.v.nrows(), t.singular_values.len()),
                (3, n, m)
            );
            for i in 0..3 {
                let rel = (t.s[i] - sr[i]).abs() / sr[0];
                assert!(rel < 1e-10, "{m}×{n}: σ{} rel err {rel:e}", i + 1);
            }
            let bound = 1e3 * f64::EPSILON * (sr[0] / (sr[2] - sr[3])).powi(2);
            let su = sin_max_angle(ur.subcols(0, 3), t.u.subcols(0, 3));
            let sv = sin_max_angle(vr.subcols(0, 3), t.v.subcols(0, 3));
            assert!(su < bound && sv < bound, "{m}×{n}: sinθ U {su:e} V {sv:e}");
            assert!(orthonormality_error(t.u.as_ref()) < 1e-12);
            assert!(t.residual < bound, "{m}×{n}: residual {:e}", t.residual);
        }
        let rank2 = with_spectrum(30, 200, &[5.0, 2.0], 3);
        let t = leading_by_gram(rank2.as_ref(), 3).unwrap();
        assert!(t.s[2] == 0.0 && (0..200).all(|p| t.v[(p, 2)] == 0.0));
        assert!((t.s[1] - 2.0).abs() < 1e-12, "σ₂ {}", t.s[1]);
        let mut bad = rank2.clone();
        bad[(4, 9)] = f64::NAN;
        assert!(matches!(
            leading_by_gram(bad.as_ref(), 3),
            Err(Error::Degenerate(_))
        ));
    }

    #[test]
    fn rank3_plus_noise_matches_thin_svd() {
        let cfg = TruncatedSvdConfig::default();
        for (idx, &(m, n)) in [(80, 300), (240, 90), (120, 120)].iter().enumerate() {
            let a = rank3_plus_noise(m, n, 0.5, 10 + idx as u64);
            let (ur, sr, vr) = reference(&a);
            let t = truncated_svd(a.as_ref(), 4, &cfg).unwrap();
            assert!(
                matches!(t.method, SvdMethod::Randomized { .. }),
                "{m}×{n}: {:?} {:?}",
                t.method,
                t.fallback_reason
            );
            assert!(t.fallback_reason.is_none() && t.converged);
            assert_eq!(
                (t.u.nrows(), t.u.ncols(), t.v.nrows(), t.v.ncols()),
                (m, 4, n, 4)
            );
            assert!(t.singular_values.len() >= 4);
            for i in 0..3 {
                let rel = (t.s[i] - sr[i]).abs() / sr[i];
                assert!(rel < 1e-10, "{m}×{n}: σ{} rel err {rel:e}", i + 1);
            }
            // σ4 is a noise singular value in a cluster: value accuracy is cluster_tolerance.
            let rel4 = (t.s[3] - sr[3]).abs() / sr[3];
            assert!(
                rel4 < 2.0 * cfg.cluster_tolerance,
                "{m}×{n}: σ4 rel err {rel4:e}"
            );
            // Rayleigh–Ritz values never exceed the true ones (interlacing).
            assert!(t.s[3] <= sr[3] * (1.0 + 1e-12));
            // Leading rank-3 subspaces: the gap σ3/σ4 is ~10², so they are well determined.
            let su = sin_max_angle(ur.subcols(0, 3), t.u.subcols(0, 3));
            let sv = sin_max_angle(vr.subcols(0, 3), t.v.subcols(0, 3));
            assert!(su < 1e-9 && sv < 1e-9, "{m}×{n}: sinθ U {su:e} V {sv:e}");
            assert!(orthonormality_error(t.u.as_ref()) < 1e-12);
            assert!(orthonormality_error(t.v.as_ref()) < 1e-12);
            // The reported residual is the check's measure; recompute it.
            let r = max_relative_residual(a.as_ref(), t.u.as_ref(), &t.s, t.v.as_ref());
            assert!((r - t.residual).abs() <= 1e-6 * r.max(1e-300) + 1e-15);
        }
    }

    #[test]
    fn exact_rank3_gives_zero_sigma4() {
        let a = rank3_plus_noise(100, 150, 0.0, 3);
        let (ur, sr, _) = reference(&a);
        let t = truncated_svd(a.as_ref(), 4, &TruncatedSvdConfig::default()).unwrap();
        assert!(t.fallback_reason.is_none(), "{:?}", t.fallback_reason);
        for i in 0..3 {
            assert!((t.s[i] - sr[i]).abs() < 1e-12 * sr[0]);
        }
        assert!(t.s[3] < 1e-12 * t.s[0], "σ4 = {:e}", t.s[3]);
        assert!(sin_max_angle(ur.subcols(0, 3), t.u.subcols(0, 3)) < 1e-10);
        assert!(orthonormality_error(t.u.as_ref()) < 1e-12);
        assert!(orthonormality_error(t.v.as_ref()) < 1e-12);
    }

    #[test]
    fn tiny_gap_is_accurate_or_falls_back() {
        // σ3/σ4 = 1 + 1e-9: the third singular vector is ill-determined.
        let mut s = vec![10.0, 5.0, 1.0 + 1e-9, 1.0];
        s.extend((0..60).map(|i| 0.5 * 0.95f64.powi(i)));
        let a = with_spectrum(150, 200, &s, 5);
        let (ur, sr, _) = reference(&a);
        let cfg = TruncatedSvdConfig::default();
        let t = truncated_svd(a.as_ref(), 3, &cfg).unwrap();
        if t.method == SvdMethod::Thin {
            assert!(t.fallback_reason.is_some());
        }
        for i in 0..3 {
            let rel = (t.s[i] - sr[i]).abs() / sr[i];
            assert!(rel < cfg.cluster_tolerance, "σ{} rel err {rel:e}", i + 1);
        }
        // The leading pair is separated (gap 2, then 5): its subspace must be accurate.
        assert!(sin_max_angle(ur.subcols(0, 2), t.u.subcols(0, 2)) < 1e-8);
        // The third vector lies (to the residual) in span{u3, u4} of the reference.
        assert!(sin_max_angle(ur.subcols(0, 4), t.u.subcols(0, 3)) < 1e-6);
    }

    #[test]
    fn unconverged_sketch_falls_back_with_reason() {
        // Slowly decaying spectrum and a single iteration: the check cannot pass.
        let s: Vec<f64> = (0..80).map(|i| 1.0 / (1.0 + 0.02 * i as f64)).collect();
        let a = with_spectrum(120, 160, &s, 9);
        let (_, sr, _) = reference(&a);
        let cfg = TruncatedSvdConfig {
            max_power_iterations: 1,
            ..Default::default()
        };
        let t = truncated_svd(a.as_ref(), 4, &cfg).unwrap();
        assert_eq!(t.method, SvdMethod::Thin);
        let reason = t.fallback_reason.as_deref().unwrap();
        assert!(reason.contains("after 1 iterations"), "{reason}");
        assert_eq!(t.singular_values.len(), 120);
        for i in 0..4 {
            assert!((t.s[i] - sr[i]).abs() < 1e-13 * sr[0]);
        }
        // Without fallback the (inaccurate) sketch is returned and flagged.
        let cfg = TruncatedSvdConfig {
            allow_fallback: false,
            ..cfg
        };
        let t = truncated_svd(a.as_ref(), 4, &cfg).unwrap();
        assert!(!t.converged && t.fallback_reason.is_none());
        assert!(matches!(
            t.method,
            SvdMethod::Randomized { iterations: 1, .. }
        ));
    }

    #[test]
    fn tall_wide_and_subspace_iteration() {
        for (m, n) in [(300, 70), (70, 300)] {
            let a = rank3_plus_noise(m, n, 0.01, 21);
            let (ur, sr, vr) = reference(&a);
            for scheme in [SketchScheme::BlockKrylov, SketchScheme::SubspaceIteration] {
                let cfg = TruncatedSvdConfig {
                    scheme,
                    ..Default::default()
                };
                let t = truncated_svd(a.as_ref(), 3, &cfg).unwrap();
                assert!(t.fallback_reason.is_none(), "{:?}", t.fallback_reason);
                for i in 0..3 {
                    assert!((t.s[i] - sr[i]).abs() < 1e-10 * sr[i]);
                }
                assert!(sin_max_angle(ur.subcols(0, 3), t.u.subcols(0, 3)) < 1e-9);
                assert!(sin_max_angle(vr.subcols(0, 3), t.v.subcols(0, 3)) < 1e-9);
            }
        }
    }

    #[test]
    fn small_zero_empty_and_clamped() {
        let cfg = TruncatedSvdConfig::default();
        // 3×5: thin path, k clamped to 3.
        let a = Mat::<f64>::from_fn(3, 5, |i, j| ((i * 5 + j) as f64).sin());
        let (_, sr, _) = reference(&a);
        let t = truncated_svd(a.as_ref(), 10, &cfg).unwrap();
        assert_eq!(t.method, SvdMethod::Thin);
        assert_eq!((t.s.len(), t.u.ncols(), t.v.ncols()), (3, 3, 3));
        for i in 0..3 {
            assert!((t.s[i] - sr[i]).abs() < 1e-14 * sr[0]);
        }
        assert!(t.residual < 1e-13);
        // Clamping on the sketch path too (k + p too large → thin).
        let b = rank3_plus_noise(70, 90, 0.1, 2);
        let t = truncated_svd(b.as_ref(), 500, &cfg).unwrap();
        assert_eq!((t.s.len(), t.u.ncols(), t.v.ncols()), (70, 70, 70));
        // Zero matrix.
        let z = Mat::<f64>::zeros(100, 200);
        let t = truncated_svd(z.as_ref(), 4, &cfg).unwrap();
        assert_eq!(t.s, vec![0.0; 4]);
        assert_eq!(t.singular_values.len(), 100);
        assert!(orthonormality_error(t.u.as_ref()) == 0.0);
        assert!(orthonormality_error(t.v.as_ref()) == 0.0);
        // k = 0 and empty matrices.
        let t = truncated_svd(b.as_ref(), 0, &cfg).unwrap();
        assert!(t.s.is_empty() && t.u.ncols() == 0 && t.v.nrows() == 90);
        let e = Mat::<f64>::zeros(0, 5);
        let t = truncated_svd(e.as_ref(), 3, &cfg).unwrap();
        assert!(t.s.is_empty() && t.v.nrows() == 5);
        // 1×1.
        let one = Mat::<f64>::from_fn(1, 1, |_, _| -2.5);
        let t = truncated_svd(one.as_ref(), 4, &cfg).unwrap();
        assert_eq!(t.s, vec![2.5]);
        assert!((t.u[(0, 0)] * t.v[(0, 0)] * t.s[0] + 2.5).abs() < 1e-15);
    }

    #[test]
    fn bad_input_is_an_error() {
        let mut a = rank3_plus_noise(70, 80, 0.1, 4);
        a[(3, 7)] = f64::NAN;
        assert!(matches!(
            truncated_svd(a.as_ref(), 4, &TruncatedSvdConfig::default()),
            Err(Error::Degenerate(_))
        ));
        a[(3, 7)] = 0.0;
        for cfg in [
            TruncatedSvdConfig {
                tolerance: 0.0,
                ..Default::default()
            },
            TruncatedSvdConfig {
                min_gap: 0.5,
                ..Default::default()
            },
            TruncatedSvdConfig {
                cluster_tolerance: f64::NAN,
                ..Default::default()
            },
        ] {
            assert!(matches!(
                truncated_svd(a.as_ref(), 4, &cfg),
                Err(Error::InvalidConfig { .. })
            ));
        }
    }

    /// From outside any pool the products go to the SVD's own pool; from a worker of a
    /// parallel loop they stay on that worker, which never waits on another pool (where
    /// it would run the loop's other items inside the wait, one nested in the next: the
    /// stack overflow of a thousand-window sparse start).
    #[test]
    fn a_parallel_loop_is_not_nested_into_the_svd_pool() {
        use rayon::prelude::*;
        use std::cell::Cell;
        thread_local!(static DEPTH: Cell<usize> = const { Cell::new(0) });
        let name = in_faer_pool(|| std::thread::current().name().map(str::to_owned));
        if faer_pool().is_some() {
            assert!(name.is_some_and(|n| n.starts_with("rank3-faer-")));
        }
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        let deepest = pool.install(|| {
            (0..64)
                .into_par_iter()
                .map(|_| {
                    let depth = DEPTH.with(|d| {
                        d.set(d.get() + 1);
                        d.get()
                    });
                    let caller = std::thread::current().id();
                    let (same, _) = in_faer_pool(|| {
                        std::thread::sleep(std::time::Duration::from_millis(2));
                        (std::thread::current().id() == caller, ())
                    });
                    DEPTH.with(|d| d.set(d.get() - 1));
                    assert!(same, "the SVD left the loop's worker");
                    depth
                })
                .max()
                .unwrap()
        });
        assert_eq!(deepest, 1, "a loop item ran inside another's wait");
    }

    #[test]
    fn deterministic_for_a_seed() {
        let a = rank3_plus_noise(90, 200, 0.5, 8);
        let cfg = TruncatedSvdConfig {
            seed: 42,
            ..Default::default()
        };
        let t1 = truncated_svd(a.as_ref(), 4, &cfg).unwrap();
        assert!(
            matches!(t1.method, SvdMethod::Randomized { .. }),
            "{:?}",
            t1.fallback_reason
        );
        let t2 = truncated_svd(a.as_ref(), 4, &cfg).unwrap();
        assert_eq!(t1.s, t2.s);
        assert_eq!(t1.singular_values, t2.singular_values);
        assert_eq!(t1.u, t2.u);
        assert_eq!(t1.v, t2.v);
        assert_eq!(t1.method, t2.method);
        // Another seed gives a different sketch but the same leading triplets.
        let t3 = truncated_svd(a.as_ref(), 4, &TruncatedSvdConfig { seed: 7, ..cfg }).unwrap();
        assert_ne!(t1.singular_values, t3.singular_values);
        for i in 0..3 {
            assert!((t1.s[i] - t3.s[i]).abs() < 1e-10 * t1.s[i]);
        }
    }
}
