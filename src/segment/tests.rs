use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Normal};

use super::*;

/// How an object moves.
#[derive(Clone, Copy)]
enum Motion {
    /// Rotates and translates.
    General,
    /// Translates only (its trajectories span a 2-dimensional affine subspace).
    Translation,
}

/// Tracks of `sizes.len()` rigid objects seen by a scaled orthographic camera over `f`
/// frames, plus `walks` random-walk tracks; returns (measurements, truth codes with −1 for
/// the walks). `hide` is the fraction of each track's frames hidden at its start or end.
fn scene(
    f: usize,
    sizes: &[(usize, Motion)],
    walks: usize,
    noise: f64,
    hide: f64,
    seed: u64,
) -> (Measurements, Vec<i64>) {
    let mut rng = StdRng::seed_from_u64(seed);
    let gauss = Normal::new(0.0, 1.0).unwrap();
    let n: usize = sizes.iter().map(|s| s.0).sum::<usize>() + walks;
    let mut w = faer::Mat::<f64>::zeros(2 * f, n);
    let mut truth = Vec::with_capacity(n);
    let mut col = 0;
    for (g, &(size, motion)) in sizes.iter().enumerate() {
        // A smooth random rotation path and image-plane drift per object.
        let axis = nalgebra::Vector3::new(
            gauss.sample(&mut rng),
            gauss.sample(&mut rng),
            gauss.sample(&mut rng),
        )
        .normalize();
        let speed = 0.02 + 0.03 * rng.random::<f64>();
        let start = nalgebra::Rotation3::from_scaled_axis(nalgebra::Vector3::new(
            gauss.sample(&mut rng),
            gauss.sample(&mut rng),
            gauss.sample(&mut rng),
        ));
        let centre = [
            100.0 + 400.0 * rng.random::<f64>(),
            100.0 + 300.0 * rng.random::<f64>(),
        ];
        let drift = [gauss.sample(&mut rng) * 3.0, gauss.sample(&mut rng) * 3.0];
        let extent = 40.0 + 60.0 * rng.random::<f64>();
        for _ in 0..size {
            let x = nalgebra::Vector3::new(
                extent * (2.0 * rng.random::<f64>() - 1.0),
                extent * (2.0 * rng.random::<f64>() - 1.0),
                extent * (2.0 * rng.random::<f64>() - 1.0),
            );
            for fr in 0..f {
                let r = match motion {
                    Motion::General => {
                        nalgebra::Rotation3::from_scaled_axis(axis * speed * fr as f64) * start
                    }
                    Motion::Translation => start,
                };
                let y = r * x;
                w[(2 * fr, col)] =
                    centre[0] + drift[0] * fr as f64 + y[0] + noise * gauss.sample(&mut rng);
                w[(2 * fr + 1, col)] =
                    centre[1] + drift[1] * fr as f64 + y[1] + noise * gauss.sample(&mut rng);
            }
            truth.push(g as i64);
            col += 1;
        }
    }
    for _ in 0..walks {
        let mut p = [
            100.0 + 400.0 * rng.random::<f64>(),
            100.0 + 300.0 * rng.random::<f64>(),
        ];
        for fr in 0..f {
            p[0] += 4.0 * gauss.sample(&mut rng);
            p[1] += 4.0 * gauss.sample(&mut rng);
            w[(2 * fr, col)] = p[0];
            w[(2 * fr + 1, col)] = p[1];
        }
        truth.push(-1);
        col += 1;
    }
    let mut visible = vec![true; f * n];
    if hide > 0.0 {
        for p in 0..n {
            let k = (hide * f as f64 * rng.random::<f64>()).round() as usize;
            let at_start = rng.random::<bool>();
            for i in 0..k {
                let fr = if at_start { i } else { f - 1 - i };
                visible[fr * n + p] = false;
            }
        }
    }
    (Measurements::new(w, visible), truth)
}

/// The subspace of `tracks` (indices of `ts`' tracks), refitted from the first minimal fit
/// of 4 consecutive ones.
fn fit_subspace(ts: &TrackSubspace, cfg: &SegmentConfig, tracks: &[usize]) -> AffineSubspace {
    let m0 = tracks
        .windows(4)
        .find_map(|w| ts.fit(w))
        .expect("a minimal fit");
    ts.refit_with(&m0, tracks, cfg.refit_sweeps)
        .expect("a subspace")
}

/// [`segment`] with the default settings (RNG seed 7), checked to find `k` groups.
fn segment_with_count(meas: &Measurements, k: usize) -> Segmentation {
    let seg = segment(
        meas,
        &SegmentConfig::default(),
        &mut StdRng::seed_from_u64(7),
    )
    .unwrap();
    let sizes: Vec<usize> = seg.objects.iter().map(|o| o.tracks.len()).collect();
    assert_eq!(seg.objects.len(), k, "groups found: {sizes:?}");
    seg
}

