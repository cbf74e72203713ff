use super::*;
use faer::Mat;

/// Small affine scene with windowed visibility: returns measurements (noise-free).
fn scene(nf: usize, np: usize, seed: u64) -> Measurements {
    let mut rng = StdRng::seed_from_u64(seed);
    let mut g = || rng.sample::<f64, _>(StandardNormal);
    let cams: Vec<f64> = (0..2 * nf * 4).map(|_| g()).collect();
    let pts: Vec<f64> = (0..3 * np).map(|_| 10.0 * g()).collect();
    let w = Mat::from_fn(2 * nf, np, |i, p| {
        let c = &cams[i * 4..i * 4 + 4];
        c[0] * pts[3 * p] + c[1] * pts[3 * p + 1] + c[2] * pts[3 * p + 2] + 100.0 * c[3]
    });
    // Track p visible in frames [start, start + len).
    let visible = (0..nf * np)
        .map(|k| {
            let (f, p) = (k / np, k % np);
            let start = (p * 7) % nf;
            let len = 3 + (p % (nf - 2));
            (f + nf - start) % nf < len
        })
        .collect();
    Measurements::new(w, visible)
}

#[test]
fn gradient_matches_finite_differences() {
    let meas = scene(6, 20, 1);
    for model in [CompletionModel::Affine, CompletionModel::Free { rank: 3 }] {
        let prob = CompletionProblem::new(&meas, model).unwrap();
        let mut rng = StdRng::seed_from_u64(7);
        let (m, t) = prob.random_start(&mut rng);
        let t: Vec<f64> = t
            .iter()
            .map(|_| rng.sample::<f64, _>(StandardNormal))
            .collect();
        let u = prob.pack(m.as_ref(), &t);
        let ps = prob.solve_points(&u, 0.0, 0.0, false);
        let (g, _) = prob.gradient(&ps);
        let h = 1e-6;
        for k in [0, 3, 5, 11, u.len() - 1] {
            let mut up = u.clone();
            up[k] += h;
            let mut um = u.clone();
            um[k] -= h;
            let fd = (prob.solve_points(&up, 0.0, 0.0, false).cost
                - prob.solve_points(&um, 0.0, 0.0, false).cost)
                / (2.0 * h);
            // `gradient` returns Jᵀr = ½ ∇f.
            let scale = g.iter().map(|x| x.abs()).fold(0.0, f64::max);
            assert!(
                (fd - 2.0 * g[k]).abs() <= 1e-5 * scale,
                "{model:?} k={k}: fd {fd} vs {}",
                2.0 * g[k]
            );
        }
    }
}

#[test]
fn normalization_keeps_cost_and_orthonormalizes() {
    let meas = scene(6, 20, 2);
    let prob = CompletionProblem::new(&meas, CompletionModel::Affine).unwrap();
    let mut rng = StdRng::seed_from_u64(3);
    let (m, _) = prob.random_start(&mut rng);
    let t: Vec<f64> = (0..12).map(|i| i as f64).collect();
    let mut u = prob.pack(m.as_ref(), &t);
    let c0 = prob.solve_points(&u, 0.0, 0.0, false).cost;
    prob.normalize(&mut u);
    let c1 = prob.solve_points(&u, 0.0, 0.0, false).cost;
    assert!((c0 - c1).abs() <= 1e-9 * c0.max(1.0));
    let (m, t) = prob.unpack(&u);
    let mtm = m.transpose() * &m;
    for i in 0..3 {
        for j in 0..3 {
            assert!((mtm[(i, j)] - if i == j { 1.0 } else { 0.0 }).abs() < 1e-12);
        }
        let d: f64 = (0..12).map(|k| m[(k, i)] * t[k]).sum();
        assert!(d.abs() < 1e-10);
    }
}

