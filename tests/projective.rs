//! The projective camera end to end: synthetic perspective scenes with truth, the real
//! benchmark optima, the robust pass judged by the projective model, and input errors.

use rank3::completion::Init;
use rank3::projective::Start;
use rank3::synth::{OutlierKind, Shape, SynthConfig, SynthScene, generate};
use rank3::{CameraModel, Config, Error, Reconstruction, TrackTable};

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

fn projective_config() -> Config {
    Config {
        camera: CameraModel::Projective,
        robust: None,
        ..Config::default()
    }
}

/// Largest distance, over every frame and track (observed or not), between the
/// reconstruction's prediction `π(P_f X_p)` and the true noise-free projection.
fn max_prediction_error(rec: &Reconstruction, s: &SynthScene) -> f64 {
    prediction_errors(rec, s).into_iter().fold(0.0, f64::max)
}

/// Distance between prediction and truth of every (frame, track) entry.
fn prediction_errors(rec: &Reconstruction, s: &SynthScene) -> Vec<f64> {
    let truth = s.perspective.as_ref().unwrap();
    let pred = rec.completed_matrix();
    let mut out = Vec::new();
    for f in 0..s.table.n_frames() {
        for p in 0..s.table.n_tracks() {
            let q = truth.project(f, &s.truth.points[p]);
            out.push(
                ((pred[(2 * f, p)] - q[0]).powi(2) + (pred[(2 * f + 1, p)] - q[1]).powi(2)).sqrt(),
            );
        }
    }
    out
}

#[test]
fn noise_free_complete_scene_is_fitted_exactly() {
    let s = scene(2.5, 0.0, 0.0, 1);
    let rec = Reconstruction::from_tracks(&s.table, &projective_config()).unwrap();
    let p = rec.projective.as_ref().unwrap();
    assert_eq!(p.start, Start::SturmTriggs);
    assert!(rec.rms_px < 1e-9, "RMS {}", rec.rms_px);
    // The affine model cannot fit strong perspective.
    assert!(rec.metric_rms_px > 1.0, "metric RMS {}", rec.metric_rms_px);
    assert!(max_prediction_error(&rec, &s) < 1e-7);
}

#[test]
fn noise_free_scenes_with_missing_data_are_fitted_exactly() {
    for (distance, missing, seed) in [(2.5, 0.3, 2), (2.5, 0.5, 3), (30.0, 0.5, 4)] {
        let s = scene(distance, missing, 0.0, seed);
        assert!(!s.table.is_complete());
        let rec = Reconstruction::from_tracks(&s.table, &projective_config()).unwrap();
        let p = rec.projective.as_ref().unwrap();
        assert_eq!(p.start, Start::Affine);
        assert!(
            rec.rms_px < 1e-9,
            "distance {distance}, missing {missing}: RMS {}",
            rec.rms_px
        );
        // Hidden entries are predicted too: the reprojections are projective invariants.
        let e = max_prediction_error(&rec, &s);
        assert!(
            e < 1e-6,
            "distance {distance}, missing {missing}: prediction off by {e} px"
        );
    }
}

#[test]
fn noisy_scene_fits_at_the_noise_level() {
    let s = scene(2.5, 0.4, 1.0, 5);
    let rec = Reconstruction::from_tracks(&s.table, &projective_config()).unwrap();
    // RMS over observed scalars of 1 px noise, less the fitted degrees of freedom.
    assert!(rec.rms_px > 0.6 && rec.rms_px < 1.0, "RMS {}", rec.rms_px);
    // The prediction of every entry, hidden ones included, against the noise-free truth:
    // its median is below the noise (the fit averages it out), while tracks seen in few
    // frames extrapolate worse.
    let mut e = prediction_errors(&rec, &s);
    e.sort_by(|a, b| a.total_cmp(b));
    let median = e[e.len() / 2];
    eprintln!(
        "prediction vs truth: median {median:.3} px, max {:.3} px",
        e[e.len() - 1]
    );
    assert!(median < 1.0, "median prediction error {median} px");
}

