//! The sparse pipeline ([`rank3::sparse`]) against the dense one and the ground truth.

use rank3::sparse::Pipeline;
use rank3::synth::{SynthConfig, generate};
use rank3::{CameraModel, Config, Reconstruction};

fn structure_error(r: &Reconstruction, truth: &rank3::MetricModel) -> f64 {
    let tru: Vec<_> = r.kept_tracks.iter().map(|&p| truth.points[p]).collect();
    rank3::eval::structure_error(&r.model.points, &tru)
}

/// A 60-frame turntable house with 40 % missing (so the sparse start chains two windows):
/// the sparse and dense pipelines reach the same optimum.
#[test]
fn sparse_and_dense_pipelines_agree_on_missing_data() {
    let scene = generate(&SynthConfig {
        frames: 60,
        points: 120,
        noise: 0.5,
        missing: 0.4,
        camera: CameraModel::ScaledOrthographic,
        seed: 3,
        ..SynthConfig::default()
    })
    .unwrap();
    let mut config = Config {
        camera: CameraModel::ScaledOrthographic,
        refine: Some(Default::default()),
        ..Config::default()
    };
    config.sparse.pipeline = Pipeline::Dense;
    let dense = Reconstruction::from_tracks(&scene.table, &config).unwrap();
    config.sparse.pipeline = Pipeline::Sparse;
    let sparse = Reconstruction::from_tracks(&scene.table, &config).unwrap();
    assert!(dense.sparse.is_none() && sparse.sparse.is_some());
    let (ed, es) = (
        structure_error(&dense, &scene.truth),
        structure_error(&sparse, &scene.truth),
    );
    eprintln!(
        "dense RMS {:.4} px structure {ed:.4}; sparse RMS {:.4} px structure {es:.4}",
        dense.rms_px, sparse.rms_px
    );
    // Both at the noise floor (σ = 0.5 px), within 1 % of each other.
    assert!(sparse.rms_px < 0.55, "sparse RMS {}", sparse.rms_px);
    assert!((sparse.rms_px - dense.rms_px).abs() < 0.01 * dense.rms_px);
    assert!(
        es < 0.05 && (es - ed).abs() < 0.01,
        "structure {es} vs {ed}"
    );
}

/// A 160-frame corridor (tracks live ~30 frames; each frame shares tracks only with its
/// neighbours; 12 % filled): the automatic choice runs the sparse pipeline, which recovers the structure to well under 1 % of its spread
/// at the noise floor (σ = 0.5 px), with every track kept.
#[test]
fn sparse_pipeline_reconstructs_a_long_banded_sequence() {
    let (table, truth) = rank3::synth::corridor(&rank3::synth::CorridorConfig {
        frames: 160,
        per_frame: 80,
        ..Default::default()
    })
    .unwrap();
    assert!(table.fill() < 0.2, "fill {}", table.fill());
    // The default (automatic) pipeline choice takes the sparse one for such a table.
    let config = Config {
        camera: CameraModel::ScaledOrthographic,
        ..Config::default()
    };
    let r = Reconstruction::from_tracks(&table, &config).unwrap();
    let report = r.sparse.as_ref().expect("the sparse pipeline ran");
    let e = structure_error(&r, &truth);
    eprintln!(
        "RMS {:.4} px, structure {e:.5}, {} iterations, {} outliers",
        r.rms_px,
        report.iterations,
        r.outlier_tracks.len()
    );
    assert_eq!(report.status, rank3::SolverStatus::Converged);
    assert!(r.rms_px < 0.5 && r.rms_px > 0.4, "RMS {}", r.rms_px);
    assert!(e < 0.01, "structure error {e}");
    assert!(r.outlier_tracks.is_empty());
    // Every frame has its camera, in the input's order.
    assert_eq!(r.frames.len(), table.n_frames());
}
