//! Generic RANSAC with MSAC scoring, adaptive iteration count, LO-RANSAC local optimization
//! and an optional robust noise-scale estimate.
//!
//! # Objective
//!
//! Items `i = 0..n` are scored against a model `θ` by a non-negative residual `r_i(θ)` (or
//! "cannot be scored", e.g. too little overlap with the model). With the inlier threshold
//! `τ`, the MSAC cost (Torr & Zisserman 2000) is the truncated quadratic
//!
//! `C(θ) = Σ_i min(r_i(θ)², τ²)`, unscored items costing `τ²` (as outliers),
//!
//! and RANSAC (Fischler & Bolles 1981) minimizes it over hypotheses fitted to random minimal
//! samples. Counting unscored items as outliers makes the comparison fair between hypotheses
//! that can score different numbers of items: one that explains more items with the same
//! residuals always wins. Inliers are the items with `r_i ≤ τ`.
//!
//! # Iteration count
//!
//! After each improvement the number of hypotheses needed to draw, with probability `p`
//! (`confidence`), at least one all-inlier sample of size `s` is updated from the current
//! inlier ratio `w`: `N = ⌈log(1 − p) / log(1 − wˢ)⌉`, clamped to
//! `[min_iterations, max_iterations]` (Fischler & Bolles 1981; Hartley & Zisserman 2004,
//! §4.7.1).
//!
//! # Local optimization
//!
//! Whenever a hypothesis becomes the best so far, it is refined: `θ ← refit(θ, inliers(θ))`,
//! re-scored, and kept while the MSAC cost decreases (until the inlier set no longer
//! changes), at most `lo_iterations` times
//! (the iterated least-squares variant of LO-RANSAC, Chum, Matas & Kittler, DAGM 2003).
//! A hypothesis that can score only part of the items (e.g. defined on few frames) costs
//! its unscored items as outliers and may lose to a broad but mediocre model before it is
//! refined; so a hypothesis whose inlier ratio *among the items it scores* beats the best
//! model's is locally optimized too, and replaces the best if its refined cost is lower.
//! Since the number of so-far-the-best hypotheses grows only logarithmically with the
//! number of draws, LO adds little to the total cost. Each refit uses at most
//! `lo_max_inliers` inliers (the first ones in the run's random item order), as LO-RANSAC's
//! inner fits use a bounded sample (Lebeda, Matas & Chum, "Fixing the locally optimized
//! RANSAC", BMVC 2012): the refit's cost is then independent of the number of inliers,
//! while the re-scoring (and so the acceptance of a refit) still covers all items.
//!
//! # Bail-out test
//!
//! Most hypotheses are hopeless, and scoring each on all `n` items dominates the cost. The
//! items are put in one random order per run; each hypothesis is scored in that order and
//! abandoned early: exactly when its partial cost already reaches the best cost (and its
//! scored-inlier ratio cannot beat the best's), and statistically (Capel, "An effective
//! bail-out test for RANSAC consensus scoring", BMVC 2005; in the spirit of the T(d,d)
//! pre-test of Matas & Chum, "Randomized RANSAC with T(d,d) test", BMVC 2002) when, after
//! 32, 64, 128, … items, Wilson intervals at `bail_out_z` standard errors say that its mean
//! per-item cost is above the best's and its scored-inlier ratio below the best's. A
//! hopeless hypothesis thus costs O(32) residuals instead of O(n); a better one is kept
//! with probability ≥ 1 − log₂(n/32)·Φ(−z) (0.99 at the default z = 3.09).
//!
//! # Unknown threshold
//!
//! With `threshold_px = None` the noise scale `σ` is estimated first, on `scale_subset`
//! items drawn at random (all when fewer): hypotheses are ranked by the
//! `scale_quantile`-quantile of their residuals (least quantile of squares,
//! Rousseeuw 1984, tolerant of up to `1 − scale_quantile` outliers); from the best one,
//! `σ = Estimator::sigma_from_residuals(residuals below that quantile)`, then iterated
//! `σ ← sigma_from_residuals({r_i ≤ κσ})` with a refit on those inliers (at most `lo_max_inliers`) between steps, where
//! `κ = Estimator::threshold_multiple(inlier_probability)` (for Gaussian residuals a
//! chi-square quantile). The MSAC run then uses `τ = κσ`; at the end `σ` is re-estimated
//! from the final inliers and, if `τ` moved, the final model is re-scored (and refitted
//! once) with the new threshold.
//!
//! # Many items
//!
//! With more than `max_scored_items` items (`M`), the run above is made on `M` items drawn
//! at random — hypotheses still come from samples of all items, but are scored, compared
//! and locally optimized on the `M` — and its final model is then scored on every item,
//! which gives the inliers, residuals and cost returned. The hypotheses' ranking needs
//! only estimates of their mean cost and inlier ratio, which `M` random items give to a
//! standard error of `≤ 0.5/√M` of their range (the principle of preemptive RANSAC,
//! Nistér, "Preemptive RANSAC for live structure and motion estimation", ICCV 2003, and of
//! the bail-out test above, applied to every hypothesis); the cost then no longer grows
//! with the number of items but for the one final scoring.
//!
//! # Complexity
//!
//! `O(iterations · (fit + j̄ · residual) + n · residual)` with `j̄ ≤ min(n, M)` the mean
//! number of items scored before bail-out (≈ 32–64 for hopeless hypotheses; `min(n, M)`
//! without bail-out), the scale bootstrap's the same with `min(n, scale_subset)` in place
//! of `n`, plus `O(#improvements · lo_iterations · (refit(min(inliers, lo_max_inliers)) +
//! min(n, M) · residual))`
//! (the full scoring through
//! [`Estimator::residuals`], which an estimator may parallelize).

