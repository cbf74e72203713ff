//! The `rank3` binary end to end: synth → reconstruct → output files, and bad input.

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;
use common::{bin, run_err, run_ok};

fn tmp(name: &str) -> PathBuf {
    common::tmp_dir("cli", name)
}

/// Reads a binary little-endian PLY with float x, y, z (+ uchar red, green, blue when the
/// frames were known, + uchar inlier) vertices.
fn read_ply(path: &Path) -> Vec<[f32; 3]> {
    let bytes = std::fs::read(path).unwrap();
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    let header = std::str::from_utf8(&bytes[..end]).unwrap();
    assert!(header.starts_with("ply\nformat binary_little_endian 1.0\n"));
    let n: usize = header
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .unwrap()
        .parse()
        .unwrap();
    for p in ["property float x", "property float y", "property float z"] {
        assert!(header.contains(p));
    }
    let stride: usize = header
        .lines()
        .filter_map(|l| l.strip_prefix("property "))
        .map(|l| if l.starts_with("float ") { 4 } else { 1 })
        .sum();
    let body = &bytes[end..];
    assert_eq!(body.len(), n * stride);
    (0..n)
        .map(|i| {
            let f = |k: usize| {
                f32::from_le_bytes(
                    body[i * stride + 4 * k..i * stride + 4 * k + 4]
                        .try_into()
                        .unwrap(),
                )
            };
            [f(0), f(1), f(2)]
        })
        .collect()
}

#[test]
fn synth_then_reconstruct_writes_all_outputs() {
    let d = tmp("e2e");
    run_ok(bin().args(["synth", "--out"]).arg(&d).args([
        "--frames",
        "12",
        "--points",
        "50",
        "--noise",
        "0.5",
        "--camera",
        "scaled-orthographic",
        "--seed",
        "3",
    ]));
    assert!(d.join("truth.json").exists());
    let out = d.join("out");
    let log = run_ok(
        bin()
            .arg("reconstruct")
            .arg(d.join("tracks.csv"))
            .arg("--out")
            .arg(&out)
            .args(["--camera", "scaled-orthographic"]),
    );
    assert!(log.contains("RMS"), "{log}");

    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("reconstruction.json")).unwrap())
            .unwrap();
    assert_eq!(json["camera_model"], "scaled-orthographic");
    let frames = json["frames"].as_array().unwrap();
    let points = json["points"].as_array().unwrap();
    assert_eq!((frames.len(), points.len()), (12, 50));
    for key in [
        "rms_px",
        "metric_upgrade",
        "singular_values",
        "set_aside",
        "timings",
    ] {
        assert!(!json[key].is_null(), "missing {key}");
    }
    assert!(json["metric_upgrade"]["method"].is_string());
    assert!(json["metric_upgrade"]["min_eigenvalue_ls"].is_number());

    // The numbers obey [x, y] = scale · rotation[0..2] · xyz + translation, and rms_px is
    // the RMS over observed scalars.
    let tracks = std::fs::read_to_string(d.join("tracks.csv")).unwrap();
    let (mut ss, mut n) = (0.0, 0usize);
    for line in tracks.lines().skip(1) {
        let v: Vec<f64> = line.split(',').map(|s| s.parse().unwrap()).collect();
        let (f, p) = (v[0] as usize, v[1] as usize);
        let fr = &frames[f];
        assert_eq!(fr["frame"].as_u64().unwrap() as usize, f);
        assert_eq!(points[p]["track"].as_u64().unwrap() as usize, p);
        let s = fr["scale"].as_f64().unwrap();
        let xyz: Vec<f64> = points[p]["xyz"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        for r in 0..2 {
            let row: Vec<f64> = fr["rotation"][r]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect();
            let pred = s * (0..3).map(|k| row[k] * xyz[k]).sum::<f64>()
                + fr["translation"][r].as_f64().unwrap();
            ss += (pred - v[2 + r]).powi(2);
            n += 1;
        }
    }
    let rms = (ss / n as f64).sqrt();
    assert!((rms - json["rms_px"].as_f64().unwrap()).abs() < 1e-9 * rms.max(1.0));
    assert!(rms < 0.6);

    // completed.txt: 2F × N, the affine prediction close to the data.
    let completed = std::fs::read_to_string(out.join("completed.txt")).unwrap();
    let rows: Vec<Vec<f64>> = completed
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| l.split_whitespace().map(|t| t.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 24);
    assert!(rows.iter().all(|r| r.len() == 50));

    let ply = read_ply(&out.join("points.ply"));
    assert_eq!(ply.len(), 50);
    for (a, b) in ply.iter().zip(points) {
        for k in 0..3 {
            let want = b["xyz"][k].as_f64().unwrap();
            assert!((a[k] as f64 - want).abs() <= 1e-5 * want.abs().max(1.0));
        }
    }
}

#[test]
fn dense_txt_and_json_inputs_work() {
    let d = tmp("formats");
    run_ok(
        bin()
            .args(["synth", "--out"])
            .arg(&d)
            .args(["--frames", "8", "--points", "30"]),
    );
    let table = rank3::TrackTable::read(d.join("tracks.csv")).unwrap();
    for name in ["tracks.txt", "tracks.json"] {
        table.write(d.join(name)).unwrap();
        let out = d.join(format!("out-{name}"));
        run_ok(
            bin()
                .arg("reconstruct")
                .arg(d.join(name))
                .arg("--out")
                .arg(&out),
        );
        assert!(out.join("reconstruction.json").exists());
    }
}

