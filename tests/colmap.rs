//! A COLMAP text model written by rank3 is read back by COLMAP itself (pycolmap), and every
//! camera, pose, keypoint and 3D point comes back as written.
//!
//! The keypoints are exact projections of the 3D points through COLMAP's own camera models,
//! so pycolmap's recomputed reprojection errors are zero only if the pose convention
//! (world-to-camera, Hamilton quaternion), the parameter order and the keypoint / track
//! bookkeeping all agree with COLMAP's.
//!
//! The Python is `$RANK3_PYTHON`, else `python3`; the test is skipped (and passes) with a
//! message when it cannot `import pycolmap` (`pip install pycolmap`; `.ci/run` installs it).

use std::path::{Path, PathBuf};
use std::process::Command;

use nalgebra::{Matrix3, Rotation3, Unit, Vector3};
use rank3::colmap::{ColmapCamera, ColmapCameraModel, ColmapImage, ColmapModel, ColmapPoint};
use serde_json::Value;

/// Prints what pycolmap read, as JSON.
const SCRIPT: &str = r#"
import json, sys
import pycolmap

rec = pycolmap.Reconstruction(sys.argv[1])

def pose(img):
    cfw = img.cam_from_world() if callable(img.cam_from_world) else img.cam_from_world
    return cfw

def model_name(cam):
    name = getattr(cam, "model_name", None)
    return name if isinstance(name, str) else cam.model.name

out = {
    "version": pycolmap.__version__,
    "num_cameras": rec.num_cameras(),
    "num_images": rec.num_images(),
    "num_points3D": rec.num_points3D(),
    "cameras": {},
    "images": {},
    "points": {},
}
for cid, cam in rec.cameras.items():
    out["cameras"][str(cid)] = {
        "model": model_name(cam),
        "width": int(cam.width),
        "height": int(cam.height),
        "params": [float(v) for v in cam.params],
    }
for iid, img in rec.images.items():
    cfw = pose(img)
    out["images"][str(iid)] = {
        "name": img.name,
        "camera_id": int(img.camera_id),
        "rotation": [[float(v) for v in row] for row in cfw.rotation.matrix()],
        "translation": [float(v) for v in cfw.translation],
        "points2d": [
            [float(p.xy[0]), float(p.xy[1]), int(p.point3D_id) if p.has_point3D() else -1]
            for p in img.points2D
        ],
    }
for pid, pt in rec.points3D.items():
    out["points"][str(pid)] = {
        "xyz": [float(v) for v in pt.xyz],
        "rgb": [int(v) for v in pt.color],
        "error": float(pt.error),
        "track_length": int(pt.track.length()),
        "track": [[int(e.image_id), int(e.point2D_idx)] for e in pt.track.elements],
    }
try:
    out["mean_reprojection_error_as_read"] = rec.compute_mean_reprojection_error()
except Exception as e:
    out["mean_reprojection_error_as_read"] = None
# Recompute every observation's reprojection error from the poses and intrinsics.
worst = 0.0
for iid, img in rec.images.items():
    for p in img.points2D:
        if p.has_point3D():
            uv = img.project_point(rec.points3D[p.point3D_id].xyz)
            worst = max(worst, float(((uv[0] - p.xy[0]) ** 2 + (uv[1] - p.xy[1]) ** 2) ** 0.5))
out["max_reprojection_error"] = worst
rec.update_point_3d_errors()
out["mean_reprojection_error_recomputed"] = rec.compute_mean_reprojection_error()
print(json.dumps(out))
"#;

