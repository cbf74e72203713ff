//! Developer diagnostic: per-seed outcome of random starts.
//! `completion_diag PATH SEEDS '{"model":"affine", ...config json...}'`
use rank3::NoopObserver;
use rank3::completion::*;
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let k: u64 = a[2].parse().unwrap();
    let base: CompletionConfig =
        serde_json::from_str(a.get(3).map(|s| s.as_str()).unwrap_or("{}")).unwrap();
    let meas = rank3::TrackTable::read(&a[1])
        .expect("readable track table")
        .measurements();
    for seed in 0..k {
        let cfg = CompletionConfig {
            init: Init::Random,
            seed,
            ..base.clone()
        };
        let c = complete(&meas, &cfg, &mut NoopObserver).unwrap();
        println!(
            "seed {seed}: rms {:.7} {:?} it {} {:.3}s",
            c.rms, c.report.status, c.report.iterations, c.report.seconds
        );
    }
}
