//! `rank3 reconstruct`, the reconstruction options it shares with `rank3 run`, and the
//! several-objects path of both.

use std::path::{Path, PathBuf};

use rank3::Config;
#[cfg(not(feature = "rerun"))]
use rank3::Reconstruction;
use rank3::table::read_tracks;

use super::args::{CameraArg, InitArg, LossArg, SolverArg, parse_objects, parse_pair};
use super::output::{refuse_overwriting_inputs, write_outputs};
use super::summary;
use super::verbosity::{self, detail, info, warning};

#[derive(clap::Args)]
pub struct ReconstructArgs {
    /// Track table: .csv (frame,track,x,y), .txt (dense 2F×N, nan = missing), .json,
    /// .npy (float array (F, N, 2) or (2F, N), NaN = missing), .npz (`tracks`, or `x` and
    /// `y`; optional `frame_ids`, `track_ids`), or a folder holding a COLMAP text model
    /// (images.txt: one track per 3D point, one frame per image). See docs/formats.md.
    #[arg(required_unless_present = "x", value_name = "TRACKS")]
    pub tracks: Option<PathBuf>,
    /// Instead of TRACKS: the x coordinates as a frames × tracks matrix (one row per frame,
    /// nan = missing; text, or a 2-D .npy), e.g. the CMU hotel tracked_points_Xs.txt. Needs
    /// --y.
    #[arg(
        long = "x",
        value_name = "FILE",
        requires = "y",
        conflicts_with = "tracks"
    )]
    pub x: Option<PathBuf>,
    /// The y coordinates matching --x (same shape and format).
    #[arg(
        long = "y",
        value_name = "FILE",
        requires = "x",
        conflicts_with = "tracks"
    )]
    pub y: Option<PathBuf>,
    /// Output directory (reconstruction.json, completed.txt, points.ply).
    #[arg(long)]
    pub out: PathBuf,
    /// Camera model (the projective and perspective reconstructions also hold the affine
    /// model they start from).
    #[arg(long, value_enum, default_value = "auto")]
    pub camera: CameraArg,
    /// The frames the tracks come from (folder of PNG/JPEG or video, matched to the table's
    /// frames by id, else by position): with them a textured mesh (mesh.obj + mesh.mtl +
    /// mesh_texture.png, mesh.glb) is built and points.ply gets colours. Not with --objects.
    #[arg(long, value_name = "DIR|VIDEO", conflicts_with = "objects")]
    pub images: Option<PathBuf>,
    /// Complete tracks of a CSV table larger than memory: the streaming factorization
    /// (docs/math.md §13) reads the file in passes and never holds W whole. Affine cameras
    /// (orthographic or scaled orthographic; auto means the latter), a per-track test
    /// instead of RANSAC, no refinement; tracks not seen in every frame are set aside.
    #[arg(long, conflicts_with_all = ["x", "images", "objects", "threshold"])]
    pub stream: bool,
    /// With --stream: memory for the block of W held at once, bytes (suffix K, M or G,
    /// e.g. 512M). Each pass over the file fills one block. Default 1G.
    #[arg(long, value_name = "BYTES", requires = "stream", value_parser = super::args::parse_bytes)]
    pub memory: Option<usize>,
    #[command(flatten)]
    pub opts: ReconstructOpts,
    #[cfg(feature = "rerun")]
    #[command(flatten)]
    pub record: rank3::recording::RecordingArgs,
}

