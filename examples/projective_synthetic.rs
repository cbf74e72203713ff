//! Accuracy of the projective camera on synthetic perspective scenes with known truth.
//!
//! `cargo run --release --example projective_synthetic -- [SEEDS] [FIRST_SEED]`
//!
//! SEEDS scenes per cell (default 10), seeds FIRST_SEED.. (default 0). Scenes: the toy
//! house (`Shape::House`) seen by a pinhole camera on a handheld arc (`Motion::HandheldArc`),
//! 30 frames, 200 tracks, focal length `distance · image_size / 2` (the synth default).
//! Grid: camera distance 2.5 (strong perspective) and 20 (weak) object radii × missing
//! fraction 0, 0.3, 0.5, 0.7 × image noise σ = 1 px and σ = 0.
//!
//! Each scene goes through the library pipeline (`Reconstruction::from_tracks`, robust pass
//! off) with `CameraModel::Projective`, and again with `CameraModel::ScaledOrthographic` for
//! comparison. The *floor* of a scene is projective bundle adjustment
//! (`rank3::projective::refine`) started from the true cameras and points on the same
//! frames and tracks as the pipeline's fit; a run *reaches the floor* when its final RMS is
//! within 1e-6 (relative) + 1e-9 px of it. The second table compares the bridges from the
//! affine start to the projective bundle adjustment on the hardest cells.

use std::time::Instant;

use rank3::projective::{Bridge, ProjectiveConfig, ProjectiveModel, refine};
use rank3::synth::{Motion, PerspectiveTruth, Shape, SynthConfig, SynthScene, generate};
use rank3::{CameraModel, Config, NoopObserver, Reconstruction};

const FRAMES: usize = 30;
const POINTS: usize = 200;
/// Relative tolerance of "reached the floor".
const FLOOR_REL_TOL: f64 = 1e-6;
/// Absolute tolerance of "reached the floor", pixels (the noise-free floor is 0).
const FLOOR_ABS_TOL: f64 = 1e-9;

/// One cell of the grid.
#[derive(Debug, Clone, Copy)]
struct Cell {
    /// Camera distance, object radii.
    distance: f64,
    missing: f64,
    /// Image noise σ, pixels.
    noise: f64,
}

/// One run of the projective pipeline on a scene, with the scene's floor.
struct ProjectiveRun {
    /// Final RMS over observed scalars, pixels.
    rms: f64,
    /// Bundle adjustment from the truth on the same observations, pixels.
    floor: f64,
    /// `σ·sqrt(1 − dof/(2·n_obs))`, dof = 11F + 3N − 15.
    expected: f64,
    /// RMS over the kept (frame, track) pairs of ‖completed − true projection‖, pixels: all
    /// pairs, hidden pairs only.
    pred_err: (f64, f64),
    seconds: f64,
    pose_iterations: usize,
    ba_iterations: usize,
}

impl ProjectiveRun {
    fn excess(&self) -> f64 {
        self.rms - self.floor
    }
    fn tolerance(&self) -> f64 {
        FLOOR_REL_TOL * self.floor + FLOOR_ABS_TOL
    }
    fn at_floor(&self) -> bool {
        self.excess().abs() <= self.tolerance()
    }
    fn below_floor(&self) -> bool {
        self.excess() < -self.tolerance()
    }
}

/// One run of the scaled-orthographic pipeline on a scene.
struct AffineRun {
    rms: f64,
    pred_err: (f64, f64),
}

fn median(v: impl IntoIterator<Item = f64>) -> f64 {
    let mut v: Vec<f64> = v.into_iter().collect();
    v.sort_by(|a, b| a.total_cmp(b));
    if v.is_empty() {
        f64::NAN
    } else if v.len() % 2 == 1 {
        v[v.len() / 2]
    } else {
        0.5 * (v[v.len() / 2 - 1] + v[v.len() / 2])
    }
}

fn max(v: impl IntoIterator<Item = f64>) -> f64 {
    v.into_iter().fold(f64::NAN, f64::max)
}

/// Pixels: fixed point for ordinary values, scientific for tiny ones.
fn px(x: f64) -> String {
    if x.is_nan() {
        "-".into()
    } else if x != 0.0 && x.abs() < 1e-3 {
        format!("{x:.1e}")
    } else {
        format!("{x:.4}")
    }
}

