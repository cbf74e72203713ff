//! Ground-truth tests of robust track rejection and gross-entry flagging.

use std::collections::HashSet;

use faer::Mat;
use rand::SeedableRng;
use rand::rngs::StdRng;
use rank3::robust::{
    NoMajorityReason, RansacConfig, RobustConfig, RobustResult, Verdict, robust_filter,
};
use rank3::synth::{OutlierKind, SynthConfig, SynthScene, generate};
use rank3::{Error, Measurements};

fn scene(kind: OutlierKind, outliers: f64, missing: f64, gross: f64, seed: u64) -> SynthScene {
    generate(&SynthConfig {
        frames: 16,
        points: 80,
        outliers,
        outlier_kind: kind,
        missing,
        min_track_length: 6,
        gross,
        seed,
        ..Default::default()
    })
    .unwrap()
}

fn run(s: &SynthScene, seed: u64) -> RobustResult {
    run_cfg(s, seed, &RobustConfig::default())
}

fn run_cfg(s: &SynthScene, seed: u64, cfg: &RobustConfig) -> RobustResult {
    robust_filter(
        &s.table.measurements(),
        cfg,
        &mut StdRng::seed_from_u64(seed),
    )
    .unwrap()
}

/// (precision, recall) of the outlier-track flags.
fn track_pr(s: &SynthScene, r: &RobustResult) -> (f64, f64) {
    let n = s.outlier_tracks.len();
    let flagged: Vec<usize> = (0..n).filter(|&p| !r.inlier_tracks[p]).collect();
    let actual = s.outlier_tracks.iter().filter(|o| o.is_some()).count();
    let tp = flagged
        .iter()
        .filter(|&&p| s.outlier_tracks[p].is_some())
        .count();
    let precision = if flagged.is_empty() {
        1.0
    } else {
        tp as f64 / flagged.len() as f64
    };
    let recall = if actual == 0 {
        1.0
    } else {
        tp as f64 / actual as f64
    };
    (precision, recall)
}

#[test]
fn outlier_tracks_of_each_kind_are_rejected_complete() {
    outlier_tracks_of_each_kind_are_rejected(0.0);
}

#[test]
fn outlier_tracks_of_each_kind_are_rejected_missing() {
    outlier_tracks_of_each_kind_are_rejected(0.3);
}

fn outlier_tracks_of_each_kind_are_rejected(missing: f64) {
    {
        for (i, kind) in [
            OutlierKind::RandomWalk,
            OutlierKind::SecondObject,
            OutlierKind::Sliding,
        ]
        .into_iter()
        .enumerate()
        {
            let s = scene(kind, 0.3, missing, 0.0, 100 + i as u64);
            let r = run(&s, 1);
            assert!(
                r.verdict.is_rigid_majority(),
                "{kind:?} {missing}: {:?}",
                r.verdict
            );
            let (p, rc) = track_pr(&s, &r);
            // 24 outliers among 80 tracks: ≥ 0.95 allows one mistake. With missing data a
            // short sliding track is indistinguishable from a point at another depth (over
            // a few frames of a turn, sliding along the image direction that depth moves
            // is explained by a depth change), so a few such tracks may be kept.
            let min_recall = if kind == OutlierKind::Sliding && missing > 0.0 {
                0.8
            } else {
                0.95
            };
            assert!(
                p >= 0.95 && rc >= min_recall,
                "{kind:?} missing {missing}: precision {p:.3}, recall {rc:.3}"
            );
            // The image noise is 0.5 px per coordinate.
            assert!(
                (r.noise_sigma - 0.5).abs() < 0.15,
                "{kind:?} missing {missing}: σ̂ = {}",
                r.noise_sigma
            );
        }
    }
}

/// A scene of `robust_benchmark`'s size: 30 frames × 300 tracks, 40 % missing.
fn benchmark_scene(kind: OutlierKind, outliers: f64, gross: f64, seed: u64) -> SynthScene {
    generate(&SynthConfig {
        frames: 30,
        points: 300,
        outliers,
        outlier_kind: kind,
        gross,
        missing: 0.4,
        min_track_length: 6,
        seed,
        ..Default::default()
    })
    .unwrap()
}

/// A track that drifts away from the rigid motion (another object, a slide) can look like
/// a good track with a few gross entries: its worst frames exceed the entry threshold
/// modestly, and without them the rest passes. Such *ambiguous* flags count in the track
/// test (`gross_entry_factor`), so these tracks are rejected. Scenes of the benchmark's
/// size with 40 % missing, where the rule `gross_entry_factor = 1` (ambiguous flags ignored)
/// kept 6–7 of the 90 outlier tracks (recall 0.922 and 0.933; robust_benchmark seeds 1, 2).
#[test]
fn drifting_tracks_cannot_hide_behind_entry_flags() {
    for (kind, seed) in [(OutlierKind::SecondObject, 1), (OutlierKind::Mixed, 2)] {
        let s = benchmark_scene(kind, 0.3, 0.05, seed);
        let r = run(&s, 1);
        let (p, rc) = track_pr(&s, &r);
        // 90 outlier tracks: 0.95 allows 4 misses, a few of which (short windows) are
        // within noise of a rigid trajectory.
        assert!(
            p >= 0.98 && rc >= 0.95,
            "{kind:?} seed {seed}: precision {p:.3}, recall {rc:.3}"
        );
    }
}

