//! Ground-truth tests of the complete-data pipeline on synthetic scenes.

use nalgebra::Vector3;
use rank3::eval::{median, rotation_errors_deg, structure_error};
use rank3::metric::UpgradeMethod;
use rank3::synth::{Motion, Shape, SynthConfig, generate};
use rank3::{CameraModel, Config, Error, Event, Observer, Reconstruction, TrackTable};

/// The core pipeline without the robust pass (tested on its own below and in
/// tests/robust.rs), so these tests measure factorization, upgrade and refinement alone.
fn config(camera: CameraModel) -> Config {
    Config {
        camera,
        robust: None,
        ..Config::default()
    }
}

fn points(rec: &Reconstruction) -> Vec<Vector3<f64>> {
    rec.points
        .iter()
        .map(|p| Vector3::new(p.xyz[0], p.xyz[1], p.xyz[2]))
        .collect()
}

fn rotations(rec: &Reconstruction) -> Vec<nalgebra::Rotation3<f64>> {
    rec.frames
        .iter()
        .map(|f| {
            nalgebra::Rotation3::from_matrix_unchecked(nalgebra::Matrix3::from_fn(|r, c| {
                f.rotation[r][c]
            }))
        })
        .collect()
}

#[test]
fn noise_free_scenes_are_recovered_exactly() {
    for camera in [CameraModel::Orthographic, CameraModel::ScaledOrthographic] {
        for shape in [Shape::House, Shape::Cloud, Shape::Cube] {
            for motion in [Motion::Turntable, Motion::HandheldArc] {
                let scene = generate(&SynthConfig {
                    shape,
                    motion,
                    camera,
                    noise: 0.0,
                    frames: 20,
                    points: 80,
                    seed: 11,
                    ..Default::default()
                })
                .unwrap();
                let rec = Reconstruction::from_tracks(&scene.table, &config(camera)).unwrap();
                let what = format!("{camera} {shape:?} {motion:?}");
                assert!(rec.rms_px < 1e-9, "{what}: rms {}", rec.rms_px);
                let e = structure_error(&points(&rec), &scene.truth.points);
                assert!(e < 1e-9, "{what}: structure error {e}");
                let rot = rotation_errors_deg(&rotations(&rec), &scene.truth.rotations);
                let worst = rot.iter().cloned().fold(0.0, f64::max);
                assert!(worst < 1e-7, "{what}: rotation error {worst}°");
                if camera == CameraModel::ScaledOrthographic {
                    for (f, fr) in rec.frames.iter().enumerate() {
                        let want = scene.truth.scales[f] / scene.truth.scales[0];
                        assert!((fr.scale - want).abs() < 1e-9, "{what}: scale {f}");
                    }
                } else {
                    assert!(rec.frames.iter().all(|f| f.scale == 1.0));
                }
                // Gauge: frame 0 is the identity camera.
                let r0 = &rec.frames[0].rotation;
                for (a, row) in r0.iter().enumerate() {
                    for (b, v) in row.iter().enumerate() {
                        let want = if a == b { 1.0 } else { 0.0 };
                        assert!((v - want).abs() < 1e-12);
                    }
                }
            }
        }
    }
}

/// Bounds at σ = 0.5 px on a 30-frame × 200-track house (image extent 400 px), over 10
/// seeds: the median per-frame rotation error stays below 0.2° and the relative structure
/// error (RMS 3D distance after similarity alignment / RMS spread) below 0.5 %.
#[test]
fn noisy_scenes_stay_within_bounds() {
    for camera in [CameraModel::Orthographic, CameraModel::ScaledOrthographic] {
        let mut rot_medians = Vec::new();
        let mut structure = Vec::new();
        for seed in 0..10 {
            let scene = generate(&SynthConfig {
                camera,
                noise: 0.5,
                seed,
                ..Default::default()
            })
            .unwrap();
            let rec = Reconstruction::from_tracks(&scene.table, &config(camera)).unwrap();
            // The residual is at the noise level: σ·sqrt(1 − dof/observations).
            assert!(
                rec.rms_px > 0.4 && rec.rms_px < 0.55,
                "{camera} seed {seed}: rms {}",
                rec.rms_px
            );
            let rot = rotation_errors_deg(&rotations(&rec), &scene.truth.rotations);
            rot_medians.push(median(&rot[1..]));
            structure.push(structure_error(&points(&rec), &scene.truth.points));
        }
        let worst_rot = rot_medians.iter().cloned().fold(0.0, f64::max);
        let worst_s = structure.iter().cloned().fold(0.0, f64::max);
        eprintln!(
            "{camera}: worst median rotation error {worst_rot:.4}°, worst structure error {worst_s:.5}"
        );
        assert!(worst_rot < 0.2, "{camera}: {rot_medians:?}");
        assert!(worst_s < 0.005, "{camera}: {structure:?}");
    }
}

