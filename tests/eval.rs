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

// ---------------------------------------------------------------------------------------
// COLMAP references.

/// A perspective scene (12 frames × 60 points, 20 % missing) reconstructed with the
/// perspective camera: `d/out/` with its COLMAP export `d/out/colmap/`.
fn perspective_with_export(name: &str, seed: &str, noise: &str) -> PathBuf {
    let d = synth_and_reconstruct(
        name,
        &[
            "--frames",
            "12",
            "--points",
            "60",
            "--noise",
            noise,
            "--missing",
            "0.2",
            "--camera",
            "perspective",
            "--distance",
            "2.5",
            "--seed",
            seed,
        ],
        &["--camera", "perspective", "--image-size", "640,480"],
    );
    assert!(d.join("out/colmap/images.txt").is_file());
    d
}

/// Copies the three files of a COLMAP text model.
fn copy_model(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for f in ["cameras.txt", "images.txt", "points3D.txt"] {
        std::fs::copy(from.join(f), to.join(f)).unwrap();
    }
}

/// Replaces line `line` (1-based) of `path` by `f(old line)`.
fn edit_line(path: &Path, line: usize, f: impl FnOnce(&str) -> String) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    lines[line - 1] = f(&lines[line - 1]);
    std::fs::write(path, lines.join("\n") + "\n").unwrap();
}

fn f64_at(v: &serde_json::Value, path: &[&str]) -> f64 {
    let mut x = v;
    for k in path {
        x = &x[*k];
    }
    x.as_f64().unwrap_or_else(|| panic!("{path:?} in {v}"))
}

#[test]
fn eval_scores_a_reconstruction_against_its_own_colmap_export() {
    let d = perspective_with_export("colmap-self", "21", "0.3");
    let out = d.join("out");
    let v = eval_json(&out.join("reconstruction.json"), &out.join("colmap"));
    assert_eq!(v["reference_kind"], "colmap");
    assert_eq!(v["reference_structure"], "points3D.txt");
    assert_eq!(v["structure"]["reflection_allowed"], false);
    assert!(structure_pct(&v) < 1e-6, "{v}");
    assert!(f64_at(&v, &["rotation_deg", "max"]) < 1e-6, "{v}");
    assert!(f64_at(&v, &["centre_pct", "max"]) < 1e-6, "{v}");
    assert!(f64_at(&v, &["focal", "error_pct"]).abs() < 1e-9, "{v}");
    // Every fitted track and every image matched, all by name.
    let rec = reconstruction_file::read(&out.join("reconstruction.json")).unwrap();
    let per = rec.perspective.as_ref().unwrap();
    let inliers = per.points.iter().filter(|p| p.inlier).count();
    let m = &v["matching"];
    assert_eq!(m["images"], per.cameras.len());
    assert_eq!(m["images_by_name"], per.cameras.len());
    assert_eq!(m["tracks_matched"], inliers);
    assert_eq!(m["tracks_unmatched"], 0);
    assert_eq!(m["agreement"], 1.0);
    assert_eq!(v["points"]["compared"], inliers);
    assert_eq!(v["frames"]["common"], per.cameras.len());
    assert_eq!(
        f64_at(&v, &["estimate_rms_px"]),
        rec.rms_px,
        "the reconstruction's RMS"
    );
    // One of the three files stands for the folder; the table names the matching.
    for file in ["images.txt", "cameras.txt", "points3D.txt"] {
        let w = eval_json(&out, &out.join("colmap").join(file));
        assert!(structure_pct(&w) < 1e-6, "{file}: {w}");
    }
    let table = run_ok(
        bin()
            .arg("eval")
            .arg(&out)
            .arg("-r")
            .arg(out.join("colmap")),
    );
    for row in [
        "(COLMAP model)",
        "matching",
        "by name",
        "no reflection",
        "focal length",
    ] {
        assert!(table.contains(row), "{table}");
    }
    eprintln!("{table}");

    // A camera model whose focal length is not compared: said so, the rest scored.
    let fisheye = d.join("fisheye");
    copy_model(&out.join("colmap"), &fisheye);
    let cams = std::fs::read_to_string(fisheye.join("cameras.txt")).unwrap();
    let line = cams.lines().position(|l| !l.starts_with('#')).unwrap() + 1;
    edit_line(&fisheye.join("cameras.txt"), line, |l| {
        let t: Vec<&str> = l.split(' ').collect();
        format!(
            "{} OPENCV_FISHEYE {} {} {} {} {} {} 0 0 0 0",
            t[0], t[2], t[3], t[4], t[4], t[5], t[6]
        )
    });
    let v = eval_json(&out, &fisheye);
    assert!(v["focal"].is_null(), "{v}");
    let note = v["matching"]["intrinsics_note"].as_str().unwrap();
    assert!(
        note.contains("OPENCV_FISHEYE") && note.contains("not compared"),
        "{v}"
    );
    assert!(structure_pct(&v) < 1e-6, "{v}");
    let table = run_ok(bin().arg("eval").arg(&out).arg("-r").arg(&fisheye));
    assert!(table.contains("intrinsics not compared"), "{table}");
}

