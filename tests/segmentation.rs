//! Motion segmentation and per-object reconstruction ([`rank3::segment`],
//! [`rank3::objects`]) against synthetic truth and on real Hopkins 155 sequences.

use rank3::eval::align_similarity;
use rank3::segment::{Label, SegmentConfig, misclassification};
use rank3::synth::{ObjectMotion, OutlierKind, SynthConfig, SynthObject, generate};
use rank3::{CameraModel, Config};

/// Misclassification of `labels` over a synthetic scene's object tracks (its random walks
/// scored apart; a track labelled outlier counts as wrong).
fn object_error(scene: &rank3::synth::SynthScene, labels: &[Label]) -> f64 {
    let idx: Vec<usize> = (0..scene.objects.len())
        .filter(|&p| scene.outlier_tracks[p].is_none())
        .collect();
    let found: Vec<i64> = idx.iter().map(|&p| labels[p].code()).collect();
    let truth: Vec<usize> = idx.iter().map(|&p| scene.objects[p]).collect();
    misclassification(&found, &truth)
}

/// The tracks of a data-set file (`None`, saying so, when the data sets are not there).
fn dataset(rel: &str) -> Option<rank3::Measurements> {
    let Some(path) = rank3::datasets::find(rel) else {
        eprintln!("SKIPPED: {rel} not found (set RANK3_DATASETS)");
        return None;
    };
    Some(
        rank3::table::read_tracks(&path)
            .unwrap()
            .table
            .measurements(),
    )
}

/// The Hopkins sequence `hopkins_dev/NAME.txt` (`None`, saying so, when the data sets are
/// not there).
fn hopkins(name: &str) -> Option<rank3::datasets::Hopkins> {
    let rel = format!("hopkins_dev/{name}.txt");
    let Some(path) = rank3::datasets::find(&rel) else {
        eprintln!("SKIPPED: {rel} not found (set RANK3_DATASETS)");
        return None;
    };
    Some(rank3::datasets::read_hopkins(&path).unwrap())
}

/// Three objects and random walks: the groups are found (K automatically), the walks
/// labelled outliers, and each rotating object's reconstruction matches its true shape up
/// to a similarity. Complete tracks with a translating object, then partial tracks with
/// rotating ones (a translating object's short partial tracks are also explained by a
/// turning body's subspace over their few frames: with 20 % missing they merge, measured).
#[test]
fn synthetic_objects_are_found_and_each_reconstructed() {
    for (missing, third) in [
        (0.0, ObjectMotion::Translating),
        (0.2, ObjectMotion::Rotating),
    ] {
        check_scene(missing, third);
    }
}

/// Three rigid bodies seen orthographically over 30 frames (240 tracks: the scene, a
/// rotating object with 25 % of them and a `third` with 20 %; 0.5 px of noise, `missing`
/// entries hidden, 5 % random-walk tracks).
fn three_bodies(missing: f64, third: ObjectMotion) -> rank3::synth::SynthScene {
    let cfg = SynthConfig {
        camera: CameraModel::Orthographic,
        frames: 30,
        points: 240,
        noise: 0.5,
        missing,
        min_track_length: 12,
        outliers: 0.05,
        outlier_kind: OutlierKind::RandomWalk,
        objects: vec![
            SynthObject {
                share: 0.25,
                motion: ObjectMotion::Rotating,
            },
            SynthObject {
                share: 0.2,
                motion: third,
            },
        ],
        seed: 3,
        ..Default::default()
    };
    generate(&cfg).unwrap()
}

