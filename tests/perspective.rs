//! The metric perspective camera end to end: self-calibration and metric bundle adjustment
//! on synthetic perspective scenes with truth, known intrinsics, and input errors.

use nalgebra::Vector3;
use rank3::eval::align_similarity;
use rank3::perspective::{Intrinsics, PerspectiveConfig};
use rank3::synth::{Shape, SynthConfig, SynthScene, generate};
use rank3::{CameraModel, Config, Error, Reconstruction};

fn scene(distance: f64, missing: f64, noise: f64, seed: u64) -> SynthScene {
    generate(&SynthConfig {
        camera: CameraModel::Perspective,
        shape: Shape::House,
        frames: 14,
        points: 60,
        noise,
        missing,
        distance,
        seed,
        ..SynthConfig::default()
    })
    .unwrap()
}

fn config(intrinsics: Intrinsics) -> Config {
    Config {
        camera: CameraModel::Perspective,
        robust: None,
        perspective: PerspectiveConfig {
            intrinsics,
            ..PerspectiveConfig::default()
        },
        ..Config::default()
    }
}

struct Errors {
    focal_rel: f64,
    structure_rel: f64,
    rotation_deg: f64,
    centre_rel: f64,
}

/// Errors of the perspective result against the truth, after a proper similarity alignment
/// of the points (the same similarity maps the camera centres).
fn errors(rec: &Reconstruction, s: &SynthScene) -> Errors {
    let truth = s.perspective.as_ref().unwrap();
    let per = rec.perspective.as_ref().expect("perspective result");
    let est: Vec<Vector3<f64>> = per.model.points.clone();
    let tp: Vec<Vector3<f64>> = rec.kept_tracks.iter().map(|&p| s.truth.points[p]).collect();
    let al = align_similarity(&est, &tp, false).expect("alignment");
    let f_true = truth.intrinsics[0][(0, 0)];
    let focal_rel = per
        .model
        .focal_px
        .iter()
        .map(|f| (f - f_true).abs() / f_true)
        .fold(0.0, f64::max);
    let mut rotation_deg: f64 = 0.0;
    let mut centre_err: f64 = 0.0;
    for (k, &f) in rec.kept_frames.iter().enumerate() {
        // R_est Aᵀ ≈ R_true (the world rotated by A = al.rotation).
        let r = per.model.rotations[k] * al.rotation.transpose();
        let d = r * truth.rotations[f].matrix().transpose();
        let ang = ((d.trace() - 1.0) / 2.0)
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees();
        rotation_deg = rotation_deg.max(ang);
        let c = al.scale * al.rotation * per.model.centre(k) + al.translation;
        centre_err = centre_err.max((c - truth.centre(f)).norm());
    }
    let dist = truth.translations[0].norm();
    Errors {
        focal_rel,
        structure_rel: al.relative_rms,
        rotation_deg,
        centre_rel: centre_err / dist,
    }
}

#[test]
fn noise_free_scene_recovers_k_r_t_and_x() {
    for (missing, seed) in [(0.0, 1), (0.3, 2)] {
        let s = scene(2.5, missing, 0.0, seed);
        let rec = Reconstruction::from_tracks(&s.table, &config(Intrinsics::default())).unwrap();
        assert_eq!(rec.camera_model, CameraModel::Perspective);
        let e = errors(&rec, &s);
        assert!(rec.rms_px < 1e-6, "missing {missing}: RMS {}", rec.rms_px);
        assert!(e.focal_rel < 1e-6, "focal error {}", e.focal_rel);
        assert!(
            e.structure_rel < 1e-6,
            "structure error {}",
            e.structure_rel
        );
        assert!(e.rotation_deg < 1e-5, "rotation error {}°", e.rotation_deg);
        assert!(e.centre_rel < 1e-6, "centre error {}", e.centre_rel);
    }
}

