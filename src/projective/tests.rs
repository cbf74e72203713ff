use super::*;
use crate::NoopObserver;
use crate::completion::{self, CompletionConfig};
use nalgebra::{Rotation3, Vector3};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

/// A perspective scene: points in a unit cube, cameras at distance `d` looking at the
/// origin, focal 600 px, principal point (320, 240). Each track visible in a contiguous
/// window when `missing` > 0.
pub(super) fn scene(
    nf: usize,
    np: usize,
    d: f64,
    missing: f64,
    seed: u64,
) -> (Measurements, Vec<[f64; 12]>, Vec<[f64; 4]>) {
    let mut rng = StdRng::seed_from_u64(seed);
    let pts: Vec<Vector3<f64>> = (0..np)
        .map(|_| {
            Vector3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            )
        })
        .collect();
    let mut cams = Vec::new();
    for f in 0..nf {
        let a = f as f64 / nf as f64;
        let r = Rotation3::from_euler_angles(0.3 * (3.0 * a).sin(), -0.6 + 1.2 * a, 0.1 * a);
        let t = Vector3::new(0.2 * a, -0.1, d);
        let k = nalgebra::Matrix3::new(600.0, 0.0, 320.0, 0.0, 600.0, 240.0, 0.0, 0.0, 1.0);
        let rt = nalgebra::Matrix3x4::from_columns(&[
            r.matrix().column(0).into(),
            r.matrix().column(1).into(),
            r.matrix().column(2).into(),
            t,
        ]);
        let p = k * rt;
        cams.push(std::array::from_fn(|i| p[(i / 4, i % 4)]));
    }
    let mut w = Mat::zeros(2 * nf, np);
    let mut vis = vec![true; nf * np];
    for p in 0..np {
        let x = [pts[p][0], pts[p][1], pts[p][2], 1.0];
        let (lo, hi) = if missing > 0.0 {
            let len = ((nf as f64 * (1.0 - missing)).round() as usize).clamp(3, nf);
            let lo = rng.random_range(0..=nf - len);
            (lo, lo + len)
        } else {
            (0, nf)
        };
        for f in 0..nf {
            let q = project(&cams[f], &x);
            w[(2 * f, p)] = q[0];
            w[(2 * f + 1, p)] = q[1];
            vis[f * np + p] = f >= lo && f < hi;
        }
    }
    let points = pts.iter().map(|v| [v[0], v[1], v[2], 1.0]).collect();
    (Measurements::new(w, vis), cams, points)
}

fn affine_fit(meas: &Measurements) -> crate::completion::Completion {
    completion::complete(meas, &CompletionConfig::default(), &mut NoopObserver).unwrap()
}

fn run(meas: &Measurements, cfg: &ProjectiveConfig) -> ProjectiveFit {
    let c = affine_fit(meas);
    fit(
        meas,
        AffineStart {
            m: c.m.as_ref(),
            s: c.s.as_ref(),
            t: &c.t,
        },
        cfg,
        0,
        &mut NoopObserver,
    )
    .unwrap()
}

#[test]
fn noise_free_complete_scene_is_fitted_exactly() {
    let (meas, _, _) = scene(12, 60, 3.0, 0.0, 1);
    let fit = run(&meas, &ProjectiveConfig::default());
    eprintln!("{:?}", fit.stages);
    assert!(fit.rms_px < 1e-9, "rms {}", fit.rms_px);
    assert!((fit.model.rms(&meas) - fit.rms_px).abs() < 1e-9);
}

#[test]
fn noise_free_missing_scene_is_fitted_exactly() {
    let (meas, _, _) = scene(20, 120, 3.0, 0.5, 2);
    let fit = run(&meas, &ProjectiveConfig::default());
    eprintln!("{:?}", fit.stages);
    assert!(fit.rms_px < 1e-9, "rms {}", fit.rms_px);
}