#[test]
fn bad_input_names_file_line_and_field() {
    let d = tmp("bad");
    let f = d.join("bad.csv");
    std::fs::write(&f, "frame,track,x,y\n0,0,1.0,2.0\n0,1,oops,2.0\n").unwrap();
    let err = run_err(
        bin()
            .arg("reconstruct")
            .arg(&f)
            .arg("--out")
            .arg(d.join("o")),
    );
    assert!(err.contains("bad.csv:3: field `x`"), "{err}");
    assert!(err.contains("oops"), "{err}");
    // The documented exit status: 1 for bad input, 2 for a usage error.
    let status = |c: &mut std::process::Command| c.output().unwrap().status.code();
    assert_eq!(
        status(
            bin()
                .arg("reconstruct")
                .arg(&f)
                .arg("--out")
                .arg(d.join("o"))
        ),
        Some(1)
    );
    assert_eq!(
        status(bin().arg("reconstruct").arg("--no-such-flag")),
        Some(2)
    );
    assert_eq!(
        status(
            bin()
                .arg("eval")
                .arg(d.join("missing.json"))
                .arg("-r")
                .arg(&f)
        ),
        Some(1)
    );

    let f = d.join("bad.txt");
    std::fs::write(&f, "# m\n1 2 3\n4 5\n").unwrap();
    let err = run_err(
        bin()
            .arg("reconstruct")
            .arg(&f)
            .arg("--out")
            .arg(d.join("o")),
    );
    assert!(
        err.contains("bad.txt:3: field `row 1`") && err.contains("ragged"),
        "{err}"
    );

    let f = d.join("tracks.xyz");
    std::fs::write(&f, "").unwrap();
    let err = run_err(
        bin()
            .arg("reconstruct")
            .arg(&f)
            .arg("--out")
            .arg(d.join("o")),
    );
    assert!(err.contains("unknown track-table format"), "{err}");

    let err = run_err(
        bin()
            .arg("reconstruct")
            .arg(d.join("absent.csv"))
            .arg("--out")
            .arg(d.join("o")),
    );
    assert!(err.contains("absent.csv"), "{err}");
}

/// A rigid 3D scene for `rank3 run`: the two faces of a convex building corner (face A in
/// the plane z = 0, x ∈ [−L, 0]; face B in the plane x = 0, z ∈ [0, L]; y ∈ [−H, H]),
/// textured with the synthetic module's procedural texture and seen by an orthographic
/// camera whose rotation `Rx(α_k) Ry(φ_k)` changes every frame.
struct Corner {
    tex: rank3::tracking::synthetic::Sequence,
    rotations: Vec<nalgebra::Matrix3<f64>>,
    w: usize,
    h: usize,
    /// Pixels per scene unit.
    s: f64,
}

const CORNER_L: f64 = 1.2;
const CORNER_H: f64 = 0.75;

impl Corner {
    fn new(frames: usize) -> Corner {
        use rank3::tracking::synthetic::{Sequence, SequenceConfig};
        let tex = Sequence::new(SequenceConfig {
            width: 256,
            height: 160,
            frames: 1,
            noise: 0.0,
            shapes: 25,
            seed: 11,
            ..SequenceConfig::default()
        });
        let rotations = (0..frames)
            .map(|k| {
                let phi = (36.0 + 2.0 * k as f64).to_radians();
                let alpha = (-12.0 + 2.5 * k as f64).to_radians();
                nalgebra::Rotation3::from_axis_angle(&nalgebra::Vector3::x_axis(), alpha).matrix()
                    * nalgebra::Rotation3::from_axis_angle(&nalgebra::Vector3::y_axis(), phi)
                        .matrix()
            })
            .collect();
        Corner {
            tex,
            rotations,
            w: 240,
            h: 200,
            s: 75.0,
        }
    }

    /// The scene point seen at pixel `(u, v)` of frame `k` and its face (0 = A, 1 = B), or
    /// `None` on the background.
    fn cast(&self, k: usize, u: f64, v: f64) -> Option<(nalgebra::Vector3<f64>, usize)> {
        let r = &self.rotations[k];
        let (r1, r2, r3) = (
            r.row(0).transpose(),
            r.row(1).transpose(),
            r.row(2).transpose(),
        );
        let p0 =
            r1 * ((u - self.w as f64 / 2.0) / self.s) + r2 * ((v - self.h as f64 / 2.0) / self.s);
        let mut best: Option<(f64, nalgebra::Vector3<f64>, usize)> = None;
        for (face, axis) in [(0usize, 2usize), (1, 0)] {
            let t = -p0[axis] / r3[axis];
            let x = p0 + r3 * t;
            let along = if face == 0 { -x[0] } else { x[2] };
            if (0.0..=CORNER_L).contains(&along)
                && x[1].abs() <= CORNER_H
                && best.as_ref().is_none_or(|b| t < b.0)
            {
                best = Some((t, x, face));
            }
        }
        best.map(|(_, x, f)| (x, f))
    }

    fn render(&self, k: usize) -> rank3::tracking::GrayImage {
        let mut data = vec![0.5f32; self.w * self.h];
        for v in 0..self.h {
            for u in 0..self.w {
                if let Some((x, face)) = self.cast(k, u as f64, v as f64) {
                    let a = if face == 0 {
                        CORNER_L + x[0]
                    } else {
                        CORNER_L + 0.2 + x[2]
                    };
                    let t = self.tex.texture(a * 75.0, (x[1] + CORNER_H) * 75.0);
                    data[v * self.w + u] = t as f32;
                }
            }
        }
        rank3::tracking::GrayImage::new(self.w, self.h, data).unwrap()
    }
}

/// Unit normal of the least-squares plane through `pts` and the RMS distance to it.
fn fit_plane(pts: &[nalgebra::Vector3<f64>]) -> (nalgebra::Vector3<f64>, f64) {
    let c = pts.iter().sum::<nalgebra::Vector3<f64>>() / pts.len() as f64;
    let cov = pts
        .iter()
        .map(|p| (p - c) * (p - c).transpose())
        .sum::<nalgebra::Matrix3<f64>>();
    let e = cov.symmetric_eigen();
    let i = e.eigenvalues.imin();
    (
        e.eigenvectors.column(i).into_owned(),
        (e.eigenvalues[i].max(0.0) / pts.len() as f64).sqrt(),
    )
}

/// The corner scene's `frames` frames rendered as `DIR/frames/000.png`, …, in a fresh test
/// folder `DIR` named `name`: the scene, `DIR` and the frames' folder.
fn rendered_corner(name: &str, frames: usize) -> (Corner, PathBuf, PathBuf) {
    let scene = Corner::new(frames);
    let d = tmp(name);
    let imgs = d.join("frames");
    std::fs::create_dir_all(&imgs).unwrap();
    for k in 0..frames {
        scene
            .render(k)
            .save_png(&imgs.join(format!("{k:03}.png")))
            .unwrap();
    }
    (scene, d, imgs)
}