#[test]
fn known_and_self_calibrated_intrinsics_agree_on_noise_free_data() {
    let s = scene(3.0, 0.2, 0.0, 3);
    let f_true = s.perspective.as_ref().unwrap().intrinsics[0][(0, 0)];
    let known = Intrinsics {
        focal_px: Some(f_true),
        principal_point: Some([320.0, 240.0]),
        image_size: None,
    };
    let a = Reconstruction::from_tracks(&s.table, &config(known)).unwrap();
    let b = Reconstruction::from_tracks(&s.table, &config(Intrinsics::default())).unwrap();
    let (pa, pb) = (a.perspective.unwrap(), b.perspective.unwrap());
    assert_eq!(pa.intrinsics.focal, "given");
    assert_eq!(pb.intrinsics.focal, "shared");
    assert!((pb.intrinsics.focal_px - f_true).abs() < 1e-6 * f_true);
    let al = align_similarity(&pb.model.points, &pa.model.points, false).unwrap();
    assert!(al.relative_rms < 1e-6, "{}", al.relative_rms);
}

#[test]
fn noisy_scene_is_close_to_the_truth() {
    let s = scene(2.5, 0.3, 0.5, 4);
    // The synthetic images are 640×480 with the principal point at their centre.
    let k = Intrinsics {
        image_size: Some([640, 480]),
        ..Intrinsics::default()
    };
    let rec = Reconstruction::from_tracks(&s.table, &config(k)).unwrap();
    let e = errors(&rec, &s);
    eprintln!(
        "RMS {:.3} px, focal {:.4}, structure {:.4}, rotation {:.3}°, centre {:.4}",
        rec.rms_px, e.focal_rel, e.structure_rel, e.rotation_deg, e.centre_rel
    );
    // 0.5 px noise, 14 frames over a 90° turn at 2.5 radii: well-conditioned.
    assert!(rec.rms_px < 0.6, "RMS {}", rec.rms_px);
    assert!(e.focal_rel < 0.03, "focal error {}", e.focal_rel);
    assert!(
        e.structure_rel < 0.02,
        "structure error {}",
        e.structure_rel
    );
    assert!(e.rotation_deg < 1.0, "rotation error {}°", e.rotation_deg);
}

#[test]
fn bad_intrinsics_are_config_errors() {
    let s = scene(2.5, 0.0, 0.0, 5);
    for (k, field) in [
        (
            Intrinsics {
                focal_px: Some(-3.0),
                ..Intrinsics::default()
            },
            "focal",
        ),
        (
            Intrinsics {
                principal_point: Some([f64::NAN, 1.0]),
                ..Intrinsics::default()
            },
            "principal-point",
        ),
        (
            Intrinsics {
                image_size: Some([0, 480]),
                ..Intrinsics::default()
            },
            "image-size",
        ),
    ] {
        match Reconstruction::from_tracks(&s.table, &config(k)) {
            Err(Error::InvalidConfig { field: f, .. }) => assert_eq!(f, field),
            other => panic!("expected InvalidConfig {field}, got {other:?}"),
        }
    }
}

/// `CameraModel::Auto` keeps the perspective camera on strong-perspective scenes and an
/// affine one on affine scenes, and says why.
#[test]
fn auto_picks_perspective_only_when_the_data_show_it() {
    let strong = scene(2.0, 0.3, 0.5, 6);
    let affine = generate(&SynthConfig {
        camera: CameraModel::ScaledOrthographic,
        shape: Shape::House,
        frames: 14,
        points: 60,
        noise: 0.5,
        missing: 0.3,
        seed: 6,
        ..SynthConfig::default()
    })
    .unwrap();
    let cfg = Config {
        camera: CameraModel::Auto,
        ..Config::default()
    };
    let a = Reconstruction::from_tracks(&strong.table, &cfg).unwrap();
    let sel = a.model_selection.as_ref().unwrap();
    assert_eq!(a.camera_model, CameraModel::Perspective, "{}", sel.reason);
    assert!(sel.delta_chi2 > sel.threshold);
    assert!(a.perspective.is_some());
    let b = Reconstruction::from_tracks(&affine.table, &cfg).unwrap();
    let sel = b.model_selection.as_ref().unwrap();
    assert_eq!(
        b.camera_model,
        CameraModel::ScaledOrthographic,
        "{}",
        sel.reason
    );
    assert!(b.perspective.is_none() && b.projective.is_none());
}