#[test]
fn random_starts_are_reproducible_with_the_seed() {
    let s = scene(3.0, 0.4, 0.5, 6);
    let mut cfg = projective_config();
    cfg.completion.init = Init::Random;
    cfg.completion.runs = 2;
    cfg.completion.seed = 11;
    let a = Reconstruction::from_tracks(&s.table, &cfg).unwrap();
    let b = Reconstruction::from_tracks(&s.table, &cfg).unwrap();
    let (pa, pb) = (a.projective.unwrap(), b.projective.unwrap());
    assert_eq!(pa.model, pb.model);
    assert_eq!(a.rms_px, b.rms_px);
}

#[test]
fn the_robust_pass_judges_tracks_by_the_projective_model() {
    let s = generate(&SynthConfig {
        camera: CameraModel::Perspective,
        frames: 20,
        points: 120,
        noise: 0.5,
        missing: 0.3,
        distance: 2.5,
        outliers: 0.1,
        outlier_kind: OutlierKind::RandomWalk,
        seed: 7,
        ..SynthConfig::default()
    })
    .unwrap();
    let cfg = Config {
        camera: CameraModel::Projective,
        ..Config::default()
    };
    let rec = Reconstruction::from_tracks(&s.table, &cfg).unwrap();
    let robust = rec.robust.as_ref().unwrap();
    assert!(robust.projective.is_some());
    let rejected: Vec<bool> = rec.points.iter().map(|p| !p.inlier).collect();
    let truly_out: Vec<bool> = s.outlier_tracks.iter().map(|o| o.is_some()).collect();
    let good_rejected = (0..rejected.len())
        .filter(|&p| rejected[p] && !truly_out[p])
        .count();
    let bad_kept = (0..rejected.len())
        .filter(|&p| !rejected[p] && truly_out[p])
        .count();
    // Strong perspective (the affine pass alone splits these tracks): every good track is
    // kept and every random walk rejected.
    assert_eq!(good_rejected, 0, "good tracks rejected");
    assert_eq!(bad_kept, 0, "outlier tracks kept");
    assert!(rec.rms_px < 0.6, "RMS {}", rec.rms_px);
}

#[test]
fn too_small_or_degenerate_input_is_a_typed_error() {
    // Five tracks: a projective reconstruction needs 7.
    let s = scene(3.0, 0.0, 0.0, 8);
    let few = s.table.select(
        &(0..s.table.n_frames()).collect::<Vec<_>>(),
        &[0, 1, 2, 3, 4],
    );
    match Reconstruction::from_tracks(&few, &projective_config()) {
        Err(Error::TooFew { .. }) => {}
        other => panic!("expected TooFew, got {other:?}"),
    }
    // A static camera: every frame the same image.
    let mut t = TrackTable::new(
        (0..6).map(rank3::Id::Int).collect(),
        (0..20).map(rank3::Id::Int).collect(),
    );
    for f in 0..6 {
        for p in 0..20 {
            t.set(
                f,
                p,
                100.0 + 17.0 * (p as f64).sin() * 10.0,
                200.0 + 13.0 * (p as f64).cos() * 10.0,
            );
        }
    }
    match Reconstruction::from_tracks(&t, &projective_config()) {
        Err(Error::Degenerate(_)) => {}
        other => panic!("expected Degenerate, got {other:?}"),
    }
}

/// The best known projective optima (ECCV 2016, Table 7) from the default pipeline.
#[test]
fn real_benchmarks_reach_the_known_projective_optima() {
    for (rel, best) in [
        ("model_house/matrix/M_dense.txt", 0.441660),
        ("dino_trimmed/M_dense.txt", 1.114493),
    ] {
        let Some(path) = rank3::datasets::find(rel) else {
            eprintln!("SKIPPED: {rel} not found");
            continue;
        };
        let table = TrackTable::read(&path).unwrap();
        let rec = Reconstruction::from_tracks(&table, &projective_config()).unwrap();
        assert!(
            ((rec.rms_px - best) / best).abs() < 1e-6,
            "{rel}: RMS {} vs best known {best}",
            rec.rms_px
        );
    }
}

