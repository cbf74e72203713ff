//! Developer diagnostic: per-seed outcome of random starts.
//! `completion_diag PATH SEEDS '{"model":"affine", ...config json...}' [FIRST_SEED] [TRACE_EVERY]`
//! (TRACE_EVERY > 0 prints every that many iterations' RMS and damping).
use rank3::completion::*;
use rank3::{Event, Observer};

struct Trace(usize);
impl Observer for Trace {
    fn on_event(&mut self, e: &Event) {
        if let Event::Iteration {
            iteration,
            rms,
            lambda,
            ..
        } = e
            && self.0 > 0
            && iteration % self.0 == 0
        {
            println!("  it {iteration} rms {rms:.6} lambda {lambda:.1e}");
        }
    }
}

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let k: u64 = a[2].parse().unwrap();
    let base: CompletionConfig =
        serde_json::from_str(a.get(3).map(|s| s.as_str()).unwrap_or("{}")).unwrap();
    let first: u64 = a.get(4).and_then(|s| s.parse().ok()).unwrap_or(0);
    let every: usize = a.get(5).and_then(|s| s.parse().ok()).unwrap_or(0);
    let meas = rank3::TrackTable::read(&a[1])
        .expect("readable track table")
        .measurements();
    for seed in first..first + k {
        let cfg = CompletionConfig {
            init: Init::Random,
            seed,
            ..base.clone()
        };
        let c = complete(&meas, &cfg, &mut Trace(every)).unwrap();
        println!(
            "seed {seed}: rms {:.7} {:?} it {} {:.3}s",
            c.rms, c.report.status, c.report.iterations, c.report.seconds
        );
    }
}