/// `truth.json` of a perspective scene written as a COLMAP model the way a model made
/// elsewhere would differ from rank3's export: images named `frames/0000NN.png` and listed
/// backwards with their own ids, 3D point ids unrelated to the track ids, keypoints off by
/// up to 0.45 px, keypoints without a 3D point, one `PINHOLE` camera per image.
fn truth_as_colmap(d: &Path, to: &Path) {
    use rank3::colmap::{ColmapCamera, ColmapCameraModel, ColmapImage, ColmapModel, ColmapPoint};
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("truth.json")).unwrap()).unwrap();
    let table = rank3::TrackTable::read(d.join("tracks.csv")).unwrap();
    let m3 = |a: &serde_json::Value| nalgebra::Matrix3::from_fn(|i, j| a[i][j].as_f64().unwrap());
    let frames = truth["frames"].as_array().unwrap();
    let n_points = truth["points"].as_array().unwrap().len();
    let point_id = |p: usize| 1000 + 7 * (n_points - p) as u64;
    let mut points: Vec<ColmapPoint> = (0..n_points)
        .map(|p| {
            let xyz = &truth["points"][p]["xyz"];
            ColmapPoint {
                id: point_id(p),
                xyz: std::array::from_fn(|k| xyz[k].as_f64().unwrap()),
                rgb: [200, 100, 50],
                error: 0.5,
                track: Vec::new(),
            }
        })
        .collect();
    let (mut cameras, mut images) = (Vec::new(), Vec::new());
    for (f, fr) in frames.iter().enumerate().rev() {
        assert_eq!(table.frame_ids()[f], Id::Int(fr["frame"].as_i64().unwrap()));
        let id = 50 + f as u32;
        let k = m3(&fr["K"]);
        cameras.push(ColmapCamera {
            id,
            model: ColmapCameraModel::Pinhole {
                fx: k[(0, 0)],
                fy: k[(1, 1)],
                cx: k[(0, 2)] + 0.5,
                cy: k[(1, 2)] + 0.5,
            },
            width: 640,
            height: 480,
        });
        let t = &fr["t"];
        let mut points2d = vec![([3.0, 4.0], None)];
        for (p, point) in points.iter_mut().enumerate() {
            let Some([x, y]) = table.get(f, p) else {
                continue;
            };
            let s = (f * 31 + p * 17) as f64;
            let jitter = [0.45 * s.sin(), 0.45 * (1.7 * s).cos()];
            point.track.push((id, points2d.len()));
            points2d.push((
                [x + 0.5 + jitter[0], y + 0.5 + jitter[1]],
                Some(point_id(p)),
            ));
            if p % 5 == 0 {
                points2d.push(([x + 9.0, y - 7.0], None));
            }
        }
        images.push(ColmapImage {
            id,
            camera_id: id,
            name: format!("frames/{f:06}.png"),
            rotation: m3(&fr["R"]),
            translation: Vector3::new(
                t[0].as_f64().unwrap(),
                t[1].as_f64().unwrap(),
                t[2].as_f64().unwrap(),
            ),
            points2d,
        });
    }
    points.retain(|p| !p.track.is_empty());
    ColmapModel {
        cameras,
        images,
        points,
    }
    .write_text(to)
    .unwrap();
}