/// Options of the reconstruction shared by `reconstruct` and `run`.
#[derive(clap::Args)]
pub struct ReconstructOpts {
    /// Skip the Levenberg–Marquardt metric refinement.
    #[arg(long)]
    pub no_refine: bool,
    /// Always solve the metric upgrade as a PSD-constrained SDP.
    #[arg(long)]
    pub force_sdp: bool,
    /// Skip the robust pass (RANSAC over tracks, gross-entry flags).
    #[arg(long)]
    pub no_robust: bool,
    /// Inlier threshold of the robust pass, pixels (default: estimated from the data; not
    /// with --no-robust).
    #[arg(long, value_name = "PX", conflicts_with = "no_robust")]
    pub threshold: Option<f64>,
    /// Missing-data solver: `wiberg` (damped Wiberg / variable projection, reliable) or
    /// `als` (alternating least squares, simple, can stall).
    #[arg(long, value_enum, default_value = "wiberg")]
    pub solver: SolverArg,
    /// Start of the missing-data solver: `auto` (data-driven) or `random` (seeded).
    #[arg(long, value_enum, default_value = "auto")]
    pub init: InitArg,
    /// Random starts of the missing-data solver (the best is kept).
    #[arg(long, default_value_t = 1)]
    pub runs: usize,
    /// Seed of every random choice (robust sampling, random starts, randomized SVD).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Aspect ratio of the pixels, fx/fy (1 = square; 0.8 for a 4:3 picture digitised at
    /// 512×480, 1.1 for NTSC DV at 720×480): every camera model then works in square pixels.
    /// Default: what the frames' files state (PNG pHYs, JPEG JFIF, the video's sample
    /// aspect ratio), else what the frame size implies for digitised analogue video
    /// (512×480, 720×480, 720×576 …; docs/math.md §9), else 1.
    #[arg(long, value_name = "R")]
    pub aspect_ratio: Option<f64>,
    /// Perspective camera: the known focal length, pixels (default: self-calibrated).
    #[arg(long, value_name = "PX")]
    pub focal: Option<f64>,
    /// Perspective camera: the known principal point, pixels (default: the image centre,
    /// or estimated when the image size is not known either).
    #[arg(long, value_name = "X,Y", value_parser = parse_pair::<f64>)]
    pub principal_point: Option<[f64; 2]>,
    /// Perspective camera: the image size, pixels (`rank3 run` knows it from the frames).
    #[arg(long, value_name = "W,H", value_parser = parse_pair::<u32>)]
    pub image_size: Option<[u32; 2]>,
    /// Perspective camera: one focal length per frame (a zooming camera).
    #[arg(long)]
    pub per_frame_focal: bool,
    /// Perspective camera: estimate the principal point in the bundle adjustment.
    #[arg(long)]
    pub estimate_principal_point: bool,
    /// Perspective camera: estimate one radial distortion coefficient k1.
    #[arg(long)]
    pub distortion: bool,
    /// Perspective camera: estimate the aspect ratio fx/fy (non-square pixels) in the
    /// bundle adjustment.
    #[arg(long)]
    pub estimate_aspect_ratio: bool,
    /// Robust loss of the perspective bundle adjustment.
    #[arg(long, value_enum, default_value = "huber")]
    pub loss: LossArg,
    /// Scale of the robust loss, pixels (not with --loss none).
    #[arg(long, value_name = "PX", default_value_t = 2.0)]
    pub loss_scale: f64,
    /// Independently moving objects: segment the tracks into rigid groups, `auto` (the
    /// number found from the data) or a given count K, and reconstruct each group on its
    /// own: OUT/objects.csv (track,object; -1 = outlier), OUT/segmentation.json and
    /// OUT/object_<k>/ per object (docs/formats.md).
    #[arg(long, value_name = "auto|K", value_parser = parse_objects)]
    pub objects: Option<rank3::segment::Objects>,
    /// With --objects: give every track the group that explains it best instead of
    /// labelling the tracks no group explains as outliers (-1), as benchmarks whose every
    /// track belongs to a motion expect (Hopkins 155). Tracks seen in too few frames to be
    /// scored stay -1.
    #[arg(long, requires = "objects")]
    pub assign_all: bool,
    /// Do not build the textured mesh (built by default when the frames are known: `run`,
    /// `reconstruct --images`; not with --objects).
    #[arg(long, conflicts_with = "objects")]
    pub no_mesh: bool,
    /// Leave the outlier tracks' points out of points.ply (not with --objects).
    #[arg(long, conflicts_with = "objects")]
    pub ply_inliers_only: bool,
}

impl ReconstructOpts {
    /// The library configuration; `image_size` is what the tracker saw (`run`), used
    /// unless `--image-size` is given; `stated` is the pixels' aspect ratio the frames'
    /// files state ([`rank3::tracking::FrameSource::pixel_aspect`]). Without
    /// `--aspect-ratio`, the ratio is the stated one, else the one the frame size implies
    /// ([`rank3::pixel_aspect::from_frame_size`]), else 1.
    pub fn config(
        &self,
        camera: CameraArg,
        image_size: Option<[u32; 2]>,
        stated: Option<rank3::pixel_aspect::PixelAspect>,
    ) -> Config {
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
        config.aspect_ratio = a.aspect_ratio;
        if a.aspect_ratio.is_none()
            && let Some(pa) = rank3::pixel_aspect::of_frames(stated, a.image_size.or(image_size))
        {
            info!(
                "pixel aspect ratio fx/fy = {}: {} (--aspect-ratio 1 for square pixels)",
                pa.ratio, pa.source
            );
            config.aspect_ratio = Some(pa.ratio);
            config.aspect_ratio_source = Some(pa.source);
        }
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
        p.estimate_aspect_ratio = a.estimate_aspect_ratio;
        p.loss = match a.loss {
            LossArg::None => rank3::perspective::Loss::Squared,
            LossArg::Huber => rank3::perspective::Loss::Huber(a.loss_scale),
            LossArg::Cauchy => rank3::perspective::Loss::Cauchy(a.loss_scale),
        };
        config
    }

