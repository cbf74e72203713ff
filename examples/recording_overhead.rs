//! Cost of a Rerun recording on a 100-frame × 2000-track synthetic run: pipeline time with
//! and without recording, the time of each logging step, and the .rrd file size.
//!
//! `cargo run --release --example recording_overhead [FRAMES TRACKS]`

use std::time::Instant;

use rank3::recording::{self, RecordingObserver};
use rank3::synth::{Shape, SynthConfig, generate};
use rank3::{Config, Reconstruction};

fn median(v: &[f64]) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let (frames, points) = (
        args.first().copied().unwrap_or(100),
        args.get(1).copied().unwrap_or(2000),
    );
    let scene = generate(&SynthConfig {
        shape: Shape::Cloud,
        frames,
        points,
        noise: 0.5,
        seed: 1,
        ..Default::default()
    })?;
    let table = &scene.table;
    let config = Config::default();
    let dir = std::env::temp_dir().join(format!("rank3-overhead-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let path = dir.join("run.rrd");
    let runs = 5;

    let mut plain = Vec::new();
    for _ in 0..runs {
        let t0 = Instant::now();
        let r = Reconstruction::from_tracks(table, &config)?;
        plain.push(t0.elapsed().as_secs_f64());
        std::hint::black_box(r);
    }

    let (mut total, mut input, mut pipeline, mut result, mut flush) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for _ in 0..runs {
        let t0 = Instant::now();
        let rec = rerun::RecordingStreamBuilder::new("rank3-overhead").save(&path)?;
        recording::log_input(&rec, table)?;
        let t1 = Instant::now();
        let mut obs = RecordingObserver::new(&rec);
        let r = Reconstruction::from_tracks_observed(table, &config, &mut obs)?;
        let t2 = Instant::now();
        recording::log_reconstruction(&rec, table, &r)?;
        let t3 = Instant::now();
        drop(obs);
        drop(rec); // flush + footer
        let t4 = Instant::now();
        total.push((t4 - t0).as_secs_f64());
        input.push((t1 - t0).as_secs_f64());
        pipeline.push((t2 - t1).as_secs_f64());
        result.push((t3 - t2).as_secs_f64());
        flush.push((t4 - t3).as_secs_f64());
    }
    let size = std::fs::metadata(&path)?.len();
    let (p, t) = (median(&plain), median(&total));
    let profile = if cfg!(debug_assertions) {
        "debug"
    } else {
        "release"
    };
    println!(
        "{frames} frames × {points} tracks, {} observations (median of {runs} runs, {profile})",
        table.n_observed()
    );
    println!("pipeline without recording: {:.1} ms", 1e3 * p);
    println!("pipeline with recording:    {:.1} ms", 1e3 * t);
    println!(
        "  log_input {:.1} ms, pipeline+observer {:.1} ms, log_reconstruction {:.1} ms, \
         flush {:.1} ms",
        1e3 * median(&input),
        1e3 * median(&pipeline),
        1e3 * median(&result),
        1e3 * median(&flush)
    );
    // Logging proper (the observer's share inside the pipeline is a handful of log calls).
    let logging = median(&input) + median(&result) + median(&flush);
    println!(
        "overhead: logging {:.1} ms = {:.1} % of the pipeline without recording; \
         end-to-end difference {:.1} ms = {:.1} %",
        1e3 * logging,
        100.0 * logging / p,
        1e3 * (t - p),
        100.0 * (t - p) / p
    );
    println!(".rrd size: {:.2} MB ({} bytes)", size as f64 / 1e6, size);
    std::fs::remove_dir_all(&dir).ok();
    Ok(())
}