fn truth_groups(truth: &[i64]) -> Vec<usize> {
    truth
        .iter()
        .map(|&t| if t < 0 { usize::MAX } else { t as usize })
        .collect()
}

/// Misclassification over the objects' tracks only (the walks are scored separately).
fn error_on_objects(seg: &Segmentation, truth: &[i64]) -> f64 {
    let idx: Vec<usize> = (0..truth.len()).filter(|&p| truth[p] >= 0).collect();
    let found: Vec<i64> = idx.iter().map(|&p| seg.labels[p].code()).collect();
    let t: Vec<usize> = truth_groups(truth)
        .into_iter()
        .enumerate()
        .filter(|(p, _)| truth[*p] >= 0)
        .map(|x| x.1)
        .collect();
    misclassification(&found, &t)
}

#[test]
fn noise_free_complete_scenes_are_segmented_exactly() {
    for (sizes, seed) in [
        (vec![(60, Motion::General), (30, Motion::General)], 1u64),
        (
            vec![
                (50, Motion::General),
                (40, Motion::General),
                (25, Motion::General),
            ],
            2,
        ),
    ] {
        let (meas, truth) = scene(30, &sizes, 0, 0.0, 0.0, seed);
        let seg = segment(
            &meas,
            &SegmentConfig::default(),
            &mut StdRng::seed_from_u64(7),
        )
        .unwrap();
        assert_eq!(seg.objects.len(), sizes.len(), "groups found");
        assert_eq!(error_on_objects(&seg, &truth), 0.0);
        assert_eq!(seg.n_outliers(), 0);
    }
}

#[test]
fn noisy_partial_scene_with_translating_object_and_random_walks() {
    let sizes = [
        (80, Motion::General),
        (30, Motion::Translation),
        (30, Motion::General),
    ];
    let (meas, truth) = scene(40, &sizes, 10, 0.5, 0.4, 3);
    let seg = segment_with_count(&meas, 3);
    let err = error_on_objects(&seg, &truth);
    assert!(err <= 0.05, "misclassification {err}");
    // Every random walk is an outlier, and (almost) no object track is.
    let walks_flagged = (0..truth.len())
        .filter(|&p| truth[p] < 0 && seg.labels[p] == Label::Outlier)
        .count();
    assert!(
        walks_flagged >= 9,
        "{walks_flagged} of 10 walks labelled outlier"
    );
    assert!(seg.n_outliers() <= 12, "outliers {}", seg.n_outliers());
    let objects_as_outliers = (0..truth.len())
        .filter(|&p| truth[p] >= 0 && seg.labels[p] == Label::Outlier)
        .count();
    // Re-judged under the refitted subspaces, no object track is left as an outlier (one
    // was before: a short track in frames the chosen hypothesis was not defined on).
    assert_eq!(objects_as_outliers, 0, "object tracks labelled outlier");
    // σ close to the noise.
    assert!((seg.sigma - 0.5).abs() < 0.15, "sigma {}", seg.sigma);

    // Every track assigned (`label_outliers = false`): the same groups, the tracks that
    // were grouped keep their group, and no track is an outlier.
    let all = segment(
        &meas,
        &SegmentConfig {
            label_outliers: false,
            ..SegmentConfig::default()
        },
        &mut StdRng::seed_from_u64(7),
    )
    .unwrap();
    assert_eq!(all.objects.len(), seg.objects.len());
    assert_eq!(all.n_outliers(), 0);
    let mut map = std::collections::HashMap::new();
    for (a, b) in seg.labels.iter().zip(&all.labels) {
        match (a, b) {
            (Label::Object(i), Label::Object(j)) => {
                assert_eq!(*map.entry(*i).or_insert(*j), *j, "group {i} split");
            }
            (Label::Object(_), other) => panic!("a grouped track became {other:?}"),
            (Label::Unscored, b) => assert_eq!(*b, Label::Unscored),
            (Label::Outlier, b) => assert!(matches!(b, Label::Object(_))),
        }
    }
    // The groups' subspaces are fitted to the tracks the outlier model grouped, not to the
    // walks assigned afterwards.
    for (i, j) in map {
        assert!(
            seg.objects[i].model.m == all.objects[j].model.m,
            "group {i}: the subspace moved"
        );
    }
}

