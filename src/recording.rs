//! Rerun recordings of every pipeline stage (cargo feature `rerun`, on by default).
//!
//! Open a saved `.rrd` in the Rerun viewer **0.36.3** (the viewer must match the SDK
//! version: `cargo install rerun-cli --version 0.36.3 --locked` or
//! `pip install rerun-sdk==0.36.3`, then `rerun file.rrd`) and step through the `stage`
//! timeline to see why the result is what it is; the `frame` timeline plays per-frame data,
//! the `iteration` timeline plots solver progress.
//!
//! The solvers know nothing about Rerun: they report to an [`crate::Observer`], and
//! [`RecordingObserver`] turns those events into log calls. [`log_input`],
//! [`log_reconstruction`], [`log_robust`] and [`log_synth_truth`] log the data of a run;
//! [`send_layout`] sends the viewer layout the CLI's recordings carry.
//!
//! # Timelines
//!
//! * `stage` (sequence): [`STAGES`] gives the index of each stage — 0 input, 1 set-aside,
//!   2 robust, 3 factorize, 4 metric-upgrade, 5 refine, 6 projective, 7 perspective, 8 result,
//!   9 mesh.
//!   Stages the table does not
//!   know get indices after it, in order of appearance.
//! * `frame` (sequence): the frame's index in the *input* table (not its id).
//! * `iteration` (sequence): solver iteration.
//!
//! # Entity paths ([`paths`])
//!
//! | path | archetype | what |
//! |---|---|---|
//! | `image/tracks` | Points2D per frame | observed positions, class id = track index |
//! | `image/frame` | EncodedImage (JPEG) per frame | the frames `rank3 track` / `run` tracked on |
//! | `tracking/{tracked,new,alive}`, `tracking/lost/<reason>` | Scalars per frame | tracker counts |
//! | `image/trajectories` | LineStrips2D | one strip per input track; from stage `robust` on coloured green (inlier) / red (outlier) |
//! | `image/set_aside/{points,trajectories}` | Points2D / LineStrips2D | set-aside tracks, red |
//! | `image/residuals` | Arrows2D per frame | observed → predicted (metric model) |
//! | `image/projective/residuals` | Arrows2D per frame | observed → `π(P_f X_p)` (projective camera) |
//! | `projective/stages` | TextDocument | each projective stage's RMS before/after, status, iterations |
//! | `projective/frame_rms` | Scalars per frame | per-frame RMS of the projective model |
//! | `image/perspective/residuals` | Arrows2D per frame | observed → `π(K(RX + t))` (perspective camera) |
//! | `perspective/world/points`, `perspective/world/outliers` | Points3D | Euclidean structure (coloured by per-point RMS), outlier tracks' points (red) |
//! | `perspective/world/camera` | Transform3D + Pinhole per frame | the camera's pose and frustum with the estimated intrinsics |
//! | `perspective/world/frustums/<k>` | Transform3D + Pinhole (static) | up to 24 evenly spaced cameras' frustums |
//! | `perspective/world/trajectory` | LineStrips3D | camera centres in frame order |
//! | `perspective/report` | TextDocument | intrinsics, self-calibration, starts, adjustment stages |
//! | `image/robust/{outliers,flagged}` | LineStrips2D / Points2D | robust pass: outlier tracks (labelled), flagged entries |
//! | `factorization/visibility` | Image (L8) | F×N mask, white = observed |
//! | `factorization/W` | Tensor (f32) | the kept 2F'×N' measurement matrix |
//! | `factorization/singular_values` | BarChart | every computed σ |
//! | `factorization/sigma4_over_sigma3` | Scalars | rank diagnostic |
//! | `affine/points` | Points3D | affine structure Ŝ (before the upgrade) |
//! | `metric/eigenvalues_ls`, `metric/eigenvalues` | BarChart | eigenvalues of L |
//! | `metric/method` | TextDocument | which path solved L and why |
//! | `world/points` | Points3D | metric structure, coloured by per-point RMS |
//! | `world/outliers` | Points3D | outlier tracks' points (fitted cameras, not refined), red |
//! | `world/camera` | Transform3D per frame | camera pose (axes = rows of R) |
//! | `world/camera/axes` | Arrows3D (static) | i (red), j (green), viewing direction k (blue) |
//! | `world/cameras/view_directions` | Arrows3D | every frame's viewing direction |
//! | `world/cameras/trajectory` | LineStrips3D | camera centres in frame order |
//! | `residuals/point_rms` | BarChart | per-point RMS of the kept tracks, pixels |
//! | `residuals/frame_rms` | Scalars per frame | per-frame RMS, pixels |
//! | `solver/<name>/run<k>/{cost,rms,lambda}` | Scalars per iteration | solver progress |
//! | `log/stages`, `log/warnings`, `log/set_aside`, `log/errors` | TextLog | events |
//! | `summary` | TextDocument (markdown) | inputs, choices, timings, warnings |
//!
//! # Size limits
//!
//! Images and tensors are subsampled (every k-th row/column) so that neither side exceeds
//! [`RecordingOptions::max_image_side`]; residual arrows are capped per frame by
//! [`RecordingOptions::max_residual_arrows_per_frame`] (evenly spaced tracks). Both are
//! generous by default; see the crate README for measured file sizes and overhead.
//!
//! Per-frame data go out as one chunk per entity (`send_columns`; residual arrows in chunks
//! of about [`RecordingOptions::residual_arrows_per_chunk`]) with the Arrow arrays built
//! directly from flat buffers, so the SDK neither serializes 10⁵ points one by one nor
//! re-batches a hundred rows.
//!
//! # Cost
//!
//! [`reconstruct_recorded`] logs the input, the visibility mask and W on a second thread
//! while the pipeline runs (W once the pipeline announces its fit with
//! [`Event::FitSelection`]), and the result afterwards, largest entity first, so that the
//! SDK's writer thread encodes it while the rest is built. On a 100-frame × 2000-track run
//! (8.4 MB file) this costs about 5 % of the pipeline's time (4.3–6.8 %); see the crate's
//! `docs/results.md` and `examples/recording_overhead.rs`.
//!
//! Cost: O(F·N) for the per-frame data (points, arrows, mask, W), O(N + F) for the rest.

use std::path::PathBuf;
use std::sync::Arc;

use rerun::external::arrow::array::{
    ArrayRef, FixedSizeListArray, Float32Array, ListArray, UInt16Array,
};
use rerun::external::arrow::buffer::OffsetBuffer;
use rerun::external::arrow::datatypes::{DataType, Field};
use rerun::external::arrow::error::ArrowError;
use rerun::external::re_uri;
use rerun::sink::LogSink;
use rerun::{
    AnnotationContext, Arrows2D, Arrows3D, BarChart, ClassDescription, Image, LineStrip3D,
    LineStrips2D, LineStrips3D, Points2D, Points3D, Radius, RecordingStream,
    RecordingStreamBuilder, RecordingStreamError, Scalars, SerializedComponentBatch,
    SerializedComponentColumn, Tensor, TensorBuffer, TensorData, TextDocument, TextLog,
    TextLogLevel, TimeColumn, Transform3D,
};

use crate::metric::UpgradeMethod;
use crate::synth::SynthScene;
use crate::table::SetAsideKind;
use crate::{Config, Error, Event, MetricModel, Observer, Reconstruction, TrackTable};

/// Stage names in `stage`-timeline order (their index is the timeline value).
pub const STAGES: [&str; 10] = [
    "input",
    "set-aside",
    "robust",
    "factorize",
    "metric-upgrade",
    "refine",
    "projective",
    "perspective",
    "result",
    "mesh",
];

/// Timeline names.
pub const TIMELINE_STAGE: &str = "stage";
/// Per-frame data; the value is the frame's index in the input table.
pub const TIMELINE_FRAME: &str = "frame";
/// Solver iterations.
pub const TIMELINE_ITERATION: &str = "iteration";

/// Entity paths used by this module.
pub mod paths {
    pub const TRACKS: &str = "image/tracks";
    /// The video frames a tracker saw (JPEG-encoded), under the tracks.
    pub const FRAME_IMAGE: &str = "image/frame";
    /// Per-frame tracker counts: `tracking/{tracked,new,alive}` and `tracking/lost/<reason>`.
    pub const TRACKING: &str = "tracking";
    pub const TRAJECTORIES: &str = "image/trajectories";
    pub const SET_ASIDE_POINTS: &str = "image/set_aside/points";
    pub const SET_ASIDE_TRAJECTORIES: &str = "image/set_aside/trajectories";
    pub const RESIDUAL_ARROWS: &str = "image/residuals";
    /// Observed → projective prediction `π(P_f X_p)` (camera `projective`).
    pub const PROJECTIVE_RESIDUALS: &str = "image/projective/residuals";
    /// The projective stages' RMS before/after, per stage (markdown table).
    pub const PROJECTIVE_STAGES: &str = "projective/stages";
    /// Per-frame RMS of the projective model, pixels.
    pub const PROJECTIVE_FRAME_RMS: &str = "projective/frame_rms";
    /// Observed → perspective prediction (camera `perspective`).
    pub const PERSPECTIVE_RESIDUALS: &str = "image/perspective/residuals";
    /// The Euclidean (perspective) structure, its outliers, cameras and trajectory.
    pub const PERSPECTIVE_POINTS: &str = "perspective/world/points";
    pub const PERSPECTIVE_OUTLIERS: &str = "perspective/world/outliers";
    pub const PERSPECTIVE_CAMERA: &str = "perspective/world/camera";
    pub const PERSPECTIVE_FRUSTUMS: &str = "perspective/world/frustums";
    pub const PERSPECTIVE_TRAJECTORY: &str = "perspective/world/trajectory";
    /// The textured surface ([`crate::mesh`]) beside the points it was built on.
    pub const MESH: &str = "world/mesh";
    pub const PERSPECTIVE_MESH: &str = "perspective/world/mesh";
    /// The mesh stages' report (markdown).
    pub const MESH_REPORT: &str = "mesh/report";
    /// Intrinsics, self-calibration, starts and stages (markdown).
    pub const PERSPECTIVE_REPORT: &str = "perspective/report";
    pub const ROBUST_OUTLIERS: &str = "image/robust/outliers";
    pub const ROBUST_FLAGGED: &str = "image/robust/flagged";
    pub const ROBUST_INLIER_COUNT: &str = "solver/ransac/inliers";
    pub const VISIBILITY: &str = "factorization/visibility";
    pub const W: &str = "factorization/W";
    pub const SINGULAR_VALUES: &str = "factorization/singular_values";
    pub const RANK_RATIO: &str = "factorization/sigma4_over_sigma3";
    pub const AFFINE_POINTS: &str = "affine/points";
    pub const EIGENVALUES_LS: &str = "metric/eigenvalues_ls";
    pub const EIGENVALUES: &str = "metric/eigenvalues";
    pub const METRIC_METHOD: &str = "metric/method";
    pub const POINTS: &str = "world/points";
    /// Outlier tracks' points, triangulated with the fitted cameras (red).
    pub const OUTLIER_POINTS: &str = "world/outliers";
    pub const CAMERA: &str = "world/camera";
    pub const CAMERA_AXES: &str = "world/camera/axes";
    pub const VIEW_DIRECTIONS: &str = "world/cameras/view_directions";
    pub const CAMERA_TRAJECTORY: &str = "world/cameras/trajectory";
    pub const POINT_RMS: &str = "residuals/point_rms";
    pub const FRAME_RMS: &str = "residuals/frame_rms";
    pub const LOG_STAGES: &str = "log/stages";
    pub const LOG_WARNINGS: &str = "log/warnings";
    pub const LOG_SET_ASIDE: &str = "log/set_aside";
    pub const LOG_ERRORS: &str = "log/errors";
    pub const SUMMARY: &str = "summary";
    pub const TRUTH_POINTS: &str = "truth/points";
    /// Ground-truth cameras; same layout as `world/camera…` under `truth/`.
    pub const TRUTH_ROOT: &str = "truth";
}

