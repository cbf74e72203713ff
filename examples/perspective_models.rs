//! The perspective camera's optional models measured against a truth: per-frame focal
//! lengths (a zooming camera), the radial coefficient `k₁`, both with the principal point
//! estimated, the robust losses of the metric
//! bundle adjustment on gross errors and outlier tracks, and how often `--camera auto`
//! picks the camera that made the data.
//!
//! `cargo run --release --example perspective_models -- [zoom] [distortion] [together] [loss]
//! [auto] [plane] [--seeds N] [--auto-seeds N] [--first-seed S] [--only DISTANCE,MISSING]` (default: all
//! six sections, 5 seeds per cell for all but `auto`, 20 scenes per setting for `auto`,
//! seeds from 0; `--only` runs one row of `auto`, distance 0 for the scaled orthographic
//! scenes). `VERBOSE=1` prints details per scene on stderr (`zoom`, and the wrong picks of
//! `auto`).
//!
//! Every scene: house shape, 90° turntable, 20 frames × 100 tracks, 0.5 px noise, image
//! 640×480 given (`image_size = 641×481`, principal point (320, 240), the synthetic one),
//! the library's [`Reconstruction`] with its defaults otherwise. Errors against the truth
//! (`common::perspective_errors`): focal length per frame (%), the largest rotation error
//! (°), structure = RMS point distance after the best proper similarity over the RMS spread
//! of the true points (%). Floor = the same metric bundle adjustment
//! ([`rank3::perspective::adjust`], same model) started at the true cameras and points on
//! every track, as in `perspective_benchmark`: the accuracy the data allow that model.
//! Table cells are medians over the seeds unless said otherwise.
//!
//! * `zoom`: scenes with [`SynthConfig::zoom`] (the focal length changing geometrically
//!   by `1 + zoom` over the sequence) fitted with one shared focal length and with one per
//!   frame.
//! * `distortion`: scenes with [`SynthConfig::distortion`] (`k₁`) fitted without and with
//!   the `k₁` estimate.
//! * `together`: a zooming camera with `k₁ = −0.2`, its principal point at the assumed
//!   image centre or 29 px off it, fitted with per-frame focal lengths, then `k₁` as well,
//!   then the principal point as well.
//! * `loss`: scenes with gross entries and/or outlier tracks, the metric adjustment under
//!   least squares (`Loss::Squared`), Huber (2 px) and Cauchy (2 px), the robust pass on
//!   and off; structure over the kept inlier tracks, RMS over their clean entries.
//! * `auto`: `--camera auto` (`CameraModel::Auto`) on perspective scenes from strong to
//!   weak perspective and on scaled orthographic scenes: which camera it keeps, and the
//!   structure error of what it kept.
//! * `plane`: scenes of points on one plane ([`Shape::Plane`]), turntable and handheld arc,
//!   complete and 30 % missing, with and without the planar start
//!   ([`PerspectiveConfig::planar_start`]): which start was kept, the errors, and how
//!   many (inlier) tracks the robust passes rejected.

mod common;

use std::collections::HashSet;

use common::{perspective_errors, truth_model};
use rank3::eval::{median, structure_error};
use rank3::perspective::{Loss, PerspectiveConfig, PerspectiveModel, adjust};
use rank3::synth::{Motion, OutlierKind, Shape, SynthConfig, SynthScene, generate};
use rank3::{CameraModel, Config, NoopObserver, Reconstruction};

struct Opts {
    /// `auto` rows to run: distance (0 = the scaled orthographic scenes) and missing.
    only: Option<(f64, f64)>,
    seeds: u64,
    auto_seeds: u64,
    first_seed: u64,
}

/// `VERBOSE=1`: one line per scene on stderr.
fn verbose() -> bool {
    std::env::var_os("VERBOSE").is_some()
}

fn base(seed: u64) -> SynthConfig {
    SynthConfig {
        camera: CameraModel::Perspective,
        shape: Shape::House,
        frames: 20,
        points: 100,
        noise: 0.5,
        distance: 2.5,
        seed,
        ..SynthConfig::default()
    }
}

fn config(camera: CameraModel) -> Config {
    let mut c = Config {
        camera,
        ..Config::default()
    };
    c.perspective.intrinsics.image_size = Some([641, 481]);
    c
}

/// One perspective fit scored against the truth.
struct Scored {
    focal_med: f64,
    focal_max: f64,
    rot: f64,
    structure: f64,
    rms: f64,
    k1: f64,
    principal_point: [f64; 2],
}