#[test]
fn one_rigid_body_is_one_group_and_a_given_count_is_honoured() {
    let (meas, truth) = scene(30, &[(100, Motion::General)], 0, 0.5, 0.0, 4);
    let seg = segment(
        &meas,
        &SegmentConfig::default(),
        &mut StdRng::seed_from_u64(1),
    )
    .unwrap();
    assert_eq!(seg.objects.len(), 1);
    assert!(seg.n_outliers() <= 2);
    assert_eq!(
        error_on_objects(&seg, &truth),
        seg.n_outliers() as f64 / 100.0
    );

    let (meas, truth) = scene(
        30,
        &[(60, Motion::General), (40, Motion::General)],
        0,
        0.5,
        0.0,
        5,
    );
    let cfg = SegmentConfig {
        objects: Objects::Count(2),
        ..Default::default()
    };
    let seg = segment(&meas, &cfg, &mut StdRng::seed_from_u64(1)).unwrap();
    assert_eq!(seg.objects.len(), 2);
    assert!(error_on_objects(&seg, &truth) <= 0.01);
}

#[test]
fn misclassification_matches_groups_optimally() {
    // Found groups are a relabelling of the truth, one track wrong, one outlier.
    let truth = [0, 0, 0, 1, 1, 2, 2, 2];
    let found = [2, 2, 1, 0, 0, 1, 1, -1];
    let e = misclassification(&found, &truth);
    assert!((e - 2.0 / 8.0).abs() < 1e-12, "{e}");
}

#[test]
fn bad_configuration_and_too_few_tracks_are_errors() {
    let (meas, _) = scene(10, &[(3, Motion::General)], 0, 0.0, 0.0, 6);
    let r = segment(
        &meas,
        &SegmentConfig::default(),
        &mut StdRng::seed_from_u64(1),
    );
    assert!(matches!(r, Err(Error::TooFew { .. })), "{r:?}");
    let cfg = SegmentConfig {
        objects: Objects::Count(0),
        ..Default::default()
    };
    assert!(matches!(
        cfg.validate(),
        Err(Error::InvalidConfig {
            field: "objects",
            ..
        })
    ));
    for (field, cfg) in [
        (
            "label_cost_scale",
            SegmentConfig {
                label_cost_scale: f64::NAN,
                ..Default::default()
            },
        ),
        (
            "split_separation",
            SegmentConfig {
                split_separation: -1.0,
                ..Default::default()
            },
        ),
        (
            "max_group_sigma_ratio",
            SegmentConfig {
                max_group_sigma_ratio: f64::INFINITY,
                ..Default::default()
            },
        ),
    ] {
        match cfg.validate() {
            Err(Error::InvalidConfig { field: f, .. }) => assert_eq!(f, field),
            r => panic!("{field}: {r:?}"),
        }
    }
}

/// Small scenes where the label cost alone (`eigengap = 0`) under-counts: two bodies of
/// 30 and 20 tracks over 12 frames, 1 px noise (like Hopkins' small sequences). The label
/// cost finds one group on each of 8 seeds; the preference affinity's eigengap raises 6 of
/// them to the two bodies, segmented exactly (measured; seeds 1 and 7 stay at one group).
#[test]
fn the_eigengap_raises_an_undercounted_small_scene() {
    let (mut raised, mut separated, mut both_raised) = (0, 0, 0);
    for seed in 1..=8u64 {
        let (meas, truth) = scene(
            12,
            &[(30, Motion::General), (20, Motion::General)],
            0,
            1.0,
            0.0,
            seed,
        );
        let run = |eigengap: f64, split_separation: f64| {
            // The perspective merge test (a fit per pair) only with both count rules on,
            // the defaults: these scenes are affine, and it must not join the bodies.
            let defaults = eigengap > 0.0 && split_separation > 0.0;
            let cfg = SegmentConfig {
                eigengap,
                split_separation,
                merge_ratio: if defaults {
                    SegmentConfig::default().merge_ratio
                } else {
                    0.0
                },
                ..SegmentConfig::default()
            };
            segment(&meas, &cfg, &mut StdRng::seed_from_u64(7)).unwrap()
        };
        let energy = run(0.0, 0.0);
        assert_eq!(energy.objects.len(), 1, "seed {seed}: the label cost alone");
        assert_eq!(energy.count_rule, CountRule::LabelCost);
        for (eigengap, split, count) in [
            (0.5, 0.0, &mut raised),
            (0.0, 10.0, &mut separated),
            (0.5, 10.0, &mut both_raised),
        ] {
            let r = run(eigengap, split);
            assert!(
                r.objects.len() <= 2,
                "seed {seed}: never more than the bodies"
            );
            if r.objects.len() == 2 {
                assert!(error_on_objects(&r, &truth) <= 0.02, "seed {seed}");
                assert!(
                    r.separation.is_some_and(|q| q > 1.0),
                    "seed {seed}: {:?}",
                    r.separation
                );
                *count += 1;
            }
        }
    }
    eprintln!("raised: eigengap {raised}, separation {separated}, both {both_raised} of 8");
    assert!(raised >= 6, "eigengap raised {raised} of 8");
    // At 1 px of noise over 12 frames the two bodies' median ratio is 4.7–38 (3 of 8 at
    // ≥ 10, measured); the real sequences' partly dependent motions are the rule's case
    // (tests/segmentation.rs).
    assert!(separated >= 3, "separation raised {separated} of 8");
    assert!(
        both_raised >= raised.max(separated),
        "both raised {both_raised} of 8"
    );
}