/// What went wrong while recording.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RecordingError {
    /// The Rerun SDK refused (file not creatable, viewer not spawnable, bad URL, …).
    #[error("rerun recording: {0}")]
    Stream(#[from] RecordingStreamError),
    /// The data handed to a log function do not fit together.
    #[error(transparent)]
    Input(#[from] Error),
    /// Building an Arrow array for a bulk log call failed (an internal inconsistency).
    #[error("rerun recording: arrow: {0}")]
    Arrow(#[from] ArrowError),
}

impl From<rerun::SerializationError> for RecordingError {
    fn from(e: rerun::SerializationError) -> Self {
        Self::Stream(e.into())
    }
}

/// Result of the log functions.
pub type RecordingResult<T = ()> = std::result::Result<T, RecordingError>;

impl From<RecordingError> for Error {
    /// Input errors unchanged; SDK failures as an [`Error::Io`] on the recording.
    fn from(e: RecordingError) -> Self {
        match e {
            RecordingError::Input(e) => e,
            RecordingError::Stream(e) => {
                Error::io("rerun recording", std::io::Error::other(e.to_string()))
            }
            RecordingError::Arrow(e) => {
                Error::io("rerun recording", std::io::Error::other(e.to_string()))
            }
        }
    }
}

/// Size limits of what gets logged. Defaults keep everything for tables up to 4096 frames
/// or tracks per side.
#[derive(Debug, Clone)]
pub struct RecordingOptions {
    /// Images and tensors larger than this on a side are subsampled. Default 4096.
    pub max_image_side: usize,
    /// At most this many residual arrows per frame (evenly spaced over the kept tracks).
    /// Default 5000.
    pub max_residual_arrows_per_frame: usize,
    /// Tracks get an annotation context (class id → track id label) up to this many
    /// tracks (class ids are 16-bit). Default 65535.
    pub max_annotated_tracks: usize,
    /// Residual arrows go out in chunks of whole frames holding about this many arrows
    /// (at least one frame each), so that the SDK's writer encodes a chunk while the next
    /// is built. Default 65536.
    pub residual_arrows_per_chunk: usize,
}

impl Default for RecordingOptions {
    fn default() -> Self {
        Self {
            max_image_side: 4096,
            max_residual_arrows_per_frame: 5000,
            max_annotated_tracks: 65535,
            residual_arrows_per_chunk: 1 << 16,
        }
    }
}

/// Where a CLI run sends its recording. At least one of the three enables recording.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct RecordingArgs {
    /// Save a Rerun recording of every stage to this .rrd file (open with Rerun viewer 0.36.3).
    #[arg(long, value_name = "FILE")]
    pub rrd: Option<PathBuf>,
    /// Spawn a Rerun viewer (`rerun` 0.36.3 on PATH) and stream the recording to it.
    #[arg(long)]
    pub spawn: bool,
    /// Stream the recording to a running viewer (default rerun+http://127.0.0.1:9876/proxy).
    #[arg(long, value_name = "URL", num_args = 0..=1,
          default_missing_value = rerun::DEFAULT_CONNECT_URL)]
    pub connect: Option<String>,
}

impl RecordingArgs {
    /// Opens the requested sinks (creating the .rrd's directory) and sends the viewer layout
    /// of `layout` ([`send_layout`]); `None` when no sink was requested.
    pub fn open(
        &self,
        application_id: &'static str,
        layout: LayoutParts,
    ) -> RecordingResult<Option<RecordingStream>> {
        let rec = self.open_sinks(application_id)?;
        if let Some(rec) = &rec {
            send_layout(rec, layout)?;
            let what = [
                self.rrd.as_ref().map(|p| p.display().to_string()),
                self.spawn.then(|| "the spawned viewer".to_string()),
                self.connect.clone(),
            ]
            .into_iter()
            .flatten()
            .collect::<Vec<_>>()
            .join(" and ");
            if let Ok(mut opened) = OPENED.lock() {
                opened.push((what, rec.clone()));
            }
        }
        Ok(rec)
    }

    fn open_sinks(&self, application_id: &'static str) -> RecordingResult<Option<RecordingStream>> {
        if let Some(dir) = self.rrd.as_deref().and_then(std::path::Path::parent)
            && !dir.as_os_str().is_empty()
        {
            std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        }
        if let Some(path) = &self.rrd {
            unlink_for_rewrite(path);
        }
        let builder = RecordingStreamBuilder::new(application_id);
        match (&self.rrd, self.spawn, &self.connect) {
            (None, false, None) => return Ok(None),
            (Some(path), false, None) => return Ok(Some(builder.save(path)?)),
            _ => {}
        }
        let mut sinks: Vec<Box<dyn LogSink>> = Vec::new();
        if let Some(path) = &self.rrd {
            sinks.push(Box::new(
                rerun::sink::FileSink::new(path).map_err(RecordingStreamError::from)?,
            ));
        }
        let mut urls = Vec::new();
        if self.spawn {
            let info = rerun::spawn(&rerun::SpawnOptions::default())
                .map_err(RecordingStreamError::from)?;
            urls.push(format!("rerun+http://127.0.0.1:{}/proxy", info.port));
        }
        if let Some(url) = &self.connect {
            urls.push(url.clone());
        }
        for url in urls {
            let re_uri::RedapUri::Proxy(uri) = url
                .parse::<re_uri::RedapUri>()
                .map_err(RecordingStreamError::from)?
            else {
                return Err(RecordingStreamError::NotAProxyEndpoint.into());
            };
            sinks.push(Box::new(rerun::sink::GrpcSink::new(uri)));
        }
        Ok(Some(builder.set_sinks(sinks)?))
    }
}

/// The recordings [`RecordingArgs::open`] opened in this process, for [`finish_opened`].
static OPENED: std::sync::Mutex<Vec<(String, RecordingStream)>> = std::sync::Mutex::new(Vec::new());

/// Flushes every recording [`RecordingArgs::open`] opened (waiting at most `timeout` for
/// each) and closes them; returns one message per recording that could not be written or
/// streamed (a full disk, a viewer that is not listening, no display for `--spawn`). The
/// command line turns these into a non-zero exit: a recording that did not happen is said.
pub fn finish_opened(timeout: std::time::Duration) -> Vec<String> {
    let opened = match OPENED.lock() {
        Ok(mut o) => std::mem::take(&mut *o),
        Err(_) => return Vec::new(),
    };
    let mut failures = Vec::new();
    for (what, rec) in opened {
        if let Err(e) = rec.flush_with_timeout(timeout) {
            failures.push(format!("the recording to {what} was not completed: {e}"));
        }
    }
    failures
}

/// Which parts of the viewer layout [`send_layout`] shows (views of absent data would sit
/// empty).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LayoutParts {
    /// Frames and tracker counts (`rank3 track`, `rank3 run`).
    pub tracking: bool,
    /// A reconstruction: metric and affine structure, W, spectra, solvers, summary.
    pub reconstruction: bool,
    /// Synthetic ground truth (`rank3 synth`).
    pub truth: bool,
    /// A perspective reconstruction: its Euclidean structure and frustums beside the
    /// affine-model structure.
    pub perspective: bool,
    /// Several objects (`--objects`): each object's structure and cameras in one 3D view.
    pub objects: bool,
}

/// Sends a viewer layout (a Rerun blueprint, made active and the default for the
/// application id) that shows each entity group of the module table in its own view: the
/// image plane (tracks, trajectories, residual arrows, robust flags, frames) beside the 3D
/// scene (metric, affine, truth in tabs); below, W and the mask, the bar charts (singular
/// values, L's eigenvalues, per-point RMS), the time series (solver iterations, frame RMS,
/// tracker counts) and the texts (summary, metric upgrade, stage log). The time panel starts
/// on the `stage` timeline. Without a layout the viewer guesses one, and its guess for a
/// reconstruction showed no 2D view of the tracks at all.
pub fn send_layout(rec: &RecordingStream, parts: LayoutParts) -> RecordingResult {
    use rerun::blueprint::{
        BarChartView, Blueprint, BlueprintActivation, ContainerLike, Horizontal, Spatial2DView,
        Spatial3DView, Tabs, TensorView, TextDocumentView, TextLogView, TimePanel, TimeSeriesView,
        Vertical,
    };
    let image = Spatial2DView::new("image: tracks, residuals, robust flags").with_origin("/image");
    let mut scene: Vec<ContainerLike> = Vec::new();
    if parts.reconstruction && parts.perspective {
        scene.push(
            Horizontal::new([
                Spatial3DView::new("perspective: Euclidean structure, camera frustums")
                    .with_origin("/perspective/world")
                    .into(),
                Spatial3DView::new("affine model: structure and cameras")
                    .with_origin("/world")
                    .into(),
            ])
            .into(),
        );
    } else if parts.reconstruction {
        scene.push(
            Spatial3DView::new("metric structure and cameras")
                .with_origin("/world")
                .into(),
        );
    }
    if parts.reconstruction {
        scene.push(
            Spatial3DView::new("affine structure")
                .with_origin("/affine")
                .into(),
        );
    }
    if parts.objects {
        scene.insert(
            0,
            Spatial3DView::new("objects: each rigid group's structure and cameras")
                .with_origin("/objects")
                .into(),
        );
    }
    if parts.truth {
        scene.push(
            Spatial3DView::new("ground truth")
                .with_origin("/truth")
                .into(),
        );
    }
    let mut top: Vec<ContainerLike> = vec![image.into()];
    if !scene.is_empty() {
        top.push(Tabs::new(scene).into());
    }
    let mut bottom: Vec<ContainerLike> = Vec::new();
    if parts.reconstruction {
        bottom.push(
            Tabs::new([
                TensorView::new("W")
                    .with_origin(format!("/{}", paths::W))
                    .into(),
                Spatial2DView::new("visibility mask")
                    .with_origin(format!("/{}", paths::VISIBILITY))
                    .into(),
            ])
            .into(),
        );
        bottom.push(
            Tabs::new(
                [
                    ("singular values", paths::SINGULAR_VALUES),
                    ("eigenvalues of L", paths::EIGENVALUES),
                    ("eigenvalues of least-squares L", paths::EIGENVALUES_LS),
                    ("per-point RMS (px)", paths::POINT_RMS),
                ]
                .map(|(name, path)| {
                    BarChartView::new(name)
                        .with_origin(format!("/{path}"))
                        .into()
                }),
            )
            .into(),
        );
    }
    let mut series: Vec<ContainerLike> = Vec::new();
    if parts.reconstruction {
        series.push(
            TimeSeriesView::new("solvers (iteration timeline)")
                .with_origin("/solver")
                .into(),
        );
        series.push(
            TimeSeriesView::new("frame RMS (px)")
                .with_origin(format!("/{}", paths::FRAME_RMS))
                .into(),
        );
    }
    if parts.tracking {
        series.push(
            TimeSeriesView::new("tracker counts")
                .with_origin(format!("/{}", paths::TRACKING))
                .into(),
        );
    }
    if !series.is_empty() {
        bottom.push(Tabs::new(series).into());
    }
    let mut texts: Vec<ContainerLike> = Vec::new();
    if parts.reconstruction {
        texts.push(
            TextDocumentView::new("summary")
                .with_origin(format!("/{}", paths::SUMMARY))
                .into(),
        );
        texts.push(
            TextDocumentView::new("metric upgrade")
                .with_origin(format!("/{}", paths::METRIC_METHOD))
                .into(),
        );
    }
    texts.push(TextLogView::new("log").with_origin("/log").into());
    bottom.push(Tabs::new(texts).into());
    let layout = Vertical::new([Horizontal::new(top).into(), Horizontal::new(bottom).into()])
        .with_row_shares([0.62, 0.38]);
    Blueprint::new(layout)
        .with_time_panel(TimePanel::new().with_timeline(TIMELINE_STAGE))
        .send(rec, BlueprintActivation::default())?;
    Ok(())
}