/// A short good track can carry more than `max_flagged_fraction` of gross entries by chance
/// (3 of 9 at a 5 % gross rate: probability 0.008). It is kept when its flags are clearly
/// gross (none ambiguous) and that many is plausible at the observed rate. Scenes where
/// the fixed fraction alone rejected one good track each (precision 0.968; robust_benchmark
/// seeds 11 and 2), while every outlier track is still rejected.
#[test]
fn short_good_tracks_with_several_gross_entries_are_kept() {
    for (kind, seed) in [(OutlierKind::RandomWalk, 11), (OutlierKind::Sliding, 2)] {
        let s = benchmark_scene(kind, 0.1, 0.05, seed);
        let r = run(&s, 1);
        let (p, rc) = track_pr(&s, &r);
        assert!(
            p >= 0.99 && rc >= 0.99,
            "{kind:?} seed {seed}: precision {p:.3}, recall {rc:.3}"
        );
    }
}

#[test]
fn clean_scene_keeps_nearly_every_track() {
    for missing in [0.0, 0.3] {
        let s = generate(&SynthConfig {
            frames: 16,
            points: 100,
            missing,
            min_track_length: 6,
            seed: 7,
            ..Default::default()
        })
        .unwrap();
        let r = run(&s, 2);
        assert!(r.verdict.is_rigid_majority());
        let kept = r.n_inliers();
        assert!(kept >= 99, "missing {missing}: kept {kept} of 100");
        // The entry test's false-alarm rate is at most 1e-4 for Gaussian noise with an exact
        // model (0.1 / #entries here);
        // with missing data the affine model is estimated from fewer tracks per frame and
        // its error adds to the residuals: allow 0.5 % of the entries.
        let obs = s.table.n_observed() as f64;
        assert!(
            r.flagged_entries.len() as f64 <= 0.005 * obs,
            "{} of {obs} entries flagged",
            r.flagged_entries.len()
        );
    }
}

/// The estimated entry threshold grows with the table (`entry_false_alarms`, a Bonferroni
/// correction), so a clean 40 × 1500 table (60 000 entries) has about 0.1 false entry
/// flags instead of the 6 the fixed per-entry probability 0.9999 would give.
#[test]
fn false_entry_flags_do_not_grow_with_the_table() {
    let s = generate(&SynthConfig {
        frames: 40,
        points: 1500,
        seed: 12,
        ..Default::default()
    })
    .unwrap();
    let n = s.table.n_observed() as f64;
    let r = run(&s, 4);
    assert!(r.verdict.is_rigid_majority());
    let k = (-2.0 * (0.1 / n).ln()).sqrt();
    assert!(
        (r.entry_threshold_px - k * r.noise_sigma).abs() <= 1e-9 * r.entry_threshold_px,
        "threshold {} px, σ̂ {} px, expected {k:.3} σ̂",
        r.entry_threshold_px,
        r.noise_sigma
    );
    assert!(
        r.flagged_entries.len() <= 2,
        "{} of {n} good entries flagged at {k:.2} σ̂",
        r.flagged_entries.len()
    );
    // `entry_false_alarms = ∞` is the fixed per-entry probability alone.
    let fixed = run_cfg(
        &s,
        4,
        &RobustConfig {
            entry_false_alarms: f64::INFINITY,
            ..RobustConfig::default()
        },
    );
    let k0 = (-2.0 * (1e-4f64).ln()).sqrt();
    assert!((fixed.entry_threshold_px - k0 * fixed.noise_sigma).abs() <= 1e-9 * k0);
}

