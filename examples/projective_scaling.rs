//! Time and peak memory of the projective factorization as the sequence grows: a long,
//! sparse, video-like table (a camera moving along a corridor of points, each track seen
//! while it is in the field of view, strong perspective, 0.5 px noise), from 1 000 to
//! 20 000 frames, through [`rank3::projective::fit_observations`] (windowed affine start,
//! pOSE, sparse projective bundle adjustment). Each size runs in its own process so that
//! its peak resident memory (`VmHWM`) is its own.
//!
//! `cargo run --release --example projective_scaling -- [FRAMES ...] [--points-per-frame K]
//! [--max-iterations N] [--affine-windows]`
//! (default 1000 2000 5000 10000 20000; K, default 150, sets the density; N caps the bundle
//! adjustment, to measure its cost per iteration; `--affine-windows` chains affine windows,
//! cheaper than the default projective ones). The growth exponents are the log–log slopes of time and memory against the
//! number of observations between the smallest and the largest size.

use std::process::Command;
use std::time::Instant;

use nalgebra::{Matrix3, Rotation3, Vector3};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Normal};
use rank3::projective::windowed::WindowConfig;
use rank3::projective::{Observation, ProjectiveConfig, fit_observations};

mod common;
use common::peak_rss_mb;

/// Frame f's camera: K [R | −R c], moving along +x at 0.25 units per frame, looking +z
/// with a slow yaw/pitch wobble.
fn camera(f: usize) -> (Matrix3<f64>, Rotation3<f64>, Vector3<f64>) {
    let k = Matrix3::new(500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0);
    let a = f as f64;
    let r = Rotation3::from_euler_angles(
        0.05 * (a / 37.0).sin(),
        0.08 * (a / 53.0).sin(),
        0.02 * (a / 71.0).cos(),
    );
    let c = Vector3::new(0.25 * a, 0.3 * (a / 90.0).sin(), 0.2 * (a / 60.0).cos());
    (k, r, c)
}

/// The sparse table: points at depth 3–7 along the corridor, observed (with noise) in every
/// frame where they project inside the 640×480 image; a track ends when it leaves the view
/// or, with probability 3 % per frame, is lost.
fn table(frames: usize, per_frame: usize, seed: u64) -> (Vec<Observation>, usize) {
    let mut rng = StdRng::seed_from_u64(seed);
    let noise = Normal::new(0.0, 0.5).unwrap();
    let length = 0.25 * frames as f64 + 20.0;
    // A point at depth z is in view for about 2·0.64·z / 0.25 ≈ 25 frames at z = 5.
    let n = (per_frame as f64 * frames as f64 / 22.0) as usize;
    let pts: Vec<Vector3<f64>> = (0..n)
        .map(|_| {
            Vector3::new(
                rng.random_range(-10.0..length),
                rng.random_range(-1.5..1.5),
                rng.random_range(3.0..7.0),
            )
        })
        .collect();
    let cams: Vec<_> = (0..frames).map(camera).collect();
    let mut obs = Vec::new();
    let mut next_track = 0;
    for p in &pts {
        // Frames where the point is visible, in order; split at losses.
        let first = ((p[0] - 5.0) / 0.25).floor().max(0.0) as usize;
        let last = (((p[0] + 5.0) / 0.25).ceil() as usize).min(frames);
        let mut id: Option<usize> = None;
        for (f, (k, r, c)) in cams.iter().enumerate().take(last).skip(first) {
            let x = r * (p - c);
            let q = k * x;
            let (u, v) = (q[0] / q[2], q[1] / q[2]);
            let visible = x[2] > 0.5 && (0.0..640.0).contains(&u) && (0.0..480.0).contains(&v);
            if !visible || rng.random_range(0.0..1.0) < 0.03 {
                id = None;
                continue;
            }
            let t = *id.get_or_insert_with(|| {
                next_track += 1;
                next_track - 1
            });
            obs.push(Observation {
                frame: f,
                track: t,
                xy: [u + noise.sample(&mut rng), v + noise.sample(&mut rng)],
            });
        }
    }
    // Tracks seen once carry no depth: drop them and renumber.
    let mut count = vec![0usize; next_track];
    for o in &obs {
        count[o.track] += 1;
    }
    let mut map = vec![usize::MAX; next_track];
    let mut n_tracks = 0;
    for t in 0..next_track {
        if count[t] >= 2 {
            map[t] = n_tracks;
            n_tracks += 1;
        }
    }
    obs.retain(|o| count[o.track] >= 2);
    for o in &mut obs {
        o.track = map[o.track];
    }
    (obs, n_tracks)
}

/// With `VERBOSE` set, prints every solver iteration to stderr.
struct Printer;

impl rank3::Observer for Printer {
    fn on_event(&mut self, e: &rank3::Event<'_>) {
        if std::env::var_os("VERBOSE").is_none() {
            return;
        }
        if let rank3::Event::Iteration {
            solver,
            iteration,
            rms,
            lambda,
            ..
        } = e
        {
            eprintln!("{solver} {iteration} rms {rms:.6} lambda {lambda:.3e}");
        }
    }
}

/// The configuration of a run: the defaults, with `--max-iterations N` capping the bundle
/// adjustment (to measure the cost per iteration on long sequences) and `--affine-windows`
/// chaining affine windows (`WindowConfig::projective = false`) instead of projective ones.
/// `JOINT=1` in the environment uses the joint (damped points, no re-solve) bundle
/// adjustment instead of variable projection, `DIRECT=1` skips pOSE (experiments).
fn config(max_iterations: Option<usize>) -> ProjectiveConfig {
    let mut c = ProjectiveConfig::default();
    if let Some(m) = max_iterations {
        c.refine.max_iterations = m;
    }
    if std::env::var_os("JOINT").is_some() {
        c.refine.damp_points = true;
        c.refine.resolve_points = false;
    }
    if std::env::var_os("DIRECT").is_some() {
        c.bridge = rank3::projective::Bridge::Direct;
    }
    c
}

/// One size, in this process: prints one tab-separated line.
fn one(frames: usize, per_frame: usize, max_iterations: Option<usize>, affine_windows: bool) {
    let (obs, n_tracks) = table(frames, per_frame, 1);
    let t0 = Instant::now();
    let r = fit_observations(
        &obs,
        frames,
        n_tracks,
        &config(max_iterations),
        &WindowConfig {
            projective: !affine_windows,
            ..WindowConfig::default()
        },
        &mut Printer,
    );
    let seconds = t0.elapsed().as_secs_f64();
    match r {
        Ok(fit) => {
            let stage_s: Vec<String> = fit
                .stages
                .iter()
                .map(|s| format!("{} {:.1} s / {} it", s.stage, s.seconds, s.iterations))
                .collect();
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
                stage_s.join(", ")
            );
        }
        Err(e) => println!("{frames}\t{n_tracks}\t{}\terror: {e}", obs.len()),
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut per_frame = 150;
    let mut sizes = Vec::new();
    let mut child = false;
    let mut max_iterations = None;
    let mut affine_windows = false;
    let mut i = 0;
    while i < args.len() {
        match args[i].as_str() {
            "--points-per-frame" => {
                per_frame = args.get(i + 1).and_then(|a| a.parse().ok()).unwrap_or(150);
                i += 1;
            }
            "--one" => child = true,
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
            one(f, per_frame, max_iterations, affine_windows);
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
    println!(
        "| frames | tracks | observations | seconds | peak MB | bytes/obs (peak) | RMS px | Schur nnz | status | stages | BA s per solve |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
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
