//! Success rate and speed of the projective factorization from random starts on the real
//! benchmark matrices (dino_trimmed, model_house), the protocol of Hong, Zach, Fitzgibbon &
//! Cipolla (ECCV 2016, Table 7): each start draws random affine cameras (Gaussian M), runs
//! the affine VarPro (rank3's damped Wiberg), then the projective chain of the variant.
//!
//! `cargo run --release --example projective_benchmark -- [K] [FIRST_SEED] [VARIANT ...]`
//!
//! K random starts per row (default 100), seeds FIRST_SEED.. (default 0). Variants (default
//! `default pose0.01+pose0.1 pose0.01 direct`):
//! * `default`: the library's default chain, `pose0.01+pose0.1^pose0.01^pose0.1` (the
//!   escapes default since 2026-12-03; `pose0.01+pose0.1` was the default before);
//! * `poseETA`: affine → pOSE (weight ETA on the affine term, VarPro) → projective VarPro;
//! * `direct`: affine → projective VarPro;
//! * `A+B` (each `poseETA` or `direct`): both chains from the same affine optimum, the one
//!   of lower final cost kept (`ProjectiveConfig::second_bridge`);
//! * `poseETA-joint` / `direct-joint`: the same with a joint (Schur, damped points, no
//!   point re-solve) projective Levenberg–Marquardt instead of VarPro;
//! * `VARIANT^E1^E2…` (each `E` `poseETA` or `direct`): after the chain, escapes from its
//!   adjusted end, in turn (`ProjectiveConfig::escapes`), e.g. `pose0.01+pose0.1^pose0.01^pose0.1`.
//!
//! `MATRICES=name:path:best,...` adds more measurement matrices (rank3's text matrix: 2F rows,
//! `nan` where unobserved) with their best known projective RMS — e.g. the other data sets of
//! ECCV 2016's Table 7 (github.com/jhh37/pba-datasets, MATLAB files: `M` with `W` the mask);
//! `ONLY_MATRICES=1` skips the two shipped ones. `VERBOSE=1` prints each start's stages,
//! `ITER=1` every iteration, warning and finished stage of the affine and projective solvers.
//!
//! A run succeeds when its final RMS is within 1e-6 (relative) of the best known projective
//! optimum, or within half a unit of its sixth decimal (the published figures' precision:
//! below an RMS of 0.5 px the relative test would ask for more digits than are known). Times are for the whole chain (affine + projective), one start.

use std::time::Instant;

mod common;

use rank3::completion::{CompletionConfig, Init, complete};
use rank3::projective::{AffineStart, Bridge, ProjectiveConfig, fit};

fn quantile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    if v.is_empty() {
        return f64::NAN;
    }
    v[((v.len() - 1) as f64 * q).round() as usize]
}

