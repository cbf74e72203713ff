//! The perspective camera's optional models against a synthetic truth: per-frame focal
//! lengths on a zooming camera (`SynthConfig::zoom`), the radial coefficient `k₁`
//! (`SynthConfig::distortion`), and the robust losses of the metric adjustment. The
//! figures behind the tolerances: `cargo run --release --example perspective_models`
//! (docs/results.md, § Perspective camera).

use nalgebra::Vector3;
use rank3::eval::align_similarity;
use rank3::perspective::{Loss, PerspectiveConfig, PerspectiveModel, adjust};
use rank3::synth::{Shape, SynthConfig, SynthScene, generate};
use rank3::{CameraModel, Config, NoopObserver, Reconstruction};

fn scene(zoom: f64, distortion: f64, noise: f64, seed: u64) -> SynthScene {
    generate(&SynthConfig {
        camera: CameraModel::Perspective,
        shape: Shape::House,
        frames: 14,
        points: 60,
        noise,
        distance: 2.5,
        zoom,
        distortion,
        seed,
        ..SynthConfig::default()
    })
    .unwrap()
}

/// The perspective camera, image size given (principal point = the synthetic one), no
/// robust pass unless asked.
fn config(per_frame_focal: bool, distortion: bool) -> Config {
    let mut perspective = PerspectiveConfig {
        per_frame_focal,
        distortion,
        ..PerspectiveConfig::default()
    };
    perspective.intrinsics.image_size = Some([641, 481]);
    Config {
        camera: CameraModel::Perspective,
        robust: None,
        perspective,
        ..Config::default()
    }
}

/// Per frame `|f − f_true| / f_true`, and the structure error (RMS point distance after the
/// best proper similarity, over the true spread).
fn errors(
    model: &PerspectiveModel,
    frames: &[usize],
    tracks: &[usize],
    s: &SynthScene,
) -> (Vec<f64>, f64) {
    let truth = s.perspective.as_ref().unwrap();
    let focal = frames
        .iter()
        .enumerate()
        .map(|(k, &f)| {
            let t = truth.intrinsics[f][(0, 0)];
            (model.focal_px[k] - t).abs() / t
        })
        .collect();
    let tp: Vec<Vector3<f64>> = tracks.iter().map(|&p| s.truth.points[p]).collect();
    let structure = align_similarity(&model.points, &tp, false)
        .unwrap()
        .relative_rms;
    (focal, structure)
}

fn run(s: &SynthScene, cfg: &Config) -> (Reconstruction, Vec<f64>, f64) {
    let rec = Reconstruction::from_tracks(&s.table, cfg).unwrap();
    let p = rec.perspective.as_ref().expect("perspective result");
    let (focal, structure) = errors(&p.model, &rec.kept_frames, &rec.kept_tracks, s);
    (rec, focal, structure)
}

/// The adjustment started at the truth (the accuracy floor of the data), all entries.
fn floor(s: &SynthScene, pc: &PerspectiveConfig) -> (Vec<f64>, f64) {
    let t = s.perspective.as_ref().unwrap();
    let start = PerspectiveModel {
        focal_px: t.intrinsics.iter().map(|k| k[(0, 0)]).collect(),
        principal_point: [t.intrinsics[0][(0, 2)], t.intrinsics[0][(1, 2)]],
        k1: t.k1,
        aspect: 1.0,
        rotations: t.rotations.iter().map(|r| *r.matrix()).collect(),
        translations: t.translations.clone(),
        points: s.truth.points.clone(),
    };
    let fit = adjust(&s.table.measurements(), &start, pc, 0, &mut NoopObserver).unwrap();
    let frames: Vec<usize> = (0..s.table.n_frames()).collect();
    let tracks: Vec<usize> = (0..s.table.n_tracks()).collect();
    errors(&fit.model, &frames, &tracks, s)
}

fn max(v: &[f64]) -> f64 {
    v.iter().copied().fold(0.0, f64::max)
}