/// Removes an existing regular, singly linked file at `path`, so that the recording goes to
/// a new file instead of over a truncated one. Truncating costs more: ext4 frees the old
/// blocks inside the truncating call, and on close starts writing back a file that was
/// truncated and rewritten (its `auto_da_alloc` safeguard); opening an 8 MB recording's
/// path took about 2 ms longer that way (`examples/recording_overhead.rs`). Symlinks and
/// hard-linked files are left alone (the sink truncates them, as `File::create` does), and
/// so is a file that cannot be removed.
fn unlink_for_rewrite(path: &std::path::Path) {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let Ok(m) = std::fs::symlink_metadata(path)
            && m.file_type().is_file()
            && m.nlink() == 1
        {
            std::fs::remove_file(path).ok();
        }
    }
    #[cfg(not(unix))]
    let _ = path;
}

/// Runs [`Reconstruction::from_tracks_observed`] with everything logged to `rec` when given:
/// the input ([`log_input`]), stage events, solver iterations and warnings
/// ([`RecordingObserver`]), then the result ([`log_reconstruction`]) or the error
/// ([`log_error`]). Without `rec` it is [`Reconstruction::from_tracks`]. Failed log calls
/// inside the pipeline are reported as a warning in the result.
///
/// The input, the visibility mask and W ([`log_measurement_matrix`], as soon as the
/// pipeline announces the frames and tracks of its fit with [`Event::FitSelection`]) are
/// logged on a second thread while the pipeline runs, so that their cost overlaps the
/// pipeline's instead of adding to it.
pub fn reconstruct_recorded(
    rec: Option<&RecordingStream>,
    table: &TrackTable,
    config: &Config,
) -> RecordingResult<Reconstruction> {
    reconstruct_recorded_with(rec, table, config, &mut crate::NoopObserver)
}

/// Forwards the first [`Event::FitSelection`] to the thread that logs W.
struct SelectionForward(Option<std::sync::mpsc::Sender<(Vec<usize>, Vec<usize>)>>);

impl Observer for SelectionForward {
    fn on_event(&mut self, event: &Event<'_>) {
        if let Event::FitSelection { frames, tracks } = event
            && let Some(tx) = self.0.take()
        {
            // The receiver only goes away if its thread failed; that error is reported
            // when the thread is joined.
            tx.send((frames.to_vec(), tracks.to_vec())).ok();
        }
    }
}

/// [`reconstruct_recorded`] with every pipeline event also sent to `extra` (a progress
/// bar, say).
pub fn reconstruct_recorded_with(
    rec: Option<&RecordingStream>,
    table: &TrackTable,
    config: &Config,
    extra: &mut dyn Observer,
) -> RecordingResult<Reconstruction> {
    let Some(rec) = rec else {
        return Ok(Reconstruction::from_tracks_observed(table, config, extra)?);
    };
    let options = RecordingOptions::default();
    let (result, matrix_logged, observer) = std::thread::scope(|scope| {
        let (tx, rx) = std::sync::mpsc::channel::<(Vec<usize>, Vec<usize>)>();
        let opts = &options;
        let background = scope.spawn(move || -> RecordingResult<bool> {
            log_input_with(rec, table, opts)?;
            log_visibility(rec, table, opts)?;
            // Blocks until the pipeline has chosen its fit, or has ended without one.
            match rx.recv() {
                Ok((frames, tracks)) => {
                    log_measurement_matrix(rec, table, &frames, &tracks, opts)?;
                    Ok(true)
                }
                Err(_) => Ok(false),
            }
        });
        let mut observer = RecordingObserver::new(rec);
        let mut forward = SelectionForward(Some(tx));
        let result = Reconstruction::from_tracks_observed(
            table,
            config,
            &mut crate::Both(&mut observer, crate::Both(&mut forward, extra)),
        );
        // Closes the channel if the pipeline ended before choosing its fit.
        drop(forward);
        observer.flush();
        let logged = background
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
        (result, logged, observer)
    });
    let matrix_logged = matrix_logged?;
    match result {
        Ok(mut result) => {
            if let (n @ 1.., Some(first)) = observer.errors() {
                result
                    .warnings
                    .push(format!("recording: {n} log call(s) failed, first: {first}"));
            }
            log_result(rec, table, &result, &options, !matrix_logged)?;
            if let Some(r) = &result.robust {
                let mut inliers = vec![false; table.n_tracks()];
                for &p in &result.kept_tracks {
                    inliers[p] = true;
                }
                log_robust(
                    rec,
                    table,
                    &inliers,
                    &r.flagged_indices,
                    &r.inliers_per_iteration,
                )?;
            }
            Ok(result)
        }
        Err(e) => {
            log_error(rec, &e)?;
            Err(e.into())
        }
    }
}

/// The `stage`-timeline index of a named stage (see [`STAGES`]); `None` for unknown names.
pub fn stage_index(stage: &str) -> Option<i64> {
    match stage {
        "complete" => Some(3),
        _ => STAGES.iter().position(|s| *s == stage).map(|i| i as i64),
    }
}

/// Sets the `stage` timeline and clears `frame` and `iteration`.
fn at_stage(rec: &RecordingStream, stage: &str) {
    rec.set_time_sequence(
        TIMELINE_STAGE,
        stage_index(stage).unwrap_or(STAGES.len() as i64),
    );
    rec.disable_timeline(TIMELINE_FRAME);
    rec.disable_timeline(TIMELINE_ITERATION);
}

/// Turns [`Event`]s into Rerun log calls: iterations become `Scalars` on the `iteration`
/// timeline (`solver/<name>/run<k>/{cost,rms,lambda}`), stage events `TextLog`s on
/// `log/stages` at the stage's `stage`-timeline index, warnings `TextLog`s (level WARN)
/// on `log/warnings`. Logging errors cannot be returned from an observer; they are counted
/// and the first is kept ([`RecordingObserver::first_error`]).
///
/// Iteration scalars are buffered per series and sent as one chunk each (`send_columns`)
/// at the next stage or warning event, when a series reaches 4096 values, on
/// [`RecordingObserver::flush`] or on drop: a solver's hundreds of iterations cost a few
/// log calls, not three each.
///
/// Cost: O(1) amortised per event.
pub struct RecordingObserver {
    rec: RecordingStream,
    unknown_stages: Vec<String>,
    stage: i64,
    errors: usize,
    first_error: Option<String>,
    /// Solver scalars not yet sent, one series per entity path and stage.
    pending: Vec<PendingSeries>,
}

/// Iteration scalars of one entity path, buffered so that a solver's hundreds of
/// iterations go out as one chunk (`send_columns`) instead of one log call each.
struct PendingSeries {
    path: String,
    stage: i64,
    iterations: Vec<i64>,
    values: Vec<f64>,
}

/// A buffered series is sent once it holds this many values (bounded memory on long runs).
const MAX_PENDING: usize = 4096;

impl RecordingObserver {
    /// An observer logging to `rec` (the stream is shared, not consumed).
    pub fn new(rec: &RecordingStream) -> Self {
        Self {
            rec: rec.clone(),
            unknown_stages: Vec::new(),
            stage: 0,
            errors: 0,
            first_error: None,
            pending: Vec::new(),
        }
    }

    /// Sends the buffered solver scalars (also done at every stage event and on drop).
    pub fn flush(&mut self) {
        let pending = std::mem::take(&mut self.pending);
        for series in pending {
            let result = self.send_series(&series);
            self.note(result);
        }
    }

    fn send_series(&self, series: &PendingSeries) -> RecordingResult {
        let columns = Scalars::update_fields()
            .with_scalars(series.values.iter().copied())
            .columns_of_unit_batches()?;
        self.rec.send_columns(
            series.path.as_str(),
            [
                TimeColumn::new_sequence(TIMELINE_ITERATION, series.iterations.iter().copied()),
                TimeColumn::new_sequence(
                    TIMELINE_STAGE,
                    std::iter::repeat_n(series.stage, series.iterations.len()),
                ),
            ],
            columns,
        )?;
        Ok(())
    }

    fn note<E: std::fmt::Display>(&mut self, result: Result<(), E>) {
        if let Err(e) = result {
            self.errors += 1;
            if self.first_error.is_none() {
                self.first_error = Some(e.to_string());
            }
        }
    }

    /// Buffers one scalar of `path` at `iteration`.
    fn push(&mut self, path: String, iteration: usize, value: f64) {
        let stage = self.stage;
        let k = match self
            .pending
            .iter()
            .position(|s| s.stage == stage && s.path == path)
        {
            Some(k) => k,
            None => {
                self.pending.push(PendingSeries {
                    path,
                    stage,
                    iterations: Vec::new(),
                    values: Vec::new(),
                });
                self.pending.len() - 1
            }
        };
        let series = &mut self.pending[k];
        series.iterations.push(iteration as i64);
        series.values.push(value);
        if series.values.len() >= MAX_PENDING {
            let series = self.pending.swap_remove(k);
            let result = self.send_series(&series);
            self.note(result);
        }
    }

    /// Number of log calls that failed, and the first failure.
    pub fn errors(&self) -> (usize, Option<&str>) {
        (self.errors, self.first_error.as_deref())
    }

    /// The first logging failure, if any.
    pub fn first_error(&self) -> Option<&str> {
        self.first_error.as_deref()
    }

    fn stage_of(&mut self, stage: &str) -> i64 {
        if let Some(i) = stage_index(stage) {
            return i;
        }
        let k = match self.unknown_stages.iter().position(|s| s == stage) {
            Some(k) => k,
            None => {
                self.unknown_stages.push(stage.to_string());
                self.unknown_stages.len() - 1
            }
        };
        (STAGES.len() + k) as i64
    }

    fn handle(&mut self, event: &Event<'_>) -> Result<(), RecordingStreamError> {
        if !matches!(event, Event::Iteration { .. }) {
            self.flush();
        }
        let rec = &self.rec;
        match event {
            Event::StageStarted { stage } => {
                self.stage = self.stage_of(stage);
                let rec = &self.rec;
                rec.set_time_sequence(TIMELINE_STAGE, self.stage);
                rec.disable_timeline(TIMELINE_FRAME);
                rec.disable_timeline(TIMELINE_ITERATION);
                rec.log(
                    paths::LOG_STAGES,
                    &TextLog::new(format!("stage {stage} started")).with_level(TextLogLevel::INFO),
                )
            }
            Event::StageFinished { stage, seconds } => {
                rec.set_time_sequence(TIMELINE_STAGE, self.stage);
                rec.disable_timeline(TIMELINE_ITERATION);
                rec.log(
                    paths::LOG_STAGES,
                    &TextLog::new(format!("stage {stage} finished in {seconds:.4} s"))
                        .with_level(TextLogLevel::INFO),
                )
            }
            Event::Iteration {
                solver,
                run,
                iteration,
                cost,
                rms,
                lambda,
            } => {
                let base = format!("solver/{solver}/run{run}");
                self.push(format!("{base}/cost"), *iteration, *cost);
                self.push(format!("{base}/rms"), *iteration, *rms);
                if lambda.is_finite() {
                    self.push(format!("{base}/lambda"), *iteration, *lambda);
                }
                Ok(())
            }
            Event::Warning { message } => {
                rec.disable_timeline(TIMELINE_ITERATION);
                rec.log(
                    paths::LOG_WARNINGS,
                    &TextLog::new(*message).with_level(TextLogLevel::WARN),
                )
            }
            // Events added later are not recorded until this observer learns them.
            #[allow(unreachable_patterns)]
            _ => Ok(()),
        }
    }
}

