//! Developer sweep: success rate of the default (or a JSON-overridden) completion solver
//! from random starts, Wiberg only.
//!
//! `completion_sweep K CASES '{"jacobian":"full", ...}' [FIRST_SEED]` with CASES a comma
//! list of `dino`, `dino4`, `house` (default all); seeds FIRST_SEED.. FIRST_SEED+K
//! (default 0). Prints one markdown row per case and the failing seeds.

use std::time::Instant;

use rank3::NoopObserver;
use rank3::completion::{CompletionConfig, CompletionModel, Init, complete};

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let k: u64 = a.get(1).and_then(|s| s.parse().ok()).unwrap_or(100);
    let which = a
        .get(2)
        .cloned()
        .unwrap_or_else(|| "dino,dino4,house".into());
    let base: CompletionConfig =
        serde_json::from_str(a.get(3).map(|s| s.as_str()).unwrap_or("{}")).expect("config json");
    let first: u64 = a.get(4).and_then(|s| s.parse().ok()).unwrap_or(0);
    let dir = rank3::datasets::dir();
    for case in which.split(',') {
        let (rel, model, best) = match case {
            "dino" => (
                "dino_trimmed/M_dense.txt",
                CompletionModel::Affine,
                1.270153,
            ),
            "dino4" => (
                "dino_trimmed/M_dense.txt",
                CompletionModel::Free { rank: 4 },
                1.084673,
            ),
            "house" => (
                "model_house/matrix/M_dense.txt",
                CompletionModel::Affine,
                2.750877,
            ),
            _ => continue,
        };
        let meas = rank3::TrackTable::read(dir.join(rel))
            .expect("data set")
            .measurements();
        let mut times = Vec::new();
        let mut ok = 0;
        let mut fails = Vec::new();
        let mut its = Vec::new();
        for seed in first..first + k {
            let cfg = CompletionConfig {
                model,
                init: Init::Random,
                seed,
                ..base.clone()
            };
            let t0 = Instant::now();
            let c = complete(&meas, &cfg, &mut NoopObserver).expect("complete");
            times.push(t0.elapsed().as_secs_f64());
            its.push(c.report.iterations as f64);
            if ((c.rms - best) / best).abs() <= 1e-6 {
                ok += 1;
            } else {
                fails.push(format!(
                    "{seed}:{:.5}/{:?}/{}",
                    c.rms, c.report.status, c.report.iterations
                ));
            }
        }
        times.sort_by(|x, y| x.total_cmp(y));
        its.sort_by(|x, y| x.total_cmp(y));
        println!(
            "| {case} | {ok}/{k} | median {:.3} s | p90 {:.3} s | median it {} | total {:.1} s |",
            times[times.len() / 2],
            times[(times.len() * 9) / 10],
            its[its.len() / 2],
            times.iter().sum::<f64>()
        );
        println!("  fails: {}", fails.join(" "));
    }
}