fn scene(cell: Cell, seed: u64) -> Result<(SynthScene, PerspectiveTruth), String> {
    let scene = generate(&SynthConfig {
        camera: CameraModel::Perspective,
        shape: Shape::House,
        motion: Motion::HandheldArc,
        frames: FRAMES,
        points: POINTS,
        noise: cell.noise,
        missing: cell.missing,
        distance: cell.distance,
        seed,
        ..Default::default()
    })
    .map_err(|e| format!("scene: {e}"))?;
    let truth = scene
        .perspective
        .clone()
        .ok_or("scene: no perspective truth")?;
    Ok((scene, truth))
}

fn pipeline(
    scene: &SynthScene,
    camera: CameraModel,
    projective: ProjectiveConfig,
) -> Result<(Reconstruction, f64), String> {
    let cfg = Config {
        camera,
        robust: None,
        projective,
        ..Config::default()
    };
    let t0 = Instant::now();
    let rec = Reconstruction::from_tracks(&scene.table, &cfg).map_err(|e| e.to_string())?;
    Ok((rec, t0.elapsed().as_secs_f64()))
}

/// RMS over the kept (frame, track) pairs of the distance between the pipeline's completed
/// matrix and the noise-free true projection, pixels: over every pair (observed or hidden),
/// and over the hidden pairs only (NaN when there are none).
fn prediction_error(
    rec: &Reconstruction,
    scene: &SynthScene,
    truth: &PerspectiveTruth,
) -> (f64, f64) {
    let c = rec.completed_matrix();
    let (mut ss, mut n) = ([0.0; 2], [0usize; 2]);
    for &f in &rec.kept_frames {
        for &p in &rec.kept_tracks {
            let t = truth.project(f, &scene.truth.points[p]);
            let e = (c[(2 * f, p)] - t[0]).powi(2) + (c[(2 * f + 1, p)] - t[1]).powi(2);
            let hidden = usize::from(!scene.table.is_visible(f, p));
            ss[hidden] += e;
            n[hidden] += 1;
        }
    }
    let all = ((ss[0] + ss[1]) / (n[0] + n[1]).max(1) as f64).sqrt();
    let hidden = if n[1] == 0 {
        f64::NAN
    } else {
        (ss[1] / n[1] as f64).sqrt()
    };
    (all, hidden)
}

/// Projective bundle adjustment from the truth on the frames and tracks the pipeline fitted.
/// Checks that these are the pipeline's observations (its model has the same RMS on them).
fn floor(
    rec: &Reconstruction,
    scene: &SynthScene,
    truth: &PerspectiveTruth,
) -> Result<(f64, rank3::Measurements), String> {
    let meas = scene
        .table
        .select(&rec.kept_frames, &rec.kept_tracks)
        .measurements();
    let fitted = rec.projective.as_ref().ok_or("no projective result")?;
    let again = fitted.model.rms(&meas);
    if (again - rec.rms_px).abs() > 1e-9 * (1.0 + rec.rms_px) {
        return Err(format!(
            "kept frames/tracks do not reproduce the fit's RMS ({again} vs {})",
            rec.rms_px
        ));
    }
    let start = ProjectiveModel {
        cameras: rec
            .kept_frames
            .iter()
            .map(|&f| {
                let p = truth.projection(f);
                std::array::from_fn(|k| p[k / 4][k % 4])
            })
            .collect(),
        points: rec
            .kept_tracks
            .iter()
            .map(|&p| {
                let x = &scene.truth.points[p];
                [x[0], x[1], x[2], 1.0]
            })
            .collect(),
    };
    let r = refine(
        &meas,
        &start,
        &ProjectiveConfig::default(),
        0,
        &mut NoopObserver,
    )
    .map_err(|e| format!("floor: {e}"))?;
    Ok((r.rms_px, meas))
}