use rand::{Rng, RngExt};

use crate::{Error, Event, NoopObserver, Observer, Result};

/// A model family for [`ransac`], in the style of kornia-rs's `ransac` module: a minimal
/// solver, a per-item residual and a local-optimization refit.
pub trait Estimator {
    /// The fitted model.
    type Model: Clone;

    /// Number of items in a minimal sample.
    fn min_sample_size(&self) -> usize;

    /// Fits a model to a minimal sample of item indices; `None` for a degenerate sample.
    fn fit(&self, sample: &[usize]) -> Option<Self::Model>;

    /// Residual of item `item` under `model` (non-negative, in the threshold's units);
    /// `None` when the item cannot be scored against this model (e.g. too little overlap).
    fn residual(&self, model: &Self::Model, item: usize) -> Option<f64>;

    /// Residuals of all items `0..n` (`residual` of each, in order). Override to compute
    /// them in parallel; the result must not depend on the thread count.
    fn residuals(&self, model: &Self::Model, n: usize) -> Vec<Option<f64>> {
        (0..n).map(|i| self.residual(model, i)).collect()
    }

    /// Residuals of the items `items` (`residual` of each, in that order). Override to
    /// compute them in parallel; the result must not depend on the thread count. The
    /// bail-out scoring asks for a block of items at a time ([`SCORE_BLOCK`]).
    fn residuals_of(&self, model: &Self::Model, items: &[usize]) -> Vec<Option<f64>> {
        items.iter().map(|&i| self.residual(model, i)).collect()
    }

    /// Local optimization: a (non-minimal) fit to the given inliers, starting from `model`.
    /// `None` when the inliers do not determine a model.
    fn refit(&self, model: &Self::Model, inliers: &[usize]) -> Option<Self::Model>;

    /// Draws a minimal sample into `out` (cleared first); `false` when no valid sample could
    /// be drawn. The default draws `min_sample_size` distinct items uniformly.
    fn sample<R: Rng + ?Sized>(&self, n_items: usize, rng: &mut R, out: &mut Vec<usize>) -> bool {
        out.clear();
        let s = self.min_sample_size();
        if n_items < s {
            return false;
        }
        while out.len() < s {
            let i = rng.random_range(0..n_items);
            if !out.contains(&i) {
                out.push(i);
            }
        }
        true
    }

    /// Noise scale `σ` from the residuals of (presumed) inliers. The default assumes absolute
    /// Gaussian residuals: `1.4826 · median`.
    fn sigma_from_residuals(&self, inlier_residuals: &[f64]) -> f64 {
        1.4826 * crate::eval::median(inlier_residuals)
    }

    /// `κ` such that an inlier's residual is below `κσ` with probability `p`. The default
    /// assumes absolute Gaussian residuals: `κ = sqrt(χ²₁(p))`.
    fn threshold_multiple(&self, p: f64) -> f64 {
        super::chi2_quantile(1.0, p).sqrt()
    }
}

/// RANSAC settings. Every field has a documented default.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct RansacConfig {
    /// Inlier threshold `τ` on the residual (pixels for the track estimator). `None`
    /// (default): estimate the noise scale robustly and use `τ = κσ` (see the module
    /// documentation).
    pub threshold_px: Option<f64>,
    /// Probability `p` of drawing at least one all-inlier sample, for the adaptive iteration
    /// count. Default 0.999.
    pub confidence: f64,
    /// Hypotheses drawn at most. Default 2000.
    pub max_iterations: usize,
    /// Hypotheses drawn at least (guards against an optimistic early inlier ratio).
    /// Default 50.
    pub min_iterations: usize,
    /// LO-RANSAC local optimization of every so-far-the-best hypothesis. Default true.
    pub local_optimization: bool,
    /// Refit/re-score rounds per local optimization. Default 5.
    pub lo_iterations: usize,
    /// A local-optimization refit uses at most this many of the inliers, the first ones
    /// in the run's random item order (Lebeda, Matas & Chum, BMVC 2012, bound the LO
    /// sample likewise); the re-scoring still covers all items. 0 = all inliers. Default
    /// 256: the affine subspace of 256 tracks is determined to well below the noise, and
    /// the refit's cost no longer grows with the number of inliers.
    pub lo_max_inliers: usize,
    /// Attempts to draw a non-degenerate sample per iteration. Default 20.
    pub max_sample_attempts: usize,
    /// Probability that an inlier's residual is below the estimated threshold (`κ` is
    /// `Estimator::threshold_multiple` of it). Used only when `threshold_px` is `None`.
    /// Default 0.999.
    pub inlier_probability: f64,
    /// Quantile minimized by the scale-bootstrap hypotheses (least quantile of squares).
    /// Used only when `threshold_px` is `None`. Default 0.25 (tolerates 75 % outliers).
    pub scale_quantile: f64,
    /// Rounds of the `σ` fixed-point iteration. Default 5.
    pub sigma_iterations: usize,
    /// The scale bootstrap draws enough hypotheses to hit, with probability `confidence`,
    /// an all-inlier sample when at least this fraction of the items are inliers
    /// (`N = log(1 − p)/log(1 − wˢ)`, 267 for w = 0.4, s = 4). Default 0.4.
    pub scale_min_inlier_ratio: f64,
    /// The scale bootstrap (least-quantile ranking and `σ` fixed point) scores this many
    /// items drawn at random (all of them when there are fewer). Default 400: the
    /// `scale_quantile` of 400 residuals ranks hypotheses as well as that of all items, and
    /// the median of ~300 inlier residuals gives `σ` to a few per cent, which the final
    /// re-estimation from all inliers then refines.
    pub scale_subset: usize,
    /// Bail-out test (see the module documentation): score each hypothesis on the items
    /// in a random order and abandon it as soon as a one-sided test at `bail_out_z`
    /// standard errors says it can beat neither the best cost nor the best scored-inlier
    /// ratio. `None` scores every hypothesis fully (up to the exact bound). Default
    /// `Some(3.09)` (one-sided 0.001 per test).
    pub bail_out_z: Option<f64>,
    /// With more items than this, the hypotheses are scored (and locally optimized) on
    /// this many items drawn at random, and only the final model on all of them (see the
    /// module documentation, *Many items*). 0 = always all items. Default 4096: an inlier
    /// ratio or a mean cost from 4096 random items has a standard error under 0.8 % of
    /// its range, and the sample-based model is then judged on every item.
    #[serde(default = "default_max_scored_items")]
    pub max_scored_items: usize,
}