/// `rank3 run` end to end on frames rendered from a rigid 3D scene with known structure:
/// tracks, metric reconstruction, and the recovered structure checked against the truth
/// (up to the similarity and mirror ambiguity of orthographic cameras) and through the
/// angle between the two faces, 90° in the scene.
#[test]
fn run_on_rendered_corner_recovers_structure() {
    let frames = 10;
    let (scene, d, imgs) = rendered_corner("run-corner", frames);
    let out = d.join("out");
    run_ok(bin().arg("run").arg(&imgs).arg("--out").arg(&out).args([
        "--max-features",
        "200",
        "--camera",
        "orthographic",
    ]));
    for f in [
        "tracks.csv",
        "reconstruction.json",
        "completed.txt",
        "points.ply",
    ] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("reconstruction.json")).unwrap())
            .unwrap();
    let rms = json["rms_px"].as_f64().unwrap();
    assert!(rms < 0.25, "metric RMS {rms} px");
    assert_eq!(json["frames"].as_array().unwrap().len(), frames);

    // Frame-0 positions of the tracks, from tracks.csv (frame,track,x,y).
    let mut first = std::collections::HashMap::new();
    for line in std::fs::read_to_string(out.join("tracks.csv"))
        .unwrap()
        .lines()
        .skip(1)
    {
        let v: Vec<f64> = line.split(',').map(|s| s.parse().unwrap()).collect();
        if v[0] == 0.0 {
            first.insert(v[1] as i64, [v[2], v[3]]);
        }
    }
    // Inlier points started in frame 0, away from the fold and the outer edges, with their
    // true 3D position (ray cast from the frame-0 position).
    let mut truth = Vec::new();
    let mut rec = Vec::new();
    let mut face = Vec::new();
    for p in json["points"].as_array().unwrap() {
        let id = p["track"].as_i64().unwrap();
        let (Some(xy), true) = (first.get(&id), p["inlier"].as_bool().unwrap()) else {
            continue;
        };
        let Some((x, f)) = scene.cast(0, xy[0], xy[1]) else {
            continue;
        };
        let along = if f == 0 { -x[0] } else { x[2] };
        if !(0.15..=CORNER_L - 0.15).contains(&along) || x[1].abs() > CORNER_H - 0.15 {
            continue;
        }
        let xyz: Vec<f64> = p["xyz"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        truth.push(x);
        rec.push(nalgebra::Vector3::new(xyz[0], xyz[1], xyz[2]));
        face.push(f);
    }
    let counts = [0, 1].map(|f| face.iter().filter(|&&g| g == f).count());
    assert!(
        counts[0] >= 20 && counts[1] >= 20,
        "points per face {counts:?}"
    );

    // Similarity (rotation or reflection, scale, shift) from truth to the reconstruction.
    let n = truth.len() as f64;
    let (ct, cr) = (
        truth.iter().sum::<nalgebra::Vector3<f64>>() / n,
        rec.iter().sum::<nalgebra::Vector3<f64>>() / n,
    );
    let h = truth
        .iter()
        .zip(&rec)
        .map(|(a, b)| (b - cr) * (a - ct).transpose())
        .sum::<nalgebra::Matrix3<f64>>();
    let svd = h.svd(true, true);
    let q = svd.u.unwrap() * svd.v_t.unwrap();
    let spread = truth.iter().map(|a| (a - ct).norm_squared()).sum::<f64>();
    let scale = svd.singular_values.sum() / spread;
    let err = truth
        .iter()
        .zip(&rec)
        .map(|(a, b)| (b - cr - scale * q * (a - ct)).norm_squared())
        .sum::<f64>();
    let rel = (err / (scale * scale * spread)).sqrt();

    // The two faces: planar, and perpendicular.
    let planes: Vec<_> = [0, 1]
        .iter()
        .map(|&f| {
            let pts: Vec<_> = rec
                .iter()
                .zip(&face)
                .filter(|(_, g)| **g == f)
                .map(|(p, _)| *p)
                .collect();
            fit_plane(&pts)
        })
        .collect();
    let size = (err / n).sqrt().max(scale * (spread / n).sqrt());
    let angle = planes[0].0.dot(&planes[1].0).abs().acos().to_degrees();
    eprintln!(
        "metric RMS {rms:.3} px, points per face {counts:?}, structure error {rel:.4}, \
         plane offsets {:.4} {:.4} (size {size:.3}), angle {angle:.2}°",
        planes[0].1, planes[1].1
    );
    // Tracking noise (~0.2 px) over a 20° turn leaves a few pixels of depth error: measured
    // 6 % of the spread, planes flat to 4 % of the size, 89.4° between them.
    assert!(rel < 0.1, "structure error {rel} of the scene's spread");
    for (normal, off) in &planes {
        assert!(
            *off < 0.06 * size,
            "face off its plane by {off} (normal {normal})"
        );
    }
    assert!((angle - 90.0).abs() < 3.0, "angle between faces {angle}°");
}