#[test]
fn serde_names_are_kebab_case() {
    assert_eq!(
        serde_json::to_string(&CompletionSolverKind::Als).unwrap(),
        "\"als\""
    );
    assert_eq!(
        serde_json::to_string(&CompletionSolverKind::Wiberg).unwrap(),
        "\"wiberg\""
    );
    assert_eq!(serde_json::to_string(&Init::Random).unwrap(), "\"random\"");
    let k: CompletionSolverKind = serde_json::from_str("\"wiberg\"").unwrap();
    assert_eq!(k, CompletionSolverKind::Wiberg);
    assert_eq!(
        "als".parse::<CompletionSolverKind>().unwrap(),
        CompletionSolverKind::Als
    );
    assert!("lm".parse::<CompletionSolverKind>().is_err());
    let cfg: CompletionConfig = serde_json::from_str(r#"{"solver":"als","runs":3}"#).unwrap();
    assert_eq!(cfg.solver, CompletionSolverKind::Als);
    assert_eq!(cfg.runs, 3);
    assert_eq!(cfg.model, CompletionModel::Affine);
}

#[test]
fn invalid_config_is_a_typed_error() {
    let meas = scene(6, 20, 4);
    for cfg in [
        CompletionConfig {
            runs: 0,
            ..Default::default()
        },
        CompletionConfig {
            model: CompletionModel::Free { rank: 0 },
            ..Default::default()
        },
        CompletionConfig {
            function_tolerance: f64::NAN,
            ..Default::default()
        },
        CompletionConfig {
            point_damping_decrease: 1.0,
            ..Default::default()
        },
        CompletionConfig {
            creep_tolerance: -1.0,
            ..Default::default()
        },
        CompletionConfig {
            geodesic_acceleration: f64::INFINITY,
            ..Default::default()
        },
    ] {
        assert!(matches!(
            complete(&meas, &cfg, &mut crate::NoopObserver),
            Err(Error::InvalidConfig { .. })
        ));
    }
}

#[test]
fn ridge_continuation_and_creep_switch_end_unregularised() {
    // Geometric continuation 1e-4, 1e-6, …, then 1e-12, and a creep switch that fires
    // immediately: the final objective is the unregularised one, so the noise-free scene
    // is fitted exactly.
    let meas = scene(8, 40, 6);
    let cfg = CompletionConfig {
        point_damping_initial: 1e-4,
        point_damping_decrease: 1e-2,
        creep_window: 1,
        creep_tolerance: 1.0,
        max_iterations: 300,
        ..Default::default()
    };
    let c = complete(&meas, &cfg, &mut crate::NoopObserver).unwrap();
    assert!(c.rms < 1e-6, "rms {}", c.rms);
}

#[test]
fn wiberg_with_and_without_geodesic_acceleration_fits_noise_free_scene() {
    let meas = scene(8, 40, 7);
    for geodesic_acceleration in [0.0, 0.75] {
        let cfg = CompletionConfig {
            geodesic_acceleration,
            max_iterations: 200,
            ..Default::default()
        };
        let c = complete(&meas, &cfg, &mut crate::NoopObserver).unwrap();
        assert!(c.rms < 1e-6, "α = {geodesic_acceleration}: rms {}", c.rms);
    }
}

#[test]
fn both_solvers_and_jacobians_fit_noise_free_scene() {
    let meas = scene(8, 40, 5);
    for (solver, jacobian) in [
        (CompletionSolverKind::Wiberg, VarProJacobian::Kaufman),
        (CompletionSolverKind::Wiberg, VarProJacobian::Full),
        (CompletionSolverKind::Als, VarProJacobian::Kaufman),
    ] {
        let cfg = CompletionConfig {
            solver,
            jacobian,
            max_iterations: if solver == CompletionSolverKind::Als {
                5000
            } else {
                200
            },
            ..Default::default()
        };
        let c = complete(&meas, &cfg, &mut crate::NoopObserver).unwrap();
        // Data are O(100) px; exact fit up to round-off.
        assert!(c.rms < 1e-6, "{solver:?} {jacobian:?}: rms {}", c.rms);
    }
}

#[test]
fn als_first_reaches_the_wiberg_optimum_and_hands_over_when_it_stalls() {
    // A noisy scene, so that the optimum has a non-zero cost to agree on.
    let mut meas = scene(10, 60, 3);
    let mut rng = StdRng::seed_from_u64(11);
    for i in 0..meas.w.nrows() {
        for p in 0..meas.w.ncols() {
            if meas.is_visible(i / 2, p) {
                meas.w[(i, p)] += 0.5 * rng.sample::<f64, _>(StandardNormal);
            }
        }
    }
    let base = CompletionConfig::default();
    let alone = complete(&meas, &base, &mut crate::NoopObserver).unwrap();
    assert_eq!(alone.als_sweeps_first, 0, "a small table runs Wiberg alone");
    assert!(alone.report.iterations > 0);
    // Forced: ALS first (every table is above 0 operations).
    let first = CompletionConfig {
        als_first_flops: 0.0,
        ..base.clone()
    };
    let a = complete(&meas, &first, &mut crate::NoopObserver).unwrap();
    assert!(a.als_sweeps_first > 0);
    assert_eq!(a.report.status, SolverStatus::Converged);
    // ALS stops by the gradient test that stops Wiberg: the same optimum, to a relative
    // cost well below the noise's share of one parameter (1 / n_obs).
    let rel = (a.rms - alone.rms).abs() / alone.rms;
    assert!(rel < 1e-6, "ALS first {} vs Wiberg {}", a.rms, alone.rms);
    // An ALS run that stalls at once hands over: the Wiberg iterations finish the job.
    let stall = CompletionConfig {
        als_first_flops: 0.0,
        stall_tolerance: 1.0,
        stall_window: 1,
        ..base
    };
    let s = complete(&meas, &stall, &mut crate::NoopObserver).unwrap();
    assert!(s.als_sweeps_first >= 1);
    assert!(
        s.report.iterations > 0,
        "Wiberg continued after the stalled ALS"
    );
    let rel = (s.rms - alone.rms).abs() / alone.rms;
    assert!(
        rel < 1e-6,
        "stalled ALS + Wiberg {} vs Wiberg {}",
        s.rms,
        alone.rms
    );
}