impl Observer for RecordingObserver {
    fn on_event(&mut self, event: &Event<'_>) {
        let result = self.handle(event);
        self.note(result);
    }
}

impl Drop for RecordingObserver {
    fn drop(&mut self) {
        self.flush();
    }
}

fn f2(p: [f64; 2]) -> [f32; 2] {
    [p[0] as f32, p[1] as f32]
}

fn f3(x: &nalgebra::Vector3<f64>) -> [f32; 3] {
    [x[0] as f32, x[1] as f32, x[2] as f32]
}

fn class_id(p: usize) -> u16 {
    (p % 65536) as u16
}

const RED: [u8; 3] = [230, 40, 40];
const GREEN: [u8; 3] = [40, 190, 60];
const ORANGE: [u8; 3] = [255, 150, 0];
const GREY: [u8; 3] = [150, 150, 150];

/// Green (0) → yellow (0.5) → red (1).
fn heat(t: f64) -> [u8; 3] {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        1.0
    };
    if t < 0.5 {
        [(510.0 * t) as u8, 200, 40]
    } else {
        [255, (200.0 * (2.0 - 2.0 * t)) as u8, 40]
    }
}

/// The Arrow field of Rerun's `Vec2D` datatype (2D positions and vectors are
/// `FixedSizeList<2, f32>` of this field).
fn vec2_field() -> Arc<Field> {
    Arc::new(Field::new("item", DataType::Float32, false))
}

/// `[x0, y0, x1, y1, …]` as a `Vec2D` Arrow array, built in one move instead of element by
/// element (the SDK's generic serializer costs several times more on 10⁵ points).
fn vec2_array(flat: Vec<f32>) -> RecordingResult<ArrayRef> {
    Ok(Arc::new(FixedSizeListArray::try_new(
        vec2_field(),
        2,
        Arc::new(Float32Array::from(flat)),
        None,
    )?))
}

/// `LineStrip2D` components (lists of `Vec2D`) from the strips' concatenated points and
/// their lengths.
fn strips_array(flat: Vec<f32>, lengths: &[usize]) -> RecordingResult<ArrayRef> {
    let item = Arc::new(Field::new(
        "item",
        DataType::FixedSizeList(vec2_field(), 2),
        false,
    ));
    Ok(Arc::new(ListArray::try_new(
        item,
        OffsetBuffer::from_lengths(lengths.iter().copied()),
        vec2_array(flat)?,
        None,
    )?))
}

/// Class ids (`u16`) as an Arrow array.
fn class_id_array(ids: Vec<u16>) -> ArrayRef {
    Arc::new(UInt16Array::from(ids))
}

/// The observed positions of `tracks` in frame order (gaps bridged), concatenated, with
/// each track's number of points. Two passes over the table's frame rows (count, then
/// fill), so that the table is read in memory order.
fn trajectories(table: &TrackTable, tracks: &[usize]) -> (Vec<f32>, Vec<usize>) {
    let mut lengths = vec![0usize; tracks.len()];
    for f in 0..table.n_frames() {
        let row = table.frame_row(f);
        for (len, &p) in lengths.iter_mut().zip(tracks) {
            *len += usize::from(row.contains(p));
        }
    }
    let mut next: Vec<usize> = lengths
        .iter()
        .scan(0, |start, &len| {
            let s = *start;
            *start += len;
            Some(2 * s)
        })
        .collect();
    let mut flat = vec![0f32; 2 * lengths.iter().sum::<usize>()];
    for f in 0..table.n_frames() {
        let row = table.frame_row(f);
        for (at, &p) in next.iter_mut().zip(tracks) {
            if let Some([x, y]) = row.get(p) {
                flat[*at] = x as f32;
                flat[*at + 1] = y as f32;
                *at += 2;
            }
        }
    }
    (flat, lengths)
}

/// `LineStrips2D` of the trajectories of `tracks`, with their class ids.
fn trajectory_batches(
    table: &TrackTable,
    tracks: &[usize],
) -> RecordingResult<[SerializedComponentBatch; 2]> {
    let (flat, lengths) = trajectories(table, tracks);
    Ok([
        SerializedComponentBatch::new(
            strips_array(flat, &lengths)?,
            LineStrips2D::descriptor_strips(),
        ),
        SerializedComponentBatch::new(
            class_id_array(tracks.iter().map(|&p| class_id(p)).collect()),
            LineStrips2D::descriptor_class_ids(),
        ),
    ])
}

/// Number of observed entries of `tracks` in `frames`: the size of the per-entry buffers,
/// allocated up front.
fn observed_count(
    table: &TrackTable,
    frames: impl IntoIterator<Item = usize>,
    tracks: &[usize],
) -> usize {
    frames
        .into_iter()
        .map(|f| {
            let row = table.frame_row(f);
            tracks.iter().filter(|&&p| row.contains(p)).count()
        })
        .sum()
}

/// Per-frame observed points of `tracks` for the given `frames`: concatenated positions,
/// class ids and the number of points per frame.
fn frame_points(
    table: &TrackTable,
    frames: &[usize],
    tracks: &[usize],
) -> (Vec<f32>, Vec<u16>, Vec<usize>) {
    let ids_of: Vec<u16> = tracks.iter().map(|&p| class_id(p)).collect();
    let n = observed_count(table, frames.iter().copied(), tracks);
    let mut flat = Vec::with_capacity(2 * n);
    let mut ids = Vec::with_capacity(n);
    let mut lengths = Vec::with_capacity(frames.len());
    for &f in frames {
        let before = ids.len();
        let row = table.frame_row(f);
        for (&p, &id) in tracks.iter().zip(&ids_of) {
            if let Some([x, y]) = row.get(p) {
                flat.push(x as f32);
                flat.push(y as f32);
                ids.push(id);
            }
        }
        lengths.push(ids.len() - before);
    }
    (flat, ids, lengths)
}

/// Sends one row per frame of an entity as a single chunk (`send_columns`): row `k` on the
/// `frame` timeline at `frames[k]` and on the `stage` timeline at `stage`. One chunk instead
/// of a log call per frame spares the SDK's batcher from re-assembling 10⁵ points.
fn send_per_frame(
    rec: &RecordingStream,
    path: &str,
    stage: &str,
    frames: &[usize],
    columns: Vec<SerializedComponentColumn>,
) -> RecordingResult {
    let stage = stage_index(stage).unwrap_or(STAGES.len() as i64);
    rec.send_columns(
        path,
        [
            TimeColumn::new_sequence(TIMELINE_FRAME, frames.iter().map(|&f| f as i64)),
            TimeColumn::new_sequence(TIMELINE_STAGE, std::iter::repeat_n(stage, frames.len())),
        ],
        columns,
    )?;
    Ok(())
}

/// Per-frame `Points2D` rows (positions, class ids, one colour and radius per row) of the
/// observed entries of `tracks`, sent with [`send_per_frame`].
fn send_frame_points(
    rec: &RecordingStream,
    path: &str,
    stage: &str,
    table: &TrackTable,
    tracks: &[usize],
    color: Option<[u8; 3]>,
    radius: f32,
) -> RecordingResult {
    let frames: Vec<usize> = (0..table.n_frames()).collect();
    let (flat, ids, lengths) = frame_points(table, &frames, tracks);
    let mut columns = vec![
        SerializedComponentBatch::new(vec2_array(flat)?, Points2D::descriptor_positions())
            .partitioned(lengths.iter().copied())?,
        SerializedComponentBatch::new(class_id_array(ids), Points2D::descriptor_class_ids())
            .partitioned(lengths.iter().copied())?,
    ];
    let mut rows =
        Points2D::update_fields().with_radii(vec![Radius::new_ui_points(radius); frames.len()]);
    if let Some(c) = color {
        rows = rows.with_colors(vec![c; frames.len()]);
    }
    columns.extend(rows.columns_of_unit_batches()?);
    send_per_frame(rec, path, stage, &frames, columns)
}

/// Logs the input table: per-frame observed points on `image/tracks` (class id = track
/// index, with an annotation context mapping it to the track id), and one trajectory per
/// track on `image/trajectories`, at stage `input`.
///
/// Cost: O(F·N).
pub fn log_input(rec: &RecordingStream, table: &TrackTable) -> RecordingResult {
    log_input_with(rec, table, &RecordingOptions::default())
}

/// [`log_input`] with explicit [`RecordingOptions`].
pub fn log_input_with(
    rec: &RecordingStream,
    table: &TrackTable,
    options: &RecordingOptions,
) -> RecordingResult {
    at_stage(rec, "input");
    let n = table.n_tracks();
    if let Some(ctx) = track_labels(table, options) {
        rec.log_static("image", &ctx)?;
        rec.log_static("world", &ctx)?;
        rec.log_static("affine", &ctx)?;
        rec.log_static(paths::TRUTH_ROOT, &ctx)?;
    }
    let all: Vec<usize> = (0..n).collect();
    rec.log(paths::TRAJECTORIES, &trajectory_batches(table, &all)?)?;
    send_frame_points(rec, paths::TRACKS, "input", table, &all, None, 2.0)
}

/// The annotation context that names each class id `track <id>` (hover labels), when the
/// table has at most `options.max_annotated_tracks` tracks.
fn track_labels(table: &TrackTable, options: &RecordingOptions) -> Option<AnnotationContext> {
    (table.n_tracks() <= options.max_annotated_tracks.min(65535)).then(|| {
        AnnotationContext::new(
            table.track_ids().iter().enumerate().map(|(p, id)| {
                ClassDescription::from((class_id(p), format!("track {id}").as_str()))
            }),
        )
    })
}

/// Every-k-th index so that at most `max` remain.
fn subsample(len: usize, max: usize) -> Vec<usize> {
    let max = max.max(1);
    let step = len.div_ceil(max).max(1);
    (0..len).step_by(step).collect()
}

/// Logs everything a finished run explains itself with (see the module table): set-aside
/// tracks, the visibility mask and W, the singular values and σ4/σ3, the affine and metric
/// structure, L's eigenvalues and the upgrade path, the cameras, the residuals and a
/// markdown summary. `table` must be the table the reconstruction was computed from.
///
/// Cost: O(F·N).
pub fn log_reconstruction(
    rec: &RecordingStream,
    table: &TrackTable,
    result: &Reconstruction,
) -> RecordingResult {
    log_reconstruction_with(rec, table, result, &RecordingOptions::default())
}

/// [`log_reconstruction`] with explicit [`RecordingOptions`].
pub fn log_reconstruction_with(
    rec: &RecordingStream,
    table: &TrackTable,
    result: &Reconstruction,
    options: &RecordingOptions,
) -> RecordingResult {
    log_result(rec, table, result, options, true)
}

/// [`log_reconstruction_with`], with the visibility mask and W left out when
/// `with_matrix` is false (already logged while the pipeline ran).
fn log_result(
    rec: &RecordingStream,
    table: &TrackTable,
    result: &Reconstruction,
    options: &RecordingOptions,
    with_matrix: bool,
) -> RecordingResult {
    check_consistent(table, result)?;
    // The largest part first, so that the SDK's writer encodes it while the rest is built.
    log_residuals(rec, table, result, options)?;
    log_set_aside(rec, table, result)?;
    if with_matrix {
        log_visibility(rec, table, options)?;
        log_measurement_matrix(
            rec,
            table,
            &result.kept_frames,
            &result.kept_tracks,
            options,
        )?;
    }
    log_factorization(rec, result)?;
    log_metric(rec, result)?;
    log_projective(rec, table, result, options)?;
    log_perspective(rec, table, result, options)?;
    at_stage(rec, "result");
    rec.log(
        paths::SUMMARY,
        &TextDocument::from_markdown(summary_markdown(result)),
    )?;
    Ok(())
}