/// With partial tracks σ4/σ3 comes from the largest complete block, so the rank warning of
/// the affine cameras can fire on a video-like table; strong perspective is far from rank 3.
#[test]
fn rank_diagnostic_is_defined_for_partial_tracks() {
    let s = scene(2.0, 0.3, 0.0, 8);
    assert!(!s.table.is_complete());
    let cfg = Config {
        camera: CameraModel::ScaledOrthographic,
        robust: None,
        ..Config::default()
    };
    let rec = Reconstruction::from_tracks(&s.table, &cfg).unwrap();
    assert!(rec.rank_ratio.is_finite(), "{}", rec.rank_ratio_source);
    assert!(rec.rank_ratio_source.contains("complete block"));
    assert!(rec.rank_ratio > 0.01, "σ4/σ3 = {}", rec.rank_ratio);
}

/// A frame with too few tracks for the projective stages (4 < 6) is kept by the automatic
/// choice, which then keeps the affine camera and says why, rather than setting it aside.
#[test]
fn auto_keeps_frames_the_projective_stages_cannot_use() {
    let mut s = generate(&SynthConfig {
        camera: CameraModel::ScaledOrthographic,
        frames: 8,
        points: 30,
        noise: 0.3,
        seed: 9,
        ..SynthConfig::default()
    })
    .unwrap();
    for p in 4..s.table.n_tracks() {
        s.table.unset(0, p);
    }
    let cfg = Config {
        camera: CameraModel::Auto,
        ..Config::default()
    };
    let rec = Reconstruction::from_tracks(&s.table, &cfg).unwrap();
    assert_eq!(rec.kept_frames.len(), 8, "{:?}", rec.set_aside);
    assert_eq!(rec.camera_model, CameraModel::ScaledOrthographic);
    assert!(
        rec.warnings.iter().any(|w| w.contains("not tried")),
        "{:?}",
        rec.warnings
    );
}

/// The long-sequence path (`perspective::fit_observations`: metric windows chained by
/// similarities, one sparse adjustment) on the strong-perspective corridor of
/// `synth::perspective_corridor`, the focal length self-calibrated.
fn long_fit(frames: usize, per_frame: usize, noise: f64) -> (f64, f64, f64) {
    long_fit_with(frames, per_frame, noise, PerspectiveConfig::default())
}

fn long_fit_with(
    frames: usize,
    per_frame: usize,
    noise: f64,
    mut cfg: PerspectiveConfig,
) -> (f64, f64, f64) {
    let (obs, truth) = rank3::synth::perspective_corridor(frames, per_frame, noise, 7);
    // The generator's principal point; the image size alone would put it at the centre of
    // the pixel grid, (319.5, 239.5).
    cfg.intrinsics.principal_point = Some([320.0, 240.0]);
    cfg.intrinsics.image_size = Some([640, 480]);
    let fit = rank3::perspective::fit_observations(
        &obs,
        frames,
        truth.len(),
        &cfg,
        &rank3::projective::ProjectiveConfig::default(),
        &rank3::projective::windowed::WindowConfig::default(),
        &mut rank3::NoopObserver,
    )
    .unwrap();
    let structure = align_similarity(&fit.model.points, &truth, false)
        .unwrap()
        .relative_rms;
    (fit.rms_px, fit.model.focal_px[0], structure)
}

#[test]
fn long_sequence_noise_free_is_recovered_exactly() {
    // 100 frames: four windows chained.
    let (rms, focal, structure) = long_fit(100, 40, 0.0);
    assert!(rms < 1e-6, "RMS {rms} px");
    assert!((focal - 500.0).abs() < 1e-5 * 500.0, "focal {focal} px");
    assert!(structure < 1e-6, "structure error {structure}");
}