fn check_scene(missing: f64, third: ObjectMotion) {
    let scene = three_bodies(missing, third);
    let config = Config {
        camera: CameraModel::Orthographic,
        ..Default::default()
    };
    let mb = rank3::objects::reconstruct_objects(&scene.table, &config, &SegmentConfig::default())
        .unwrap();
    let sizes: Vec<usize> = mb.objects.iter().map(|o| o.tracks.len()).collect();
    assert_eq!(mb.objects.len(), 3, "groups {sizes:?}");
    // Misclassification over the object tracks (walks scored apart).
    let err = object_error(&scene, &mb.segmentation.labels);
    assert!(err <= 0.03, "misclassification {err}, groups {sizes:?}");
    let walks: Vec<usize> = (0..240)
        .filter(|&p| scene.outlier_tracks[p].is_some())
        .collect();
    let flagged = walks
        .iter()
        .filter(|&&p| mb.segmentation.labels[p] == Label::Outlier)
        .count();
    assert!(
        flagged + 1 >= walks.len(),
        "{flagged} of {} walks flagged",
        walks.len()
    );
    // Each rotating object's structure against its true shape (the extra objects are the
    // shape scaled by 0.35: a similarity).
    for o in &mb.objects {
        let third_object = o.tracks.iter().filter(|&&p| scene.objects[p] == 2).count();
        if third == ObjectMotion::Translating && third_object > o.tracks.len() / 2 {
            continue; // the translating object: its depth is not observable
        }
        let rec = o
            .reconstruction
            .as_ref()
            .expect("rotating objects are reconstructed");
        let (est, tru): (Vec<_>, Vec<_>) = rec
            .kept_tracks
            .iter()
            .enumerate()
            .map(|(i, &p)| (rec.model.points[i], scene.truth.points[o.tracks[p]]))
            .unzip();
        let a = align_similarity(&est, &tru, true).unwrap();
        assert!(
            a.relative_rms < 0.05,
            "object {}: structure error {}",
            o.index,
            a.relative_rms
        );
    }
}

/// Two real two-motion Hopkins 155 sequences (skipped without the data set): the number
/// of groups is found and almost every track is grouped right.
#[test]
fn hopkins_two_motion_sequences() {
    for (name, bound) in [("arm", 0.03), ("1R2RC_g12", 0.02)] {
        let Some(h) = hopkins(name) else {
            return;
        };
        let cfg = SegmentConfig {
            image_area: Some(h.image_size.0 * h.image_size.1),
            ..Default::default()
        };
        use rand::SeedableRng;
        let s = rank3::segment::segment(
            &h.measurements,
            &cfg,
            &mut rand::rngs::StdRng::seed_from_u64(1),
        )
        .unwrap();
        assert_eq!(s.objects.len(), 2, "{name}");
        let err = misclassification(&s.codes(), &h.groups);
        assert!(err <= bound, "{name}: misclassification {err}");
    }
}

/// Partly dependent motions on a small sequence (Hopkins `two_cranes_g12`, 72 tracks;
/// skipped without the data set): the label cost and the affinity's eigengap both name one
/// group, the separation of the two-group partition names two (its median ratio measured
/// 23), grouped exactly. With the separation rule off, one group: the rule is what counts
/// the second crane. The rule leaves the dinosaur (one rigid body, partial tracks; the
/// label cost finds one group or two depending on the draw) as it was: its best two-group
/// split has a median ratio of 7.5.
#[test]
fn partly_dependent_motions_are_counted_by_their_separation() {
    use rand::SeedableRng;
    use rank3::segment::{CountRule, segment};
    let Some(h) = hopkins("two_cranes_g12") else {
        return;
    };
    let run = |split_separation: f64| {
        let cfg = SegmentConfig {
            image_area: Some(h.image_size.0 * h.image_size.1),
            split_separation,
            ..Default::default()
        };
        segment(
            &h.measurements,
            &cfg,
            &mut rand::rngs::StdRng::seed_from_u64(1),
        )
        .unwrap()
    };
    let off = run(0.0);
    assert_eq!(off.objects.len(), 1, "without the rule");
    let on = run(SegmentConfig::default().split_separation);
    assert_eq!(on.objects.len(), 2);
    assert_eq!(on.count_rule, CountRule::Separation);
    let q = on.separation.unwrap();
    assert!(q >= 10.0, "separation {q}");
    let err = misclassification(&on.codes(), &h.groups);
    assert!(err <= 0.02, "misclassification {err}");

    let Some(meas) = dataset("dino_trimmed/M_dense.txt") else {
        return;
    };
    for seed in [0, 1] {
        let groups = |split_separation: f64| {
            let cfg = SegmentConfig {
                split_separation,
                ..Default::default()
            };
            let s = segment(&meas, &cfg, &mut rand::rngs::StdRng::seed_from_u64(seed)).unwrap();
            assert_ne!(
                s.count_rule,
                CountRule::Separation,
                "the dinosaur, seed {seed}"
            );
            s.objects.len()
        };
        assert_eq!(groups(10.0), groups(0.0), "the dinosaur, seed {seed}");
    }
}

