//! `rank3 synth`: a synthetic scene with its ground truth.

use std::path::PathBuf;

use rank3::synth::{Motion, OutlierKind, Shape, SynthConfig};

use super::args::{CameraArg, MotionArg, OutlierArg, ShapeArg, parse_synth_object};
use super::verbosity::{detail, say};

#[derive(clap::Args)]
pub struct SynthArgs {
    /// Output directory.
    #[arg(long)]
    pub out: PathBuf,
    /// Number of frames (camera poses).
    #[arg(long, default_value_t = 30)]
    pub frames: usize,
    /// Number of 3D points (one track each).
    #[arg(long, default_value_t = 200)]
    pub points: usize,
    /// Image noise σ, pixels.
    #[arg(long, default_value_t = 0.5)]
    pub noise: f64,
    /// Camera: orthographic, scaled orthographic (weak perspective) or pinhole perspective
    /// (truth.json then also holds each frame's K, R, t, P and camera centre).
    #[arg(long, value_enum, default_value = "orthographic")]
    pub camera: CameraArg,
    /// Focal length of the perspective camera, pixels [default: DISTANCE · 200, so that the
    /// object spans about 400 px]. Only with --camera perspective.
    #[arg(long, value_name = "PX")]
    pub focal: Option<f64>,
    /// Distance of the perspective camera from the object's centre, in object radii
    /// (> 1.2; 2–3 is strong perspective, 20 or more nearly weak perspective). Only with
    /// --camera perspective.
    #[arg(long, value_name = "D", default_value_t = rank3::synth::DEFAULT_DISTANCE)]
    pub distance: f64,
    /// A zooming perspective camera: frame f's focal length is FOCAL · (1 + Z)^(f / (F − 1)),
    /// from FOCAL to (1 + Z) · FOCAL over the sequence (Z > −1; 0 = fixed focal length).
    /// Only with --camera perspective.
    #[arg(long, value_name = "Z", default_value_t = 0.0)]
    pub zoom: f64,
    /// Radial distortion k₁ of the perspective camera (COLMAP's SIMPLE_RADIAL on normalised
    /// coordinates: image = f (1 + k₁‖n‖²) n + c; 0 = none). Only with --camera perspective.
    #[arg(
        long,
        value_name = "K1",
        default_value_t = 0.0,
        allow_negative_numbers = true
    )]
    pub distortion: f64,
    /// The object's shape.
    #[arg(long, value_enum, default_value = "house")]
    pub shape: ShapeArg,
    /// The camera's path around the object.
    #[arg(long, value_enum, default_value = "turntable")]
    pub motion: MotionArg,
    /// Fraction of entries missing (each track visible in one contiguous window).
    #[arg(long, default_value_t = 0.0)]
    pub missing: f64,
    /// Fraction of tracks that are outliers.
    #[arg(long, default_value_t = 0.0)]
    pub outliers: f64,
    /// How the outlier tracks move (with --outliers).
    #[arg(long, value_enum, default_value = "mixed")]
    pub outlier_kind: OutlierArg,
    /// Fraction of entries of inlier tracks with a gross error (15–60 px).
    #[arg(long, default_value_t = 0.0)]
    pub gross: f64,
    /// Extra rigid objects moving independently of the main one, as a comma-separated
    /// list of `SHARE:MOTION` (fraction of the tracks, `rotating` or `translating`), e.g.
    /// `0.2:rotating,0.15:translating`. Their tracks' object is `object` in truth.json.
    #[arg(long, value_name = "SHARE:MOTION,...", value_delimiter = ',', value_parser = parse_synth_object)]
    pub objects: Option<Vec<rank3::synth::SynthObject>>,
    /// Seed of the scene's random choices (points, noise, missing entries, outliers).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    #[cfg(feature = "rerun")]
    #[command(flatten)]
    pub record: rank3::recording::RecordingArgs,
}

pub fn synth(a: &SynthArgs) -> Result<(), rank3::Error> {
    let cfg = SynthConfig {
        shape: match a.shape {
            ShapeArg::House => Shape::House,
            ShapeArg::Cloud => Shape::Cloud,
            ShapeArg::Cube => Shape::Cube,
            ShapeArg::Plane => Shape::Plane,
        },
        motion: match a.motion {
            MotionArg::Turntable => Motion::Turntable,
            MotionArg::HandheldArc => Motion::HandheldArc,
        },
        camera: a.camera.into(),
        frames: a.frames,
        points: a.points,
        noise: a.noise,
        missing: a.missing,
        outliers: a.outliers,
        objects: a.objects.clone().unwrap_or_default(),
        outlier_kind: match a.outlier_kind {
            OutlierArg::Mixed => OutlierKind::Mixed,
            OutlierArg::RandomWalk => OutlierKind::RandomWalk,
            OutlierArg::SecondObject => OutlierKind::SecondObject,
            OutlierArg::Sliding => OutlierKind::Sliding,
        },
        gross: a.gross,
        seed: a.seed,
        focal: a.focal,
        distance: a.distance,
        zoom: a.zoom,
        distortion: a.distortion,
        ..SynthConfig::default()
    };
    let scene = rank3::synth::generate(&cfg)?;
    detail!(
        "scene: {:?} on {:?}, {} camera{}, {} frames × {} points, noise σ {} px, {:.1} % \
         missing, {:.1} % outlier tracks ({:?}), {:.1} % gross entries, {} extra object(s), \
         seed {}",
        cfg.shape,
        cfg.motion,
        a.camera.name(),
        if cfg.is_perspective() {
            format!(
                " (focal {:.1} px, {} radii away)",
                cfg.focal_px(),
                cfg.distance
            )
        } else {
            String::new()
        },
        cfg.frames,
        cfg.points,
        cfg.noise,
        100.0 * cfg.missing,
        100.0 * cfg.outliers,
        cfg.outlier_kind,
        100.0 * cfg.gross,
        cfg.objects.len(),
        cfg.seed
    );
    #[cfg(feature = "rerun")]
    if let Some(rec) = a.record.open(
        "rank3",
        rank3::recording::LayoutParts {
            truth: true,
            ..Default::default()
        },
    )? {
        rank3::recording::log_input(&rec, &scene.table)?;
        rank3::recording::log_synth_truth(&rec, &scene)?;
    }
    std::fs::create_dir_all(&a.out).map_err(|e| rank3::Error::io(&a.out, e))?;
    let tracks = a.out.join("tracks.csv");
    scene.table.write(&tracks)?;
    let truth = a.out.join("truth.json");
    rank3::atomic::write(&truth, scene.truth_json())?;
    say!(
        "wrote {} ({} frames × {} tracks, {} observations) and {}",
        tracks.display(),
        scene.table.n_frames(),
        scene.table.n_tracks(),
        scene.table.n_observed(),
        truth.display()
    );
    Ok(())
}