/// Only two of the four windows estimate the focal length
/// (`PerspectiveConfig::focal_sample_windows`); the other two are fitted once with the
/// median held fixed, from their own starts: still exact.
#[test]
fn long_sequence_with_a_focal_sample_is_recovered_exactly() {
    let cfg = PerspectiveConfig {
        focal_sample_windows: 2,
        ..PerspectiveConfig::default()
    };
    let (rms, focal, structure) = long_fit_with(100, 40, 0.0, cfg);
    assert!(rms < 1e-6, "RMS {rms} px");
    assert!((focal - 500.0).abs() < 1e-5 * 500.0, "focal {focal} px");
    assert!(structure < 1e-6, "structure error {structure}");
}

#[test]
fn long_sequence_with_noise_is_at_the_noise_level() {
    // σ = 0.5 px: the RMS is the noise less the parameters' share, the focal length and
    // the structure within what 140 frames of 0.5 px tracks determine (1 000 frames of the
    // same corridor: 0.15 % and 0.11 %, docs/results.md).
    let (rms, focal, structure) = long_fit(140, 60, 0.5);
    assert!(rms > 0.4 && rms < 0.5, "RMS {rms} px");
    assert!((focal - 500.0).abs() < 0.03 * 500.0, "focal {focal} px");
    assert!(structure < 0.01, "structure error {structure}");
}

#[test]
fn long_sequence_input_errors_are_typed() {
    let (mut obs, truth) = rank3::synth::perspective_corridor(60, 30, 0.0, 1);
    let cfg = PerspectiveConfig::default();
    let run = |obs: &[rank3::projective::Observation], frames: usize| {
        rank3::perspective::fit_observations(
            obs,
            frames,
            truth.len(),
            &cfg,
            &rank3::projective::ProjectiveConfig::default(),
            &rank3::projective::windowed::WindowConfig::default(),
            &mut rank3::NoopObserver,
        )
    };
    // A frame index outside the table.
    assert!(matches!(run(&obs, 10), Err(Error::InvalidConfig { .. })));
    // A non-finite position.
    obs[3].xy[0] = f64::NAN;
    assert!(matches!(run(&obs, 60), Err(Error::Degenerate(_))));
}

/// `perspective::refine_observations` (the long path's sparse adjustment from a given
/// model): started near the truth of a noise-free corridor — every rotation turned by
/// ~0.6°, every point moved by ~1 % of its depth, the focal length 4 % off — it recovers
/// the exact cameras, focal length and points; a start of the wrong size is a typed error.
#[test]
fn a_long_sequence_is_refined_from_a_given_model() {
    use nalgebra::{Rotation3, Vector3};
    let frames = 80;
    let (obs, truth) = rank3::synth::perspective_corridor(frames, 40, 0.0, 3);
    let mut cfg = PerspectiveConfig::default();
    cfg.intrinsics.principal_point = Some([320.0, 240.0]);
    cfg.intrinsics.image_size = Some([640, 480]);
    let cams: Vec<_> = (0..frames)
        .map(rank3::synth::perspective_corridor_camera)
        .collect();
    let nudge = |k: usize| ((k as f64) * 0.7).sin();
    let start = rank3::perspective::PerspectiveModel {
        focal_px: vec![520.0],
        principal_point: [320.0, 240.0],
        k1: 0.0,
        aspect: 1.0,
        rotations: cams
            .iter()
            .enumerate()
            .map(|(f, (_, r, _))| {
                Rotation3::from_euler_angles(0.01 * nudge(f), 0.01 * nudge(f + 1), 0.0).matrix()
                    * r.matrix()
            })
            .collect(),
        translations: cams.iter().map(|(_, r, c)| -(r * c)).collect(),
        points: truth
            .iter()
            .enumerate()
            .map(|(p, x)| x + 0.05 * Vector3::new(nudge(p), nudge(p + 2), nudge(p + 5)))
            .collect(),
    };
    let fit = rank3::perspective::refine_observations(
        &obs,
        frames,
        truth.len(),
        &start,
        &cfg,
        &mut rank3::NoopObserver,
    )
    .unwrap();
    assert!(
        start_rms_is_large(&obs, &start),
        "the start must be off the data"
    );
    assert!(fit.rms_px < 1e-6, "RMS {} px", fit.rms_px);
    assert!(
        (fit.model.focal_px[0] - 500.0).abs() < 1e-5 * 500.0,
        "focal {} px",
        fit.model.focal_px[0]
    );
    let structure = align_similarity(&fit.model.points, &truth, false)
        .unwrap()
        .relative_rms;
    assert!(structure < 1e-6, "structure error {structure}");
    let mut short = start.clone();
    short.points.pop();
    assert!(matches!(
        rank3::perspective::refine_observations(
            &obs,
            frames,
            truth.len(),
            &short,
            &cfg,
            &mut rank3::NoopObserver,
        ),
        Err(Error::Dimension { .. })
    ));
}