/// Tracks noisier than `max_group_sigma` (2 px of noise per coordinate): the bound on a
/// group's σ follows the data's own noise level (`max_group_sigma_ratio`), so the bodies
/// are still groups; with the fixed 2 px bound alone (ratio 0) no hypothesis survives and
/// the segmentation failed (`Degenerate`).
#[test]
fn noisy_tracks_still_form_groups() {
    let (meas, truth) = scene(
        30,
        &[(150, Motion::General), (90, Motion::General)],
        0,
        2.0,
        0.0,
        5,
    );
    let run = |ratio: f64| {
        // With the fixed bound the tracks fall into many small groups; the perspective
        // merge test, a fit per pair of them, has nothing to do with the bound.
        let cfg = SegmentConfig {
            max_group_sigma_ratio: ratio,
            merge_ratio: if ratio > 0.0 {
                SegmentConfig::default().merge_ratio
            } else {
                0.0
            },
            ..SegmentConfig::default()
        };
        segment(&meas, &cfg, &mut StdRng::seed_from_u64(3))
    };
    let seg = run(SegmentConfig::default().max_group_sigma_ratio).unwrap();
    let sizes: Vec<usize> = seg.objects.iter().map(|o| o.tracks.len()).collect();
    assert_eq!(
        seg.objects.len(),
        2,
        "groups found: {sizes:?}, σ {}",
        seg.sigma
    );
    let err = error_on_objects(&seg, &truth);
    assert!(err <= 0.02, "misclassification {err}");
    assert!((seg.sigma - 2.0).abs() < 0.4, "sigma {}", seg.sigma);
    // With the fixed bound alone every local hypothesis is above it: no group at all.
    match run(0.0) {
        Err(Error::Degenerate(_)) => {}
        Ok(s) => assert!(
            s.n_outliers() > meas.n_points() / 2,
            "with the fixed bound: {} groups, {} outliers",
            s.objects.len(),
            s.n_outliers()
        ),
        Err(e) => panic!("{e}"),
    }
}

/// Each track's neighbour list holds its `k` nearest trajectories and no more memory than
/// that: a list that kept the buffer of all `N` candidates made the lists `N²` in all
/// (6.9 GB at 20 000 tracks, docs/results.md).
#[test]
fn neighbour_lists_are_the_k_nearest_and_sized_k() {
    let (meas, truth) = scene(
        12,
        &[(150, Motion::General), (150, Motion::General)],
        0,
        0.0,
        0.0,
        3,
    );
    let ts = TrackSubspace::new(&meas, &SubspaceConfig::default());
    let eligible: Vec<usize> = (0..meas.n_points()).collect();
    let k = 12;
    let nbrs = neighbours(&ts, &eligible, k);
    assert_eq!(nbrs.len(), meas.n_points());
    let dist = |p: usize, q: usize| -> f64 {
        (0..2 * meas.n_frames())
            .map(|r| (meas.w[(r, p)] - meas.w[(r, q)]).powi(2))
            .sum()
    };
    for (p, list) in nbrs.iter().enumerate() {
        assert_eq!(list.len(), k, "track {p}");
        assert!(
            list.capacity() <= k,
            "track {p}: capacity {}",
            list.capacity()
        );
        assert!(!list.contains(&p));
        // Sorted by trajectory distance (every track sees every frame, so the mean over
        // shared frames orders them as the whole trajectories do).
        for pair in list.windows(2) {
            assert!(dist(p, pair[0]) <= dist(p, pair[1]));
        }
    }
    // Most neighbours are on the track's own object (the two may overlap in the image).
    let same = nbrs
        .iter()
        .enumerate()
        .flat_map(|(p, l)| l.iter().map(move |&q| (p, q)))
        .filter(|&(p, q)| truth[p] == truth[q])
        .count();
    assert!(
        same * 10 >= 9 * k * meas.n_points(),
        "{same} of {}",
        k * meas.n_points()
    );
}