#[test]
fn noise_free_zooming_scene_recovers_every_focal_length() {
    // The focal length grows by half over the sequence (500 → 750 px).
    let s = scene(0.5, 0.0, 0.0, 3);
    let (rec, focal, structure) = run(&s, &config(true, false));
    assert_eq!(rec.kept_frames.len(), 14);
    assert!(max(&focal) < 1e-6, "per-frame focal errors {focal:?}");
    assert!(structure < 1e-6, "structure {structure}");
    assert!(rec.rms_px < 1e-6, "RMS {}", rec.rms_px);
    // One shared focal length cannot explain the zoom: measured 47 % largest focal error and
    // an RMS of 1.5 px on this scene.
    let (rec, focal, _) = run(&s, &config(false, false));
    eprintln!(
        "zoom, shared focal: max focal error {:.3} %, RMS {:.3} px",
        100.0 * max(&focal),
        rec.rms_px
    );
    assert!(max(&focal) > 0.1, "{focal:?}");
    assert!(rec.rms_px > 0.5, "RMS {}", rec.rms_px);
}

#[test]
fn noise_free_distorted_scene_recovers_k1_and_the_focal_length() {
    let k1 = -0.2;
    let s = scene(0.0, k1, 0.0, 4);
    let (rec, focal, structure) = run(&s, &config(false, true));
    let p = rec.perspective.as_ref().unwrap();
    assert!((p.model.k1 - k1).abs() < 1e-6, "k1 {}", p.model.k1);
    assert!(max(&focal) < 1e-6, "focal {focal:?}");
    assert!(structure < 1e-6, "structure {structure}");
    // Without the k₁ estimate the same scene is fitted at the distortion's cost (measured:
    // RMS 0.36 px, focal length 1.6 % off).
    let (rec, focal, _) = run(&s, &config(false, false));
    eprintln!(
        "k1 not estimated: max focal error {:.3} %, RMS {:.3} px",
        100.0 * max(&focal),
        rec.rms_px
    );
    assert!(rec.rms_px > 0.05, "RMS {}", rec.rms_px);
    assert!(max(&focal) > 1e-3, "{focal:?}");
}

/// With 0.5 px noise the pipeline's per-frame focal lengths are as good as the data allow.
/// Measured (`perspective_models zoom`, 20 frames × 100 tracks, complete, 5 seeds): the
/// pipeline reaches the floor's optimum to the printed digits (zoom 0.5: median focal error
/// 0.24 %, largest over the frames 0.54 %). On these smaller scenes (14 × 60) the floor's
/// largest per-frame error is 0.73 % (seed 1) and 0.51 % (seed 2), and the pipeline equals
/// it. The test allows the pipeline 1.5× the floor plus 0.1 % — the noise moves both alike,
/// a different optimum (a start that ends elsewhere, one frame's focal length running off:
/// 21 % on the frame the robust pass thinned, docs/results.md) does not pass — and the floor
/// itself 2 %.
#[test]
fn noisy_zooming_scene_is_at_the_floor() {
    for seed in [1, 2] {
        let s = scene(0.5, 0.0, 0.5, seed);
        let cfg = config(true, false);
        let (rec, focal, structure) = run(&s, &cfg);
        let (floor_focal, floor_structure) = floor(&s, &cfg.perspective);
        eprintln!(
            "seed {seed}: max focal error {:.3} % (floor {:.3} %), structure {:.3} % (floor {:.3} %)",
            100.0 * max(&focal),
            100.0 * max(&floor_focal),
            100.0 * structure,
            100.0 * floor_structure
        );
        assert!(
            max(&focal) <= 1.5 * max(&floor_focal) + 1e-3,
            "seed {seed}: focal errors {focal:?} vs floor {floor_focal:?}"
        );
        assert!(
            max(&floor_focal) < 0.02,
            "seed {seed}: floor {floor_focal:?}"
        );
        assert!(
            structure <= 1.5 * floor_structure + 1e-3,
            "seed {seed}: structure {structure} vs floor {floor_structure}"
        );
        assert!(rec.rms_px < 0.6, "seed {seed}: RMS {}", rec.rms_px);
    }
}

/// Gross entries (5 %, 15–60 px) with the robust pass off: least squares is pulled off by
/// them, the Cauchy loss reaches the structure of the clean data. Measured
/// (`perspective_models loss`, 20 × 100, 5 seeds): least squares 3.2 % structure error,
/// Cauchy 0.25 %, the floor 0.25 %; on this 14 × 60 scene Cauchy 0.36 %, least squares
/// 3.6 %.
#[test]
fn cauchy_loss_discounts_gross_entries_without_the_robust_pass() {
    let s = generate(&SynthConfig {
        camera: CameraModel::Perspective,
        shape: Shape::House,
        frames: 14,
        points: 60,
        noise: 0.5,
        distance: 2.5,
        gross: 0.05,
        seed: 5,
        ..SynthConfig::default()
    })
    .unwrap();
    let mut cfg = config(false, false);
    cfg.perspective.loss = Loss::Cauchy(2.0);
    let (_, _, cauchy) = run(&s, &cfg);
    cfg.perspective.loss = Loss::Squared;
    let (_, _, squares) = run(&s, &cfg);
    eprintln!(
        "structure: Cauchy {:.3} %, least squares {:.3} %",
        100.0 * cauchy,
        100.0 * squares
    );
    assert!(cauchy < 0.01, "Cauchy structure {cauchy}");
    assert!(
        squares > 2.0 * cauchy,
        "least squares {squares} vs Cauchy {cauchy}"
    );
}