/// Whether `model` reprojects `obs` at more than 1 px RMS.
fn start_rms_is_large(
    obs: &[rank3::projective::Observation],
    model: &rank3::perspective::PerspectiveModel,
) -> bool {
    let mut m = model.clone();
    m.focal_px = vec![model.focal_px[0]; model.rotations.len()];
    let sum: f64 = obs
        .iter()
        .map(|o| {
            let y = m.project_point(o.frame, &m.points[o.track]);
            (y[0] - o.xy[0]).powi(2) + (y[1] - o.xy[1]).powi(2)
        })
        .sum();
    (sum / (2 * obs.len()) as f64).sqrt() > 1.0
}

/// `PerspectiveConfig::accept_at_noise`: where the screened self-calibration is within the
/// noise of the projective fit, the six starts lifted from the affine model and the planar
/// start are neither built nor screened, and the adjustment ends at the optimum the full screening reaches;
/// where it is not (five screening iterations leave it at 1.2 px on the strong-perspective
/// scene, noise 0.5 px), every start is screened as before.
#[test]
fn an_accepted_self_calibration_ends_where_the_full_screening_does() {
    for (distance, missing, seed, accepted) in [
        (3.0, 0.0, 2, true),
        (3.0, 0.3, 3, true),
        (1.5, 0.0, 5, false),
    ] {
        let s = scene(distance, missing, 0.5, seed);
        let on = Reconstruction::from_tracks(&s.table, &config(Intrinsics::default())).unwrap();
        let mut full = config(Intrinsics::default());
        full.perspective.accept_at_noise = false;
        let off = Reconstruction::from_tracks(&s.table, &full).unwrap();
        let (pa, pb) = (on.perspective.unwrap(), off.perspective.unwrap());
        let case = format!("distance {distance}, missing {missing}, seed {seed}");
        // Self-calibration, 3 focal lengths × 2 mirror images of the affine model, the plane.
        assert_eq!(pb.starts.len(), 8, "{case}");
        if accepted {
            let kinds: Vec<&str> = pa.starts.iter().map(|r| r.kind).collect();
            assert_eq!(kinds, ["self-calibration"], "{case}");
            assert!(pa.starts[0].chosen, "{case}");
        } else {
            assert_eq!(pa.starts.len(), 8, "{case}");
        }
        assert!(
            (on.rms_px - off.rms_px).abs() <= 1e-9 * off.rms_px,
            "{case}: RMS {} with early acceptance, {} without",
            on.rms_px,
            off.rms_px
        );
        let al = align_similarity(&pa.model.points, &pb.model.points, false).unwrap();
        assert!(al.relative_rms < 1e-6, "{case}: {}", al.relative_rms);
    }
}