fn run_projective(
    scene: &SynthScene,
    truth: &PerspectiveTruth,
    cfg: ProjectiveConfig,
) -> Result<ProjectiveRun, String> {
    let (rec, seconds) = pipeline(scene, CameraModel::Projective, cfg)?;
    let (floor, meas) = floor(&rec, scene, truth)?;
    let stages = &rec
        .projective
        .as_ref()
        .ok_or("no projective result")?
        .stages;
    let iterations = |name: &str| {
        stages
            .iter()
            .filter(|s| s.stage == name)
            .map(|s| s.iterations)
            .sum()
    };
    let (f, n, obs) = (meas.n_frames(), meas.n_points(), meas.n_observed());
    let dof = (11 * f + 3 * n) as f64 - 15.0;
    Ok(ProjectiveRun {
        rms: rec.rms_px,
        floor,
        expected: scene.config.noise * (1.0 - dof / (2 * obs) as f64).max(0.0).sqrt(),
        pred_err: prediction_error(&rec, scene, truth),
        seconds,
        pose_iterations: iterations("pose"),
        ba_iterations: iterations("projective-ba"),
    })
}

fn run_affine(scene: &SynthScene, truth: &PerspectiveTruth) -> Result<AffineRun, String> {
    let (rec, _) = pipeline(
        scene,
        CameraModel::ScaledOrthographic,
        ProjectiveConfig::default(),
    )?;
    Ok(AffineRun {
        rms: rec.rms_px,
        pred_err: prediction_error(&rec, scene, truth),
    })
}

/// "reached/runs", with the count of runs below the floor when there are any.
fn floor_column(runs: &[ProjectiveRun]) -> String {
    let ok = runs.iter().filter(|r| r.at_floor()).count();
    let below = runs.iter().filter(|r| r.below_floor()).count();
    if below > 0 {
        format!("{ok}/{} ({below} below)", runs.len())
    } else {
        format!("{ok}/{}", runs.len())
    }
}

/// The largest `RMS − floor` over the runs that missed the floor ("-" when none did).
fn worst_miss(runs: &[ProjectiveRun]) -> String {
    let misses = runs.iter().filter(|r| !r.at_floor()).map(|r| r.excess());
    let worst = misses.fold(f64::NAN, |a, b| if a.abs() >= b.abs() { a } else { b });
    if worst.is_nan() {
        "-".into()
    } else {
        format!("{worst:+.2e}")
    }
}

/// Runs `run` on every seed's scene of `cell`, collecting results and error messages.
fn over_seeds<T>(
    cell: Cell,
    seeds: std::ops::Range<u64>,
    label: &str,
    errors: &mut Vec<String>,
    mut run: impl FnMut(&SynthScene, &PerspectiveTruth) -> Result<T, String>,
) -> Vec<T> {
    let mut out = Vec::new();
    for seed in seeds {
        match scene(cell, seed).and_then(|(s, t)| run(&s, &t)) {
            Ok(r) => out.push(r),
            Err(e) => errors.push(format!(
                "distance {}, missing {}, σ {}, seed {seed}, {label}: {e}",
                cell.distance, cell.missing, cell.noise
            )),
        }
    }
    out
}

fn print_errors(errors: &[String]) {
    if !errors.is_empty() {
        println!();
        println!("Errors ({}):", errors.len());
        for e in errors {
            println!("* {e}");
        }
    }
}