#[test]
fn eval_against_the_truth_and_its_colmap_model_agree() {
    let d = perspective_with_export("colmap-truth", "22", "0.3");
    let truth_model = d.join("truth_colmap");
    truth_as_colmap(&d, &truth_model);
    let out = d.join("out");
    let a = eval_json(&out, &d.join("truth.json"));
    let b = eval_json(&out, &truth_model);
    eprintln!("truth.json: {a}\nCOLMAP model of the truth: {b}");
    assert_eq!(b["reference_kind"], "colmap");
    // The same points and frames compared, and the same figures.
    assert_eq!(a["points"]["compared"], b["points"]["compared"], "{b}");
    assert_eq!(a["frames"]["common"], b["frames"]["common"], "{b}");
    assert_eq!(b["matching"]["images_by_stem"], b["frames"]["common"]);
    assert_eq!(b["matching"]["images_by_name"], 0);
    assert_eq!(b["matching"]["tracks_unmatched"], 0);
    assert_eq!(b["matching"]["tracks_ambiguous"], 0);
    for path in [
        &["structure", "rms_pct"][..],
        &["structure", "max_pct"],
        &["structure", "scale"],
        &["rotation_deg", "median"],
        &["rotation_deg", "max"],
        &["centre_pct", "rms"],
        &["centre_pct", "max"],
        &["focal", "reference_px"],
        &["focal", "error_pct"],
    ] {
        let (x, y) = (f64_at(&a, path), f64_at(&b, path));
        assert!(
            (x - y).abs() <= 1e-9 * x.abs().max(1e-6),
            "{path:?}: {x} (truth.json) vs {y} (COLMAP)"
        );
    }
    // A reasonable reconstruction, not a vacuous agreement.
    assert!(structure_pct(&a) > 1e-4 && structure_pct(&a) < 2.0, "{a}");
    assert_eq!(f64_at(&b, &["focal", "reference_px"]), 500.0);

    // Another reconstruction of the same scene with twice the image noise, scored against
    // the first one's export: matched by observations 0.5 px apart, and as close to it as
    // their errors against the truth allow.
    let e = perspective_with_export("colmap-noisier", "22", "0.6");
    let t = eval_json(&e.join("out"), &d.join("truth.json"));
    let v = eval_json(&e.join("out"), &out.join("colmap"));
    let m = &v["matching"];
    assert_eq!(m["images_unmatched"], 0, "{v}");
    assert!(f64_at(m, &["agreement"]) > 0.9, "{v}");
    let (sa, st, sv) = (structure_pct(&a), structure_pct(&t), structure_pct(&v));
    eprintln!("structure errors: first {sa} %, second {st} %, second vs first {sv} %");
    assert!(
        sv < 1.5 * (sa + st) + 0.01 && sv > 0.2 * (st - sa).abs(),
        "{v}"
    );
}

#[test]
fn a_malformed_colmap_reference_names_the_file_and_line() {
    let d = perspective_with_export("colmap-bad", "23", "0.3");
    let out = d.join("out");
    let bad = d.join("bad");
    copy_model(&out.join("colmap"), &bad);
    // Line 7 is the second image's first line (4 comment lines, then 2 lines per image).
    edit_line(&bad.join("images.txt"), 7, |l| {
        let mut t: Vec<&str> = l.split(' ').collect();
        t[2] = "zero";
        t.join(" ")
    });
    match compare::evaluate(&out, &bad) {
        Err(EvalError::Input(rank3::Error::Parse {
            path, line, field, ..
        })) => {
            assert_eq!(path, bad.join("images.txt"));
            assert_eq!((line, field.as_str()), (7, "QX"));
        }
        other => panic!("{other:?}"),
    }
    let err = run_err(bin().arg("eval").arg(&out).arg("-r").arg(&bad));
    assert!(err.contains("images.txt:7") && err.contains("QX"), "{err}");
    // A keypoint line cut short, and a camera with the wrong number of parameters.
    copy_model(&out.join("colmap"), &bad);
    edit_line(&bad.join("images.txt"), 8, |l| format!("{l} 12.5"));
    let err = run_err(
        bin()
            .arg("eval")
            .arg(&out)
            .arg("-r")
            .arg(bad.join("images.txt")),
    );
    assert!(
        err.contains("images.txt:8") && err.contains("POINT3D_ID"),
        "{err}"
    );
    copy_model(&out.join("colmap"), &bad);
    edit_line(&bad.join("cameras.txt"), 4, |l| {
        l.replacen("SIMPLE_PINHOLE", "OPENCV", 1)
    });
    match compare::evaluate(&out, &bad) {
        Err(EvalError::Input(rank3::Error::Parse { line, field, .. })) => {
            assert_eq!((line, field.as_str()), (4, "PARAMS"))
        }
        other => panic!("{other:?}"),
    }
    // A missing file is named.
    copy_model(&out.join("colmap"), &bad);
    std::fs::remove_file(bad.join("points3D.txt")).unwrap();
    let err = run_err(bin().arg("eval").arg(&out).arg("-r").arg(&bad));
    assert!(err.contains("points3D.txt"), "{err}");
}