/// A Python that can `import pycolmap`, or `None` with a message saying the test is skipped.
fn python_with_pycolmap() -> Option<String> {
    let python = std::env::var("RANK3_PYTHON").unwrap_or_else(|_| "python3".into());
    let ok = Command::new(&python)
        .args(["-c", "import pycolmap"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        eprintln!(
            "SKIPPED: `{python}` cannot import pycolmap (pip install pycolmap, or set \
             RANK3_PYTHON to a Python that has it)"
        );
        return None;
    }
    Some(python)
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("rank3-colmap-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// COLMAP's projection (`ImgFromCam`) of a point in camera coordinates.
fn project(model: &ColmapCameraModel, x_cam: &Vector3<f64>) -> [f64; 2] {
    let (u, v) = (x_cam.x / x_cam.z, x_cam.y / x_cam.z);
    match *model {
        ColmapCameraModel::SimplePinhole { f, cx, cy } => [f * u + cx, f * v + cy],
        ColmapCameraModel::Pinhole { fx, fy, cx, cy } => [fx * u + cx, fy * v + cy],
        ColmapCameraModel::SimpleRadial { f, cx, cy, k } => {
            let radial = 1.0 + k * (u * u + v * v);
            [f * u * radial + cx, f * v * radial + cy]
        }
        ColmapCameraModel::Opencv {
            fx,
            fy,
            cx,
            cy,
            k1,
            k2,
            p1,
            p2,
        } => {
            let r2 = u * u + v * v;
            let radial = 1.0 + k1 * r2 + k2 * r2 * r2;
            let du = radial * u + 2.0 * p1 * u * v + p2 * (r2 + 2.0 * u * u);
            let dv = radial * v + p1 * (r2 + 2.0 * v * v) + 2.0 * p2 * u * v;
            [fx * du + cx, fy * dv + cy]
        }
    }
}

/// Three cameras (one per model; camera 4 shared by two images), four cameras on an arc
/// looking at eight points, every point seen in every image, plus one keypoint per image
/// without a 3D point (the second keypoint, so track indices are not trivially aligned).
fn model() -> ColmapModel {
    let cameras = vec![
        ColmapCamera {
            id: 4,
            model: ColmapCameraModel::SimpleRadial {
                f: 812.5,
                cx: 400.5,
                cy: 300.5,
                k: -0.05,
            },
            width: 800,
            height: 600,
        },
        ColmapCamera {
            id: 2,
            model: ColmapCameraModel::SimplePinhole {
                f: 700.0,
                cx: 320.0,
                cy: 240.0,
            },
            width: 640,
            height: 480,
        },
        ColmapCamera {
            id: 9,
            model: ColmapCameraModel::Pinhole {
                fx: 1000.25,
                fy: 990.75,
                cx: 512.5,
                cy: 384.5,
            },
            width: 1024,
            height: 768,
        },
    ];
    let xyz: Vec<[f64; 3]> = (0..8)
        .map(|i| {
            let i = i as f64;
            [
                (i * 1.3).sin(),
                0.5 * (i * 0.7).cos() - 0.2,
                0.3 * (i * 2.1).sin(),
            ]
        })
        .collect();
    let point_ids: Vec<u64> = (0..8).map(|i| 100 + 7 * i).collect();
    let image_ids = [3u32, 1, 8, 2];
    let camera_of = [4u32, 2, 9, 4];
    let mut images = Vec::new();
    for (j, (&id, &camera_id)) in image_ids.iter().zip(&camera_of).enumerate() {
        // Camera centre on an arc of radius 5 around the origin, looking at it.
        let a = -0.6 + 0.4 * j as f64;
        let centre = Vector3::new(5.0 * a.sin(), 0.3 * j as f64 - 0.4, -5.0 * a.cos());
        let look = Rotation3::face_towards(&(-centre), &Vector3::new(0.0, -1.0, 0.0));
        // face_towards maps camera +z to the viewing direction: that is camera-to-world.
        let tilt = Rotation3::from_axis_angle(&Unit::new_normalize(Vector3::z()), 0.1 * j as f64);
        let r: Matrix3<f64> = (look * tilt).inverse().into_inner();
        let t = -r * centre;
        let model = &cameras.iter().find(|c| c.id == camera_id).unwrap().model;
        let mut points2d = Vec::new();
        for (k, p) in xyz.iter().enumerate() {
            let x_cam = r * Vector3::from(*p) + t;
            assert!(x_cam.z > 1.0, "point {k} behind image {id}");
            points2d.push((project(model, &x_cam), Some(point_ids[k])));
            if k == 0 {
                points2d.push(([12.25, 34.5], None));
            }
        }
        images.push(ColmapImage {
            id,
            camera_id,
            name: format!("images/frame_{id:04}.jpg"),
            rotation: r,
            translation: t,
            points2d,
        });
    }
    let points = (0..8)
        .map(|k| ColmapPoint {
            id: point_ids[k],
            xyz: xyz[k],
            rgb: [k as u8 * 30, 255 - k as u8, 7],
            error: 0.125 * (k + 1) as f64,
            track: image_ids
                .iter()
                .map(|&im| (im, if k == 0 { 0 } else { k + 1 }))
                .collect(),
        })
        .collect();
    ColmapModel {
        cameras,
        images,
        points,
    }
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1.0)
}

fn num(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

fn assert_close(what: &str, got: &Value, want: &[f64]) {
    let got: Vec<f64> = got
        .as_array()
        .unwrap_or_else(|| panic!("{what}: not an array: {got}"))
        .iter()
        .map(num)
        .collect();
    assert_eq!(got.len(), want.len(), "{what}: {got:?} vs {want:?}");
    for (g, w) in got.iter().zip(want) {
        assert!(
            close(*g, *w),
            "{what}: pycolmap read {got:?}, rank3 wrote {want:?}"
        );
    }
}

fn read_with_pycolmap(python: &str, dir: &Path) -> Value {
    let out = Command::new(python)
        .args(["-c", SCRIPT])
        .arg(dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "pycolmap could not read the model:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "pycolmap printed no JSON ({e}):\n{}",
            String::from_utf8_lossy(&out.stdout)
        )
    })
}

#[test]
fn pycolmap_reads_the_model_back() {
    let Some(python) = python_with_pycolmap() else {
        return;
    };
    let dir = tmp("pycolmap");
    let m = model();
    m.write_text(&dir).unwrap();
    let got = read_with_pycolmap(&python, &dir);
    std::fs::remove_dir_all(&dir).ok();

    let n_obs: usize = m.points.iter().map(|p| p.track.len()).sum();
    println!(
        "pycolmap {} read {} cameras, {} images, {} 3D points ({n_obs} observations); mean \
         reprojection error as read {}, recomputed {}; largest reprojection error {:e} px",
        got["version"],
        got["num_cameras"],
        got["num_images"],
        got["num_points3D"],
        got["mean_reprojection_error_as_read"],
        got["mean_reprojection_error_recomputed"],
        num(&got["max_reprojection_error"]),
    );
    assert_eq!(got["num_cameras"], m.cameras.len());
    assert_eq!(got["num_images"], m.images.len());
    assert_eq!(got["num_points3D"], m.points.len());

    for c in &m.cameras {
        let g = &got["cameras"][c.id.to_string()];
        assert_eq!(g["model"], c.model.name(), "camera {}", c.id);
        assert_eq!(
            (g["width"].as_u64(), g["height"].as_u64()),
            (Some(c.width.into()), Some(c.height.into()))
        );
        assert_close(
            &format!("camera {} params", c.id),
            &g["params"],
            &c.model.params(),
        );
    }
    for im in &m.images {
        let g = &got["images"][im.id.to_string()];
        assert_eq!(g["name"], im.name.as_str());
        assert_eq!(g["camera_id"], im.camera_id);
        for row in 0..3 {
            let want: Vec<f64> = (0..3).map(|c| im.rotation[(row, c)]).collect();
            assert_close(
                &format!("image {} R row {row}", im.id),
                &g["rotation"][row],
                &want,
            );
        }
        assert_close(
            &format!("image {} t", im.id),
            &g["translation"],
            im.translation.as_slice(),
        );
        let kps = g["points2d"].as_array().unwrap();
        assert_eq!(kps.len(), im.points2d.len(), "image {} keypoints", im.id);
        for (k, (kp, (xy, owner))) in kps.iter().zip(&im.points2d).enumerate() {
            let kp = kp.as_array().unwrap();
            let xy_read = Value::Array(kp[..2].to_vec());
            assert_close(&format!("image {} keypoint {k}", im.id), &xy_read, xy);
            let want = owner.map_or(-1, |p| p as i64);
            assert_eq!(kp[2].as_i64(), Some(want), "image {} keypoint {k}", im.id);
        }
    }
    for p in &m.points {
        let g = &got["points"][p.id.to_string()];
        assert_close(&format!("point {} xyz", p.id), &g["xyz"], &p.xyz);
        assert_eq!(g["rgb"], serde_json::json!(p.rgb));
        assert!(close(num(&g["error"]), p.error), "point {} error", p.id);
        assert_eq!(g["track_length"], p.track.len());
        assert_eq!(g["track"], serde_json::json!(p.track));
    }

    // The stored ERRORs come back; recomputed from poses and intrinsics they vanish.
    let stored_mean = m.points.iter().map(|p| p.error).sum::<f64>() / m.points.len() as f64;
    if let Some(e) = got["mean_reprojection_error_as_read"].as_f64() {
        assert!(
            close(e, stored_mean),
            "mean error as read {e}, written {stored_mean}"
        );
    }
    let worst = num(&got["max_reprojection_error"]);
    assert!(worst < 1e-9, "largest reprojection error {worst:e} px");
    let recomputed = num(&got["mean_reprojection_error_recomputed"]);
    assert!(
        recomputed < 1e-9,
        "recomputed mean reprojection error {recomputed:e} px"
    );
}

/// The pipeline's perspective result exported as a COLMAP model: our reader reads back what
/// was written, and pycolmap, projecting our points through our cameras with its own
/// formulas, reproduces the keypoints of a noise-free scene (which checks the pose, the
/// intrinsics and the half-pixel shift together).
#[test]
fn perspective_reconstruction_exports_to_colmap() {
    use rank3::synth::{Shape, SynthConfig, generate};
    use rank3::{CameraModel, Config, Reconstruction};
    let s = generate(&SynthConfig {
        camera: CameraModel::Perspective,
        shape: Shape::House,
        frames: 10,
        points: 50,
        noise: 0.0,
        missing: 0.3,
        distance: 2.5,
        seed: 7,
        ..SynthConfig::default()
    })
    .unwrap();
    let mut cfg = Config {
        camera: CameraModel::Perspective,
        ..Config::default()
    };
    cfg.perspective.intrinsics.image_size = Some([641, 481]);
    let rec = Reconstruction::from_tracks(&s.table, &cfg).unwrap();
    let m = rank3::output::colmap_model(&rec, &s.table).expect("a perspective result");
    assert_eq!(m.cameras.len(), 1);
    assert_eq!(m.images.len(), rec.kept_frames.len());
    let n_obs: usize = m.images.iter().map(|i| i.points2d.len()).sum();
    assert_eq!(
        n_obs,
        s.table.n_observed(),
        "every observation is a keypoint"
    );
    let dir = tmp("pipeline");
    m.write_text(&dir).unwrap();
    let back = ColmapModel::read_text(&dir).unwrap();
    assert!(
        back.cameras == m.cameras && back.points == m.points,
        "cameras or points differ"
    );
    assert_eq!(back.images.len(), m.images.len());
    for (a, b) in back.images.iter().zip(&m.images) {
        assert!(a.points2d == b.points2d && a.name == b.name && a.translation == b.translation);
        assert!(
            (a.rotation - b.rotation).norm() < 1e-14,
            "image {} rotation",
            a.id
        );
    }
    if let Some(python) = python_with_pycolmap() {
        let got = read_with_pycolmap(&python, &dir);
        println!(
            "pycolmap: {} images, {} points, recomputed mean reprojection error {:e} px",
            got["num_images"],
            got["num_points3D"],
            num(&got["mean_reprojection_error_recomputed"])
        );
        assert_eq!(got["num_points3D"], m.points.len());
        assert!(num(&got["max_reprojection_error"]) < 1e-6);
    }
    std::fs::remove_dir_all(&dir).ok();
}