fn score(
    model: &PerspectiveModel,
    frames: &[usize],
    tracks: &[usize],
    rms: f64,
    s: &SynthScene,
) -> Scored {
    let e = perspective_errors(model, frames, tracks, s);
    Scored {
        focal_med: median(&e.focal),
        focal_max: e.focal.iter().copied().fold(0.0, f64::max),
        rot: e.rot_max_deg,
        structure: e.structure,
        rms,
        k1: model.k1,
        principal_point: model.principal_point,
    }
}

/// The pipeline with `cfg` on `s`, scored; `Err` with the message when it fails.
fn pipeline(s: &SynthScene, cfg: &Config) -> Result<(Reconstruction, Scored), String> {
    let rec = Reconstruction::from_tracks(&s.table, cfg).map_err(|e| e.to_string())?;
    let p = rec
        .perspective
        .as_ref()
        .ok_or_else(|| "no perspective result".to_string())?;
    assert_eq!(p.model.points.len(), rec.kept_tracks.len());
    let sc = score(&p.model, &rec.kept_frames, &rec.kept_tracks, p.rms_px, s);
    Ok((rec, sc))
}

/// The floor: `adjust` from `start` on every entry of `s`, with `pc`'s model.
fn floor(s: &SynthScene, start: &PerspectiveModel, pc: &PerspectiveConfig) -> Scored {
    let fit = adjust(&s.table.measurements(), start, pc, 0, &mut NoopObserver).expect("floor");
    let frames: Vec<usize> = (0..s.table.n_frames()).collect();
    let tracks: Vec<usize> = (0..s.table.n_tracks()).collect();
    score(&fit.model, &frames, &tracks, fit.rms_px, s)
}

fn med(rows: &[Scored], f: impl Fn(&Scored) -> f64) -> f64 {
    median(&rows.iter().map(f).collect::<Vec<_>>())
}

fn worst(rows: &[Scored], f: impl Fn(&Scored) -> f64) -> f64 {
    rows.iter().map(f).fold(0.0, f64::max)
}

/// `pipeline (floor)` of the medians, `scale` times the value.
fn pf(p: &[Scored], fl: &[Scored], scale: f64, f: impl Fn(&Scored) -> f64 + Copy) -> String {
    format!("{:.3} ({:.3})", scale * med(p, f), scale * med(fl, f))
}