fn default_max_scored_items() -> usize {
    4096
}

impl Default for RansacConfig {
    fn default() -> Self {
        Self {
            threshold_px: None,
            confidence: 0.999,
            max_iterations: 2000,
            min_iterations: 50,
            local_optimization: true,
            lo_iterations: 5,
            lo_max_inliers: 256,
            max_sample_attempts: 20,
            inlier_probability: 0.999,
            scale_quantile: 0.25,
            sigma_iterations: 5,
            scale_min_inlier_ratio: 0.4,
            scale_subset: 400,
            bail_out_z: Some(3.09),
            max_scored_items: default_max_scored_items(),
        }
    }
}

impl RansacConfig {
    /// Checks ranges; errors name the field.
    pub fn validate(&self) -> Result<()> {
        let bad =
            |field: &'static str, message: String| Err(Error::InvalidConfig { field, message });
        if let Some(t) = self.threshold_px
            && !(t > 0.0 && t.is_finite())
        {
            return bad("ransac.threshold_px", format!("{t} is not positive"));
        }
        if !(self.confidence > 0.0 && self.confidence < 1.0) {
            return bad(
                "ransac.confidence",
                format!("{} is not in (0, 1)", self.confidence),
            );
        }
        if self.max_iterations == 0 || self.min_iterations > self.max_iterations {
            return bad(
                "ransac.max_iterations",
                format!(
                    "need 0 < min_iterations ({}) ≤ max_iterations ({})",
                    self.min_iterations, self.max_iterations
                ),
            );
        }
        if self.max_sample_attempts == 0 {
            return bad("ransac.max_sample_attempts", "must be ≥ 1".into());
        }
        if !(self.inlier_probability > 0.5 && self.inlier_probability < 1.0) {
            return bad(
                "ransac.inlier_probability",
                format!("{} is not in (0.5, 1)", self.inlier_probability),
            );
        }
        if !(self.scale_quantile > 0.0 && self.scale_quantile <= 0.5) {
            return bad(
                "ransac.scale_quantile",
                format!("{} is not in (0, 0.5]", self.scale_quantile),
            );
        }
        if !(self.scale_min_inlier_ratio > 0.0 && self.scale_min_inlier_ratio <= 1.0) {
            return bad(
                "ransac.scale_min_inlier_ratio",
                format!("{} is not in (0, 1]", self.scale_min_inlier_ratio),
            );
        }
        if self.scale_subset < 16 {
            return bad(
                "ransac.scale_subset",
                format!("{} < 16 items cannot rank hypotheses", self.scale_subset),
            );
        }
        if let Some(z) = self.bail_out_z
            && !(z > 0.0 && z.is_finite())
        {
            return bad("ransac.bail_out_z", format!("{z} is not positive"));
        }
        Ok(())
    }
}

/// How a RANSAC run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum RansacStatus {
    /// The adaptive iteration count `N(w, p)` was reached.
    Converged,
    /// `max_iterations` hypotheses were drawn before `N(w, p)` was reached: the confidence
    /// `p` is not guaranteed.
    MaxIterations,
    /// No non-degenerate sample could be drawn or fitted: there is no model.
    NoModel,
}

/// Result of [`ransac`].
#[derive(Debug, Clone)]
pub struct RansacResult<M> {
    /// The best model after local optimization (`None` only with [`RansacStatus::NoModel`]).
    pub model: Option<M>,
    /// Inlier flag per item (`r_i ≤ threshold`).
    pub inliers: Vec<bool>,
    /// Residual per item under `model` (`None`: cannot be scored).
    pub residuals: Vec<Option<f64>>,
    /// Hypotheses drawn in the MSAC phase (the scale bootstrap's are in `scale_iterations`).
    pub iterations: usize,
    /// Hypotheses drawn by the scale bootstrap (0 when the threshold was given).
    pub scale_iterations: usize,
    /// MSAC cost `Σ min(r², τ²)` of `model` (lower is better).
    pub score: f64,
    pub n_inliers: usize,
    /// Threshold `τ` used for the final inlier decision.
    pub threshold: f64,
    /// Estimated noise scale `σ` (`None` when the threshold was given).
    pub sigma: Option<f64>,
    /// Local-optimization refits that improved the cost.
    pub lo_improvements: usize,
    pub status: RansacStatus,
}

struct Scored<M> {
    model: M,
    residuals: Vec<Option<f64>>,
    cost: f64,
    n_in: usize,
    n_scored: usize,
}

impl<M> Scored<M> {
    /// Inlier ratio among the items this model can score.
    fn scored_ratio(&self) -> f64 {
        if self.n_scored == 0 {
            0.0
        } else {
            self.n_in as f64 / self.n_scored as f64
        }
    }
}