/// The default configuration with the orthographic camera.
fn orthographic() -> Config {
    Config {
        camera: CameraModel::Orthographic,
        ..Default::default()
    }
}

/// An orthographic scene (0.5 px of noise) with a second rigidly rotating object holding
/// `share` of the tracks and `gross` of the entries gross, and the second object's tracks.
fn second_object_scene(
    frames: usize,
    points: usize,
    share: f64,
    gross: f64,
    seed: u64,
) -> (rank3::synth::SynthScene, Vec<usize>) {
    let cfg = SynthConfig {
        camera: CameraModel::Orthographic,
        frames,
        points,
        noise: 0.5,
        gross,
        objects: vec![SynthObject {
            share,
            motion: ObjectMotion::Rotating,
        }],
        seed,
        ..Default::default()
    };
    let scene = generate(&cfg).unwrap();
    let second = (0..points).filter(|&p| scene.objects[p] == 1).collect();
    (scene, second)
}

/// How many of `tracks` (by index) a robust report rejected as whole tracks.
fn rejected_among(rb: &rank3::reconstruction::RobustReport, tracks: &[usize]) -> usize {
    let rejected: std::collections::HashSet<String> =
        rb.outlier_tracks.iter().map(|i| i.to_string()).collect();
    tracks
        .iter()
        .filter(|p| rejected.contains(&p.to_string()))
        .count()
}

/// The single-object pipeline (orthographic) on `table`, which must see two rigid groups:
/// its robust report, and how many of the tracks `second` (by index) it rejected whole
/// (at least all but one).
fn second_object_run(
    table: &rank3::TrackTable,
    second: &[usize],
) -> (rank3::reconstruction::RobustReport, usize) {
    let rec = rank3::Reconstruction::from_tracks(table, &orthographic()).unwrap();
    let rb = rec.robust.unwrap();
    assert_eq!(rb.rigid_groups_seen, 2);
    let caught = rejected_among(&rb, second);
    assert!(
        caught + 1 >= second.len(),
        "{caught} of {} rejected",
        second.len()
    );
    (rb, caught)
}

/// The single-object pipeline with a clearly separate second rigid object (25 % of the
/// tracks): the robust report sees two rigid groups and every track of the second object
/// is rejected whole (the robust pass alone already does that here; the Hopkins test below
/// is the hard case).
#[test]
fn single_object_pipeline_rejects_a_second_object_as_tracks() {
    let (scene, second) = second_object_scene(24, 160, 0.25, 0.0, 5);
    let (rb, _) = second_object_run(&scene.table, &second);
    let flagged_on_second = rb
        .flagged_entries
        .iter()
        .filter(|e| second.iter().any(|p| p.to_string() == e.track.to_string()))
        .count();
    assert!(
        flagged_on_second <= 2,
        "{flagged_on_second} entries flagged on the second object"
    );
    // Few main-object tracks lost.
    assert!(
        rb.n_outlier_tracks <= second.len() + 4,
        "{} outliers",
        rb.n_outlier_tracks
    );
}