/// `rank3 run --camera perspective` on a folder of images names each image of its COLMAP model
/// by its file, so that COLMAP (`--image_path` = the folder) and OpenMVS find the pictures:
/// every name in `colmap/images.txt` is a file of the folder, once each (the frame ids, the
/// files' stems, were written before and COLMAP's `image_undistorter` read no image), and
/// its points have the frames' colours. Where COLMAP is installed (CI installs it), its
/// `model_analyzer` reads the model and its `image_undistorter` finds every image.
#[test]
fn run_names_the_colmap_images_by_their_files() {
    let frames = 10;
    let (_, d, imgs) = rendered_corner("run-colmap-names", frames);
    let out = d.join("out");
    let log = run_ok(bin().arg("run").arg(&imgs).arg("--out").arg(&out).args([
        "--max-features",
        "200",
        "--camera",
        "perspective",
    ]));
    assert!(log.contains("images named by their files"), "{log}");
    let text = std::fs::read_to_string(out.join("colmap").join("images.txt")).unwrap();
    // Image lines: `IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME`, each followed by its
    // keypoints' line.
    let names: Vec<&str> = text
        .lines()
        .filter(|l| !l.starts_with('#'))
        .step_by(2)
        .map(|l| l.split_whitespace().nth(9).expect("a NAME"))
        .collect();
    assert_eq!(names.len(), frames, "{text}");
    let distinct: std::collections::HashSet<&str> = names.iter().copied().collect();
    assert_eq!(distinct.len(), frames);
    for n in names {
        assert!(
            n.ends_with(".png") && imgs.join(n).is_file(),
            "{n} is not a frame file"
        );
    }
    // The points have the frames' colours (`POINT3D_ID X Y Z R G B ERROR TRACK[]`), as in
    // points.ply: not all the grey of a model without frames.
    let points = std::fs::read_to_string(out.join("colmap").join("points3D.txt")).unwrap();
    let colours: std::collections::HashSet<Vec<&str>> = points
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| l.split_whitespace().skip(4).take(3).collect())
        .collect();
    assert!(colours.len() > 5, "{} distinct colours", colours.len());

    // COLMAP's own reader and its undistorter, the step before dense stereo (and what
    // OpenMVS's `InterfaceCOLMAP` reads), find every image.
    let colmap = std::env::var("RANK3_COLMAP").unwrap_or_else(|_| "colmap".into());
    let analyzer = Command::new(&colmap)
        .args(["model_analyzer", "--path"])
        .arg(out.join("colmap"))
        .output();
    let Ok(analyzer) = analyzer else {
        eprintln!(
            "SKIPPED: `{colmap}` not found (apt-get install colmap, or set RANK3_COLMAP): \
             COLMAP's own reader was not run"
        );
        return;
    };
    let log = String::from_utf8_lossy(&analyzer.stdout).into_owned()
        + &String::from_utf8_lossy(&analyzer.stderr);
    assert!(analyzer.status.success(), "{log}");
    let points_written = points.lines().filter(|l| !l.starts_with('#')).count();
    assert!(
        log.contains(&format!("Registered images: {frames}")),
        "{log}"
    );
    assert!(log.contains(&format!("Points: {points_written}")), "{log}");
    let dense = d.join("dense");
    let undistorter = Command::new(&colmap)
        .args(["image_undistorter", "--image_path"])
        .arg(&imgs)
        .arg("--input_path")
        .arg(out.join("colmap"))
        .arg("--output_path")
        .arg(&dense)
        .output()
        .unwrap();
    let log = String::from_utf8_lossy(&undistorter.stderr);
    assert!(undistorter.status.success(), "{log}");
    assert!(!log.contains("Cannot read image"), "{log}");
    let undistorted = std::fs::read_dir(dense.join("images")).unwrap().count();
    assert_eq!(undistorted, frames, "{log}");
}

/// `synth --camera perspective` then `reconstruct --camera projective`: the JSON holds a
/// projective block whose P and X reproduce the truth, and completed.txt is π(P X).
#[test]
fn projective_camera_end_to_end() {
    let d = tmp("projective");
    run_ok(bin().args(["synth", "--out"]).arg(&d).args([
        "--camera",
        "perspective",
        "--distance",
        "2.5",
        "--noise",
        "0",
        "--frames",
        "10",
        "--points",
        "40",
        "--missing",
        "0.3",
    ]));
    let out = d.join("r");
    let log = run_ok(
        bin()
            .arg("reconstruct")
            .arg(d.join("tracks.csv"))
            .arg("--out")
            .arg(&out)
            .args(["--camera", "projective", "--no-robust"]),
    );
    assert!(log.contains("projective camera"), "{log}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("reconstruction.json")).unwrap())
            .unwrap();
    assert_eq!(json["camera_model"], "projective");
    let p = &json["projective"];
    let cams = p["cameras"].as_array().unwrap();
    let pts = p["points"].as_array().unwrap();
    assert_eq!(cams.len(), 10);
    assert_eq!(pts.len(), 40);
    assert!(json["rms_px"].as_f64().unwrap() < 1e-9);
    assert_eq!(json["rms_px"], p["rms_px"]);
    // completed.txt (every frame and track, hidden entries included) equals π(P_f X_p) of the
    // JSON's numbers, and the truth's noise-free projections.
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("truth.json")).unwrap()).unwrap();
    let text = std::fs::read_to_string(out.join("completed.txt")).unwrap();
    let rows: Vec<Vec<f64>> = text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| l.split_whitespace().map(|v| v.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 20);
    for f in 0..10 {
        let pm: Vec<Vec<f64>> = serde_json::from_value(cams[f]["p"].clone()).unwrap();
        let tp: Vec<Vec<f64>> = serde_json::from_value(truth["frames"][f]["P"].clone()).unwrap();
        for k in 0..40 {
            let x: Vec<f64> = serde_json::from_value(pts[k]["x"].clone()).unwrap();
            let proj = |m: &Vec<Vec<f64>>, x: &[f64]| {
                let r: Vec<f64> = (0..3)
                    .map(|i| (0..4).map(|j| m[i][j] * x[j]).sum())
                    .collect();
                [r[0] / r[2], r[1] / r[2]]
            };
            let q = proj(&pm, &x);
            let xt: Vec<f64> = serde_json::from_value(truth["points"][k]["xyz"].clone()).unwrap();
            let t = proj(&tp, &[xt[0], xt[1], xt[2], 1.0]);
            for c in 0..2 {
                assert!(
                    (rows[2 * f + c][k] - q[c]).abs() < 1e-6,
                    "frame {f} track {k}"
                );
                assert!(
                    (q[c] - t[c]).abs() < 1e-6,
                    "frame {f} track {k}: {q:?} vs truth {t:?}"
                );
            }
        }
    }
}