/// The house at 2.5 radii, 20 frames × 100 tracks, 0.5 px noise: the scenes of
/// `perspective_models` (`base` there), with a zoom, missing data and a seed.
fn house_20x100(zoom: f64, missing: f64, seed: u64) -> SynthScene {
    generate(&SynthConfig {
        camera: CameraModel::Perspective,
        shape: Shape::House,
        frames: 20,
        points: 100,
        noise: 0.5,
        distance: 2.5,
        zoom,
        missing,
        seed,
        ..SynthConfig::default()
    })
    .unwrap()
}

/// Strong perspective with 30 % missing (seed 14, house, 20 × 100): the affine robust pass
/// rejects 45 tracks that only perspective explains and leaves the last frame with 5, too
/// few for a projective camera. `--camera auto` used to keep the affine model of half the
/// tracks (structure error 87 %); now the projective model judges every track and the
/// perspective camera is chosen (0.45 % median over seeds 0–19, docs/results.md).
#[test]
fn auto_survives_an_affine_selection_that_starves_a_frame() {
    let s = house_20x100(0.0, 0.3, 14);
    let mut cfg = Config {
        camera: CameraModel::Auto,
        ..Config::default()
    };
    cfg.perspective.intrinsics.image_size = Some([641, 481]);
    let rec = Reconstruction::from_tracks(&s.table, &cfg).unwrap();
    assert_eq!(
        rec.camera_model,
        CameraModel::Perspective,
        "{:?}",
        rec.warnings
    );
    let p = rec.perspective.as_ref().unwrap();
    let truth: Vec<Vector3<f64>> = p
        .points
        .iter()
        .filter(|q| q.inlier)
        .map(|q| {
            let p = s
                .table
                .track_ids()
                .iter()
                .position(|t| t == &q.track)
                .unwrap();
            s.truth.points[p]
        })
        .collect();
    let est: Vec<Vector3<f64>> = p
        .points
        .iter()
        .filter(|q| q.inlier)
        .map(|q| Vector3::from(q.xyz))
        .collect();
    let e = align_similarity(&est, &truth, false).unwrap().relative_rms;
    assert!(e < 0.01, "structure error {:.3} %", 100.0 * e);
}

/// A zooming camera with 30 % missing (zoom 0.5, seed 1, house, 20 × 100, per-frame focal
/// lengths, robust pass on): the last frame is seen by about 20 tracks, and the affine
/// robust pass flags 7 of its entries that only perspective explains. Its camera, fitted
/// without them, extrapolates, so they looked far off and stayed flagged, and the frame's
/// focal length ended 21 % off. The projective verdict now re-estimates the camera of a
/// frame with flagged entries from all of them (resection) and clears the flags that
/// camera agrees with: every frame's focal length is at the floor (0.69 % max, floor
/// 0.74 %; `perspective_models zoom`).
#[test]
fn verdict_rejudges_flags_of_a_sparsely_seen_zooming_frame() {
    let s = house_20x100(0.5, 0.3, 1);
    let mut cfg = config(true, false);
    cfg.robust = Config::default().robust;
    let (rec, focal, structure) = run(&s, &cfg);
    let last = *rec.kept_frames.last().unwrap();
    let robust = rec.robust.as_ref().unwrap();
    let in_last = robust
        .flagged_indices
        .iter()
        .filter(|&&(f, _)| f == last)
        .count();
    assert_eq!(
        in_last, 0,
        "flagged in the last frame: {:?}",
        robust.flagged_indices
    );
    assert!(
        max(&focal) < 0.02,
        "largest focal error {:.3} %",
        100.0 * max(&focal)
    );
    assert!(
        structure < 0.01,
        "structure error {:.3} %",
        100.0 * structure
    );
}