#[test]
fn gross_entries_are_flagged() {
    for missing in [0.0, 0.3] {
        let s = scene(OutlierKind::Mixed, 0.2, missing, 0.04, 21);
        let r = run(&s, 3);
        assert!(r.verdict.is_rigid_majority());
        let truth: HashSet<(usize, usize)> = s.gross_entries.iter().copied().collect();
        assert!(truth.len() >= 15, "scene has {} gross entries", truth.len());
        let tp = r
            .flagged_entries
            .iter()
            .filter(|e| truth.contains(e))
            .count();
        let precision = tp as f64 / r.flagged_entries.len().max(1) as f64;
        // Gross entries on tracks wrongly rejected cannot be flagged: recall is measured on
        // the retained tracks' entries, and the track flags are checked too.
        let on_inliers = truth.iter().filter(|e| r.inlier_tracks[e.1]).count();
        let recall = tp as f64 / on_inliers.max(1) as f64;
        // Same remark as above for precision with missing data.
        let min_precision = if missing > 0.0 { 0.85 } else { 0.95 };
        assert!(
            precision >= min_precision && recall >= 0.95,
            "missing {missing}: entry precision {precision:.3}, recall {recall:.3}"
        );
        // A short track with two gross entries can be rejected as a whole (more than
        // `max_flagged_fraction` of it is flagged): with missing data (tracks of 6–16
        // frames here) allow 20 % of the gross entries to sit on rejected tracks.
        let min_kept = if missing > 0.0 { 0.8 } else { 0.95 };
        assert!(
            on_inliers as f64 >= min_kept * truth.len() as f64,
            "missing {missing}: {on_inliers} of {} gross entries on kept tracks",
            truth.len()
        );
        let (p, rc) = track_pr(&s, &r);
        // Track flags on this small scene (16 frames, mixed outliers, 4 % gross): with
        // missing data short sliding / second-object tracks can be kept (see above) and
        // short good tracks with two gross entries rejected.
        let (min_p, min_r) = if missing > 0.0 {
            (0.85, 0.75)
        } else {
            (0.95, 0.95)
        };
        assert!(p >= min_p && rc >= min_r, "track P {p:.3} R {rc:.3}");
        // The flag → refit loop converges before its cap.
        assert!(
            r.gross_rounds < RobustConfig::default().max_gross_rounds,
            "missing {missing}: {} refits",
            r.gross_rounds
        );
    }
}

#[test]
fn no_rigid_majority_is_reported_not_hidden() {
    // Fewer hypotheses than the default cap keep this fast in debug builds; the verdicts
    // do not depend on it.
    let cfg = RobustConfig {
        ransac: RansacConfig {
            max_iterations: 300,
            ..Default::default()
        },
        rival_max_iterations: 150,
        ..Default::default()
    };
    // 70 % random walks: the rigid group is 30 % of the tracks.
    let s = scene(OutlierKind::RandomWalk, 0.7, 0.0, 0.0, 31);
    let r = run_cfg(&s, 4, &cfg);
    match r.verdict {
        Verdict::NoRigidMajority {
            reason,
            inlier_fraction,
            ..
        } => {
            assert_eq!(reason, NoMajorityReason::TooFewInliers);
            assert!(inlier_fraction < 0.4, "{inlier_fraction}");
        }
        v => panic!("expected no majority, got {v:?}"),
    }
    assert!(r.model.is_none() && r.inlier_tracks.iter().all(|&b| !b));
    assert!(r.flagged_entries.is_empty());

    // Two rigid objects of equal size.
    let s = scene(OutlierKind::SecondObject, 0.5, 0.0, 0.0, 32);
    let r = run_cfg(&s, 5, &cfg);
    match r.verdict {
        Verdict::NoRigidMajority {
            inlier_fraction,
            rival_fraction,
            ..
        } => {
            assert!(
                inlier_fraction > 0.4 && rival_fraction > 0.4,
                "{inlier_fraction} {rival_fraction}"
            );
        }
        v => panic!("expected no majority, got {v:?}"),
    }
    assert!(r.model.is_none());
    // The best group found is still one of the two objects (diagnostics).
    let group: Vec<bool> = (0..80)
        .filter(|&p| r.candidate_tracks[p])
        .map(|p| s.outlier_tracks[p].is_some())
        .collect();
    assert!(group.iter().all(|&b| b == group[0]));
}

/// Two equal rigid objects with missing data are still reported as no majority. In this
/// held-out benchmark scene (30 × 300, 50 % second object, 5 % gross, 40 % missing, seed
/// 339) the rival search used to stop adaptively after a partial group (78 of the 143
/// tracks of the other object, seen in some frames only), and the second object was
/// claimed as the rigid majority.
#[test]
fn two_equal_objects_with_missing_data_are_no_majority() {
    let s = benchmark_scene(OutlierKind::SecondObject, 0.5, 0.05, 339);
    let r = run(&s, 1);
    match r.verdict {
        Verdict::NoRigidMajority {
            reason,
            rival_fraction,
            ..
        } => {
            assert_eq!(reason, NoMajorityReason::RivalGroup);
            assert!(rival_fraction > 0.4, "rival {rival_fraction}");
        }
        v => panic!("expected no majority, got {v:?}"),
    }
}

#[test]
fn the_seed_makes_results_reproducible() {
    let s = scene(OutlierKind::Mixed, 0.3, 0.3, 0.02, 41);
    let (a, b) = (run(&s, 9), run(&s, 9));
    assert_eq!(a.inlier_tracks, b.inlier_tracks);
    assert_eq!(a.flagged_entries, b.flagged_entries);
    assert_eq!(a.iterations, b.iterations);
    assert_eq!(a.score.to_bits(), b.score.to_bits());
    assert_eq!(a.noise_sigma.to_bits(), b.noise_sigma.to_bits());
}