/// A short video-like sparse table: a camera moving along a corridor of points at depth
/// 3–7, each track observed while the point is in view (no noise).
fn corridor(
    frames: usize,
    points: usize,
    seed: u64,
) -> (Vec<rank3::projective::Observation>, usize) {
    use nalgebra::{Matrix3, Rotation3, Vector3};
    use rand::{RngExt, SeedableRng};
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let k = Matrix3::new(500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0);
    let mut obs = Vec::new();
    let mut n_tracks = 0;
    for _ in 0..points {
        let p = Vector3::new(
            rng.random_range(-3.0..0.25 * frames as f64 + 3.0),
            rng.random_range(-1.5..1.5),
            rng.random_range(3.0..7.0),
        );
        let mut seen = Vec::new();
        for f in 0..frames {
            let a = f as f64;
            let r =
                Rotation3::from_euler_angles(0.05 * (a / 7.0).sin(), 0.08 * (a / 11.0).sin(), 0.0);
            let x = r * (p - Vector3::new(0.25 * a, 0.2 * (a / 9.0).sin(), 0.0));
            let q = k * x;
            let (u, v) = (q[0] / q[2], q[1] / q[2]);
            if x[2] > 0.5 && (0.0..640.0).contains(&u) && (0.0..480.0).contains(&v) {
                seen.push((f, [u, v]));
            }
        }
        if seen.len() >= 2 {
            for (frame, xy) in seen {
                obs.push(rank3::projective::Observation {
                    frame,
                    track: n_tracks,
                    xy,
                });
            }
            n_tracks += 1;
        }
    }
    (obs, n_tracks)
}

#[test]
fn a_sparse_sequence_is_fitted_exactly_through_windows() {
    use rank3::projective::windowed::WindowConfig;
    use rank3::projective::{ProjectiveConfig, fit_observations};
    let (obs, n_tracks) = corridor(30, 240, 3);
    let windows = WindowConfig {
        window: 14,
        overlap: 6,
        ..WindowConfig::default()
    };
    for projective in [true, false] {
        let w = WindowConfig {
            projective,
            ..windows.clone()
        };
        let fit = fit_observations(
            &obs,
            30,
            n_tracks,
            &ProjectiveConfig::default(),
            &w,
            &mut rank3::NoopObserver,
        )
        .unwrap();
        assert_eq!(fit.start, Start::Windows);
        assert!(
            fit.rms_px < 1e-9,
            "projective windows {projective}: RMS {}",
            fit.rms_px
        );
        let worst = obs
            .iter()
            .map(|o| {
                let q = fit.model.project(o.frame, o.track);
                (q[0] - o.xy[0]).hypot(q[1] - o.xy[1])
            })
            .fold(0.0, f64::max);
        assert!(worst < 1e-8, "worst reprojection {worst}");
    }
    // Bad input: a repeated pair and an index out of range are typed errors.
    let mut dup = obs.clone();
    dup.push(obs[0]);
    assert!(matches!(
        fit_observations(
            &dup,
            30,
            n_tracks,
            &ProjectiveConfig::default(),
            &windows,
            &mut rank3::NoopObserver
        ),
        Err(Error::Degenerate(_))
    ));
    assert!(matches!(
        fit_observations(
            &obs,
            10,
            n_tracks,
            &ProjectiveConfig::default(),
            &windows,
            &mut rank3::NoopObserver
        ),
        Err(Error::InvalidConfig { .. })
    ));
}

/// The windows placed on the metric reference (each by its own homography onto the
/// perspective windows chained by similarities, the route a drifted chain takes) start
/// within a tenth of a pixel of noise-free data and reach the exact fit, as the chain
/// does, and say that they took that route.
#[test]
fn the_windows_placed_on_a_metric_reference_start_exactly() {
    use rank3::projective::windowed::WindowConfig;
    use rank3::projective::{ProjectiveConfig, fit_observations};
    struct Warnings(Vec<String>);
    impl rank3::Observer for Warnings {
        fn on_event(&mut self, e: &rank3::Event<'_>) {
            if let rank3::Event::Warning { message } = e {
                self.0.push(message.to_string());
            }
        }
    }
    let (obs, n_tracks) = corridor(40, 320, 7);
    for drift_ratio in [None, Some(3.0), Some(0.0)] {
        let windows = WindowConfig {
            window: 14,
            overlap: 6,
            drift_ratio,
            ..WindowConfig::default()
        };
        let mut warnings = Warnings(Vec::new());
        let fit = fit_observations(
            &obs,
            40,
            n_tracks,
            &ProjectiveConfig::default(),
            &windows,
            &mut warnings,
        )
        .unwrap();
        let ba = fit.stages.last().unwrap();
        assert_eq!(ba.stage, "projective-ba");
        // The chain is exact on noise-free data; the reference is a metric fit that
        // assumes the principal point at the tracks' bounding-box centre and is adjusted for
        // a few iterations only, so the windows placed on it start near, not at, the data
        // (measured: 0.032 px).
        let start_bound = if drift_ratio == Some(0.0) { 0.1 } else { 1e-6 };
        assert!(
            ba.rms_before_px < start_bound,
            "{drift_ratio:?}: the start reprojects at {} px",
            ba.rms_before_px
        );
        assert!(fit.rms_px < 1e-9, "{drift_ratio:?}: RMS {}", fit.rms_px);
        let placed_again = warnings.0.iter().any(|w| w.contains("metric reference"));
        assert_eq!(
            placed_again,
            drift_ratio == Some(0.0),
            "{drift_ratio:?}: {:?}",
            warnings.0
        );
    }
}

