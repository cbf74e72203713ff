//! `reconstruction.json` read back ([`rank3::reconstruction_file`]) and `rank3 eval`
//! ([`rank3::compare`]): round trips, scores against synthetic ground truth, typed errors.

use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use rank3::compare::{self, EvalError};
use rank3::reconstruction_file::{self, ReadError, ReconstructionFile, SCHEMA};
use rank3::synth::{SynthConfig, SynthScene, generate};
use rank3::{CameraModel, Config, Id, Reconstruction};

mod common;
use common::{bin, run_err, run_ok};

fn tmp(name: &str) -> PathBuf {
    common::tmp_dir("eval", name)
}

fn scene(camera: CameraModel, noise: f64, missing: f64, seed: u64) -> SynthScene {
    generate(&SynthConfig {
        camera,
        frames: 12,
        points: 50,
        noise,
        missing,
        seed,
        ..SynthConfig::default()
    })
    .unwrap()
}

fn reconstruct(s: &SynthScene, camera: CameraModel) -> Reconstruction {
    Reconstruction::from_tracks(
        &s.table,
        &Config {
            camera,
            ..Config::default()
        },
    )
    .unwrap()
}

/// Writes `rec` with the library's writer, reads it back, and checks that nothing was
/// lost: the typed reader serializes to exactly the JSON document written, and its frames
/// and points are the reconstruction's.
fn round_trip(rec: &Reconstruction, name: &str) -> ReconstructionFile {
    let d = tmp(name);
    let written = rank3::output::write_all(rec, &d).unwrap();
    let text = std::fs::read_to_string(&written.json).unwrap();
    let file = reconstruction_file::read(&written.json).unwrap();
    assert_eq!(file.schema, SCHEMA);
    let as_written: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(as_written["schema"], SCHEMA);
    assert_eq!(
        serde_json::to_value(&file).unwrap(),
        as_written,
        "the reader lost or changed a key"
    );
    // Written again and read again: the same document.
    let again = reconstruction_file::from_json_str(&file.to_json(), &written.json).unwrap();
    assert_eq!(
        serde_json::to_value(&again).unwrap(),
        serde_json::to_value(&file).unwrap()
    );
    // The typed values are the reconstruction's (to the last bit, or within a rounding of
    // the decimal text).
    let close = |a: f64, b: f64| a == b || (a - b).abs() <= 1e-14 * a.abs().max(b.abs());
    assert_eq!(file.camera_model, rec.camera_model);
    assert_eq!(file.frames.len(), rec.frames.len());
    for (r, f) in file.frames.iter().zip(&rec.frames) {
        assert_eq!(r.frame, f.frame);
        assert_eq!(r.n_observations, f.n_observations);
        for i in 0..3 {
            for j in 0..3 {
                assert!(close(r.rotation[i][j], f.rotation[i][j]));
            }
        }
        assert!(close(r.scale, f.scale) && close(r.rms_px, f.rms_px));
        assert!(close(r.translation[0], f.translation[0]));
    }
    assert_eq!(file.points.len(), rec.points.len());
    for (r, p) in file.points.iter().zip(&rec.points) {
        assert_eq!((&r.track, r.inlier), (&p.track, p.inlier));
        assert!((0..3).all(|k| close(r.xyz[k], p.xyz[k])));
    }
    assert!(close(file.rms_px, rec.rms_px));
    assert_eq!(file.set_aside, rec.set_aside);
    assert_eq!(file.perspective.is_some(), rec.perspective.is_some());
    if let (Some(a), Some(b)) = (&file.perspective, &rec.perspective) {
        assert!(close(a.intrinsics.focal_px, b.intrinsics.focal_px));
        assert_eq!(a.cameras.len(), b.cameras.len());
        for (x, y) in a.cameras.iter().zip(&b.cameras) {
            assert_eq!(x.frame, y.frame);
            assert!((0..3).all(|k| close(x.centre[k], y.centre[k])));
        }
        assert_eq!(a.points.len(), b.points.len());
    }
    file
}