/// `reconstruct --objects auto` on two rigid bodies moving independently (50 and 35 tracks; orthographic
/// camera, 0.3 px noise) plus random-walk tracks: two objects found with their tracks,
/// the walks labelled −1, one reconstruction per object on its own tracks.
#[test]
fn objects_are_segmented_and_reconstructed_each() {
    use rand::{RngExt, SeedableRng};
    use rand_distr::{Distribution, Normal};
    let d = tmp("objects");
    let mut rng = rand::rngs::StdRng::seed_from_u64(11);
    let g = Normal::new(0.0, 1.0).unwrap();
    let (frames, sizes, walks) = (24usize, [50usize, 35], 3usize);
    let mut csv = String::from("frame,track,x,y\n");
    let mut truth = Vec::new();
    let mut track = 0;
    for (o, &size) in sizes.iter().enumerate() {
        let axis = nalgebra::Vector3::new(g.sample(&mut rng), g.sample(&mut rng), 1.0).normalize();
        let centre = [150.0 + 250.0 * o as f64, 200.0];
        let drift = [2.0 - 4.0 * o as f64, 1.0 + o as f64];
        for _ in 0..size {
            let x = nalgebra::Vector3::new(
                60.0 * (rng.random::<f64>() - 0.5),
                60.0 * (rng.random::<f64>() - 0.5),
                60.0 * (rng.random::<f64>() - 0.5),
            );
            for f in 0..frames {
                let r = nalgebra::Rotation3::from_scaled_axis(
                    axis * (0.04 + 0.03 * o as f64) * f as f64,
                );
                let y = r * x;
                csv += &format!(
                    "{f},{track},{},{}\n",
                    centre[0] + drift[0] * f as f64 + y[0] + 0.3 * g.sample(&mut rng),
                    centre[1] + drift[1] * f as f64 + y[1] + 0.3 * g.sample(&mut rng)
                );
            }
            truth.push(o as i64);
            track += 1;
        }
    }
    for _ in 0..walks {
        let mut p = [
            100.0 + 400.0 * rng.random::<f64>(),
            100.0 + 200.0 * rng.random::<f64>(),
        ];
        for f in 0..frames {
            p[0] += 3.0 * g.sample(&mut rng);
            p[1] += 3.0 * g.sample(&mut rng);
            csv += &format!("{f},{track},{},{}\n", p[0], p[1]);
        }
        truth.push(-1);
        track += 1;
    }
    let input = d.join("two.csv");
    std::fs::write(&input, csv).unwrap();
    let out = d.join("out");
    let log = run_ok(
        bin()
            .args(["reconstruct"])
            .arg(&input)
            .arg("--out")
            .arg(&out)
            .args(["--objects", "auto", "--camera", "orthographic"]),
    );
    assert!(log.contains("2 object(s) (found)"), "{log}");
    let labels: Vec<(usize, i64)> = std::fs::read_to_string(out.join("objects.csv"))
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| {
            let (t, o) = l.split_once(',').unwrap();
            (t.parse().unwrap(), o.parse().unwrap())
        })
        .collect();
    assert_eq!(labels.len(), truth.len(), "every input track is listed");
    // The largest object is object 0; the walks are −1.
    for (t, o) in &labels {
        let expect = match truth[*t] {
            -1 => -1,
            k => k,
        };
        assert_eq!(*o, expect, "track {t}");
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("segmentation.json")).unwrap())
            .unwrap();
    assert_eq!(report["n_objects"], 2);
    assert_eq!(report["n_outlier_tracks"], walks);
    // Two clearly separate bodies: the label cost counts them, and the report says so and
    // how far apart they are.
    assert_eq!(report["count_rule"], "label_cost");
    let q = report["separation"].as_f64().unwrap();
    assert!(q > 10.0, "separation {q}");
    for k in 0..2 {
        let rec: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(out.join(format!("object_{k}/reconstruction.json"))).unwrap(),
        )
        .unwrap();
        assert!(
            rec["rms_px"].as_f64().unwrap() < 0.5,
            "object {k}: {}",
            rec["rms_px"]
        );
        assert_eq!(report["objects"][k]["n_tracks"], sizes[k]);
    }
    // The folder's outputs belong to the last run: a single-object run into it removes the
    // objects' files and folders (and leaves the user's own files), and back.
    std::fs::write(out.join("notes.txt"), "mine").unwrap();
    run_ok(
        bin()
            .args(["reconstruct"])
            .arg(&input)
            .arg("--out")
            .arg(&out)
            .args(["--camera", "orthographic", "--no-robust"]),
    );
    for gone in ["objects.csv", "segmentation.json", "object_0", "object_1"] {
        assert!(!out.join(gone).exists(), "{gone} left from the earlier run");
    }
    assert!(out.join("reconstruction.json").exists());
    run_ok(
        bin()
            .args(["reconstruct"])
            .arg(&input)
            .arg("--out")
            .arg(&out)
            .args([
                "--objects",
                "auto",
                "--camera",
                "orthographic",
                "--assign-all",
            ]),
    );
    for gone in ["reconstruction.json", "completed.txt", "points.ply"] {
        assert!(!out.join(gone).exists(), "{gone} left from the earlier run");
    }
    assert!(out.join("object_1/reconstruction.json").exists());
    // --assign-all: the walks are given a group too; the bodies' tracks keep theirs.
    let assigned = std::fs::read_to_string(out.join("objects.csv")).unwrap();
    for (line, (t, o)) in assigned.lines().skip(1).zip(&labels) {
        let (t2, o2) = line.split_once(',').unwrap();
        assert_eq!(t2.parse::<usize>().unwrap(), *t);
        let o2: i64 = o2.parse().unwrap();
        assert!(o2 >= 0, "track {t} is {o2} with --assign-all");
        if *o >= 0 {
            assert_eq!(o2, *o, "track {t}");
        }
    }
    assert_eq!(
        std::fs::read_to_string(out.join("notes.txt")).unwrap(),
        "mine"
    );
    // No temporary file is left behind.
    let temps = std::fs::read_dir(&out)
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .file_name()
                .to_string_lossy()
                .contains("rank3-tmp")
        })
        .count();
    assert_eq!(temps, 0);
    // A count of 0 is refused by the argument parser.
    let err = run_err(
        bin()
            .args(["reconstruct"])
            .arg(&input)
            .arg("--out")
            .arg(&out)
            .args(["--objects", "0"]),
    );
    assert!(err.contains("neither `auto` nor a count"), "{err}");
}

