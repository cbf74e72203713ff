//! Speed and resident memory of reading a long-format CSV track table
//! ([`rank3::TrackTable::read`]): writes a complete F×N table (`frame,track,x,y`, integer ids,
//! coordinates with 3 decimals) to a temporary file, then reads it in a child process so
//! that the peak resident memory (`VmHWM`) is the reader's own.
//!
//! `cargo run --release --example read_speed -- [FRAMES TRACKS]` (default 300 10000).

use std::io::Write;
use std::time::Instant;

mod common;
use common::peak_rss_mb;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().map(String::as_str) == Some("--child") {
        let path = &args[1];
        let bytes = std::fs::metadata(path).expect("file").len() as f64;
        let t = Instant::now();
        let table = rank3::TrackTable::read(path).expect("read");
        let secs = t.elapsed().as_secs_f64();
        let n = table.n_observed();
        println!(
            "read {:.0} MB, {n} observations in {secs:.2} s: {:.0} MB/s; peak resident {:.0} MB \
             ({:.0} bytes per observation)",
            bytes / 1e6,
            bytes / 1e6 / secs,
            peak_rss_mb(),
            peak_rss_mb() * 1048576.0 / n as f64
        );
        return;
    }
    let frames: usize = args.first().and_then(|a| a.parse().ok()).unwrap_or(300);
    let tracks: usize = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(10_000);
    let path = std::env::temp_dir().join(format!("rank3-read-speed-{frames}x{tracks}.csv"));
    {
        let mut f = std::io::BufWriter::new(std::fs::File::create(&path).expect("create"));
        writeln!(f, "frame,track,x,y").unwrap();
        for fr in 0..frames {
            for p in 0..tracks {
                let x = (p % 640) as f64 + 0.001 * (fr % 997) as f64;
                let y = (p / 640 % 480) as f64 + 0.002 * (fr % 991) as f64;
                writeln!(f, "{fr},{p},{x:.3},{y:.3}").unwrap();
            }
        }
    }
    let out = std::process::Command::new(std::env::current_exe().unwrap())
        .args(["--child", path.to_str().unwrap()])
        .output()
        .expect("child");
    print!("{}", String::from_utf8_lossy(&out.stdout));
    eprint!("{}", String::from_utf8_lossy(&out.stderr));
    let _ = std::fs::remove_file(&path);
}