#[test]
fn a_sparse_sequence_is_refined_from_a_given_model() {
    use rank3::projective::windowed::WindowConfig;
    use rank3::projective::{ProjectiveConfig, fit_observations, refine_observations};
    let (obs, n_tracks) = corridor(30, 240, 5);
    let windows = WindowConfig {
        window: 14,
        overlap: 6,
        ..WindowConfig::default()
    };
    let cfg = ProjectiveConfig::default();
    let fit =
        fit_observations(&obs, 30, n_tracks, &cfg, &windows, &mut rank3::NoopObserver).unwrap();
    // The optimum moved by a deterministic perturbation of every camera and point entry
    // (1 % of each entry's magnitude): the adjustment goes back to a zero-residual fit.
    let mut start = fit.model.clone();
    for (i, v) in start.cameras.iter_mut().flatten().enumerate() {
        *v *= 1.0 + 0.01 * ((i as f64) * 0.7).sin();
    }
    for (i, v) in start.points.iter_mut().flatten().enumerate() {
        *v *= 1.0 + 0.01 * ((i as f64) * 1.3).cos();
    }
    let rms_start = {
        let ss: f64 = obs
            .iter()
            .map(|o| {
                let q = start.project(o.frame, o.track);
                (q[0] - o.xy[0]).powi(2) + (q[1] - o.xy[1]).powi(2)
            })
            .sum();
        (ss / (2 * obs.len()) as f64).sqrt()
    };
    assert!(
        rms_start > 0.1,
        "the perturbed start fits too well: {rms_start}"
    );
    // With and without the geodesic acceleration of the adjustment.
    for geodesic_acceleration in [0.0, 0.75] {
        let mut c = cfg.clone();
        c.refine.geodesic_acceleration = geodesic_acceleration;
        let r =
            refine_observations(&obs, 30, n_tracks, &start, &c, &mut rank3::NoopObserver).unwrap();
        assert_eq!(r.start, Start::Given);
        assert!(
            r.rms_px < 1e-9,
            "α = {geodesic_acceleration}: RMS {} from {rms_start}",
            r.rms_px
        );
    }
    // A start of the wrong size is a typed error.
    let mut short = start.clone();
    short.points.pop();
    assert!(matches!(
        refine_observations(&obs, 30, n_tracks, &short, &cfg, &mut rank3::NoopObserver),
        Err(Error::Dimension { .. })
    ));
}

/// Observations of frames `lo..hi` of [`rank3::synth::perspective_corridor`]`(frames, 150,
/// 0.5, seed)`, frames renumbered from 0 and tracks seen there at least twice renumbered
/// in order, and the number of tracks.
fn corridor_slice(
    frames: usize,
    seed: u64,
    lo: usize,
    hi: usize,
) -> (Vec<rank3::projective::Observation>, usize) {
    let (obs, truth) = rank3::synth::perspective_corridor(frames, 150, 0.5, seed);
    let mut count = vec![0usize; truth.len()];
    for o in obs.iter().filter(|o| (lo..hi).contains(&o.frame)) {
        count[o.track] += 1;
    }
    let mut id = vec![usize::MAX; truth.len()];
    let mut n = 0;
    let mut out = Vec::new();
    for o in obs.iter().filter(|o| (lo..hi).contains(&o.frame)) {
        if count[o.track] < 2 {
            continue;
        }
        if id[o.track] == usize::MAX {
            id[o.track] = n;
            n += 1;
        }
        out.push(rank3::projective::Observation {
            frame: o.frame - lo,
            track: id[o.track],
            xy: o.xy,
        });
    }
    (out, n)
}

