//! The `rank3` command line: `rank3 synth`, `rank3 reconstruct`.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Parser, Subcommand, ValueEnum};
use rank3::synth::{Motion, OutlierKind, Shape, SynthConfig};
use rank3::tracks::read_tracks;
use rank3::{CameraModel, Config, Reconstruction};

#[derive(Parser)]
#[command(
    name = "rank3",
    version,
    about = "Structure and motion from 2D point tracks by Tomasi–Kanade factorization"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Reconstruct metric structure and cameras from a track table (.csv, .txt, .json).
    Reconstruct(ReconstructArgs),
    /// Write a synthetic scene with ground truth: DIR/tracks.csv and DIR/truth.json.
    Synth(SynthArgs),
}

#[derive(Clone, Copy, ValueEnum)]
enum CameraArg {
    Orthographic,
    ScaledOrthographic,
}

impl From<CameraArg> for CameraModel {
    fn from(c: CameraArg) -> Self {
        match c {
            CameraArg::Orthographic => CameraModel::Orthographic,
            CameraArg::ScaledOrthographic => CameraModel::ScaledOrthographic,
        }
    }
}

#[derive(clap::Args)]
struct ReconstructArgs {
    /// Track table: .csv (frame,track,x,y), .txt (dense 2F×N, nan = missing) or .json.
    tracks: PathBuf,
    /// Output directory (reconstruction.json, completed.txt, points.ply).
    #[arg(long)]
    out: PathBuf,
    /// Metric camera model.
    #[arg(long, value_enum, default_value = "orthographic")]
    camera: CameraArg,
    /// Skip the Levenberg–Marquardt metric refinement.
    #[arg(long)]
    no_refine: bool,
    /// Always solve the metric upgrade as a PSD-constrained SDP.
    #[arg(long)]
    force_sdp: bool,
    /// Seed of the randomized SVD.
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

#[derive(Clone, Copy, ValueEnum)]
enum ShapeArg {
    House,
    Cloud,
    Cube,
}

#[derive(Clone, Copy, ValueEnum)]
enum MotionArg {
    Turntable,
    HandheldArc,
}

#[derive(Clone, Copy, ValueEnum)]
enum OutlierArg {
    Mixed,
    RandomWalk,
    SecondObject,
    Sliding,
}

#[derive(clap::Args)]
struct SynthArgs {
    /// Output directory.
    #[arg(long)]
    out: PathBuf,
    #[arg(long, default_value_t = 30)]
    frames: usize,
    #[arg(long, default_value_t = 200)]
    points: usize,
    /// Image noise σ, pixels.
    #[arg(long, default_value_t = 0.5)]
    noise: f64,
    #[arg(long, value_enum, default_value = "orthographic")]
    camera: CameraArg,
    #[arg(long, value_enum, default_value = "house")]
    shape: ShapeArg,
    #[arg(long, value_enum, default_value = "turntable")]
    motion: MotionArg,
    /// Fraction of entries missing (each track visible in one contiguous window).
    #[arg(long, default_value_t = 0.0)]
    missing: f64,
    /// Fraction of tracks that are outliers.
    #[arg(long, default_value_t = 0.0)]
    outliers: f64,
    #[arg(long, value_enum, default_value = "mixed")]
    outlier_kind: OutlierArg,
    /// Fraction of entries of inlier tracks with a gross error (15–60 px).
    #[arg(long, default_value_t = 0.0)]
    gross: f64,
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Reconstruct(a) => reconstruct(&a),
        Command::Synth(a) => synth(&a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn reconstruct(a: &ReconstructArgs) -> Result<(), rank3::Error> {
    let loaded = read_tracks(&a.tracks)?;
    for w in &loaded.warnings {
        eprintln!("warning: {w}");
    }
    let t = &loaded.table;
    eprintln!(
        "read {}: {} frames × {} tracks, {} observations ({:.1} % filled)",
        a.tracks.display(),
        t.n_frames(),
        t.n_tracks(),
        t.n_observed(),
        100.0 * t.fill()
    );
    let mut config = Config {
        camera: a.camera.into(),
        ..Config::default()
    };
    config.svd.seed = a.seed;
    config.metric.force_sdp = a.force_sdp;
    if a.no_refine {
        config.refine = None;
    }
    let rec = Reconstruction::from_tracks(t, &config)?;
    let written = rank3::output::write_all(&rec, &a.out)?;
    print_summary(&rec, &written.json, &a.out);
    Ok(())
}

fn print_summary(rec: &Reconstruction, json: &Path, out: &Path) {
    for s in &rec.set_aside {
        eprintln!("set aside {:?} {}: {}", s.kind, s.id, s.reason);
    }
    for w in &rec.warnings {
        eprintln!("warning: {w}");
    }
    let sv: Vec<String> = rec
        .singular_values
        .iter()
        .take(6)
        .map(|v| format!("{v:.4}"))
        .collect();
    eprintln!(
        "singular values: {} (σ4/σ3 = {:.4})",
        sv.join(" "),
        rec.rank_ratio
    );
    eprintln!(
        "affine fit RMS {:.6} px; metric upgrade by {:?} (least-squares L min eigenvalue {:.3e})",
        rec.factorization.rms_px, rec.metric_upgrade.method, rec.metric_upgrade.min_eigenvalue_ls
    );
    if let Some(r) = &rec.refinement {
        eprintln!(
            "refinement: RMS {:.6} → {:.6} px ({:?}, {} iterations, {:.3} s)",
            r.rms_before_px, r.rms_after_px, r.status, r.iterations, r.seconds
        );
    }
    println!(
        "{} camera, {} frames, {} points, RMS {:.6} px → {}",
        rec.camera_model,
        rec.frames.len(),
        rec.points.len(),
        rec.rms_px,
        out.display()
    );
    let _ = json;
}

fn synth(a: &SynthArgs) -> Result<(), rank3::Error> {
    let cfg = SynthConfig {
        shape: match a.shape {
            ShapeArg::House => Shape::House,
            ShapeArg::Cloud => Shape::Cloud,
            ShapeArg::Cube => Shape::Cube,
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
        outlier_kind: match a.outlier_kind {
            OutlierArg::Mixed => OutlierKind::Mixed,
            OutlierArg::RandomWalk => OutlierKind::RandomWalk,
            OutlierArg::SecondObject => OutlierKind::SecondObject,
            OutlierArg::Sliding => OutlierKind::Sliding,
        },
        gross: a.gross,
        seed: a.seed,
        ..SynthConfig::default()
    };
    let scene = rank3::synth::generate(&cfg)?;
    std::fs::create_dir_all(&a.out).map_err(|e| rank3::Error::io(&a.out, e))?;
    let tracks = a.out.join("tracks.csv");
    scene.table.write(&tracks)?;
    let truth = a.out.join("truth.json");
    std::fs::write(&truth, scene.truth_json()).map_err(|e| rank3::Error::io(&truth, e))?;
    println!(
        "wrote {} ({} frames × {} tracks, {} observations) and {}",
        tracks.display(),
        scene.table.n_frames(),
        scene.table.n_tracks(),
        scene.table.n_observed(),
        truth.display()
    );
    Ok(())
}
