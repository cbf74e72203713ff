//! How well a track table determines the pixels' aspect ratio `f_x / f_y`: the table is
//! reconstructed under each ratio of a grid (`Config::aspect_ratio`, scaled orthographic
//! camera, robust pass on) and the reprojection RMS is measured in the *input's* pixels over
//! the kept tracks' observations (entries above 3 px left out, so the robust pass's
//! flagged entries do not dominate), with the metric upgrade's constraint RMS. A flat
//! profile means the data cannot tell the ratio (docs/math.md §9, [`rank3::pixel_aspect`]);
//! each reconstruction is written to `out/aspect-scan/a<R>/` for `examples/hotel_walls.rs`.
//!
//! ```text
//! cargo run --release --example aspect_scan                 # the hotel reference tracks
//! cargo run --release --example aspect_scan -- TRACKS.csv   # any table
//! ```
//!
//! Cost: one reconstruction per grid ratio (13).

use rank3::table::dense::read_xy;
use rank3::{CameraModel, Config, Reconstruction};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let table = match std::env::args().nth(1) {
        Some(path) => rank3::table::read_tracks(&path)?.table,
        None => {
            let (Some(xs), Some(ys)) = (
                rank3::datasets::find("hotel/tracked_points_Xs.txt"),
                rank3::datasets::find("hotel/tracked_points_Ys.txt"),
            ) else {
                eprintln!("hotel reference tracks not found (set RANK3_DATASETS)");
                return Ok(());
            };
            read_xy(&xs, &ys)?
        }
    };
    println!(
        "| f_x / f_y | RMS, input pixels (entries ≤ 3 px) | scalars | upgrade constraint RMS |"
    );
    println!("|---|---|---|---|");
    for k in 0..=12 {
        let a = 0.7 + 0.05 * k as f64;
        let cfg = Config {
            camera: CameraModel::ScaledOrthographic,
            aspect_ratio: Some(a),
            ..Config::default()
        };
        let rec = Reconstruction::from_tracks(&table, &cfg)?;
        let m = &rec.model;
        let (mut ss, mut n) = (0.0, 0usize);
        for (fk, &f) in rec.kept_frames.iter().enumerate() {
            for (pk, &p) in rec.kept_tracks.iter().enumerate() {
                if let Some([x, y]) = table.get(f, p) {
                    let q = m.project(fk, pk);
                    let e = (q[0] - x).powi(2) + (q[1] - y).powi(2);
                    if e < 9.0 {
                        ss += e;
                        n += 2;
                    }
                }
            }
        }
        println!(
            "| {a:.2} | {:.5} | {n} | {:.3e} |",
            (ss / n.max(1) as f64).sqrt(),
            rec.metric_upgrade.constraint_rms
        );
        rank3::output::write_all(
            &rec,
            std::path::Path::new(&format!("out/aspect-scan/a{a:.2}")),
        )?;
    }
    Ok(())
}