#[test]
fn affine_reconstruction_round_trips() {
    // Missing entries, an outlier track and gross errors: the completion and robust blocks
    // are there too.
    let s = generate(&SynthConfig {
        camera: CameraModel::ScaledOrthographic,
        frames: 12,
        points: 50,
        missing: 0.2,
        outliers: 0.05,
        gross: 0.01,
        seed: 4,
        ..SynthConfig::default()
    })
    .unwrap();
    let rec = reconstruct(&s, CameraModel::ScaledOrthographic);
    let file = round_trip(&rec, "rt-affine");
    assert!(file.completion.is_some() && file.robust.is_some());
    assert!(file.perspective.is_none());
    assert!(matches!(file.frames[0].frame, Id::Int(0)));
}

#[test]
fn perspective_reconstruction_round_trips() {
    let s = generate(&SynthConfig {
        camera: CameraModel::Perspective,
        frames: 12,
        points: 50,
        distance: 2.5,
        seed: 5,
        ..SynthConfig::default()
    })
    .unwrap();
    let rec = reconstruct(&s, CameraModel::Perspective);
    let file = round_trip(&rec, "rt-perspective");
    let per = file.perspective.as_ref().unwrap();
    assert!(file.projective.is_some() && !per.cameras.is_empty());
    assert!(per.intrinsics.focal_px > 0.0);
}

#[test]
fn string_ids_round_trip_as_strings() {
    // An image folder's ids are file stems: strings, also when they look like numbers.
    let s = scene(CameraModel::Orthographic, 0.3, 0.0, 6);
    let frames: Vec<Id> = (0..s.table.n_frames())
        .map(|f| Id::Str(format!("img_{f:03}")))
        .collect();
    let tracks: Vec<Id> = (0..s.table.n_tracks())
        .map(|p| Id::Str(format!("{p:04}")))
        .collect();
    let mut table = rank3::TrackTable::new(frames, tracks);
    for f in 0..s.table.n_frames() {
        for p in 0..s.table.n_tracks() {
            if let Some(q) = s.table.get(f, p) {
                table.set(f, p, q[0], q[1]);
            }
        }
    }
    let rec = Reconstruction::from_tracks(
        &table,
        &Config {
            camera: CameraModel::Orthographic,
            ..Config::default()
        },
    )
    .unwrap();
    let file = round_trip(&rec, "rt-strings");
    assert_eq!(file.frames[2].frame, Id::Str("img_002".into()));
    assert_eq!(file.points[7].track, Id::Str("0007".into()));
}

#[test]
fn unknown_schema_is_a_typed_error() {
    let d = tmp("schema");
    let s = scene(CameraModel::Orthographic, 0.3, 0.0, 7);
    let w = rank3::output::write_all(&reconstruct(&s, CameraModel::Orthographic), &d).unwrap();
    let text = std::fs::read_to_string(&w.json).unwrap().replacen(
        "rank3.reconstruction/1",
        "rank3.reconstruction/2",
        1,
    );
    let future = d.join("future.json");
    std::fs::write(&future, text).unwrap();
    match reconstruction_file::read(&future) {
        Err(ReadError::UnsupportedSchema {
            path,
            found,
            supported,
        }) => {
            assert_eq!(path, future);
            assert_eq!(found, "rank3.reconstruction/2");
            assert_eq!(supported, SCHEMA);
        }
        other => panic!("{other:?}"),
    }
    // A file of the first layout without the key (written before it existed) still reads.
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&w.json).unwrap()).unwrap();
    v.as_object_mut().unwrap().remove("schema");
    let old = d.join("old.json");
    std::fs::write(&old, v.to_string()).unwrap();
    assert_eq!(reconstruction_file::read(&old).unwrap().schema, SCHEMA);
    // Missing file, broken JSON.
    assert!(matches!(
        reconstruction_file::read(&d.join("nope.json")),
        Err(ReadError::Io { .. })
    ));
    std::fs::write(
        d.join("bad.json"),
        "{\"schema\": \"rank3.reconstruction/1\",\n\"frames\": 3}",
    )
    .unwrap();
    match reconstruction_file::read(&d.join("bad.json")) {
        Err(ReadError::Json { line, .. }) => assert_eq!(line, 2),
        other => panic!("{other:?}"),
    }
}