fn zoom(o: &Opts) {
    println!(
        "\n### zoom: per-frame focal lengths (`per_frame_focal`) against one shared focal length\n"
    );
    println!(
        "House, turntable 90°, 20 frames × 100 tracks, 0.5 px noise, image size given; \
         focal length of frame 0 = distance · 200 px, of frame f = that · (1 + zoom)^(f/19). \
         Medians over seeds {}–{}; pipeline (floor).\n",
        o.first_seed,
        o.first_seed + o.seeds - 1
    );
    println!(
        "| zoom | distance | missing | focal model | focal err % median over frames | focal err % max over frames | rotation err ° (max) | structure err % | RMS px | worst seed: structure err % | failed |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for &(zoom, distance, missing) in &[
        (0.0, 2.5, 0.0),
        (0.5, 2.5, 0.0),
        (-0.3, 2.5, 0.0),
        (0.0, 2.5, 0.3),
        (0.5, 2.5, 0.3),
        (0.5, 4.0, 0.0),
        (0.0, 4.0, 0.0),
    ] {
        for per_frame in [false, true] {
            let (mut p, mut fl, mut failed) = (Vec::new(), Vec::new(), 0);
            for seed in o.first_seed..o.first_seed + o.seeds {
                let s = generate(&SynthConfig {
                    zoom,
                    distance,
                    missing,
                    ..base(seed)
                })
                .expect("scene");
                let mut cfg = config(CameraModel::Perspective);
                cfg.perspective.per_frame_focal = per_frame;
                match pipeline(&s, &cfg) {
                    Ok((rec, sc)) => {
                        if verbose() {
                            let pm = &rec.perspective.as_ref().expect("checked").model;
                            eprintln!(
                                "zoom {zoom} distance {distance} missing {missing} per-frame \
                                 {per_frame} seed {seed}: frames {} tracks {}, focal max {:.3} %, \
                                 rotation {:.3}°, RMS {:.4} px, focal px {:?}",
                                rec.kept_frames.len(),
                                rec.kept_tracks.len(),
                                100.0 * sc.focal_max,
                                sc.rot,
                                sc.rms,
                                pm.focal_px.iter().map(|f| f.round()).collect::<Vec<_>>()
                            );
                            let p = rec.perspective.as_ref().expect("checked");
                            for st in &p.stages {
                                eprintln!(
                                    "  stage {} {:?} {} iterations, RMS {:.4} → {:.4} px",
                                    st.stage,
                                    st.status,
                                    st.iterations,
                                    st.rms_before_px,
                                    st.rms_after_px
                                );
                            }
                            for st in &p.starts {
                                eprintln!(
                                    "  start {} focal {:.0} mirrored {} screened RMS {:.4}{}",
                                    st.kind,
                                    st.focal_px,
                                    st.mirrored,
                                    st.rms_px,
                                    if st.chosen { " (chosen)" } else { "" }
                                );
                            }
                            if let Some(r) = &rec.robust {
                                eprintln!(
                                    "  robust pass: {} outlier tracks {:?}, {} flagged entries \
                                     (frame, track) {:?}",
                                    r.n_outlier_tracks,
                                    r.outlier_tracks,
                                    r.n_flagged_entries,
                                    r.flagged_indices
                                );
                                eprintln!("  projective verdict: {:?}", r.projective);
                            }
                            let per_frame_tracks: Vec<usize> = rec
                                .kept_frames
                                .iter()
                                .map(|&f| {
                                    rec.kept_tracks
                                        .iter()
                                        .filter(|&&t| s.table.is_visible(f, t))
                                        .count()
                                })
                                .collect();
                            eprintln!("  kept tracks per frame {per_frame_tracks:?}");
                            // The adjustment from the truth on exactly the entries the
                            // pipeline fitted: same data, so a lower cost there means the
                            // pipeline stopped in another minimum.
                            let mut t = s.table.clone();
                            if let Some(r) = &rec.robust {
                                for &(f, p) in &r.flagged_indices {
                                    t.unset(f, p);
                                }
                            }
                            let t = t.select(&rec.kept_frames, &rec.kept_tracks);
                            let mut start = truth_model(&s);
                            start.points =
                                rec.kept_tracks.iter().map(|&p| s.truth.points[p]).collect();
                            let fit = adjust(
                                &t.measurements(),
                                &start,
                                &cfg.perspective,
                                0,
                                &mut NoopObserver,
                            )
                            .expect("floor on the kept entries");
                            let e = perspective_errors(
                                &fit.model,
                                &rec.kept_frames,
                                &rec.kept_tracks,
                                &s,
                            );
                            eprintln!(
                                "  from the truth on the same entries: RMS {:.6} px (pipeline \
                                 {:.6}), focal max {:.3} %, rotation {:.3}°, focal px {:?}",
                                fit.rms_px,
                                p.rms_px,
                                100.0 * e.focal.iter().copied().fold(0.0, f64::max),
                                e.rot_max_deg,
                                fit.model
                                    .focal_px
                                    .iter()
                                    .map(|f| f.round())
                                    .collect::<Vec<_>>()
                            );
                        }
                        p.push(sc)
                    }
                    Err(e) => {
                        eprintln!("zoom {zoom} distance {distance} seed {seed}: {e}");
                        failed += 1;
                        continue;
                    }
                }
                // The shared model's floor starts at the geometric mean of the true focals.
                let mut start = truth_model(&s);
                if !per_frame {
                    let g = (start.focal_px.iter().map(|f| f.ln()).sum::<f64>()
                        / start.focal_px.len() as f64)
                        .exp();
                    start.focal_px.iter_mut().for_each(|f| *f = g);
                }
                let f = floor(&s, &start, &cfg.perspective);
                if verbose() {
                    eprintln!(
                        "  floor: focal max {:.3} %, rotation {:.3}°, RMS {:.4} px",
                        100.0 * f.focal_max,
                        f.rot,
                        f.rms
                    );
                }
                fl.push(f);
            }
            println!(
                "| {zoom} | {distance} | {missing} | {} | {} | {} | {} | {} | {} | {:.3} ({:.3}) | {failed} |",
                if per_frame { "per frame" } else { "shared" },
                pf(&p, &fl, 100.0, |r| r.focal_med),
                pf(&p, &fl, 100.0, |r| r.focal_max),
                pf(&p, &fl, 1.0, |r| r.rot),
                pf(&p, &fl, 100.0, |r| r.structure),
                pf(&p, &fl, 1.0, |r| r.rms),
                100.0 * worst(&p, |r| r.structure),
                100.0 * worst(&fl, |r| r.structure),
            );
        }
    }
}