/// `PerspectiveConfig::screen_frames`: a long sequence's starts are screened on a subset
/// of frames spanning it (here 8 of 36, every start screened: strong perspective, early
/// acceptance off), and the chosen start, adjusted on the whole table, ends at the optimum
/// the whole table's screening reaches.
#[test]
fn starts_screened_on_a_subset_end_where_the_whole_tables_screening_does() {
    let s = generate(&SynthConfig {
        camera: CameraModel::Perspective,
        shape: Shape::House,
        frames: 36,
        points: 60,
        noise: 0.5,
        missing: 0.3,
        distance: 1.5,
        seed: 4,
        ..SynthConfig::default()
    })
    .unwrap();
    let run = |screen_frames: usize| {
        let mut c = config(Intrinsics::default());
        c.perspective.accept_at_noise = false;
        c.perspective.screen_frames = screen_frames;
        Reconstruction::from_tracks(&s.table, &c).unwrap()
    };
    let (sub, whole) = (run(8), run(0));
    let (ps, pw) = (
        sub.perspective.as_ref().unwrap(),
        whole.perspective.as_ref().unwrap(),
    );
    let (nf, np) = (whole.kept_frames.len(), whole.kept_tracks.len());
    assert_eq!(ps.starts.len(), 8);
    assert_eq!(pw.starts.len(), 8);
    for (a, b) in ps.starts.iter().zip(&pw.starts) {
        assert_eq!(
            (a.screen_frames, b.screen_frames, b.screen_tracks),
            (8, nf, np)
        );
        assert!(a.screen_tracks >= 7 && a.screen_tracks <= np, "{a:?}");
    }
    let chosen = |p: &rank3::reconstruction::PerspectiveResult| {
        let c = p.starts.iter().find(|r| r.chosen).unwrap();
        (c.kind, c.mirrored)
    };
    assert_eq!(chosen(ps), chosen(pw));
    assert!(
        (sub.rms_px - whole.rms_px).abs() <= 1e-7 * whole.rms_px,
        "RMS {} screened on the subset, {} on the whole table",
        sub.rms_px,
        whole.rms_px
    );
    let al = align_similarity(&ps.model.points, &pw.model.points, false).unwrap();
    assert!(al.relative_rms < 1e-5, "{}", al.relative_rms);
    let e = errors(&sub, &s);
    assert!(
        e.structure_rel < 0.02,
        "structure error {}",
        e.structure_rel
    );
}

/// A principal point freed on a short turntable (10 frames, image size unknown) can run out
/// of the picture along the direction in which it trades against the rotation. The estimate
/// is rejected then (COLMAP's rule for bogus cameras: the principal point outside the image
/// — here the observations' bounding box); the fit holds the bounding box's centre, says so,
/// and its focal length is closer to the truth than the rejected one's.
#[test]
fn an_implausible_principal_point_estimate_is_rejected() {
    let s = generate(&SynthConfig {
        camera: CameraModel::Perspective,
        frames: 10,
        points: 60,
        noise: 0.5,
        focal: Some(500.0),
        distance: 5.0,
        seed: 2,
        ..SynthConfig::default()
    })
    .unwrap();
    let cfg = Config {
        camera: CameraModel::Perspective,
        ..Config::default()
    };
    let rec = Reconstruction::from_tracks(&s.table, &cfg).unwrap();
    let per = rec.perspective.as_ref().expect("perspective result");
    let k = &per.intrinsics;
    let rejected = k
        .principal_point_rejected
        .as_ref()
        .expect("the freed principal point leaves the observations' bounding box");
    assert_eq!(k.principal_point_source, "track bounding box");
    assert!(rec.warnings.iter().any(|w| w.contains("was rejected")));
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for f in 0..s.table.n_frames() {
        for p in 0..s.table.n_tracks() {
            if let Some(v) = s.table.get(f, p) {
                for d in 0..2 {
                    lo[d] = lo[d].min(v[d]);
                    hi[d] = hi[d].max(v[d]);
                }
            }
        }
    }
    let inside = |c: [f64; 2]| (0..2).all(|d| c[d] >= lo[d] && c[d] <= hi[d]);
    assert!(!inside(rejected.principal_point), "{rejected:?}");
    assert!(inside(k.principal_point), "{:?}", k.principal_point);
    for d in 0..2 {
        assert!((k.principal_point[d] - (lo[d] + hi[d]) / 2.0).abs() < 1e-6);
    }
    // reconstruction.json carries the rejected estimate, and the typed reader keeps it.
    let dir = std::env::temp_dir().join(format!(
        "rank3_rejected_principal_point_{}",
        std::process::id()
    ));
    let written = rank3::output::write_all(&rec, &dir).unwrap();
    let file = rank3::reconstruction_file::read(&written.json).unwrap();
    let read = file.perspective.expect("perspective block").intrinsics;
    assert_eq!(read.principal_point_rejected.as_ref(), Some(rejected));
    assert_eq!(read.principal_point_source, "track bounding box");
    let _ = std::fs::remove_dir_all(&dir);
    let err = |f: f64| (f - 500.0).abs() / 500.0;
    assert!(
        err(k.focal_px) < err(rejected.focal_px) && err(k.focal_px) < 0.05,
        "focal {} px held, {} px rejected",
        k.focal_px,
        rejected.focal_px
    );
}