    /// With `-v`: the settings in force, one line.
    pub fn print_settings(&self, camera: CameraArg, config: &Config) {
        detail!(
            "settings: camera {}, robust pass {}, missing-data solver {} ({} start, {} \
             run(s)), metric upgrade {}, refinement {}, seed {}{}",
            camera.name(),
            match (&config.robust, self.threshold) {
                (None, _) => "off".to_string(),
                (Some(_), Some(px)) => format!("on (threshold {px} px)"),
                (Some(_), None) => "on (threshold from the data)".to_string(),
            },
            rank3::output::spelled(&config.completion.solver),
            rank3::output::spelled(&config.completion.init),
            config.completion.runs,
            if self.force_sdp {
                "by SDP"
            } else {
                "least squares, SDP if needed"
            },
            if config.refine.is_some() { "on" } else { "off" },
            self.seed,
            if config.camera.is_perspective() {
                let i = &config.perspective.intrinsics;
                format!(
                    "; perspective: focal {}, principal point {}, image size {}{}{}{}{}, loss {:?}",
                    i.focal_px
                        .map_or("self-calibrated".to_string(), |f| format!("{f} px")),
                    i.principal_point
                        .map_or("default".to_string(), |[x, y]| format!("({x}, {y})")),
                    i.image_size
                        .map_or("unknown".to_string(), |[w, h]| format!("{w}×{h}")),
                    if self.per_frame_focal {
                        ", focal per frame"
                    } else {
                        ""
                    },
                    if self.estimate_principal_point {
                        ", principal point estimated"
                    } else {
                        ""
                    },
                    if self.distortion {
                        ", k1 estimated"
                    } else {
                        ""
                    },
                    if self.estimate_aspect_ratio {
                        ", aspect ratio estimated"
                    } else {
                        ""
                    },
                    config.perspective.loss
                )
            } else {
                String::new()
            }
        );
    }
}