/// `rank3 synth` + `rank3 reconstruct` into `d/out`; returns `d`.
fn synth_and_reconstruct(name: &str, synth: &[&str], reconstruct: &[&str]) -> PathBuf {
    let d = tmp(name);
    run_ok(bin().args(["synth", "--out"]).arg(&d).args(synth));
    run_ok(
        bin()
            .arg("reconstruct")
            .arg(d.join("tracks.csv"))
            .arg("--out")
            .arg(d.join("out"))
            .args(reconstruct),
    );
    d
}

fn eval_json(est: &Path, reference: &Path) -> serde_json::Value {
    let out = bin()
        .arg("eval")
        .arg(est)
        .arg("--reference")
        .arg(reference)
        .arg("--json")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

fn structure_pct(v: &serde_json::Value) -> f64 {
    v["structure"]["rms_pct"].as_f64().unwrap()
}

#[test]
fn eval_scores_an_affine_reconstruction_against_truth() {
    // The structure error grows with the image noise, about linearly: 0 without noise.
    let mut errors = Vec::new();
    for noise in ["0", "0.5", "2"] {
        let d = synth_and_reconstruct(
            &format!("affine-{noise}"),
            &[
                "--frames",
                "12",
                "--points",
                "60",
                "--noise",
                noise,
                "--camera",
                "scaled-orthographic",
                "--seed",
                "8",
            ],
            &["--camera", "scaled-orthographic"],
        );
        // The output folder and the truth file; the table on stdout.
        let table = run_ok(
            bin()
                .arg("eval")
                .arg(d.join("out"))
                .arg("--reference")
                .arg(d.join("truth.json")),
        );
        for row in ["structure error", "rotation error", "reprojection RMS"] {
            assert!(table.contains(row), "{table}");
        }
        let v = eval_json(&d.join("out"), &d.join("truth.json"));
        assert_eq!(v["reference_kind"], "truth");
        assert_eq!(v["points"]["common"], 60);
        assert_eq!(v["frames"]["common"], 12);
        assert_eq!(v["structure"]["reflection_allowed"], true);
        assert!(v["centre_pct"].is_null() && v["focal"].is_null());
        // The same figure as the library's own comparison of the same points.
        let rec = reconstruction_file::read(&d.join("out/reconstruction.json")).unwrap();
        let truth: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(d.join("truth.json")).unwrap()).unwrap();
        let v3 = |a: &serde_json::Value| {
            Vector3::new(
                a[0].as_f64().unwrap(),
                a[1].as_f64().unwrap(),
                a[2].as_f64().unwrap(),
            )
        };
        // Tracks in the same order on both sides; the outliers the robust pass found are
        // left out, as `rank3 eval` does.
        let truth_points = truth["points"].as_array().unwrap();
        let (est, tru): (Vec<_>, Vec<_>) = rec
            .points
            .iter()
            .zip(truth_points)
            .filter(|(p, _)| p.inlier)
            .map(|(p, t)| (Vector3::from(p.xyz), v3(&t["xyz"])))
            .unzip();
        assert_eq!(v["points"]["compared"], est.len());
        let lib = 100.0 * rank3::eval::structure_error(&est, &tru);
        assert!(
            (structure_pct(&v) - lib).abs() < 1e-9 * lib.max(1.0),
            "{v} vs {lib}"
        );
        let rms = v["estimate_rms_px"].as_f64().unwrap();
        assert!((rms - rec.rms_px).abs() < 1e-12);
        errors.push((
            structure_pct(&v),
            v["rotation_deg"]["rms"].as_f64().unwrap(),
        ));
    }
    eprintln!("structure / rotation errors at noise 0, 0.5, 2 px: {errors:?}");
    let (e0, e05, e2) = (errors[0].0, errors[1].0, errors[2].0);
    assert!(e0 < 1e-3, "noise-free: {e0} %");
    // 0.5 px on an object about 400 px across: a fraction of a per cent.
    assert!(e05 > 0.01 && e05 < 1.0, "noise 0.5 px: {e05} %");
    // Four times the noise, two to eight times the error.
    assert!(e2 > 2.0 * e05 && e2 < 8.0 * e05, "{e05} % → {e2} %");
    assert!(errors[0].1 < 1e-3 && errors[1].1 < 1.0, "{errors:?}");
}

