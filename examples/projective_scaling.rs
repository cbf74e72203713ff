//! Time and peak memory of the projective factorization as the sequence grows: a long,
//! sparse, video-like table (a camera moving along a corridor of points, each track seen
//! while it is in the field of view, strong perspective, 0.5 px noise), from 1 000 to
//! 20 000 frames, through [`rank3::projective::fit_observations`] (windowed affine start,
//! pOSE, sparse projective bundle adjustment). Each size runs in its own process so that
//! its peak resident memory (`VmHWM`) is its own.
//!
//! `cargo run --release --example projective_scaling -- [FRAMES ...] [--points-per-frame K]
//! [--max-iterations N] [--affine-windows] [--perspective [--focal PX] [--from-truth]]`
//! (default 1000 2000 5000 10000 20000; K, default 150, sets the density; N caps the bundle
//! adjustment, to measure its cost per iteration; `--affine-windows` chains affine windows,
//! cheaper than the default projective ones; `--perspective` runs the metric perspective
//! chain instead, [`rank3::perspective::fit_observations`], and scores its focal length and
//! structure against the truth, the focal length self-calibrated unless `--focal` gives
//! it; with `--from-truth` (and `--one`) the same metric adjustment is also run started at
//! the true cameras, focal length and points — the accuracy floor — and scored alike). The
//! growth exponents are the log–log slopes of time and memory against the number of
//! observations between the smallest and the largest size.

use std::process::Command;
use std::time::Instant;

use nalgebra::Vector3;
use rank3::eval::align_similarity;
use rank3::perspective::PerspectiveConfig;
use rank3::projective::windowed::WindowConfig;
use rank3::projective::{Observation, ProjectiveConfig, fit_observations};

mod common;
use common::peak_rss_mb;

/// The corridor table ([`rank3::synth::perspective_corridor`], 0.5 px noise).
fn table(frames: usize, per_frame: usize, seed: u64) -> (Vec<Observation>, Vec<Vector3<f64>>) {
    rank3::synth::perspective_corridor(frames, per_frame, 0.5, seed)
}

