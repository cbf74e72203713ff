//! Robust factorization: rejection of outlier tracks and of gross per-entry errors.
//!
//! Trackers make two kinds of mistakes: a whole track follows the wrong thing (slides
//! along an edge, jumps to another object, belongs to an independently moving object), and
//! a good track has a few gross errors. [`robust_filter`] finds both:
//!
//! 1. **Outlier tracks**: RANSAC/MSAC with LO-RANSAC local optimization ([`ransac`](mod@ransac)) over
//!    the tracks, with the affine-subspace track estimator ([`subspace::TrackSubspace`]):
//!    rigid trajectories span a 3-dimensional affine subspace of R^{2F}; a minimal sample
//!    of 4 tracks is a hypothesis, a track's residual is its trimmed RMS distance to the
//!    subspace over the frames it shares with it. Works with missing data (overlap-aware
//!    sampling, unscored tracks cost as outliers, refit by an affine factorization over
//!    all frames).
//! 2. **Noise level**: unless `ransac.threshold_px` is given, `σ` is estimated robustly
//!    (least-quantile bootstrap, then the fixed point `σ = median{r ≤ κσ}`) and the track
//!    threshold is `τ = κσ`, `κ = sqrt(χ²_ν(p)/ν)` (see [`subspace`]).
//! 3. **Gross entries and final classification**: the model is refitted on the RANSAC
//!    inliers (ALS warm-started from the RANSAC model,
//!    [`TrackSubspace::refit_warm_reporting`]); the entry noise `σ_e` is the median entry
//!    distance / sqrt(2 ln 2) (each distance scaled by `1/sqrt(1 − 3/(2k))` for the
//!    track's 3 fitted coordinates); entries
//!    farther than `entry_threshold_px` (default `sqrt(χ²₂(p)) · σ_e`, `p` the larger of
//!    `entry_probability` = 0.9999 (4.29 σ_e) and `1 − entry_false_alarms / n` for `n`
//!    observed entries (Bonferroni: 0.1 false flags expected per table, 4.65 σ_e for
//!    5 000 entries)) from their track's fit are flagged (each track is refitted on
//!    its entries within the threshold; when more than `max_flagged_fraction` would be
//!    flagged, a per-track RANSAC over frame pairs looks for a better start; it gives up
//!    early on tracks where no pair explains half the entries a passing track keeps). A
//!    track is an inlier when the RMS `r` of its unflagged entries and its *ambiguous* flagged
//!    ones (closer than `gross_entry_factor` × the entry threshold: these may be the worst
//!    frames of a drifting track rather than glitches) over those `k` frames passes the χ²
//!    test `r ≤ σ_e sqrt(χ²_ν(track_probability)/ν)`, `ν = 2k − 3` (or `r ≤ threshold_px`
//!    when given), and at most `max_flagged_fraction` of its entries are flagged. The model is
//!    refitted without the flagged entries and this is repeated (at most
//!    `max_gross_rounds` refits) until it has converged: the inliers are the ones the model
//!    was fitted to, and the entries whose flag changed since the model was fitted (other
//!    than those the fit's ALS reweighting set aside anyway, which a refit would set aside
//!    again) would move no frame's fit by more than 0.02 σ_e (per frame, the sum of their
//!    distances over the number of entries fitted there). The refit's own
//!    reweighting already sets aside gross entries, so on typical data the first
//!    classification is final and no refit is needed. A frame with more than
//!    `max_flagged_fraction` of its inlier entries flagged (at least 3) has a camera that
//!    is off, not that many gross entries: before the refit its camera is re-estimated
//!    from its entries and the tracks' fitted coordinates (resection),
//!    and its flags are not set aside from the refit.
//! 4. **Verdict**: a rigid majority exists when the inlier fraction is at least
//!    `min_inlier_fraction` and no *rival* rigid group (a second RANSAC over the rejected
//!    tracks, same threshold, `rival_max_iterations` hypotheses) has at least
//!    `max_rival_ratio` times as many tracks. Otherwise [`Verdict::NoRigidMajority`] is
//!    returned with the numbers, and no model or inlier set is claimed.
//!
//! References: M. A. Fischler and R. C. Bolles, "Random sample consensus", CACM 24(6),
//! 1981; P. H. S. Torr and A. Zisserman, "MLESAC: a new robust estimator with application
//! to estimating image geometry", CVIU 78(1), 2000 (MSAC cost); O. Chum, J. Matas and
//! J. Kittler, "Locally optimized RANSAC", DAGM 2003; P. J. Rousseeuw, "Least median of
//! squares regression", JASA 79, 1984; C. Tomasi and T. Kanade, IJCV 9(2), 1992.
//!
//! Complexity: O(I · j̄ · k) for I RANSAC hypotheses (I adaptive, ≤ `max_iterations`)
//! each scored on `j̄` tracks of `k` frames before the bail-out test abandons it (`j̄` ≈
//! 32–64 for hopeless hypotheses, the scale bootstrap on at most `scale_subset` tracks; see
//! [`ransac`](mod@ransac)); with missing data add O(I · N · F/64) for sampling; plus a few
//! affine refits (O(#observations) per ALS sweep, warm-started from the RANSAC model; the
//! local-optimization refits on at most `ransac.lo_max_inliers` tracks), plus per
//! classification round O(#observations) for the track fits and O(32·k) per rejected track
//! for the per-track frame-pair search (O(k²) for tracks it can rescue) and O(#entries of
//! the frame) per suspect frame's resection, plus the rival search (`rival_max_iterations`
//! hypotheses on the rejected tracks only, and only when they are numerous enough to
//! matter).

// `!(x > y)` is used on purpose: it is true for NaN, which must take the safe branch.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod ransac;
pub mod select;
pub mod subspace;

use rand::Rng;
use rayon::prelude::*;
use serde::Serialize;

pub use ransac::{Estimator, RansacConfig, RansacResult, RansacStatus, ransac, ransac_observed};
pub use subspace::{AffineSubspace, SubspaceConfig, TrackFit, TrackSubspace};

use crate::{Error, Measurements, NoopObserver, Observer, Result};

