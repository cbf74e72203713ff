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
//!   9 mesh (the completion, `complete`, is logged on 3 and the robust pass's search for
//!   other objects, `other-objects`, on 2).
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
//! | `image/trajectories` | LineStrips2D | one strip per input track (stage `input`, frame 0); from stage `robust` on coloured green (inlier) / red (outlier) |
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
//! | `image/robust/{outliers,flagged}` | LineStrips2D / Points2D | robust pass: outlier tracks (labelled when few), flagged entries |
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
//! | `solver/{cost,log10_cost,rms,lambda,log10_lambda}/<name>/run<k>` | Scalars per iteration | solver progress, one entity per quantity and run ([`paths::SOLVER_COST`] …) |
//! | `solver/inliers/ransac` | Scalars per iteration | RANSAC's inlier track count |
//! | `log/stages`, `log/warnings`, `log/set_aside`, `log/errors` | TextLog | events |
//! | `summary` | TextDocument (markdown) | inputs, choices, timings, warnings |
//!
//! # Viewer layout
//!
//! The CLI's recordings carry a layout ([`send_layout`]): the image plane beside the 3D
//! structures, and below them W, the bar charts, the time series and the texts.
//!
//! * Each solver quantity has its own plot and axis: the cost and λ as log₁₀ (they span
//!   decades; the viewer 0.36 has no logarithmic axis), the RMS in pixels, the RANSAC
//!   inlier count. They plot against the `iteration` timeline.
//! * Track labels: every point, strip and arrow of a track carries its class id, which the
//!   annotation context names `track <id>` on hover; labels are drawn only on the image
//!   plane for flagged tracks (set aside, robust outliers), and only when there are at most
//!   24 of them.
//! * The 3D views open framed on their points (an eye on the first camera's side), once the
//!   structures are logged: the layout is sent again with the eyes.
//! * The time panel opens on the timeline where the recording's data live: `frame` for
//!   `rank3 track`, `stage` otherwise.
//!
//! # Modules
//!
//! `sinks` (the CLI's [`RecordingArgs`] and [`finish_opened`]), `layout` (the blueprint),
//! `observer` ([`RecordingObserver`], [`reconstruct_recorded`]), `input` (the track table,
//! frames, tracker counts, synthetic truth), `reconstruction` (set-aside, factorization,
//! metric upgrade, cameras, residuals, summary), `robust`, `perspective` (the projective
//! and perspective cameras), `objects`, `mesh`, and `bulk` (Arrow arrays built from flat
//! buffers, per-frame chunks, colours).
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
//! [`Event::FitSelection`](crate::Event::FitSelection)), and the result afterwards, largest
//! entity first, so that the SDK's writer thread encodes it while the rest is built. On a 100-frame × 2000-track run
//! (8.4 MB file) this costs about 5 % of the pipeline's time (4.3–6.8 %); see the crate's
//! `docs/results.md` and `examples/recording_overhead.rs`.
//!
//! Cost: O(F·N) for the per-frame data (points, arrows, mask, W), O(N + F) for the rest.

mod bulk;
mod input;
mod layout;
mod mesh;
mod objects;
mod observer;
mod perspective;
mod reconstruction;
mod robust;
mod sinks;

pub use input::{log_frame, log_input, log_input_with, log_synth_truth, log_tracking};
pub use layout::{LayoutParts, send_layout};
pub use mesh::log_mesh;
pub use objects::log_objects;
pub use observer::{RecordingObserver, reconstruct_recorded, reconstruct_recorded_with};
pub use reconstruction::{
    log_error, log_measurement_matrix, log_reconstruction, log_reconstruction_with, log_streamed,
    log_visibility, summary_markdown,
};
pub use robust::log_robust;
pub use sinks::{RecordingArgs, finish_opened};

use rerun::RecordingStream;
use rerun::RecordingStreamError;
use rerun::external::arrow::error::ArrowError;

use crate::Error;

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
    /// RANSAC's inlier count per iteration (`iteration` timeline).
    pub const ROBUST_INLIER_COUNT: &str = "solver/inliers/ransac";
    /// Solver progress per iteration, one entity per solver run under each:
    /// `<quantity>/<solver>/run<k>` (`iteration` timeline). The layout plots each quantity
    /// on its own axis.
    pub const SOLVER_COST: &str = "solver/cost";
    /// log₁₀ of the cost (the viewer 0.36 has no logarithmic axis; costs span decades).
    pub const SOLVER_LOG10_COST: &str = "solver/log10_cost";
    /// The damping λ of Levenberg–Marquardt solvers.
    pub const SOLVER_LAMBDA: &str = "solver/lambda";
    /// log₁₀ of λ.
    pub const SOLVER_LOG10_LAMBDA: &str = "solver/log10_lambda";
    /// The RMS reprojection error, pixels.
    pub const SOLVER_RMS: &str = "solver/rms";
    /// Inlier counts (RANSAC: [`ROBUST_INLIER_COUNT`]).
    pub const SOLVER_INLIERS: &str = "solver/inliers";
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

/// The `stage`-timeline index of a named stage (see [`STAGES`]); `None` for unknown names.
pub fn stage_index(stage: &str) -> Option<i64> {
    match stage {
        "complete" => Some(3),
        // The searches for other rigid objects (segmenting the kept tracks, and among the
        // tracks the pass rejected): part of the robust stage.
        "other-objects" | "other-bodies" => Some(2),
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