/// `stage seconds / iterations` for each stage, comma-separated.
fn stage_summary(stages: &[rank3::projective::StageReport]) -> String {
    stages
        .iter()
        .map(|s| format!("{} {:.1} s / {} it", s.stage, s.seconds, s.iterations))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The configuration of a run: the defaults, with `--max-iterations N` capping the bundle
/// adjustment (to measure the cost per iteration on long sequences) and `--affine-windows`
/// chaining affine windows (`WindowConfig::projective = false`) instead of projective ones.
/// `JOINT=1` in the environment uses the joint (damped points, no re-solve) bundle
/// adjustment instead of variable projection, `DIRECT=1` skips pOSE, `NOISE_TOL`, `REL_TOL`,
/// `GEO`, `EXT` and `LDEC` set the adjustment's knobs (`common::adjustment_knobs`),
/// `DRIFT=r` the windows' drift test
/// (`WindowConfig::drift_ratio`; 0: always place the windows on the metric reference,
/// negative: never), and `METRIC_START=1`
/// starts the adjustment from the metric chain's cameras (experiments).
fn config(max_iterations: Option<usize>) -> ProjectiveConfig {
    let mut c = ProjectiveConfig::default();
    if let Some(m) = max_iterations {
        c.refine.max_iterations = m;
    }
    if std::env::var_os("JOINT").is_some() {
        c.refine.damp_points = true;
        c.refine.resolve_points = false;
    }
    common::adjustment_knobs(&mut c.refine);
    if std::env::var_os("DIRECT").is_some() {
        c.bridge = rank3::projective::Bridge::Direct;
    }
    c
}

/// One size, in this process: prints one tab-separated line.
fn one(frames: usize, per_frame: usize, max_iterations: Option<usize>, affine_windows: bool) {
    let (obs, truth) = table(frames, per_frame, 1);
    let n_tracks = truth.len();
    let t0 = Instant::now();
    let r = if std::env::var_os("METRIC_START").is_some() {
        metric_start(&obs, frames, n_tracks, &config(max_iterations))
    } else {
        fit_observations(
            &obs,
            frames,
            n_tracks,
            &config(max_iterations),
            &WindowConfig {
                projective: !affine_windows,
                drift_ratio: match common::env::<f64>("DRIFT") {
                    Some(r) if r < 0.0 => None,
                    Some(r) => Some(r),
                    None => WindowConfig::default().drift_ratio,
                },
                ..WindowConfig::default()
            },
            &mut common::Trace::from_env("VERBOSE"),
        )
    };
    let seconds = t0.elapsed().as_secs_f64();
    match r {
        Ok(fit) => {
            let stage_s = stage_summary(&fit.stages);
            let ba = fit
                .stages
                .last()
                .map_or(f64::NAN, |s| s.seconds / s.iterations.max(1) as f64);
            println!(
                "{frames}\t{n_tracks}\t{}\t{seconds:.2}\t{:.1}\t{:.4}\t{}\t{:?}\t{}\t{ba:.3}",
                obs.len(),
                peak_rss_mb(),
                fit.rms_px,
                fit.schur_nnz,
                fit.report.status,
                stage_s
            );
        }
        Err(e) => println!("{frames}\t{n_tracks}\t{}\terror: {e}", obs.len()),
    }
}

/// Experiment: the projective adjustment started from the metric chain's cameras `K[R|t]`.
fn metric_start(
    obs: &[Observation],
    frames: usize,
    n_tracks: usize,
    cfg: &ProjectiveConfig,
) -> rank3::Result<rank3::projective::ProjectiveFit> {
    let mut pcfg = PerspectiveConfig::default();
    pcfg.intrinsics.image_size = Some([640, 480]);
    let t0 = Instant::now();
    let m = rank3::perspective::fit_observations(
        obs,
        frames,
        n_tracks,
        &pcfg,
        cfg,
        &WindowConfig::default(),
        &mut common::Trace::from_env("VERBOSE"),
    )?;
    let metric_s = t0.elapsed().as_secs_f64();
    let start = rank3::projective::ProjectiveModel {
        cameras: (0..frames).map(|f| m.model.camera_matrix(f)).collect(),
        points: m
            .model
            .points
            .iter()
            .map(|x| [x[0], x[1], x[2], 1.0])
            .collect(),
    };
    let mut fit = rank3::projective::refine_observations(
        obs,
        frames,
        n_tracks,
        &start,
        cfg,
        &mut common::Trace::from_env("VERBOSE"),
    )?;
    fit.stages.insert(
        0,
        rank3::projective::StageReport {
            stage: format!("metric ({} it, rms {:.4})", m.report.iterations, m.rms_px),
            status: m.report.status,
            iterations: m.report.iterations,
            rms_before_px: f64::NAN,
            rms_after_px: m.rms_px,
            seconds: metric_s,
            linear_solver: None,
            cg_iterations: 0,
        },
    );
    Ok(fit)
}

/// One size through the perspective chain ([`rank3::perspective::fit_observations`]:
/// metric windows chained by similarities, sparse metric bundle adjustment),
/// image size given (640×480), the focal length self-calibrated unless `focal` is given
/// (true focal length 500 px). Prints one tab-separated line: frames, tracks,
/// observations, seconds, peak MB, RMS px, focal px, focal error %, structure error %
/// (after the best similarity, of the true points' spread), status, stages.
fn one_perspective(frames: usize, per_frame: usize, focal: Option<f64>, from_truth: bool) {
    let (obs, truth) = table(frames, per_frame, 1);
    let n_tracks = truth.len();
    let mut cfg = PerspectiveConfig::default();
    if std::env::var_os("NO_IMAGE_SIZE").is_none() {
        cfg.intrinsics.image_size = Some([640, 480]);
    }
    cfg.intrinsics.focal_px = focal;
    let t0 = Instant::now();
    let r = rank3::perspective::fit_observations(
        &obs,
        frames,
        n_tracks,
        &cfg,
        &config(None),
        &WindowConfig::default(),
        &mut common::Trace::from_env("VERBOSE"),
    );
    let seconds = t0.elapsed().as_secs_f64();
    match r {
        Ok(fit) => {
            let stage_s = stage_summary(&fit.stages);
            let f = fit.model.focal_px[0];
            let structure = align_similarity(&fit.model.points, &truth, false)
                .map_or(f64::NAN, |a| 100.0 * a.relative_rms);
            println!(
                "{frames}\t{n_tracks}\t{}\t{seconds:.2}\t{:.1}\t{:.4}\t{f:.2}\t{:.3}\t{structure:.3}\t{:?}\t{}",
                obs.len(),
                peak_rss_mb(),
                fit.rms_px,
                100.0 * (f - 500.0).abs() / 500.0,
                fit.report.status,
                stage_s
            );
        }
        Err(e) => println!("{frames}\t{n_tracks}\t{}\terror: {e}", obs.len()),
    }
    if from_truth {
        // The same adjustment started at the truth: K (500 px, principal point (320, 240)),
        // R_f, t_f = −R_f c_f and the true points.
        let cams: Vec<_> = (0..frames)
            .map(rank3::synth::perspective_corridor_camera)
            .collect();
        let start = rank3::perspective::PerspectiveModel {
            focal_px: vec![focal.unwrap_or(500.0); frames],
            principal_point: [320.0, 240.0],
            k1: 0.0,
            aspect: 1.0,
            rotations: cams.iter().map(|(_, r, _)| *r.matrix()).collect(),
            translations: cams.iter().map(|(_, r, c)| -(r * c)).collect(),
            points: truth.clone(),
        };
        let t0 = Instant::now();
        match rank3::perspective::refine_observations(
            &obs,
            frames,
            n_tracks,
            &start,
            &cfg,
            &mut common::Trace::from_env("VERBOSE"),
        ) {
            Ok(fit) => {
                let f = fit.model.focal_px[0];
                let structure = align_similarity(&fit.model.points, &truth, false)
                    .map_or(f64::NAN, |a| 100.0 * a.relative_rms);
                println!(
                    "from the truth: {:.2} s, {} iterations, {:?}, RMS {:.9} px, focal {f:.2} px \
                     ({:.3} %), structure error {structure:.3} %",
                    t0.elapsed().as_secs_f64(),
                    fit.report.iterations,
                    fit.report.status,
                    fit.rms_px,
                    100.0 * (f - 500.0).abs() / 500.0
                );
            }
            Err(e) => println!("from the truth: error: {e}"),
        }
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut per_frame = 150;
    let mut sizes = Vec::new();
    let mut child = false;
    let mut max_iterations = None;
    let mut affine_windows = false;
    let mut perspective = false;
    let mut focal = None;
    let mut from_truth = false;
    let mut i = 0;
    while i < args.len() {
        match args[i].as_str() {
            "--points-per-frame" => {
                per_frame = args.get(i + 1).and_then(|a| a.parse().ok()).unwrap_or(150);
                i += 1;
            }
            "--one" => child = true,
            "--perspective" => perspective = true,
            "--from-truth" => from_truth = true,
            "--focal" => {
                focal = args.get(i + 1).and_then(|a| a.parse().ok());
                i += 1;
            }
            "--affine-windows" => affine_windows = true,
            "--max-iterations" => {
                max_iterations = args.get(i + 1).and_then(|a| a.parse().ok());
                i += 1;
            }
            a => sizes.extend(a.parse::<usize>().ok()),
        }
        i += 1;
    }
    if child {
        for &f in &sizes {
            if perspective {
                one_perspective(f, per_frame, focal, from_truth);
            } else {
                one(f, per_frame, max_iterations, affine_windows);
            }
        }
        return;
    }
    if sizes.is_empty() {
        sizes = vec![1000, 2000, 5000, 10000, 20000];
    }
    println!(
        "Long sparse perspective sequences (≈{per_frame} tracks per frame, tracks 2–40 frames, \
         0.5 px noise); one process per size; peak = VmHWM of that process."
    );
    println!();
    if perspective {
        println!(
            "| frames | tracks | observations | seconds | peak MB | bytes/obs (peak) | RMS px | focal px | focal err % | structure err % | status | stages |"
        );
        println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    } else {
        println!(
            "| frames | tracks | observations | seconds | peak MB | bytes/obs (peak) | RMS px | Schur nnz | status | stages | BA s per solve |"
        );
        println!("|---|---|---|---|---|---|---|---|---|---|---|");
    }
    let exe = std::env::current_exe().expect("current executable");
    let mut rows = Vec::new();
    for f in sizes {
        let mut cmd = Command::new(&exe);
        cmd.args([
            "--one",
            &f.to_string(),
            "--points-per-frame",
            &per_frame.to_string(),
        ]);
        if let Some(m) = max_iterations {
            cmd.args(["--max-iterations", &m.to_string()]);
        }
        if affine_windows {
            cmd.arg("--affine-windows");
        }
        if perspective {
            cmd.arg("--perspective");
        }
        if let Some(f) = focal {
            cmd.args(["--focal", &f.to_string()]);
        }
        let out = cmd.output().expect("run a size");
        let line = String::from_utf8_lossy(&out.stdout).trim().to_string();
        let c: Vec<&str> = line.split('\t').collect();
        if c.len() < 9 {
            println!("| {f} | {} |", line.replace('\t', " | "));
            continue;
        }
        let (nobs, secs, mb): (f64, f64, f64) = (
            c[2].parse().unwrap_or(f64::NAN),
            c[3].parse().unwrap_or(f64::NAN),
            c[4].parse().unwrap_or(f64::NAN),
        );
        let rest: Vec<&str> = c[5..].to_vec();
        if perspective {
            println!(
                "| {} | {} | {} | {:.2} | {:.0} | {:.0} | {} |",
                c[0],
                c[1],
                c[2],
                secs,
                mb,
                mb * 1048576.0 / nobs,
                rest.join(" | ")
            );
            rows.push((nobs, secs, mb));
            continue;
        }
        println!(
            "| {} | {} | {} | {:.2} | {:.0} | {:.0} | {} | {} | {} | {} | {} |",
            c[0],
            c[1],
            c[2],
            secs,
            mb,
            mb * 1048576.0 / nobs,
            c[5],
            c[6],
            c[7],
            c[8],
            c.get(9).unwrap_or(&"")
        );
        rows.push((nobs, secs, mb));
    }
    if let (Some(a), Some(b)) = (rows.first(), rows.last())
        && b.0 > a.0
    {
        let k = (b.0 / a.0).ln();
        println!();
        println!(
            "growth exponents (log–log, smallest → largest): time {:.2}, peak memory {:.2}",
            (b.1 / a.1).ln() / k,
            (b.2 / a.2).ln() / k
        );
    }
}