fn check_consistent(table: &TrackTable, r: &Reconstruction) -> RecordingResult {
    let (fk, nk) = (r.kept_frames.len(), r.kept_tracks.len());
    let bad = r.input_frame_ids.len() != table.n_frames()
        || r.input_track_ids.len() != table.n_tracks()
        || r.model.n_frames() != fk
        || r.model.n_points() != nk
        || r.affine_structure.ncols() != nk
        || r.points.len() != nk + r.outlier_tracks.len()
        || r.points.iter().filter(|p| p.inlier).count() != nk
        || r.outlier_model.n_points() != r.outlier_tracks.len()
        || r.outlier_tracks.iter().any(|&p| p >= table.n_tracks())
        || r.frames.len() != fk
        || r.kept_frames.iter().any(|&f| f >= table.n_frames())
        || r.kept_tracks.iter().any(|&p| p >= table.n_tracks());
    if bad {
        return Err(Error::Dimension {
            context: "recording::log_reconstruction (table vs reconstruction)",
            expected: format!(
                "a reconstruction of a {}×{} table",
                table.n_frames(),
                table.n_tracks()
            ),
            got: format!(
                "one of a {}×{} table with {} kept frames and {} kept tracks",
                r.input_frame_ids.len(),
                r.input_track_ids.len(),
                fk,
                nk
            ),
        }
        .into());
    }
    Ok(())
}

fn log_set_aside(rec: &RecordingStream, table: &TrackTable, r: &Reconstruction) -> RecordingResult {
    at_stage(rec, "set-aside");
    // Neither kept nor an outlier of the robust pass (those are drawn by `log_robust`).
    let mut used = vec![false; table.n_tracks()];
    for &p in r.kept_tracks.iter().chain(&r.outlier_tracks) {
        used[p] = true;
    }
    let aside: Vec<usize> = (0..table.n_tracks()).filter(|&p| !used[p]).collect();
    for s in &r.set_aside {
        let what = match s.kind {
            SetAsideKind::Track => "track",
            SetAsideKind::Frame => "frame",
        };
        rec.log(
            paths::LOG_SET_ASIDE,
            &TextLog::new(format!("set aside {what} {}: {}", s.id, s.reason))
                .with_level(TextLogLevel::INFO),
        )?;
    }
    if aside.is_empty() {
        return Ok(());
    }
    let labels = LineStrips2D::update_fields()
        .with_colors([RED])
        .with_labels(
            aside
                .iter()
                .map(|&p| format!("set aside: track {}", table.track_ids()[p])),
        );
    let [strips, ids] = trajectory_batches(table, &aside)?;
    rec.log(
        paths::SET_ASIDE_TRAJECTORIES,
        &[&strips as &dyn rerun::AsComponents, &ids, &labels],
    )?;
    send_frame_points(
        rec,
        paths::SET_ASIDE_POINTS,
        "set-aside",
        table,
        &aside,
        Some(RED),
        3.0,
    )
}

/// Logs the visibility mask of the whole input table on `factorization/visibility` (an
/// L8 image, white = observed, subsampled per [`RecordingOptions::max_image_side`]) at stage
/// `factorize`.
///
/// Cost: O(F·N).
pub fn log_visibility(
    rec: &RecordingStream,
    table: &TrackTable,
    options: &RecordingOptions,
) -> RecordingResult {
    at_stage(rec, "factorize");
    let rows = subsample(table.n_frames(), options.max_image_side);
    let cols = subsample(table.n_tracks(), options.max_image_side);
    let mut mask = Vec::with_capacity(rows.len() * cols.len());
    for &f in &rows {
        let row = table.frame_row(f);
        mask.extend(
            cols.iter()
                .map(|&p| if row.contains(p) { 255u8 } else { 0 }),
        );
    }
    rec.log(
        paths::VISIBILITY,
        &Image::from_l8(mask, [cols.len() as u32, rows.len() as u32]),
    )?;
    Ok(())
}

/// Logs the measurement matrix W of the given input `frames` and `tracks` (indices into
/// `table`) on `factorization/W` at stage `factorize`: a 2F'×N' f32 tensor with rows x₀, y₀,
/// x₁, y₁, … and NaN where unobserved, subsampled per [`RecordingOptions::max_image_side`].
///
/// Cost: O(F'·N').
pub fn log_measurement_matrix(
    rec: &RecordingStream,
    table: &TrackTable,
    frames: &[usize],
    tracks: &[usize],
    options: &RecordingOptions,
) -> RecordingResult {
    if let Some(&bad) = frames
        .iter()
        .find(|&&f| f >= table.n_frames())
        .or_else(|| tracks.iter().find(|&&p| p >= table.n_tracks()))
    {
        return Err(Error::Dimension {
            context: "recording::log_measurement_matrix (frames, tracks)",
            expected: format!(
                "frame indices below {} and track indices below {}",
                table.n_frames(),
                table.n_tracks()
            ),
            got: bad.to_string(),
        }
        .into());
    }
    at_stage(rec, "factorize");
    let rows = subsample(frames.len(), options.max_image_side / 2);
    let cols = subsample(tracks.len(), options.max_image_side);
    let mut w = vec![f32::NAN; 2 * rows.len() * cols.len()];
    let cols: Vec<usize> = cols.iter().map(|&kp| tracks[kp]).collect();
    for (r, &kf) in rows.iter().enumerate() {
        let (wx, wy) = w[2 * r * cols.len()..(2 * r + 2) * cols.len()].split_at_mut(cols.len());
        let row = table.frame_row(frames[kf]);
        for ((&p, u), v) in cols.iter().zip(wx).zip(wy) {
            if let Some([x, y]) = row.get(p) {
                (*u, *v) = (x as f32, y as f32);
            }
        }
    }
    let w = TensorData::new(
        vec![2 * rows.len() as u64, cols.len() as u64],
        TensorBuffer::F32(w.into()),
    )
    .with_dim_names(["row (2·frame + x|y)", "track"]);
    rec.log(paths::W, &Tensor::new(w))?;
    Ok(())
}

/// The factorization's results: singular values, σ4/σ3 and the affine structure.
fn log_factorization(rec: &RecordingStream, r: &Reconstruction) -> RecordingResult {
    at_stage(rec, "factorize");
    rec.log(
        paths::SINGULAR_VALUES,
        &BarChart::new(r.singular_values.clone()),
    )?;
    if r.rank_ratio.is_finite() {
        rec.log(paths::RANK_RATIO, &Scalars::single(r.rank_ratio))?;
    }
    let s = &r.affine_structure;
    rec.log(
        paths::AFFINE_POINTS,
        &Points3D::new(
            (0..s.ncols()).map(|p| [s[(0, p)] as f32, s[(1, p)] as f32, s[(2, p)] as f32]),
        )
        .with_class_ids(r.kept_tracks.iter().map(|&p| class_id(p))),
    )?;
    Ok(())
}

/// Camera centre placed back along the viewing direction `k` (scaled orthographic: by
/// `1/s`, since magnification is inversely proportional to depth).
fn camera_centre(model: &MetricModel, f: usize, d: f64) -> nalgebra::Vector3<f64> {
    let k = model.rotations[f].matrix().row(2).transpose();
    let s = model.scales[f];
    let s = if s.is_finite() && s > 0.0 { s } else { 1.0 };
    -k * (d / s)
}

/// A viewing distance: twice the largest distance of a point from the centroid (≥ 1e-9).
fn scene_distance(model: &MetricModel) -> f64 {
    let n = model.points.len().max(1) as f64;
    let c = model
        .points
        .iter()
        .fold(nalgebra::Vector3::zeros(), |a, p| a + p)
        / n;
    let r = model
        .points
        .iter()
        .map(|p| (p - c).norm())
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max);
    if r > 0.0 { 2.0 * r } else { 1.0 }
}

/// Cameras of `model` under `base` (`world` or `truth`): a Transform3D per frame on
/// `<base>/camera` (frame timeline value `frame_index[f]`), static camera-local axes on
/// `<base>/camera/axes`, all viewing directions and the centre trajectory under
/// `<base>/cameras/`.
fn log_cameras(
    rec: &RecordingStream,
    base: &str,
    model: &MetricModel,
    frame_index: &[usize],
) -> RecordingResult {
    let d = scene_distance(model);
    let centres: Vec<nalgebra::Vector3<f64>> = (0..model.n_frames())
        .map(|f| camera_centre(model, f, d))
        .collect();
    let axis = (0.25 * d) as f32;
    rec.log_static(
        format!("{base}/camera/axes"),
        &Arrows3D::from_vectors([[axis, 0.0, 0.0], [0.0, axis, 0.0], [0.0, 0.0, 2.0 * axis]])
            .with_colors([RED, GREEN, [60, 90, 255]])
            .with_labels(["i", "j", "k (view)"]),
    )?;
    rec.log(
        format!("{base}/cameras/view_directions"),
        &Arrows3D::from_vectors((0..model.n_frames()).map(|f| {
            let k = model.rotations[f].matrix().row(2).transpose();
            f3(&(k * (0.5 * d)))
        }))
        .with_origins(centres.iter().map(f3))
        .with_colors([[60, 90, 255]]),
    )?;
    rec.log(
        format!("{base}/cameras/trajectory"),
        &LineStrips3D::new([LineStrip3D::from_iter(centres.iter().map(f3))]).with_colors([GREY]),
    )?;
    for f in 0..model.n_frames() {
        rec.set_time_sequence(TIMELINE_FRAME, frame_index[f] as i64);
        let r = model.rotations[f].matrix();
        // Columns of the camera-to-world rotation are the camera axes i, j, k (rows of R).
        let cols: [[f32; 3]; 3] =
            std::array::from_fn(|a| std::array::from_fn(|b| r[(a, b)] as f32));
        rec.log(
            format!("{base}/camera"),
            &Transform3D::from_translation_mat3x3(f3(&centres[f]), cols),
        )?;
    }
    rec.disable_timeline(TIMELINE_FRAME);
    Ok(())
}

fn upgrade_text(r: &Reconstruction) -> String {
    let u = &r.metric_upgrade;
    let mut s = format!(
        "## Metric upgrade\n\nSolved `L = QQᵀ` by **{}**.\n\n\
         * eigenvalues of the least-squares L: {:.4e}, {:.4e}, {:.4e}\n\
         * eigenvalues of the L used: {:.4e}, {:.4e}, {:.4e}\n\
         * constraint RMS at the L used: {:.3e}\n",
        match u.method {
            UpgradeMethod::LeastSquares => "linear least squares (L positive definite)",
            UpgradeMethod::Sdp => "the PSD-constrained SDP",
        },
        u.eigenvalues_ls[0],
        u.eigenvalues_ls[1],
        u.eigenvalues_ls[2],
        u.eigenvalues[0],
        u.eigenvalues[1],
        u.eigenvalues[2],
        u.constraint_rms
    );
    if u.method == UpgradeMethod::Sdp {
        s.push_str(&format!(
            "* why: the least-squares L's smallest eigenvalue is {:.3e} (not positive definite, \
             or forced)\n* SDP status: {}, {} iterations\n",
            u.min_eigenvalue_ls,
            u.sdp_status.as_deref().unwrap_or("?"),
            u.sdp_iterations.map_or("?".into(), |i| i.to_string())
        ));
    }
    s
}

/// The points of the kept tracks, in `kept_tracks` order: `r.points` holds every kept and
/// outlier track in input order, and the kept ones are the inliers (both ascending).
fn kept_points(r: &Reconstruction) -> impl Iterator<Item = &crate::reconstruction::PointResult> {
    r.points.iter().filter(|p| p.inlier)
}

