//! Time and peak memory of the sparse affine pipeline ([`rank3::sparse`]) as a long,
//! sparse, video-like table grows ([`rank3::synth::corridor`]: scaled orthographic camera
//! travelling along a corridor of points, tracks alive ~30 frames, 0.5 px noise), through
//! `Reconstruction::from_tracks` with the default configuration (the sparse pipeline is
//! chosen automatically once the dense table does not fit; `--sparse` forces it). Each size
//! runs in its own process so that its peak resident memory (`VmHWM`) is its own.
//! Accuracy: reprojection RMS and structure error against the ground truth (after the best
//! similarity). `--compare` also runs the dense
//! pipeline on the same table (where it fits) and prints the largest difference of the two
//! results' structure errors.
//!
//! `cargo run --release --example sparse_scaling -- [FRAMES ...] [--per-frame K] [--sparse]
//! [--compare] [--max-solves N] [--window-tolerance T]` (default 1000 2000 5000 10000
//! 20000; K, default 150, sets the density; N caps the adjustment's linear solves, default
//! 100; T is the windows' completion tolerance, default 1e-4; `--tail-tolerance X` sets
//! `LmConfig::window_relative_tolerance`, default 1e-6). `--from-truth` also runs the
//! adjustment started at the true cameras and points.
//! The growth exponents are the log–log slopes of time and memory against the number of
//! observations between the smallest and the largest size.

use std::process::Command;
use std::time::Instant;

use rank3::eval;
use rank3::sparse::Pipeline;
use rank3::synth::{CorridorConfig, corridor};
use rank3::{Config, Reconstruction};

mod common;
use common::peak_rss_mb;

/// Structure error (RMS distance after the best similarity, reflection allowed, over the
/// RMS spread) of a reconstruction's kept tracks against the truth.
fn accuracy(r: &Reconstruction, truth: &rank3::MetricModel) -> f64 {
    let tru: Vec<_> = r.kept_tracks.iter().map(|&p| truth.points[p]).collect();
    eval::structure_error(&r.model.points, &tru)
}

/// With `VERBOSE` set, prints every solver iteration and stage to stderr, each with the
/// seconds since the reconstruction started.
struct Printer(Instant);

impl rank3::Observer for Printer {
    fn on_event(&mut self, e: &rank3::Event<'_>) {
        if std::env::var_os("VERBOSE").is_none() {
            return;
        }
        match e {
            rank3::Event::Iteration {
                solver,
                run,
                iteration,
                rms,
                lambda,
                ..
            } => eprintln!(
                "{:8.2} s {solver}[{run}] {iteration} rms {rms:.10} lambda {lambda:.3e}",
                self.0.elapsed().as_secs_f64()
            ),
            rank3::Event::StageFinished { stage, seconds } => eprintln!(
                "{:8.2} s stage {stage}: {seconds:.2} s",
                self.0.elapsed().as_secs_f64()
            ),
            _ => {}
        }
    }
}

/// The settings a run can change (`--max-solves`, `--window-tolerance`, `--tail-tolerance`,
/// `--from-truth`).
struct Tuning {
    max_solves: Option<usize>,
    window_tolerance: Option<f64>,
    tail_tolerance: Option<f64>,
    from_truth: bool,
}

fn child(frames: usize, per_frame: usize, sparse: bool, compare: bool, tuning: &Tuning) {
    let t0 = Instant::now();
    let (table, truth) = corridor(&CorridorConfig {
        frames,
        per_frame,
        ..CorridorConfig::default()
    })
    .expect("corridor");
    let gen_s = t0.elapsed().as_secs_f64();
    let mut config = Config {
        camera: rank3::CameraModel::ScaledOrthographic,
        ..Config::default()
    };
    if sparse {
        config.sparse.pipeline = Pipeline::Sparse;
    }
    if let Some(t) = tuning.window_tolerance {
        config.sparse.window.completion.function_tolerance = t;
    }
    if let Some(t) = tuning.tail_tolerance {
        config.sparse.lm.window_relative_tolerance = t;
    }
    if let Some(n) = tuning.max_solves {
        config.sparse.lm.max_iterations = n;
    }
    let t1 = Instant::now();
    let r = Reconstruction::from_tracks_observed(&table, &config, &mut Printer(Instant::now()))
        .expect("reconstruction");
    let run_s = t1.elapsed().as_secs_f64();
    let structure = accuracy(&r, &truth);
    let mut line = format!(
        "{frames:>6} frames {:>8} tracks {:>9} obs | generate {gen_s:6.2} s | reconstruct \
         {run_s:7.2} s | peak {:7.0} MB | {} | RMS {:.4} px | structure {:.3} % \
         | outliers {} | iterations {}",
        table.n_tracks(),
        table.n_observed(),
        peak_rss_mb(),
        if r.sparse.is_some() {
            "sparse"
        } else {
            "dense "
        },
        r.rms_px,
        100.0 * structure,
        r.outlier_tracks.len(),
        r.sparse.as_ref().map_or(0, |s| s.iterations),
    );
    if compare {
        let mut dense = config.clone();
        dense.sparse.pipeline = Pipeline::Dense;
        let t2 = Instant::now();
        match Reconstruction::from_tracks(&table, &dense) {
            Ok(d) => {
                let dstruct = accuracy(&d, &truth);
                line += &format!(
                    " || dense {:.2} s RMS {:.4} px structure {:.3} %",
                    t2.elapsed().as_secs_f64(),
                    d.rms_px,
                    100.0 * dstruct
                );
            }
            Err(e) => line += &format!(" || dense: {e}"),
        }
    }
    println!("{line}");
    if std::env::var_os("PROFILE").is_some() {
        for chunk in r.frames.chunks(50) {
            let worst = chunk.iter().map(|f| f.rms_px).fold(0.0, f64::max);
            println!(
                "        frames {}..: worst frame RMS {worst:.2} px",
                chunk[0].frame
            );
        }
    }
    for w in r.warnings.iter().skip(1) {
        println!("        warning: {w}");
    }
    if tuning.from_truth {
        adjust_from_truth(&table, &truth, &config);
    }
}