/// Tracks seen in only 3–4 frames (fewer than `min_overlap`) take no part in the search;
/// step 7 gives them to the group that explains them, and never a random walk.
#[test]
fn short_tracks_join_their_group_and_short_walks_do_not() {
    let f = 30;
    let sizes = [(60, Motion::General), (40, Motion::General)];
    let (meas, truth) = scene(f, &sizes, 12, 0.5, 0.0, 11);
    let n = truth.len();
    // Every third object track and every walk cut to a window of 3 or 4 frames.
    let mut visible = meas.visible.clone();
    let mut rng = StdRng::seed_from_u64(5);
    let short: Vec<usize> = (0..n).filter(|&p| truth[p] < 0 || p % 3 == 0).collect();
    for &p in &short {
        let len = 3 + (p % 2);
        let start = rng.random_range(0..=f - len);
        for fr in 0..f {
            visible[fr * n + p] = (start..start + len).contains(&fr);
        }
    }
    let meas = Measurements::new(meas.w.clone(), visible);
    let run = |short_track_frames| {
        segment(
            &meas,
            &SegmentConfig {
                short_track_frames,
                ..SegmentConfig::default()
            },
            &mut StdRng::seed_from_u64(7),
        )
        .unwrap()
    };
    let off = run(5);
    assert!(short.iter().all(|&p| off.labels[p] == Label::Unscored));
    let seg = run(SegmentConfig::default().short_track_frames);
    assert_eq!(seg.objects.len(), 2);
    // Each found group's true object, by the majority of its long tracks.
    let truth_of = |g: usize| {
        let long = |t| {
            seg.objects[g]
                .tracks
                .iter()
                .filter(|&&p| !short.contains(&p) && truth[p] == t)
                .count()
        };
        if long(0) >= long(1) { 0 } else { 1 }
    };
    let (mut right, mut wrong) = (0, 0);
    for &p in short.iter().filter(|&&p| truth[p] >= 0) {
        if let Label::Object(g) = seg.labels[p] {
            if truth_of(g) == truth[p] {
                right += 1;
            } else {
                wrong += 1;
            }
        }
    }
    let objects_short = short.iter().filter(|&&p| truth[p] >= 0).count();
    assert_eq!(wrong, 0, "short tracks given the wrong group");
    assert!(
        right * 10 >= objects_short * 8,
        "{right} of {objects_short} short object tracks placed"
    );
    let walks_placed = (0..n)
        .filter(|&p| truth[p] < 0 && matches!(seg.labels[p], Label::Object(_)))
        .count();
    assert_eq!(walks_placed, 0, "short random walks given a group");
    // The groups' member lists hold the short tracks they took.
    for (g, o) in seg.objects.iter().enumerate() {
        assert!(o.tracks.windows(2).all(|w| w[0] < w[1]));
        assert!(o.tracks.iter().all(|&p| seg.labels[p] == Label::Object(g)));
    }
}

/// A small object (24 tracks beside 250) is a group of its own even when a random walk or
/// two land in it: the bound on a group's noise is judged on its typical track, not on a
/// mean that one walk carries above the bound (before: labelled outliers).
#[test]
fn small_object_holding_a_walk_is_still_a_group() {
    let sizes = [(250, Motion::General), (24, Motion::General)];
    let (meas, truth) = scene(30, &sizes, 15, 0.5, 0.0, 21);
    let seg = segment_with_count(&meas, 2);
    let err = error_on_objects(&seg, &truth);
    assert!(err <= 0.02, "misclassification {err}");
}