/// The same with gross entries spread over the table (3 % of the entries, 15–60 px off):
/// nearly every track carries a flag, but glitches land far off, so the robust pass calls
/// none of those flags ambiguous and the other-objects search looks only at the rejected
/// tracks and those with an ambiguous flag (before, every flagged track: nearly all). The
/// second object is still found and rejected whole, and no track of the main body is lost.
#[test]
fn second_object_is_found_among_spread_gross_entries() {
    use rand::SeedableRng;
    let (scene, second) = second_object_scene(30, 200, 0.2, 0.03, 7);
    let r = rank3::robust::robust_filter(
        &scene.table.measurements(),
        &rank3::robust::RobustConfig::default(),
        &mut rand::rngs::StdRng::seed_from_u64(0),
    )
    .unwrap();
    let main_kept: Vec<usize> = (0..200)
        .filter(|&p| scene.objects[p] == 0 && r.inlier_tracks[p])
        .collect();
    let flagged = main_kept
        .iter()
        .filter(|&&p| r.flagged_entries.iter().any(|e| e.1 == p))
        .count();
    let ambiguous = main_kept
        .iter()
        .filter(|&&p| r.ambiguous_flags[p] > 0)
        .count();
    assert!(
        flagged * 2 > main_kept.len(),
        "{flagged} of {} main-body tracks flagged",
        main_kept.len()
    );
    assert!(
        ambiguous * 20 <= main_kept.len(),
        "{ambiguous} of {} main-body tracks with an ambiguous flag",
        main_kept.len()
    );
    let (rb, caught) = second_object_run(&scene.table, &second);
    assert!(
        rb.n_outlier_tracks <= caught + 2,
        "{} main-body tracks rejected",
        rb.n_outlier_tracks - caught
    );
}

/// Three rigid bodies (the scene, 55 % of the tracks; two objects turning on their own,
/// 25 % and 20 %; 20 % of the entries missing, 5 % random-walk tracks) through the
/// single-object pipeline: the robust pass leaves signs of other bodies, the kept tracks
/// are segmented, and both other bodies' tracks are rejected whole, none patched entry by
/// entry (before, on Hopkins `2RT3RC_g12`, 173 entries of the other bodies' kept tracks
/// were flagged as gross errors one by one). The scene is reconstructed from its own
/// tracks.
#[test]
fn other_bodies_are_segmented_and_rejected_whole() {
    let scene = three_bodies(0.2, ObjectMotion::Rotating);
    let rec = rank3::Reconstruction::from_tracks(&scene.table, &orthographic()).unwrap();
    let rb = rec.robust.as_ref().unwrap();
    assert_eq!(rb.rigid_groups_seen, 3);
    let others: Vec<usize> = (0..240)
        .filter(|&p| scene.objects[p] != 0 && scene.outlier_tracks[p].is_none())
        .collect();
    let caught = rejected_among(rb, &others);
    assert!(
        caught + 2 >= others.len(),
        "{caught} of {} other-body tracks rejected",
        others.len()
    );
    let on_others = rb
        .flagged_entries
        .iter()
        .filter(|e| others.iter().any(|p| p.to_string() == e.track.to_string()))
        .count();
    assert!(
        on_others <= 2,
        "{on_others} entries flagged on other bodies"
    );
    let scene_tracks: Vec<usize> = (0..240)
        .filter(|&p| scene.objects[p] == 0 && scene.outlier_tracks[p].is_none())
        .collect();
    let lost = rejected_among(rb, &scene_tracks);
    assert!(
        lost <= 4,
        "{lost} of the scene's {} tracks rejected",
        scene_tracks.len()
    );
    assert!(rec.rms_px < 1.0, "RMS {} px", rec.rms_px);
}