#[test]
fn eval_sees_a_perturbed_reconstruction() {
    let d = synth_and_reconstruct(
        "perturbed",
        &[
            "--frames", "12", "--points", "60", "--noise", "0.5", "--seed", "9",
        ],
        &["--camera", "orthographic"],
    );
    let good = eval_json(&d.join("out"), &d.join("truth.json"));
    // The points moved by about 5 % of their spread, one camera turned by 10°.
    let mut file = reconstruction_file::read(&d.join("out/reconstruction.json")).unwrap();
    let spread = {
        let n = file.points.len() as f64;
        let c = file
            .points
            .iter()
            .fold(Vector3::zeros(), |a, p| a + Vector3::from(p.xyz))
            / n;
        (file
            .points
            .iter()
            .map(|p| (Vector3::from(p.xyz) - c).norm_squared())
            .sum::<f64>()
            / n)
            .sqrt()
    };
    for (k, p) in file.points.iter_mut().enumerate() {
        let s = 0.05 * spread;
        let k = k as f64;
        p.xyz[0] += s * (1.3 * k).sin();
        p.xyz[1] += s * (2.1 * k + 0.4).cos();
        p.xyz[2] += s * (0.7 * k + 1.0).sin();
    }
    let turn = nalgebra::Rotation3::from_axis_angle(&Vector3::y_axis(), 10f64.to_radians());
    let r = nalgebra::Matrix3::from_fn(|i, j| file.frames[5].rotation[i][j]) * turn.matrix();
    file.frames[5].rotation = std::array::from_fn(|i| std::array::from_fn(|j| r[(i, j)]));
    let bad = d.join("bad");
    std::fs::create_dir_all(&bad).unwrap();
    std::fs::write(bad.join("reconstruction.json"), file.to_json()).unwrap();
    let worse = eval_json(&bad, &d.join("truth.json"));
    let (g, w) = (structure_pct(&good), structure_pct(&worse));
    assert!(g < 1.0 && w > 3.0 && w > 10.0 * g, "{g} % → {w} %");
    let max_rot = worse["rotation_deg"]["max"].as_f64().unwrap();
    assert!((max_rot - 10.0).abs() < 1.5, "{worse}");
    // Against itself: nothing.
    let same = eval_json(&bad, &bad.join("reconstruction.json"));
    assert_eq!(same["reference_kind"], "reconstruction");
    assert!(structure_pct(&same) < 1e-9, "{same}");
    assert!(same["rotation_deg"]["max"].as_f64().unwrap() < 1e-6);
}

#[test]
fn eval_scores_a_perspective_reconstruction() {
    let d = synth_and_reconstruct(
        "perspective",
        &[
            "--frames",
            "12",
            "--points",
            "60",
            "--noise",
            "0.3",
            "--camera",
            "perspective",
            "--distance",
            "2.5",
            "--seed",
            "10",
        ],
        &["--camera", "perspective", "--image-size", "640,480"],
    );
    let v = eval_json(&d.join("out/reconstruction.json"), &d);
    assert_eq!(v["estimate_structure"], "perspective.points");
    assert_eq!(v["structure"]["reflection_allowed"], false);
    assert_eq!(v["structure"]["reflected"], false);
    assert!(structure_pct(&v) < 1.0, "{v}");
    assert!(v["rotation_deg"]["max"].as_f64().unwrap() < 1.0, "{v}");
    assert!(v["centre_pct"]["rms"].as_f64().unwrap() < 2.0, "{v}");
    let focal = &v["focal"];
    assert!(
        (focal["reference_px"].as_f64().unwrap() - 500.0).abs() < 1e-9,
        "{v}"
    );
    assert!(focal["error_pct"].as_f64().unwrap().abs() < 3.0, "{v}");
    let table = run_ok(
        bin()
            .arg("eval")
            .arg(d.join("out"))
            .arg("-r")
            .arg(d.join("truth.json")),
    );
    for row in ["camera centres", "focal length", "no reflection"] {
        assert!(table.contains(row), "{table}");
    }
}