fn log_metric(rec: &RecordingStream, r: &Reconstruction) -> RecordingResult {
    // The world has the first camera's axes: x right, y down, z forward (as the images).
    rec.log_static("world", &rerun::ViewCoordinates::RDF())?;
    at_stage(rec, "metric-upgrade");
    let u = &r.metric_upgrade;
    rec.log(
        paths::EIGENVALUES_LS,
        &BarChart::new(u.eigenvalues_ls.to_vec()),
    )?;
    rec.log(paths::EIGENVALUES, &BarChart::new(u.eigenvalues.to_vec()))?;
    rec.log(
        paths::METRIC_METHOD,
        &TextDocument::from_markdown(upgrade_text(r)),
    )?;
    let max_rms = kept_points(r)
        .map(|p| p.rms_px)
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max);
    rec.log(
        paths::POINTS,
        &Points3D::new(r.model.points.iter().map(f3))
            .with_colors(kept_points(r).map(|p| {
                heat(if max_rms > 0.0 {
                    p.rms_px / max_rms
                } else {
                    0.0
                })
            }))
            .with_class_ids(r.kept_tracks.iter().map(|&p| class_id(p))),
    )?;
    if !r.outlier_tracks.is_empty() {
        rec.log(
            paths::OUTLIER_POINTS,
            &Points3D::new(r.outlier_model.points.iter().map(f3))
                .with_colors([RED])
                .with_class_ids(r.outlier_tracks.iter().map(|&p| class_id(p))),
        )?;
    }
    log_cameras(rec, "world", &r.model, &r.kept_frames)
}

fn log_residuals(
    rec: &RecordingStream,
    table: &TrackTable,
    r: &Reconstruction,
    options: &RecordingOptions,
) -> RecordingResult {
    at_stage(rec, "refine");
    rec.log(
        paths::POINT_RMS,
        &BarChart::new(kept_points(r).map(|p| p.rms_px).collect::<Vec<f64>>()),
    )?;
    send_residual_arrows(
        rec,
        table,
        r,
        options,
        paths::RESIDUAL_ARROWS,
        "refine",
        |kf, kp| {
            let q = r.model.project(kf, kp);
            [q[0], q[1]]
        },
    )?;
    let rms = Scalars::update_fields()
        .with_scalars(r.frames.iter().map(|f| f.rms_px))
        .columns_of_unit_batches()?;
    send_per_frame(
        rec,
        paths::FRAME_RMS,
        "refine",
        &r.kept_frames,
        rms.collect(),
    )
}

/// Residual arrows (observed → `predict(kept frame, kept track)`) of the kept tracks on
/// `path` per frame at `stage`, sent in blocks of frames
/// ([`RecordingOptions::residual_arrows_per_chunk`]).
#[allow(clippy::too_many_arguments)]
fn send_residual_arrows(
    rec: &RecordingStream,
    table: &TrackTable,
    r: &Reconstruction,
    options: &RecordingOptions,
    path: &str,
    stage: &str,
    predict: impl Fn(usize, usize) -> [f64; 2],
) -> RecordingResult {
    let tracks = subsample(r.kept_tracks.len(), options.max_residual_arrows_per_frame);
    let inputs: Vec<usize> = tracks.iter().map(|&kp| r.kept_tracks[kp]).collect();
    // Sent in blocks of frames (RecordingOptions::residual_arrows_per_chunk), so that the
    // SDK's writer encodes a block while the next one is built.
    let block = (options.residual_arrows_per_chunk / tracks.len().max(1)).max(1);
    let frames: Vec<(usize, usize)> = r.kept_frames.iter().copied().enumerate().collect();
    for part in frames.chunks(block) {
        let n = observed_count(table, part.iter().map(|&(_, fi)| fi), &inputs);
        let mut origins = Vec::with_capacity(2 * n);
        let mut vectors = Vec::with_capacity(2 * n);
        let mut ids = Vec::with_capacity(n);
        let mut lengths = Vec::with_capacity(part.len());
        for &(kf, fi) in part {
            let before = ids.len();
            let row = table.frame_row(fi);
            for (&kp, &pi) in tracks.iter().zip(&inputs) {
                if let Some([x, y]) = row.get(pi) {
                    let q = predict(kf, kp);
                    origins.push(x as f32);
                    origins.push(y as f32);
                    vectors.push((q[0] - x) as f32);
                    vectors.push((q[1] - y) as f32);
                    ids.push(class_id(pi));
                }
            }
            lengths.push(ids.len() - before);
        }
        let columns = vec![
            SerializedComponentBatch::new(vec2_array(vectors)?, Arrows2D::descriptor_vectors())
                .partitioned(lengths.iter().copied())?,
            SerializedComponentBatch::new(vec2_array(origins)?, Arrows2D::descriptor_origins())
                .partitioned(lengths.iter().copied())?,
            SerializedComponentBatch::new(class_id_array(ids), Arrows2D::descriptor_class_ids())
                .partitioned(lengths.iter().copied())?,
        ];
        let frame_values: Vec<usize> = part.iter().map(|&(_, fi)| fi).collect();
        send_per_frame(rec, path, stage, &frame_values, columns)?;
    }
    Ok(())
}

/// The projective stages (camera `projective`): residual arrows to `π(P_f X_p)`, per-frame
/// RMS, and a table of each stage's RMS before/after at stage `projective`. Nothing for
/// the affine cameras.
fn log_projective(
    rec: &RecordingStream,
    table: &TrackTable,
    r: &Reconstruction,
    options: &RecordingOptions,
) -> RecordingResult {
    let Some(p) = &r.projective else {
        return Ok(());
    };
    send_residual_arrows(
        rec,
        table,
        r,
        options,
        paths::PROJECTIVE_RESIDUALS,
        "projective",
        |kf, kp| p.model.project(kf, kp),
    )?;
    let rms = Scalars::update_fields()
        .with_scalars(p.cameras.iter().map(|c| c.rms_px))
        .columns_of_unit_batches()?;
    send_per_frame(
        rec,
        paths::PROJECTIVE_FRAME_RMS,
        "projective",
        &r.kept_frames,
        rms.collect(),
    )?;
    at_stage(rec, "projective");
    rec.log(
        paths::PROJECTIVE_STAGES,
        &TextDocument::from_markdown(projective_markdown(p)),
    )?;
    Ok(())
}

/// The perspective reconstruction: residual arrows, Euclidean points, the camera path with
/// pinhole frustums of the estimated intrinsics, and a report.
fn log_perspective(
    rec: &RecordingStream,
    table: &TrackTable,
    r: &Reconstruction,
    options: &RecordingOptions,
) -> RecordingResult {
    let Some(p) = &r.perspective else {
        return Ok(());
    };
    let m = &p.model;
    send_residual_arrows(
        rec,
        table,
        r,
        options,
        paths::PERSPECTIVE_RESIDUALS,
        "perspective",
        |kf, kp| m.project(kf, kp),
    )?;
    at_stage(rec, "perspective");
    rec.log_static("perspective/world", &rerun::ViewCoordinates::RDF())?;
    let fitted: Vec<&crate::reconstruction::PointResult> =
        p.points.iter().filter(|q| q.inlier).collect();
    let max_rms = fitted
        .iter()
        .map(|q| q.rms_px)
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max)
        .max(1e-12);
    // The unit is the points' RMS spread about their centroid: sizes relative to it.
    rec.log(
        paths::PERSPECTIVE_POINTS,
        &Points3D::new(m.points.iter().map(f3))
            .with_colors(fitted.iter().map(|q| heat(q.rms_px / max_rms)))
            .with_radii([0.01f32]),
    )?;
    rec.log(
        paths::PERSPECTIVE_OUTLIERS,
        &Points3D::new(
            p.outlier_points
                .iter()
                .filter(|x| x.iter().all(|v| v.is_finite()))
                .map(f3),
        )
        .with_colors([RED])
        .with_radii([0.012f32]),
    )?;
    let nf = m.rotations.len();
    let centres: Vec<nalgebra::Vector3<f64>> = (0..nf).map(|f| m.centre(f)).collect();
    rec.log(
        paths::PERSPECTIVE_TRAJECTORY,
        &LineStrips3D::new([LineStrip3D::from_iter(centres.iter().map(f3))]).with_colors([GREY]),
    )?;
    let size = p
        .intrinsics
        .image_size
        .map(|[w, h]| [w as f32, h as f32])
        .unwrap_or([
            (2.0 * m.principal_point[0] + 1.0) as f32,
            (2.0 * m.principal_point[1] + 1.0) as f32,
        ]);
    let pinhole = |f: usize| {
        rerun::Pinhole::from_focal_length_and_resolution([m.focal_px[f] as f32; 2], size)
            .with_principal_point([m.principal_point[0] as f32, m.principal_point[1] as f32])
            .with_image_plane_distance(0.15f32)
    };
    // Camera-to-world: translation = centre, rotation = Rᵀ (its columns are the camera's
    // x (right), y (down), z (forward) axes, Rerun's default RDF pinhole frame).
    let pose = |f: usize| {
        let rt = m.rotations[f].transpose();
        let cols: [[f32; 3]; 3] =
            std::array::from_fn(|c| std::array::from_fn(|row| rt[(row, c)] as f32));
        Transform3D::from_translation_mat3x3(f3(&centres[f]), cols)
    };
    let step = nf.div_ceil(24).max(1);
    for f in (0..nf).step_by(step) {
        let path = format!("{}/{f}", paths::PERSPECTIVE_FRUSTUMS);
        rec.log_static(path.clone(), &pose(f))?;
        rec.log_static(path, &pinhole(f))?;
    }
    for f in 0..nf {
        rec.set_time_sequence(TIMELINE_FRAME, r.kept_frames[f] as i64);
        rec.log(paths::PERSPECTIVE_CAMERA, &pose(f))?;
        rec.log(paths::PERSPECTIVE_CAMERA, &pinhole(f))?;
    }
    rec.disable_timeline(TIMELINE_FRAME);
    rec.log(
        paths::PERSPECTIVE_REPORT,
        &TextDocument::from_markdown(perspective_markdown(p)),
    )?;
    Ok(())
}

/// Markdown report of the perspective stages.
fn perspective_markdown(p: &crate::reconstruction::PerspectiveResult) -> String {
    let k = &p.intrinsics;
    let mut s = format!(
        "# Perspective reconstruction\n\nRMS {:.6} px; {:.1} % of the observations in front of \
         their camera.\n\n## Intrinsics\n\n* focal length {:.2} px ({})\n* principal point \
         ({:.2}, {:.2}) ({})\n* k₁ {:.5}\n",
        p.rms_px,
        100.0 * p.in_front,
        k.focal_px,
        k.focal,
        k.principal_point[0],
        k.principal_point[1],
        k.principal_point_source,
        k.k1
    );
    if let Some(sc) = &p.self_calibration {
        s.push_str(&format!(
            "\n## Self-calibration\n\n* linear absolute dual quadric eigenvalues: {:.4} {:.4} \
             {:.4} {:.4}\n* PSD-constrained solve: {}\n",
            sc.linear_eigenvalues[0],
            sc.linear_eigenvalues[1],
            sc.linear_eigenvalues[2],
            sc.linear_eigenvalues[3],
            sc.sdp_status.as_deref().unwrap_or("not needed")
        ));
    }
    s.push_str(
        "\n## Starts (screened)\n\n| start | focal (px) | mirrored | RMS (px) | kept |\n\
         |---|---|---|---|---|\n",
    );
    for st in &p.starts {
        s.push_str(&format!(
            "| {} | {:.1} | {} | {:.4} | {} |\n",
            st.kind,
            st.focal_px,
            st.mirrored,
            st.rms_px,
            if st.chosen { "✓" } else { "" }
        ));
    }
    s.push_str("\n## Adjustment\n\n");
    s.push_str(&stages_table(&p.stages));
    s
}

