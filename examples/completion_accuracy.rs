//! Accuracy of affine completion on the complete CMU hotel reference tracks (51 frames ×
//! 491 tracks) after hiding entries the way a tracker loses points: each track is kept
//! only in one random contiguous window of frames (seeded). Prints the median and p95
//! Euclidean pixel error of the filled-in positions against the hidden truth.
//!
//! `cargo run --release --example completion_accuracy -- [SEED]`

use std::time::Instant;

use faer::Mat;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rank3::completion::{CompletionConfig, complete};
use rank3::{Measurements, NoopObserver};

fn main() {
    let seed: u64 = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(1);
    let dir = rank3::datasets::dir().join("hotel");
    let (xs, ys) = (
        dir.join("tracked_points_Xs.txt"),
        dir.join("tracked_points_Ys.txt"),
    );
    if !xs.exists() || !ys.exists() {
        println!(
            "hotel reference tracks not found in {} (set RANK3_DATASETS); nothing to do",
            dir.display()
        );
        return;
    }
    let table = match rank3::table::dense::read_xy(&xs, &ys) {
        Ok(t) => t,
        Err(e) => {
            println!("cannot read the hotel tracks: {e}");
            return;
        }
    };
    let (nf, np) = (table.n_frames(), table.n_tracks());
    let truth: Mat<f64> = table.measurements().w;
    println!(
        "hotel: {nf} frames × {np} tracks (complete reference), seed {seed}; affine model, wiberg, auto init"
    );
    println!();
    println!(
        "| target missing | actual missing | RMS observed (px) | median hidden error (px) | p95 hidden error (px) | max (px) | status | iterations | seconds |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    let full_rms = {
        let meas = Measurements::complete(truth.clone());
        let c = complete(&meas, &CompletionConfig::default(), &mut NoopObserver)
            .expect("complete data");
        c.rms
    };
    for target in [0.3, 0.5, 0.6, 0.7] {
        let mut rng = StdRng::seed_from_u64(seed ^ (target * 1000.0) as u64);
        let mean_len = (1.0 - target) * nf as f64;
        let lo = ((0.5 * mean_len).round() as usize).max(2);
        let hi = ((1.5 * mean_len).round() as usize).min(nf).max(lo);
        let mut visible = vec![false; nf * np];
        for p in 0..np {
            let len = rng.random_range(lo..=hi);
            let start = rng.random_range(0..=nf - len);
            for f in start..start + len {
                visible[f * np + p] = true;
            }
        }
        let meas = Measurements::new(truth.clone(), visible);
        let missing = 1.0 - meas.n_observed() as f64 / (nf * np) as f64;
        let t0 = Instant::now();
        let c = match complete(&meas, &CompletionConfig::default(), &mut NoopObserver) {
            Ok(c) => c,
            Err(e) => {
                println!("| {target:.2} | {missing:.3} | error: {e} | | | | | | |");
                continue;
            }
        };
        let secs = t0.elapsed().as_secs_f64();
        let mut err = Vec::new();
        for f in 0..nf {
            for p in 0..np {
                if !meas.is_visible(f, p) {
                    let [px, py] = c.predict_point(f, p);
                    err.push(
                        ((px - truth[(2 * f, p)]).powi(2) + (py - truth[(2 * f + 1, p)]).powi(2))
                            .sqrt(),
                    );
                }
            }
        }
        err.sort_by(f64::total_cmp);
        let q = |f: f64| err[((err.len() - 1) as f64 * f).round() as usize];
        println!(
            "| {target:.2} | {missing:.3} | {:.3} | {:.3} | {:.3} | {:.2} | {:?} | {} | {secs:.2} |",
            c.rms,
            q(0.5),
            q(0.95),
            q(1.0),
            c.report.status,
            c.report.iterations,
        );
    }
    println!();
    println!("affine fit RMS of the complete table (model error floor): {full_rms:.3} px");
}