#[test]
fn invariant_to_permutations_and_image_translation() {
    let scene = generate(&SynthConfig {
        noise: 0.5,
        frames: 15,
        points: 60,
        seed: 4,
        ..Default::default()
    })
    .unwrap();
    let cfg = config(CameraModel::Orthographic);
    let base = Reconstruction::from_tracks(&scene.table, &cfg).unwrap();
    let base_pts = points(&base);

    // Tracks reversed: same points for the same track ids.
    let n = scene.table.n_tracks();
    let f = scene.table.n_frames();
    let rev: Vec<usize> = (0..n).rev().collect();
    let all_frames: Vec<usize> = (0..f).collect();
    let permuted = scene.table.permuted(&all_frames, &rev);
    let rec = Reconstruction::from_tracks(&permuted, &cfg).unwrap();
    assert!((rec.rms_px - base.rms_px).abs() < 1e-9);
    for (k, p) in rec.points.iter().enumerate() {
        let orig = &base.points[n - 1 - k];
        assert_eq!(p.track, orig.track);
        for c in 0..3 {
            assert!((p.xyz[c] - orig.xyz[c]).abs() < 1e-6, "track {k}");
        }
    }

    // Frames shuffled: a different reference frame, so compare up to a similarity.
    let mut frames: Vec<usize> = (0..f).collect();
    frames.swap(0, 7);
    frames.swap(3, 11);
    let tracks: Vec<usize> = (0..n).collect();
    let rec = Reconstruction::from_tracks(&scene.table.permuted(&frames, &tracks), &cfg).unwrap();
    assert!((rec.rms_px - base.rms_px).abs() < 1e-6 * base.rms_px);
    assert!(structure_error(&points(&rec), &base_pts) < 1e-6);

    // Image translated by (123.4, −56.7): same structure, shifted translations.
    let mut moved = scene.table.clone();
    for fi in 0..f {
        for p in 0..n {
            if let Some([x, y]) = moved.get(fi, p) {
                moved.set(fi, p, x + 123.4, y - 56.7);
            }
        }
    }
    let rec = Reconstruction::from_tracks(&moved, &cfg).unwrap();
    assert!((rec.rms_px - base.rms_px).abs() < 1e-9);
    for (a, b) in rec.points.iter().zip(&base.points) {
        for c in 0..3 {
            assert!((a.xyz[c] - b.xyz[c]).abs() < 1e-6);
        }
    }
    for (a, b) in rec.frames.iter().zip(&base.frames) {
        assert!((a.translation[0] - b.translation[0] - 123.4).abs() < 1e-6);
        assert!((a.translation[1] - b.translation[1] + 56.7).abs() < 1e-6);
    }
}

