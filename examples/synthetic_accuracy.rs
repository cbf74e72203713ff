//! Ground-truth accuracy of the complete-data pipeline on synthetic scenes at several noise
//! levels: median over seeds of the per-scene median rotation error, relative structure error
//! (after similarity alignment, allowing the depth reversal) and RMS.
//!
//! `cargo run --release --example synthetic_accuracy [seeds]`

use nalgebra::{Matrix3, Rotation3, Vector3};
use rank3::eval::{median, percentile, rotation_errors_deg, structure_error};
use rank3::synth::{Motion, Shape, SynthConfig, generate};
use rank3::{CameraModel, Config, Reconstruction};

fn main() -> Result<(), rank3::Error> {
    let seeds: u64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(20);
    println!(
        "| camera | shape / motion | σ (px) | median rotation error (°) | p90 | structure error (%) | p90 | RMS (px) | LS / SDP |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for camera in [CameraModel::Orthographic, CameraModel::ScaledOrthographic] {
        for (shape, motion) in [
            (Shape::House, Motion::Turntable),
            (Shape::Cloud, Motion::HandheldArc),
        ] {
            for noise in [0.0, 0.5, 1.0, 2.0] {
                let (mut rot, mut st, mut rms) = (Vec::new(), Vec::new(), Vec::new());
                let mut sdp = 0;
                for seed in 0..seeds {
                    let scene = generate(&SynthConfig {
                        camera,
                        shape,
                        motion,
                        noise,
                        seed,
                        ..Default::default()
                    })?;
                    let cfg = Config {
                        camera,
                        ..Config::default()
                    };
                    let rec = Reconstruction::from_tracks(&scene.table, &cfg)?;
                    let est_r: Vec<Rotation3<f64>> = rec
                        .frames
                        .iter()
                        .map(|f| {
                            Rotation3::from_matrix_unchecked(Matrix3::from_fn(|a, b| {
                                f.rotation[a][b]
                            }))
                        })
                        .collect();
                    let est_p: Vec<Vector3<f64>> =
                        rec.points.iter().map(|p| Vector3::from(p.xyz)).collect();
                    let r = rotation_errors_deg(&est_r, &scene.truth.rotations);
                    rot.push(median(&r[1..]));
                    st.push(100.0 * structure_error(&est_p, &scene.truth.points));
                    rms.push(rec.rms_px);
                    if rec.metric_upgrade.method == rank3::metric::UpgradeMethod::Sdp {
                        sdp += 1;
                    }
                }
                println!(
                    "| {camera} | {shape:?} / {motion:?} | {noise} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} | {}/{} |",
                    median(&rot),
                    percentile(&rot, 90.0),
                    median(&st),
                    percentile(&st, 90.0),
                    median(&rms),
                    seeds as usize - sdp,
                    sdp
                );
            }
        }
    }
    Ok(())
}
