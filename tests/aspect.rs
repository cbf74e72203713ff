//! Non-square pixels: a known aspect ratio (`Config::aspect_ratio`) for every camera model,
//! and the aspect ratio estimated by the perspective bundle adjustment
//! (`PerspectiveConfig::estimate_aspect_ratio`), on noise-free scenes whose image x axis is
//! squeezed by 0.8 (a 4:3 picture digitised at 512×480).

use rank3::colmap::ColmapCameraModel;
use rank3::eval::align_similarity;
use rank3::perspective::{Intrinsics, PerspectiveConfig};
use rank3::synth::{Shape, SynthConfig, SynthScene, generate};
use rank3::{CameraModel, Config, Reconstruction};

const ASPECT: f64 = 0.8;

fn scene(camera: CameraModel, missing: f64, seed: u64) -> SynthScene {
    let mut s = generate(&SynthConfig {
        camera,
        shape: Shape::House,
        frames: 14,
        points: 60,
        noise: 0.0,
        missing,
        distance: 2.5,
        seed,
        ..SynthConfig::default()
    })
    .unwrap();
    s.table.scale([ASPECT, 1.0]);
    s
}

/// Relative RMS structure error of `points` (the kept tracks') against the truth, after the
/// best similarity (with a reflection when `mirror`: the affine depth reversal).
fn structure_error(
    points: &[nalgebra::Vector3<f64>],
    rec: &Reconstruction,
    s: &SynthScene,
    mirror: bool,
) -> f64 {
    let truth: Vec<_> = rec.kept_tracks.iter().map(|&p| s.truth.points[p]).collect();
    align_similarity(points, &truth, mirror)
        .expect("alignment")
        .relative_rms
}

/// Largest distance between the model's prediction and the observation, input pixels.
fn prediction_error(rec: &Reconstruction, s: &SynthScene) -> f64 {
    let m = rec.completed_matrix();
    let mut worst: f64 = 0.0;
    for f in 0..s.table.n_frames() {
        for p in 0..s.table.n_tracks() {
            if let Some([x, y]) = s.table.get(f, p) {
                worst = worst
                    .max((m[(2 * f, p)] - x).abs())
                    .max((m[(2 * f + 1, p)] - y).abs());
            }
        }
    }
    worst
}

#[test]
fn a_known_aspect_ratio_recovers_the_affine_structure() {
    for missing in [0.0, 0.3] {
        let s = scene(CameraModel::ScaledOrthographic, missing, 3);
        let cfg = |aspect| Config {
            camera: CameraModel::ScaledOrthographic,
            robust: None,
            aspect_ratio: aspect,
            ..Config::default()
        };
        let rec = Reconstruction::from_tracks(&s.table, &cfg(Some(ASPECT))).unwrap();
        assert_eq!(rec.aspect_ratio, ASPECT);
        assert!(rec.rms_px < 1e-7, "missing {missing}: RMS {}", rec.rms_px);
        let e = structure_error(&rec.model.points, &rec, &s, true);
        assert!(e < 1e-7, "missing {missing}: structure error {e}");
        // Predictions are in the input's (squeezed) pixels.
        let d = prediction_error(&rec, &s);
        assert!(d < 1e-6, "missing {missing}: prediction off by {d} px");
        // Square pixels assumed: the fit is no longer exact and the structure is bent.
        let square = Reconstruction::from_tracks(&s.table, &cfg(None)).unwrap();
        let e1 = structure_error(&square.model.points, &square, &s, true);
        assert!(
            e1 > 100.0 * e.max(1e-6),
            "square pixels: structure error {e1}"
        );
    }
}

fn perspective_config(s: &SynthScene, aspect: Option<f64>, estimate: bool) -> Config {
    let k = s.perspective.as_ref().unwrap().intrinsics[0];
    Config {
        camera: CameraModel::Perspective,
        robust: None,
        aspect_ratio: aspect,
        perspective: PerspectiveConfig {
            intrinsics: Intrinsics {
                // The principal point of the squeezed images.
                principal_point: Some([ASPECT * k[(0, 2)], k[(1, 2)]]),
                ..Intrinsics::default()
            },
            estimate_aspect_ratio: estimate,
            ..PerspectiveConfig::default()
        },
        ..Config::default()
    }
}

#[test]
fn the_perspective_camera_takes_a_known_aspect_ratio_or_estimates_it() {
    for (missing, seed) in [(0.0, 1), (0.3, 2)] {
        let s = scene(CameraModel::Perspective, missing, seed);
        let f_true = s.perspective.as_ref().unwrap().intrinsics[0][(1, 1)];
        for (aspect, estimate, source) in
            [(Some(ASPECT), false, "given"), (None, true, "estimated")]
        {
            let what = format!("missing {missing}, {source}");
            let rec =
                Reconstruction::from_tracks(&s.table, &perspective_config(&s, aspect, estimate))
                    .unwrap();
            let per = rec.perspective.as_ref().expect("perspective result");
            let k = &per.intrinsics;
            assert_eq!(k.aspect_ratio_source, source, "{what}");
            assert!(
                (k.aspect_ratio - ASPECT).abs() < 1e-6,
                "{what}: aspect {}",
                k.aspect_ratio
            );
            assert!(
                ((k.focal_px - f_true) / f_true).abs() < 1e-6,
                "{what}: focal {}",
                k.focal_px
            );
            assert!(
                (k.k[0][0] - ASPECT * f_true).abs() < 1e-6 * f_true,
                "{what}: K {:?}",
                k.k
            );
            assert!(rec.rms_px < 1e-6, "{what}: RMS {}", rec.rms_px);
            let e = structure_error(&per.model.points, &rec, &s, false);
            assert!(e < 1e-6, "{what}: structure error {e}");
            let d = prediction_error(&rec, &s);
            assert!(d < 1e-5, "{what}: prediction off by {d} px");
            // The COLMAP export has focal lengths fx = aspect · fy.
            let colmap = rank3::output::colmap_model(&rec, &s.table).expect("a COLMAP model");
            match colmap.cameras[0].model {
                ColmapCameraModel::Pinhole { fx, fy, .. } => {
                    assert!((fx - ASPECT * fy).abs() < 1e-9 * fy, "{what}: {fx} vs {fy}")
                }
                ref m => panic!("{what}: COLMAP camera {m:?}"),
            }
        }
    }
}