/// Few frames with little rotation (a 10° sweep) and strong noise (2 px) make the
/// least-squares L indefinite in about a third of the seeds; the SDP path must take over
/// and still give proper rotations.
#[test]
fn indefinite_least_squares_takes_the_sdp_path() {
    let mut found = 0;
    for seed in 0..40 {
        let scene = generate(&SynthConfig {
            frames: 6,
            points: 20,
            noise: 2.0,
            sweep_deg: Some(10.0),
            shape: Shape::Cloud,
            motion: Motion::HandheldArc,
            seed,
            ..Default::default()
        })
        .unwrap();
        let rec =
            match Reconstruction::from_tracks(&scene.table, &config(CameraModel::Orthographic)) {
                Ok(r) => r,
                Err(e) => panic!("seed {seed}: {e}"),
            };
        if rec.metric_upgrade.min_eigenvalue_ls > 0.0 {
            continue;
        }
        found += 1;
        assert_eq!(rec.metric_upgrade.method, UpgradeMethod::Sdp, "seed {seed}");
        assert!(rec.metric_upgrade.eigenvalues[0] >= -1e-9 * rec.metric_upgrade.eigenvalues[2]);
        for fr in &rec.frames {
            let r = nalgebra::Matrix3::from_fn(|a, b| fr.rotation[a][b]);
            assert!((r * r.transpose() - nalgebra::Matrix3::identity()).norm() < 1e-9);
            assert!((r.determinant() - 1.0).abs() < 1e-9);
        }
        assert!(rec.rms_px.is_finite());
    }
    assert!(found >= 3, "only {found} indefinite cases in 40 seeds");
}

/// Tracks that enter and leave the frame (40 % missing, contiguous windows) go through the
/// missing-data solver; noise-free data are still recovered exactly.
#[test]
fn missing_entries_are_completed_and_recovered() {
    for camera in [CameraModel::Orthographic, CameraModel::ScaledOrthographic] {
        let scene = generate(&SynthConfig {
            camera,
            missing: 0.4,
            noise: 0.0,
            frames: 20,
            points: 120,
            seed: 2,
            ..Default::default()
        })
        .unwrap();
        assert!(!scene.table.is_complete());
        let cfg = Config {
            camera,
            ..Config::default()
        };
        let rec = Reconstruction::from_tracks(&scene.table, &cfg).unwrap();
        let c = rec.completion.as_ref().expect("completion ran");
        assert!(c.rms_px < 1e-6, "{camera}: affine rms {}", c.rms_px);
        assert!(rec.rms_px < 1e-6, "{camera}: rms {}", rec.rms_px);
        assert_eq!(rec.robust.as_ref().unwrap().n_outlier_tracks, 0);
        let e = structure_error(&points(&rec), &scene.truth.points);
        assert!(e < 1e-6, "{camera}: structure error {e}");
        // completed.txt fills the hidden entries with the true projections.
        let full = rec.completed_matrix();
        let mut worst = 0.0f64;
        for f in 0..20 {
            for p in 0..120 {
                let q = scene.truth.project(f, p);
                worst = worst
                    .max((full[(2 * f, p)] - q[0]).abs())
                    .max((full[(2 * f + 1, p)] - q[1]).abs());
            }
        }
        assert!(worst < 1e-5, "{camera}: worst filled-in error {worst} px");
    }
}

/// The default pipeline rejects outlier tracks and gross entries, and the structure of the
/// inliers stays close to the clean-data fit.
#[test]
fn robust_pass_rejects_outliers_in_the_pipeline() {
    let base = SynthConfig {
        frames: 24,
        points: 150,
        noise: 0.5,
        seed: 5,
        ..Default::default()
    };
    let clean = generate(&base).unwrap();
    let dirty = generate(&SynthConfig {
        outliers: 0.2,
        gross: 0.02,
        ..base.clone()
    })
    .unwrap();
    let rec_clean = Reconstruction::from_tracks(&clean.table, &Config::default()).unwrap();
    let rec = Reconstruction::from_tracks(&dirty.table, &Config::default()).unwrap();
    let robust = rec.robust.as_ref().unwrap();
    let truth_out: Vec<bool> = dirty.outlier_tracks.iter().map(|o| o.is_some()).collect();
    let flagged_out: Vec<bool> = rec.points.iter().map(|p| !p.inlier).collect();
    let tp = truth_out
        .iter()
        .zip(&flagged_out)
        .filter(|(t, f)| **t && **f)
        .count() as f64;
    let precision = tp / flagged_out.iter().filter(|&&f| f).count().max(1) as f64;
    let recall = tp / truth_out.iter().filter(|&&t| t).count() as f64;
    assert!(
        precision >= 0.9 && recall >= 0.9,
        "P {precision} R {recall}"
    );
    assert!(robust.n_flagged_entries > 0);
    // Structure of the true inlier tracks the fit kept, against the truth, relative to the
    // clean fit's error on the same tracks.
    let kept: Vec<usize> = (0..150)
        .filter(|&p| !truth_out[p] && rec.points[p].inlier)
        .collect();
    let sel = |r: &Reconstruction| -> Vec<Vector3<f64>> {
        kept.iter()
            .map(|&p| Vector3::from(r.points[p].xyz))
            .collect()
    };
    let truth: Vec<Vector3<f64>> = kept.iter().map(|&p| dirty.truth.points[p]).collect();
    let e_dirty = structure_error(&sel(&rec), &truth);
    let e_clean = structure_error(&sel(&rec_clean), &truth);
    assert!(e_dirty <= 1.5 * e_clean, "{e_dirty} vs clean {e_clean}");
    // Outlier tracks are reported with inlier = false and appear in the JSON.
    let json: serde_json::Value = serde_json::from_str(&rec.to_json()).unwrap();
    assert_eq!(
        json["robust"]["n_outlier_tracks"].as_u64().unwrap() as usize,
        flagged_out.iter().filter(|&&f| f).count()
    );
}