/// Random-walk outlier tracks (20 %) and one rigid body: the other-objects check finds no
/// second object. A group of random walks is explained by its own subspace far better than
/// by the body's, but only at a noise no rigid body of the scene has; its rigid consensus
/// within that bound is empty. (Before the consensus: two rigid groups seen.)
#[test]
fn random_walks_are_not_another_object() {
    let cfg = SynthConfig {
        camera: CameraModel::Orthographic,
        frames: 60,
        points: 400,
        noise: 0.5,
        missing: 0.3,
        outliers: 0.2,
        outlier_kind: OutlierKind::RandomWalk,
        seed: 3,
        ..Default::default()
    };
    let scene = generate(&cfg).unwrap();
    let rec = rank3::Reconstruction::from_tracks(&scene.table, &orthographic()).unwrap();
    let rb = rec.robust.unwrap();
    assert_eq!(rb.rigid_groups_seen, 1);
    assert_eq!(rb.other_object_tracks, 0);
}

/// Hopkins `cars1` (skipped without the data set; a car moving slowly in front of a moving
/// camera): the affine robust pass alone kept 50 of the car's 77 tracks with 155 of their
/// entries flagged as gross errors (F1 of the rejections 0.50); the other-objects check
/// finds the car as a rigid group and rejects its tracks whole. Seeds 0 and 1 (the RANSAC
/// draws; `RANK3_SEEDS=N` runs seeds 0..N). With one pooled noise level the check found the
/// car on one seed of six; with each model's own (`segment::other_objects`) and the tracks
/// outside the group re-judged, on all six (66–77 of the car's 77 tracks rejected, 4–8 of
/// the scene's). Since the search looks at the rejected tracks and those with an ambiguous
/// flag only (2026-11-29): the car is found on all six seeds, and seed 5 rejects 65 of its
/// tracks, one short of this test's 85 % (seeds 0–4 pass).
#[test]
fn hopkins_second_object_is_rejected_as_tracks() {
    let Some(h) = hopkins("cars1") else {
        return;
    };
    let table = rank3::TrackTable::from_measurements(&h.measurements);
    let config = Config {
        camera: CameraModel::Orthographic,
        ..Default::default()
    };
    let seeds: Vec<u64> = std::env::var("RANK3_SEEDS")
        .ok()
        .and_then(|v| v.parse().ok())
        .map_or(vec![0, 1], |n: u64| (0..n).collect());
    for seed in seeds {
        second_object_rejected(
            &h,
            &table,
            &Config {
                seed,
                ..config.clone()
            },
        );
    }
}

/// A nearly planar background (150 points, relief ±1 % of its width) seen in perspective
/// (focal 800 px, 4 widths away, the camera turning by up to 12° and moving sideways) and a
/// second object (50 points in a box) turning and moving on its own over it; Gaussian
/// noise of 0.5 px. Returns the table and the second object's tracks.
fn planar_scene_with_an_object(frames: usize, seed: u64) -> (rank3::TrackTable, Vec<usize>) {
    use nalgebra::{Rotation3, Vector3};
    use rand::{RngExt, SeedableRng};
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let normal = rand_distr::Normal::new(0.0, 0.5).unwrap();
    let (n_bg, n_obj) = (150, 50);
    let mut pts: Vec<Vector3<f64>> = (0..n_bg)
        .map(|_| {
            Vector3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-0.02..0.02),
            )
        })
        .collect();
    pts.extend((0..n_obj).map(|_| {
        Vector3::new(
            rng.random_range(-0.25..0.25),
            rng.random_range(-0.25..0.25),
            rng.random_range(-0.25..0.25),
        )
    }));
    let mut w = faer::Mat::zeros(2 * frames, n_bg + n_obj);
    for f in 0..frames {
        let a = f as f64 / (frames - 1) as f64;
        // The camera: 8 units from the plane, turning and moving sideways.
        let cam_r = Rotation3::from_euler_angles(0.2 * a, -0.1 + 0.2 * a, 0.05 * a);
        let cam_t = Vector3::new(-0.6 * a, 0.3 * a, 8.0);
        // The object: above the plane, turning about a tilted axis and drifting.
        let obj_r = Rotation3::from_euler_angles(0.5 * a, 0.3 * a, -0.4 * a);
        let obj_t = Vector3::new(0.3 + 0.4 * a, -0.2 + 0.2 * a, 0.4);
        for (p, x) in pts.iter().enumerate() {
            let xw = if p < n_bg { *x } else { obj_r * x + obj_t };
            let xc = cam_r * xw + cam_t;
            for k in 0..2 {
                w[(2 * f + k, p)] = 800.0 * xc[k] / xc[2] + rng.sample(normal);
            }
        }
    }
    let meas = rank3::Measurements::new(w, vec![true; frames * (n_bg + n_obj)]);
    (
        rank3::TrackTable::from_measurements(&meas),
        (n_bg..n_bg + n_obj).collect(),
    )
}