/// An output that is one of the inputs is refused before anything is opened: the input
/// survives byte for byte (`--rrd INPUT` used to delete it), and so does a frame in the
/// input folder of `track`.
#[test]
fn outputs_never_overwrite_inputs() {
    let d = tmp("inputs-survive");
    let input = d.join("t.csv");
    let text = "frame,track,x,y\n0,0,1,2\n0,1,3,4\n1,0,1.5,2\n1,1,3.5,4\n";
    std::fs::write(&input, text).unwrap();
    for args in [
        vec![
            "--out",
            d.join("r").to_str().unwrap(),
            "--rrd",
            input.to_str().unwrap(),
        ],
        vec!["--out", input.to_str().unwrap()],
    ] {
        let err = run_err(bin().arg("reconstruct").arg(&input).args(&args));
        assert!(err.contains("would overwrite the input"), "{err}");
        assert_eq!(std::fs::read_to_string(&input).unwrap(), text);
    }
    let frames = d.join("frames");
    std::fs::create_dir_all(&frames).unwrap();
    let frame = frames.join("000.png");
    std::fs::write(&frame, b"not really a png").unwrap();
    let err = run_err(
        bin()
            .arg("track")
            .arg(&frames)
            .arg("--out")
            .arg(d.join("t2.csv"))
            .arg("--rrd")
            .arg(&frame),
    );
    assert!(err.contains("would overwrite the input"), "{err}");
    assert_eq!(std::fs::read(&frame).unwrap(), b"not really a png");
}

/// `rank3 … | head` with the reader gone before rank3 prints: no panic, a normal exit.
#[test]
fn closed_stdout_is_not_a_panic() {
    let d = tmp("closed-stdout");
    let mut child = bin()
        .args(["synth", "--frames", "5", "--points", "12", "--out"])
        .arg(&d)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take()); // close the pipe's read end
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("panicked"), "{err}");
    assert!(out.status.success(), "{err}");
}

/// `track` on frames with nothing to track (blank) is an error that says why, not an empty
/// table and exit 0.
#[test]
fn track_with_no_trackable_point_is_an_error() {
    let d = tmp("blank-frames");
    let frames = d.join("frames");
    std::fs::create_dir_all(&frames).unwrap();
    for k in 0..3 {
        image::GrayImage::new(64, 48)
            .save(frames.join(format!("{k:03}.png")))
            .unwrap();
    }
    let err = run_err(
        bin()
            .arg("track")
            .arg(&frames)
            .arg("--out")
            .arg(d.join("t.csv")),
    );
    assert!(
        err.contains("no point could be tracked in its 3 frame(s)"),
        "{err}"
    );
    assert!(!d.join("t.csv").exists());
}

/// A run that fails on bad input does not destroy an existing recording: the input is read
/// (or the frames opened) before `--rrd` replaces the file.
#[cfg(feature = "rerun")]
#[test]
fn bad_input_leaves_an_existing_recording_alone() {
    let d = tmp("keep-rrd");
    let rrd = d.join("old.rrd");
    std::fs::write(&rrd, b"an earlier recording").unwrap();
    let bad = d.join("bad.csv");
    std::fs::write(&bad, "frame,track,x,y\n0,0,1,oops\n").unwrap();
    let err = run_err(
        bin()
            .arg("reconstruct")
            .arg(&bad)
            .arg("--out")
            .arg(d.join("out"))
            .arg("--rrd")
            .arg(&rrd),
    );
    assert!(err.contains("bad.csv:2"), "{err}");
    assert_eq!(std::fs::read(&rrd).unwrap(), b"an earlier recording");
    for cmd in ["run", "track"] {
        let out = if cmd == "run" {
            d.join("o")
        } else {
            d.join("t.csv")
        };
        run_err(
            bin()
                .arg(cmd)
                .arg(d.join("no-such-folder"))
                .arg("--out")
                .arg(out)
                .arg("--rrd")
                .arg(&rrd),
        );
        assert_eq!(
            std::fs::read(&rrd).unwrap(),
            b"an earlier recording",
            "{cmd}"
        );
    }
}

