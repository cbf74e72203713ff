//! The CMU hotel reference tracks (51 frames × 491 complete tracks) through the complete-data
//! pipeline: prints RMS, σ4/σ3 and the metric-upgrade path for the affine camera models, and
//! the perspective camera's focal length; writes each reconstruction to
//! `out/hotel-reference/CAMERA/` (for `examples/hotel_walls.rs`).
//!
//! `cargo run --release --example hotel` (data set directory from `RANK3_DATASETS`, default
//! `../shared/datasets`).

use rank3::table::dense::read_xy;
use rank3::{CameraModel, Config, Reconstruction};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (Some(xs), Some(ys)) = (
        rank3::datasets::find("hotel/tracked_points_Xs.txt"),
        rank3::datasets::find("hotel/tracked_points_Ys.txt"),
    ) else {
        return Ok(());
    };
    let table = read_xy(&xs, &ys)?;
    println!(
        "hotel: {} frames × {} tracks, {:.1} % observed",
        table.n_frames(),
        table.n_tracks(),
        100.0 * table.fill()
    );
    println!(
        "| camera | affine RMS (px) | metric RMS before LM | metric RMS after LM | σ4/σ3 | upgrade | LS L min eig | time (s) |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for camera in [
        CameraModel::Orthographic,
        CameraModel::ScaledOrthographic,
        CameraModel::Perspective,
    ] {
        let mut cfg = Config {
            camera,
            ..Config::default()
        };
        cfg.perspective.intrinsics.image_size = Some([512, 480]);
        let t0 = std::time::Instant::now();
        let rec = Reconstruction::from_tracks(&table, &cfg)?;
        let secs = t0.elapsed().as_secs_f64();
        let (before, after) = rec
            .refinement
            .as_ref()
            .map_or((f64::NAN, f64::NAN), |r| (r.rms_before_px, r.rms_after_px));
        println!(
            "| {camera} | {:.4} | {before:.4} | {after:.4} | {:.4} | {:?} | {:.3e} | {secs:.3} |",
            rec.factorization.rms_px,
            rec.rank_ratio,
            rec.metric_upgrade.method,
            rec.metric_upgrade.min_eigenvalue_ls
        );
        let sv: Vec<String> = rec
            .singular_values
            .iter()
            .take(6)
            .map(|v| format!("{v:.2}"))
            .collect();
        eprintln!("  singular values: {}", sv.join(", "));
        for w in &rec.warnings {
            eprintln!("  warning: {w}");
        }
        if let Some(p) = &rec.perspective {
            eprintln!(
                "  perspective: RMS {:.4} px, focal {:.1} px ({}), {} starts screened",
                p.rms_px,
                p.intrinsics.focal_px,
                p.intrinsics.focal,
                p.starts.len()
            );
        }
        let dir = std::path::Path::new("out/hotel-reference").join(camera.to_string());
        rank3::output::write_all(&rec, &dir)?;
    }
    Ok(())
}