/// A second object over a nearly planar background, with the CLI's default camera (`auto`):
/// the projective model fitted to the background leaves 3 of each camera's 11 degrees of
/// freedom to nothing, and its verdict must not readmit the object the affine pass found.
/// Before the object was held out by its own rigid motion (2026-11-29) the verdict
/// readmitted 22 of its tracks refit by refit, kept 21 of 50 out, flagged 24 of their
/// entries, and saw one rigid group (seed 2: 24, 22, 47, one group; Hopkins `1R2RC_g12`: 88
/// of 89 tracks readmitted). Measured since: 43 rejected (seed 2: 46), none readmitted, no
/// background track lost. One seed: the automatic camera's fits take 18 s in debug.
#[test]
fn second_object_over_a_plane_stays_rejected_with_the_automatic_camera() {
    let (table, second) = planar_scene_with_an_object(20, 1);
    let rec = rank3::Reconstruction::from_tracks(
        &table,
        &Config {
            camera: CameraModel::Auto,
            ..Default::default()
        },
    )
    .unwrap();
    let rb = rec.robust.unwrap();
    assert_eq!(rb.rigid_groups_seen, 2);
    let j = rb.projective.as_ref().expect("the projective verdict ran");
    assert_eq!(j.objects_held_out, 1);
    let caught = rejected_among(&rb, &second);
    assert!(caught >= 40, "{caught} of 50 rejected");
    assert!(
        rb.n_outlier_tracks - caught <= 3,
        "{} background tracks rejected",
        rb.n_outlier_tracks - caught
    );
}

/// A second object that passes the affine track test whole, within the pipeline's 2 px
/// floor (Hopkins `1R2RC_g23`: 113 of its 121 tracks kept at a median 0.65 px where the
/// test without the floor is 0.11 px), is found by the second search over the kept tracks
/// (orthographic camera, seeds 0 and 1). Before it (2026-11-29): 8 of the 121 rejected, one
/// rigid group seen.
#[test]
fn hopkins_object_within_the_track_floor_is_rejected_as_tracks() {
    let Some(h) = hopkins("1R2RC_g23") else {
        return;
    };
    let table = rank3::TrackTable::from_measurements(&h.measurements);
    for seed in [0, 1] {
        second_object_rejected(
            &h,
            &table,
            &Config {
                seed,
                ..orthographic()
            },
        );
    }
}

