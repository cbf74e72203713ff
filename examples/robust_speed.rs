//! Cost of the robust pass next to the rest of the pipeline.
//!
//! `cargo run --release --example robust_speed`
//!
//! On the synthetic 100-frame × 2000-track table (20 % outlier tracks, 2 % gross entries,
//! 0.5 px noise, seed 1) it times `robust_filter` (default settings, RNG seed 1) against
//! `Reconstruction::from_tracks` with `robust: None` on the same scene generated without
//! outliers and gross errors (factorization + metric upgrade, then the same with the LM
//! refinement: the rest of the pipeline). Also a 40 %-missing variant and a small 30 × 300
//! table. Each figure is the best of `REPEATS` runs (the machine may be shared).

use std::time::Instant;

use rand::SeedableRng;
use rand::rngs::StdRng;
use rank3::robust::{RobustConfig, RobustResult, robust_filter};
use rank3::synth::{SynthConfig, SynthScene, generate};
use rank3::{Config, Reconstruction};

const REPEATS: usize = 3;

fn best_of<T>(mut f: impl FnMut() -> T) -> (f64, T) {
    let mut best = f64::INFINITY;
    let mut out = None;
    for _ in 0..REPEATS {
        let t0 = Instant::now();
        let r = f();
        best = best.min(t0.elapsed().as_secs_f64());
        out = Some(r);
    }
    (best, out.expect("REPEATS ≥ 1"))
}

fn accuracy(scene: &SynthScene, r: &RobustResult) -> (f64, f64) {
    let n = r.inlier_tracks.len();
    let truth_out: Vec<bool> = scene.outlier_tracks.iter().map(|o| o.is_some()).collect();
    let flagged = (0..n).filter(|&p| !r.inlier_tracks[p]).count();
    let actual = truth_out.iter().filter(|&&b| b).count();
    let tp = (0..n)
        .filter(|&p| !r.inlier_tracks[p] && truth_out[p])
        .count();
    let ratio = |a: usize, b: usize| if b == 0 { 1.0 } else { a as f64 / b as f64 };
    (ratio(tp, flagged), ratio(tp, actual))
}

fn run(label: &str, sc: &SynthConfig) -> Result<(), Box<dyn std::error::Error>> {
    let scene = generate(sc)?;
    let clean = generate(&SynthConfig {
        outliers: 0.0,
        gross: 0.0,
        ..sc.clone()
    })?;
    let meas = scene.table.measurements();
    let cfg = RobustConfig::default();
    let (t_rob, r) = best_of(|| robust_filter(&meas, &cfg, &mut StdRng::seed_from_u64(1)));
    let r = r?;
    let (t_fact, rec) = best_of(|| {
        Reconstruction::from_tracks(
            &clean.table,
            &Config {
                robust: None,
                refine: None,
                ..Config::default()
            },
        )
    });
    rec?;
    let (t_full, rec) = best_of(|| {
        Reconstruction::from_tracks(
            &clean.table,
            &Config {
                robust: None,
                ..Config::default()
            },
        )
    });
    rec?;
    let (p, rc) = accuracy(&scene, &r);
    println!(
        "| {label} | {t_rob:.3} | {t_fact:.3} | {t_full:.3} | {:.2} | {} ({} scale) | {} | {} | {p:.3} | {rc:.3} |",
        t_rob / t_full,
        r.ransac.iterations,
        r.ransac.scale_iterations,
        r.n_inliers(),
        r.flagged_entries.len(),
    );
    Ok(())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    println!(
        "| table | robust (s) | fact. + metric (s) | whole pipeline, no robust (s) | robust / pipeline | hypotheses | inliers | flagged entries | track P | track R |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    let big = SynthConfig {
        frames: 100,
        points: 2000,
        outliers: 0.2,
        gross: 0.02,
        noise: 0.5,
        seed: 1,
        ..Default::default()
    };
    run("100 × 2000, complete", &big)?;
    run(
        "100 × 2000, missing 0.4",
        &SynthConfig {
            missing: 0.4,
            min_track_length: 10,
            ..big.clone()
        },
    )?;
    run(
        "30 × 300, complete",
        &SynthConfig {
            frames: 30,
            points: 300,
            ..big.clone()
        },
    )?;
    Ok(())
}