/// With a second bridge, `fit` runs both bridges from the same affine start and adjusts
/// from the end of lower projective cost: each bridge's reported cost is that of the same
/// bridge run alone (the adjustment's start, bit for bit), and the result is that bridge's
/// chain run alone.
#[test]
fn the_adjustment_starts_from_the_lower_of_two_bridges() {
    let (mut meas, _, _) = scene(16, 80, 2.5, 0.5, 5);
    let mut rng = StdRng::seed_from_u64(9);
    for v in meas.w.col_iter_mut() {
        for x in v.iter_mut() {
            *x += rng.random_range(-1.0..1.0);
        }
    }
    let both = ProjectiveConfig {
        sturm_triggs: false,
        bridge: Bridge::Pose { eta: 0.01 },
        second_bridge: Some(Bridge::Direct),
        ..ProjectiveConfig::default()
    };
    let two = run(&meas, &both);
    assert_eq!(two.bridges.len(), 2);
    assert_eq!(two.bridges[0].bridge, both.bridge);
    assert_eq!(two.bridges.iter().filter(|b| b.kept).count(), 1);
    let lowest = two
        .bridges
        .iter()
        .map(|b| b.start_rms_px)
        .fold(f64::INFINITY, f64::min);
    for b in &two.bridges {
        let alone = run(
            &meas,
            &ProjectiveConfig {
                bridge: b.bridge,
                second_bridge: None,
                ..both.clone()
            },
        );
        assert!(alone.bridges.is_empty());
        let ba = alone
            .stages
            .iter()
            .find(|s| s.stage == "projective-ba")
            .unwrap();
        assert_eq!(
            ba.rms_before_px.to_bits(),
            b.start_rms_px.to_bits(),
            "{:?}",
            b.bridge
        );
        assert_eq!(b.kept, b.start_rms_px == lowest);
        if b.kept {
            assert_eq!(two.rms_px.to_bits(), alone.rms_px.to_bits());
            assert_eq!(two.model, alone.model);
        }
    }
    // The direct bridge starts from the affine optimum, pOSE nearer the projective one.
    assert!(two.bridges[0].kept);
    // Noise of 1 px (uniform, σ ≈ 0.58 px): at the noise level.
    assert!(two.rms_px < 0.6, "rms {}", two.rms_px);
}

/// `check_observations` counts per frame and per track in one walk: the first non-finite
/// value in frame-major order is named, then too few tracks in a frame or frames of a track.
#[test]
fn check_observations_names_the_first_bad_value_and_the_counts() {
    let (nf, np) = (4, 9);
    let w = Mat::from_fn(2 * nf, np, |r, p| (r * 13 + p * 7) as f64);
    let ok = Measurements::complete(w.clone());
    assert!(check_observations(&ok).is_ok());
    let mut bad = w.clone();
    bad[(2 * 2 + 1, 1)] = f64::NAN; // frame 2, track 1
    bad[(2 * 3, 0)] = f64::INFINITY; // frame 3, track 0: later in frame-major order
    bad[(2 * 2, 5)] = f64::NAN; // frame 2, track 5
    let e = check_observations(&Measurements::complete(bad)).unwrap_err();
    assert!(
        e.to_string()
            .contains("observed value of track 1 in frame 2 is not finite"),
        "{e}"
    );
    // Frame 1 sees 5 tracks.
    let mut vis = vec![true; nf * np];
    for p in 5..np {
        vis[np + p] = false;
    }
    let e = check_observations(&Measurements::new(w.clone(), vis)).unwrap_err();
    assert!(
        matches!(
            e,
            Error::TooFew {
                needed: 6,
                have: 5,
                ..
            }
        ),
        "{e}"
    );
    // Track 8 is seen in frame 0 only.
    let mut vis = vec![true; nf * np];
    for f in 1..nf {
        vis[f * np + 8] = false;
    }
    let e = check_observations(&Measurements::new(w, vis)).unwrap_err();
    assert!(
        matches!(
            e,
            Error::TooFew {
                needed: 2,
                have: 1,
                ..
            }
        ),
        "{e}"
    );
}