pub fn reconstruct(a: &ReconstructArgs) -> Result<(), rank3::Error> {
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
    if a.stream {
        return reconstruct_streamed(a);
    }
    // The table is read before the recording opens (opening it replaces an existing .rrd,
    // which bad input must not destroy).
    let read_start = std::time::Instant::now();
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
        warning!("{w}");
    }
    let t = &loaded.table;
    let read_seconds = read_start.elapsed().as_secs_f64();
    info!(
        "read {}: {} frames × {} tracks, {} observations ({:.1} % filled){}",
        match (&a.tracks, &a.y) {
            (None, Some(y)) => format!("{} and {}", loaded.path.display(), y.display()),
            _ => loaded.path.display().to_string(),
        },
        t.n_frames(),
        t.n_tracks(),
        t.n_observed(),
        100.0 * t.fill(),
        if verbosity::verbose() {
            format!(" in {read_seconds:.2} s")
        } else {
            String::new()
        }
    );
    let stated = match &a.images {
        Some(images) => rank3::tracking::FrameSource::pixel_aspect_of(images)?,
        None => None,
    };
    let config = a.opts.config(a.camera, None, stated);
    a.opts.print_settings(a.camera, &config);
    if let Some(objects) = a.opts.objects {
        return reconstruct_objects(
            #[cfg(feature = "rerun")]
            recording.as_ref(),
            t,
            &config,
            objects,
            a.opts.assign_all,
            &a.out,
        );
    }
    let fit_start = std::time::Instant::now();
    #[cfg(feature = "rerun")]
    let rec = rank3::recording::reconstruct_recorded(recording.as_ref(), t, &config)?;
    #[cfg(feature = "rerun")]
    super::output::show_perspective_layout(
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
    detail!(
        "reconstruction: {:.2} s wall",
        fit_start.elapsed().as_secs_f64()
    );
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

/// `--stream`: the streaming factorization of the complete tracks of a CSV file
/// ([`rank3::stream`]), then the usual files and summary.
fn reconstruct_streamed(a: &ReconstructArgs) -> Result<(), rank3::Error> {
    let Some(path) = a.tracks.as_deref() else {
        return Err(rank3::Error::InvalidConfig {
            field: "--stream",
            message: "give a CSV track table (not --x/--y)".into(),
        });
    };
    if rank3::table::Format::from_path(path)? != rank3::table::Format::Csv {
        return Err(rank3::Error::InvalidConfig {
            field: "--stream",
            message: format!(
                "{}: the streaming factorization reads the long CSV format (frame,track,x,y)",
                path.display()
            ),
        });
    }
    if a.opts.aspect_ratio.is_some_and(|r| r != 1.0) {
        return Err(rank3::Error::InvalidConfig {
            field: "--aspect-ratio",
            message: "the streaming factorization works in square pixels: divide x by the \
                      ratio in the file, or drop --stream"
                .into(),
        });
    }
    let cfg = rank3::stream::StreamConfig {
        memory_budget_bytes: a.memory.unwrap_or(1 << 30),
        camera: a.camera.into(),
        metric: rank3::metric::MetricConfig {
            force_sdp: a.opts.force_sdp,
            ..Default::default()
        },
        robust: !a.opts.no_robust,
        ..Default::default()
    };
    #[cfg(feature = "rerun")]
    let recording = a.record.open(
        "rank3",
        rank3::recording::LayoutParts {
            reconstruction: true,
            ..Default::default()
        },
    )?;
    let mut source = rank3::stream::CsvFile {
        path: path.to_path_buf(),
    };
    let start = std::time::Instant::now();
    #[cfg(feature = "rerun")]
    let result = match recording.as_ref() {
        Some(r) => {
            let mut observer = rank3::recording::RecordingObserver::new(r);
            let result = rank3::stream::factorize(&mut source, &cfg, &mut observer);
            observer.flush();
            if let Err(e) = &result {
                rank3::recording::log_error(r, e)?;
            }
            result?
        }
        None => rank3::stream::factorize(&mut source, &cfg, &mut rank3::NoopObserver)?,
    };
    #[cfg(not(feature = "rerun"))]
    let result = rank3::stream::factorize(&mut source, &cfg, &mut rank3::NoopObserver)?;
    for w in &result.warnings {
        warning!("{w}");
    }
    let report = &result.report;
    info!(
        "streamed {}: {} frames × {} tracks, {} observations; {} pass(es) over the file, \
         {} block(s) of {} tracks, {:.2} s",
        path.display(),
        result.frame_ids.len(),
        result.track_ids.len(),
        result.observations,
        report.passes,
        report.blocks,
        report.block_tracks,
        start.elapsed().as_secs_f64()
    );
    let rec = result.into_reconstruction();
    #[cfg(feature = "rerun")]
    if let Some(r) = recording.as_ref() {
        rank3::recording::log_streamed(r, &rec)?;
    }
    rank3::output::remove_stale(&a.out, &rank3::output::RECONSTRUCTION_FILES)?;
    let write_start = std::time::Instant::now();
    rank3::output::write_all_with(
        &rec,
        &a.out,
        rank3::output::PlyOptions {
            colors: None,
            inliers_only: a.opts.ply_inliers_only,
        },
    )?;
    summary::print_summary(&rec, &a.out);
    detail!(
        "wrote {} in {:.2} s",
        a.out.display(),
        write_start.elapsed().as_secs_f64()
    );
    Ok(())
}

/// `--objects`: segmentation, one reconstruction per object, their files and recording.
pub fn reconstruct_objects(
    #[cfg(feature = "rerun")] recording: Option<&rerun::RecordingStream>,
    table: &rank3::TrackTable,
    config: &Config,
    objects: rank3::segment::Objects,
    assign_all: bool,
    out: &Path,
) -> Result<(), rank3::Error> {
    let seg = rank3::segment::SegmentConfig {
        objects,
        label_outliers: !assign_all,
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
    info!(
        "segmentation: {} object(s) ({}), {} outlier and {} unscored tracks{}, σ {:.3} px, {} rounds, {:.2} s",
        mb.objects.len(),
        if given { "given" } else { "found" },
        s.n_outliers(),
        s.n_unscored(),
        if mb.unscored_in_the_only_object().is_empty() {
            ""
        } else {
            " (reconstructed with the only object)"
        },
        s.sigma,
        s.rounds,
        s.seconds
    );
    for o in &mb.objects {
        match &o.reconstruction {
            Ok(r) => {
                info!(
                    "object {}: {} tracks, camera {}, RMS {:.3} px -> {}",
                    o.index,
                    o.tracks.len(),
                    rank3::output::spelled(&r.camera_model),
                    r.rms_px,
                    out.join(rank3::objects::object_dir(o.index)).display()
                );
                if verbosity::verbose() {
                    summary::print_report(r);
                    summary::print_timings(r);
                }
            }
            Err(e) => info!(
                "object {}: {} tracks, not reconstructed: {e}",
                o.index,
                o.tracks.len()
            ),
        }
    }
    let [csv, json] = rank3::output::OBJECTS_FILES.map(|name| out.join(name));
    info!("wrote {} and {}", csv.display(), json.display());
    Ok(())
}