/// Markdown table of the projective stages.
fn projective_markdown(p: &crate::reconstruction::ProjectiveResult) -> String {
    format!(
        "# Projective reconstruction\n\nstart: {:?}; final RMS {:.6} px; reduced camera system \
         {} non-zeros\n\n{}",
        p.start,
        p.rms_px,
        p.schur_nnz,
        stages_table(&p.stages)
    )
}

/// Markdown table of solver stages: status, iterations, RMS before and after, seconds.
fn stages_table(stages: &[crate::projective::StageReport]) -> String {
    let mut s = String::from(
        "| stage | status | iterations | RMS before (px) | RMS after (px) | s |\n\
         |---|---|---|---|---|---|\n",
    );
    for st in stages {
        s.push_str(&format!(
            "| {} | {:?} | {} | {:.6} | {:.6} | {:.3} |\n",
            st.stage, st.status, st.iterations, st.rms_before_px, st.rms_after_px, st.seconds
        ));
    }
    s
}

/// The markdown run summary logged on `summary`: inputs, choices, results, timings,
/// warnings.
pub fn summary_markdown(r: &Reconstruction) -> String {
    let i = &r.input;
    let mut s = String::from("# rank3 reconstruction\n\n## Input\n\n");
    s.push_str(&format!(
        "* {} frames × {} tracks, {} observations ({:.1} % filled)\n\
         * used: {} frames × {} tracks; set aside: {} track(s), {} frame(s)\n",
        i.frames,
        i.tracks,
        i.observations,
        100.0 * i.fill,
        i.frames_used,
        i.tracks_used,
        r.set_aside
            .iter()
            .filter(|a| a.kind == SetAsideKind::Track)
            .count(),
        r.set_aside
            .iter()
            .filter(|a| a.kind == SetAsideKind::Frame)
            .count(),
    ));
    s.push_str("\n## Choices\n\n");
    s.push_str(&format!(
        "* camera model: {}\n* factorization: {} (SVD: {}{})\n* metric upgrade: {:?}\n\
         * refinement: {}\n* depth-reversal convention mirrored the solution: {}\n",
        r.camera_model,
        r.factorization.method,
        r.factorization.svd_method,
        r.factorization
            .svd_fallback_reason
            .as_deref()
            .map_or(String::new(), |why| format!(", fallback: {why}")),
        r.metric_upgrade.method,
        match &r.refinement {
            Some(f) if f.skipped.is_some() => {
                format!("skipped ({})", f.skipped.as_deref().unwrap_or(""))
            }
            Some(f) => format!(
                "RMS {:.6} → {:.6} px ({:?}, {} iterations)",
                f.rms_before_px, f.rms_after_px, f.status, f.iterations
            ),
            None => "off".into(),
        },
        r.mirrored
    ));
    let sv: Vec<String> = r
        .singular_values
        .iter()
        .take(6)
        .map(|v| format!("{v:.4}"))
        .collect();
    s.push_str(&format!(
        "\n## Results\n\n* singular values: {}\n* σ4/σ3 = {:.4}\n* affine fit RMS: {:.6} px\n\
         * final RMS: {:.6} px\n",
        sv.join(", "),
        r.rank_ratio,
        r.factorization.rms_px,
        r.rms_px
    ));
    if let Some(p) = &r.projective {
        s.push_str(&format!(
            "* camera model: projective (start {:?}); metric (scaled-orthographic) model RMS \
             {:.6} px\n",
            p.start, r.metric_rms_px
        ));
        for st in &p.stages {
            s.push_str(&format!(
                "* projective {}: RMS {:.6} → {:.6} px ({:?}, {} iterations)\n",
                st.stage, st.rms_before_px, st.rms_after_px, st.status, st.iterations
            ));
        }
    }
    s.push_str("\n## Timings\n\n| stage | seconds |\n|---|---|\n");
    for t in &r.timings {
        s.push_str(&format!("| {} | {:.4} |\n", t.stage, t.seconds));
    }
    s.push_str("\n## Warnings\n\n");
    if r.warnings.is_empty() {
        s.push_str("none\n");
    }
    for w in &r.warnings {
        s.push_str(&format!("* {w}\n"));
    }
    s.push('\n');
    s.push_str(&upgrade_text(r));
    s
}

/// Logs a failed run's error on `log/errors` (level ERROR) at stage `result`.
pub fn log_error(rec: &RecordingStream, error: &Error) -> RecordingResult {
    at_stage(rec, "result");
    rec.log(
        paths::LOG_ERRORS,
        &TextLog::new(error.to_string()).with_level(TextLogLevel::ERROR),
    )?;
    Ok(())
}

/// Logs the robust (RANSAC) pass at stage `robust`: a colour per input trajectory on
/// `image/trajectories` (green inlier, red outlier; the strips logged by [`log_input`] keep
/// their positions), the outlier tracks' trajectories in red (labelled) on
/// `image/robust/outliers`,
/// flagged entries as orange points per frame on `image/robust/flagged`, and the inlier count
/// per RANSAC iteration on `solver/ransac/inliers` (`iteration` timeline).
///
/// `inlier_tracks[p]` refers to track `p` of `table`; `flagged_entries` are `(frame, track)`
/// indices into `table`.
///
/// Cost: O(F·N + #flagged + #iterations).
pub fn log_robust(
    rec: &RecordingStream,
    table: &TrackTable,
    inlier_tracks: &[bool],
    flagged_entries: &[(usize, usize)],
    inliers_per_iteration: &[usize],
) -> RecordingResult {
    if inlier_tracks.len() != table.n_tracks() {
        return Err(Error::Dimension {
            context: "recording::log_robust inlier_tracks",
            expected: format!("{} entries (one per track)", table.n_tracks()),
            got: inlier_tracks.len().to_string(),
        }
        .into());
    }
    if let Some(&(f, p)) = flagged_entries
        .iter()
        .find(|&&(f, p)| f >= table.n_frames() || p >= table.n_tracks())
    {
        return Err(Error::Dimension {
            context: "recording::log_robust flagged_entries",
            expected: format!(
                "(frame, track) indices below ({}, {})",
                table.n_frames(),
                table.n_tracks()
            ),
            got: format!("({f}, {p})"),
        }
        .into());
    }
    at_stage(rec, "robust");
    let (inl, outl): (Vec<usize>, Vec<usize>) =
        (0..table.n_tracks()).partition(|&p| inlier_tracks[p]);
    // The input trajectories turn green (inlier) or red (outlier) from this stage on: a
    // colour column, not a second copy of every trajectory.
    rec.log(
        paths::TRAJECTORIES,
        &LineStrips2D::update_fields().with_colors(
            inlier_tracks
                .iter()
                .map(|&inlier| if inlier { GREEN } else { RED }),
        ),
    )?;
    let labels = LineStrips2D::update_fields()
        .with_colors([RED])
        .with_labels(
            outl.iter()
                .map(|&p| format!("outlier track {}", table.track_ids()[p])),
        );
    let [strips, ids] = trajectory_batches(table, &outl)?;
    rec.log(
        paths::ROBUST_OUTLIERS,
        &[&strips as &dyn rerun::AsComponents, &ids, &labels],
    )?;
    rec.log(
        paths::LOG_STAGES,
        &TextLog::new(format!(
            "robust: {} inlier track(s), {} outlier track(s), {} flagged entr(y/ies)",
            inl.len(),
            outl.len(),
            flagged_entries.len()
        ))
        .with_level(TextLogLevel::INFO),
    )?;
    let mut by_frame: Vec<Vec<usize>> = vec![Vec::new(); table.n_frames()];
    for &(f, p) in flagged_entries {
        by_frame[f].push(p);
    }
    for (f, tracks) in by_frame.iter().enumerate() {
        if tracks.is_empty() {
            continue;
        }
        rec.set_time_sequence(TIMELINE_FRAME, f as i64);
        let (pos, ids): (Vec<[f32; 2]>, Vec<u16>) = tracks
            .iter()
            .filter_map(|&p| table.get(f, p).map(|xy| (f2(xy), class_id(p))))
            .unzip();
        rec.log(
            paths::ROBUST_FLAGGED,
            &Points2D::new(pos)
                .with_class_ids(ids)
                .with_colors([ORANGE])
                .with_radii([Radius::new_ui_points(5.0)]),
        )?;
    }
    rec.disable_timeline(TIMELINE_FRAME);
    for (it, &count) in inliers_per_iteration.iter().enumerate() {
        rec.set_time_sequence(TIMELINE_ITERATION, it as i64);
        rec.log(paths::ROBUST_INLIER_COUNT, &Scalars::single(count as f64))?;
    }
    rec.disable_timeline(TIMELINE_ITERATION);
    Ok(())
}

/// Logs a frame the tracker saw on `image/frame` as a JPEG (`quality` 1–100) at `frame`
/// timeline value `index`, stage `input`, beneath the tracks of [`log_input`]. The image
/// is encoded here (about 5 ms for 640×480), so a recording holds tens of kilobytes per
/// frame instead of the raw pixels.
///
/// Cost: O(width·height).
pub fn log_frame(
    rec: &RecordingStream,
    index: usize,
    image: &crate::tracking::GrayImage,
    quality: u8,
) -> RecordingResult {
    let (w, h) = (image.width, image.height);
    let pixels: Vec<u8> = image
        .data
        .iter()
        .map(|&v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect();
    let mut jpeg = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, quality.clamp(1, 100))
        .encode(&pixels, w as u32, h as u32, image::ExtendedColorType::L8)
        .map_err(|e| Error::Image {
            path: PathBuf::from(format!("frame {index}")),
            message: format!("cannot encode the frame as JPEG for the recording: {e}"),
        })?;
    rec.set_time_sequence(TIMELINE_STAGE, 0);
    rec.set_time_sequence(TIMELINE_FRAME, index as i64);
    rec.log(
        paths::FRAME_IMAGE,
        &rerun::EncodedImage::from_file_contents(jpeg).with_draw_order(-10.0),
    )?;
    rec.disable_timeline(TIMELINE_FRAME);
    Ok(())
}

/// Logs the tracker's per-frame counts as Scalars on the `frame` timeline (stage `input`):
/// `tracking/tracked`, `tracking/new`, `tracking/alive` and `tracking/lost/<reason>` for
/// the reasons out_of_image, low_texture, residual and forward_backward.
///
/// Cost: O(F).
pub fn log_tracking(
    rec: &RecordingStream,
    stats: &[crate::tracking::FrameStats],
) -> RecordingResult {
    let frames: Vec<usize> = stats.iter().map(|s| s.frame).collect();
    type Count = fn(&crate::tracking::FrameStats) -> usize;
    let series: [(&str, Count); 7] = [
        ("tracked", |s| s.tracked),
        ("new", |s| s.new),
        ("alive", |s| s.alive),
        ("lost/out_of_image", |s| s.lost_out_of_image),
        ("lost/low_texture", |s| s.lost_low_texture),
        ("lost/residual", |s| s.lost_residual),
        ("lost/forward_backward", |s| s.lost_forward_backward),
    ];
    for (name, count) in series {
        let column = Scalars::update_fields()
            .with_scalars(stats.iter().map(|s| count(s) as f64))
            .columns_of_unit_batches()?;
        send_per_frame(
            rec,
            &format!("{}/{name}", paths::TRACKING),
            "input",
            &frames,
            column.collect(),
        )?;
    }
    Ok(())
}