/// Points on one plane: the projective factorization and the absolute dual quadric are not
/// determined by them, and only the planar start (`perspective::planar`) reaches the
/// optimum. Noise-free, complete and with missing data, both motions: K, R, t and X
/// recovered, and the planar start is the one kept. With 0.5 px of noise it ends at the
/// noise level, where without it the same scene ends pixels off.
#[test]
fn a_planar_scene_recovers_k_r_t_and_x() {
    use rank3::synth::Motion;
    let plane = |motion, missing, noise, seed| {
        generate(&SynthConfig {
            camera: CameraModel::Perspective,
            shape: Shape::Plane,
            motion,
            frames: 14,
            points: 60,
            noise,
            missing,
            distance: 2.5,
            seed,
            ..SynthConfig::default()
        })
        .unwrap()
    };
    let mut cfg = config(Intrinsics::default());
    cfg.perspective.intrinsics.image_size = Some([641, 481]);
    for (motion, missing, seed) in [(Motion::Turntable, 0.0, 1), (Motion::HandheldArc, 0.3, 2)] {
        let s = plane(motion, missing, 0.0, seed);
        let rec = Reconstruction::from_tracks(&s.table, &cfg).unwrap();
        let e = errors(&rec, &s);
        let per = rec.perspective.as_ref().unwrap();
        let chosen: Vec<_> = per.starts.iter().filter(|st| st.chosen).collect();
        assert_eq!(chosen.len(), 1);
        assert_eq!(chosen[0].kind, "plane", "{motion:?} {missing}");
        assert!(
            rec.rms_px < 1e-6,
            "{motion:?} {missing}: RMS {}",
            rec.rms_px
        );
        assert!(e.focal_rel < 1e-6, "focal error {}", e.focal_rel);
        assert!(e.structure_rel < 1e-6, "structure {}", e.structure_rel);
        assert!(e.rotation_deg < 1e-5, "rotation error {}°", e.rotation_deg);
        assert!(e.centre_rel < 1e-6, "centre error {}", e.centre_rel);
    }
    let s = plane(Motion::HandheldArc, 0.0, 0.5, 3);
    let rec = Reconstruction::from_tracks(&s.table, &cfg).unwrap();
    let e = errors(&rec, &s);
    assert!(rec.rms_px < 0.55, "RMS {}", rec.rms_px);
    assert!(e.focal_rel < 0.02, "focal error {}", e.focal_rel);
    assert!(e.rotation_deg < 1.0, "rotation error {}°", e.rotation_deg);
    cfg.perspective.planar_start = false;
    let off = Reconstruction::from_tracks(&s.table, &cfg).unwrap();
    assert!(
        off.rms_px > 2.0,
        "without the planar start: RMS {}",
        off.rms_px
    );
}

