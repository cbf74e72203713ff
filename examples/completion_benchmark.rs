//! Success rate and speed of the completion solvers from random starts on the real
//! benchmark matrices (dino_trimmed, model_house).
//!
//! `cargo run --release --example completion_benchmark -- [K] [ALS_MAX_ITERATIONS] [FIRST_SEED]`
//! (K random starts per row, default 100, seeds FIRST_SEED.. (default 0); ALS iteration cap,
//! default 3000, 0 skips the ALS rows).
//! A run succeeds when its RMS is within 1e-6 (relative) of the best-known optimum.

use std::time::Instant;

use rank3::completion::{CompletionConfig, CompletionModel, CompletionSolverKind, Init, complete};
use rank3::{NoopObserver, SolverStatus};

fn quantile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    if v.is_empty() {
        return f64::NAN;
    }
    let idx = ((v.len() - 1) as f64 * q).round() as usize;
    v[idx]
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let k: usize = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(100);
    let als_cap: usize = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(3000);
    let first_seed: u64 = args.get(3).and_then(|a| a.parse().ok()).unwrap_or(0);
    let dir = rank3::datasets::dir();
    let cases = [
        (
            "dino_trimmed",
            "dino_trimmed/M_dense.txt",
            CompletionModel::Affine,
            1.270153,
        ),
        (
            "dino_trimmed",
            "dino_trimmed/M_dense.txt",
            CompletionModel::Free { rank: 4 },
            1.084673,
        ),
        (
            "model_house",
            "model_house/matrix/M_dense.txt",
            CompletionModel::Affine,
            2.750877,
        ),
    ];
    println!(
        "K = {k} random starts per row (seeds {first_seed}..{}); success = RMS within 1e-6 \
         relative of the best known",
        first_seed + k as u64
    );
    println!();
    println!(
        "| data set | model | solver | success | converged/stalled/max-it | median s | p90 s | best RMS | best known |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for (name, rel, model, best_known) in cases {
        let path = dir.join(rel);
        if !path.exists() {
            println!(
                "| {name} | - | - | data set not found at {} (set RANK3_DATASETS); skipped | | | | | |",
                path.display()
            );
            continue;
        }
        let meas = match rank3::TrackTable::read(&path) {
            Ok(t) => t.measurements(),
            Err(e) => {
                println!("| {name} | - | - | cannot read: {e} | | | | | |");
                continue;
            }
        };
        for solver in [CompletionSolverKind::Wiberg, CompletionSolverKind::Als] {
            if solver == CompletionSolverKind::Als && als_cap == 0 {
                continue;
            }
            let mut times = Vec::new();
            let mut ok = 0;
            let mut best = f64::INFINITY;
            let (mut conv, mut stall, mut maxit) = (0, 0, 0);
            for seed in first_seed..first_seed + k as u64 {
                let cfg = CompletionConfig {
                    solver,
                    model,
                    init: Init::Random,
                    seed,
                    max_iterations: if solver == CompletionSolverKind::Als {
                        als_cap
                    } else {
                        CompletionConfig::default().max_iterations
                    },
                    ..Default::default()
                };
                let t0 = Instant::now();
                let c = match complete(&meas, &cfg, &mut NoopObserver) {
                    Ok(c) => c,
                    Err(e) => {
                        println!("error: {e}");
                        return;
                    }
                };
                times.push(t0.elapsed().as_secs_f64());
                if ((c.rms - best_known) / best_known).abs() <= 1e-6 {
                    ok += 1;
                }
                match c.report.status {
                    SolverStatus::Converged => conv += 1,
                    SolverStatus::Stalled => stall += 1,
                    SolverStatus::MaxIterations => maxit += 1,
                }
                best = best.min(c.rms);
            }
            let model_s = match model {
                CompletionModel::Affine => "affine".to_string(),
                CompletionModel::Free { rank } => format!("free rank {rank}"),
            };
            println!(
                "| {name} | {model_s} | {} | {ok}/{k} ({:.0} %) | {conv}/{stall}/{maxit} | {:.3} | {:.3} | {best:.6} | {best_known} |",
                solver.name(),
                100.0 * ok as f64 / k as f64,
                quantile(&mut times.clone(), 0.5),
                quantile(&mut times, 0.9),
            );
        }
    }
}