/// The pipeline announces the frames and tracks of its fit once, before it factorizes, and
/// they are those the result reports as kept (outlier tracks excluded).
#[test]
fn fit_selection_event_names_the_kept_frames_and_tracks() {
    #[derive(Default)]
    struct Probe {
        selections: Vec<(Vec<usize>, Vec<usize>)>,
        factorize_started_after: Option<usize>,
    }
    impl Observer for Probe {
        fn on_event(&mut self, event: &Event<'_>) {
            match event {
                Event::FitSelection { frames, tracks } => {
                    self.selections.push((frames.to_vec(), tracks.to_vec()))
                }
                Event::StageStarted { stage: "factorize" } => {
                    self.factorize_started_after = Some(self.selections.len())
                }
                _ => {}
            }
        }
    }
    let scene = generate(&SynthConfig {
        frames: 12,
        points: 60,
        noise: 0.5,
        outliers: 0.2,
        seed: 5,
        ..Default::default()
    })
    .unwrap();
    let mut probe = Probe::default();
    let rec =
        Reconstruction::from_tracks_observed(&scene.table, &Config::default(), &mut probe).unwrap();
    assert!(rec.kept_tracks.len() < 60, "no outlier track was excluded");
    assert_eq!(
        probe.selections,
        vec![(rec.kept_frames.clone(), rec.kept_tracks.clone())]
    );
    assert_eq!(probe.factorize_started_after, Some(1));
}

/// Most tracks are random walks: no rigid majority, and the pipeline says so instead of
/// returning a confident wrong model.
#[test]
fn no_rigid_majority_is_an_error_not_a_model() {
    let scene = generate(&SynthConfig {
        frames: 20,
        points: 100,
        outliers: 0.7,
        outlier_kind: rank3::synth::OutlierKind::RandomWalk,
        seed: 1,
        ..Default::default()
    })
    .unwrap();
    match Reconstruction::from_tracks(&scene.table, &Config::default()) {
        Err(Error::NoRigidMajority {
            inlier_fraction, ..
        }) => assert!(inlier_fraction < 0.6),
        other => panic!(
            "expected NoRigidMajority, got {:?}",
            other.map(|r| r.rms_px)
        ),
    }
}

