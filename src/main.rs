//! The `rank3` command line: `rank3 synth`, `rank3 reconstruct`.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Parser, Subcommand, ValueEnum};
use rank3::synth::{Motion, OutlierKind, Shape, SynthConfig};
use rank3::table::read_tracks;
use rank3::{CameraModel, Config, Reconstruction};

#[derive(Parser)]
#[command(
    name = "rank3",
    version,
    about = "Structure and motion from 2D point tracks by Tomasi–Kanade factorization",
    after_help = "Exit status: 0 success; 1 an error (bad input, naming its file, line and \
                  field; an output or recording that could not be written; a solver's setup \
                  that failed); 2 a usage error (an unknown or missing argument)."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Reconstruct metric structure and cameras from a track table (.csv, .txt, .json, .npy,
    /// .npz, a COLMAP text model folder, or --x/--y matrices).
    Reconstruct(ReconstructArgs),
    /// Write a synthetic scene with ground truth: DIR/tracks.csv and DIR/truth.json.
    Synth(SynthArgs),
    /// Track corners through a folder of images or a video (KLT) into a track table.
    Track(TrackArgs),
    /// Video or images → tracks → reconstruction, in one command.
    Run(RunArgs),
    /// Score a reconstruction against a reference (synth's truth.json or another
    /// reconstruction.json): structure, rotation, camera centre and focal length errors.
    Eval(EvalArgs),
}

#[derive(clap::Args)]
struct EvalArgs {
    /// The reconstruction: a reconstruction.json, or the output folder holding it.
    reconstruction: PathBuf,
    /// The reference: the truth.json written by `rank3 synth`, another reconstruction.json,
    /// or a folder holding either.
    #[arg(long, short = 'r', value_name = "FILE|DIR")]
    reference: PathBuf,
    /// Print the scores as JSON instead of a table.
    #[arg(long)]
    json: bool,
}

/// `rank3 eval`: the table (or JSON) on stdout; errors as the other subcommands (exit 1).
fn eval_cmd(a: &EvalArgs) -> ExitCode {
    match rank3::compare::evaluate(&a.reconstruction, &a.reference) {
        Ok(c) if a.json => {
            say(format_args!(
                "{}",
                serde_json::to_string_pretty(&c).unwrap_or_default()
            ));
            ExitCode::SUCCESS
        }
        Ok(c) => {
            say(format_args!("{}", c.to_string().trim_end()));
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

#[derive(Clone, Copy, ValueEnum)]
enum CameraArg {
    /// Chosen from the data: the perspective camera when it explains the tracks
    /// significantly better than the scaled orthographic one (BIC), else the latter.
    Auto,
    /// Orthographic projection (affine, unit scale).
    Orthographic,
    /// Scaled orthographic / weak perspective (affine, one scale per frame).
    ScaledOrthographic,
    /// Projective camera `w ≃ P X` (3×4 P per frame, homogeneous points; up to a 4×4
    /// homography). Not for `synth`.
    Projective,
    /// Pinhole perspective camera `K [R | t]`: projective factorization, self-calibration
    /// (or the given `--focal`), metric bundle adjustment.
    Perspective,
}

impl From<CameraArg> for CameraModel {
    fn from(c: CameraArg) -> Self {
        match c {
            CameraArg::Orthographic => CameraModel::Orthographic,
            CameraArg::ScaledOrthographic => CameraModel::ScaledOrthographic,
            CameraArg::Perspective => CameraModel::Perspective,
            CameraArg::Projective => CameraModel::Projective,
            CameraArg::Auto => CameraModel::Auto,
        }
    }
}

#[derive(clap::Args)]
struct ReconstructArgs {
    /// Track table: .csv (frame,track,x,y), .txt (dense 2F×N, nan = missing), .json,
    /// .npy (float array (F, N, 2) or (2F, N), NaN = missing), .npz (`tracks`, or `x` and
    /// `y`; optional `frame_ids`, `track_ids`), or a folder holding a COLMAP text model
    /// (images.txt: one track per 3D point, one frame per image). See docs/formats.md.
    #[arg(required_unless_present = "x", value_name = "TRACKS")]
    tracks: Option<PathBuf>,
    /// Instead of TRACKS: the x coordinates as a frames × tracks matrix (one row per frame,
    /// nan = missing; text, or a 2-D .npy), e.g. the CMU hotel tracked_points_Xs.txt. Needs
    /// --y.
    #[arg(
        long = "x",
        value_name = "FILE",
        requires = "y",
        conflicts_with = "tracks"
    )]
    x: Option<PathBuf>,
    /// The y coordinates matching --x (same shape and format).
    #[arg(
        long = "y",
        value_name = "FILE",
        requires = "x",
        conflicts_with = "tracks"
    )]
    y: Option<PathBuf>,
    /// Output directory (reconstruction.json, completed.txt, points.ply).
    #[arg(long)]
    out: PathBuf,
    /// Camera model (the projective and perspective reconstructions also hold the affine
    /// model they start from).
    #[arg(long, value_enum, default_value = "auto")]
    camera: CameraArg,
    /// The frames the tracks come from (folder of PNG/JPEG or video, matched to the table's
    /// frames by id, else by position): with them a textured mesh (mesh.obj + mesh.mtl +
    /// mesh_texture.png, mesh.glb) is built and points.ply gets colours.
    #[arg(long, value_name = "DIR|VIDEO")]
    images: Option<PathBuf>,
    #[command(flatten)]
    opts: ReconstructOpts,
    #[cfg(feature = "rerun")]
    #[command(flatten)]
    record: rank3::recording::RecordingArgs,
}