fn accuracy_table(seeds: std::ops::Range<u64>) {
    println!(
        "Columns: distance (object radii), missing fraction, σ (px), n = seeds that ran; RMS = \
         final RMS over observed scalars (median, max); expected = σ·sqrt(1 − dof/(2·n_obs)), \
         dof = 11F + 3N − 15 (median); floor = RMS of projective BA started from the truth \
         (median); at floor = runs within 1e-6 rel. + 1e-9 px of their floor; worst miss = \
         largest RMS − floor among the others (px); pred err = RMS over all kept (frame, track) \
         pairs, observed and hidden, of ‖completed − true projection‖ (2-D norm, px, median), and \
         over the hidden pairs only; affine = the scaled-orthographic pipeline on the same \
         scene (its final RMS over observed scalars and its pred errs, medians); time = median wall time of the \
         projective pipeline (s)."
    );
    println!();
    println!(
        "| distance | missing | σ | n | RMS median | RMS max | expected | floor | at floor | worst miss | pred err | pred err hidden | affine RMS | affine pred err | affine pred err hidden | time s |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut errors = Vec::new();
    let mut noise_free_max: f64 = 0.0;
    for noise in [1.0, 0.0] {
        for distance in [2.5, 20.0] {
            for missing in [0.0, 0.3, 0.5, 0.7] {
                let cell = Cell {
                    distance,
                    missing,
                    noise,
                };
                let runs = over_seeds(cell, seeds.clone(), "projective", &mut errors, |s, t| {
                    run_projective(s, t, ProjectiveConfig::default())
                });
                let affine = over_seeds(
                    cell,
                    seeds.clone(),
                    "scaled orthographic",
                    &mut errors,
                    run_affine,
                );
                if noise == 0.0 {
                    noise_free_max = noise_free_max.max(max(runs.iter().map(|r| r.rms)));
                }
                println!(
                    "| {distance} | {missing} | {noise} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {:.3} |",
                    runs.len(),
                    px(median(runs.iter().map(|r| r.rms))),
                    px(max(runs.iter().map(|r| r.rms))),
                    px(median(runs.iter().map(|r| r.expected))),
                    px(median(runs.iter().map(|r| r.floor))),
                    floor_column(&runs),
                    worst_miss(&runs),
                    px(median(runs.iter().map(|r| r.pred_err.0))),
                    px(median(runs.iter().map(|r| r.pred_err.1))),
                    px(median(affine.iter().map(|r| r.rms))),
                    px(median(affine.iter().map(|r| r.pred_err.0))),
                    px(median(affine.iter().map(|r| r.pred_err.1))),
                    median(runs.iter().map(|r| r.seconds)),
                );
            }
        }
    }
    println!();
    println!(
        "Noise-free (σ = 0) runs: largest final RMS {noise_free_max:.2e} px ({} 1e-9 px).",
        if noise_free_max < 1e-9 {
            "below"
        } else {
            "NOT below"
        }
    );
    print_errors(&errors);
}

fn bridge_table(seeds: std::ops::Range<u64>) {
    println!(
        "Bridges from the affine start to projective BA, distance 2.5, σ = 1. Columns: n = \
         seeds that ran; at floor and worst miss as above; RMS = final RMS (median); iterations \
         = median pOSE + projective BA iterations; time = median wall time of the pipeline (s)."
    );
    println!();
    println!(
        "| missing | bridge | n | at floor | worst miss | RMS median | pOSE it | BA it | time s |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    let bridges = [
        ("pOSE η = 0.01 (default)", Bridge::Pose { eta: 0.01 }),
        ("pOSE η = 0.1", Bridge::Pose { eta: 0.1 }),
        ("direct", Bridge::Direct),
    ];
    let mut errors = Vec::new();
    for missing in [0.5, 0.7] {
        let cell = Cell {
            distance: 2.5,
            missing,
            noise: 1.0,
        };
        for (name, bridge) in bridges {
            // Each bridge alone (one chain), to compare them.
            let cfg = ProjectiveConfig {
                bridge,
                second_bridge: None,
                ..Default::default()
            };
            let runs = over_seeds(cell, seeds.clone(), name, &mut errors, |s, t| {
                run_projective(s, t, cfg.clone())
            });
            println!(
                "| {missing} | {name} | {} | {} | {} | {} | {} | {} | {:.3} |",
                runs.len(),
                floor_column(&runs),
                worst_miss(&runs),
                px(median(runs.iter().map(|r| r.rms))),
                median(runs.iter().map(|r| r.pose_iterations as f64)),
                median(runs.iter().map(|r| r.ba_iterations as f64)),
                median(runs.iter().map(|r| r.seconds)),
            );
        }
    }
    print_errors(&errors);
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n_seeds: u64 = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(10);
    let first: u64 = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(0);
    let seeds = first..first + n_seeds;
    println!(
        "Projective camera on synthetic perspective scenes: house, handheld arc, {FRAMES} \
         frames, {POINTS} tracks, seeds {first}..{}, robust pass off.",
        first + n_seeds
    );
    println!();
    accuracy_table(seeds.clone());
    println!();
    bridge_table(seeds);
}
