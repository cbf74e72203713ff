//! Outlier tracks and gross entries judged by the projective camera.
//!
//! The robust pass ([`crate::robust`]) finds outliers with the affine camera, which cannot
//! explain perspective: on real footage it rejects tracks that a projective camera fits to
//! a pixel. Once a projective model is fitted, every track is judged again by that model:
//!
//! 1. Each track's point is triangulated from the fitted cameras
//!    ([`ProjectiveModel::triangulate`]) on its entries not flagged so far (all entries for
//!    a track rejected by the affine pass).
//! 2. The entry noise `σ_e` (per coordinate) is the median image distance of the fitted
//!    tracks' entries divided by `sqrt(2 ln 2)` (the median of a Rayleigh distribution).
//! 3. Entries farther than `τ_e = max(sqrt(χ²₂(p_e)) σ_e, min_entry_threshold_px)` from their
//!    track's reprojection are flagged, `p_e = max(entry_probability, 1 − entry_false_alarms
//!    / n)` as in the robust pass (or the configured `entry_threshold_px`); each track is
//!    triangulated again without its flagged entries and its entries are flagged again.
//! 4. A track is an inlier when at most `max_flagged_fraction` of its entries are flagged,
//!    at least 2 remain, and `sqrt(Σ d² / ν) ≤ max(σ_e sqrt(χ²_ν(track_probability)/ν),
//!    min_track_threshold_px)` over its `k` unflagged entries, `ν = 2k − 3` (the point's
//!    three degrees of freedom), or `≤ ransac.threshold_px` when that is given.
//!
//! The same settings ([`RobustConfig`]) as the affine pass, so a user's thresholds mean the
//! same thing whatever the camera. Cost: two triangulations, `O(observations)`.

use super::ProjectiveModel;
use crate::Measurements;
use crate::robust::{RobustConfig, chi2_quantile};

/// Classification of every track and entry under a projective model.
#[derive(Debug, Clone, PartialEq)]
pub struct ProjectiveVerdict {
    pub inlier: Vec<bool>,
    /// Flagged entries of inlier tracks, (frame, track), sorted.
    pub flagged: Vec<(usize, usize)>,
    /// Entry noise σ_e per coordinate, pixels.
    pub noise_sigma_px: f64,
    /// Entry threshold, pixels.
    pub entry_threshold_px: f64,
}

/// Judges every track of `meas` (the fitted frames × all candidate tracks) by the cameras of
/// `model`. `fitted[p]` says which tracks the model was fitted to (they set `σ_e`);
/// `flagged` are the entries set aside so far.
pub fn judge(
    meas: &Measurements,
    model: &ProjectiveModel,
    fitted: &[bool],
    flagged: &[(usize, usize)],
    cfg: &RobustConfig,
) -> ProjectiveVerdict {
    let (nf, np) = (meas.n_frames(), meas.n_points());
    let mut hidden = vec![false; nf * np];
    for &(f, p) in flagged {
        if fitted[p] {
            hidden[f * np + p] = true;
        }
    }
    let mut sigma = f64::NAN;
    let mut tau = f64::NAN;
    for _pass in 0..2 {
        let visible: Vec<bool> = (0..nf * np)
            .map(|i| meas.visible[i] && !hidden[i])
            .collect();
        let sub = Measurements::new(meas.w.clone(), visible);
        let points = ProjectiveModel {
            cameras: model.cameras.clone(),
            points: vec![[f64::NAN; 4]; np],
        }
        .triangulate(&sub);
        let dist = |f: usize, p: usize| -> f64 {
            let x = &points[p];
            if !x[0].is_finite() {
                return f64::INFINITY;
            }
            let c = &model.cameras[f];
            let d = c[8] * x[0] + c[9] * x[1] + c[10] * x[2] + c[11] * x[3];
            let u = (c[0] * x[0] + c[1] * x[1] + c[2] * x[2] + c[3] * x[3]) / d;
            let v = (c[4] * x[0] + c[5] * x[1] + c[6] * x[2] + c[7] * x[3]) / d;
            ((u - meas.w[(2 * f, p)]).powi(2) + (v - meas.w[(2 * f + 1, p)]).powi(2)).sqrt()
        };
        if sigma.is_nan() {
            let mut ds: Vec<f64> = meas
                .observed_pairs()
                .filter(|&(f, p)| fitted[p] && !hidden[f * np + p])
                .map(|(f, p)| dist(f, p))
                .filter(|d| d.is_finite())
                .collect();
            ds.sort_by(|a, b| a.total_cmp(b));
            let med = if ds.is_empty() { 0.0 } else { ds[ds.len() / 2] };
            sigma = med / (2.0 * std::f64::consts::LN_2).sqrt();
            let n = meas.n_observed().max(1) as f64;
            let pe = cfg.entry_probability.max(1.0 - cfg.entry_false_alarms / n);
            tau = cfg.entry_threshold_px.unwrap_or_else(|| {
                (chi2_quantile(2.0, pe).sqrt() * sigma).max(cfg.min_entry_threshold_px)
            });
        }
        for (f, p) in meas.observed_pairs() {
            hidden[f * np + p] = dist(f, p) > tau;
        }
        if _pass == 1 {
            let mut inlier = vec![false; np];
            let mut out_flags = Vec::new();
            for p in 0..np {
                let (mut k, mut nflag, mut ss) = (0usize, 0usize, 0.0);
                for f in 0..nf {
                    if !meas.is_visible(f, p) {
                        continue;
                    }
                    if hidden[f * np + p] {
                        nflag += 1;
                    } else {
                        k += 1;
                        ss += dist(f, p).powi(2);
                    }
                }
                let total = k + nflag;
                if k < 2 || (nflag as f64) > cfg.max_flagged_fraction * total as f64 {
                    continue;
                }
                let nu = (2 * k) as f64 - 3.0;
                let r = (ss / nu).sqrt();
                let limit = match cfg.ransac.threshold_px {
                    Some(t) => t,
                    None => (sigma * (chi2_quantile(nu, cfg.track_probability) / nu).sqrt())
                        .max(cfg.min_track_threshold_px),
                };
                if r <= limit {
                    inlier[p] = true;
                    for f in 0..nf {
                        if meas.is_visible(f, p) && hidden[f * np + p] {
                            out_flags.push((f, p));
                        }
                    }
                }
            }
            out_flags.sort_unstable();
            return ProjectiveVerdict {
                inlier,
                flagged: out_flags,
                noise_sigma_px: sigma,
                entry_threshold_px: tau,
            };
        }
    }
    unreachable!("the loop returns on its second pass")
}