/// The Schur update by dense products over runs of tracks and the track-by-track one give
/// the same adjustment up to rounding: a noisy scene with tracks entering and leaving
/// (the chunks then hold zeros where a track does not see a frame of their union) and a
/// complete one (every chunk spans every frame).
#[test]
fn dense_schur_update_matches_the_track_by_track_one() {
    for (missing, seed) in [(0.3, 11), (0.0, 12)] {
        let (mut meas, _, _) = scene(30, 160, 2.5, missing, seed);
        let mut rng = StdRng::seed_from_u64(seed);
        for p in 0..meas.n_points() {
            for r in 0..2 * meas.n_frames() {
                if meas.visible[(r / 2) * meas.n_points() + p] {
                    meas.w[(r, p)] += rng.random_range(-0.5..0.5);
                }
            }
        }
        let track_by_track = |dense: bool| {
            let mut cfg = ProjectiveConfig::default();
            cfg.pose.dense_schur = dense;
            cfg.refine.dense_schur = dense;
            // The escapes come back to the same optimum, and which end is lower by rounding
            // would decide whether their stages are appended: compare the chain alone.
            cfg.escapes.clear();
            run(&meas, &cfg)
        };
        let (a, b) = (track_by_track(true), track_by_track(false));
        assert!(a.rms_px > 0.1 && a.rms_px < 0.5, "rms {}", a.rms_px);
        assert!(
            (a.rms_px - b.rms_px).abs() <= 1e-9 * b.rms_px,
            "missing {missing}: {} vs {}",
            a.rms_px,
            b.rms_px
        );
        // The same steps (a wrong reduced system would change the path, not the optimum)
        // and fitted projections that agree far below the noise.
        let its =
            |f: &ProjectiveFit| -> Vec<usize> { f.stages.iter().map(|s| s.iterations).collect() };
        assert_eq!(its(&a), its(&b), "missing {missing}");
        let diff = meas
            .observed_pairs()
            .map(|(f, p)| {
                let (qa, qb) = (a.model.project(f, p), b.model.project(f, p));
                (qa[0] - qb[0]).abs().max((qa[1] - qb[1]).abs())
            })
            .fold(0.0, f64::max);
        assert!(
            diff < 1e-6,
            "missing {missing}: projections differ by {diff} px"
        );
    }
}