fn score<E: Estimator>(est: &E, model: E::Model, n: usize, tau: f64) -> Scored<E::Model> {
    let residuals = est.residuals(&model, n);
    let t2 = tau * tau;
    let mut cost = 0.0;
    let mut n_in = 0;
    for r in &residuals {
        match r {
            Some(r) if r.is_finite() && *r <= tau => {
                cost += r * r;
                n_in += 1;
            }
            _ => cost += t2,
        }
    }
    let n_scored = residuals.iter().filter(|r| r.is_some()).count();
    Scored {
        model,
        residuals,
        cost,
        n_in,
        n_scored,
    }
}

/// Wilson score interval `[lo, hi]` at `z` standard errors for a proportion `p̂` estimated
/// from `j` trials; used with `p̂` the mean of a variable in `[0, 1]` (whose variance is
/// at most `p̂(1 − p̂)`, the Bernoulli case).
fn wilson(p: f64, j: f64, z: f64) -> (f64, f64) {
    let z2 = z * z;
    let centre = p + z2 / (2.0 * j);
    let half = z * (p * (1.0 - p) / j + z2 / (4.0 * j * j)).max(0.0).sqrt();
    let d = 1.0 + z2 / j;
    ((centre - half) / d, (centre + half) / d)
}

/// First item count at which the bail-out tests are applied; later at doubling counts.
const BAIL_OUT_FIRST: usize = 32;

/// Items whose residuals the bail-out scoring computes at once ([`Estimator::residuals_of`],
/// which an estimator may spread over threads): blocks end at the bail-out tests' counts
/// and are at most this long. The items are still judged one by one in order, so the
/// outcome is that of scoring one item at a time; a hypothesis abandoned inside a block
/// wastes at most the rest of the block.
pub const SCORE_BLOCK: usize = 256;

/// Ends of the scoring blocks over `n` items: the bail-out counts 32, 64, 128, … and every
/// [`SCORE_BLOCK`] items in between, then `n`.
fn block_ends(n: usize) -> impl Iterator<Item = usize> {
    let mut end = 0;
    let mut check = BAIL_OUT_FIRST;
    std::iter::from_fn(move || {
        if end >= n {
            return None;
        }
        end = (end + SCORE_BLOCK).min(check).min(n);
        if end == check {
            check *= 2;
        }
        Some(end)
    })
}

/// MSAC scoring of `model` over the items in `order` (a permutation of `0..n`) that gives
/// up (returns `None`) as soon as the hypothesis can neither beat the cost `bound` nor the
/// scored-inlier ratio `ratio_bound`.
///
/// * Exact bound: the partial cost is a lower bound of the cost (non-negative terms), and
///   with `o` scored outliers among `n` items the ratio is at most `1 − o/n`.
/// * Bail-out (Capel, BMVC 2005), with `z = Some(z)`: after `j = 32, 64, 128, …` items of
///   the random order, the mean per-item cost `c̄` (in units of `τ²`, a variable in
///   `[0, 1]`) and the scored-inlier ratio have Wilson intervals at `z` standard errors; the
///   hypothesis is abandoned when the lower end of the cost interval exceeds the best's
///   mean cost `bound / (n τ²)` *and* the upper end of the ratio interval is below
///   `ratio_bound`. Each test wrongly abandons a better hypothesis with probability about
///   `Φ(−z)`, so a good hypothesis survives all `log₂(n/32)` tests with probability
///   `≥ 1 − log₂(n/32) Φ(−z)` (0.99 for z = 3.09, n = 2000); cost O(j) instead of O(n)
///   for the typical hopeless hypothesis.
fn score_bounded<E: Estimator>(
    est: &E,
    model: E::Model,
    order: &[usize],
    tau: f64,
    bound: f64,
    ratio_bound: f64,
    z: Option<f64>,
) -> Option<Scored<E::Model>> {
    let n = order.len();
    let t2 = tau * tau;
    let mut residuals = vec![None; n];
    let mut cost = 0.0;
    let mut n_in = 0;
    let mut n_scored = 0;
    let mut scored_out = 0usize;
    let mut check = BAIL_OUT_FIRST;
    let mut block: Vec<Option<f64>> = Vec::new();
    let mut ends = block_ends(n);
    let mut block_start = 0;
    for (j, &i) in order.iter().enumerate() {
        if j == block_start + block.len() {
            block_start = j;
            let end = ends.next().unwrap_or(n);
            block = est.residuals_of(&model, &order[j..end]);
        }
        let r = block[j - block_start];
        if r.is_some() {
            n_scored += 1;
        }
        match r {
            Some(r) if r.is_finite() && r <= tau => {
                cost += r * r;
                n_in += 1;
            }
            Some(_) => {
                cost += t2;
                scored_out += 1;
            }
            None => cost += t2,
        }
        if cost >= bound && 1.0 - scored_out as f64 / n as f64 <= ratio_bound {
            return None;
        }
        residuals[i] = r;
        if j + 1 == check && j + 1 < n {
            check *= 2;
            if let Some(z) = z
                && bound.is_finite()
                && t2 > 0.0
            {
                let jf = (j + 1) as f64;
                let (cost_lo, _) = wilson((cost / (jf * t2)).min(1.0), jf, z);
                let hopeless_cost = cost_lo > bound / (n as f64 * t2);
                let hopeless_ratio = n_scored > 0 && {
                    let (_, hi) = wilson(n_in as f64 / n_scored as f64, n_scored as f64, z);
                    hi < ratio_bound
                };
                if hopeless_cost && hopeless_ratio {
                    return None;
                }
            }
        }
    }
    Some(Scored {
        model,
        residuals,
        cost,
        n_in,
        n_scored,
    })
}