fn distortion(o: &Opts) {
    println!("\n### distortion: the radial coefficient k₁ (`distortion`)\n");
    println!(
        "House, turntable 90°, 20 frames × 100 tracks, 0.5 px noise, image size given, focal \
         length shared (distance · 200 px); k₁ on normalised coordinates (COLMAP \
         SIMPLE_RADIAL). Medians over seeds {}–{}; pipeline (floor).\n",
        o.first_seed,
        o.first_seed + o.seeds - 1
    );
    println!(
        "| true k₁ | distance | k₁ estimated | k₁ found | k₁ error | focal err % | rotation err ° (max) | structure err % | RMS px | worst seed: structure err % | failed |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for &(k1, distance) in &[
        (0.0, 2.5),
        (-0.1, 2.5),
        (-0.25, 2.5),
        (0.15, 2.5),
        (-0.25, 4.0),
    ] {
        for estimate in [false, true] {
            let (mut p, mut fl, mut failed) = (Vec::new(), Vec::new(), 0);
            for seed in o.first_seed..o.first_seed + o.seeds {
                let s = generate(&SynthConfig {
                    distortion: k1,
                    distance,
                    ..base(seed)
                })
                .expect("scene");
                let mut cfg = config(CameraModel::Perspective);
                cfg.perspective.distortion = estimate;
                match pipeline(&s, &cfg) {
                    Ok((_, sc)) => p.push(sc),
                    Err(e) => {
                        eprintln!("k1 {k1} distance {distance} seed {seed}: {e}");
                        failed += 1;
                        continue;
                    }
                }
                // Without the k₁ estimate the adjustment holds the start's k₁: 0.
                let mut start = truth_model(&s);
                if !estimate {
                    start.k1 = 0.0;
                }
                fl.push(floor(&s, &start, &cfg.perspective));
            }
            let err = |r: &Scored| (r.k1 - k1).abs();
            println!(
                "| {k1} | {distance} | {} | {} | {} | {} | {} | {} | {} | {:.3} ({:.3}) | {failed} |",
                if estimate { "yes" } else { "no" },
                format_args!("{:.4} ({:.4})", med(&p, |r| r.k1), med(&fl, |r| r.k1)),
                format_args!("{:.4} ({:.4})", med(&p, err), med(&fl, err)),
                pf(&p, &fl, 100.0, |r| r.focal_max),
                pf(&p, &fl, 1.0, |r| r.rot),
                pf(&p, &fl, 100.0, |r| r.structure),
                pf(&p, &fl, 1.0, |r| r.rms),
                100.0 * worst(&p, |r| r.structure),
                100.0 * worst(&fl, |r| r.structure),
            );
        }
    }
}