/// Inputs whose dense structures would not fit are typed errors or fallbacks, never aborts:
/// a sparse table whose dense F×N form is far larger than its observations, a frame whose
/// header declares 400 megapixels, an absurd tracker window, an oversized synthetic scene;
/// a tall table (2000 frames × 8 tracks) runs with ALS instead of the dense Wiberg solver and
/// without the dense refinement, saying so.
#[test]
fn oversized_inputs_are_refused_or_degrade_gracefully() {
    let d = tmp("budget");
    // 20 000 frames × 20 000 tracks, 5 observations per track (the dense table: 6.8 GB).
    let mut csv = String::from("frame,track,x,y\n");
    for p in 0..20_000usize {
        for k in 0..5 {
            let f = (p + 3 * k) % 20_000;
            csv.push_str(&format!("{f},{p},{}.5,{}.5\n", k * 10, p % 400));
        }
    }
    let sparse = d.join("sparse.csv");
    std::fs::write(&sparse, csv).unwrap();
    // Run under a 2 GiB address-space limit: the dense table alone would be 6.8 GB, so
    // this fails (allocation abort) unless the table is read and fitted sparsely.
    let mut cmd = bin();
    cmd.arg("reconstruct")
        .arg(&sparse)
        .arg("--out")
        .arg(d.join("o1"));
    unsafe {
        use std::os::unix::process::CommandExt;
        cmd.pre_exec(|| {
            let lim = libc::rlimit {
                rlim_cur: 2 << 30,
                rlim_max: 2 << 30,
            };
            if libc::setrlimit(libc::RLIMIT_AS, &lim) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    let err = run_err(&mut cmd);
    // The table goes to the sparse pipeline, which names why these tracks (no rigid
    // scene) cannot be factorized.
    assert!(
        err.contains("20000 frames × 20000 tracks") && err.contains("degenerate input"),
        "{err}"
    );

    // A PNG whose header declares 20 000 × 20 000 pixels (and holds almost no data).
    let mut ihdr = b"IHDR".to_vec();
    ihdr.extend_from_slice(&20_000u32.to_be_bytes());
    ihdr.extend_from_slice(&20_000u32.to_be_bytes());
    ihdr.extend_from_slice(&[8, 0, 0, 0, 0]);
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    png.extend_from_slice(&13u32.to_be_bytes());
    png.extend_from_slice(&ihdr);
    png.extend_from_slice(&common::crc32(&ihdr).to_be_bytes());
    // A start of image data (the decoder reads the header up to it) and the end marker.
    for (kind, data) in [
        (&b"IDAT"[..], &[0x78u8, 0x9c, 0x03, 0x00][..]),
        (&b"IEND"[..], &[][..]),
    ] {
        let mut chunk = kind.to_vec();
        chunk.extend_from_slice(data);
        png.extend_from_slice(&(data.len() as u32).to_be_bytes());
        png.extend_from_slice(&chunk);
        png.extend_from_slice(&common::crc32(&chunk).to_be_bytes());
    }
    let frames = d.join("frames");
    std::fs::create_dir_all(&frames).unwrap();
    std::fs::write(frames.join("000.png"), &png).unwrap();
    let err = run_err(
        bin()
            .arg("track")
            .arg(&frames)
            .arg("--out")
            .arg(d.join("t.csv")),
    );
    assert!(
        err.contains("20000 × 20000") && err.contains("megapixels"),
        "{err}"
    );

    let err = run_err(
        bin()
            .arg("track")
            .arg(&frames)
            .arg("--out")
            .arg(d.join("t.csv"))
            .args(["--window", "100001"]),
    );
    assert!(err.contains("klt.window"), "{err}");

    let scene = d.join("huge-synth");
    let err = run_err(
        bin()
            .args(["synth", "--frames", "100000", "--points", "100000", "--out"])
            .arg(&scene),
    );
    assert!(err.contains("GiB"), "{err}");
    assert!(!scene.exists(), "synth left a folder behind");

    // Tall: 2000 frames × 8 tracks, a fifth of the entries missing.
    let mut csv = String::from("frame,track,x,y\n");
    let pts: Vec<[f64; 3]> = (0..8)
        .map(|p| {
            let t = p as f64;
            [(t * 1.3).sin(), (t * 2.1).cos(), (t * 0.7).sin() * 0.8]
        })
        .collect();
    for f in 0..2000usize {
        let a = (-30.0 + 60.0 * f as f64 / 1999.0f64).to_radians();
        for (p, x) in pts.iter().enumerate() {
            if f > 2 && (f * 7 + p * 3) % 5 == 0 {
                continue;
            }
            let u = 200.0 * (a.cos() * x[0] + a.sin() * x[2]) + 320.0;
            let v = 200.0 * x[1] + 240.0;
            csv.push_str(&format!("{f},{p},{u:.4},{v:.4}\n"));
        }
    }
    let tall = d.join("tall.csv");
    std::fs::write(&tall, csv).unwrap();
    let out = d.join("o2");
    let log = run_ok(
        bin()
            .arg("reconstruct")
            .arg(&tall)
            .arg("--out")
            .arg(&out)
            .args(["--camera", "orthographic"]),
    );
    assert!(log.contains("als ran instead of wiberg"), "{log}");
    // The dense refinement's 12 000 × 12 000 camera matrix would be over the budget: the
    // sparse engine refines instead (memory linear in the observations), nothing skipped.
    assert!(!log.contains("refinement was skipped"), "{log}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("reconstruction.json")).unwrap())
            .unwrap();
    assert_eq!(json["completion"]["solver"], "als");
    assert_eq!(
        json["refinement"]["status"], "converged",
        "{}",
        json["refinement"]
    );
    assert!(json["refinement"]["skipped"].is_null());
    assert!(
        json["rms_px"].as_f64().unwrap() < 0.01,
        "{}",
        json["rms_px"]
    );
}

/// Runs `cmd`: exit code, stdout, stderr.
fn outputs(cmd: &mut std::process::Command) -> (Option<i32>, String, String) {
    let out = cmd.output().unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// `-q` prints nothing on a clean success (warnings and errors only), before or after the
/// subcommand; `-v` prints more than the default; errors print at every level (exit 1);
/// `eval`'s scores are its output and stay on stdout with `-q`.
#[test]
fn quiet_and_verbose_output_levels() {
    let d = tmp("verbosity");
    let (code, out, err) = outputs(
        bin()
            .args(["synth", "-q", "--frames", "10", "--points", "40", "--out"])
            .arg(&d),
    );
    assert_eq!(code, Some(0), "{err}");
    assert_eq!((out.as_str(), err.as_str()), ("", ""));
    assert!(d.join("tracks.csv").exists() && d.join("truth.json").exists());
    let reconstruct = |level: Option<&str>, out: &str| {
        let mut cmd = bin();
        cmd.args(level)
            .arg("reconstruct")
            .arg(d.join("tracks.csv"))
            .arg("--out")
            .arg(d.join(out))
            .args(["--camera", "scaled-orthographic"]);
        outputs(&mut cmd)
    };
    let (code, out, err) = reconstruct(Some("-q"), "quiet");
    assert_eq!(code, Some(0), "{err}");
    assert_eq!((out.as_str(), err.as_str()), ("", ""));
    assert!(d.join("quiet/reconstruction.json").exists());
    let (code, out, normal) = reconstruct(None, "normal");
    assert_eq!(code, Some(0), "{normal}");
    assert!(
        out.contains("scaled-orthographic camera, 10 frames"),
        "{out}"
    );
    assert!(normal.contains("singular values") && !normal.contains("time per stage"));
    let (code, out_v, verbose) = reconstruct(Some("--verbose"), "verbose");
    assert_eq!(code, Some(0), "{verbose}");
    assert_eq!(out_v.replace("verbose", "normal"), out);
    assert!(
        verbose.lines().count() > normal.lines().count() + 3,
        "default:\n{normal}\n-v:\n{verbose}"
    );
    for line in normal.lines() {
        assert!(verbose.contains(line.split(" (").next().unwrap()), "{line}");
    }
    for detail in [
        "settings: camera scaled-orthographic",
        "time per stage (s): ",
        "wrote ",
    ] {
        assert!(verbose.contains(detail), "{detail}:\n{verbose}");
    }

    // Errors print with -q, exit 1.
    let bad = d.join("bad.csv");
    std::fs::write(&bad, "frame,track,x,y\n0,0,1.0,oops\n").unwrap();
    let (code, out, err) = outputs(
        bin()
            .args(["reconstruct", "-q"])
            .arg(&bad)
            .arg("--out")
            .arg(d.join("o")),
    );
    assert_eq!(code, Some(1));
    assert_eq!(out, "");
    assert!(
        err.starts_with("error: ") && err.contains("bad.csv:2"),
        "{err}"
    );

    // eval's table is its output: printed with -q too.
    let (code, table, err) = outputs(
        bin()
            .args(["-q", "eval"])
            .arg(d.join("quiet"))
            .arg("-r")
            .arg(d.join("truth.json")),
    );
    assert_eq!(code, Some(0), "{err}");
    assert_eq!(err, "");
    assert!(!table.is_empty());
    // -q and -v together are a usage error.
    let (code, _, err) = outputs(bin().args(["-q", "-v", "synth", "--out"]).arg(&d));
    assert_eq!(code, Some(2));
    assert!(
        err.contains("--quiet") && err.contains("--verbose"),
        "{err}"
    );
}

/// Options that would do nothing in the combination given are refused as usage errors
/// (exit 2) saying why, before any work.
#[test]
fn options_that_do_nothing_are_refused() {
    let d = tmp("inert-options");
    let points = d.join("points.txt");
    std::fs::write(&points, "10 10\n20 20\n").unwrap();
    let table = d.join("t.csv");
    std::fs::write(&table, "frame,track,x,y\n0,0,1,2\n").unwrap();
    let out = d.join("out");
    let cases: Vec<(Vec<std::ffi::OsString>, &str)> = vec![
        // Re-detection is always on without --init-points.
        (
            vec![
                "track".into(),
                d.clone().into(),
                "--out".into(),
                d.join("t2.csv").into(),
                "--redetect".into(),
            ],
            "--init-points",
        ),
        // Nothing is detected with --init-points alone.
        (
            vec![
                "track".into(),
                d.clone().into(),
                "--out".into(),
                d.join("t2.csv").into(),
                "--init-points".into(),
                points.clone().into(),
                "--quality".into(),
                "0.1".into(),
            ],
            "add --redetect",
        ),
        (
            vec![
                "reconstruct".into(),
                table.clone().into(),
                "--out".into(),
                out.clone().into(),
                "--camera".into(),
                "orthographic".into(),
                "--focal".into(),
                "800".into(),
            ],
            "--focal is an option of the perspective camera",
        ),
        (
            vec![
                "reconstruct".into(),
                table.clone().into(),
                "--out".into(),
                out.clone().into(),
                "--no-mesh".into(),
            ],
            "--no-mesh does nothing without --images",
        ),
        (
            vec![
                "reconstruct".into(),
                table.clone().into(),
                "--out".into(),
                out.clone().into(),
                "--no-robust".into(),
                "--threshold".into(),
                "2".into(),
            ],
            "--no-robust",
        ),
        (
            vec![
                "synth".into(),
                "--out".into(),
                out.clone().into(),
                "--distance".into(),
                "3".into(),
            ],
            "add --camera perspective",
        ),
    ];
    for (args, says) in cases {
        let (code, _, err) = outputs(bin().args(&args));
        assert_eq!(code, Some(2), "{args:?}: {err}");
        assert!(err.contains(says), "{args:?}: {err}");
    }
    assert!(!out.exists(), "a refused command wrote {}", out.display());
}

/// `--stream`: the complete tracks of a CSV read in passes (here 5 blocks of 10 tracks),
/// the same reconstruction as one block, the usual files, `eval` reads them; the options
/// it cannot honour are refused.
#[test]
fn stream_reads_a_csv_in_passes() {
    let d = tmp("stream");
    run_ok(bin().args(["synth", "--out"]).arg(&d).args([
        "--frames",
        "12",
        "--points",
        "50",
        "--noise",
        "0.5",
        "--camera",
        "scaled-orthographic",
        "--seed",
        "4",
    ]));
    let tracks = d.join("tracks.csv");
    let json_of = |out: &Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(out.join("reconstruction.json")).unwrap())
            .unwrap()
    };
    // 2K: 2048 / (2F · 8 bytes) = 10 tracks per block.
    let (one, many) = (d.join("one"), d.join("many"));
    let log = run_ok(
        bin()
            .args(["reconstruct", "--stream"])
            .arg(&tracks)
            .arg("--out")
            .arg(&one),
    );
    assert!(log.contains("1 pass(es) over the file"), "{log}");
    run_ok(
        bin()
            .args(["reconstruct", "--stream", "--memory", "2K"])
            .arg(&tracks)
            .arg("--out")
            .arg(&many),
    );
    let (a, b) = (json_of(&one), json_of(&many));
    assert_eq!(b["stream"]["blocks"], 5);
    // The counting pass, five Gram passes, one structure pass.
    assert_eq!(b["stream"]["passes"], 7);
    assert_eq!(a["camera_model"], "scaled-orthographic");
    let (ra, rb) = (a["rms_px"].as_f64().unwrap(), b["rms_px"].as_f64().unwrap());
    assert!((ra - rb).abs() < 1e-9 && ra < 0.6, "{ra} vs {rb}");
    assert_eq!(b["points"].as_array().unwrap().len(), 50);
    for f in ["completed.txt", "points.ply"] {
        assert!(many.join(f).exists(), "{f}");
    }
    let scores = run_ok(
        bin()
            .arg("eval")
            .arg(&many)
            .arg("--reference")
            .arg(d.join("truth.json")),
    );
    assert!(scores.contains("structure"), "{scores}");
    // Refused: a camera it does not fit, a format it does not stream.
    let err = run_err(
        bin()
            .args(["reconstruct", "--stream", "--camera", "perspective"])
            .arg(&tracks)
            .arg("--out")
            .arg(d.join("p")),
    );
    assert!(err.contains("affine cameras"), "{err}");
    std::fs::write(d.join("t.txt"), "1 2\n3 4\n").unwrap();
    let err = run_err(
        bin()
            .args(["reconstruct", "--stream"])
            .arg(d.join("t.txt"))
            .arg("--out")
            .arg(d.join("q")),
    );
    assert!(err.contains("long CSV format"), "{err}");
}