/// Options of the reconstruction shared by `reconstruct` and `run`.
#[derive(clap::Args)]
struct ReconstructOpts {
    /// Skip the Levenberg–Marquardt metric refinement.
    #[arg(long)]
    no_refine: bool,
    /// Always solve the metric upgrade as a PSD-constrained SDP.
    #[arg(long)]
    force_sdp: bool,
    /// Skip the robust pass (RANSAC over tracks, gross-entry flags).
    #[arg(long)]
    no_robust: bool,
    /// Inlier threshold of the robust pass, pixels (default: estimated from the data).
    #[arg(long, value_name = "PX")]
    threshold: Option<f64>,
    /// Missing-data solver: `wiberg` (damped Wiberg / variable projection, reliable) or
    /// `als` (alternating least squares, simple, can stall).
    #[arg(long, value_enum, default_value = "wiberg")]
    solver: SolverArg,
    /// Start of the missing-data solver: `auto` (data-driven) or `random` (seeded).
    #[arg(long, value_enum, default_value = "auto")]
    init: InitArg,
    /// Random starts of the missing-data solver (the best is kept).
    #[arg(long, default_value_t = 1)]
    runs: usize,
    /// Seed of every random choice (robust sampling, random starts, randomized SVD).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Perspective camera: the known focal length, pixels (default: self-calibrated).
    #[arg(long, value_name = "PX")]
    focal: Option<f64>,
    /// Perspective camera: the known principal point, pixels (default: the image centre,
    /// or estimated when the image size is not known either).
    #[arg(long, value_name = "X,Y", value_parser = parse_pair::<f64>)]
    principal_point: Option<[f64; 2]>,
    /// Perspective camera: the image size, pixels (`rank3 run` knows it from the frames).
    #[arg(long, value_name = "W,H", value_parser = parse_pair::<u32>)]
    image_size: Option<[u32; 2]>,
    /// Perspective camera: one focal length per frame (a zooming camera).
    #[arg(long)]
    per_frame_focal: bool,
    /// Perspective camera: estimate the principal point in the bundle adjustment.
    #[arg(long)]
    estimate_principal_point: bool,
    /// Perspective camera: estimate one radial distortion coefficient k1.
    #[arg(long)]
    distortion: bool,
    /// Robust loss of the perspective bundle adjustment.
    #[arg(long, value_enum, default_value = "huber")]
    loss: LossArg,
    /// Scale of the robust loss, pixels.
    #[arg(long, value_name = "PX", default_value_t = 2.0)]
    loss_scale: f64,
    /// Independently moving objects: segment the tracks into rigid groups, `auto` (the
    /// number found from the data) or a given count K, and reconstruct each group on its
    /// own: OUT/objects.csv (track,object; -1 = outlier), OUT/segmentation.json and
    /// OUT/object_<k>/ per object (docs/formats.md).
    #[arg(long, value_name = "auto|K", value_parser = parse_objects)]
    objects: Option<rank3::segment::Objects>,
    /// Do not build the textured mesh (built by default when the frames are known: `run`,
    /// `reconstruct --images`).
    #[arg(long)]
    no_mesh: bool,
    /// Leave the outlier tracks' points out of points.ply.
    #[arg(long)]
    ply_inliers_only: bool,
}

/// A line on stdout; a closed stdout (`rank3 … | head`) is not an error worth a panic.
fn say(line: std::fmt::Arguments<'_>) {
    use std::io::Write as _;
    let _ = writeln!(std::io::stdout().lock(), "{line}");
}