fn variant(name: &str) -> Option<ProjectiveConfig> {
    let mut cfg = ProjectiveConfig {
        sturm_triggs: false,
        ..ProjectiveConfig::default()
    };
    // `CHAIN^E1^E2…`: the chain, then escapes from its adjusted end
    // (`ProjectiveConfig::escapes`), each `poseETA` or `direct`.
    if name == "default" {
        common::adjustment_knobs(&mut cfg.refine);
        return Some(cfg);
    }
    let mut parts = name.split('^');
    let name = parts.next()?;
    let (base, joint) = match name.strip_suffix("-joint") {
        Some(b) => (b, true),
        None => (name, false),
    };
    let bridge = |b: &str| -> Option<Bridge> {
        Some(if b == "direct" {
            Bridge::Direct
        } else {
            Bridge::Pose {
                eta: b.strip_prefix("pose")?.parse().ok()?,
            }
        })
    };
    // `A+B`: two chains from each start, the lower kept; `A` alone: one chain.
    let (first, second) = match base.split_once('+') {
        Some((a, b)) => (bridge(a)?, Some(bridge(b)?)),
        None => (bridge(base)?, None),
    };
    cfg.bridge = first;
    cfg.second_bridge = second;
    cfg.escapes = parts.map(bridge).collect::<Option<Vec<_>>>()?;
    if joint {
        cfg.refine.damp_points = true;
        cfg.refine.resolve_points = false;
    }
    // Experiments: `NOISE_TOL`, `REL_TOL`, `GEO`, `EXT`, `LDEC` (`common::adjustment_knobs`).
    common::adjustment_knobs(&mut cfg.refine);
    Some(cfg)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let k: usize = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(100);
    let first_seed: u64 = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(0);
    let mut variants: Vec<String> = args.iter().skip(3).cloned().collect();
    if variants.is_empty() {
        variants = vec![
            "default".into(),
            "pose0.01+pose0.1".into(),
            "pose0.01".into(),
            "direct".into(),
        ];
    }
    let dir = rank3::datasets::dir();
    let mut cases: Vec<(String, std::path::PathBuf, f64)> = vec![
        (
            "dino_trimmed".into(),
            dir.join("dino_trimmed/M_dense.txt"),
            1.114493,
        ),
        (
            "model_house".into(),
            dir.join("model_house/matrix/M_dense.txt"),
            0.441660,
        ),
    ];
    // More matrices of the family: `MATRICES=name:path:best,name:path:best` (e.g. the other
    // data sets of ECCV 2016's Table 7, with their best known projective RMS).
    for spec in std::env::var("MATRICES").unwrap_or_default().split(',') {
        let f: Vec<&str> = spec.split(':').collect();
        if let [name, path, best] = f[..] {
            match best.parse() {
                Ok(b) => cases.push((name.into(), path.into(), b)),
                Err(_) => eprintln!("MATRICES: cannot read the best RMS of {spec:?}"),
            }
        } else if !spec.is_empty() {
            eprintln!("MATRICES: {spec:?} is not name:path:best");
        }
    }
    if std::env::var_os("ONLY_MATRICES").is_some() {
        cases.drain(..2);
    }
    println!(
        "K = {k} random starts per row (seeds {first_seed}..{}); success = final RMS within 1e-6 \
         relative of the best known projective optimum or half a unit of its sixth decimal",
        first_seed + k as u64
    );
    println!();
    println!(
        "| data set | variant | success | affine optimum reached | converged/stalled/max-it | median iterations (pOSE + BA) | median s | p90 s | best RMS | best known |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for (name, path, best_known) in cases {
        if !path.exists() {
            println!(
                "| {name} | - | data set not found at {} (set RANK3_DATASETS); skipped |",
                path.display()
            );
            continue;
        }
        let table = match rank3::TrackTable::read(&path) {
            Ok(t) => t,
            Err(e) => {
                println!("| {name} | - | cannot read: {e} |");
                continue;
            }
        };
        // A track seen in fewer than two frames constrains nothing: the pipeline sets it
        // aside (and reports it); so does the benchmark (Merton 3 has nine such tracks).
        let kept: Vec<usize> = (0..table.n_tracks())
            .filter(|&p| table.track_len(p) >= 2)
            .collect();
        if kept.len() < table.n_tracks() {
            eprintln!(
                "{name}: {} of {} tracks seen in fewer than two frames, set aside",
                table.n_tracks() - kept.len(),
                table.n_tracks()
            );
        }
        let all_frames: Vec<usize> = (0..table.n_frames()).collect();
        let meas = table.select(&all_frames, &kept).measurements();
        for v in &variants {
            let Some(cfg) = variant(v) else {
                println!("| {name} | {v} | unknown variant |");
                continue;
            };
            let (mut ok, mut affine_ok) = (0, 0);
            let (mut conv, mut stall, mut maxit) = (0, 0, 0);
            let mut times = Vec::new();
            let mut iters = Vec::new();
            let mut best = f64::INFINITY;
            let mut affine_best = f64::INFINITY;
            let mut affine_rms = Vec::new();
            let mut failed = false;
            let mut trace = common::Trace::from_env("ITER");
            // The published optima have six decimals: a run succeeds within 1e-6 of the
            // optimum (relative) or within half a unit of its last published digit.
            let tolerance = (1e-6 * best_known).max(5e-7);
            let verbose = std::env::var_os("VERBOSE").is_some();
            for seed in first_seed..first_seed + k as u64 {
                let t0 = Instant::now();
                let acfg = CompletionConfig {
                    init: Init::Random,
                    seed,
                    ..CompletionConfig::default()
                };
                let c = match complete(&meas, &acfg, &mut trace) {
                    Ok(c) => c,
                    Err(e) => {
                        println!("| {name} | {v} | affine error (seed {seed}): {e} |");
                        failed = true;
                        break;
                    }
                };
                let start = AffineStart {
                    m: c.m.as_ref(),
                    s: c.s.as_ref(),
                    t: &c.t,
                };
                let r = match fit(&meas, start, &cfg, 0, &mut trace) {
                    Ok(r) => r,
                    Err(e) => {
                        println!("| {name} | {v} | projective error (seed {seed}): {e} |");
                        failed = true;
                        break;
                    }
                };
                times.push(t0.elapsed().as_secs_f64());
                iters.push(r.stages.iter().map(|s| s.iterations).sum::<usize>() as f64);
                affine_rms.push(c.rms);
                affine_best = affine_best.min(c.rms);
                if (r.rms_px - best_known).abs() <= tolerance {
                    ok += 1;
                }
                match r.report.status {
                    rank3::SolverStatus::Converged => conv += 1,
                    rank3::SolverStatus::Stalled => stall += 1,
                    rank3::SolverStatus::MaxIterations => maxit += 1,
                }
                best = best.min(r.rms_px);
                if verbose {
                    eprintln!(
                        "{name} {v} seed {seed}: affine {:.6} ({:?}, {} it) -> {:.6} ({:?})",
                        c.rms,
                        c.report.status,
                        c.report.iterations,
                        r.rms_px,
                        r.stages
                            .iter()
                            .map(|s| format!(
                                "{} {:?} {} it {:.6} {:.6}",
                                s.stage, s.status, s.iterations, s.rms_before_px, s.rms_after_px
                            ))
                            .collect::<Vec<_>>()
                    );
                    for b in &r.bridges {
                        eprintln!(
                            "  bridge {:?}: start {:.6} px, {} it, {:.3} s, kept {}",
                            b.bridge, b.start_rms_px, b.iterations, b.seconds, b.kept
                        );
                    }
                    for e in &r.escapes {
                        eprintln!(
                            "  escape {:?} from {:.6}: bridge end {:.6} -> {:.6} px, {} it, {:.3} s, kept {}, returned {}",
                            e.bridge,
                            e.from_rms_px,
                            e.bridge_rms_px,
                            e.rms_px,
                            e.iterations,
                            e.seconds,
                            e.kept,
                            e.returned
                        );
                    }
                }
            }
            if failed {
                continue;
            }
            affine_ok += affine_rms
                .iter()
                .filter(|&&a| (a - affine_best) / affine_best <= 1e-6)
                .count();
            println!(
                "| {name} | {v} | {ok}/{k} ({:.0} %) | {affine_ok}/{k} | {conv}/{stall}/{maxit} | {:.0} | {:.3} | {:.3} | {best:.9} | {best_known} |",
                100.0 * ok as f64 / k as f64,
                quantile(&mut iters, 0.5),
                quantile(&mut times.clone(), 0.5),
                quantile(&mut times, 0.9),
            );
        }
    }
}