#[test]
fn a_colmap_reference_sharing_no_frame_or_no_observation_is_refused() {
    let d = perspective_with_export("colmap-disjoint", "24", "0.3");
    let out = d.join("out");
    let other = d.join("other");
    copy_model(&out.join("colmap"), &other);
    // Every image renamed: no name or stem is a frame id.
    let text = std::fs::read_to_string(other.join("images.txt")).unwrap();
    let mut k = 0;
    let renamed: Vec<String> = text
        .lines()
        .enumerate()
        .map(|(i, l)| {
            if i >= 4 && i % 2 == 0 {
                k += 1;
                let mut t: Vec<String> = l.split(' ').map(str::to_string).collect();
                t[9] = format!("view_{k}.jpg");
                t.join(" ")
            } else {
                l.to_string()
            }
        })
        .collect();
    std::fs::write(other.join("images.txt"), renamed.join("\n") + "\n").unwrap();
    match compare::evaluate(&out, &other) {
        Err(EvalError::NoCommonFrames {
            estimate,
            reference,
            reference_examples,
            ..
        }) => {
            assert_eq!(estimate, out.join("reconstruction.json"));
            assert_eq!(reference, other);
            assert!(
                reference_examples.contains("view_1.jpg"),
                "{reference_examples}"
            );
        }
        other => panic!("{other:?}"),
    }
    let err = run_err(bin().arg("eval").arg(&out).arg("-r").arg(&other));
    assert!(
        err.contains("share no frame") && err.contains("view_1.jpg"),
        "{err}"
    );

    // An estimate without observations (an affine result has no COLMAP export): refused,
    // saying what to give; with its track table, scored.
    run_ok(
        bin()
            .arg("reconstruct")
            .arg(d.join("tracks.csv"))
            .arg("--out")
            .arg(d.join("affine"))
            .args(["--camera", "scaled-orthographic"]),
    );
    match compare::evaluate(&d.join("affine"), &out.join("colmap")) {
        Err(EvalError::NoObservations { reason, .. }) => {
            assert!(reason.contains("--tracks"), "{reason}")
        }
        other => panic!("{other:?}"),
    }
    let opts = compare::EvalOptions {
        tracks: Some(d.join("tracks.csv")),
        ..Default::default()
    };
    let c = compare::evaluate_with(&d.join("affine"), &out.join("colmap"), &opts).unwrap();
    let m = c.matching.as_ref().unwrap();
    // Every 3D point of the export is one track of the table; the table's observations
    // that the export marks as outliers (`-1`) do not vote.
    let exported = std::fs::read_to_string(out.join("colmap/points3D.txt"))
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#'))
        .count();
    assert_eq!(m.tracks_matched, exported, "{m:?}");
    assert_eq!(m.tracks_ambiguous, 0, "{m:?}");
    assert!(m.agreement > 0.9, "{m:?}");
    assert!(c.structure.reflection_allowed && c.structure.rms_pct.is_finite());
    // The truth's COLMAP-free reference is unchanged: a truth.json still reads.
    assert!(compare::evaluate(&d.join("affine"), &d.join("truth.json")).is_ok());
    // A tolerance that is not a positive number.
    let opts = compare::EvalOptions {
        match_tolerance_px: 0.0,
        ..Default::default()
    };
    assert!(matches!(
        compare::evaluate_with(&out, &out.join("colmap"), &opts),
        Err(EvalError::InvalidTolerance(_))
    ));
}

/// The model as COLMAP's own writer (pycolmap) writes it, with an `OPENCV` camera and
/// images renamed `img_000NN.jpg`... skipped without pycolmap.
#[test]
fn eval_reads_a_colmap_model_written_by_pycolmap() {
    let python = std::env::var("RANK3_PYTHON").unwrap_or_else(|_| "python3".into());
    let has = std::process::Command::new(&python)
        .args(["-c", "import pycolmap"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !has {
        eprintln!("SKIPPED: `{python}` cannot import pycolmap (set RANK3_PYTHON)");
        return;
    }
    let d = perspective_with_export("colmap-pycolmap", "25", "0.3");
    let out = d.join("out");
    let written = d.join("pycolmap");
    std::fs::create_dir_all(&written).unwrap();
    let script = r#"
import sys, pycolmap
rec = pycolmap.Reconstruction(sys.argv[1])
for cid, cam in rec.cameras.items():
    f, cx, cy = list(cam.params)[:3]
    cam.model = pycolmap.CameraModelId.OPENCV
    cam.params = [f, f, cx, cy, 0.0, 0.0, 0.0, 0.0]
for iid, img in rec.images.items():
    img.name = "images/%06d.jpg" % int(img.name)
rec.write_text(sys.argv[2])
"#;
    let o = std::process::Command::new(&python)
        .args(["-c", script])
        .arg(out.join("colmap"))
        .arg(&written)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = eval_json(&out, &written);
    assert_eq!(
        v["matching"]["images_by_stem"], v["frames"]["reference"],
        "{v}"
    );
    assert_eq!(v["matching"]["camera_models"][0], "OPENCV");
    assert!(structure_pct(&v) < 1e-6, "{v}");
    assert!(f64_at(&v, &["rotation_deg", "max"]) < 1e-6, "{v}");
    assert!(f64_at(&v, &["focal", "error_pct"]).abs() < 1e-9, "{v}");
}