/// A camera that only turns about its centre (a tripod pan) determines its focal length and
/// rotations but no depth: the result says so (`rotation_parallax_px` within the noise, and
/// a warning), while a perspective scene that moves the camera is not flagged.
#[test]
fn a_camera_that_only_rotates_is_reported() {
    use faer::Mat;
    use nalgebra::Rotation3;
    use rank3::{Measurements, TrackTable};
    let (nf, np, focal) = (12, 80, 500.0);
    let mut state = 99u64;
    let mut gauss = || {
        // Sum of 12 uniforms − 6: a unit normal deviate, good enough for noise.
        (0..12)
            .map(|_| {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (state >> 11) as f64 / (1u64 << 53) as f64
            })
            .sum::<f64>()
            - 6.0
    };
    let points: Vec<Vector3<f64>> = (0..np)
        .map(|_| Vector3::new(gauss(), 0.7 * gauss(), 6.0 + 0.5 * gauss()))
        .collect();
    let mut w = Mat::<f64>::zeros(2 * nf, np);
    for f in 0..nf {
        let a = f as f64 / (nf - 1) as f64;
        let rot = Rotation3::from_euler_angles(0.08 * (6.0 * a).sin(), 0.35 * (a - 0.5), 0.0);
        for (p, x) in points.iter().enumerate() {
            let y = rot * x;
            w[(2 * f, p)] = focal * y.x / y.z + 320.0 + 0.5 * gauss();
            w[(2 * f + 1, p)] = focal * y.y / y.z + 240.0 + 0.5 * gauss();
        }
    }
    let table = TrackTable::from_measurements(&Measurements::complete(w));
    let mut cfg = config(Intrinsics::default());
    cfg.perspective.intrinsics.image_size = Some([641, 481]);
    let rec = Reconstruction::from_tracks(&table, &cfg).unwrap();
    let per = rec.perspective.as_ref().unwrap();
    let parallax = per.rotation_parallax_px.expect("measured");
    assert!(parallax < 3.0 * per.rms_px, "parallax {parallax} px");
    assert!(
        rec.warnings.iter().any(|w| w.contains("only rotates")),
        "{:?}",
        rec.warnings
    );
    assert!((per.intrinsics.focal_px - focal).abs() < 0.05 * focal);
    // The same cloud seen by a camera that moves: not flagged.
    let s = scene(2.5, 0.0, 0.5, 5);
    let rec = Reconstruction::from_tracks(&s.table, &cfg).unwrap();
    let per = rec.perspective.as_ref().unwrap();
    assert!(per.rotation_parallax_px.unwrap() > 10.0 * per.rms_px);
    assert!(!rec.warnings.iter().any(|w| w.contains("only rotates")));
}

/// A planar scene with 10 % outlier tracks and 1 % gross entries, with the CLI's defaults
/// (automatic camera, robust pass): the affine pass, which cannot explain a plane seen in
/// perspective, groups many of the plane's tracks with the outliers as "another object".
/// Judged against the projective cameras only by the tracks its own motion explains, that
/// group is not held out, and the verdict keeps the plane's tracks.
#[test]
fn a_planar_scene_with_outliers_keeps_its_tracks() {
    use rank3::synth::Motion;
    // Seed 2 lost 70 of its 135 tracks before the evidence was limited to the tracks the
    // group's own motion explains and each track's weight capped, 55 with the first alone
    // (seed 0: 58 before either, none since).
    let seed = 2;
    let s = generate(&SynthConfig {
        camera: CameraModel::Perspective,
        shape: Shape::Plane,
        motion: Motion::Turntable,
        frames: 20,
        points: 150,
        noise: 0.5,
        missing: 0.3,
        outliers: 0.1,
        gross: 0.01,
        focal: Some(500.0),
        distance: 2.5,
        seed,
        ..SynthConfig::default()
    })
    .unwrap();
    let mut cfg = Config {
        camera: CameraModel::Auto,
        ..Config::default()
    };
    cfg.perspective.intrinsics.image_size = Some([641, 481]);
    let rec = Reconstruction::from_tracks(&s.table, &cfg).unwrap();
    assert_eq!(rec.camera_model, CameraModel::Perspective);
    let is_outlier = |p: usize| s.outlier_tracks[p].is_some();
    let n_outliers = (0..s.outlier_tracks.len())
        .filter(|&p| is_outlier(p))
        .count();
    let lost = rec
        .outlier_tracks
        .iter()
        .filter(|&&p| !is_outlier(p))
        .count();
    let caught = rec
        .outlier_tracks
        .iter()
        .filter(|&&p| is_outlier(p))
        .count();
    assert!(lost <= 3, "{lost} of the plane's tracks rejected");
    assert!(
        caught + 2 >= n_outliers,
        "{caught} of {n_outliers} outlier tracks rejected"
    );
    let per = rec.perspective.as_ref().unwrap();
    assert!((per.intrinsics.focal_px - 500.0).abs() < 25.0);
}