/// The reduced camera system solved by conjugate gradients on its implicit form and by
/// sparse Cholesky gives the same adjustment: the whole projective chain (pOSE, then the
/// projective bundle adjustment) on a noisy scene with tracks entering and leaving, and
/// an adjustment with three cameras held fixed (their springs and zeroed rows). The CG
/// tolerance is the default's 10⁻⁶: the steps differ by about that, the optimum does not.
#[test]
fn the_iterative_reduced_solver_matches_the_direct_one() {
    use super::bundle::{LinearSolver, LmConfig, Progress};
    let (mut meas, cams, pts) = scene(30, 160, 2.5, 0.3, 11);
    let mut rng = StdRng::seed_from_u64(11);
    for p in 0..meas.n_points() {
        for r in 0..2 * meas.n_frames() {
            if meas.visible[(r / 2) * meas.n_points() + p] {
                meas.w[(r, p)] += rng.random_range(-0.5..0.5);
            }
        }
    }
    let with = |solver: LinearSolver| {
        let mut cfg = ProjectiveConfig::default();
        cfg.pose.linear_solver = solver;
        cfg.refine.linear_solver = solver;
        run(&meas, &cfg)
    };
    let (direct, iterative) = (with(LinearSolver::Direct), with(LinearSolver::Iterative));
    assert!(
        direct.rms_px > 0.1 && direct.rms_px < 0.5,
        "rms {}",
        direct.rms_px
    );
    assert!(
        (direct.rms_px - iterative.rms_px).abs() <= 1e-7 * direct.rms_px,
        "{} vs {}",
        direct.rms_px,
        iterative.rms_px
    );
    for s in iterative
        .stages
        .iter()
        .filter(|s| s.stage != "sturm-triggs")
    {
        assert_eq!(s.linear_solver, Some(LinearSolver::Iterative), "{s:?}");
        assert!(s.cg_iterations >= s.iterations, "{s:?}");
    }
    for s in direct.stages.iter().filter(|s| s.stage != "sturm-triggs") {
        assert_eq!(s.linear_solver, Some(LinearSolver::Direct), "{s:?}");
        assert_eq!(s.cg_iterations, 0, "{s:?}");
    }
    let diff = meas
        .observed_pairs()
        .map(|(f, p)| {
            let (qa, qb) = (direct.model.project(f, p), iterative.model.project(f, p));
            (qa[0] - qb[0]).abs().max((qa[1] - qb[1]).abs())
        })
        .fold(0.0, f64::max);
    assert!(diff < 1e-4, "projections differ by {diff} px");

    // Three cameras held fixed, from the truth perturbed (normalized coordinates).
    let norm = Normalization::of(&meas);
    let g = super::graph(&meas, &norm);
    let t = [
        [norm.scale, 0.0, -norm.scale * norm.centre[0]],
        [0.0, norm.scale, -norm.scale * norm.centre[1]],
        [0.0, 0.0, 1.0],
    ];
    let mut c0 = Vec::new();
    for p in &cams {
        for r in 0..3 {
            for col in 0..4 {
                let v: f64 = (0..3).map(|k| t[r][k] * p[k * 4 + col]).sum();
                c0.push(v * (1.0 + 0.02 * rng.random_range(-1.0..1.0)));
            }
        }
    }
    for f in 0..meas.n_frames() {
        super::bundle::normalize(&mut c0[12 * f..12 * f + 12]);
    }
    let x0: Vec<f64> = pts.iter().flat_map(|x| x.iter().copied()).collect();
    let fixed: Vec<bool> = (0..meas.n_frames()).map(|f| f < 3).collect();
    let adjust = |solver: LinearSolver| {
        let (mut c, mut x) = (c0.clone(), x0.clone());
        let cfg = LmConfig {
            linear_solver: solver,
            ..LmConfig::default()
        };
        let r = super::bundle::minimize_fixed(
            &super::models::Projective,
            &g,
            &mut c,
            &mut x,
            &fixed,
            &cfg,
            &mut Progress {
                observer: &mut NoopObserver,
                name: "test",
                run: 0,
                rms_scale: 1.0,
                stop: None,
            },
        )
        .unwrap();
        assert_eq!(r.linear_solver, solver);
        (r, c)
    };
    let ((rd, cd), (ri, ci)) = (
        adjust(LinearSolver::Direct),
        adjust(LinearSolver::Iterative),
    );
    assert!(rd.report.final_cost < 0.5 * rd.report.initial_cost);
    assert!(
        (rd.report.final_cost - ri.report.final_cost).abs() <= 1e-7 * rd.report.final_cost,
        "{} vs {}",
        rd.report.final_cost,
        ri.report.final_cost
    );
    // Held fixed: a zero step, renormalised (rounding only).
    for (a, b) in ci[..36]
        .iter()
        .chain(&cd[..36])
        .zip(c0[..36].iter().cycle())
    {
        assert!((a - b).abs() < 1e-14, "a fixed camera moved: {a} vs {b}");
    }
    assert!(ri.cg_iterations > 0 && rd.cg_iterations == 0);
}

/// Cameras with a common centre `C` (the projective cameras a planar scene can drift
/// towards: `P_f = [H_f | 0]`, `C = (0, 0, 0, 1)`) make `C` the smallest eigenvector of every
/// track's linear triangulation, with noise; the triangulation takes the point on the
/// plane instead, which reprojects at the noise level.
#[test]
fn linear_triangulation_avoids_a_common_camera_centre() {
    let mut rng = StdRng::seed_from_u64(7);
    let cams: Vec<[f64; 12]> = (0..6)
        .map(|f| {
            let r = Rotation3::from_euler_angles(0.05 * f as f64, 0.1 * f as f64, 0.0);
            let h = r.matrix();
            let mut c = [0.0; 12];
            for i in 0..3 {
                for j in 0..3 {
                    c[4 * i + j] = h[(i, j)] + if i == j { 0.0 } else { 0.02 * f as f64 };
                }
            }
            c
        })
        .collect();
    for _ in 0..20 {
        let x = [
            rng.random_range(-0.5..0.5),
            rng.random_range(-0.5..0.5),
            1.0,
            0.0,
        ];
        let views: Vec<([f64; 12], [f64; 2])> = cams
            .iter()
            .map(|c| {
                let q = project(c, &x);
                let noise = 1e-3;
                (
                    *c,
                    [
                        q[0] + noise * rng.random_range(-1.0..1.0),
                        q[1] + noise * rng.random_range(-1.0..1.0),
                    ],
                )
            })
            .collect();
        let y = dlt_views(views.iter().map(|(c, w)| (&c[..], *w)));
        let rms = (views
            .iter()
            .map(|(c, w)| {
                let q = project(c, &y);
                (q[0] - w[0]).powi(2) + (q[1] - w[1]).powi(2)
            })
            .sum::<f64>()
            / (2 * views.len()) as f64)
            .sqrt();
        assert!(rms < 3e-3, "reprojection RMS {rms} of {y:?}");
    }
}