/// A long sequence of short tracks (`rank3 synth --missing 0.85`: each track seen in 18 of
/// the 120 frames). Segmented whole, local hypotheses cannot carry one subspace per body
/// over every frame (`rank3 reconstruct --objects auto` on these tables: 48.6 % and 50.3 %
/// misclassified, 4 and 2 groups; docs/results.md); window by window the bodies are
/// found, one body stays one group, and the walks are labelled outliers.
#[test]
fn a_long_sequence_of_short_tracks_is_segmented_by_windows() {
    use crate::synth::{ObjectMotion, OutlierKind, SynthConfig, SynthObject, generate};
    for (objects, seed) in [
        (
            vec![SynthObject {
                share: 0.3,
                motion: ObjectMotion::Rotating,
            }],
            1u64,
        ),
        (vec![], 2),
    ] {
        let scene = generate(&SynthConfig {
            frames: 120,
            points: 500,
            missing: 0.85,
            outliers: 0.05,
            outlier_kind: OutlierKind::RandomWalk,
            objects: objects.clone(),
            seed,
            ..Default::default()
        })
        .unwrap();
        let meas = scene.table.measurements();
        let truth: Vec<i64> = (0..scene.objects.len())
            .map(|p| match scene.outlier_tracks[p] {
                Some(_) => -1,
                None => scene.objects[p] as i64,
            })
            .collect();
        // Fewer hypotheses per window than the default 400, for the debug build's time.
        let cfg = SegmentConfig {
            hypotheses: 250,
            ..Default::default()
        };
        let seg = segment(&meas, &cfg, &mut StdRng::seed_from_u64(7)).unwrap();
        let sizes: Vec<usize> = seg.objects.iter().map(|o| o.tracks.len()).collect();
        assert_eq!(seg.count_rule, CountRule::Windows);
        if seed == 1 {
            // The sparse table, segmented without its dense W, gives the same segmentation
            // to the last bit.
            let sparse = segment_table(&scene.table, &cfg, &mut StdRng::seed_from_u64(7)).unwrap();
            assert_eq!(sparse.labels, seg.labels);
            assert_eq!(sparse.objects.len(), seg.objects.len());
            for (a, b) in sparse.objects.iter().zip(&seg.objects) {
                assert_eq!(a.tracks, b.tracks);
                assert_eq!(a.model.defined, b.model.defined);
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&a.model.m), bits(&b.model.m));
                assert_eq!(bits(&a.model.t), bits(&b.model.t));
                assert_eq!(a.rms.to_bits(), b.rms.to_bits());
            }
        }
        assert_eq!(
            seg.objects.len(),
            1 + objects.len(),
            "groups found: {sizes:?}"
        );
        let err = error_on_objects(&seg, &truth);
        assert!(err < 0.12, "misclassified {err}, groups {sizes:?}");
        // The walks are outliers (at most a fifth of them taken by a group).
        let walks: Vec<usize> = (0..truth.len()).filter(|&p| truth[p] < 0).collect();
        let taken = walks
            .iter()
            .filter(|&&p| matches!(seg.labels[p], Label::Object(_)))
            .count();
        assert!(
            5 * taken <= walks.len(),
            "{taken} of {} walks grouped",
            walks.len()
        );
        // Each group's subspace, chained from its windows', is defined on (nearly) every
        // frame and explains its typical track to the noise (0.5 px).
        let ts = TrackSubspace::new(&meas, &cfg.subspace);
        for o in &seg.objects {
            assert!(
                o.model.n_defined() >= 110,
                "{} frames, groups {sizes:?}",
                o.model.n_defined()
            );
            let rms: Vec<f64> = o
                .tracks
                .iter()
                .filter_map(|&p| ts.track_fit(&o.model, p).map(|f| f.rms))
                .collect();
            assert!(rms.len() * 10 >= o.tracks.len() * 9, "{} scored", rms.len());
            let median = crate::eval::median(&rms);
            assert!(
                median < 0.7,
                "median track RMS {median}, group RMS {}",
                o.rms
            );
        }
    }
}

/// [`other_objects_seeded`]: an object among a few seed tracks of a search over the whole
/// table is found with the hypotheses seeded there only (50 of them here, for 40 seeds of
/// 280 candidates), its tracks and none of the scene's.
#[test]
fn a_seeded_search_finds_the_object_among_its_seeds() {
    let sizes = [(250, Motion::General), (30, Motion::General)];
    let (meas, truth) = scene(30, &sizes, 0, 0.5, 0.0, 5);
    let cfg = SegmentConfig::default();
    let ts = TrackSubspace::new(&meas, &cfg.subspace);
    let scene_tracks: Vec<usize> = (0..250).collect();
    let m0 = ts.fit(&scene_tracks[..4]).expect("a minimal fit");
    let main = ts
        .refit_with(&m0, &scene_tracks, cfg.refit_sweeps)
        .expect("the scene's subspace");
    let candidates: Vec<usize> = (0..meas.n_points()).collect();
    // The object's 30 tracks and 10 of the scene's.
    let seeds: Vec<usize> = (240..280).collect();
    let mut rng = StdRng::seed_from_u64(3);
    let groups =
        other_objects_seeded(&meas, &main, 0.5, &candidates, Some(&seeds), &cfg, &mut rng).unwrap();
    assert_eq!(groups.len(), 1, "{} groups", groups.len());
    let g = &groups[0].tracks;
    let on_object = g.iter().filter(|&&p| truth[p] == 1).count();
    assert!(on_object >= 29, "{on_object} of the object's 30 tracks");
    assert_eq!(g.len(), on_object, "scene tracks in the group: {g:?}");
}