/// Settings of [`robust_filter`]. Every field has a documented default.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct RobustConfig {
    /// RANSAC settings (threshold `None` = estimate the noise; confidence 0.999; 50–2000
    /// hypotheses; LO on).
    pub ransac: RansacConfig,
    /// Track estimator settings.
    pub subspace: SubspaceConfig,
    /// Per-entry gross-error threshold, pixels (distance in the image). `None` (default):
    /// `sqrt(χ²₂(entry_probability)) · σ_e`.
    pub entry_threshold_px: Option<f64>,
    /// Floor of the estimated per-entry threshold, pixels. Default 0 (purely σ-based; the
    /// pipeline's default [`crate::Config`] sets 4). Real tracks carry
    /// model error (perspective under an affine camera) that is not Gaussian noise: on the
    /// Oxford dinosaur the affine optimum's entry residuals have a 99th percentile of 3.3 px
    /// while the median-based σ is 0.3 px, so a purely σ-based threshold would flag good
    /// entries by the hundred. Ignored when `entry_threshold_px` is given.
    pub min_entry_threshold_px: f64,
    /// Floor of the estimated per-track threshold (trimmed RMS), pixels. Default 0 (the
    /// pipeline's default [`crate::Config`] sets 2: the dinosaur's per-track RMS at the
    /// affine optimum has median 0.5, 95th percentile 1.5, 99th 3.0 px). Ignored when
    /// `ransac.threshold_px` is given.
    pub min_track_threshold_px: f64,
    /// Probability that a good entry is below the estimated entry threshold, at least.
    /// Default 0.9999 (4.29 σ_e). On tables of more than `entry_false_alarms / (1 −
    /// entry_probability)` entries (1000 with the defaults) the threshold is raised so that
    /// the expected number of good entries flagged stays `entry_false_alarms`.
    pub entry_probability: f64,
    /// Expected number of good entries flagged in the whole table by the estimated entry
    /// threshold, for Gaussian noise of the estimated σ_e: the per-entry probability is
    /// `max(entry_probability, 1 − entry_false_alarms / n)` for `n` observed entries (a
    /// Bonferroni correction: one test per entry, `n` tests). Without it the false flags
    /// grow with the table (at 0.9999, 0.5 per 5 000 entries, 20 per 200 000), and at a low
    /// gross-error rate they are a large share of all flags. The threshold is then 4.65 σ_e
    /// for 5 000 entries and 5.39 σ_e for 200 000 with the default 0.1; a glitch below it
    /// is as large as the largest Gaussian errors the table is expected to hold anyway.
    /// Default 0.1; `f64::INFINITY` uses `entry_probability` alone. Ignored when
    /// `entry_threshold_px` is given.
    pub entry_false_alarms: f64,
    /// Final per-track test (after the refit, with the entry-level `σ`): a track whose
    /// unflagged entries have RMS `r` over `k` frames is an inlier when
    /// `r ≤ σ sqrt(χ²_ν(track_probability)/ν)`, `ν = 2k − 3` (or `r ≤ threshold_px` when the
    /// RANSAC threshold is given). Default 0.9999.
    pub track_probability: f64,
    /// Refits of the flag → refit → re-classify loop at most. Default 5.
    pub max_gross_rounds: usize,
    /// A track with more than this fraction of its entries flagged is an outlier track,
    /// unless (once the flag → refit loop has settled) none of its flags is ambiguous (see
    /// `gross_entry_factor`), at least 5 entries remain, and that many flags is plausible
    /// for a good track: `P(X ≥ g) ≥ 1 − track_probability` for `X ~ Binomial(k, q̂)`, `g`
    /// flags among its `k` entries, `q̂` the flagged fraction of the tracks within this
    /// fraction. (A good track of 9 frames carries 3 gross entries with probability 0.008 at
    /// a 5 % gross rate.) Default 0.3.
    pub max_flagged_fraction: f64,
    /// Flagged entries closer to their track's fit than `gross_entry_factor` times the entry
    /// threshold are *ambiguous*: an isolated glitch of a good track, or the worst frames
    /// of a track that drifts away from the rigid motion (a slide along an edge, a point on
    /// another object) and would otherwise pass its test by shedding them. They stay
    /// flagged, but they also count in the track's χ² test (`r` and `k` include them); only
    /// entries beyond the factor are gross enough to be set aside from it. Default 2 (8.6
    /// σ_e at an entry threshold of 4.29 σ_e). `f64::INFINITY` counts every flagged entry;
    /// 1 counts none and skips the settled re-classification, so that no track over
    /// `max_flagged_fraction` is kept either (the rules before these settings existed).
    pub gross_entry_factor: f64,
    /// Below this inlier fraction there is no rigid majority. Default 0.4.
    pub min_inlier_fraction: f64,
    /// A rival rigid group among the rejected tracks with at least this many tracks
    /// relative to the inliers means there is no (unambiguous) rigid majority. Default 0.6.
    pub max_rival_ratio: f64,
    /// Rigidity sanity check: a group whose noise estimate `σ` exceeds this fraction of
    /// the observations' RMS distance to their frame centroid is not a rigid fit (a
    /// rank-3 subspace explains any set of tracks at a large enough scale): the verdict is
    /// then [`NoMajorityReason::NoiseTooLarge`]. Default 0.05 (0.01 rejected a clean
    /// Gaussian-cloud scene with 0.5 px noise and ~45 px spread as not rigid).
    pub max_relative_noise: f64,
    /// Run the rival search. Default true.
    pub rival_search: bool,
    /// RANSAC hypotheses of the rival search: all of them are drawn (no adaptive stop,
    /// which a partial group seen in some frames would end early with missing data). It
    /// runs only when the rejected tracks number at least `max_rival_ratio` × the inliers.
    /// Default 300.
    pub rival_max_iterations: usize,
    /// Look for other rigid objects, by segmenting the tracks when the pass leaves a sign
    /// of one (then passing again over the scene's tracks only; [`crate::segment`]) or,
    /// when that finds one body or cannot run whole (a long sequence segmented by
    /// windows), among the rejected and flagged tracks after the pass
    /// ([`crate::segment::other_objects`]), and reject the tracks of each as whole tracks,
    /// never patched entry by entry (used by [`crate::Reconstruction`]'s pipeline, which
    /// reports the groups seen). Default true.
    pub separate_objects: bool,
    /// With `separate_objects`: segment the tracks when the pass leaves a sign of another
    /// body (off: only the search after the pass). [`crate::objects::reconstruct_objects`]
    /// turns it off for each object's own reconstruction, whose tracks a segmentation has
    /// just grouped. Default true.
    pub segment_first: bool,
}

impl Default for RobustConfig {
    fn default() -> Self {
        Self {
            ransac: RansacConfig::default(),
            subspace: SubspaceConfig::default(),
            entry_threshold_px: None,
            min_entry_threshold_px: 0.0,
            min_track_threshold_px: 0.0,
            entry_probability: 0.9999,
            entry_false_alarms: 0.1,
            track_probability: 0.9999,
            max_gross_rounds: 5,
            max_flagged_fraction: 0.3,
            gross_entry_factor: 2.0,
            min_inlier_fraction: 0.4,
            max_rival_ratio: 0.6,
            max_relative_noise: 0.05,
            rival_search: true,
            rival_max_iterations: 300,
            separate_objects: true,
            segment_first: true,
        }
    }
}