/// Random affine cameras and points for `meas` (entries uniform in ±1, translations at
/// the image centre (320, 240)): a start from nowhere near the optimum.
fn random_affine(meas: &Measurements, seed: u64) -> (Mat<f64>, Mat<f64>, Vec<f64>) {
    let (nf, np) = (meas.n_frames(), meas.n_points());
    let mut rng = StdRng::seed_from_u64(seed);
    let m = Mat::from_fn(2 * nf, 3, |_, _| rng.random_range(-1.0..1.0));
    let s = Mat::from_fn(3, np, |_, _| rng.random_range(-1.0..1.0));
    let t: Vec<f64> = (0..2 * nf)
        .map(|i| if i % 2 == 0 { 320.0 } else { 240.0 })
        .collect();
    (m, s, t)
}

/// `escapes`: from where the adjustment stopped, a pOSE bridge from the adjusted cameras
/// and a second adjustment; the lower model is kept and reported, with the chain of stages
/// that led to it. Here the first adjustment is cut short (3 iterations from a random
/// affine start), so the escape has somewhere lower to go; without escapes nothing is
/// tried.
#[test]
fn an_escape_from_the_adjusted_end_keeps_the_lower_model() {
    let (meas, _, _) = scene(16, 80, 2.5, 0.4, 12);
    let (m, s, t) = random_affine(&meas, 3);
    let cut = ProjectiveConfig {
        sturm_triggs: false,
        bridge: Bridge::Direct,
        second_bridge: None,
        escapes: Vec::new(),
        refine: LmConfig {
            max_iterations: 3,
            ..ProjectiveConfig::default().refine
        },
        ..ProjectiveConfig::default()
    };
    let go = |cfg: &ProjectiveConfig| {
        let start = AffineStart {
            m: m.as_ref(),
            s: s.as_ref(),
            t: &t,
        };
        fit(&meas, start, cfg, 0, &mut NoopObserver).unwrap()
    };
    let plain = go(&cut);
    assert!(plain.escapes.is_empty());
    let escaped = go(&ProjectiveConfig {
        escapes: vec![Bridge::Pose { eta: 0.01 }, Bridge::Direct],
        ..cut.clone()
    });
    assert_eq!(escaped.escapes.len(), 2);
    let e = &escaped.escapes[0];
    assert_eq!(e.bridge, Bridge::Pose { eta: 0.01 });
    assert_eq!(e.from_rms_px.to_bits(), plain.rms_px.to_bits());
    assert!(e.kept, "{e:?} from {}", plain.rms_px);
    assert!(e.bridge_rms_px.is_finite() && e.iterations > 3);
    // The second escape starts from the first's model.
    assert_eq!(escaped.escapes[1].from_rms_px.to_bits(), e.rms_px.to_bits());
    let kept_last = escaped.escapes.iter().rev().find(|e| e.kept).unwrap();
    assert_eq!(escaped.rms_px.to_bits(), kept_last.rms_px.to_bits());
    assert!(
        escaped.rms_px < 0.5 * plain.rms_px,
        "{} against {}",
        escaped.rms_px,
        plain.rms_px
    );
    assert!((escaped.model.rms(&meas) - escaped.rms_px).abs() < 1e-9 * plain.rms_px.max(1.0));
    // The stages: the chain escaped from, then the escape's bridge and adjustment.
    let names: Vec<&str> = escaped.stages.iter().map(|s| s.stage.as_str()).collect();
    assert_eq!(
        &names[..plain.stages.len()],
        &plain
            .stages
            .iter()
            .map(|s| s.stage.as_str())
            .collect::<Vec<_>>()[..]
    );
    assert!(
        names.ends_with(&["projective-ba"]) && names.contains(&"pose"),
        "{names:?}"
    );
    // A bad weight is refused by name.
    let bad = ProjectiveConfig {
        escapes: vec![Bridge::Pose { eta: 0.0 }],
        ..ProjectiveConfig::default()
    };
    assert!(matches!(
        bad.validate(),
        Err(Error::InvalidConfig {
            field: "projective.escapes",
            ..
        })
    ));
}