/// Collects the warnings sent to the observer.
#[derive(Default)]
struct Warnings(Vec<String>);

impl rank3::Observer for Warnings {
    fn on_event(&mut self, e: &rank3::Event<'_>) {
        if let rank3::Event::Warning { message } = e {
            self.0.push(message.to_string());
        }
    }
}

/// Frames 720..780 of the 20 000-frame corridor benchmark (`projective_scaling`): the
/// window of frames 740..780 ends its own fit in a local minimum of its affine completion
/// (13× the noise level, with either bridge), which broke the chain there (RMS in the
/// thousands of pixels after it was placed) and left the 20 000-frame run stalled at
/// 1 035 px. Such a window is now extended from the chain (resection of its new frames,
/// triangulation of its new tracks) and the fit ends at the noise level.
#[test]
fn a_window_whose_own_fit_fails_is_extended_from_the_chain() {
    use rank3::projective::windowed::WindowConfig;
    use rank3::projective::{ProjectiveConfig, fit_observations};
    let (obs, n_tracks) = corridor_slice(20000, 1, 720, 780);
    let mut warnings = Warnings::default();
    // 30 solves per adjustment: the windows at the noise level need about 10, the failing
    // one runs to the cap either way (193 solves by default).
    let mut cfg = ProjectiveConfig::default();
    cfg.refine.max_iterations = 30;
    let fit = fit_observations(
        &obs,
        60,
        n_tracks,
        &cfg,
        &WindowConfig::default(),
        &mut warnings,
    )
    .unwrap();
    assert!(
        warnings
            .0
            .iter()
            .any(|w| w.contains("extended from the chain")),
        "{:?}",
        warnings.0
    );
    // σ = 0.5 px less the fitted parameters' share: 0.46 px on the 2 000-frame corridor.
    assert!(fit.rms_px < 0.5, "RMS {} px, {:?}", fit.rms_px, warnings.0);
}

/// The Gauss–Newton decrement rule (`LmConfig::decrement_tolerance`) ends a noisy
/// sequence's adjustment sooner than the window rules alone, at an RMS within the 10⁻⁶ it
/// promises (the projective benchmarks' precision).
#[test]
fn the_decrement_rule_ends_a_noisy_sequence_sooner_at_the_same_rms() {
    use rand::{RngExt, SeedableRng};
    use rank3::projective::windowed::WindowConfig;
    use rank3::projective::{ProjectiveConfig, fit_observations};
    let frames = 80;
    let (mut obs, n_tracks) = corridor(frames, 500, 5);
    let mut rng = rand::rngs::StdRng::seed_from_u64(9);
    for o in &mut obs {
        o.xy[0] += rng.random_range(-0.8..0.8);
        o.xy[1] += rng.random_range(-0.8..0.8);
    }
    let windows = WindowConfig {
        window: 20,
        overlap: 10,
        ..WindowConfig::default()
    };
    let run = |decrement_tolerance: f64| {
        let mut cfg = ProjectiveConfig::default();
        cfg.refine.decrement_tolerance = decrement_tolerance;
        fit_observations(
            &obs,
            frames,
            n_tracks,
            &cfg,
            &windows,
            &mut rank3::NoopObserver,
        )
        .unwrap()
    };
    let with = run(ProjectiveConfig::default().refine.decrement_tolerance);
    let without = run(0.0);
    eprintln!(
        "with the rule: {} px, {} solves; without: {} px, {} solves",
        with.rms_px, with.report.iterations, without.rms_px, without.report.iterations
    );
    assert_eq!(with.report.status, rank3::SolverStatus::Converged);
    assert!(
        with.rms_px > 0.3 && with.rms_px < 0.5,
        "RMS {}",
        with.rms_px
    );
    assert!(
        (with.rms_px - without.rms_px).abs() <= 1e-6 * without.rms_px,
        "{} against {}",
        with.rms_px,
        without.rms_px
    );
    assert!(
        with.report.iterations < without.report.iterations,
        "{} solves against {}",
        with.report.iterations,
        without.report.iterations
    );
}