#[test]
fn eval_reports_bad_references_as_typed_errors() {
    let d = tmp("errors");
    let s = scene(CameraModel::Orthographic, 0.3, 0.0, 11);
    let rec = reconstruct(&s, CameraModel::Orthographic);
    let out = d.join("out");
    rank3::output::write_all(&rec, &out).unwrap();
    std::fs::write(d.join("truth.json"), s.truth_json()).unwrap();
    let est = out.join("reconstruction.json");
    assert!(compare::evaluate(&out, &d).is_ok());

    // A missing reference: the file is named.
    let missing = d.join("missing.json");
    match compare::evaluate(&est, &missing) {
        Err(EvalError::Read(ReadError::Io { path, .. })) => assert_eq!(path, missing),
        other => panic!("{other:?}"),
    }
    let err = run_err(bin().arg("eval").arg(&est).arg("-r").arg(&missing));
    assert!(err.contains("missing.json"), "{err}");
    // A folder with nothing to compare with.
    let empty = d.join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    assert!(matches!(
        compare::evaluate(&est, &empty),
        Err(EvalError::NothingToRead { .. })
    ));
    assert!(matches!(
        compare::evaluate(&empty, &d),
        Err(EvalError::NothingToRead { .. })
    ));

    // Another scene's truth with string track ids: no common track.
    let mut truth: serde_json::Value = serde_json::from_str(&s.truth_json()).unwrap();
    for p in truth["points"].as_array_mut().unwrap() {
        let id = p["track"].to_string();
        p["track"] = serde_json::Value::String(format!("t{id}"));
    }
    let other = d.join("other_truth.json");
    std::fs::write(&other, truth.to_string()).unwrap();
    match compare::evaluate(&est, &other) {
        Err(EvalError::NoCommonTracks {
            estimate,
            reference,
            ..
        }) => {
            assert_eq!((estimate, reference), (est.clone(), other.clone()));
        }
        other => panic!("{other:?}"),
    }
    let err = run_err(bin().arg("eval").arg(&est).arg("-r").arg(&other));
    assert!(
        err.contains("no track id in common") && err.contains("other_truth.json"),
        "{err}"
    );

    // Three common points.
    let mut few: serde_json::Value = serde_json::from_str(&s.truth_json()).unwrap();
    few["points"].as_array_mut().unwrap().truncate(3);
    let few_path = d.join("few.json");
    std::fs::write(&few_path, few.to_string()).unwrap();
    match compare::evaluate(&est, &few_path) {
        Err(EvalError::TooFewCommonPoints { have, needed, .. }) => {
            assert_eq!((have, needed), (3, compare::MIN_COMMON_POINTS));
        }
        other => panic!("{other:?}"),
    }
    let err = run_err(bin().arg("eval").arg(&est).arg("-r").arg(&few_path));
    assert!(err.contains("at least 4 needed"), "{err}");

    // A reference from a later rank3.
    let text = std::fs::read_to_string(&est)
        .unwrap()
        .replacen(SCHEMA, "rank3.reconstruction/9", 1);
    let future = d.join("future.json");
    std::fs::write(&future, text).unwrap();
    assert!(matches!(
        compare::evaluate(&est, &future),
        Err(EvalError::Read(ReadError::UnsupportedSchema { .. }))
    ));
    let err = run_err(bin().arg("eval").arg(&est).arg("-r").arg(&future));
    assert!(err.contains("newer rank3"), "{err}");

    // The truth given as the estimate.
    assert!(matches!(
        compare::evaluate(&d.join("truth.json"), &est),
        Err(EvalError::TruthAsEstimate { .. })
    ));
    // A broken truth.json.
    let broken = d.join("broken_truth.json");
    std::fs::write(&broken, "{\"config\": {}, \"frames\": []}").unwrap();
    assert!(matches!(
        compare::evaluate(&est, &broken),
        Err(EvalError::Truth { .. })
    ));
}