impl RobustConfig {
    fn validate(&self) -> Result<()> {
        self.ransac.validate()?;
        let bad =
            |field: &'static str, message: String| Err(Error::InvalidConfig { field, message });
        for (field, v) in [
            ("min_entry_threshold_px", self.min_entry_threshold_px),
            ("min_track_threshold_px", self.min_track_threshold_px),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(field, format!("{v} is not a non-negative number"));
            }
        }
        let s = &self.subspace;
        if s.min_overlap < 3 {
            return bad(
                "subspace.min_overlap",
                format!("{} < 3 frames cannot test a track", s.min_overlap),
            );
        }
        if !(0.0..0.5).contains(&s.trim_fraction) {
            return bad(
                "subspace.trim_fraction",
                format!("{} is not in [0, 0.5)", s.trim_fraction),
            );
        }
        if !(s.min_sample_condition >= 0.0 && s.min_sample_condition < 1.0) {
            return bad(
                "subspace.min_sample_condition",
                format!("{} is not in [0, 1)", s.min_sample_condition),
            );
        }
        if let Some(t) = self.entry_threshold_px
            && !(t > 0.0 && t.is_finite())
        {
            return bad("entry_threshold_px", format!("{t} is not positive"));
        }
        if !(self.entry_probability > 0.5 && self.entry_probability < 1.0) {
            return bad(
                "entry_probability",
                format!("{} is not in (0.5, 1)", self.entry_probability),
            );
        }
        if !(self.entry_false_alarms > 0.0) {
            return bad(
                "entry_false_alarms",
                format!("{} is not positive", self.entry_false_alarms),
            );
        }
        if !(self.track_probability > 0.5 && self.track_probability < 1.0) {
            return bad(
                "track_probability",
                format!("{} is not in (0.5, 1)", self.track_probability),
            );
        }
        if !(self.gross_entry_factor >= 1.0) {
            return bad(
                "gross_entry_factor",
                format!("{} is not ≥ 1", self.gross_entry_factor),
            );
        }
        if !(0.0..=1.0).contains(&self.max_flagged_fraction) {
            return bad(
                "max_flagged_fraction",
                format!("{} is not in [0, 1]", self.max_flagged_fraction),
            );
        }
        if !(0.0..=1.0).contains(&self.min_inlier_fraction) {
            return bad(
                "min_inlier_fraction",
                format!("{} is not in [0, 1]", self.min_inlier_fraction),
            );
        }
        if !(self.max_rival_ratio > 0.0) {
            return bad(
                "max_rival_ratio",
                format!("{} is not positive", self.max_rival_ratio),
            );
        }
        Ok(())
    }
}

/// Why no rigid majority was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum NoMajorityReason {
    /// No non-degenerate 4-track sample could be drawn or fitted.
    NoHypothesis,
    /// The best rigid group is smaller than `min_inlier_fraction` of the tracks.
    TooFewInliers,
    /// Another rigid group of comparable size exists among the rejected tracks.
    RivalGroup,
    /// The best group's noise estimate is too large relative to the image spread of the
    /// tracks (`max_relative_noise`): it is not a rigid fit.
    NoiseTooLarge,
}

/// Whether the tracks contain one dominant rigid motion.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "kebab-case", tag = "verdict")]
pub enum Verdict {
    /// One rigid group explains `inlier_fraction` of the tracks; the largest rival group
    /// found among the rest has `rival_fraction` (0 when the search did not run).
    RigidMajority {
        inlier_fraction: f64,
        rival_fraction: f64,
    },
    /// No unambiguous rigid majority: the result claims no model and no inliers.
    NoRigidMajority {
        reason: NoMajorityReason,
        /// Fraction of tracks in the best rigid group found.
        inlier_fraction: f64,
        /// Fraction of tracks in the best rival group (0 when not searched).
        rival_fraction: f64,
        /// The configured floor.
        min_inlier_fraction: f64,
    },
}

impl Verdict {
    /// True for [`Verdict::RigidMajority`].
    pub fn is_rigid_majority(&self) -> bool {
        matches!(self, Verdict::RigidMajority { .. })
    }
}

/// Result of [`robust_filter`].
#[derive(Debug, Clone)]
pub struct RobustResult {
    pub verdict: Verdict,
    /// Inlier flag per track (all false with [`Verdict::NoRigidMajority`]).
    pub inlier_tracks: Vec<bool>,
    /// Gross entries of inlier tracks, (frame, track), sorted (empty without a majority).
    pub flagged_entries: Vec<(usize, usize)>,
    /// Per track, how many of its flagged entries are *ambiguous* (within
    /// `gross_entry_factor` × the entry threshold: the worst frames of a track drifting
    /// from the rigid motion — a point on another object — rather than a glitch, which
    /// lands far off); 0 for tracks that are not inliers, and for all when
    /// `gross_entry_factor` ≤ 1 (no flag is then told apart). Empty without a majority.
    pub ambiguous_flags: Vec<usize>,
    /// Per track, an inlier kept only by `min_track_threshold_px`: its RMS is above the
    /// noise test `σ_e sqrt(χ²_ν(track_probability)/ν)` and within the floor — model error
    /// the floor forgives (perspective under an affine camera), or another object moving
    /// close to the main body. False for all with a given `ransac.threshold_px`; empty
    /// without a majority.
    pub floor_kept: Vec<bool>,
    /// Image noise σ per coordinate, pixels (robust estimate from the inlier entries).
    pub noise_sigma: f64,
    /// Track threshold `τ` on the trimmed RMS residual, pixels.
    pub threshold_px: f64,
    /// Entry threshold on the image distance, pixels.
    pub entry_threshold_px: f64,
    /// RANSAC hypotheses drawn (MSAC phase + scale bootstrap).
    pub iterations: usize,
    /// MSAC cost of the RANSAC model.
    pub score: f64,
    /// Per-track residual under the final model (`None`: cannot be scored).
    pub track_residuals: Vec<Option<f64>>,
    /// Affine coordinates of the inlier tracks under `model` (`None` for others).
    pub coordinates: Vec<Option<[f64; 3]>>,
    /// The final affine model (refit on the inliers without the flagged entries); `None`
    /// without a majority.
    pub model: Option<AffineSubspace>,
    /// The best rigid group found, whatever the verdict (diagnostics only).
    pub candidate_tracks: Vec<bool>,
    /// Tracks in the best rival group (0 when the search did not run).
    pub rival_tracks: usize,
    /// Refits of the flag → refit → re-classify loop (0 when the first classification
    /// already agreed with the entries the initial refit had set aside).
    pub gross_rounds: usize,
    /// The RANSAC run over the tracks.
    pub ransac: RansacResult<AffineSubspace>,
}

impl RobustResult {
    /// Number of inlier tracks.
    pub fn n_inliers(&self) -> usize {
        self.inlier_tracks.iter().filter(|&&b| b).count()
    }
}