/// The default chain from an affine start: both bridges, then the two escapes (pOSE at
/// η = 0.01, then 0.1) from the adjusted end, each reported; the model kept is the lowest
/// the chain and the escapes reached, so an escape never raises the cost. Noise-free
/// perspective scene with missing entries, started from random affine cameras: the fit
/// reaches the data (RMS < 1e-6 px).
#[test]
fn the_default_escapes_keep_the_lowest_model() {
    let cfg = ProjectiveConfig::default();
    assert_eq!(
        cfg.escapes,
        vec![Bridge::Pose { eta: 0.01 }, Bridge::Pose { eta: 0.1 }]
    );
    let (meas, _, _) = scene(12, 60, 2.5, 0.3, 21);
    let (m, s, t) = random_affine(&meas, 8);
    let start = AffineStart {
        m: m.as_ref(),
        s: s.as_ref(),
        t: &t,
    };
    let f = fit(&meas, start, &cfg, 0, &mut NoopObserver).unwrap();
    assert_eq!(f.bridges.len(), 2);
    assert_eq!(f.escapes.len(), 2);
    assert_eq!(f.escapes[0].bridge, Bridge::Pose { eta: 0.01 });
    assert_eq!(f.escapes[1].bridge, Bridge::Pose { eta: 0.1 });
    for e in &f.escapes {
        assert!(f.rms_px <= e.from_rms_px, "{e:?} → {}", f.rms_px);
        if e.rms_px.is_finite() {
            assert!(f.rms_px <= e.rms_px, "{e:?} → {}", f.rms_px);
            assert_eq!(e.kept, e.rms_px < e.from_rms_px, "{e:?}");
        }
    }
    assert!(f.rms_px < 1e-6, "RMS {} px", f.rms_px);
    assert!((f.model.rms(&meas) - f.rms_px).abs() < 1e-9);
}

/// The scene of [`scene`] with uniform noise of ±1 px (σ ≈ 0.58 px) on every entry.
fn noisy_scene(nf: usize, np: usize, missing: f64, seed: u64) -> Measurements {
    let (mut meas, _, _) = scene(nf, np, 2.5, missing, seed);
    let mut rng = StdRng::seed_from_u64(seed + 1000);
    for v in meas.w.col_iter_mut() {
        for x in v.iter_mut() {
            *x += rng.random_range(-1.0..1.0);
        }
    }
    meas
}

/// An escape whose adjustment comes back into the basin of the model it left stops there
/// (`back_in_basin`) and is not kept. A noisy scene (σ ≈ 0.58 px, 30 % missing) from
/// random affine cameras: the chain reaches the optimum, both default escapes return to
/// it, each reported as returned within the gate of its cost, and the model is the chain's
/// own, bit for bit, as without escapes.
#[test]
fn an_escape_back_in_the_basin_it_left_stops_there() {
    let meas = noisy_scene(12, 60, 0.3, 21);
    let (m, s, t) = random_affine(&meas, 8);
    let go = |escapes: Vec<Bridge>| {
        let start = AffineStart {
            m: m.as_ref(),
            s: s.as_ref(),
            t: &t,
        };
        let cfg = ProjectiveConfig {
            escapes,
            ..ProjectiveConfig::default()
        };
        fit(&meas, start, &cfg, 0, &mut NoopObserver).unwrap()
    };
    let plain = go(Vec::new());
    let f = go(ProjectiveConfig::default().escapes);
    assert_eq!(f.escapes.len(), 2);
    for e in &f.escapes {
        assert!(e.returned && !e.kept, "{e:?}");
        assert_eq!(e.from_rms_px.to_bits(), plain.rms_px.to_bits());
        assert!(
            e.rms_px >= e.from_rms_px
                && e.rms_px.powi(2) <= (1.0 + RETURN_GATE) * e.from_rms_px.powi(2),
            "{e:?}"
        );
    }
    assert_eq!(f.rms_px.to_bits(), plain.rms_px.to_bits());
    assert_eq!(f.model, plain.model);
    assert_eq!(f.stages.len(), plain.stages.len());
    // At the noise level.
    assert!(f.rms_px < 0.6, "rms {}", f.rms_px);
}