#[test]
fn a_sample_is_segmented_and_every_other_track_labelled() {
    // Three bodies (one translating), 40 % of each track's frames hidden, 12 random walks;
    // half the tracks segmented, the other half labelled against the groups found.
    let sizes = [
        (160, Motion::General),
        (60, Motion::General),
        (40, Motion::Translation),
    ];
    let (meas, truth) = scene(40, &sizes, 12, 0.5, 0.4, 11);
    let table = crate::TrackTable::from_measurements(&meas);
    let n = truth.len();
    let sample: Vec<usize> = (0..n).filter(|p| p % 2 == 0).collect();
    let seg = segment_table_sampled(
        &table,
        &sample,
        &SegmentConfig::default(),
        &mut StdRng::seed_from_u64(7),
    )
    .unwrap()
    .expect("segmented whole, not by windows");
    assert_eq!(seg.labels.len(), n);
    assert_eq!(seg.objects.len(), 3, "groups found");
    // Ordered by the whole membership, largest first, and consistent with the labels.
    let sizes_found: Vec<usize> = seg.objects.iter().map(|o| o.tracks.len()).collect();
    assert!(
        sizes_found.windows(2).all(|w| w[0] >= w[1]),
        "{sizes_found:?}"
    );
    for (g, o) in seg.objects.iter().enumerate() {
        assert!(o.tracks.iter().all(|&p| seg.labels[p] == Label::Object(g)));
    }
    let labelled: usize = sizes_found.iter().sum();
    let grouped = seg
        .labels
        .iter()
        .filter(|l| matches!(l, Label::Object(_)))
        .count();
    assert_eq!(labelled, grouped);
    // The tracks outside the sample are labelled as well as those in it: both halves'
    // object tracks within 2 % of the truth, and the walks outliers.
    let err = error_on_objects(&seg, &truth);
    assert!(err <= 0.02, "misclassification {err}");
    let odd_objects: Vec<usize> = (0..n).filter(|&p| p % 2 == 1 && truth[p] >= 0).collect();
    let found: Vec<i64> = odd_objects.iter().map(|&p| seg.labels[p].code()).collect();
    let t: Vec<usize> = odd_objects.iter().map(|&p| truth[p] as usize).collect();
    let err_odd = misclassification(&found, &t);
    assert!(
        err_odd <= 0.02,
        "misclassification outside the sample {err_odd}"
    );
    let walks_out = (0..n)
        .filter(|&p| truth[p] < 0 && seg.labels[p] == Label::Outlier)
        .count();
    assert!(walks_out >= 11, "{walks_out} of 12 walks labelled outlier");

    // A sample of every track is the whole segmentation; a bad index is an error.
    let whole = segment_table(
        &table,
        &SegmentConfig::default(),
        &mut StdRng::seed_from_u64(7),
    )
    .unwrap();
    let all = segment_table_sampled(
        &table,
        &(0..n).collect::<Vec<_>>(),
        &SegmentConfig::default(),
        &mut StdRng::seed_from_u64(7),
    )
    .unwrap()
    .unwrap();
    assert_eq!(all.labels, whole.labels);
    for bad in [vec![3, 2], vec![0, n]] {
        assert!(matches!(
            segment_table_sampled(
                &table,
                &bad,
                &SegmentConfig::default(),
                &mut StdRng::seed_from_u64(7)
            ),
            Err(Error::InvalidConfig {
                field: "sample",
                ..
            })
        ));
    }
}

#[test]
fn a_search_sample_is_bounded_and_prefers_the_suspects() {
    // 3000 tracks of 100 frames: m = 60 000 / 100 = 600 tracks, half of them from the 400
    // preferred; 100 tracks: all.
    let tracks: Vec<usize> = (0..3000).collect();
    let preferred = |p: usize| p % 30 < 4;
    let mut rng = StdRng::seed_from_u64(3);
    let s = search_sample(&tracks, |_| 100, preferred, &mut rng);
    assert_eq!(s.len(), 600);
    assert!(s.windows(2).all(|w| w[0] < w[1]), "increasing, no repeats");
    assert_eq!(s.iter().filter(|&&p| preferred(p)).count(), 300);
    let again = search_sample(&tracks, |_| 100, preferred, &mut StdRng::seed_from_u64(3));
    assert_eq!(s, again, "reproducible with the seed");
    // Fewer preferred than half: all of them, the rest from the others.
    let s = search_sample(&tracks, |_| 100, |p| p < 50, &mut rng);
    assert_eq!((s.len(), s.iter().filter(|&&p| p < 50).count()), (600, 50));
    // Short tracks: the budget in tracks is capped; long ones: at least 200 tracks.
    assert_eq!(
        search_sample(&tracks, |_| 10, preferred, &mut rng).len(),
        SEARCH_MAX_TRACKS
    );
    assert_eq!(
        search_sample(&tracks, |_| 5000, preferred, &mut rng).len(),
        SEARCH_MIN_TRACKS
    );
    assert_eq!(
        search_sample(&tracks[..100], |_| 100, preferred, &mut rng),
        (0..100).collect::<Vec<_>>()
    );
}