/// The checks of [`hopkins_second_object_is_rejected_as_tracks`] for one configuration.
fn second_object_rejected(
    h: &rank3::datasets::Hopkins,
    table: &rank3::TrackTable,
    config: &Config,
) {
    let rec = rank3::Reconstruction::from_tracks(table, config).unwrap();
    let rb = rec.robust.as_ref().unwrap();
    eprintln!(
        "seed {}: {} groups, {} outlier tracks, {} flagged entries",
        config.seed, rb.rigid_groups_seen, rb.n_outlier_tracks, rb.n_flagged_entries
    );
    assert_eq!(rb.rigid_groups_seen, 2);
    let mut sizes = vec![0usize; h.n_groups];
    h.groups.iter().for_each(|&g| sizes[g] += 1);
    let main = (0..h.n_groups).max_by_key(|&g| sizes[g]).unwrap();
    let other: Vec<usize> = (0..h.groups.len())
        .filter(|&p| h.groups[p] != main)
        .collect();
    let caught = rejected_among(rb, &other);
    assert!(
        caught * 100 >= 85 * other.len(),
        "{caught} of {} rejected",
        other.len()
    );
    let lost = rb.n_outlier_tracks - caught;
    assert!(lost <= 10, "{lost} tracks of the main group rejected");
    let flagged_other = rb
        .flagged_entries
        .iter()
        .filter(|e| {
            e.track
                .to_string()
                .parse::<usize>()
                .is_ok_and(|p| h.groups[p] != main)
        })
        .count();
    assert!(
        flagged_other <= 40,
        "{flagged_other} entries flagged on the car's kept tracks"
    );
}

/// Strong perspective (distance 4 object radii, focal 800 px): the affine subspaces cut one
/// rigid body into pieces, and the perspective-aware merge test (`merge_ratio`) joins them,
/// while two independently moving bodies in the same setting stay apart. The Model House
/// (10 frames, real, strong perspective) likewise becomes one group.
#[test]
fn pieces_of_a_body_seen_in_perspective_are_merged() {
    use rand::SeedableRng;
    use rank3::segment::{CountRule, segment};
    let scene = |objects: Vec<SynthObject>| {
        generate(&SynthConfig {
            camera: CameraModel::Perspective,
            distance: 4.0,
            focal: Some(800.0),
            frames: 20,
            points: 200,
            noise: 0.5,
            outliers: 0.05,
            outlier_kind: OutlierKind::RandomWalk,
            objects,
            seed: 1,
            ..Default::default()
        })
        .unwrap()
    };
    let run = |meas: &rank3::Measurements, merge_ratio: f64| {
        let cfg = SegmentConfig {
            merge_ratio,
            ..Default::default()
        };
        segment(meas, &cfg, &mut rand::rngs::StdRng::seed_from_u64(1)).unwrap()
    };
    // One body: pieces without the test, one group with it; every walk an outlier and
    // every track of the body in the group.
    let one = scene(Vec::new());
    let meas = one.table.measurements();
    let off = run(&meas, 0.0);
    assert!(
        off.objects.len() >= 2,
        "without the test: {} groups",
        off.objects.len()
    );
    let on = run(&meas, SegmentConfig::default().merge_ratio);
    assert_eq!(on.objects.len(), 1, "tests {:?}", on.merge_tests);
    assert_eq!(on.count_rule, CountRule::PerspectiveMerge);
    assert_eq!(on.objects[0].pieces, off.objects.len());
    let merged = on.merge_tests.iter().find(|t| t.merged).unwrap();
    let r = merged.ratios.unwrap();
    assert!(r[0] < 1.0 && r[1] < 1.0, "ratios {r:?}");
    for (p, w) in one.outlier_tracks.iter().enumerate() {
        let expected = if w.is_some() {
            Label::Outlier
        } else {
            Label::Object(0)
        };
        assert_eq!(on.labels[p], expected, "track {p}");
    }
    // Two bodies: two groups, as the truth has them (a few tracks labelled outlier: 3 of
    // 190 measured).
    let two = scene(vec![SynthObject {
        share: 0.25,
        motion: ObjectMotion::Rotating,
    }]);
    let s = run(
        &two.table.measurements(),
        SegmentConfig::default().merge_ratio,
    );
    assert_eq!(s.objects.len(), 2, "tests {:?}", s.merge_tests);
    let err = object_error(&two, &s.labels);
    assert!(err <= 0.03, "misclassification {err}");

    let Some(meas) = dataset("model_house/matrix/M_dense.txt") else {
        return;
    };
    let s = run(&meas, SegmentConfig::default().merge_ratio);
    assert_eq!(
        s.objects.len(),
        1,
        "the Model House: tests {:?}",
        s.merge_tests
    );
}

