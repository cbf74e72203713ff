//! Diagnosis of the robust pass's misses against ground truth (development tool).
//!
//! `cargo run --release --example robust_diag -- [seed] [missing]`
//!
//! For every outlier track: frames observed `k`, the χ² statistic of its observations
//! against the TRUE rigid affine subspace (true cameras, best 3D point by least squares),
//! `χ² = Σ‖e‖²/σ²` with `ν = 2k − 3`, its noise-free part `λ` (same scene generated with
//! σ = 0), and whether the pass flagged it. For every false-positive entry flag: whether
//! its track is a true outlier, the track length, the entry's distance. For every frame with
//! three or more false flags on true inlier tracks: how many tracks see it, the outlier
//! tracks and gross entries among the kept ones, and how far the final model's camera is
//! from the truth there (`DIAG_FRAMES=1` also lists each entry: observed, predicted, true).

use faer::Mat;
use nalgebra::{Matrix3, Vector3};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rank3::robust::{RobustConfig, SubspaceConfig, TrackSubspace, chi2_quantile, robust_filter};
use rank3::synth::{OutlierKind, SynthConfig, generate};

/// Sum of squared distances of track `p` (observed frames) to the true rigid subspace.
fn true_ss(scene: &rank3::synth::SynthScene, w: &Mat<f64>, vis: &[bool], p: usize) -> (usize, f64) {
    let t = &scene.truth;
    let nf = t.n_frames();
    let n = vis.len() / nf;
    let frames: Vec<usize> = (0..nf).filter(|&f| vis[f * n + p]).collect();
    let mut g = Matrix3::zeros();
    let mut b = Vector3::zeros();
    let rows = |f: usize| {
        let r = t.rotations[f].matrix();
        let s = t.scales[f];
        [
            Vector3::new(s * r[(0, 0)], s * r[(0, 1)], s * r[(0, 2)]),
            Vector3::new(s * r[(1, 0)], s * r[(1, 1)], s * r[(1, 2)]),
        ]
    };
    for &f in &frames {
        let m = rows(f);
        for c in 0..2 {
            let y = w[(2 * f + c, p)] - t.translations[f][c];
            g += m[c] * m[c].transpose();
            b += m[c] * y;
        }
    }
    let x = g
        .try_inverse()
        .map(|gi| gi * b)
        .unwrap_or_else(Vector3::zeros);
    let mut ss = 0.0;
    for &f in &frames {
        let m = rows(f);
        for c in 0..2 {
            let y = w[(2 * f + c, p)] - t.translations[f][c];
            ss += (m[c].dot(&x) - y).powi(2);
        }
    }
    (frames.len(), ss)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let seed: u64 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(11);
    let missing: f64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(0.4);
    let cfg = RobustConfig::default();
    for (kind, outliers, gross) in [
        (OutlierKind::RandomWalk, 0.1, 0.05),
        (OutlierKind::RandomWalk, 0.3, 0.05),
        (OutlierKind::SecondObject, 0.1, 0.01),
        (OutlierKind::SecondObject, 0.3, 0.01),
        (OutlierKind::Sliding, 0.3, 0.05),
        (OutlierKind::Mixed, 0.3, 0.05),
        (OutlierKind::Mixed, 0.3, 0.01),
    ] {
        let sc = SynthConfig {
            frames: 30,
            points: 300,
            outliers,
            outlier_kind: kind,
            gross,
            missing,
            min_track_length: 6,
            seed,
            ..Default::default()
        };
        let scene = generate(&sc)?;
        let nf = generate(&SynthConfig {
            noise: 0.0,
            ..sc.clone()
        })?;
        let sigma = sc.noise;
        let meas = scene.table.measurements();
        let m0 = nf.table.measurements();
        let r = robust_filter(&meas, &cfg, &mut StdRng::seed_from_u64(1))?;
        let n = meas.n_points();
        println!(
            "\n## {kind:?} {:.0}% out {:.0}% gross, missing {missing}, seed {seed}: σ̂ = {:.3}, entry thr {:.2}",
            100.0 * outliers,
            100.0 * gross,
            r.noise_sigma,
            r.entry_threshold_px
        );
        let gross_set: std::collections::HashSet<(usize, usize)> =
            scene.gross_entries.iter().copied().collect();
        let (mut n_out, mut missed, mut undet, mut fp_tracks) = (0, 0, 0, 0);
        for p in 0..n {
            let is_out = scene.outlier_tracks[p].is_some();
            let flagged = !r.inlier_tracks[p];
            if !is_out && !flagged {
                continue;
            }
            let (k, ss) = true_ss(&scene, &meas.w, &meas.visible, p);
            let (_, lam) = true_ss(&nf, &m0.w, &m0.visible, p);
            // Gross entries would dominate: report the statistic without them.
            let nu = (2 * k) as f64 - 3.0;
            let chi = ss / (sigma * sigma);
            let q99 = chi2_quantile(nu, 0.99);
            let q9999 = chi2_quantile(nu, 0.9999);
            if is_out {
                n_out += 1;
                if chi <= q99 {
                    undet += 1;
                }
            } else {
                fp_tracks += 1;
            }
            if is_out && !flagged {
                missed += 1;
            }
            if is_out
                && !flagged
                && let Some(model) = &r.model
            {
                let est = TrackSubspace::new(&meas, &SubspaceConfig::default());
                let fr: Vec<u32> = est.frames_of(p).to_vec();
                let Some(s_all) = est.ls_coords(model, p, &fr) else {
                    continue;
                };
                let mut line = String::new();
                let mut ss = 0.0;
                for &f in &fr {
                    let d = est.dist2(model, p, f as usize, &s_all).sqrt() / r.noise_sigma;
                    ss += d * d;
                    let fl = r.flagged_entries.binary_search(&(f as usize, p)).is_ok();
                    line += &format!(" {f}:{d:.1}{}", if fl { "*" } else { "" });
                }
                println!(
                    "    model fit on all entries: χ² {ss:.1} (ν {}); d/σ̂ per frame (* flagged):{line}",
                    2 * fr.len() - 3
                );
            }
            if (is_out && !flagged) || (!is_out && flagged) || chi <= q99 {
                let ngross = (0..30).filter(|&f| gross_set.contains(&(f, p))).count();
                println!(
                    "  track {p:3} {} {:?}: k = {k:2}, true rms {:.2} px, χ² {:.1} (ν {nu}, q99 {:.1}, q9999 {:.1}), λ {:.1}, alg resid {:?}, gross {ngross}",
                    if is_out { "MISSED-OUT" } else { "FALSE-OUT " },
                    scene.outlier_tracks[p],
                    (ss / nu).sqrt(),
                    chi,
                    q99,
                    q9999,
                    lam / (sigma * sigma),
                    r.track_residuals[p].map(|x| (x * 1000.0).round() / 1000.0),
                );
            }
        }
        println!(
            "  outliers {n_out}, missed {missed}, true χ² ≤ q99 (undetectable) {undet}, false outlier flags {fp_tracks}"
        );
        // Entry false positives.
        for &(f, p) in &r.flagged_entries {
            if gross_set.contains(&(f, p)) {
                continue;
            }
            let k = (0..30).filter(|&g| meas.visible[g * n + p]).count();
            let d = {
                let t = scene.truth.project(f, p);
                ((meas.w[(2 * f, p)] - t[0]).powi(2) + (meas.w[(2 * f + 1, p)] - t[1]).powi(2))
                    .sqrt()
            };
            println!(
                "  FP entry ({f},{p}): track {} k = {k}, |obs − true proj| = {d:.2} px",
                if scene.outlier_tracks[p].is_some() {
                    "OUTLIER"
                } else {
                    "inlier"
                }
            );
        }
        // Frames with several false flags: is that frame's camera off, and what in it?
        let mut per_frame = vec![0usize; 30];
        for &(f, p) in &r.flagged_entries {
            if !gross_set.contains(&(f, p)) && scene.outlier_tracks[p].is_none() {
                per_frame[f] += 1;
            }
        }
        for (f, &fp) in per_frame.iter().enumerate() {
            let Some(model) = r.model.as_ref().filter(|_| fp >= 3) else {
                continue;
            };
            let (mut n_obs, mut n_out, mut ss, mut cnt) = (0, 0, 0.0, 0);
            let mut contaminators = String::new();
            for p in 0..n {
                if !meas.visible[f * n + p] || !r.inlier_tracks[p] {
                    continue;
                }
                n_obs += 1;
                let t = scene.truth.project(f, p);
                let dev = ((meas.w[(2 * f, p)] - t[0]).powi(2)
                    + (meas.w[(2 * f + 1, p)] - t[1]).powi(2))
                .sqrt();
                if scene.outlier_tracks[p].is_some() || gross_set.contains(&(f, p)) {
                    n_out += 1;
                    let fl = r.flagged_entries.binary_search(&(f, p)).is_ok();
                    contaminators += &format!(" {p}:{dev:.1}px{}", if fl { "*" } else { "" });
                } else if let Some([x, y]) = r.coordinates[p].map(|s| model.predict(f, &s)) {
                    ss += (x - t[0]).powi(2) + (y - t[1]).powi(2);
                    cnt += 1;
                    if std::env::var("DIAG_FRAMES").is_ok() {
                        let fl = r.flagged_entries.binary_search(&(f, p)).is_ok();
                        println!(
                            "    {p}: obs ({:.1},{:.1}) pred ({x:.1},{y:.1}) true ({:.1},{:.1}) flagged {fl}",
                            meas.w[(2 * f, p)],
                            meas.w[(2 * f + 1, p)],
                            t[0],
                            t[1]
                        );
                    }
                }
            }
            let in_frame = (0..n).filter(|&p| meas.visible[f * n + p]).count();
            println!(
                "  frame {f} (defined {}): {fp} false flags; {in_frame} tracks observed, {n_obs} kept, of which {n_out} outlier/gross entries (track:|obs − true| px, * flagged):{contaminators}; model vs truth RMS over true inliers {:.2} px",
                model.defined[f],
                (ss / cnt.max(1) as f64).sqrt()
            );
        }
        // Missed gross entries.
        for &(f, p) in &scene.gross_entries {
            if r.inlier_tracks[p] && r.flagged_entries.binary_search(&(f, p)).is_err() {
                let k = (0..30).filter(|&g| meas.visible[g * n + p]).count();
                println!("  missed gross entry ({f},{p}) k = {k}");
            } else if !r.inlier_tracks[p] {
                let k = (0..30).filter(|&g| meas.visible[g * n + p]).count();
                println!("  gross entry ({f},{p}) on a rejected good track (k = {k})");
            }
        }
    }
    Ok(())
}