/// Logs a synthetic scene's ground truth under `truth/`: the true points (outlier tracks
/// red, the rest grey) on `truth/points` and the true cameras laid out like `world/`
/// (`log_cameras` layout) on `truth/camera…`, at stage `input`. Pair with [`log_input`].
///
/// Cost: O(F + N).
pub fn log_synth_truth(rec: &RecordingStream, scene: &SynthScene) -> RecordingResult {
    at_stage(rec, "input");
    let m = &scene.truth;
    rec.log(
        paths::TRUTH_POINTS,
        &Points3D::new(m.points.iter().map(f3))
            .with_colors((0..m.n_points()).map(|p| {
                if scene.outlier_tracks.get(p).is_some_and(|o| o.is_some()) {
                    RED
                } else {
                    GREY
                }
            }))
            .with_class_ids((0..m.n_points()).map(class_id)),
    )?;
    let frames: Vec<usize> = (0..m.n_frames()).collect();
    log_cameras(rec, paths::TRUTH_ROOT, m, &frames)?;
    rec.log(
        paths::LOG_STAGES,
        &TextLog::new(format!(
            "synthetic scene: {} frames × {} tracks, {} outlier track(s), {} gross entr(y/ies)",
            m.n_frames(),
            m.n_points(),
            scene.outlier_tracks.iter().filter(|o| o.is_some()).count(),
            scene.gross_entries.len()
        ))
        .with_level(TextLogLevel::INFO),
    )?;
    Ok(())
}

/// Distinct colours for objects (cycled).
const OBJECT_COLOURS: [[u8; 3]; 8] = [
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [148, 103, 189],
    [23, 190, 207],
    [188, 189, 34],
    [227, 119, 194],
    [140, 86, 75],
];

/// Colour of object `k` (cycled).
fn object_colour(k: usize) -> [u8; 3] {
    OBJECT_COLOURS[k % OBJECT_COLOURS.len()]
}

/// Logs a multi-object result ([`crate::objects`]): each object's trajectories in its
/// colour on `image/objects/<k>/trajectories` (stage `input`) and, per frame, its points on
/// `image/objects/<k>`; the outlier tracks likewise in red under `image/objects/outliers`; each reconstructed object's points and cameras (in its own
/// frame, which a translation on `objects/<k>` places beside the previous object's, so
/// that they do not overlap) under `objects/<k>/`; a
/// markdown summary on `objects/summary`. At stage `result`.
///
/// Cost: O(F·N) plus each object's points and cameras.
pub fn log_objects(
    rec: &RecordingStream,
    table: &TrackTable,
    mb: &crate::objects::MultiBody,
) -> RecordingResult {
    // The input's hover labels, then trajectories and per-frame points coloured by object
    // (not the input's per-track colours).
    at_stage(rec, "input");
    if let Some(ctx) = track_labels(table, &RecordingOptions::default()) {
        rec.log_static("image", &ctx)?;
    }
    let outliers: Vec<usize> = (0..table.n_tracks())
        .filter(|&p| mb.segmentation.labels[p].code() < 0)
        .collect();
    let groups = mb
        .objects
        .iter()
        .map(|o| {
            let path = format!("image/objects/{}", o.index);
            (path, &o.tracks, object_colour(o.index))
        })
        .chain(
            (!outliers.is_empty()).then(|| ("image/objects/outliers".to_string(), &outliers, RED)),
        )
        .collect::<Vec<_>>();
    for (path, tracks, colour) in &groups {
        rec.log(
            format!("{path}/trajectories"),
            &[
                &trajectory_batches(table, tracks)? as &dyn rerun::AsComponents,
                &LineStrips2D::update_fields().with_colors([*colour]),
            ],
        )?;
    }
    at_stage(rec, "result");
    for (path, tracks, colour) in &groups {
        send_frame_points(rec, path, "result", table, tracks, Some(*colour), 3.0)?;
    }
    let mut offset = 0.0;
    let mut md = String::from(
        "| object | tracks | subspace RMS (px) | camera | RMS (px) |\n|---|---|---|---|---|\n",
    );
    for o in &mb.objects {
        let colour = object_colour(o.index);
        match &o.reconstruction {
            Ok(r) => {
                let pts = &r.model.points;
                let radius = pts
                    .iter()
                    .map(|x| x.norm())
                    .fold(0.0, f64::max)
                    .max(scene_distance(&r.model) * 0.1);
                let shift = (offset + radius) as f32;
                offset += 2.5 * radius;
                let base = format!("objects/{}", o.index);
                rec.log(
                    format!("{base}/points"),
                    &Points3D::new(pts.iter().map(f3))
                        .with_colors([colour])
                        .with_class_ids(r.kept_tracks.iter().map(|&p| class_id(o.tracks[p]))),
                )?;
                rec.log(
                    base.clone(),
                    &rerun::Transform3D::from_translation([shift, 0.0, 0.0]),
                )?;
                log_cameras(rec, &format!("{base}/cameras"), &r.model, &r.kept_frames)?;
                md.push_str(&format!(
                    "| {} | {} | {:.3} | {:?} | {:.3} |\n",
                    o.index,
                    o.tracks.len(),
                    o.subspace_rms_px,
                    r.camera_model,
                    r.rms_px
                ));
            }
            Err(e) => md.push_str(&format!(
                "| {} | {} | {:.3} | failed: {} | |\n",
                o.index,
                o.tracks.len(),
                o.subspace_rms_px,
                e.replace('|', "/")
            )),
        }
    }
    md.push_str(&format!(
        "\n{} outlier and {} unscored tracks; σ {:.3} px; {} rounds.\n",
        mb.segmentation.n_outliers(),
        mb.segmentation.n_unscored(),
        mb.segmentation.sigma,
        mb.segmentation.rounds
    ));
    rec.log_static("objects/summary", &TextDocument::from_markdown(md))?;
    Ok(())
}

/// Logs the textured surface at the `mesh` stage: [`paths::PERSPECTIVE_MESH`] beside the
/// Euclidean points when `r` has a perspective result, else [`paths::MESH`] beside the
/// affine-family ones (the positions the mesh was built on); the atlas is the albedo texture
/// (the per-vertex colours are used only without one: the viewer multiplies the two);
/// [`paths::MESH_REPORT`] holds its report.
pub fn log_mesh(
    rec: &RecordingStream,
    r: &Reconstruction,
    mesh: &crate::mesh::Mesh,
) -> RecordingResult {
    at_stage(rec, "mesh");
    let path = if r.perspective.is_some() {
        paths::PERSPECTIVE_MESH
    } else {
        paths::MESH
    };
    let mut m = rerun::Mesh3D::new(mesh.positions.iter().copied())
        .with_triangle_indices(
            mesh.triangles
                .iter()
                .map(|t| rerun::TriangleIndices::from(*t)),
        )
        .with_vertex_normals(mesh.normals.iter().copied());
    if mesh.texture.is_none() {
        m = m.with_vertex_colors(
            mesh.colors
                .iter()
                .map(|c| rerun::Color::from_rgb(c[0], c[1], c[2])),
        );
    }
    if let Some(tex) = &mesh.texture {
        m = m
            .with_vertex_texcoords(mesh.texcoords.iter().copied())
            .with_albedo_texture_image(Image::from_rgb24(
                tex.as_raw().clone(),
                [tex.width(), tex.height()],
            ));
    }
    rec.log_static(path, &m)?;
    let rep = &mesh.report;
    let s = &rep.surface;
    let mut md = format!(
        "# Mesh\n\n{} triangles over {} of {} eligible tracks; {:.3} s triangulating, {:.3} s \
         texturing.\n\n| reference view | observed | new | candidates | kept |\n|---|---|---|---|---|\n",
        s.triangles, s.vertices, s.eligible_tracks, rep.seconds_surface, rep.seconds_texture
    );
    for v in &s.reference_views {
        md += &format!(
            "| {} | {} | {} | {} | {} |\n",
            v.frame, v.observed, v.new_vertices, v.candidates, v.kept
        );
    }
    let d = &s.dropped;
    md += &format!(
        "\nDropped: {} degenerate, {} edge-on, {} long edge, {} back-facing, {} occluding, {} \
         overlapping, {} duplicates.\n",
        d.degenerate, d.edge_on, d.long_edge, d.back_facing, d.occluding, d.overlap, d.duplicate
    );
    if let Some(t) = &rep.texture {
        md += &format!(
            "\nTexture: {} charts from {} frames, atlas {}×{} px (scale {:.3}); median view angle \
             {:.1}°, {:.1} % of the area within 30° of frontal, {:.1} % within 5° of its most frontal view.\n",
            t.charts,
            t.views_used,
            t.atlas_px[0],
            t.atlas_px[1],
            t.scale,
            t.median_view_angle_deg,
            100.0 * t.share_within_30deg,
            100.0 * t.share_near_most_frontal
        );
    }
    rec.log_static(paths::MESH_REPORT, &TextDocument::from_markdown(md))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use rerun::Loggable;

    /// The hand-built Arrow arrays must have exactly the types the SDK's serializers produce
    /// (a Rerun upgrade that changes them fails here, not in the viewer).
    #[test]
    fn bulk_arrays_match_the_sdk_types() {
        let pts = vec2_array(vec![1.0, 2.0, 3.0, 4.0]).unwrap();
        assert_eq!(pts.data_type(), &rerun::datatypes::Vec2D::arrow_datatype());
        assert_eq!(
            pts.data_type(),
            &rerun::components::Position2D::arrow_datatype()
        );
        assert_eq!(
            pts.data_type(),
            &rerun::components::Vector2D::arrow_datatype()
        );
        assert_eq!(pts.len(), 2);
        let strips = strips_array(vec![0.0; 10], &[2, 0, 3]).unwrap();
        assert_eq!(
            strips.data_type(),
            &rerun::components::LineStrip2D::arrow_datatype()
        );
        assert_eq!(strips.len(), 3);
        assert!(
            strips_array(vec![0.0; 10], &[2, 4]).is_err(),
            "lengths beyond the data"
        );
        let ids = class_id_array(vec![1, 2]);
        assert_eq!(
            ids.data_type(),
            &rerun::components::ClassId::arrow_datatype()
        );
    }

    /// Trajectories are built in memory order by two passes; they must equal the
    /// per-track walk through the frames, gaps bridged.
    #[test]
    fn trajectories_match_a_walk_along_each_track() {
        let mut t = TrackTable::new(
            (0..4).map(crate::table::Id::Int).collect(),
            (0..3).map(crate::table::Id::Int).collect(),
        );
        for (f, p, x, y) in [
            (0, 0, 1.0, 2.0),
            (2, 0, 3.0, 4.0),
            (1, 2, 5.0, 6.0),
            (3, 2, 7.0, 8.0),
            (0, 2, 9.0, 10.0),
        ] {
            t.set(f, p, x, y);
        }
        let (flat, lengths) = trajectories(&t, &[2, 1, 0]);
        assert_eq!(lengths, vec![3, 0, 2]);
        assert_eq!(
            flat,
            vec![9.0, 10.0, 5.0, 6.0, 7.0, 8.0, 1.0, 2.0, 3.0, 4.0]
        );
    }

    /// An existing recording is replaced by a new file (a new inode), not truncated; a
    /// symlink is left in place, so the sink writes through it.
    #[cfg(unix)]
    #[test]
    fn rrd_is_written_to_a_new_file_but_symlinks_are_kept() {
        use std::os::unix::fs::MetadataExt;
        let dir = std::env::temp_dir().join(format!("rank3-unlink-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (file, link) = (dir.join("a.rrd"), dir.join("b.rrd"));
        std::fs::write(&file, b"old").unwrap();
        let before = std::fs::metadata(&file).unwrap().ino();
        // Keep the old inode alive, so that the new file cannot reuse its number.
        let _old = std::fs::File::open(&file).unwrap();
        unlink_for_rewrite(&file);
        assert!(!file.exists());
        std::fs::write(&file, b"new").unwrap();
        assert_ne!(std::fs::metadata(&file).unwrap().ino(), before);
        std::os::unix::fs::symlink(&file, &link).unwrap();
        unlink_for_rewrite(&link);
        assert!(
            std::fs::symlink_metadata(&link)
                .unwrap()
                .file_type()
                .is_symlink()
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