#[test]
fn a_noisy_group_is_judged_by_its_refitted_consensus() {
    // A second body's 40 tracks in one group with 20 random walks (σ of the group far above
    // `max_group_sigma`): its rigid consensus is found, refitted, held to the bound on its
    // typical track, and judged; the walks are not taken along. The scene's tracks carry
    // a gross entry each (30–60 px), which the trimmed fits ignore.
    let (mut meas, truth) = scene(
        30,
        &[(250, Motion::General), (40, Motion::General)],
        20,
        0.5,
        0.0,
        12,
    );
    let mut rng = StdRng::seed_from_u64(4);
    for p in 0..250 {
        let fr = rng.random_range(0..30);
        let a = std::f64::consts::TAU * rng.random::<f64>();
        let d = 30.0 + 30.0 * rng.random::<f64>();
        meas.w[(2 * fr, p)] += d * a.cos();
        meas.w[(2 * fr + 1, p)] += d * a.sin();
    }
    let cfg = SegmentConfig::default();
    let ts = TrackSubspace::new(&meas, &cfg.subspace);
    let fit = |tracks: &[usize]| fit_subspace(&ts, &cfg, tracks);
    let main = fit(&(0..250).collect::<Vec<_>>());
    // The objects judged in one noisy group of `tracks` (σ 10 px, the scene's 0.5 px).
    let judge = |tracks: Vec<usize>, rng: &mut StdRng| {
        let model = fit(&tracks);
        let group = ObjectGroup {
            tracks,
            rms: 10.0,
            sigma: 10.0,
            model,
            pieces: 1,
        };
        other_objects_among(&meas, &main, 0.5, &[group], &cfg, rng).expect("valid input")
    };
    for seed in 0..3 {
        let mut rng = StdRng::seed_from_u64(seed);
        let found = judge((250..310).collect(), &mut rng);
        assert_eq!(found.len(), 1, "seed {seed}: {} bodies", found.len());
        let on = found[0].tracks.iter().filter(|&&p| truth[p] == 1).count();
        assert!(
            on >= 39 && found[0].tracks.len() == on,
            "seed {seed}: {on} of the body's 40 tracks, group {:?}",
            found[0].tracks
        );
        // The walks alone are no body.
        let found = judge((290..310).collect(), &mut rng);
        assert!(found.is_empty(), "seed {seed}: walks taken for a body");
    }
}

#[test]
fn an_object_split_over_two_noisy_groups_is_found_whole() {
    // A second body's 40 tracks spread over two groups of the segmentation, each with 15
    // random walks (σ far above `max_group_sigma`): the first group's consensus, refitted,
    // takes the body's tracks of the second group too, and the second group, whose
    // consensus is then claimed, adds no body. Each half alone is a body (judged apart):
    // without the widening the result would be two bodies of 20.
    let (meas, truth) = scene(
        30,
        &[(250, Motion::General), (40, Motion::General)],
        30,
        0.5,
        0.0,
        21,
    );
    let cfg = SegmentConfig::default();
    let ts = TrackSubspace::new(&meas, &cfg.subspace);
    let fit = |tracks: &[usize]| fit_subspace(&ts, &cfg, tracks);
    let main = fit(&(0..250).collect::<Vec<_>>());
    let group = |tracks: Vec<usize>| ObjectGroup {
        model: fit(&tracks),
        tracks,
        rms: 10.0,
        sigma: 10.0,
        pieces: 1,
    };
    // Body tracks 250..270 with walks 290..305; body tracks 270..290 with walks 305..320.
    let groups = [
        group((250..270).chain(290..305).collect()),
        group((270..290).chain(305..320).collect()),
    ];
    for seed in 0..3 {
        let mut rng = StdRng::seed_from_u64(seed);
        let found =
            other_objects_among(&meas, &main, 0.5, &groups, &cfg, &mut rng).expect("valid input");
        assert_eq!(found.len(), 1, "seed {seed}: {} bodies", found.len());
        let on = found[0].tracks.iter().filter(|&&p| truth[p] == 1).count();
        assert!(
            on >= 39 && found[0].tracks.len() == on,
            "seed {seed}: {on} of the body's 40 tracks, group {:?}",
            found[0].tracks
        );
        // Each half alone is judged a body: the test above is the widening's.
        let half = other_objects_among(&meas, &main, 0.5, &groups[1..], &cfg, &mut rng)
            .expect("valid input");
        assert_eq!(half.len(), 1, "seed {seed}: the second half alone");
    }
}