/// `back_in_basin` compares predictions, which the projective gauge leaves alone: the
/// adjusted model of a noisy scene in another gauge (`P H⁻¹`, `H X`) and a nearby model
/// (one camera moved, excess cost ~10⁻⁴ of the cost, its predictions' distance what the
/// Gauss–Newton model of the minimum says) are back; a model below the one left, one above
/// the gate, and one whose predictions are farther than the quadratic model allows are not.
#[test]
fn back_in_basin_reads_the_predictions_not_the_gauge() {
    let meas = noisy_scene(12, 60, 0.3, 4);
    let f = run(&meas, &ProjectiveConfig::default());
    let norm = Normalization::of(&meas);
    let g = graph(&meas, &norm);
    let (cams, pts) = normalized_start(&f.model, &norm);
    let cost = bundle::cost(&models::Projective, &g, &cams, &pts, &[]);
    let left = predictions(&g, &cams, &pts);
    assert!(back_in_basin(&g, &left, cost, &cams, &pts, cost));
    // Another gauge: the same predictions.
    let h = nalgebra::Matrix4::new(
        1.2, 0.1, -0.3, 0.2, 0.05, 0.9, 0.1, -0.1, 0.2, -0.1, 1.1, 0.3, 0.1, 0.2, -0.05, 1.0,
    );
    let hi = h.try_inverse().unwrap();
    let moved_cams: Vec<f64> = cams
        .chunks(12)
        .flat_map(|c| {
            let p = nalgebra::Matrix3x4::from_row_slice(c) * hi;
            (0..12).map(move |i| p[(i / 4, i % 4)])
        })
        .collect();
    let moved_pts: Vec<f64> = pts
        .chunks(4)
        .flat_map(|x| {
            (h * nalgebra::Vector4::from_row_slice(x))
                .iter()
                .copied()
                .collect::<Vec<_>>()
        })
        .collect();
    let gauge = predictions(&g, &moved_cams, &moved_pts);
    let d2: f64 = gauge.iter().zip(&left).map(|(a, b)| (a - b).powi(2)).sum();
    assert!(d2 < 1e-20 * cost.max(1.0), "{d2}");
    assert!(back_in_basin(
        &g,
        &left,
        cost,
        &moved_cams,
        &moved_pts,
        cost * (1.0 + 1e-9)
    ));
    // One camera moved along a random direction to ~10⁻⁴ of the cost: excess ≈ distance².
    let mut rng = StdRng::seed_from_u64(5);
    let dir: Vec<f64> = (0..12).map(|_| rng.random_range(-1.0..1.0)).collect();
    let at = |eps: f64| {
        let mut c = cams.clone();
        for (v, d) in c[12 * 5..12 * 6].iter_mut().zip(&dir) {
            *v += eps * d;
        }
        (bundle::cost(&models::Projective, &g, &c, &pts, &[]), c)
    };
    let mut eps = 1e-6;
    while at(eps).0 < cost * (1.0 + 1e-4) {
        eps *= 1.5;
    }
    let (near_cost, near) = at(eps);
    assert!(
        near_cost <= cost * (1.0 + 1e-3),
        "{}",
        near_cost / cost - 1.0
    );
    assert!(back_in_basin(&g, &left, cost, &near, &pts, near_cost));
    // Not back: below the model left, above the gate, or predicting too differently.
    assert!(!back_in_basin(&g, &left, near_cost, &cams, &pts, cost));
    assert!(!back_in_basin(
        &g,
        &left,
        cost,
        &cams,
        &pts,
        cost * (1.0 + 2.0 * RETURN_GATE)
    ));
    let far: Vec<f64> = left.iter().map(|v| v + 1e-2).collect();
    let excess = 1e-4 * cost;
    let far_d2 = 1e-4 * left.len() as f64;
    assert!(far_d2 > 2.0 * excess, "{far_d2} {excess}");
    assert!(!back_in_basin(&g, &far, cost, &cams, &pts, cost + excess));
}