mod common;

/// A small gray PNG at `path` whose `pHYs` chunk states `ppu` pixels per metre along x and y.
fn png_with_phys(path: &std::path::Path, ppu: [u32; 2]) {
    let mut png = Vec::new();
    image::GrayImage::from_fn(32, 24, |x, y| image::Luma([((x * 7 + y * 13) % 255) as u8]))
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
    let mut chunk = b"pHYs".to_vec();
    chunk.extend(ppu[0].to_be_bytes());
    chunk.extend(ppu[1].to_be_bytes());
    chunk.push(1);
    let mut bytes = png[..33].to_vec(); // signature (8) + IHDR (25)
    bytes.extend(9u32.to_be_bytes());
    bytes.extend(&chunk);
    bytes.extend(common::crc32(&chunk).to_be_bytes());
    bytes.extend(&png[33..]);
    std::fs::write(path, bytes).unwrap();
}

/// Where the CLI takes the aspect ratio from when `--aspect-ratio` is not given: the frames'
/// PNG `pHYs` chunk (`reconstruct --images`), the frame size of digitised analogue video
/// (`--image-size 512,480`), else square pixels; `--aspect-ratio` overrides both. A scene
/// squeezed by 0.8 is fitted exactly only under the right ratio.
#[test]
fn cli_takes_the_aspect_ratio_from_the_frames() {
    let d = common::tmp_dir("aspect", "cli");
    common::run_ok(common::bin().arg("synth").arg("--out").arg(&d).args([
        "--frames",
        "12",
        "--points",
        "60",
        "--noise",
        "0",
        "--camera",
        "scaled-orthographic",
        // A turntable (one rotation axis) cannot tell the squeeze from the scene's shape.
        "--motion",
        "handheld-arc",
    ]));
    // The x coordinates squeezed by 0.8 (a 4:3 picture digitised at 512×480).
    let text = std::fs::read_to_string(d.join("tracks.csv")).unwrap();
    let mut squeezed = String::new();
    for (k, line) in text.lines().enumerate() {
        if k == 0 || line.starts_with('#') {
            squeezed += line;
        } else {
            let v: Vec<&str> = line.split(',').collect();
            let x: f64 = v[2].parse().unwrap();
            squeezed += &format!("{},{},{},{}", v[0], v[1], ASPECT * x, v[3]);
        }
        squeezed.push('\n');
    }
    let tracks = d.join("squeezed.csv");
    std::fs::write(&tracks, squeezed).unwrap();
    let frames = d.join("frames");
    std::fs::create_dir_all(&frames).unwrap();
    for k in 0..12 {
        png_with_phys(&frames.join(format!("{k:03}.png")), [4000, 5000]);
    }
    let fit = |name: &str, extra: &[&str]| -> serde_json::Value {
        let out = d.join(name);
        common::run_ok(
            common::bin()
                .arg("reconstruct")
                .arg(&tracks)
                .arg("--out")
                .arg(&out)
                .args(["--camera", "scaled-orthographic", "--no-robust"])
                .args(extra),
        );
        serde_json::from_str(&std::fs::read_to_string(out.join("reconstruction.json")).unwrap())
            .unwrap()
    };
    let images = frames.to_str().unwrap();
    for (name, extra, ratio, source, exact) in [
        (
            "phys",
            vec!["--images", images, "--no-mesh"],
            0.8,
            "pHYs chunk: 4000×5000 pixels per metre",
            true,
        ),
        (
            "size",
            vec!["--image-size", "512,480"],
            0.8,
            "512×480 frame size",
            true,
        ),
        (
            "given",
            vec!["--image-size", "512,480", "--aspect-ratio", "1"],
            1.0,
            "given",
            false,
        ),
        (
            "square",
            vec!["--image-size", "640,480"],
            1.0,
            "square pixels",
            false,
        ),
    ] {
        let json = fit(name, &extra);
        let got = json["aspect_ratio"].as_f64().unwrap();
        assert!((got - ratio).abs() < 1e-12, "{name}: aspect ratio {got}");
        let src = json["aspect_ratio_source"].as_str().unwrap();
        assert!(src.contains(source), "{name}: source {src:?}");
        let rms = json["rms_px"].as_f64().unwrap();
        if exact {
            assert!(rms < 1e-6, "{name}: RMS {rms} px under the right ratio");
        } else {
            assert!(rms > 1e-3, "{name}: RMS {rms} px under square pixels");
        }
    }
}