/// The accuracy floor: the same adjustment started at the true cameras and points (the
/// tracks the pipeline would fit: the configuration's set-aside minimums, with at least 4
/// tracks per frame as for any partial table). Prints its solves, RMS and structure error.
fn adjust_from_truth(table: &rank3::TrackTable, truth: &rank3::MetricModel, config: &Config) {
    let (kept, _, frames, tracks) = table.set_aside(
        config.min_frames_per_track,
        config.min_points_per_frame.max(4),
    );
    let prob = rank3::sparse::SparseProblem::new(&kept, true);
    let (mut cams, mut pts) = prob.cams_and_points(truth, &frames, &tracks);
    let t0 = Instant::now();
    let lm = prob
        .adjust(
            &mut cams,
            &mut pts,
            &config.sparse,
            rank3::CameraModel::ScaledOrthographic,
            0,
            &mut Printer(Instant::now()),
        )
        .expect("adjustment from the truth");
    let est: Vec<_> = pts
        .chunks_exact(3)
        .map(|x| nalgebra::Vector3::new(x[0], x[1], x[2]))
        .collect();
    let tru: Vec<_> = tracks.iter().map(|&p| truth.points[p]).collect();
    let n_res = 2.0 * kept.n_observed() as f64;
    println!(
        "        from the truth: {} solves ({:?}), {:.2} s, RMS {:.10} px, structure {:.3} %",
        lm.report.iterations,
        lm.report.status,
        t0.elapsed().as_secs_f64(),
        (lm.report.final_cost / n_res).sqrt() * prob.scale,
        100.0 * eval::structure_error(&est, &tru)
    );
}

/// The flags that take a value (passed on to each child process as given).
const VALUE_FLAGS: [&str; 4] = [
    "--per-frame",
    "--max-solves",
    "--window-tolerance",
    "--tail-tolerance",
];

/// The value after flag `name` in `args`, parsed.
fn value<T: std::str::FromStr>(args: &[String], name: &str) -> Option<T> {
    let i = args.iter().position(|a| a == name)?;
    args.get(i + 1)?.parse().ok()
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let flag = |name: &str| args.iter().any(|a| a == name);
    let per_frame = value(&args, "--per-frame").unwrap_or(150);
    let (sparse, compare) = (flag("--sparse"), flag("--compare"));
    if let Some(f) = value(&args, "--child") {
        let tuning = Tuning {
            max_solves: value(&args, "--max-solves"),
            window_tolerance: value(&args, "--window-tolerance"),
            tail_tolerance: value(&args, "--tail-tolerance"),
            from_truth: flag("--from-truth"),
        };
        child(f, per_frame, sparse, compare, &tuning);
        return;
    }
    let mut sizes: Vec<usize> = args
        .iter()
        .enumerate()
        .filter(|(i, a)| {
            !a.starts_with("--") && (*i == 0 || !VALUE_FLAGS.contains(&args[i - 1].as_str()))
        })
        .filter_map(|(_, a)| a.parse().ok())
        .collect();
    if sizes.is_empty() {
        sizes = vec![1000, 2000, 5000, 10000, 20000];
    }
    println!(
        "sparse pipeline on corridor tables ({per_frame} tracks per frame), one process per size"
    );
    let exe = std::env::current_exe().expect("exe");
    let mut points = Vec::new();
    for &f in &sizes {
        let mut cmd = Command::new(&exe);
        cmd.args(["--child", &f.to_string()]);
        for name in ["--sparse", "--compare", "--from-truth"] {
            if flag(name) {
                cmd.arg(name);
            }
        }
        for name in VALUE_FLAGS {
            if let Some(i) = args.iter().position(|a| a == name) {
                cmd.args(&args[i..(i + 2).min(args.len())]);
            }
        }
        let out = cmd.output().expect("child");
        let text = String::from_utf8_lossy(&out.stdout);
        print!("{text}");
        if !out.status.success() {
            eprintln!("{}", String::from_utf8_lossy(&out.stderr));
            continue;
        }
        let num = |key: &str| -> Option<f64> {
            let first = text.lines().next()?;
            let i = first.find(key)?;
            first[..i].split_whitespace().last()?.parse().ok()
        };
        if let (Some(obs), Some(secs), Some(mb)) = (num(" obs"), num(" s | peak"), num(" MB")) {
            points.push((obs, secs, mb));
        }
    }
    if points.len() >= 2 {
        let (a, b) = (points[0], points[points.len() - 1]);
        let slope = |ya: f64, yb: f64| (yb / ya).ln() / (b.0 / a.0).ln();
        println!(
            "growth exponents (vs observations): time {:.2}, peak memory {:.2}",
            slope(a.1, b.1),
            slope(a.2, b.2)
        );
    }
}
