//! The `rank3` binary end to end: synth → reconstruct → output files, and bad input.

use std::path::{Path, PathBuf};
use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_rank3"))
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("rank3-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn run_ok(cmd: &mut Command) -> String {
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr)
}

fn run_err(cmd: &mut Command) -> String {
    let out = cmd.output().unwrap();
    assert!(!out.status.success());
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Reads a binary little-endian PLY with float x, y, z (+ uchar inlier) vertices.
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
    let body = &bytes[end..];
    assert_eq!(body.len(), n * 13);
    (0..n)
        .map(|i| {
            let f = |k: usize| {
                f32::from_le_bytes(body[i * 13 + 4 * k..i * 13 + 4 * k + 4].try_into().unwrap())
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