/// Residuals of the items `items` (in that order, which is random) for the least-quantile
/// bootstrap, or `None` once the `k`-th smallest cannot be below `bound`: exactly, when more
/// than `len − k` items have a residual ≥ `bound`; and, with `z = Some(z)`, when after
/// `j = 32, 64, …` items the Wilson upper bound of the fraction below `bound` is below
/// `k / len` (see [`score_bounded`]).
fn residuals_bounded<E: Estimator>(
    est: &E,
    model: &E::Model,
    items: &[usize],
    k: usize,
    bound: f64,
    z: Option<f64>,
) -> Option<Vec<Option<f64>>> {
    let m = items.len();
    let mut out = Vec::with_capacity(m);
    let mut above = 0;
    let mut check = BAIL_OUT_FIRST;
    let mut block: Vec<Option<f64>> = Vec::new();
    let mut ends = block_ends(m);
    let mut block_start = 0;
    for j in 0..m {
        if j == block_start + block.len() {
            block_start = j;
            let end = ends.next().unwrap_or(m);
            block = est.residuals_of(model, &items[j..end]);
        }
        let r = block[j - block_start];
        if r.is_none_or(|r| !(r < bound)) {
            above += 1;
            if above > m - k {
                return None;
            }
        }
        out.push(r);
        if j + 1 == check && j + 1 < m {
            check *= 2;
            if let Some(z) = z
                && bound.is_finite()
            {
                let jf = (j + 1) as f64;
                let (_, hi) = wilson((jf - above as f64) / jf, jf, z);
                if hi < k as f64 / m as f64 {
                    return None;
                }
            }
        }
    }
    Some(out)
}

/// Per item: its residual is at most `tau` (an unscored item is not an inlier).
fn inlier_flags(residuals: &[Option<f64>], tau: f64) -> Vec<bool> {
    residuals
        .iter()
        .map(|r| matches!(r, Some(r) if *r <= tau))
        .collect()
}

fn inlier_indices(residuals: &[Option<f64>], tau: f64) -> Vec<usize> {
    residuals
        .iter()
        .enumerate()
        .filter(|(_, r)| matches!(r, Some(r) if *r <= tau))
        .map(|(i, _)| i)
        .collect()
}

/// `N = ⌈log(1 − p) / log(1 − wˢ)⌉` clamped to `[lo, hi]`.
pub fn adaptive_iterations(
    inlier_ratio: f64,
    sample_size: usize,
    confidence: f64,
    lo: usize,
    hi: usize,
) -> usize {
    let ws = inlier_ratio.clamp(0.0, 1.0).powi(sample_size as i32);
    let n = if ws >= 1.0 - 1e-15 {
        0.0
    } else if ws <= 1e-300 {
        f64::INFINITY
    } else {
        ((1.0 - confidence).ln() / (1.0 - ws).ln()).ceil()
    };
    if n.is_finite() {
        (n.max(0.0) as usize).clamp(lo, hi)
    } else {
        hi
    }
}

/// Iterated least-squares local optimization (LO-RANSAC): refit on the inliers (at most
/// `max_inliers` of them, the first in `order`; 0 = all) while the MSAC cost decreases
/// and the inlier set changes.
fn local_optimize<E: Estimator>(
    est: &E,
    mut best: Scored<E::Model>,
    order: &[usize],
    tau: f64,
    rounds: usize,
    max_inliers: usize,
    improvements: &mut usize,
) -> Scored<E::Model> {
    let n = order.len();
    for _ in 0..rounds {
        let mut inl = inlier_indices(&best.residuals, tau);
        if max_inliers > 0 && inl.len() > max_inliers {
            inl = order
                .iter()
                .copied()
                .filter(|&i| matches!(best.residuals[i], Some(r) if r <= tau))
                .take(max_inliers)
                .collect();
            inl.sort_unstable();
        }
        if inl.len() < est.min_sample_size() {
            break;
        }
        let Some(m) = est.refit(&best.model, &inl) else {
            break;
        };
        let cand = score(est, m, n, tau);
        if cand.cost < best.cost * (1.0 - 1e-9) {
            // Converged when the inliers did not change: the next refit would fit the
            // same entries from (nearly) the same start.
            let same = (0..n).all(|i| {
                matches!(cand.residuals[i], Some(r) if r <= tau)
                    == matches!(best.residuals[i], Some(r) if r <= tau)
            });
            best = cand;
            *improvements += 1;
            if same {
                break;
            }
        } else {
            break;
        }
    }
    best
}

/// The items `items` of `est` (indices into them are this estimator's items); samples are
/// still drawn from all `n_all` items of `est`, whose item numbers the samples and fits
/// keep.
struct Subset<'a, E> {
    est: &'a E,
    items: &'a [usize],
    n_all: usize,
}

impl<E: Estimator> Estimator for Subset<'_, E> {
    type Model = E::Model;
    fn min_sample_size(&self) -> usize {
        self.est.min_sample_size()
    }
    fn fit(&self, sample: &[usize]) -> Option<E::Model> {
        self.est.fit(sample)
    }
    fn residual(&self, model: &E::Model, item: usize) -> Option<f64> {
        self.est.residual(model, self.items[item])
    }
    fn residuals(&self, model: &E::Model, n: usize) -> Vec<Option<f64>> {
        self.est.residuals_of(model, &self.items[..n])
    }
    fn residuals_of(&self, model: &E::Model, items: &[usize]) -> Vec<Option<f64>> {
        let mapped: Vec<usize> = items.iter().map(|&j| self.items[j]).collect();
        self.est.residuals_of(model, &mapped)
    }
    fn refit(&self, model: &E::Model, inliers: &[usize]) -> Option<E::Model> {
        let mut mapped: Vec<usize> = inliers.iter().map(|&j| self.items[j]).collect();
        mapped.sort_unstable();
        self.est.refit(model, &mapped)
    }
    fn sample<R: Rng + ?Sized>(&self, _n_items: usize, rng: &mut R, out: &mut Vec<usize>) -> bool {
        self.est.sample(self.n_all, rng, out)
    }
    fn sigma_from_residuals(&self, inlier_residuals: &[f64]) -> f64 {
        self.est.sigma_from_residuals(inlier_residuals)
    }
    fn threshold_multiple(&self, p: f64) -> f64 {
        self.est.threshold_multiple(p)
    }
}

