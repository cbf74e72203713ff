//! Cost of a Rerun recording on a 100-frame × 2000-track synthetic run: pipeline time with
//! and without recording, the time of each logging step, the process CPU time, and the .rrd
//! file size.
//!
//! `cargo run --release --example recording_overhead [FRAMES TRACKS [RUNS]]`
//!
//! The recorded run is what `rank3 reconstruct --rrd` does: the .rrd is opened by
//! [`recording::RecordingArgs::open`] and the run is [`recording::reconstruct_recorded`]
//! (input, mask and W logged beside the pipeline, observer events, result and robust pass),
//! opening and closing the .rrd included. Plain and recorded runs alternate so that a change
//! in machine load hits both alike; the figures are medians over `RUNS` (default 101) pairs,
//! plus the median of the per-pair differences. On a shared 2-core machine the overhead
//! from 21 pairs of the same code ranged over 2.9–13.5 % between invocations, from 151
//! pairs over 7.8–9.3 %.
//!
//! When the `rank3` binary sits next to this example's directory (`cargo build --release
//! --bins --examples`), the same table is also written to CSV and `rank3 reconstruct
//! t.csv --out DIR` is timed end to end with and without `--rrd`, alternating likewise: what
//! a user of the CLI pays for the recording.

use std::time::Instant;

use rank3::recording;
use rank3::synth::{Shape, SynthConfig, generate};
use rank3::{Config, Reconstruction};

fn median(v: &[f64]) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// CPU time (user + system, all threads, including finished ones) of this process in
/// seconds: `clock_gettime(CLOCK_PROCESS_CPUTIME_ID)`, nanosecond resolution (the kernel's
/// per-thread accounting); NaN if the clock is unavailable.
fn cpu_seconds() -> f64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec for the duration of the call.
    if unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut ts) } != 0 {
        return f64::NAN;
    }
    ts.tv_sec as f64 + 1e-9 * ts.tv_nsec as f64
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let (frames, points, runs) = (
        args.first().copied().unwrap_or(100),
        args.get(1).copied().unwrap_or(2000),
        args.get(2).copied().unwrap_or(101).max(1),
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

    let (mut plain, mut plain_cpu, mut total, mut total_cpu) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut open, mut pipeline, mut close) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..runs {
        let (c0, t0) = (cpu_seconds(), Instant::now());
        let r = Reconstruction::from_tracks(table, &config)?;
        plain.push(t0.elapsed().as_secs_f64());
        plain_cpu.push(cpu_seconds() - c0);
        std::hint::black_box(r);

        let (c0, t0) = (cpu_seconds(), Instant::now());
        let rec = recording::RecordingArgs {
            rrd: Some(path.clone()),
            ..Default::default()
        }
        .open(
            "rank3-overhead",
            recording::LayoutParts {
                reconstruction: true,
                ..Default::default()
            },
        )?
        .ok_or("no recording sink")?;
        let t1 = Instant::now();
        let r = recording::reconstruct_recorded(Some(&rec), table, &config)?;
        let t2 = Instant::now();
        drop(rec); // flush + footer
        let t3 = Instant::now();
        total.push((t3 - t0).as_secs_f64());
        total_cpu.push(cpu_seconds() - c0);
        open.push((t1 - t0).as_secs_f64());
        pipeline.push((t2 - t1).as_secs_f64());
        close.push((t3 - t2).as_secs_f64());
        std::hint::black_box(r);
    }
    let size = std::fs::metadata(&path)?.len();
    let diffs: Vec<f64> = total.iter().zip(&plain).map(|(t, p)| t - p).collect();
    let cpu_diffs: Vec<f64> = total_cpu
        .iter()
        .zip(&plain_cpu)
        .map(|(t, p)| t - p)
        .collect();
    let (p, t, d) = (median(&plain), median(&total), median(&diffs));
    let profile = if cfg!(debug_assertions) {
        "debug"
    } else {
        "release"
    };
    println!(
        "{frames} frames × {points} tracks, {} observations ({runs} alternating pairs, {profile})",
        table.n_observed()
    );
    println!(
        "pipeline without recording: {:.1} ms wall, {:.1} ms CPU",
        1e3 * p,
        1e3 * median(&plain_cpu)
    );
    println!(
        "pipeline with recording:    {:.1} ms wall, {:.1} ms CPU",
        1e3 * t,
        1e3 * median(&total_cpu)
    );
    println!(
        "  open .rrd {:.1} ms, pipeline + logging {:.1} ms, flush + close {:.1} ms",
        1e3 * median(&open),
        1e3 * median(&pipeline),
        1e3 * median(&close)
    );
    println!(
        "overhead (median of per-pair differences): wall {:.1} ms = {:.1} %, CPU {:.1} ms = {:.1} %",
        1e3 * d,
        100.0 * d / p,
        1e3 * median(&cpu_diffs),
        100.0 * median(&cpu_diffs) / median(&plain_cpu)
    );
    println!(".rrd size: {:.2} MB ({} bytes)", size as f64 / 1e6, size);
    cli_overhead(table, &dir, runs)?;
    std::fs::remove_dir_all(&dir).ok();
    Ok(())
}

/// `rank3 reconstruct` end to end, with and without `--rrd`, `runs` alternating pairs.
fn cli_overhead(
    table: &rank3::TrackTable,
    dir: &std::path::Path,
    runs: usize,
) -> Result<(), Box<dyn std::error::Error>> {
    let exe = std::env::current_exe()?;
    let Some(bin) = exe
        .parent()
        .and_then(|d| d.parent())
        .map(|d| d.join("rank3"))
        .filter(|b| b.is_file())
    else {
        println!("CLI: no rank3 binary next to the examples (cargo build --release --bins)");
        return Ok(());
    };
    let csv = dir.join("t.csv");
    table.write(&csv)?;
    let time = |extra: &[&std::ffi::OsStr]| -> Result<f64, Box<dyn std::error::Error>> {
        let t0 = Instant::now();
        let out = std::process::Command::new(&bin)
            .arg("reconstruct")
            .arg(&csv)
            .arg("--out")
            .arg(dir.join("out"))
            .args(extra)
            .output()?;
        let t = t0.elapsed().as_secs_f64();
        if !out.status.success() {
            return Err(String::from_utf8_lossy(&out.stderr).into_owned().into());
        }
        Ok(t)
    };
    let rrd = dir.join("cli.rrd");
    let (mut plain, mut recorded) = (Vec::new(), Vec::new());
    for _ in 0..runs {
        plain.push(time(&[])?);
        recorded.push(time(&["--rrd".as_ref(), rrd.as_os_str()])?);
    }
    let d: Vec<f64> = recorded.iter().zip(&plain).map(|(r, p)| r - p).collect();
    let (p, d) = (median(&plain), median(&d));
    println!(
        "CLI `rank3 reconstruct t.csv --out DIR` end to end: {:.1} ms without, {:.1} ms with \
         --rrd; overhead (median of per-pair differences) {:.1} ms = {:.1} %",
        1e3 * p,
        1e3 * median(&recorded),
        1e3 * d,
        100.0 * d / p
    );
    Ok(())
}