/// Refuses, before anything is opened, an output (the .rrd, the output file or folder, the
/// files written in the folder) that would overwrite an input.
fn refuse_overwriting_inputs(
    inputs: &[&Path],
    out_dir: Option<&Path>,
    out_file: Option<&Path>,
    #[cfg(feature = "rerun")] record: &rank3::recording::RecordingArgs,
) -> Result<(), rank3::Error> {
    let mut outputs: Vec<(&'static str, PathBuf)> = Vec::new();
    #[cfg(feature = "rerun")]
    if let Some(r) = &record.rrd {
        outputs.push(("--rrd", r.clone()));
    }
    if let Some(f) = out_file {
        outputs.push(("--out", f.to_path_buf()));
    }
    if let Some(d) = out_dir {
        outputs.push(("--out", d.to_path_buf()));
        let written = rank3::output::RECONSTRUCTION_FILES
            .iter()
            .chain(&rank3::output::OBJECTS_FILES)
            .chain(&rank3::mesh::export::MESH_FILES)
            .chain(&["tracks.csv"]);
        outputs.extend(written.map(|n| ("output file", d.join(n))));
    }
    let refs: Vec<(&'static str, &Path)> = outputs.iter().map(|(w, p)| (*w, p.as_path())).collect();
    rank3::output::check_outputs(&refs, inputs)
}

fn parse_synth_object(item: &str) -> Result<rank3::synth::SynthObject, String> {
    use rank3::synth::{ObjectMotion, SynthObject};
    let (share, motion) = item
        .trim()
        .split_once(':')
        .ok_or_else(|| format!("`{item}` is not SHARE:MOTION (e.g. 0.2:rotating)"))?;
    let share: f64 = share
        .trim()
        .parse()
        .map_err(|_| format!("`{share}` is not a fraction"))?;
    let motion = match motion.trim() {
        "rotating" => ObjectMotion::Rotating,
        "translating" => ObjectMotion::Translating,
        m => {
            return Err(format!(
                "motion `{m}` is neither `rotating` nor `translating`"
            ));
        }
    };
    Ok(SynthObject { share, motion })
}

fn parse_objects(s: &str) -> Result<rank3::segment::Objects, String> {
    if s.eq_ignore_ascii_case("auto") {
        return Ok(rank3::segment::Objects::Auto);
    }
    match s.parse::<usize>() {
        Ok(k) if (1..=1000).contains(&k) => Ok(rank3::segment::Objects::Count(k)),
        _ => Err(format!("`{s}` is neither `auto` nor a count in 1..=1000")),
    }
}

/// `--objects`: segmentation, one reconstruction per object, their files and recording.
fn reconstruct_objects_cli(
    #[cfg(feature = "rerun")] recording: Option<&rerun::RecordingStream>,
    table: &rank3::TrackTable,
    config: &Config,
    objects: rank3::segment::Objects,
    out: &Path,
) -> Result<(), rank3::Error> {
    let seg = rank3::segment::SegmentConfig {
        objects,
        image_area: config
            .perspective
            .intrinsics
            .image_size
            .map(|[w, h]| w as f64 * h as f64),
        ..Default::default()
    };
    let mb = rank3::objects::reconstruct_objects(table, config, &seg)?;
    #[cfg(feature = "rerun")]
    if let Some(r) = recording {
        rank3::recording::log_objects(r, table, &mb)?;
    }
    let given = matches!(objects, rank3::segment::Objects::Count(_));
    let dirs: Vec<String> = mb
        .objects
        .iter()
        .filter(|o| o.reconstruction.is_ok())
        .map(|o| rank3::objects::object_dir(o.index))
        .collect();
    let mut keep = rank3::output::OBJECTS_FILES.to_vec();
    keep.extend(dirs.iter().map(String::as_str));
    rank3::output::remove_stale(out, &keep)?;
    rank3::output::write_objects(&mb, given, out)?;
    let s = &mb.segmentation;
    eprintln!(
        "segmentation: {} object(s) ({}), {} outlier and {} unscored tracks, σ {:.3} px, {} rounds, {:.2} s",
        mb.objects.len(),
        if given { "given" } else { "found" },
        s.n_outliers(),
        s.n_unscored(),
        s.sigma,
        s.rounds,
        s.seconds
    );
    for o in &mb.objects {
        match &o.reconstruction {
            Ok(r) => eprintln!(
                "object {}: {} tracks, camera {:?}, RMS {:.3} px -> {}",
                o.index,
                o.tracks.len(),
                r.camera_model,
                r.rms_px,
                out.join(rank3::objects::object_dir(o.index)).display()
            ),
            Err(e) => eprintln!(
                "object {}: {} tracks, not reconstructed: {e}",
                o.index,
                o.tracks.len()
            ),
        }
    }
    let [csv, json] = rank3::output::OBJECTS_FILES.map(|name| out.join(name));
    eprintln!("wrote {} and {}", csv.display(), json.display());
    Ok(())
}

#[derive(Clone, Copy, ValueEnum)]
enum LossArg {
    /// Plain least squares.
    None,
    /// Huber: quadratic within the scale, linear beyond.
    Huber,
    /// Cauchy: logarithmic beyond the scale.
    Cauchy,
}

/// Parses `A,B` (or `AxB`) into two values.
fn parse_pair<T: std::str::FromStr>(s: &str) -> Result<[T; 2], String> {
    let parts: Vec<&str> = s.split([',', 'x', 'X']).map(str::trim).collect();
    match parts.as_slice() {
        [a, b] => match (a.parse(), b.parse()) {
            (Ok(a), Ok(b)) => Ok([a, b]),
            _ => Err(format!("`{s}`: expected two numbers as A,B")),
        },
        _ => Err(format!("`{s}`: expected two numbers as A,B")),
    }
}

#[derive(Clone, Copy, ValueEnum)]
enum SolverArg {
    Wiberg,
    Als,
}

#[derive(Clone, Copy, ValueEnum)]
enum InitArg {
    Auto,
    Random,
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
    /// Camera: orthographic, scaled orthographic (weak perspective) or pinhole perspective
    /// (truth.json then also holds each frame's K, R, t, P and camera centre).
    #[arg(long, value_enum, default_value = "orthographic")]
    camera: CameraArg,
    /// Focal length of the perspective camera, pixels [default: DISTANCE · 200, so that the
    /// object spans about 400 px].
    #[arg(long, value_name = "PX")]
    focal: Option<f64>,
    /// Distance of the perspective camera from the object's centre, in object radii
    /// (> 1.2; 2–3 is strong perspective, 20 or more nearly weak perspective).
    #[arg(long, value_name = "D", default_value_t = rank3::synth::DEFAULT_DISTANCE)]
    distance: f64,
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
    /// Extra rigid objects moving independently of the main one, as a comma-separated
    /// list of `SHARE:MOTION` (fraction of the tracks, `rotating` or `translating`), e.g.
    /// `0.2:rotating,0.15:translating`. Their tracks' object is `object` in truth.json.
    #[arg(long, value_name = "SHARE:MOTION,...", value_delimiter = ',', value_parser = parse_synth_object)]
    objects: Option<Vec<rank3::synth::SynthObject>>,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    #[cfg(feature = "rerun")]
    #[command(flatten)]
    record: rank3::recording::RecordingArgs,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Reconstruct(a) => reconstruct(&a),
        Command::Synth(a) => synth(&a),
        Command::Track(a) => track_cmd(&a),
        Command::Run(a) => run_cmd(&a),
        Command::Eval(a) => return eval_cmd(&a),
    };
    // A recording that could not be written or streamed is an error too (after the
    // command's own outputs, which are written by then).
    #[cfg(feature = "rerun")]
    let recording_failures = rank3::recording::finish_opened(std::time::Duration::from_secs(20));
    #[cfg(not(feature = "rerun"))]
    let recording_failures: Vec<String> = Vec::new();
    for f in &recording_failures {
        eprintln!("error: {f}");
    }
    match result {
        Ok(()) if recording_failures.is_empty() => ExitCode::SUCCESS,
        Ok(()) => ExitCode::FAILURE,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn reconstruct(a: &ReconstructArgs) -> Result<(), rank3::Error> {
    let mut inputs: Vec<&Path> = [&a.tracks, &a.x, &a.y]
        .into_iter()
        .filter_map(Option::as_deref)
        .collect();
    inputs.extend(a.images.as_deref());
    refuse_overwriting_inputs(
        &inputs,
        Some(&a.out),
        None,
        #[cfg(feature = "rerun")]
        &a.record,
    )?;
    // The table is read before the recording opens (opening it replaces an existing .rrd,
    // which bad input must not destroy).
    let loaded = match (&a.tracks, &a.x, &a.y) {
        (Some(t), _, _) => read_tracks(t)?,
        (None, Some(x), Some(y)) => rank3::table::read_xy(x, y)?,
        _ => {
            return Err(rank3::Error::InvalidConfig {
                field: "TRACKS",
                message: "give a track table, or --x and --y".into(),
            });
        }
    };
    #[cfg(feature = "rerun")]
    let recording = a.record.open(
        "rank3",
        rank3::recording::LayoutParts {
            reconstruction: a.opts.objects.is_none(),
            perspective: matches!(a.camera, CameraArg::Perspective) && a.opts.objects.is_none(),
            objects: a.opts.objects.is_some(),
            ..Default::default()
        },
    )?;
    for w in &loaded.warnings {
        eprintln!("warning: {w}");
    }
    let t = &loaded.table;
    eprintln!(
        "read {}: {} frames × {} tracks, {} observations ({:.1} % filled)",
        match (&a.tracks, &a.y) {
            (None, Some(y)) => format!("{} and {}", loaded.path.display(), y.display()),
            _ => loaded.path.display().to_string(),
        },
        t.n_frames(),
        t.n_tracks(),
        t.n_observed(),
        100.0 * t.fill()
    );
    let config = a.opts.config(a.camera, None);
    if let Some(objects) = a.opts.objects {
        return reconstruct_objects_cli(
            #[cfg(feature = "rerun")]
            recording.as_ref(),
            t,
            &config,
            objects,
            &a.out,
        );
    }
    #[cfg(feature = "rerun")]
    let rec = rank3::recording::reconstruct_recorded(recording.as_ref(), t, &config)?;
    #[cfg(feature = "rerun")]
    show_perspective_layout(
        recording.as_ref(),
        &rec,
        a.camera,
        rank3::recording::LayoutParts {
            reconstruction: true,
            ..Default::default()
        },
    )?;
    #[cfg(not(feature = "rerun"))]
    let rec = Reconstruction::from_tracks(t, &config)?;
    write_outputs(
        rec,
        t,
        a.images.as_deref().map(|p| (p, a.opts.image_size)),
        &a.opts,
        &a.out,
        #[cfg(feature = "rerun")]
        recording.as_ref(),
    )
}

/// Builds the textured mesh when the frames are known (a failure is reported after the
/// reconstruction's files are written, so nothing computed is lost), then writes every
/// output of a single-object run and prints the summary.
fn write_outputs(
    mut rec: Reconstruction,
    table: &rank3::TrackTable,
    frames: Option<(&Path, Option<[u32; 2]>)>,
    opts: &ReconstructOpts,
    out: &Path,
    #[cfg(feature = "rerun")] recording: Option<&rerun::RecordingStream>,
) -> Result<(), rank3::Error> {
    let mut mesh_error = None;
    let mesh = match frames {
        Some((path, size)) if !opts.no_mesh => {
            match rank3::mesh::from_frames(&rec, table, path, size, &Default::default()) {
                Ok(m) => Some(m),
                Err(e) => {
                    mesh_error = Some(e);
                    None
                }
            }
        }
        _ => None,
    };
    if let Some(m) = &mesh {
        rec.mesh = Some(m.report.clone());
    }
    let colors: Option<std::collections::HashMap<rank3::Id, [u8; 3]>> = mesh.as_ref().map(|m| {
        table
            .track_ids()
            .iter()
            .zip(&m.track_colors)
            .filter_map(|(id, c)| Some((id.clone(), (*c)?)))
            .collect()
    });
    let mut keep = rank3::output::RECONSTRUCTION_FILES.to_vec();
    if rec.sparse.is_some() {
        // No completed.txt (see output::Written); an earlier run's is removed.
        keep.retain(|&f| f != "completed.txt");
    }
    if rec.perspective.is_some() {
        keep.push("colmap");
    }
    if mesh.is_some() {
        keep.extend(rank3::mesh::export::MESH_FILES);
    }
    rank3::output::remove_stale(out, &keep)?;
    rank3::output::write_all_with(
        &rec,
        out,
        rank3::output::PlyOptions {
            colors: colors.as_ref(),
            inliers_only: opts.ply_inliers_only,
        },
    )?;
    if let Some(m) = &mesh {
        rank3::mesh::export::write_all(m, out)?;
        #[cfg(feature = "rerun")]
        if let Some(r) = recording {
            rank3::recording::log_mesh(r, &rec, m)?;
        }
    }
    write_colmap(&rec, table, out)?;
    print_summary(&rec, out);
    if let Some(m) = &mesh {
        if let Some(t) = &m.report.texture
            && t.charts_unfilled > 0
        {
            eprintln!(
                "warning: {} of {} texture charts come from frames that were not given (left \
                 black): {} of the {} frames read matched the table's {} frames by {}",
                t.charts_unfilled,
                t.charts,
                t.frames_matched,
                t.frames_read,
                table.n_frames(),
                t.frames_matched_by
            );
        }
        let s = &m.report.surface;
        let tex = m.report.texture.as_ref().map_or(String::new(), |t| {
            format!(
                ", texture {}×{} px from {} frames",
                t.atlas_px[0], t.atlas_px[1], t.views_used
            )
        });
        say(format_args!(
            "mesh: {} triangles on {} tracks{tex} ({:.2} s) → {}",
            s.triangles,
            s.vertices,
            m.report.seconds_surface + m.report.seconds_texture,
            out.join("mesh.glb").display()
        ));
    }
    match mesh_error {
        Some(e) => {
            eprintln!("the reconstruction was written; the mesh was not:");
            Err(e)
        }
        None => Ok(()),
    }
}

/// With `--camera auto` the layout sent when the recording opened has no perspective views
/// (the camera was not chosen yet); when the perspective camera was chosen, the layout is
/// sent again with its structure beside the affine model's.
#[cfg(feature = "rerun")]
fn show_perspective_layout(
    recording: Option<&rerun::RecordingStream>,
    rec: &Reconstruction,
    camera: CameraArg,
    parts: rank3::recording::LayoutParts,
) -> Result<(), rank3::Error> {
    if let Some(r) = recording
        && matches!(camera, CameraArg::Auto)
        && rec.perspective.is_some()
    {
        rank3::recording::send_layout(
            r,
            rank3::recording::LayoutParts {
                perspective: true,
                ..parts
            },
        )?;
    }
    Ok(())
}

/// With a perspective result, the COLMAP text model in `OUT/colmap/`.
fn write_colmap(
    rec: &Reconstruction,
    table: &rank3::TrackTable,
    out: &Path,
) -> Result<(), rank3::Error> {
    let dir = out.join("colmap");
    if rank3::output::write_colmap(rec, table, &dir)? {
        eprintln!("wrote COLMAP model {}", dir.display());
    }
    Ok(())
}

impl ReconstructOpts {
    /// The library configuration; `image_size` is what the tracker saw (`run`), used
    /// unless `--image-size` is given.
    fn config(&self, camera: CameraArg, image_size: Option<[u32; 2]>) -> Config {
        let a = self;
        let mut config = Config {
            camera: camera.into(),
            ..Config::default()
        };
        config.svd.seed = a.seed;
        config.seed = a.seed;
        config.completion.seed = a.seed;
        config.completion.runs = a.runs;
        config.completion.solver = match a.solver {
            SolverArg::Wiberg => rank3::completion::CompletionSolverKind::Wiberg,
            SolverArg::Als => rank3::completion::CompletionSolverKind::Als,
        };
        config.completion.init = match a.init {
            InitArg::Auto => rank3::completion::Init::Auto,
            InitArg::Random => rank3::completion::Init::Random,
        };
        if a.no_robust {
            config.robust = None;
        } else if let (Some(rc), Some(px)) = (config.robust.as_mut(), a.threshold) {
            rc.ransac.threshold_px = Some(px);
        }
        config.metric.force_sdp = a.force_sdp;
        if a.no_refine {
            config.refine = None;
        }
        let p = &mut config.perspective;
        p.intrinsics = rank3::perspective::Intrinsics {
            focal_px: a.focal,
            principal_point: a.principal_point,
            image_size: a.image_size.or(image_size),
        };
        p.per_frame_focal = a.per_frame_focal;
        p.estimate_principal_point = a.estimate_principal_point;
        p.distortion = a.distortion;
        p.loss = match a.loss {
            LossArg::None => rank3::perspective::Loss::Squared,
            LossArg::Huber => rank3::perspective::Loss::Huber(a.loss_scale),
            LossArg::Cauchy => rank3::perspective::Loss::Cauchy(a.loss_scale),
        };
        config
    }
}

fn print_summary(rec: &Reconstruction, out: &Path) {
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
    if rec.completion.is_none() {
        eprintln!(
            "singular values: {} (σ4/σ3 = {:.4})",
            sv.join(" "),
            rec.rank_ratio
        );
    } else {
        // With missing data the spectrum is that of the rank-3 completion: σ4/σ3 comes from
        // the largest complete block.
        eprintln!(
            "singular values of the completed matrix: {} (σ4/σ3 = {:.4} on {})",
            sv.join(" "),
            rec.rank_ratio,
            rec.rank_ratio_source
        );
    }
    if let Some(r) = &rec.robust {
        eprintln!(
            "robust pass: {} inlier / {} outlier tracks, {} gross entries flagged (σ ≈ {:.3} px, \
             RANSAC τ {:.3} px on trimmed RMS, entry threshold {:.3} px, {:.2} s)",
            r.n_inlier_tracks,
            r.n_outlier_tracks,
            r.n_flagged_entries,
            r.noise_sigma_px,
            r.threshold_px,
            r.entry_threshold_px,
            r.seconds
        );
    }
    if let Some(c) = &rec.completion {
        eprintln!(
            "completion: {} ({:?} model) affine RMS {:.6} px, {:?} after {} iterations, {:.2} s",
            c.solver.name(),
            c.model,
            c.rms_px,
            c.status,
            c.iterations,
            c.seconds
        );
    }
    eprintln!(
        "affine fit RMS {:.6} px; metric upgrade by {:?} (least-squares L min eigenvalue {:.3e})",
        rec.factorization.rms_px, rec.metric_upgrade.method, rec.metric_upgrade.min_eigenvalue_ls
    );
    if let Some(r) = &rec.refinement
        && let Some(why) = &r.skipped
    {
        eprintln!("refinement: skipped: {why}");
    } else if let Some(r) = &rec.refinement {
        eprintln!(
            "refinement: RMS {:.6} → {:.6} px ({:?}, {} iterations, {:.3} s)",
            r.rms_before_px, r.rms_after_px, r.status, r.iterations, r.seconds
        );
    }
    if let Some(j) = rec.robust.as_ref().and_then(|r| r.projective.as_ref()) {
        eprintln!(
            "projective verdict: {} track(s) readmitted, {} rejected, flagged entries {} → {} \
             (σ ≈ {:.3} px, entry threshold {:.3} px), {} refit(s)",
            j.readmitted_tracks,
            j.rejected_tracks,
            j.flagged_before,
            j.flagged_after,
            j.noise_sigma_px,
            j.entry_threshold_px,
            j.refits
        );
    }
    if let Some(p) = &rec.projective {
        for s in &p.stages {
            eprintln!(
                "projective {}: RMS {:.6} → {:.6} px ({:?}, {} iterations, {:.3} s)",
                s.stage, s.rms_before_px, s.rms_after_px, s.status, s.iterations, s.seconds
            );
        }
    }
    if let Some(p) = &rec.perspective
        && let Some(sc) = &p.self_calibration
    {
        eprintln!(
            "self-calibration: {} (linear Q eigenvalues {:.3} {:.3} {:.3} {:.3}{}), {:.1} % of \
             observations in front",
            if sc.sdp { "PSD-constrained" } else { "linear" },
            sc.linear_eigenvalues[0],
            sc.linear_eigenvalues[1],
            sc.linear_eigenvalues[2],
            sc.linear_eigenvalues[3],
            sc.sdp_status
                .as_ref()
                .map_or(String::new(), |s| format!(", SDP {s}")),
            100.0 * p.in_front
        );
    }
    if let Some(p) = &rec.perspective {
        let starts: Vec<String> = p
            .starts
            .iter()
            .map(|s| {
                format!(
                    "{}{} f={:.0}: {:.3}{}",
                    s.kind,
                    if s.mirrored { " (mirrored)" } else { "" },
                    s.focal_px,
                    s.rms_px,
                    if s.chosen { " ←" } else { "" }
                )
            })
            .collect();
        eprintln!(
            "perspective starts (RMS px after screening): {}",
            starts.join(", ")
        );
        for s in &p.stages {
            eprintln!(
                "perspective {}: RMS {:.6} → {:.6} px ({:?}, {} iterations, {:.3} s)",
                s.stage, s.rms_before_px, s.rms_after_px, s.status, s.iterations, s.seconds
            );
        }
        let k = &p.intrinsics;
        eprintln!(
            "intrinsics: focal {:.2} px ({}), principal point ({:.2}, {:.2}) ({}), k1 {:.4}",
            k.focal_px,
            k.focal,
            k.principal_point[0],
            k.principal_point[1],
            k.principal_point_source,
            k.k1
        );
    }
    if let Some(sel) = &rec.model_selection {
        eprintln!("camera model chosen: {}", sel.reason);
    }
    let fitted = rec.points.iter().filter(|p| p.inlier).count();
    let outliers = rec.points.len() - fitted;
    say(format_args!(
        "{} camera, {} frames, {fitted} points fitted{}, RMS {:.6} px{} → {}",
        rec.camera_model,
        rec.frames.len(),
        if outliers > 0 {
            format!(" ({outliers} outlier tracks left out)")
        } else {
            String::new()
        },
        rec.rms_px,
        rec.perspective.as_ref().map_or(String::new(), |p| format!(
            ", focal {:.1} px",
            p.intrinsics.focal_px
        )),
        out.display()
    ));
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
        ..SynthConfig::default()
    };
    let scene = rank3::synth::generate(&cfg)?;
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
    say(format_args!(
        "wrote {} ({} frames × {} tracks, {} observations) and {}",
        tracks.display(),
        scene.table.n_frames(),
        scene.table.n_tracks(),
        scene.table.n_observed(),
        truth.display()
    ));
    Ok(())
}
// ---------------------------------------------------------------- rank3 track / rank3 run

/// Tracking options shared by `rank3 track` and `rank3 run`.
#[derive(clap::Args)]
struct TrackOpts {
    /// Follow these first-frame points (`x y` per line, `#` comments) instead of detecting;
    /// track ids are the 0-based indices of the point lines.
    #[arg(long)]
    init_points: Option<PathBuf>,
    /// Detect new corners as tracks die (always on without --init-points).
    #[arg(long)]
    redetect: bool,
    /// Maximum number of live tracks (corners detected, strongest first).
    #[arg(long, default_value_t = 500)]
    max_features: usize,
    /// Corner quality relative to the strongest corner's minimum eigenvalue.
    #[arg(long, default_value_t = 0.01)]
    quality: f32,
    /// Minimum distance between corners, pixels.
    #[arg(long, default_value_t = 8.0)]
    min_distance: f32,
    /// Lucas–Kanade window side (odd).
    #[arg(long, default_value_t = 21)]
    window: usize,
    /// Coarsest pyramid level (0 = no pyramid).
    #[arg(long, default_value_t = 3)]
    levels: usize,
    /// Newton iterations per level at most.
    #[arg(long, default_value_t = 30)]
    iterations: usize,
    /// Forward–backward round-trip tolerance, pixels.
    #[arg(long, default_value_t = 1.0)]
    fb_threshold: f32,
    /// Skip the forward–backward check (about twice as fast, less reliable).
    #[arg(long)]
    no_fb: bool,
    /// Largest mean absolute intensity error over the window (intensities in [0, 1]).
    #[arg(long, default_value_t = 0.06)]
    max_residual: f32,
    /// Low-texture threshold: minimum eigenvalue of the gradient matrix / window area.
    #[arg(long, default_value_t = 1e-4)]
    min_eigenvalue: f32,
    /// Lose points closer than this to the border, pixels (default 0: a point is lost when
    /// it leaves the image; its window may cross the border).
    #[arg(long)]
    border_margin: Option<f32>,
    /// Start new tracks at the whole-pixel corners, without the sub-pixel (Förstner)
    /// refinement.
    #[arg(long)]
    no_subpixel: bool,
}

impl TrackOpts {
    fn config(&self) -> rank3::tracking::TrackerConfig {
        let mut c = rank3::tracking::TrackerConfig::default();
        c.detect.max_features = self.max_features;
        c.detect.quality_level = self.quality;
        c.detect.min_distance = self.min_distance;
        c.klt.window = self.window;
        c.klt.max_level = self.levels;
        c.klt.max_iterations = self.iterations;
        c.klt.fb_threshold = (!self.no_fb).then_some(self.fb_threshold);
        c.klt.max_residual = self.max_residual;
        c.klt.min_eigenvalue = self.min_eigenvalue;
        c.klt.border_margin = self.border_margin;
        c.redetect_with_points = self.redetect;
        if self.no_subpixel {
            c.subpixel = None;
        }
        c
    }
}

#[derive(clap::Args)]
struct TrackArgs {
    /// A folder of PNG/JPEG frames (natural name order) or a video file (needs ffmpeg).
    input: PathBuf,
    /// Output track table: .csv, .txt, .json, .npy or .npz.
    #[arg(long)]
    out: PathBuf,
    #[command(flatten)]
    opts: TrackOpts,
    #[cfg(feature = "rerun")]
    #[command(flatten)]
    record: rank3::recording::RecordingArgs,
}

#[derive(clap::Args)]
struct RunArgs {
    /// A folder of PNG/JPEG frames (natural name order) or a video file (needs ffmpeg).
    input: PathBuf,
    /// Output directory (tracks.csv, reconstruction.json, completed.txt, points.ply).
    #[arg(long)]
    out: PathBuf,
    #[command(flatten)]
    opts: TrackOpts,
    /// Camera model.
    #[arg(long, value_enum, default_value = "auto")]
    camera: CameraArg,
    /// Reconstruct from the tracks seen in every frame only (by default the partial
    /// tracks are used, through the missing-data solver).
    #[arg(long)]
    complete_tracks: bool,
    #[command(flatten)]
    recon: ReconstructOpts,
    #[cfg(feature = "rerun")]
    #[command(flatten)]
    record: rank3::recording::RecordingArgs,
}

fn bar_style(template: &str) -> indicatif::ProgressStyle {
    indicatif::ProgressStyle::with_template(template)
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
}

/// What tracking produced: the table and the per-frame counts.
struct Tracked {
    table: rank3::TrackTable,
    /// Width and height of the frames, pixels.
    image_size: Option<[u32; 2]>,
    /// Per-frame counts (recorded with `--rrd`).
    #[cfg_attr(not(feature = "rerun"), allow(dead_code))]
    stats: Vec<rank3::tracking::FrameStats>,
}

/// Tracks `input` with a progress bar; prints a summary to stderr. `on_frame` sees every
/// decoded frame with its index.
fn track_input(
    input: &Path,
    opts: &TrackOpts,
    on_frame: &mut dyn FnMut(usize, &rank3::tracking::GrayImage),
) -> Result<Tracked, rank3::Error> {
    let cfg = opts.config();
    let init = opts
        .init_points
        .as_deref()
        .map(rank3::tracking::read_init_points)
        .transpose()?;
    let mut src = rank3::tracking::FrameSource::open(input)?;
    let bar = match src.len_hint() {
        Some(n) => indicatif::ProgressBar::new(n as u64).with_style(bar_style(
            "tracking {bar:30} {pos}/{len} frames ({per_sec}, eta {eta}) {msg}",
        )),
        None => indicatif::ProgressBar::new_spinner().with_style(bar_style(
            "tracking {spinner} {pos} frames ({per_sec}) {msg}",
        )),
    };
    let t0 = std::time::Instant::now();
    let cpu0 = process_cpu_seconds();
    let mut stats = Vec::new();
    let mut image_size = None;
    let result = rank3::tracking::track_source(&mut src, &cfg, init, &mut |s, image| {
        image_size.get_or_insert([image.width as u32, image.height as u32]);
        bar.inc(1);
        bar.set_message(format!("{} alive", s.alive));
        stats.push(*s);
        on_frame(s.frame, image);
    });
    bar.finish_and_clear();
    let (table, summary) = result?;
    let wall = t0.elapsed().as_secs_f64();
    let cpu = process_cpu_seconds().zip(cpu0).map(|(a, b)| a - b);
    let lost: Vec<String> = summary
        .lost
        .iter()
        .map(|(k, v)| format!("{k} {v}"))
        .collect();
    eprintln!(
        "tracked {} frames: {} tracks started, {} kept, {} alive at the end; lost: {}",
        summary.frames,
        summary.started,
        summary.kept,
        summary.alive_at_end,
        if lost.is_empty() {
            "none".to_string()
        } else {
            lost.join(", ")
        }
    );
    eprintln!(
        "tracking time {:.3} s ({:.1} frames/s), total with decoding {:.3} s ({:.1} frames/s){}",
        summary.seconds,
        summary.frames as f64 / summary.seconds.max(1e-9),
        wall,
        summary.frames as f64 / wall.max(1e-9),
        cpu.map_or(String::new(), |c| format!(", CPU {c:.3} s with decoding"))
    );
    Ok(Tracked {
        table,
        stats,
        image_size,
    })
}

/// Records what tracking produced besides the frames (logged as they are tracked): the
/// tracker's per-frame counts, and the track table (points per frame and trajectories)
/// when `log_table`.
#[cfg(feature = "rerun")]
fn record_tracking(
    rec: &rerun::RecordingStream,
    tracked: &Tracked,
    log_table: bool,
) -> Result<(), rank3::Error> {
    rank3::recording::log_tracking(rec, &tracked.stats)?;
    if log_table {
        rank3::recording::log_input(rec, &tracked.table)?;
    }
    Ok(())
}

/// CPU seconds (user + system, all threads) of this process so far; Linux only.
fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    let fields: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    let ticks = |i: usize| fields.get(i)?.parse::<f64>().ok();
    // utime and stime (fields 14 and 15 of proc(5)), in clock ticks of 1/100 s.
    Some((ticks(11)? + ticks(12)?) / 100.0)
}

/// The recording a command writes to (none without the `rerun` feature).
#[cfg(feature = "rerun")]
type Recording = Option<rerun::RecordingStream>;
#[cfg(not(feature = "rerun"))]
type Recording = ();

/// Opens the requested recording, tracks `input` and records the tracking (the table too
/// when `log_table`).
fn track_recorded(
    input: &Path,
    opts: &TrackOpts,
    #[cfg(feature = "rerun")] record: &rank3::recording::RecordingArgs,
    #[cfg_attr(not(feature = "rerun"), allow(unused_variables))] log_table: bool,
    #[cfg_attr(not(feature = "rerun"), allow(unused_variables))] perspective: bool,
) -> Result<(Tracked, Recording), rank3::Error> {
    // The input must open (folder with images, decodable video) before the recording is
    // opened: opening it replaces an existing .rrd, which a run that fails at once on bad
    // input must not destroy.
    drop(rank3::tracking::FrameSource::open(input)?);
    if let Some(p) = &opts.init_points {
        rank3::tracking::read_init_points(p)?;
    }
    // `rank3 track` logs the table itself; `rank3 run` reconstructs from it.
    #[cfg(feature = "rerun")]
    let recording = record.open(
        "rank3",
        rank3::recording::LayoutParts {
            tracking: true,
            reconstruction: !log_table,
            truth: false,
            perspective: !log_table && perspective,
            objects: false,
        },
    )?;
    #[cfg(not(feature = "rerun"))]
    let recording = ();
    // Frames are recorded (JPEG) as they are tracked; the first logging failure is kept.
    #[cfg(feature = "rerun")]
    let mut log_error: Option<rank3::recording::RecordingError> = None;
    #[cfg_attr(not(feature = "rerun"), allow(unused_variables))]
    let tracked = track_input(input, opts, &mut |index, image| {
        #[cfg(feature = "rerun")]
        if let Some(rec) = &recording
            && log_error.is_none()
            && let Err(e) = rank3::recording::log_frame(rec, index, image, 85)
        {
            log_error = Some(e);
        }
    })?;
    #[cfg(feature = "rerun")]
    if let Some(e) = log_error {
        return Err(e.into());
    }
    #[cfg(feature = "rerun")]
    if let Some(rec) = &recording {
        record_tracking(rec, &tracked, log_table)?;
    }
    if tracked.table.n_tracks() == 0 || tracked.table.n_observed() == 0 {
        return Err(rank3::Error::EmptyTable {
            path: Some(input.to_path_buf()),
            reason: format!(
                "no point could be tracked in its {} frame(s): no corner passed the detector \
                 (blank or textureless frames?) — try a lower --quality (now {}) or \
                 --min-distance (now {} px), or give --init-points",
                tracked.table.n_frames(),
                opts.quality,
                opts.min_distance
            ),
        });
    }
    Ok((tracked, recording))
}

fn track_cmd(a: &TrackArgs) -> Result<(), rank3::Error> {
    let mut inputs: Vec<&Path> = vec![&a.input];
    inputs.extend(a.opts.init_points.as_deref());
    refuse_overwriting_inputs(
        &inputs,
        None,
        Some(&a.out),
        #[cfg(feature = "rerun")]
        &a.record,
    )?;
    // Fail on a bad output extension before the (long) tracking.
    rank3::table::Format::from_path(&a.out)?;
    let (tracked, _recording) = track_recorded(
        &a.input,
        &a.opts,
        #[cfg(feature = "rerun")]
        &a.record,
        true,
        false,
    )?;
    let table = tracked.table;
    table.write(&a.out)?;
    say(format_args!(
        "wrote {} ({} frames × {} tracks, {} observations, {:.1} % filled)",
        a.out.display(),
        table.n_frames(),
        table.n_tracks(),
        table.n_observed(),
        100.0 * table.fill()
    ));
    Ok(())
}

/// Ticks a spinner on every pipeline event.
struct SpinnerObserver(indicatif::ProgressBar);

impl rank3::Observer for SpinnerObserver {
    fn on_event(&mut self, event: &rank3::Event<'_>) {
        match event {
            rank3::Event::StageStarted { stage } => self.0.set_message(stage.to_string()),
            rank3::Event::Iteration {
                solver,
                iteration,
                rms,
                ..
            } => self
                .0
                .set_message(format!("{solver} iteration {iteration}, RMS {rms:.4} px")),
            _ => {}
        }
        self.0.tick();
    }
}

fn run_cmd(a: &RunArgs) -> Result<(), rank3::Error> {
    let mut inputs: Vec<&Path> = vec![&a.input];
    inputs.extend(a.opts.init_points.as_deref());
    refuse_overwriting_inputs(
        &inputs,
        Some(&a.out),
        None,
        #[cfg(feature = "rerun")]
        &a.record,
    )?;
    std::fs::create_dir_all(&a.out).map_err(|e| rank3::Error::io(&a.out, e))?;
    // The table goes in with the reconstruction (reconstruct_recorded logs it).
    #[cfg_attr(not(feature = "rerun"), allow(unused_variables))]
    let (tracked, recording) = track_recorded(
        &a.input,
        &a.opts,
        #[cfg(feature = "rerun")]
        &a.record,
        false,
        matches!(a.camera, CameraArg::Perspective),
    )?;
    let mut table = tracked.table;
    let tracked_size = tracked.image_size;
    let tracks = a.out.join("tracks.csv");
    table.write(&tracks)?;
    eprintln!(
        "wrote {} ({} frames × {} tracks, {:.1} % filled)",
        tracks.display(),
        table.n_frames(),
        table.n_tracks(),
        100.0 * table.fill()
    );
    if a.complete_tracks {
        let full: Vec<usize> = (0..table.n_tracks())
            .filter(|&p| table.track_len(p) == table.n_frames())
            .collect();
        let frames: Vec<usize> = (0..table.n_frames()).collect();
        eprintln!(
            "--complete-tracks: reconstructing from the {} tracks seen in all {} frames",
            full.len(),
            table.n_frames()
        );
        table = table.select(&frames, &full);
    }
    let config = a.recon.config(a.camera, tracked_size);
    if let Some(objects) = a.recon.objects {
        #[cfg(feature = "rerun")]
        if let Some(r) = recording.as_ref() {
            rank3::recording::send_layout(
                r,
                rank3::recording::LayoutParts {
                    tracking: true,
                    objects: true,
                    ..Default::default()
                },
            )?;
        }
        return reconstruct_objects_cli(
            #[cfg(feature = "rerun")]
            recording.as_ref(),
            &table,
            &config,
            objects,
            &a.out,
        );
    }
    let spinner = indicatif::ProgressBar::new_spinner()
        .with_style(bar_style("reconstructing {spinner} {elapsed} {msg}"));
    let mut obs = SpinnerObserver(spinner.clone());
    #[cfg(feature = "rerun")]
    let rec =
        rank3::recording::reconstruct_recorded_with(recording.as_ref(), &table, &config, &mut obs)
            .map_err(rank3::Error::from);
    #[cfg(not(feature = "rerun"))]
    let rec = Reconstruction::from_tracks_observed(&table, &config, &mut obs);
    spinner.finish_and_clear();
    let rec = rec?;
    #[cfg(feature = "rerun")]
    show_perspective_layout(
        recording.as_ref(),
        &rec,
        a.camera,
        rank3::recording::LayoutParts {
            tracking: true,
            reconstruction: true,
            ..Default::default()
        },
    )?;
    write_outputs(
        rec,
        &table,
        Some((&a.input, a.recon.image_size.or(tracked_size))),
        &a.recon,
        &a.out,
        #[cfg(feature = "rerun")]
        recording.as_ref(),
    )
}