/// [`ransac_observed`] with more than `max_scored_items` items: the run on that many
/// items drawn at random (module documentation, *Many items*), its model then scored on
/// all `n` items. `O(n)` beyond the subset's run.
fn ransac_on_subset<E: Estimator, R: Rng + ?Sized>(
    est: &E,
    n: usize,
    config: &RansacConfig,
    rng: &mut R,
    observer: &mut dyn Observer,
    run: usize,
) -> Result<RansacResult<E::Model>> {
    let m = config.max_scored_items;
    // The first m of a random permutation (partial Fisher–Yates), in item order.
    let mut order: Vec<usize> = (0..n).collect();
    for i in 0..m {
        order.swap(i, rng.random_range(i..n));
    }
    order.truncate(m);
    order.sort_unstable();
    let sub = Subset {
        est,
        items: &order,
        n_all: n,
    };
    let r = ransac_all(&sub, m, config, rng, observer, run)?;
    let Some(model) = r.model else {
        return Ok(RansacResult {
            model: None,
            inliers: vec![false; n],
            residuals: vec![None; n],
            ..r
        });
    };
    let best = score(est, model, n, r.threshold);
    let inliers = inlier_flags(&best.residuals, r.threshold);
    Ok(RansacResult {
        model: Some(best.model),
        n_inliers: best.n_in,
        inliers,
        residuals: best.residuals,
        score: best.cost,
        ..r
    })
}

/// Draws one hypothesis: up to `attempts` samples until one fits.
fn draw<E: Estimator, R: Rng + ?Sized>(
    est: &E,
    n: usize,
    attempts: usize,
    rng: &mut R,
    buf: &mut Vec<usize>,
) -> Option<E::Model> {
    for _ in 0..attempts {
        if est.sample(n, rng, buf)
            && let Some(m) = est.fit(buf)
        {
            return Some(m);
        }
    }
    None
}

/// Value of the `q`-quantile of residuals, unscored items counting as `+∞`.
fn quantile_residual(residuals: &[Option<f64>], q: f64) -> f64 {
    let mut v: Vec<f64> = residuals
        .iter()
        .map(|r| r.filter(|x| x.is_finite()).unwrap_or(f64::INFINITY))
        .collect();
    if v.is_empty() {
        return f64::INFINITY;
    }
    let k = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1;
    let (_, x, _) = v.select_nth_unstable_by(k, |a, b| a.total_cmp(b));
    *x
}

fn residuals_below(residuals: &[Option<f64>], tau: f64) -> Vec<f64> {
    residuals
        .iter()
        .filter_map(|r| r.filter(|x| *x <= tau))
        .collect()
}

/// [`ransac_observed`] without an observer.
pub fn ransac<E: Estimator, R: Rng + ?Sized>(
    est: &E,
    n_items: usize,
    config: &RansacConfig,
    rng: &mut R,
) -> Result<RansacResult<E::Model>> {
    ransac_observed(est, n_items, config, rng, &mut NoopObserver, 0)
}

/// RANSAC/MSAC with LO over items `0..n_items`; see the module documentation.
///
/// Emits `Event::Iteration { solver: "ransac", run, iteration, cost: best MSAC cost so far,
/// rms: NaN, lambda: best inlier count so far }` per MSAC hypothesis, and the same with
/// `solver: "ransac-scale"` (cost: best residual quantile) per scale-bootstrap hypothesis.
///
/// Errors: invalid configuration, or fewer items than a minimal sample.
pub fn ransac_observed<E: Estimator, R: Rng + ?Sized>(
    est: &E,
    n_items: usize,
    config: &RansacConfig,
    rng: &mut R,
    observer: &mut dyn Observer,
    run: usize,
) -> Result<RansacResult<E::Model>> {
    config.validate()?;
    let s = est.min_sample_size();
    if n_items < s {
        return Err(Error::TooFew {
            what: "items for a RANSAC minimal sample",
            needed: s,
            have: n_items,
        });
    }
    if config.max_scored_items > 0 && n_items > config.max_scored_items.max(s) {
        return ransac_on_subset(est, n_items, config, rng, observer, run);
    }
    ransac_all(est, n_items, config, rng, observer, run)
}