/// Upper-tail quantile of the standard normal: `z` with `Φ(z) = p`, by bisection on
/// `Φ(z) = erfc(−z/√2)/2` (erfc by Abramowitz & Stegun 7.1.26, |error| < 1.5e-7).
pub fn normal_quantile(p: f64) -> f64 {
    let erfc = |x: f64| -> f64 {
        let s = x.signum();
        let x = x.abs();
        let t = 1.0 / (1.0 + 0.327_591_1 * x);
        let poly = t
            * (0.254_829_592
                + t * (-0.284_496_736
                    + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
        let erf = 1.0 - poly * (-x * x).exp();
        1.0 - s * erf
    };
    let phi = |z: f64| 0.5 * erfc(-z / std::f64::consts::SQRT_2);
    let (mut lo, mut hi) = (-10.0, 10.0);
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if phi(mid) < p {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// `(Δχ², σ²)` of a richer model against a simpler one nested in it, both fitted to the
/// same `n` scalars: `σ² = SS_r / (n − k)` from the richer model's fit (`k` its parameters,
/// gauge removed) and `Δχ² = (SS_s − SS_r) / σ²`, with `SS = rms² n`. Used by the camera
/// choice (affine against projective or perspective) and by the perspective fit's early
/// acceptance (metric against projective).
pub(crate) fn delta_chi2(simple_rms: f64, richer_rms: f64, n: f64, k: usize) -> (f64, f64) {
    let ss_s = simple_rms * simple_rms * n;
    let ss_r = richer_rms * richer_rms * n;
    let sigma2 = ss_r / (n - k as f64).max(1.0);
    let delta = if sigma2 > 0.0 {
        (ss_s - ss_r) / sigma2
    } else if ss_s > ss_r {
        f64::INFINITY
    } else {
        0.0
    };
    (delta, sigma2)
}

/// Quantile `χ²_ν(p)`: exact for ν = 2 (`−2 ln(1 − p)`) and ν = 1 (`z²_{(1+p)/2}`),
/// Wilson–Hilferty otherwise: `ν (1 − 2/(9ν) + z_p sqrt(2/(9ν)))³`.
pub fn chi2_quantile(nu: f64, p: f64) -> f64 {
    if (nu - 2.0).abs() < 1e-12 {
        return -2.0 * (1.0 - p).ln();
    }
    if (nu - 1.0).abs() < 1e-12 {
        let z = normal_quantile(0.5 * (1.0 + p));
        return z * z;
    }
    let a = 2.0 / (9.0 * nu);
    let z = normal_quantile(p);
    nu * (1.0 - a + z * a.sqrt()).powi(3).max(0.0)
}

/// [`robust_filter_observed`] without an observer.
pub fn robust_filter<R: Rng + ?Sized>(
    meas: &Measurements,
    config: &RobustConfig,
    rng: &mut R,
) -> Result<RobustResult> {
    robust_filter_observed(meas, config, rng, &mut NoopObserver)
}

/// Rejects outlier tracks and flags gross entries; see the module documentation.
///
/// Observer: `Event::Iteration` with `solver: "ransac-scale"` / `"ransac"` (run 0: the main
/// search; run 1: the rival search), `cost` = best MSAC cost (or residual quantile),
/// `lambda` = best inlier count, `rms` = NaN.
///
/// Errors: invalid configuration; fewer than 3 frames, fewer than 8 tracks, or fewer than
/// 4 tracks seen in `min_overlap` frames ([`Error::TooFew`]).
pub fn robust_filter_observed<R: Rng + ?Sized>(
    meas: &Measurements,
    config: &RobustConfig,
    rng: &mut R,
    observer: &mut dyn Observer,
) -> Result<RobustResult> {
    config.validate()?;
    let (nf, n) = (meas.n_frames(), meas.n_points());
    if nf < 3 {
        return Err(Error::TooFew {
            what: "frames for robust track rejection",
            needed: 3,
            have: nf,
        });
    }
    if n < 8 {
        return Err(Error::TooFew {
            what: "tracks for robust track rejection",
            needed: 8,
            have: n,
        });
    }
    let est = TrackSubspace::new(meas, &config.subspace);
    if est.n_eligible() < 4 {
        return Err(Error::TooFew {
            what: "tracks seen in at least `min_overlap` frames",
            needed: 4,
            have: est.n_eligible(),
        });
    }
    let rr = ransac_observed(&est, n, &config.ransac, rng, observer, 0)?;
    let iterations = rr.iterations + rr.scale_iterations;
    let Some(ransac_model) = rr.model.clone() else {
        return Ok(no_majority(
            NoMajorityReason::NoHypothesis,
            n,
            config,
            rr,
            f64::NAN,
        ));
    };
    let tau = rr.threshold;
    let frac = |k: usize| k as f64 / n as f64;

    // Final refit on the RANSAC inliers, then flag → refit → re-classify.
    let mut inl: Vec<usize> = (0..n).filter(|&p| rr.inliers[p]).collect();
    // The current model was fitted to the inliers without the entries `fit_flags` (flagged
    // before the refit) and `als_excluded` (set aside by the refit's reweighting); sorted.
    let mut fit_flags: Vec<(usize, usize)> = Vec::new();
    let (mut model, mut als_excluded) = est
        .refit_warm_reporting(
            &ransac_model,
            &est.refit_tracks(&inl, config.subspace.max_refit_tracks),
            config.subspace.final_als_iterations,
        )
        .unwrap_or((ransac_model, Vec::new()));
    let mut flagged: Vec<(usize, usize)>;
    let mut cur = est.clone();
    let mut sigma_e = f64::NAN;
    let mut rounds = 0;
    // Ambiguous flags count in the track test only once the model has settled: while it
    // is still off in some frame, good tracks have moderate distances there.
    let mut strict = false;
    let entry_k = chi2_quantile(
        2.0,
        config
            .entry_probability
            .max(1.0 - config.entry_false_alarms / meas.n_observed().max(1) as f64),
    )
    .sqrt();
    // Noise floor for noise-free input (keeps thresholds positive).
    let floor = 1e-9 * meas.w.norm_max().max(1.0);
    // The fits of the last round, kept for the re-classification once settled.
    let mut reuse: Option<(Vec<Option<EntryFit>>, f64)> = None;
    let (fits, entry_thr, floor_kept) = loop {
        let (fits, entry_thr) = if let Some(kept) = reuse.take() {
            kept
        } else {
            // Robust entry scale from the inlier tracks' entries: first from the trimmed fits
            // (biased low: trimming keeps the best frames), then from the threshold-based fits;
            // each distance scaled by 1/sqrt(1 − 3/(2k)) for the 3 coordinates fitted from k
            // frames; σ_e = median / sqrt(2 ln 2).
            // The frames where the model is defined, per inlier track (borrowed when they
            // are all of the track's frames: the usual case).
            let defined: Vec<std::borrow::Cow<'_, [u32]>> = inl
                .par_iter()
                .map(|&p| {
                    let frames = est.frames_of(p);
                    if frames.iter().all(|&fr| model.defined[fr as usize]) {
                        std::borrow::Cow::Borrowed(frames)
                    } else {
                        std::borrow::Cow::Owned(
                            frames
                                .iter()
                                .copied()
                                .filter(|&fr| model.defined[fr as usize])
                                .collect(),
                        )
                    }
                })
                .collect();
            let scale_of = |fits: &[Option<[f64; 3]>]| -> Option<f64> {
                // The median over every entry, on all cores, without a buffer of them all
                // ([`select::median_indexed`]; exact): the `i`-th distance of inlier track
                // `j`, each scaled by its leverage.
                let counts: Vec<usize> = inl
                    .iter()
                    .zip(&defined)
                    .map(|(&p, d)| if fits[p].is_some() { d.len() } else { 0 })
                    .collect();
                let lev: Vec<f64> = defined
                    .iter()
                    .map(|d| (1.0 - 3.0 / (2.0 * d.len() as f64)).max(0.1).sqrt())
                    .collect();
                let distance = |j: usize, i: usize| {
                    let p = inl[j];
                    let s = fits[p].as_ref().expect("counted only with a fit");
                    est.dist2(&model, p, defined[j][i] as usize, s).sqrt() / lev[j]
                };
                let med = select::median_indexed(&counts, distance);
                (!med.is_nan()).then(|| (med / 1.177_410_022_515_474_8).max(floor))
            };
            // Only the inlier tracks' fits enter the scale.
            let is_inl = {
                let mut v = vec![false; n];
                for &p in &inl {
                    v[p] = true;
                }
                v
            };
            // Trimmed fits of all tracks (the start of every entry fit below).
            let starts: Vec<Option<TrackFit>> = (0..n)
                .into_par_iter()
                .with_min_len(64)
                .map(|p| cur.track_fit(&model, p))
                .collect();
            let trimmed: Vec<Option<[f64; 3]>> = (0..n)
                .map(|p| {
                    if is_inl[p] {
                        starts[p].map(|f| f.s)
                    } else {
                        None
                    }
                })
                .collect();
            if let Some(sg) = scale_of(&trimmed) {
                sigma_e = sg;
            }
            // Track `p`'s fit with its entries beyond `thr` set aside.
            let fit = |p: usize, thr: f64| {
                entry_fit(
                    &est,
                    &model,
                    p,
                    starts[p].as_ref(),
                    thr,
                    config.gross_entry_factor,
                    config.max_flagged_fraction,
                )
            };
            let thr0 = config
                .entry_threshold_px
                .unwrap_or((entry_k * sigma_e).max(config.min_entry_threshold_px));
            let fits0: Vec<Option<EntryFit>> = (0..n)
                .into_par_iter()
                .map(|p| if is_inl[p] { fit(p, thr0) } else { None })
                .collect();
            let coords0: Vec<Option<[f64; 3]>> =
                fits0.iter().map(|f| f.as_ref().map(|f| f.s)).collect();
            if let Some(sg) = scale_of(&coords0) {
                sigma_e = sg;
            }
            let entry_thr = config
                .entry_threshold_px
                .unwrap_or((entry_k * sigma_e).max(config.min_entry_threshold_px));
            // At the same threshold (e.g. both at the floor `min_entry_threshold_px`) the
            // inlier tracks' fits are those just made.
            let same = entry_thr.to_bits() == thr0.to_bits();
            let fits: Vec<Option<EntryFit>> = fits0
                .into_par_iter()
                .enumerate()
                .map(|(p, f0)| {
                    if same && is_inl[p] {
                        f0
                    } else {
                        fit(p, entry_thr)
                    }
                })
                .collect();
            (fits, entry_thr)
        };
        // χ²_ν(track_probability)/ν for ν = 2k − 3, k = 0..=F (computed once per round).
        let chi2_ratio: Vec<f64> = (0..=nf)
            .map(|k| {
                let nu = (2 * k) as f64 - 3.0;
                chi2_quantile(nu, config.track_probability) / nu
            })
            .collect();
        let within = |fit: &EntryFit| {
            fit.flagged.len() as f64 <= config.max_flagged_fraction * fit.seen as f64
        };
        // Flagged fraction of the entries of the scorable tracks within
        // `max_flagged_fraction` (only the settled classification uses it).
        let gross_rate = if strict {
            let (n_flag, n_seen) = fits
                .iter()
                .flatten()
                .filter(|f| within(f))
                .fold((0usize, 0usize), |(a, b), f| {
                    (a + f.flagged.len(), b + f.seen)
                });
            n_flag as f64 / n_seen.max(1) as f64
        } else {
            0.0
        };
        let mut new_flags = Vec::new();
        let mut new_inl = Vec::new();
        // Inliers that pass only by `min_track_threshold_px` (`RobustResult::floor_kept`).
        let mut by_floor = vec![false; n];
        for (p, fit) in fits.iter().enumerate() {
            let Some(fit) = fit else {
                // Seen in too few of the model's frames to be tested: no evidence against
                // the track, so it is kept (`track_residuals[p]` stays `None`). A track
                // whose fit failed for other reasons (too many flagged entries) is not.
                let in_span = cur
                    .frames_of(p)
                    .iter()
                    .filter(|&&f| model.defined[f as usize])
                    .count();
                if in_span < cur.min_overlap() {
                    new_inl.push(p);
                }
                continue;
            };
            // The unflagged entries and the ambiguous flagged ones face the χ² test.
            let (rms, k) = if strict {
                fit.test_rms()
            } else {
                (fit.rms, fit.kept)
            };
            let noise_limit = sigma_e * chi2_ratio[k.min(nf)].sqrt();
            let limit = match config.ransac.threshold_px {
                Some(t) => t,
                None => noise_limit.max(config.min_track_threshold_px),
            };
            // A track over the fraction is kept when, once the model has settled, all its
            // flags are clearly gross (none ambiguous), at least 5 entries remain for its χ²
            // test, and that many gross entries is plausible at the observed rate.
            let rescued = strict
                && fit.ambiguous == 0
                && fit.kept >= 5
                && binomial_tail(fit.seen, fit.flagged.len(), gross_rate)
                    >= 1.0 - config.track_probability;
            if rms > limit || (!within(fit) && !rescued) {
                continue;
            }
            new_inl.push(p);
            by_floor[p] = config.ransac.threshold_px.is_none() && k >= 2 && rms > noise_limit;
            new_flags.extend(fit.flagged.iter().map(|&f| (f, p)));
        }
        new_flags.sort_unstable();
        // Converged when the inliers are unchanged and refitting without the new flags
        // would move no frame's fit by more than `REFIT_SHIFT_TOLERANCE · σ_e`
        // ([`refit_shift_small`]). That refit would set aside the new flags and (again)
        // the entries its reweighting rejects, so the entries whose weight would change
        // are those whose flag changed, less those the reweighting set aside anyway.
        let toggled: Vec<(usize, usize)> = symmetric_difference(&new_flags, &fit_flags)
            .into_iter()
            .filter(|e| als_excluded.binary_search(e).is_err())
            .collect();
        // Frames where more than `max_flagged_fraction` of the inlier tracks' entries are
        // flagged: their camera is off, not their entries (see [`suspect_frames`]).
        let suspect = if strict {
            Vec::new()
        } else {
            suspect_frames(
                &est,
                &model,
                &new_inl,
                &new_flags,
                config.max_flagged_fraction,
            )
        };
        let converged = suspect.is_empty()
            && new_inl == inl
            && refit_shift_small(
                &est,
                &model,
                &fits,
                &inl,
                &toggled,
                entry_thr,
                REFIT_SHIFT_TOLERANCE * sigma_e,
            );
        flagged = new_flags;
        inl = new_inl;
        if converged || rounds >= config.max_gross_rounds || inl.len() < 4 {
            if !strict && inl.len() >= 4 && config.gross_entry_factor > 1.0 {
                // Settled: classify again (same model), counting the ambiguous flags.
                strict = true;
                rounds = 0;
                reuse = Some((fits, entry_thr));
                continue;
            }
            break (fits, entry_thr, by_floor);
        }
        rounds += 1;
        // A suspect frame's camera is re-estimated from its entries and the tracks' own
        // coordinates, and its flags are not set aside from the refit.
        for &f in &suspect {
            resect_frame(meas, &mut model, f, &inl, &fits, entry_thr);
        }
        let exclude: Vec<(usize, usize)> = flagged
            .iter()
            .filter(|e| suspect.binary_search(&e.0).is_err())
            .copied()
            .collect();
        cur = est.with_exclusions_shared(meas, &exclude);
        if let Some((m, excluded)) =
            cur.refit_reporting(&model, &inl, config.subspace.final_als_iterations)
        {
            model = m;
            fit_flags = exclude;
            als_excluded = excluded;
        }
    };
    let residuals: Vec<Option<f64>> = fits.iter().map(|f| f.as_ref().map(|f| f.rms)).collect();
    let mut inlier_tracks = vec![false; n];
    for &p in &inl {
        inlier_tracks[p] = true;
    }
    let n_in = inl.len();

    // Rival search among the rejected, scorable tracks.
    let mut rival = 0usize;
    let rejected: Vec<usize> = (0..n)
        .filter(|&p| !inlier_tracks[p] && est.frames_of(p).len() >= est.min_overlap())
        .collect();
    if config.rival_search
        && rejected.len() >= 8
        && rejected.len() as f64 >= config.max_rival_ratio * n_in as f64
    {
        let sub = meas.select_tracks(&rejected);
        let rest = TrackSubspace::new(&sub, &config.subspace);
        let rc = RansacConfig {
            threshold_px: Some(tau),
            max_iterations: config.rival_max_iterations,
            // The whole budget, no adaptive stop: with missing data a sample of rival
            // tracks that share only some frames yields part of their group, and its
            // inlier ratio would end the search early (seen: 78 of an equal group of 143
            // after the adaptive stop; 141 once 100 or more hypotheses were drawn).
            min_iterations: config.rival_max_iterations,
            ..config.ransac.clone()
        };
        if rest.n_eligible() >= 4
            && let Ok(r2) = ransac_observed(&rest, rejected.len(), &rc, rng, observer, 1)
        {
            rival = r2.n_inliers;
        }
    }

    let candidate_tracks = inlier_tracks.clone();
    let spread = observation_spread(meas);
    let reason = if !(sigma_e <= config.max_relative_noise * spread) {
        Some(NoMajorityReason::NoiseTooLarge)
    } else if frac(n_in) < config.min_inlier_fraction {
        Some(NoMajorityReason::TooFewInliers)
    } else if rival as f64 >= config.max_rival_ratio * n_in as f64 {
        Some(NoMajorityReason::RivalGroup)
    } else {
        None
    };
    if let Some(reason) = reason {
        let mut out = no_majority(reason, n, config, rr, tau);
        out.verdict = Verdict::NoRigidMajority {
            reason,
            inlier_fraction: frac(n_in),
            rival_fraction: frac(rival),
            min_inlier_fraction: config.min_inlier_fraction,
        };
        out.candidate_tracks = candidate_tracks;
        out.rival_tracks = rival;
        out.noise_sigma = sigma_e;
        out.entry_threshold_px = entry_thr;
        out.track_residuals = residuals;
        out.gross_rounds = rounds;
        out.iterations = iterations;
        return Ok(out);
    }
    let coordinates = (0..n)
        .map(|p| {
            if inlier_tracks[p] {
                fits[p].as_ref().map(|f| f.s)
            } else {
                None
            }
        })
        .collect();
    Ok(RobustResult {
        verdict: Verdict::RigidMajority {
            inlier_fraction: frac(n_in),
            rival_fraction: frac(rival),
        },
        ambiguous_flags: (0..n)
            .map(|p| match &fits[p] {
                Some(f) if inlier_tracks[p] && strict => f.ambiguous,
                _ => 0,
            })
            .collect(),
        floor_kept,
        inlier_tracks,
        flagged_entries: flagged,
        noise_sigma: sigma_e,
        threshold_px: tau,
        entry_threshold_px: entry_thr,
        iterations,
        score: rr.score,
        track_residuals: residuals,
        coordinates,
        model: Some(model),
        candidate_tracks,
        rival_tracks: rival,
        gross_rounds: rounds,
        ransac: rr,
    })
}

/// A track's fit with its gross entries identified.
struct EntryFit {
    s: [f64; 3],
    /// Per-coordinate RMS of the unflagged entries, corrected for the 3 coordinates.
    rms: f64,
    /// Frames whose entry is farther than the entry threshold.
    flagged: Vec<usize>,
    /// Unflagged frames.
    kept: usize,
    /// Observed frames where the model is defined.
    seen: usize,
    /// Sum of squared distances of the unflagged entries.
    ss: f64,
    /// Flagged entries within the ambiguity bound (`gross_entry_factor` × threshold) and the
    /// sum of their squared distances.
    ambiguous: usize,
    ambiguous_ss: f64,
}

impl EntryFit {
    /// RMS for the track test: the unflagged entries plus the ambiguous flagged ones
    /// (per coordinate, corrected for the 3 fitted coordinates), and their number.
    fn test_rms(&self) -> (f64, usize) {
        let k = self.kept + self.ambiguous;
        (
            ((self.ss + self.ambiguous_ss) / ((2 * k) as f64 - 3.0)).sqrt(),
            k,
        )
    }
}

/// Frames (sorted) where more than `max_fraction` of the entries of the tracks `inl`, and
/// at least 3, are among `flags` (the flagged (frame, track) entries of those tracks).
///
/// Gross entries are rare and independent of the frame, so a frame with a large share of
/// them has a camera that is off rather than entries: a camera poorly determined by the
/// start (few tracks see the frame, at the ends of a sequence with missing data) leaves
/// good entries far from it, and setting them aside in the refit would keep it off. The
/// same bound as for a track's share of flags. O(Σ_inl k + #flags).
fn suspect_frames(
    est: &TrackSubspace,
    model: &AffineSubspace,
    inl: &[usize],
    flags: &[(usize, usize)],
    max_fraction: f64,
) -> Vec<usize> {
    let nf = model.n_frames;
    let mut entries = vec![0usize; nf];
    for &p in inl {
        for &f in est.frames_of(p) {
            if model.defined[f as usize] {
                entries[f as usize] += 1;
            }
        }
    }
    let mut flagged = vec![0usize; nf];
    for &(f, _) in flags {
        flagged[f] += 1;
    }
    (0..nf)
        .filter(|&f| flagged[f] >= 3 && flagged[f] as f64 > max_fraction * entries[f] as f64)
        .collect()
}

/// Re-estimates frame `f`'s camera `[M_f | t_f]` (camera resection) from the entries of
/// the tracks `inl` seen there, each at its coordinates from its entry fit (which set
/// aside the entries it flagged, so they come from the track's other frames): least
/// squares `min Σ_p ‖w_fp − M_f s_p − t_f‖²` over all of them, then twice over those
/// within `thr` of the current fit. Unchanged when fewer than 5 entries remain or the
/// coordinates are degenerate. O(#entries in the frame).
fn resect_frame(
    meas: &Measurements,
    model: &mut AffineSubspace,
    f: usize,
    inl: &[usize],
    fits: &[Option<EntryFit>],
    thr: f64,
) {
    use nalgebra::{Matrix4, Vector4};
    let n = meas.n_points();
    let obs: Vec<(Vector4<f64>, f64, f64)> = inl
        .iter()
        .filter(|&&p| meas.visible[f * n + p])
        .filter_map(|&p| {
            let s = fits[p].as_ref()?.s;
            Some((
                Vector4::new(s[0], s[1], s[2], 1.0),
                meas.w[(2 * f, p)],
                meas.w[(2 * f + 1, p)],
            ))
        })
        .collect();
    let mut keep = vec![true; obs.len()];
    for round in 0..3 {
        let (mut a, mut bx, mut by, mut cnt) = (
            Matrix4::<f64>::zeros(),
            Vector4::zeros(),
            Vector4::zeros(),
            0,
        );
        for ((v, x, y), _) in obs.iter().zip(&keep).filter(|(_, k)| **k) {
            a += v * v.transpose();
            bx += v * *x;
            by += v * *y;
            cnt += 1;
        }
        if cnt < 5 {
            return;
        }
        let Some((mx, my)) = subspace::solve_camera(&a, &bx, &by) else {
            return;
        };
        model.set_camera(f, &mx, &my);
        if round < 2 {
            for ((v, x, y), k) in obs.iter().zip(keep.iter_mut()) {
                *k = (mx.dot(v) - x).powi(2) + (my.dot(v) - y).powi(2) <= thr * thr;
            }
        }
    }
}

/// Starting from `s`, twice: keep the entries within `thr2` (squared), refit on them;
/// then split the frames into kept and flagged.
fn threshold_refit(
    est: &TrackSubspace,
    model: &AffineSubspace,
    p: usize,
    frames: &[u32],
    mut s: [f64; 3],
    thr2: f64,
    ambiguous2: f64,
) -> Option<EntryFit> {
    let mut good: Vec<u32> = Vec::with_capacity(frames.len());
    for _ in 0..2 {
        good.clear();
        good.extend(
            frames
                .iter()
                .copied()
                .filter(|&f| est.dist2(model, p, f as usize, &s) <= thr2),
        );
        if good.len() < 2 {
            break;
        }
        match est.ls_coords(model, p, &good) {
            Some(s2) => s = s2,
            None => break,
        }
    }
    let mut flagged = Vec::new();
    let (mut ss, mut kept) = (0.0, 0usize);
    let (mut ambiguous_ss, mut ambiguous) = (0.0, 0usize);
    for &f in frames {
        let d2 = est.dist2(model, p, f as usize, &s);
        if d2 <= thr2 {
            ss += d2;
            kept += 1;
        } else {
            flagged.push(f as usize);
            if d2 <= ambiguous2 {
                ambiguous_ss += d2;
                ambiguous += 1;
            }
        }
    }
    (kept >= 2).then(|| EntryFit {
        s,
        rms: (ss / ((2 * kept) as f64 - 3.0)).sqrt(),
        flagged,
        kept,
        seen: frames.len(),
        ss,
        ambiguous,
        ambiguous_ss,
    })
}

/// Fits track `p` to `model` with its gross entries set aside: start from the trimmed fit
/// `start` (of `cur`, which excludes the entries flagged so far) and refit on the entries
/// within `thr` ([`threshold_refit`]; flagged entries within `ambiguous_factor · thr` are
/// counted as ambiguous). When that leaves more than `max_flagged` of the
/// entries flagged (the trimmed start was pulled by several gross entries), a per-track
/// RANSAC over frame pairs (2 frames = 4 equations for the 3 coordinates; pairs
/// `(i, i + k/3)` and `(i, i + k/2)`, `i` in a spread order) looks for the largest set of
/// consistent entries. The search stops after [`PAIR_PRETEST`] pairs when none of them has
/// `(1 − max_flagged)·k/2` consistent entries: a track that could pass (at least
/// `(1 − max_flagged)·k` good entries) has both entries of a pair good with probability
/// `≥ (1 − max_flagged)²` (0.49), so missing it 32 times in a row has probability
/// `≤ 0.51³² ≈ 5·10⁻¹⁰`; whole outlier tracks then cost O(32·k) instead of O(k²).
/// `None` when the track cannot be scored.
fn entry_fit(
    est: &TrackSubspace,
    model: &AffineSubspace,
    p: usize,
    start: Option<&TrackFit>,
    thr: f64,
    ambiguous_factor: f64,
    max_flagged: f64,
) -> Option<EntryFit> {
    let start = start?;
    let frames: Vec<u32> = est
        .frames_of(p)
        .iter()
        .copied()
        .filter(|&f| model.defined[f as usize])
        .collect();
    let thr2 = thr * thr;
    let ambiguous2 = thr2 * ambiguous_factor * ambiguous_factor;
    let first = threshold_refit(est, model, p, &frames, start.s, thr2, ambiguous2);
    let k = frames.len();
    let acceptable = |e: &EntryFit| e.flagged.len() as f64 <= max_flagged * k as f64;
    if first.as_ref().is_some_and(acceptable) || k < 4 {
        return first;
    }
    let mut best: Option<(usize, [f64; 3])> = None;
    // Visit the first frames of the pairs in the order i_j = j·g mod k (g coprime with k,
    // near k/φ), so that the first pairs are spread over the track.
    let g = {
        let mut g = ((k as f64 * 0.618).round() as usize).max(1);
        while gcd(g, k) != 1 {
            g += 1;
        }
        g
    };
    let useful = ((1.0 - max_flagged) * k as f64 / 2.0).ceil() as usize;
    let mut tried = 0usize;
    'search: for step in [k / 3, k / 2] {
        if step == 0 {
            continue;
        }
        for j in 0..k {
            if tried == PAIR_PRETEST && best.is_none_or(|b| b.0 < useful) {
                break 'search;
            }
            tried += 1;
            let i = j * g % k;
            let pair = [frames[i], frames[(i + step) % k]];
            if pair[0] == pair[1] {
                continue;
            }
            let Some(s) = est.ls_coords(model, p, &pair) else {
                continue;
            };
            // Count the consistent entries; stop once this pair cannot beat the best.
            let need = best.map_or(0, |b| b.0);
            let mut count = 0usize;
            for (j, &f) in frames.iter().enumerate() {
                if est.dist2(model, p, f as usize, &s) <= thr2 {
                    count += 1;
                }
                if count + (k - j - 1) <= need {
                    break;
                }
            }
            if best.is_none_or(|b| count > b.0) {
                best = Some((count, s));
            }
        }
    }
    let second =
        best.and_then(|(_, s)| threshold_refit(est, model, p, &frames, s, thr2, ambiguous2));
    match (first, second) {
        (Some(a), Some(b)) => Some(if b.kept > a.kept { b } else { a }),
        (a, b) => a.or(b),
    }
}

/// `P(X ≥ g)` for `X ~ Binomial(k, q)`. O(g).
fn binomial_tail(k: usize, g: usize, q: f64) -> f64 {
    if g == 0 {
        return 1.0;
    }
    if q <= 0.0 || g > k {
        return 0.0;
    }
    if q >= 1.0 {
        return 1.0;
    }
    let mut term = (1.0 - q).powi(k as i32);
    let mut below = 0.0;
    for i in 0..g {
        below += term;
        term *= (k - i) as f64 / (i + 1) as f64 * q / (1.0 - q);
    }
    (1.0 - below).max(0.0)
}

/// Pairs tried by [`entry_fit`]'s per-track RANSAC before it gives up on a track in which
/// no pair explains half of the entries a passing track must keep.
const PAIR_PRETEST: usize = 32;

fn gcd(mut a: usize, mut b: usize) -> usize {
    while b != 0 {
        (a, b) = (b, a % b);
    }
    a
}

/// Symmetric difference of two sorted lists (sorted).
fn symmetric_difference(a: &[(usize, usize)], b: &[(usize, usize)]) -> Vec<(usize, usize)> {
    let (mut i, mut j) = (0, 0);
    let mut d = Vec::new();
    while i < a.len() && j < b.len() {
        match a[i].cmp(&b[j]) {
            std::cmp::Ordering::Less => {
                d.push(a[i]);
                i += 1;
            }
            std::cmp::Ordering::Greater => {
                d.push(b[j]);
                j += 1;
            }
            std::cmp::Ordering::Equal => {
                i += 1;
                j += 1;
            }
        }
    }
    d.extend_from_slice(&a[i..]);
    d.extend_from_slice(&b[j..]);
    d
}

/// Convergence tolerance of the flag → refit loop, in units of `σ_e` (see
/// [`refit_shift_small`]).
const REFIT_SHIFT_TOLERANCE: f64 = 0.02;

/// Whether refitting the model after toggling the entries in `toggled` (flagged now but
/// used by the current fit, or the reverse) would move it by at most `tol` pixels in every
/// frame. Bound: in the least-squares fit of frame `f`'s motion to its
/// `n_f` used entries, adding or removing one entry at distance `d_e` from its fit moves
/// the frame's fit by about `d_e / n_f` (its leverage is of order `1/n_f`), so the test is
/// `Σ_{e ∈ toggled, frame f} d_e ≤ tol · n_f` for every frame (`d_e` from the track's
/// current fit; `entry_thr` when the track has none). O(#toggled + Σ_inliers k).
fn refit_shift_small(
    est: &TrackSubspace,
    model: &AffineSubspace,
    fits: &[Option<EntryFit>],
    inl: &[usize],
    toggled: &[(usize, usize)],
    entry_thr: f64,
    tol: f64,
) -> bool {
    if toggled.is_empty() {
        return true;
    }
    if !(tol > 0.0) {
        return false;
    }
    let nf = model.n_frames;
    let mut used = vec![0usize; nf];
    for &p in inl {
        for &f in est.frames_of(p) {
            used[f as usize] += 1;
        }
    }
    let mut shift = vec![0.0; nf];
    for &(f, p) in toggled {
        shift[f] += match &fits[p] {
            Some(fit) => est.dist2(model, p, f, &fit.s).sqrt(),
            None => entry_thr,
        };
    }
    (0..nf).all(|f| shift[f] <= tol * used[f].max(1) as f64)
}

/// RMS distance of the observations to their frame's centroid (per coordinate), pixels.
/// Two passes over the observations, each on all cores by tiles of
/// [`crate::measurements::TILE_TRACKS`] tracks whose per-row sums are added in tile order
/// (the result does not depend on the number of threads). `O(F·N)`.
fn observation_spread(meas: &Measurements) -> f64 {
    use crate::measurements::TILE_TRACKS;
    let (nf, n) = (meas.n_frames(), meas.n_points());
    let rows = 2 * nf;
    // Per-row sums over tiles of tracks: `term(r, p)` for observed entries.
    let row_sums = |term: &(dyn Fn(usize, usize) -> f64 + Sync)| -> Vec<f64> {
        let parts: Vec<Vec<f64>> = (0..n.div_ceil(TILE_TRACKS))
            .into_par_iter()
            .map(|t| {
                let mut acc = vec![0.0; rows];
                for p in t * TILE_TRACKS..((t + 1) * TILE_TRACKS).min(n) {
                    for f in 0..nf {
                        if meas.visible[f * n + p] {
                            acc[2 * f] += term(2 * f, p);
                            acc[2 * f + 1] += term(2 * f + 1, p);
                        }
                    }
                }
                acc
            })
            .collect();
        let mut sum = vec![0.0; rows];
        for part in parts {
            sum.iter_mut().zip(part).for_each(|(s, v)| *s += v);
        }
        sum
    };
    let count: Vec<usize> = (0..nf)
        .map(|f| {
            meas.visible[f * n..(f + 1) * n]
                .iter()
                .filter(|&&v| v)
                .count()
        })
        .collect();
    let sum = row_sums(&|r, p| meas.w[(r, p)]);
    let mean: Vec<f64> = (0..rows)
        .map(|r| sum[r] / count[r / 2].max(1) as f64)
        .collect();
    let ss = row_sums(&|r, p| (meas.w[(r, p)] - mean[r]).powi(2));
    let cnt = 2 * count.iter().sum::<usize>();
    if cnt == 0 {
        0.0
    } else {
        (ss.iter().sum::<f64>() / cnt as f64).sqrt()
    }
}

fn no_majority(
    reason: NoMajorityReason,
    n: usize,
    config: &RobustConfig,
    rr: RansacResult<AffineSubspace>,
    tau: f64,
) -> RobustResult {
    RobustResult {
        verdict: Verdict::NoRigidMajority {
            reason,
            inlier_fraction: 0.0,
            rival_fraction: 0.0,
            min_inlier_fraction: config.min_inlier_fraction,
        },
        inlier_tracks: vec![false; n],
        flagged_entries: Vec::new(),
        ambiguous_flags: Vec::new(),
        floor_kept: Vec::new(),
        noise_sigma: rr.sigma.unwrap_or(f64::NAN),
        threshold_px: tau,
        entry_threshold_px: f64::NAN,
        iterations: rr.iterations + rr.scale_iterations,
        score: rr.score,
        track_residuals: vec![None; n],
        coordinates: vec![None; n],
        model: None,
        candidate_tracks: vec![false; n],
        rival_tracks: 0,
        gross_rounds: 0,
        ransac: rr,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn symmetric_difference_of_sorted_lists() {
        let a = [(0, 1), (0, 3), (2, 0), (5, 5)];
        let b = [(0, 3), (1, 0), (5, 5), (6, 0)];
        assert_eq!(
            symmetric_difference(&a, &b),
            vec![(0, 1), (1, 0), (2, 0), (6, 0)]
        );
        assert!(symmetric_difference(&a, &a).is_empty());
        assert_eq!(symmetric_difference(&[], &b), b.to_vec());
    }

    #[test]
    fn binomial_tail_matches_direct_sums() {
        // P(X ≥ 3), X ~ Bin(9, 0.05) = 1 − Σ_{i<3} C(9,i) 0.05^i 0.95^(9−i) ≈ 0.00836.
        let direct = 1.0
            - (0.95f64.powi(9) + 9.0 * 0.05 * 0.95f64.powi(8) + 36.0 * 0.0025 * 0.95f64.powi(7));
        assert!((binomial_tail(9, 3, 0.05) - direct).abs() < 1e-12);
        assert!((direct - 0.00836).abs() < 5e-5);
        assert_eq!(binomial_tail(9, 0, 0.05), 1.0);
        assert_eq!(binomial_tail(9, 1, 0.0), 0.0);
        assert_eq!(binomial_tail(3, 4, 0.5), 0.0);
        assert!((binomial_tail(4, 1, 0.5) - 0.9375).abs() < 1e-12);
    }

    #[test]
    fn chi_square_and_normal_quantiles() {
        assert!((normal_quantile(0.999) - 3.090_232).abs() < 1e-4);
        assert!((normal_quantile(0.5)).abs() < 1e-6);
        assert!((chi2_quantile(2.0, 0.999) - 13.815_51).abs() < 1e-4);
        assert!((chi2_quantile(1.0, 0.99) - 6.634_897).abs() < 1e-3);
        // Tables: χ²₇(0.999) = 24.322, χ²₅₀(0.999) = 86.661.
        assert!((chi2_quantile(7.0, 0.999) - 24.322).abs() < 0.3);
        assert!((chi2_quantile(50.0, 0.999) / 86.661 - 1.0).abs() < 0.005);
    }
}