/// Per-frame focal lengths, `k₁` and the principal point estimated together, on a zooming
/// camera with a barrel distortion, its principal point at the image centre or off it.
fn together(o: &Opts) {
    println!(
        "\n### together: per-frame focal lengths, k₁ and the principal point estimated at once\n"
    );
    println!(
        "House, turntable 90°, 20 frames × 100 tracks, 0.5 px noise, image size given (641×481, \
         centre (320, 240)); focal length 500 px at frame 0, ×1.5 over the sequence (zoom 0.5); \
         k₁ = −0.2; the principal point at the centre, or the tracks shifted by (+24, −16) px \
         (principal point (344, 224), the centre still assumed). Per-frame focal lengths in \
         every row. Medians over seeds {}–{}; pipeline (floor: the same model adjusted from \
         the truth, the fixed principal point at the assumed centre).\n",
        o.first_seed,
        o.first_seed + o.seeds - 1
    );
    println!(
        "| principal point | missing | k₁ estimated | principal point estimated | focal err % median over frames | focal err % max over frames | k₁ found | principal point err px | rotation err ° (max) | structure err % | RMS px | worst seed: structure err % | failed |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    let k1_true = -0.2;
    for &(shift, missing) in &[
        ([0.0, 0.0], 0.0),
        ([0.0, 0.0], 0.3),
        ([24.0, -16.0], 0.0),
        ([24.0, -16.0], 0.3),
    ] {
        for &(k1, pp) in &[(false, false), (true, false), (true, true)] {
            let (mut p, mut fl, mut failed) = (Vec::new(), Vec::new(), 0);
            let mut pp_true = [0.0; 2];
            for seed in o.first_seed..o.first_seed + o.seeds {
                let mut s = generate(&SynthConfig {
                    zoom: 0.5,
                    distortion: k1_true,
                    missing,
                    ..base(seed)
                })
                .expect("scene");
                s.table.translate(shift);
                let mut cfg = config(CameraModel::Perspective);
                cfg.perspective.per_frame_focal = true;
                cfg.perspective.distortion = k1;
                cfg.perspective.estimate_principal_point = pp;
                match pipeline(&s, &cfg) {
                    Ok((_, sc)) => p.push(sc),
                    Err(e) => {
                        eprintln!("shift {shift:?} missing {missing} seed {seed}: {e}");
                        failed += 1;
                        continue;
                    }
                }
                let mut start = truth_model(&s);
                let centre = start.principal_point;
                pp_true = [centre[0] + shift[0], centre[1] + shift[1]];
                // What the adjustment holds fixed it holds at the assumed value.
                if pp {
                    start.principal_point = pp_true;
                }
                if !k1 {
                    start.k1 = 0.0;
                }
                fl.push(floor(&s, &start, &cfg.perspective));
            }
            let k1_found = |r: &Scored| r.k1;
            let pp_err = |r: &Scored| {
                (r.principal_point[0] - pp_true[0]).hypot(r.principal_point[1] - pp_true[1])
            };
            println!(
                "| ({}, {}) | {missing} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {:.3} ({:.3}) | {failed} |",
                pp_true[0],
                pp_true[1],
                if k1 { "yes" } else { "no" },
                if pp { "yes" } else { "no" },
                pf(&p, &fl, 100.0, |r| r.focal_med),
                pf(&p, &fl, 100.0, |r| r.focal_max),
                format_args!("{:.4} ({:.4})", med(&p, k1_found), med(&fl, k1_found)),
                pf(&p, &fl, 1.0, pp_err),
                pf(&p, &fl, 1.0, |r| r.rot),
                pf(&p, &fl, 100.0, |r| r.structure),
                pf(&p, &fl, 1.0, |r| r.rms),
                100.0 * worst(&p, |r| r.structure),
                100.0 * worst(&fl, |r| r.structure),
            );
        }
    }
}

fn plane(o: &Opts) {
    println!("\n### plane: a planar scene, with and without the planar start\n");
    println!(
        "Points on a 2 × 2 plane (`Shape::Plane`), distance 2.5, 20 frames × 100 tracks, \
         0.5 px noise, image size given (641×481), focal length 500 px, shared and \
         self-calibrated; the pipeline's defaults (`--camera perspective`), with the planar \
         start (default) and without it (`PerspectiveConfig::planar_start = false`). Medians \
         over seeds {}–{}; pipeline (floor: the adjustment from the truth). Tracks rejected: \
         total over the seeds (every track is an inlier).\n",
        o.first_seed,
        o.first_seed + o.seeds - 1
    );
    println!(
        "| motion | missing | planar start | chosen start (seeds) | focal err % | rotation err ° (max) | structure err % | RMS px | worst seed: RMS px / focal err % | tracks rejected | failed |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for &(motion, mname) in &[
        (Motion::Turntable, "turntable 90°"),
        (Motion::HandheldArc, "handheld arc 60°"),
    ] {
        for &missing in &[0.0, 0.3] {
            for planar in [true, false] {
                let (mut p, mut fl, mut failed, mut rejected) = (Vec::new(), Vec::new(), 0, 0);
                let mut chosen: Vec<&'static str> = Vec::new();
                for seed in o.first_seed..o.first_seed + o.seeds {
                    let s = generate(&SynthConfig {
                        shape: Shape::Plane,
                        motion,
                        missing,
                        focal: Some(500.0),
                        ..base(seed)
                    })
                    .expect("scene");
                    let mut cfg = config(CameraModel::Perspective);
                    cfg.perspective.planar_start = planar;
                    match pipeline(&s, &cfg) {
                        Ok((rec, sc)) => {
                            rejected += rec.outlier_tracks.len();
                            if let Some(st) = rec
                                .perspective
                                .as_ref()
                                .and_then(|pr| pr.starts.iter().find(|st| st.chosen))
                            {
                                chosen.push(st.kind);
                            }
                            p.push(sc);
                        }
                        Err(e) => {
                            eprintln!("{mname} missing {missing} seed {seed}: {e}");
                            failed += 1;
                            continue;
                        }
                    }
                    fl.push(floor(&s, &truth_model(&s), &cfg.perspective));
                }
                let mut kinds: Vec<String> = Vec::new();
                for k in ["self-calibration", "affine", "plane"] {
                    let n = chosen.iter().filter(|&&c| c == k).count();
                    if n > 0 {
                        kinds.push(format!("{k} {n}"));
                    }
                }
                let focal_err = |r: &Scored| r.focal_med;
                println!(
                    "| {mname} | {missing} | {} | {} | {} | {} | {} | {} | {:.3} / {:.1} | {rejected} | {failed} |",
                    if planar { "yes" } else { "no" },
                    kinds.join(", "),
                    pf(&p, &fl, 100.0, focal_err),
                    pf(&p, &fl, 1.0, |r| r.rot),
                    pf(&p, &fl, 100.0, |r| r.structure),
                    pf(&p, &fl, 1.0, |r| r.rms),
                    worst(&p, |r| r.rms),
                    100.0 * worst(&p, focal_err),
                );
            }
        }
    }
}

/// RMS of `model` over the clean entries (inlier tracks, no gross error) of the fitted
/// frames and tracks, pixels.
fn inlier_rms(model: &PerspectiveModel, frames: &[usize], tracks: &[usize], s: &SynthScene) -> f64 {
    let gross: HashSet<(usize, usize)> = s.gross_entries.iter().copied().collect();
    let (mut ss, mut n) = (0.0, 0usize);
    for (k, &f) in frames.iter().enumerate() {
        for (j, &p) in tracks.iter().enumerate() {
            if s.outlier_tracks[p].is_some() || gross.contains(&(f, p)) {
                continue;
            }
            if let Some(w) = s.table.get(f, p) {
                let q = model.project(k, j);
                ss += (q[0] - w[0]).powi(2) + (q[1] - w[1]).powi(2);
                n += 2;
            }
        }
    }
    (ss / n.max(1) as f64).sqrt()
}

fn loss(o: &Opts) {
    println!(
        "\n### loss: robust losses of the metric adjustment on gross errors and outlier tracks\n"
    );
    println!(
        "House, turntable 90°, distance 2.5, 20 frames × 100 tracks, 0.5 px noise, image size \
         given, focal length shared. Gross entries: 15–60 px in a random direction; outlier \
         tracks: random walks, a second object and sliding points in turn. Structure and \
         focal errors over the kept tracks that are inliers; RMS over their clean entries. \
         Floor: the default adjustment from the truth on the clean data (outlier tracks and \
         gross entries removed). Medians over seeds {}–{}.\n",
        o.first_seed,
        o.first_seed + o.seeds - 1
    );
    println!(
        "| corruption | loss | robust pass | structure err % (floor) | focal err % (floor) | inlier RMS px (floor) | tracks kept (outliers among them) | worst seed: structure err % | metric adjustment not converged | failed |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for &(name, gross, outliers) in &[
        ("5 % gross entries", 0.05, 0.0),
        ("20 % outlier tracks", 0.0, 0.2),
        ("both", 0.05, 0.2),
    ] {
        for (lname, l) in [
            ("least squares", Loss::Squared),
            ("Huber 2 px", Loss::Huber(2.0)),
            ("Cauchy 2 px", Loss::Cauchy(2.0)),
        ] {
            for robust in [true, false] {
                let (mut p, mut fl, mut failed) = (Vec::new(), Vec::new(), 0);
                let (mut kept, mut kept_out) = (Vec::new(), Vec::new());
                // Runs whose last metric adjustment did not end `Converged`.
                let mut not_converged = 0;
                for seed in o.first_seed..o.first_seed + o.seeds {
                    let s = generate(&SynthConfig {
                        gross,
                        outliers,
                        outlier_kind: OutlierKind::Mixed,
                        ..base(seed)
                    })
                    .expect("scene");
                    let mut cfg = config(CameraModel::Perspective);
                    cfg.perspective.loss = l;
                    if !robust {
                        cfg.robust = None;
                    }
                    let rec = match Reconstruction::from_tracks(&s.table, &cfg) {
                        Ok(r) if r.perspective.is_some() => r,
                        Ok(_) => {
                            failed += 1;
                            continue;
                        }
                        Err(e) => {
                            eprintln!("{name} {lname} robust {robust} seed {seed}: {e}");
                            failed += 1;
                            continue;
                        }
                    };
                    let per = rec.perspective.as_ref().expect("checked");
                    if per
                        .stages
                        .iter()
                        .any(|st| st.status != rank3::SolverStatus::Converged)
                    {
                        not_converged += 1;
                    }
                    let pm = &per.model;
                    // The inlier tracks among the kept ones.
                    let inl: Vec<usize> = (0..rec.kept_tracks.len())
                        .filter(|&j| s.outlier_tracks[rec.kept_tracks[j]].is_none())
                        .collect();
                    let sub = PerspectiveModel {
                        points: inl.iter().map(|&j| pm.points[j]).collect(),
                        ..pm.clone()
                    };
                    let tracks: Vec<usize> = inl.iter().map(|&j| rec.kept_tracks[j]).collect();
                    let rms = inlier_rms(&sub, &rec.kept_frames, &tracks, &s);
                    p.push(score(&sub, &rec.kept_frames, &tracks, rms, &s));
                    kept.push(rec.kept_tracks.len() as f64);
                    kept_out.push((rec.kept_tracks.len() - inl.len()) as f64);
                    // Floor on the clean data.
                    let mut clean = s.table.clone();
                    for &(f, t) in &s.gross_entries {
                        clean.unset(f, t);
                    }
                    let inliers: Vec<usize> = (0..s.table.n_tracks())
                        .filter(|&t| s.outlier_tracks[t].is_none())
                        .collect();
                    let frames: Vec<usize> = (0..s.table.n_frames()).collect();
                    let clean = clean.select(&frames, &inliers);
                    let mut start = truth_model(&s);
                    start.points = inliers.iter().map(|&t| s.truth.points[t]).collect();
                    let pc = config(CameraModel::Perspective).perspective;
                    let fit = adjust(&clean.measurements(), &start, &pc, 0, &mut NoopObserver)
                        .expect("floor");
                    let rms = inlier_rms(&fit.model, &frames, &inliers, &s);
                    fl.push(score(&fit.model, &frames, &inliers, rms, &s));
                }
                println!(
                    "| {name} | {lname} | {} | {} | {} | {} | {:.0} ({:.0}) | {:.3} ({:.3}) | {not_converged} | {failed} |",
                    if robust { "on" } else { "off" },
                    pf(&p, &fl, 100.0, |r| r.structure),
                    pf(&p, &fl, 100.0, |r| r.focal_max),
                    pf(&p, &fl, 1.0, |r| r.rms),
                    median(&kept),
                    median(&kept_out),
                    100.0 * worst(&p, |r| r.structure),
                    100.0 * worst(&fl, |r| r.structure),
                );
            }
        }
    }
}

fn auto(o: &Opts) {
    println!("\n### auto: which camera `--camera auto` keeps\n");
    println!(
        "House, turntable 90°, 20 frames × 100 tracks, 0.5 px noise, image size given, \
         missing as listed; {} scenes per row (seeds {}–{}). Right = the camera that made the \
         data. Structure error of the kept model: the perspective one after the best proper \
         similarity, the scaled orthographic one after the best similarity or its mirror \
         image (its depth reversal is not determined). Δχ²/threshold of the test that \
         decided (> 1: perspective): the projective pre-test when it stopped the perspective \
         stages, else the perspective test.\n",
        o.auto_seeds,
        o.first_seed,
        o.first_seed + o.auto_seeds - 1
    );
    println!(
        "| data | missing | perspective kept | scaled orthographic kept (by the pre-test) | right | Δχ²/threshold median (min–max) | structure err % of the kept model, median (max) | scaled orthographic structure err %, median | perspective forced where auto kept the affine camera: structure err %, median (max) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    let settings: Vec<(String, Option<f64>, f64)> = vec![
        ("perspective, distance 2.5".into(), Some(2.5), 0.0),
        ("perspective, distance 4".into(), Some(4.0), 0.0),
        ("perspective, distance 8".into(), Some(8.0), 0.0),
        ("perspective, distance 15".into(), Some(15.0), 0.0),
        ("perspective, distance 30".into(), Some(30.0), 0.0),
        ("perspective, distance 45".into(), Some(45.0), 0.0),
        ("perspective, distance 60".into(), Some(60.0), 0.0),
        ("perspective, distance 100".into(), Some(100.0), 0.0),
        ("scaled orthographic".into(), None, 0.0),
        ("perspective, distance 2.5".into(), Some(2.5), 0.3),
        ("perspective, distance 8".into(), Some(8.0), 0.3),
        ("perspective, distance 15".into(), Some(15.0), 0.3),
        ("perspective, distance 30".into(), Some(30.0), 0.3),
        ("perspective, distance 60".into(), Some(60.0), 0.3),
        ("scaled orthographic".into(), None, 0.3),
    ];
    for (name, distance, missing) in settings {
        if let Some((d, m)) = o.only
            && (d != distance.unwrap_or(0.0) || m != missing)
        {
            continue;
        }
        let (mut n_persp, mut n_aff, mut n_pre, mut right, mut failed) = (0, 0, 0, 0, 0);
        let (mut ratio, mut chosen_err, mut aff_err, mut forced_err) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for seed in o.first_seed..o.first_seed + o.auto_seeds {
            let s = generate(&SynthConfig {
                camera: if distance.is_some() {
                    CameraModel::Perspective
                } else {
                    CameraModel::ScaledOrthographic
                },
                distance: distance.unwrap_or(rank3::synth::DEFAULT_DISTANCE),
                missing,
                ..base(seed)
            })
            .expect("scene");
            let rec = match Reconstruction::from_tracks(&s.table, &config(CameraModel::Auto)) {
                Ok(r) => r,
                Err(e) => {
                    eprintln!("{name} missing {missing} seed {seed}: {e}");
                    failed += 1;
                    continue;
                }
            };
            let tp: Vec<_> = rec.kept_tracks.iter().map(|&p| s.truth.points[p]).collect();
            let affine = structure_error(&rec.model.points, &tp);
            aff_err.push(100.0 * affine);
            if let Some(sel) = &rec.model_selection {
                ratio.push(sel.delta_chi2 / sel.threshold);
                if sel.perspective_rms_px.is_none() && sel.reason.contains("skipped") {
                    n_pre += 1;
                }
            }
            let persp = rec.camera_model == CameraModel::Perspective;
            if verbose() && persp != distance.is_some() {
                eprintln!(
                    "{name} missing {missing} seed {seed}: kept {:?}: {}; warnings {:?}",
                    rec.camera_model,
                    rec.model_selection
                        .as_ref()
                        .map_or(String::new(), |m| m.reason.clone()),
                    rec.warnings
                );
            }
            if persp {
                n_persp += 1;
                let p = rec.perspective.as_ref().expect("perspective kept");
                let e = perspective_errors(&p.model, &rec.kept_frames, &rec.kept_tracks, &s);
                chosen_err.push(100.0 * e.structure);
            } else {
                n_aff += 1;
                chosen_err.push(100.0 * affine);
                if distance.is_some() {
                    let forced = pipeline(&s, &config(CameraModel::Perspective));
                    match forced {
                        Ok((_, sc)) => forced_err.push(100.0 * sc.structure),
                        Err(e) => eprintln!("{name} seed {seed}: forced perspective: {e}"),
                    }
                }
            }
            if persp == distance.is_some() {
                right += 1;
            }
        }
        let mm = |v: &[f64]| {
            if v.is_empty() {
                "–".to_string()
            } else {
                format!(
                    "{:.3} ({:.3})",
                    median(v),
                    v.iter().copied().fold(f64::MIN, f64::max)
                )
            }
        };
        let total = n_persp + n_aff;
        println!(
            "| {name} | {missing} | {n_persp} | {n_aff} ({n_pre}) | {right}/{total}{} | {:.3} ({:.3}–{:.3}) | {} | {:.3} | {} |",
            if failed > 0 {
                format!(", {failed} failed")
            } else {
                String::new()
            },
            median(&ratio),
            ratio.iter().copied().fold(f64::MAX, f64::min),
            ratio.iter().copied().fold(f64::MIN, f64::max),
            mm(&chosen_err),
            median(&aff_err),
            mm(&forced_err),
        );
    }
}

fn main() {
    let mut opts = Opts {
        only: None,
        seeds: 5,
        auto_seeds: 20,
        first_seed: 0,
    };
    let mut sections = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut num = |name: &str| -> u64 {
            args.next()
                .and_then(|v| v.parse().ok())
                .unwrap_or_else(|| panic!("{name} needs a number"))
        };
        match a.as_str() {
            "--seeds" => opts.seeds = num("--seeds").max(1),
            "--auto-seeds" => opts.auto_seeds = num("--auto-seeds").max(1),
            "--first-seed" => opts.first_seed = num("--first-seed"),
            "--only" => {
                let v: Vec<f64> = args
                    .next()
                    .unwrap_or_default()
                    .split(',')
                    .filter_map(|x| x.parse().ok())
                    .collect();
                assert!(v.len() == 2, "--only DISTANCE,MISSING");
                opts.only = Some((v[0], v[1]));
            }
            "zoom" | "distortion" | "together" | "loss" | "auto" | "plane" => sections.push(a),
            other => panic!(
                "unknown argument {other}: [zoom] [distortion] [together] [loss] [auto] [plane] [--seeds N] \
                 [--auto-seeds N] [--first-seed S] [--only DISTANCE,MISSING]"
            ),
        }
    }
    let want = |k: &str| sections.is_empty() || sections.iter().any(|a| a == k);
    let t0 = std::time::Instant::now();
    if want("zoom") {
        zoom(&opts);
    }
    if want("distortion") {
        distortion(&opts);
    }
    if want("together") {
        together(&opts);
    }
    if want("loss") {
        loss(&opts);
    }
    if want("auto") {
        auto(&opts);
    }
    if want("plane") {
        plane(&opts);
    }
    eprintln!(
        "total {:.1} s, peak memory {:.0} MB",
        t0.elapsed().as_secs_f64(),
        common::peak_rss_mb()
    );
}
