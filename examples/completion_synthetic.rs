//! Filling in hidden entries on synthetic scenes with ground truth: `rank3 synth --missing`
//! tables (each track visible in one contiguous window) through the default pipeline without
//! the robust pass; error = image distance between the filled-in position (completed.txt) and
//! the true noise-free projection of every hidden (frame, track) pair.
//!
//! `cargo run --release --example completion_synthetic [seeds]`

use rank3::eval::{median, percentile};
use rank3::synth::{SynthConfig, generate};
use rank3::{Config, Reconstruction};

fn main() -> Result<(), rank3::Error> {
    let seeds: u64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(5);
    println!(
        "| missing (target) | missing (actual) | σ (px) | median hidden error (px) | p95 | max | completion RMS (px) |"
    );
    println!("|---|---|---|---|---|---|---|");
    for missing in [0.3, 0.5, 0.7] {
        for noise in [0.0, 0.5] {
            let (mut errs, mut actual, mut rms) = (Vec::new(), Vec::new(), Vec::new());
            for seed in 0..seeds {
                let scene = generate(&SynthConfig {
                    frames: 40,
                    points: 300,
                    missing,
                    noise,
                    seed,
                    ..Default::default()
                })?;
                let cfg = Config {
                    robust: None,
                    ..Config::default()
                };
                let rec = Reconstruction::from_tracks(&scene.table, &cfg)?;
                let full = rec.completed_matrix();
                for f in 0..40 {
                    for p in 0..300 {
                        if !scene.table.is_visible(f, p) {
                            let q = scene.truth.project(f, p);
                            errs.push((full[(2 * f, p)] - q[0]).hypot(full[(2 * f + 1, p)] - q[1]));
                        }
                    }
                }
                actual.push(1.0 - scene.table.fill());
                rms.push(rec.completion.as_ref().map_or(f64::NAN, |c| c.rms_px));
            }
            println!(
                "| {missing} | {:.3} | {noise} | {:.4} | {:.4} | {:.4} | {:.4} |",
                median(&actual),
                median(&errs),
                percentile(&errs, 95.0),
                percentile(&errs, 100.0),
                median(&rms)
            );
        }
    }
    Ok(())
}