#[test]
fn under_observed_tracks_and_frames_are_reported() {
    let scene = generate(&SynthConfig {
        frames: 10,
        points: 30,
        seed: 9,
        ..Default::default()
    })
    .unwrap();
    let mut t = scene.table.clone();
    // Track 5 seen only in frame 0, frame 9 sees only tracks 0 and 1.
    for f in 1..10 {
        t.unset(f, 5);
    }
    for p in 2..30 {
        t.unset(9, p);
    }
    // Make the rest complete again by dropping frame 9's points 0,1 from nothing: the
    // table now has missing entries only in the set-aside track and frame.
    let rec = Reconstruction::from_tracks(&t, &config(CameraModel::Orthographic)).unwrap();
    let ids: Vec<String> = rec
        .set_aside
        .iter()
        .map(|s| format!("{:?} {}", s.kind, s.id))
        .collect();
    assert_eq!(ids, vec!["Track 5", "Frame 9"]);
    assert_eq!(rec.points.len(), 29);
    assert_eq!(rec.frames.len(), 9);
    assert!(rec.points.iter().all(|p| p.track != rank3::Id::Int(5)));
    // completed.txt keeps the input's shape, nan for set-aside rows/columns.
    let c = rec.completed_matrix();
    assert_eq!((c.nrows(), c.ncols()), (20, 30));
    assert!(c[(0, 5)].is_nan() && c[(18, 0)].is_nan() && c[(0, 0)].is_finite());
}

#[test]
fn too_small_tables_are_errors() {
    let mut t = TrackTable::new(
        vec![0usize.into(), 1usize.into()],
        vec![0usize.into(), 1usize.into(), 2usize.into()],
    );
    for f in 0..2 {
        for p in 0..3 {
            t.set(f, p, p as f64, f as f64);
        }
    }
    assert!(matches!(
        Reconstruction::from_tracks(&t, &Config::default()),
        Err(Error::TooFew { .. })
    ));
}

/// A table too small for the robust pass (7 tracks, or tracks that share too few frames
/// for any 4-track sample) is still reconstructed, with the default settings: the robust
/// pass is skipped with a warning that says why, and the fit is exact on noise-free data.
/// Two frames are a typed error for every affine model (two orthographic views leave a
/// one-parameter family of structures), never a numerical failure.
#[test]
fn a_table_too_small_for_the_robust_pass_is_fitted_without_it() {
    for camera in [CameraModel::Orthographic, CameraModel::ScaledOrthographic] {
        let scene = generate(&SynthConfig {
            camera,
            noise: 0.0,
            frames: 12,
            points: 7,
            seed: 3,
            ..Default::default()
        })
        .unwrap();
        let cfg = Config {
            camera,
            ..Config::default()
        };
        let rec = Reconstruction::from_tracks(&scene.table, &cfg).unwrap();
        assert!(rec.rms_px < 1e-9, "{camera}: rms {}", rec.rms_px);
        assert!(rec.robust.is_none(), "{camera}: a robust report");
        let w = rec
            .warnings
            .iter()
            .find(|w| w.starts_with("robust pass skipped"))
            .unwrap_or_else(|| panic!("{camera}: no warning in {:?}", rec.warnings));
        assert!(w.contains("need at least 8, have 7"), "{w}");
        assert_eq!(rec.points.len(), 7);
        assert!(rec.points.iter().all(|p| p.inlier));
        let e = structure_error(&points(&rec), &scene.truth.points);
        assert!(e < 1e-9, "{camera}: structure error {e}");

        let scene = generate(&SynthConfig {
            camera,
            noise: 0.0,
            frames: 12,
            points: 20,
            seed: 3,
            ..Default::default()
        })
        .unwrap();
        let two = scene.table.select(&[0, 5], &(0..20).collect::<Vec<_>>());
        match Reconstruction::from_tracks(&two, &cfg) {
            Err(Error::TooFew {
                what,
                needed: 3,
                have: 2,
            }) if what.contains("metric upgrade") => {}
            other => panic!("{camera}, two frames: {:?}", other.map(|r| r.rms_px)),
        }
    }
}

/// A clean Gaussian-cloud scene (small image spread relative to the noise) is rigid: the
/// default pipeline, robust pass included, must reconstruct it and keep every track.
#[test]
fn clean_cloud_scene_passes_the_default_pipeline() {
    let scene = generate(&SynthConfig {
        shape: Shape::Cloud,
        frames: 30,
        points: 200,
        noise: 0.5,
        seed: 1,
        ..Default::default()
    })
    .unwrap();
    let rec = Reconstruction::from_tracks(&scene.table, &Config::default()).unwrap();
    assert_eq!(rec.robust.as_ref().unwrap().n_outlier_tracks, 0);
    assert!(rec.rms_px < 0.55, "rms {}", rec.rms_px);
}