#[test]
fn a_given_threshold_is_used() {
    let s = scene(OutlierKind::Sliding, 0.2, 0.0, 0.0, 51);
    let cfg = RobustConfig {
        ransac: RansacConfig {
            threshold_px: Some(1.0),
            ..Default::default()
        },
        entry_threshold_px: Some(5.0),
        ..Default::default()
    };
    let r = robust_filter(&s.table.measurements(), &cfg, &mut StdRng::seed_from_u64(0)).unwrap();
    assert_eq!(r.threshold_px, 1.0);
    assert_eq!(r.entry_threshold_px, 5.0);
    assert_eq!(r.ransac.scale_iterations, 0);
    let (p, rc) = track_pr(&s, &r);
    assert!(p >= 0.95 && rc >= 0.95, "P {p:.3} R {rc:.3}");
    for (p, res) in r.track_residuals.iter().enumerate() {
        if r.inlier_tracks[p] {
            assert!(res.unwrap() <= 1.0);
        }
    }
}

#[test]
fn unusable_input_is_a_typed_error() {
    let cfg = RobustConfig::default();
    let mut rng = StdRng::seed_from_u64(0);
    let two_frames = Measurements::complete(Mat::from_fn(4, 20, |r, c| (r * c) as f64));
    assert!(matches!(
        robust_filter(&two_frames, &cfg, &mut rng),
        Err(Error::TooFew {
            needed: 3,
            have: 2,
            ..
        })
    ));
    let few_tracks = Measurements::complete(Mat::from_fn(20, 5, |r, c| (r + c) as f64));
    assert!(matches!(
        robust_filter(&few_tracks, &cfg, &mut rng),
        Err(Error::TooFew {
            needed: 8,
            have: 5,
            ..
        })
    ));
    // Every track seen in 2 frames only: nothing can be scored.
    let mut vis = vec![false; 10 * 12];
    for p in 0..12 {
        vis[(p % 9) * 12 + p] = true;
        vis[(p % 9 + 1) * 12 + p] = true;
    }
    let short = Measurements::new(Mat::from_fn(20, 12, |r, c| (r + c) as f64), vis);
    assert!(matches!(
        robust_filter(&short, &cfg, &mut rng),
        Err(Error::TooFew {
            needed: 4,
            have: 0,
            ..
        })
    ));
    let bad = RobustConfig {
        min_inlier_fraction: 1.5,
        ..Default::default()
    };
    let s = scene(OutlierKind::Mixed, 0.0, 0.0, 0.0, 1);
    assert!(matches!(
        robust_filter(&s.table.measurements(), &bad, &mut rng),
        Err(Error::InvalidConfig {
            field: "min_inlier_fraction",
            ..
        })
    ));
}

/// No frame's camera stays off with its good entries flagged. Two held-out scenes of the
/// benchmark's kind (30 × 300, mixed outliers 30 %, 1 % gross entries, 40 % missing):
/// * seed 101: the last frame, seen by 37 tracks, started poorly; ALS's reweighting cut kept
///   only the 4 entries its camera passed near and fitted it exactly through them, and 22
///   of the frame's 26 good entries were flagged (structure error 134× clean). ALS now skips
///   the cut in a frame where fewer than half of the entries pass.
/// * seed 216: the first frame's camera was still off after the first refit (ALS converges
///   slowly where few tracks link a frame to the rest); 18 of its 29 good entries were
///   flagged and the refits, which set flagged entries aside, kept it off. A frame with more
///   than `max_flagged_fraction` of its entries flagged now has its camera re-estimated from
///   the tracks' own coordinates (resection) and its flags re-examined.
#[test]
fn no_frame_keeps_an_off_camera_with_its_entries_flagged() {
    for seed in [101, 216] {
        let s = benchmark_scene(OutlierKind::Mixed, 0.3, 0.01, seed);
        let r = run(&s, 1);
        assert!(r.verdict.is_rigid_majority());
        let gross: HashSet<(usize, usize)> = s.gross_entries.iter().copied().collect();
        let mut false_flags = vec![0usize; s.table.n_frames()];
        for &(f, p) in &r.flagged_entries {
            if s.outlier_tracks[p].is_none() && !gross.contains(&(f, p)) {
                false_flags[f] += 1;
            }
        }
        // About 0.1 false flags are expected in the whole table (`entry_false_alarms`);
        // a frame whose camera is off has tens.
        assert!(
            false_flags.iter().all(|&c| c <= 2),
            "seed {seed}: false entry flags per frame: {false_flags:?}"
        );
    }
}