/// One rigid body whose table has tracks seen in two frames only (as a three-frame sequence
/// has by the hundred: Merton 3 has 438 of 575). The segmentation cannot score them and
/// finds one group; the one object's reconstruction takes them, as the single-object
/// pipeline does, instead of leaving them out (`objects.csv` gives them that object).
#[test]
fn unscored_tracks_join_the_only_object() {
    let mut scene = generate(&SynthConfig {
        camera: CameraModel::Orthographic,
        frames: 12,
        points: 80,
        noise: 0.5,
        seed: 5,
        ..Default::default()
    })
    .unwrap();
    let short: Vec<usize> = (60..80).collect();
    for &p in &short {
        for f in 2..12 {
            scene.table.unset(f, p);
        }
    }
    let config = Config {
        camera: CameraModel::Orthographic,
        ..Default::default()
    };
    let mb = rank3::objects::reconstruct_objects(&scene.table, &config, &SegmentConfig::default())
        .unwrap();
    assert_eq!(mb.objects.len(), 1);
    for &p in &short {
        assert_eq!(mb.segmentation.labels[p], Label::Unscored, "track {p}");
    }
    assert_eq!(mb.unscored_in_the_only_object(), short);
    assert_eq!(mb.report(false).n_unscored_in_the_only_object, short.len());
    let o = &mb.objects[0];
    assert!(short.iter().all(|p| o.tracks.contains(p)));
    let rec = o.reconstruction.as_ref().expect("reconstructed");
    let fitted: Vec<usize> = rec.kept_tracks.iter().map(|&i| o.tracks[i]).collect();
    let inliers = short.iter().filter(|p| fitted.contains(p)).count();
    assert!(inliers >= 18, "{inliers} of the 20 two-frame tracks fitted");
    let csv = mb.objects_csv();
    let zeros = csv.lines().skip(1).filter(|l| l.ends_with(",0")).count();
    assert_eq!(zeros, o.tracks.len());
}

/// Eight tracks over six frames: every local sample (4 tracks) fits its subspace exactly,
/// which left no hypothesis, and `--objects` stopped with an error where the single-object
/// pipeline fits the table. Now the first sample's subspace is refitted to all the tracks,
/// a given count of 1 is one object, and with the count found — where no group pays for
/// its parameters on so few tracks — the one group is taken rather than none.
#[test]
fn a_table_of_a_few_tracks_is_one_object() {
    let scene = generate(&SynthConfig {
        camera: CameraModel::Orthographic,
        frames: 6,
        points: 8,
        noise: 0.5,
        seed: 2,
        ..Default::default()
    })
    .unwrap();
    let config = Config {
        camera: CameraModel::Orthographic,
        ..Default::default()
    };
    for (objects, rule) in [
        (rank3::segment::Objects::Count(1), "given"),
        (rank3::segment::Objects::Auto, "one_group_fallback"),
    ] {
        let seg = SegmentConfig {
            objects,
            ..SegmentConfig::default()
        };
        let mb = rank3::objects::reconstruct_objects(&scene.table, &config, &seg).unwrap();
        assert_eq!(mb.objects.len(), 1, "{objects:?}");
        let report = serde_json::to_value(mb.report(false)).unwrap();
        assert_eq!(report["count_rule"], rule);
        let rec = mb.objects[0]
            .reconstruction
            .as_ref()
            .expect("reconstructed");
        assert!(
            rec.kept_tracks.len() >= 7,
            "{} tracks fitted",
            rec.kept_tracks.len()
        );
        assert!(rec.rms_px < 1.0, "RMS {}", rec.rms_px);
    }
}
