//! The textured mesh end to end: `rank3 run` on rendered frames of a textured 3D corner
//! writes mesh.obj/.mtl/_texture.png, mesh.glb and a coloured points.ply that a real reader
//! (trimesh) loads with faces, texture coordinates and the texture image; `reconstruct
//! --images` builds the same; `--no-mesh` and `--ply-inliers-only` do what they say.
//!
//! The reader is `$RANK3_PYTHON` (else `python3`) with `trimesh` and `Pillow`; without them
//! that part is skipped with a message (`.ci/run` installs both).

use std::path::{Path, PathBuf};
use std::process::Command;

use nalgebra::Vector3;
use rank3::tracking::scene3d::{Scene3d, arc_cameras, write_frames};

mod common;
use common::{bin, run_ok};

fn tmp(name: &str) -> PathBuf {
    common::tmp_dir("mesh", name)
}

/// `rank3 reconstruct TRACKS --out OUT --camera orthographic` plus `extra`.
fn reconstruct(tracks: &Path, out: &Path, extra: &[&std::ffi::OsStr]) -> String {
    run_ok(
        bin()
            .arg("reconstruct")
            .arg(tracks)
            .arg("--out")
            .arg(out)
            .args(["--camera", "orthographic"])
            .args(extra),
    )
}

/// Ten 320×240 frames of the textured corner seen along a ±20° arc.
fn frames(dir: &Path) {
    let size = [320, 240];
    let cams = arc_cameras(
        10,
        5.0,
        20.0,
        0.6,
        Vector3::new(0.0, 0.0, -0.7),
        300.0,
        size,
    );
    write_frames(&Scene3d::corner(false), &cams, size, dir).unwrap();
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn ply_header(path: &Path) -> String {
    let bytes = std::fs::read(path).unwrap();
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap();
    String::from_utf8_lossy(&bytes[..end]).into_owned()
}

fn ply_vertices(path: &Path) -> usize {
    ply_header(path)
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .unwrap()
        .parse()
        .unwrap()
}

const READER: &str = r#"
import json, sys
import numpy as np
import trimesh
out = {}
obj = trimesh.load(sys.argv[1] + "/mesh.obj", force="mesh")
out["obj_faces"] = int(len(obj.faces))
out["obj_uv"] = list(np.asarray(obj.visual.uv).shape)
out["obj_texture"] = list(obj.visual.material.image.size)
glb = trimesh.load(sys.argv[1] + "/mesh.glb")
g = list(glb.geometry.values())[0]
out["glb_faces"] = int(len(g.faces))
out["glb_uv"] = list(np.asarray(g.visual.uv).shape)
out["glb_texture"] = list(g.visual.material.baseColorTexture.size)
ply = trimesh.load(sys.argv[1] + "/points.ply")
c = np.asarray(ply.colors)
out["ply_points"] = int(len(ply.vertices))
out["ply_distinct_colours"] = int(len(np.unique(c[:, :3], axis=0)))
print(json.dumps(out))
"#;

/// A Python that can import trimesh and Pillow, or `None` with a message.
fn python_with_trimesh() -> Option<String> {
    let python = std::env::var("RANK3_PYTHON").unwrap_or_else(|_| "python3".into());
    let ok = Command::new(&python)
        .args(["-c", "import trimesh, PIL"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        eprintln!(
            "SKIPPED: `{python}` cannot import trimesh and PIL (pip install trimesh pillow, or \
             set RANK3_PYTHON to a Python that has them)"
        );
        return None;
    }
    Some(python)
}

#[test]
fn run_writes_a_textured_mesh_that_a_real_reader_loads() {
    let d = tmp("run");
    let imgs = d.join("frames");
    frames(&imgs);
    let out = d.join("out");
    let log = run_ok(bin().arg("run").arg(&imgs).arg("--out").arg(&out));
    assert!(log.contains("mesh: "), "{log}");
    for f in [
        "mesh.obj",
        "mesh.mtl",
        "mesh_texture.png",
        "mesh.glb",
        "points.ply",
    ] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    let rec = json(&out.join("reconstruction.json"));
    let mesh = &rec["mesh"];
    let triangles = mesh["surface"]["triangles"].as_u64().unwrap() as usize;
    assert!(triangles > 100, "{triangles} triangles: {mesh}");
    assert_eq!(mesh["texture"]["frames_matched"], 10);
    assert_eq!(mesh["texture"]["frames_matched_by"], "id");
    assert!(ply_header(&out.join("points.ply")).contains("property uchar red"));
    // The two walls are textured mostly from views within 5° of their most frontal one.
    assert!(mesh["texture"]["share_near_most_frontal"].as_f64().unwrap() > 0.8);

    let Some(python) = python_with_trimesh() else {
        return;
    };
    let o = Command::new(&python)
        .args(["-c", READER])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let atlas = &mesh["texture"]["atlas_px"];
    assert_eq!(r["obj_faces"], triangles);
    assert_eq!(r["glb_faces"], triangles);
    assert_eq!(r["obj_uv"][1], 2);
    assert_eq!(r["glb_uv"][1], 2);
    assert_eq!(r["obj_texture"], *atlas);
    assert_eq!(r["glb_texture"], *atlas);
    let points = rec["perspective"]["points"]
        .as_array()
        .or(rec["points"].as_array())
        .unwrap()
        .len();
    assert_eq!(r["ply_points"], points);
    assert!(r["ply_distinct_colours"].as_u64().unwrap() > 20, "{r}");
}

#[test]
fn reconstruct_with_images_meshes_and_the_mesh_options_work() {
    let d = tmp("reconstruct");
    let imgs = d.join("frames");
    frames(&imgs);
    let tracks = d.join("tracks.csv");
    run_ok(bin().arg("track").arg(&imgs).arg("--out").arg(&tracks));
    let out = d.join("out");
    let images = [std::ffi::OsStr::new("--images"), imgs.as_os_str()];
    reconstruct(&tracks, &out, &images);
    let rec = json(&out.join("reconstruction.json"));
    assert!(rec["mesh"]["surface"]["triangles"].as_u64().unwrap() > 100);
    for f in ["mesh.obj", "mesh.mtl", "mesh_texture.png", "mesh.glb"] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    // Without the frames, no mesh: the earlier run's mesh files go (a folder's outputs
    // belong to one run).
    reconstruct(&tracks, &out, &[]);
    for f in ["mesh.obj", "mesh.mtl", "mesh_texture.png", "mesh.glb"] {
        assert!(!out.join(f).exists(), "stale {f}");
    }
    assert!(json(&out.join("reconstruction.json"))["mesh"].is_null());
    assert!(!ply_header(&out.join("points.ply")).contains("red"));
    // --no-mesh keeps the colours out too; --ply-inliers-only drops the outliers' points.
    let options = ["--no-mesh", "--ply-inliers-only"].map(std::ffi::OsStr::new);
    reconstruct(&tracks, &out, &[&images[..], &options[..]].concat());
    assert!(!out.join("mesh.glb").exists());
    let rec = json(&out.join("reconstruction.json"));
    let inliers = rec["points"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|p| p["inlier"] == true)
        .count();
    assert_eq!(ply_vertices(&out.join("points.ply")), inliers);
    // Frames that are not the table's: matched by position, and what could not be textured
    // is said.
    let other = d.join("other");
    std::fs::create_dir_all(&other).unwrap();
    std::fs::copy(imgs.join("frame_000.png"), other.join("zzz.png")).unwrap();
    let o = bin()
        .arg("reconstruct")
        .arg(&tracks)
        .arg("--out")
        .arg(d.join("out2"))
        .arg("--images")
        .arg(&other)
        .args(["--camera", "orthographic"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    let rec = json(&d.join("out2").join("reconstruction.json"));
    assert_eq!(rec["mesh"]["texture"]["frames_matched_by"], "position");
    assert_eq!(rec["mesh"]["texture"]["frames_matched"], 1);
    if rec["mesh"]["texture"]["charts_unfilled"].as_u64().unwrap() > 0 {
        assert!(
            err.contains("come from frames that were not given"),
            "{err}"
        );
    }
}

/// Every camera model goes through the mesh's one projection abstraction: the scene built
/// from each reconstruction reprojects the fitted entries exactly as the model does (the same
/// RMS to 1 %; measured equal to 1e-12), and meshes without using an outlier track.
#[test]
fn every_camera_model_meshes_through_its_own_projection() {
    use rank3::synth::{OutlierKind, SynthConfig, generate};
    let scene = generate(&SynthConfig {
        camera: rank3::CameraModel::Perspective,
        frames: 10,
        points: 60,
        noise: 0.3,
        missing: 0.2,
        distance: 3.0,
        outliers: 0.05,
        outlier_kind: OutlierKind::RandomWalk,
        seed: 4,
        ..Default::default()
    })
    .unwrap();
    let table = &scene.table;
    for camera in [
        rank3::CameraModel::Orthographic,
        rank3::CameraModel::ScaledOrthographic,
        rank3::CameraModel::Projective,
        rank3::CameraModel::Perspective,
    ] {
        let config = rank3::Config {
            camera,
            ..Default::default()
        };
        let rec = rank3::Reconstruction::from_tracks(table, &config).unwrap();
        let s = rank3::mesh::Scene::from_reconstruction(&rec, table, None).unwrap();
        // Residuals of the fitted (inlier) tracks through the abstraction (whose observations
        // leave out the entries the robust pass flagged).
        let (mut ss, mut n) = (0.0, 0usize);
        for (f, obs) in s.observations.iter().enumerate() {
            for &(p, xy) in obs {
                if !s.inlier[p as usize] {
                    continue;
                }
                if let Some(q) = s.project(f, p as usize) {
                    ss += (q[0] - xy[0]).powi(2) + (q[1] - xy[1]).powi(2);
                    n += 2;
                }
            }
        }
        let rms = (ss / n as f64).sqrt();
        assert!(n > 200, "{camera:?}: {n} residuals");
        assert!(
            (rms - rec.rms_px).abs() <= 0.01 * rec.rms_px + 1e-9,
            "{camera:?}: RMS through the mesh scene {rms} vs the reconstruction's {}",
            rec.rms_px
        );
        let mesh = rank3::mesh::build(&s, &rank3::mesh::MeshConfig::default(), None).unwrap();
        assert!(mesh.triangles.len() > 20, "{camera:?}: {:?}", mesh.report);
        assert!(
            mesh.vertex_tracks.iter().all(|&p| s.inlier[p as usize]),
            "{camera:?}: an outlier track is a vertex"
        );
    }
}
