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
//! Before step 3, a frame with entries flagged so far has a camera fitted without them. When
//! the frame is seen by few tracks that camera extrapolates, and the flagged entries (set
//! aside by the affine pass, which cannot explain perspective) look far off because they
//! were left out. So each such frame's camera is re-estimated from all its entries of the
//! fitted tracks (a resection, [`resect`]: Levenberg–Marquardt on the reprojection error
//! from the fitted camera, then twice again on the entries within `τ_e`), and the
//! re-estimated camera is used for the frame's verdict when it explains more of the
//! frame's entries within `τ_e` than the fitted one (a consensus test, as in RANSAC), and
//! the frame has at least [`MIN_RESECTION_ENTRIES`] of them. A camera the flagged entries
//! agree with clears their flags; the caller's refit then fits the frame with them.
//!
//! The same settings ([`RobustConfig`]) as the affine pass, so a user's thresholds mean the
//! same thing whatever the camera. Cost: two triangulations, `O(observations)`, and a
//! 12-parameter resection per frame with flagged entries, `O(entries of the frame)`.

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
    let mut cameras = model.cameras.clone();
    for _pass in 0..2 {
        let visible: Vec<bool> = (0..nf * np)
            .map(|i| meas.visible[i] && !hidden[i])
            .collect();
        let sub = Measurements::new(meas.w.clone(), visible);
        let points = ProjectiveModel {
            cameras: cameras.clone(),
            points: vec![[f64::NAN; 4]; np],
        }
        .triangulate(&sub);
        let entry = |f: usize, p: usize| [meas.w[(2 * f, p)], meas.w[(2 * f + 1, p)]];
        let dist_with = |c: &[f64; 12], f: usize, p: usize| -> f64 {
            let x = &points[p];
            if !x[0].is_finite() {
                return f64::INFINITY;
            }
            let [u, v] = super::project(c, x);
            let [a, b] = entry(f, p);
            ((u - a).powi(2) + (v - b).powi(2)).sqrt()
        };
        if sigma.is_nan() {
            let mut ds: Vec<f64> = meas
                .observed_pairs()
                .filter(|&(f, p)| fitted[p] && !hidden[f * np + p])
                .map(|(f, p)| dist_with(&cameras[f], f, p))
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
            // Frames with flagged entries: their cameras again, fitted with them.
            for f in 0..nf {
                if !(0..np).any(|p| hidden[f * np + p]) {
                    continue;
                }
                let tracks: Vec<usize> = (0..np)
                    .filter(|&p| fitted[p] && meas.is_visible(f, p) && points[p][0].is_finite())
                    .collect();
                if tracks.len() < MIN_RESECTION_ENTRIES {
                    continue;
                }
                let within = |c: &[f64; 12]| {
                    tracks
                        .iter()
                        .filter(|&&p| dist_with(c, f, p) <= tau)
                        .count()
                };
                let entries: Vec<([f64; 4], [f64; 2])> =
                    tracks.iter().map(|&p| (points[p], entry(f, p))).collect();
                let c = resect(&cameras[f], &entries, tau);
                if within(&c) > within(&cameras[f]) {
                    cameras[f] = c;
                }
            }
        }
        let dist = |f: usize, p: usize| dist_with(&cameras[f], f, p);
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

/// Entries a frame needs (of fitted tracks) for its camera to be re-estimated by the
/// verdict: 24 equations for the 11 degrees of freedom of a projective camera, so that a
/// camera fitted with a wrong entry still shows it.
pub const MIN_RESECTION_ENTRIES: usize = 12;

/// Camera resection: the projective camera `P` (row-major 3×4, pixels) minimizing
/// `Σ_i ‖π(P X_i) − w_i‖²` over `entries` `(X_i, w_i)`, by Levenberg–Marquardt (at most 20
/// iterations, Marquardt's diagonal scaling) from `start`, in coordinates where the
/// entries are centred with mean distance `√2` and the points have unit norm; then twice
/// more on the entries within `tau` pixels of the result (a trimmed fit). Returns `start`
/// when fewer than 6 entries remain. `O(entries)` per iteration (12×12 normal equations).
/// Reference: Hartley & Zisserman, *Multiple View Geometry*, 2nd ed., §7.2 (the gold
/// standard resection) and §4.4 (normalization).
pub fn resect(start: &[f64; 12], entries: &[([f64; 4], [f64; 2])], tau: f64) -> [f64; 12] {
    use nalgebra::{SMatrix, SVector};
    let n = entries.len().max(1) as f64;
    let (cx, cy) = entries
        .iter()
        .fold((0.0, 0.0), |(a, b), (_, w)| (a + w[0] / n, b + w[1] / n));
    let spread = entries
        .iter()
        .map(|(_, w)| ((w[0] - cx).powi(2) + (w[1] - cy).powi(2)).sqrt())
        .sum::<f64>()
        / n;
    if !(spread > 0.0) || entries.len() < 6 {
        return *start;
    }
    let s = std::f64::consts::SQRT_2 / spread;
    let local: Vec<([f64; 4], [f64; 2])> = entries
        .iter()
        .map(|(x, w)| {
            let norm = x.iter().map(|v| v * v).sum::<f64>().sqrt();
            (x.map(|v| v / norm), [(w[0] - cx) * s, (w[1] - cy) * s])
        })
        .collect();
    // P' = T P with T = [s 0 −s cx; 0 s −s cy; 0 0 1].
    let mut p = SVector::<f64, 12>::zeros();
    for c in 0..4 {
        p[c] = s * (start[c] - cx * start[8 + c]);
        p[4 + c] = s * (start[4 + c] - cy * start[8 + c]);
        p[8 + c] = start[8 + c];
    }
    p /= p.norm();
    let cost = |p: &SVector<f64, 12>, keep: &[bool]| -> f64 {
        local
            .iter()
            .zip(keep)
            .filter(|(_, k)| **k)
            .map(|((x, w), _)| {
                let [u, v] = super::project(p.as_slice().try_into().expect("12"), x);
                (u - w[0]).powi(2) + (v - w[1]).powi(2)
            })
            .sum()
    };
    let mut keep = vec![true; local.len()];
    for round in 0..3 {
        if keep.iter().filter(|&&k| k).count() < 6 {
            return *start;
        }
        let mut lambda = 1e-3;
        let mut e = cost(&p, &keep);
        for _ in 0..20 {
            let mut h = SMatrix::<f64, 12, 12>::zeros();
            let mut g = SVector::<f64, 12>::zeros();
            for ((x, w), _) in local.iter().zip(&keep).filter(|(_, k)| **k) {
                let xv = nalgebra::Vector4::from(*x);
                let d = p.fixed_rows::<4>(8).dot(&xv);
                if d.abs() < 1e-12 {
                    continue;
                }
                let u = p.fixed_rows::<4>(0).dot(&xv) / d;
                let v = p.fixed_rows::<4>(4).dot(&xv) / d;
                let mut ju = SVector::<f64, 12>::zeros();
                let mut jv = SVector::<f64, 12>::zeros();
                for c in 0..4 {
                    ju[c] = x[c] / d;
                    ju[8 + c] = -u * x[c] / d;
                    jv[4 + c] = x[c] / d;
                    jv[8 + c] = -v * x[c] / d;
                }
                h += ju * ju.transpose() + jv * jv.transpose();
                g += ju * (u - w[0]) + jv * (v - w[1]);
            }
            let mut improved = false;
            while lambda < 1e12 {
                let mut a = h;
                for i in 0..12 {
                    a[(i, i)] += lambda * h[(i, i)].max(1e-12);
                }
                let Some(ch) = a.cholesky() else {
                    lambda *= 10.0;
                    continue;
                };
                let mut q = p - ch.solve(&g);
                q /= q.norm();
                let e2 = cost(&q, &keep);
                if e2 < e {
                    let small = e - e2 <= 1e-12 * e;
                    p = q;
                    e = e2;
                    lambda = (lambda / 10.0).max(1e-12);
                    improved = !small;
                    break;
                }
                lambda *= 10.0;
            }
            if !improved {
                break;
            }
        }
        if round < 2 {
            let tau_local = tau * s;
            for ((x, w), k) in local.iter().zip(keep.iter_mut()) {
                let [u, v] = super::project(p.as_slice().try_into().expect("12"), x);
                *k = ((u - w[0]).powi(2) + (v - w[1]).powi(2)).sqrt() <= tau_local;
            }
        }
    }
    // P = T⁻¹ P'.
    let mut out = [0.0; 12];
    for c in 0..4 {
        out[8 + c] = p[8 + c];
        out[c] = p[c] / s + cx * p[8 + c];
        out[4 + c] = p[4 + c] / s + cy * p[8 + c];
    }
    out
}