/// [`ransac_observed`] scoring every item (the configuration checked by the caller).
fn ransac_all<E: Estimator, R: Rng + ?Sized>(
    est: &E,
    n_items: usize,
    config: &RansacConfig,
    rng: &mut R,
    observer: &mut dyn Observer,
    run: usize,
) -> Result<RansacResult<E::Model>> {
    let s = est.min_sample_size();
    let n = n_items;
    let mut buf = Vec::with_capacity(s);
    let mut lo_improvements = 0;
    let no_model = |iterations, scale_iterations| RansacResult {
        model: None,
        inliers: vec![false; n],
        residuals: vec![None; n],
        iterations,
        scale_iterations,
        score: f64::INFINITY,
        n_inliers: 0,
        threshold: config.threshold_px.unwrap_or(f64::NAN),
        sigma: None,
        lo_improvements: 0,
        status: RansacStatus::NoModel,
    };

    // A random order of the items: the scale bootstrap's subset is its head, and the MSAC
    // hypotheses are scored in this order (bail-out test).
    let mut order: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        order.swap(i, rng.random_range(0..=i));
    }

    // Phase 1 (unknown threshold): least-quantile hypotheses, then σ by fixed point.
    let kappa = est.threshold_multiple(config.inlier_probability);
    let mut scale_iterations = 0;
    let mut sigma = None;
    let tau = match config.threshold_px {
        Some(t) => t,
        None => {
            let budget = adaptive_iterations(
                config.scale_min_inlier_ratio,
                s,
                config.confidence,
                config.min_iterations,
                config.max_iterations,
            );
            // Scale bootstrap on a random subset of the items (in random order).
            let sub: Vec<usize> = order[..config.scale_subset.min(n)].to_vec();
            let m_sub = sub.len();
            let k = ((config.scale_quantile * m_sub as f64).ceil() as usize).clamp(1, m_sub);
            let mut best: Option<(f64, E::Model, Vec<Option<f64>>)> = None;
            for it in 0..budget {
                scale_iterations = it + 1;
                if let Some(m) = draw(est, n, config.max_sample_attempts, rng, &mut buf) {
                    let bound = best.as_ref().map_or(f64::INFINITY, |b| b.0);
                    if let Some(res) = residuals_bounded(est, &m, &sub, k, bound, config.bail_out_z)
                    {
                        let q = quantile_residual(&res, config.scale_quantile);
                        if q < bound {
                            best = Some((q, m, res));
                        }
                    }
                }
                observer.on_event(&Event::Iteration {
                    solver: "ransac-scale",
                    run,
                    iteration: it,
                    cost: best.as_ref().map_or(f64::INFINITY, |b| b.0),
                    rms: f64::NAN,
                    lambda: f64::NAN,
                });
            }
            let Some((q, mut model, mut res)) = best.filter(|b| b.0.is_finite()) else {
                return Ok(no_model(0, scale_iterations));
            };
            let mut sg = est.sigma_from_residuals(&residuals_below(&res, q));
            for _ in 0..config.sigma_iterations {
                if !(sg > 0.0 && sg.is_finite()) {
                    break;
                }
                let t = kappa * sg;
                // `sub` is in random order: its first inliers are a random subsample.
                let mut inl: Vec<usize> = inlier_indices(&res, t)
                    .into_iter()
                    .map(|j| sub[j])
                    .collect();
                if config.lo_max_inliers > 0 {
                    inl.truncate(config.lo_max_inliers);
                }
                if inl.len() >= s
                    && let Some(m) = est.refit(&model, &inl)
                {
                    model = m;
                    res = sub.iter().map(|&i| est.residual(&model, i)).collect();
                }
                let new = est.sigma_from_residuals(&residuals_below(&res, t));
                let done = (new - sg).abs() <= 1e-3 * sg;
                sg = new;
                if done {
                    break;
                }
            }
            if !(sg > 0.0 && sg.is_finite()) {
                // Noise-free data: any positive floor relative to the data works; use the
                // smallest positive residual scale available.
                sg = residuals_below(&res, f64::INFINITY)
                    .into_iter()
                    .filter(|r| *r > 0.0)
                    .fold(f64::INFINITY, f64::min);
                if !sg.is_finite() {
                    sg = 1e-12;
                }
            }
            sigma = Some(sg);
            kappa * sg
        }
    };

    // Phase 2: MSAC with LO.
    let mut best: Option<Scored<E::Model>> = None;
    let mut needed = config.max_iterations;
    let mut iterations = 0;
    while iterations < needed.max(config.min_iterations) && iterations < config.max_iterations {
        iterations += 1;
        if let Some(m) = draw(est, n, config.max_sample_attempts, rng, &mut buf) {
            let bound = best.as_ref().map_or(f64::INFINITY, |b| b.cost);
            let ratio_bound = best.as_ref().map_or(0.0, |b| b.scored_ratio());
            let cand = score_bounded(est, m, &order, tau, bound, ratio_bound, config.bail_out_z)
                .filter(|c| {
                    c.cost < bound
                        || (config.local_optimization
                            && c.n_in >= s
                            && c.scored_ratio() > ratio_bound)
                });
            if let Some(cand) = cand {
                let cand = if config.local_optimization {
                    local_optimize(
                        est,
                        cand,
                        &order,
                        tau,
                        config.lo_iterations,
                        config.lo_max_inliers,
                        &mut lo_improvements,
                    )
                } else {
                    cand
                };
                if cand.cost < bound {
                    needed = adaptive_iterations(
                        cand.n_in as f64 / n as f64,
                        s,
                        config.confidence,
                        config.min_iterations,
                        config.max_iterations,
                    );
                    best = Some(cand);
                }
            }
        }
        observer.on_event(&Event::Iteration {
            solver: "ransac",
            run,
            iteration: iterations - 1,
            cost: best.as_ref().map_or(f64::INFINITY, |b| b.cost),
            rms: f64::NAN,
            lambda: best.as_ref().map_or(0.0, |b| b.n_in as f64),
        });
    }
    let status = if iterations >= needed.max(config.min_iterations) {
        RansacStatus::Converged
    } else {
        RansacStatus::MaxIterations
    };
    let Some(mut best) = best else {
        return Ok(no_model(iterations, scale_iterations));
    };

    // Phase 3 (estimated threshold): re-estimate σ from the final inliers.
    let mut tau = tau;
    if sigma.is_some() {
        let sg = est.sigma_from_residuals(&residuals_below(&best.residuals, tau));
        if sg > 0.0 && sg.is_finite() {
            let t = kappa * sg;
            if (t - tau).abs() > 0.02 * tau {
                tau = t;
                best = score(est, best.model, n, tau);
                if config.local_optimization {
                    best = local_optimize(
                        est,
                        best,
                        &order,
                        tau,
                        1,
                        config.lo_max_inliers,
                        &mut lo_improvements,
                    );
                }
            }
            sigma = Some(sg);
        }
    }
    let inliers = inlier_flags(&best.residuals, tau);
    Ok(RansacResult {
        model: Some(best.model),
        n_inliers: best.n_in,
        inliers,
        residuals: best.residuals,
        iterations,
        scale_iterations,
        score: best.cost,
        threshold: tau,
        sigma,
        lo_improvements,
        status,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand::rngs::StdRng;

    /// Line fitting y = a x + b with absolute vertical residuals: a textbook check of the
    /// generic machinery.
    struct Line {
        pts: Vec<(f64, f64)>,
    }

    impl Estimator for Line {
        type Model = (f64, f64);
        fn min_sample_size(&self) -> usize {
            2
        }
        fn fit(&self, s: &[usize]) -> Option<(f64, f64)> {
            let (p, q) = (self.pts[s[0]], self.pts[s[1]]);
            if (q.0 - p.0).abs() < 1e-9 {
                return None;
            }
            let a = (q.1 - p.1) / (q.0 - p.0);
            Some((a, p.1 - a * p.0))
        }
        fn residual(&self, m: &(f64, f64), i: usize) -> Option<f64> {
            let (x, y) = self.pts[i];
            Some((y - m.0 * x - m.1).abs())
        }
        fn refit(&self, _m: &(f64, f64), inl: &[usize]) -> Option<(f64, f64)> {
            let n = inl.len() as f64;
            let (mut sx, mut sy, mut sxx, mut sxy) = (0.0, 0.0, 0.0, 0.0);
            for &i in inl {
                let (x, y) = self.pts[i];
                sx += x;
                sy += y;
                sxx += x * x;
                sxy += x * y;
            }
            let d = n * sxx - sx * sx;
            if d.abs() < 1e-12 {
                return None;
            }
            let a = (n * sxy - sx * sy) / d;
            Some((a, (sy - a * sx) / n))
        }
    }

    fn line_data(seed: u64) -> (Line, Vec<bool>) {
        let mut rng = StdRng::seed_from_u64(seed);
        let mut pts = Vec::new();
        let mut out = Vec::new();
        for i in 0..200 {
            let x = i as f64 * 0.05;
            if i % 5 < 2 {
                pts.push((x, rng.random_range(-20.0..20.0)));
                out.push(true);
            } else {
                let e: f64 = rng.random_range(-0.1..0.1);
                pts.push((x, 2.0 * x - 1.0 + e));
                out.push(false);
            }
        }
        (Line { pts }, out)
    }

    #[test]
    fn fits_a_line_with_40_percent_outliers_known_and_estimated_threshold() {
        let (line, out) = line_data(1);
        for thr in [Some(0.3), None] {
            let cfg = RansacConfig {
                threshold_px: thr,
                ..Default::default()
            };
            let r = ransac(&line, 200, &cfg, &mut StdRng::seed_from_u64(5)).unwrap();
            let (a, b) = r.model.unwrap();
            assert!((a - 2.0).abs() < 0.02 && (b + 1.0).abs() < 0.1, "{a} {b}");
            let inlier_true = r
                .inliers
                .iter()
                .zip(&out)
                .filter(|(i, o)| **i && !**o)
                .count();
            assert!(inlier_true >= 118, "{inlier_true} of 120 inliers found");
            let wrong = r
                .inliers
                .iter()
                .zip(&out)
                .filter(|(i, o)| **i && **o)
                .count();
            assert!(wrong <= 2, "{wrong} outliers accepted");
            assert!(r.status == RansacStatus::Converged);
            if thr.is_none() {
                // Uniform noise in ±0.1 has σ = 0.058.
                let s = r.sigma.unwrap();
                assert!(s > 0.03 && s < 0.09, "σ = {s}");
            }
        }
    }

    /// Scoring blocks end at every bail-out count and are at most `SCORE_BLOCK` long.
    #[test]
    fn scoring_blocks_end_at_the_bail_out_counts() {
        let ends = |n| block_ends(n).collect::<Vec<_>>();
        assert_eq!(ends(0), Vec::<usize>::new());
        assert_eq!(ends(10), vec![10]);
        assert_eq!(ends(32), vec![32]);
        assert_eq!(ends(1000), vec![32, 64, 128, 256, 512, 768, 1000]);
        assert_eq!(ends(1100), vec![32, 64, 128, 256, 512, 768, 1024, 1100]);
    }

    #[test]
    fn adaptive_count_formula() {
        // w = 0.5, s = 4, p = 0.99: log(0.01)/log(15/16) = 71.4 → 72.
        assert_eq!(adaptive_iterations(0.5, 4, 0.99, 1, 1000), 72);
        assert_eq!(adaptive_iterations(1.0, 4, 0.99, 10, 1000), 10);
        assert_eq!(adaptive_iterations(0.0, 4, 0.99, 10, 1000), 1000);
    }

    #[test]
    fn too_few_items_and_bad_config_are_errors() {
        let (line, _) = line_data(2);
        let cfg = RansacConfig::default();
        assert!(matches!(
            ransac(&line, 1, &cfg, &mut StdRng::seed_from_u64(0)),
            Err(Error::TooFew { .. })
        ));
        let bad = RansacConfig {
            confidence: 1.0,
            ..Default::default()
        };
        assert!(matches!(
            ransac(&line, 200, &bad, &mut StdRng::seed_from_u64(0)),
            Err(Error::InvalidConfig { .. })
        ));
    }
}
