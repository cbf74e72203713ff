//! The pipeline: track table in, metric structure and cameras out.
//!
//! 1. **Set-aside** ([`TrackTable::set_aside`]): tracks seen in too few frames, frames with
//!    too few tracks, and blocks disconnected from the main one are reported, not used.
//!    Then **degenerate input** is refused before the robust pass ([`crate::degeneracy`]:
//!    static camera, collinear points, rank < 3, coordinates too large for double
//!    precision), and the image origin is moved to the observations' centroid, so that no
//!    stage depends on where it is; the results are moved back at the end.
//! 2. **Affine factorization**. Complete data: the centering trick (Tomasi & Kanade 1992,
//!    §3.4) `t_f = mean_p w_fp`, `W̃ = W − t 1ᵀ`, and the rank-3 truncation
//!    `W̃ ≈ U₃Σ₃V₃ᵀ` (Eckart–Young), `M̂ = U₃Σ₃^{1/2}`, `Ŝ = Σ₃^{1/2}V₃ᵀ`, by a truncated SVD
//!    ([`crate::svd`]). σ4/σ3 is the rank diagnostic.
//! 3. **Metric upgrade** ([`crate::metric`]): `L = QQᵀ` by least squares, or by an SDP when
//!    that `L` is not positive definite; `M = M̂Q`; each frame's rows projected to the
//!    nearest (scaled) rotation; points by per-point least squares given those cameras.
//! 4. **Refinement** ([`crate::refine`]): Levenberg–Marquardt on the metric model over the
//!    observed entries.
//! 5. **Gauge**: frame 0's camera is the identity, the point centroid is the origin, for the
//!    scaled model frame 0's scale is 1, and the depth-reversal convention of
//!    [`crate::metric::apply_necker_convention`].
//!
//! Cost: O(F·N) for W plus the truncated SVD (O(F·N·k) per pass), O(F) for the upgrade,
//! and the refinement's cost per iteration (see [`crate::refine`]).

use std::time::Instant;

use faer::Mat;
use nalgebra::Vector3;
use serde::Serialize;

use rand::SeedableRng;

use crate::completion::{self, CompletionConfig, CompletionModel, CompletionSolverKind};
use crate::degeneracy;
use crate::metric::{self, MetricConfig, MetricUpgrade};
use crate::perspective::{self, PerspectiveConfig};
use crate::projective::{self, ProjectiveConfig, ProjectiveModel};
use crate::refine::{self, RefineConfig, RefineResult};
use crate::robust::{self, RobustConfig};
use crate::svd::{self, SvdMethod, TruncatedSvdConfig};
use crate::table::{Id, SetAside};
use crate::{
    CameraModel, Error, Event, Measurements, MetricModel, NoopObserver, Observer, Result,
    SolverStatus, TrackTable,
};

/// Pipeline settings. Every field has a documented default.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Config {
    /// Metric camera model. Default orthographic.
    pub camera: CameraModel,
    /// Tracks seen in fewer frames are set aside. Default 2.
    pub min_frames_per_track: usize,
    /// Frames with fewer tracks are set aside. Default 3 for complete data (a frame's
    /// 2×3 camera needs 3 points); missing-data solvers may need more and say so.
    pub min_points_per_frame: usize,
    /// Truncated SVD settings. Default: [`TruncatedSvdConfig::default`] with
    /// `cluster_tolerance = 1e-2`.
    pub svd: TruncatedSvdConfig,
    /// Metric upgrade settings.
    pub metric: MetricConfig,
    /// Robust pass (outlier tracks, gross entries) before the fit; `None` skips it.
    /// Default on, with thresholds floored at 2 px per track and 4 px per entry.
    pub robust: Option<RobustConfig>,
    /// Missing-data solver, used when the table (after the robust pass) is incomplete.
    /// Default: damped Wiberg on the affine model, data-driven start.
    pub completion: CompletionConfig,
    /// Seed of the robust pass's sampling. Default 0.
    pub seed: u64,
    /// Levenberg–Marquardt refinement; `None` skips it. Default on.
    pub refine: Option<RefineConfig>,
    /// The projective stages, used with [`CameraModel::Projective`] and
    /// [`CameraModel::Perspective`].
    pub projective: ProjectiveConfig,
    /// The Euclidean upgrade and metric bundle adjustment, used with
    /// [`CameraModel::Perspective`] (known intrinsics go in its `intrinsics`).
    pub perspective: PerspectiveConfig,
    /// The sparse pipeline, for tables whose dense matrix does not fit
    /// ([`crate::sparse`]); its `pipeline` field chooses. Default
    /// [`crate::sparse::SparseConfig::default`].
    #[serde(default)]
    pub sparse: crate::sparse::SparseConfig,
    /// Warn "far from rank 3" when σ4/σ3 exceeds this. Default 0.1.
    pub rank3_warning_ratio: f64,
    /// Warn "close to rank 2" when σ3/σ2 is below this. Default 0.05.
    pub rank2_warning_ratio: f64,
    /// Known aspect ratio of the pixels, `f_x / f_y` (the width of a pixel's image of a
    /// unit square over its height; 1 = square pixels). Video digitised from a 4:3 picture
    /// at 512×480 has 0.8, NTSC DV (720×480) 1.1 (10:11 sample aspect ratio). The
    /// pipeline divides the image's x coordinates by it (about the observations'
    /// centroid) so that every camera model works in square pixels, and multiplies the
    /// results back: [`Reconstruction::aspect_ratio`]. Residuals and RMS values are then
    /// in square pixels the size of the pixel height. Default `None` (1).
    #[serde(default)]
    pub aspect_ratio: Option<f64>,
    /// Where [`Config::aspect_ratio`] came from, in words, for the reports
    /// ([`Reconstruction::aspect_ratio_source`]): `None` means given by the user.
    /// [`crate::pixel_aspect`] fills it when the ratio is read from the input files or
    /// assumed from the frame size. Default `None`.
    #[serde(default)]
    pub aspect_ratio_source: Option<String>,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            camera: CameraModel::Orthographic,
            min_frames_per_track: 2,
            min_points_per_frame: 3,
            // σ4 only feeds the σ4/σ3 diagnostic: 1 % relative accuracy is ample and halves
            // the Krylov iterations (see benches/svd.rs).
            svd: TruncatedSvdConfig {
                cluster_tolerance: 1e-2,
                ..TruncatedSvdConfig::default()
            },
            metric: MetricConfig::default(),
            // Floors for model error that is not noise (perspective under the affine
            // camera): see `RobustConfig::min_track_threshold_px`.
            robust: Some(RobustConfig {
                min_track_threshold_px: 2.0,
                min_entry_threshold_px: 4.0,
                ..RobustConfig::default()
            }),
            completion: CompletionConfig::default(),
            seed: 0,
            refine: Some(RefineConfig::default()),
            projective: ProjectiveConfig::default(),
            perspective: PerspectiveConfig::default(),
            sparse: crate::sparse::SparseConfig::default(),
            rank3_warning_ratio: 0.1,
            rank2_warning_ratio: 0.05,
            aspect_ratio: None,
            aspect_ratio_source: None,
        }
    }
}

/// One frame's metric camera: `[x, y] = scale · rotation[rows 0..2] · xyz + translation`.
#[derive(Debug, Clone, Serialize)]
pub struct FrameResult {
    pub frame: Id,
    /// Rows are the camera axes i, j, k (k = i × j) in world coordinates.
    pub rotation: [[f64; 3]; 3],
    pub translation: [f64; 2],
    pub scale: f64,
    /// RMS reprojection error of this frame's observations (x, y separately), pixels.
    pub rms_px: f64,
    pub n_observations: usize,
}

/// One track's 3D point.
#[derive(Debug, Clone, Serialize)]
pub struct PointResult {
    pub track: Id,
    pub xyz: [f64; 3],
    /// False for tracks rejected as outliers (all true until the robust pass runs).
    pub inlier: bool,
    /// RMS reprojection error of this track's observations, pixels.
    pub rms_px: f64,
    pub n_observations: usize,
}

/// The affine factorization's report.
#[derive(Debug, Clone, Serialize)]
pub struct FactorizationReport {
    /// `"svd"` for complete data.
    pub method: String,
    /// `"thin"` or `"randomized"`.
    pub svd_method: String,
    pub svd_fallback_reason: Option<String>,
    /// RMS of the affine fit `M̂Ŝ + t1ᵀ` over observed scalars, pixels.
    pub rms_px: f64,
}

/// The missing-data completion's report.
#[derive(Debug, Clone, Serialize)]
pub struct CompletionReport {
    pub solver: CompletionSolverKind,
    pub model: CompletionModel,
    /// RMS of the affine fit over observed scalars, pixels (the literature's measure).
    pub rms_px: f64,
    pub status: SolverStatus,
    pub iterations: usize,
    /// Alternating least-squares sweeps run before `solver` because its iterations would
    /// be costly on this table (`completion.als_first_flops`); 0 when it ran alone. When
    /// the sweeps converged, `iterations` is 0.
    pub als_sweeps_first: usize,
    pub runs: usize,
    pub seconds: f64,
}

/// A (frame, track) pair by id.
#[derive(Debug, Clone, Serialize)]
pub struct EntryId {
    pub frame: Id,
    pub track: Id,
}

/// The robust pass's report.
#[derive(Debug, Clone, Serialize)]
pub struct RobustReport {
    pub n_inlier_tracks: usize,
    pub n_outlier_tracks: usize,
    pub n_flagged_entries: usize,
    pub outlier_tracks: Vec<Id>,
    pub flagged_entries: Vec<EntryId>,
    /// Robust estimate of the image noise σ, pixels.
    pub noise_sigma_px: f64,
    /// RANSAC's inlier threshold `τ` on a track's *trimmed* RMS residual, pixels (the final
    /// keep/reject decision compares the untrimmed RMS with
    /// `max(σ·sqrt(χ²_ν(p)/ν), min_track_threshold_px)`, see [`crate::robust`]).
    pub threshold_px: f64,
    /// Entry-level gross-error threshold, pixels.
    pub entry_threshold_px: f64,
    pub iterations: usize,
    /// With the projective camera: how the projective model judged the tracks again
    /// ([`crate::projective::verdict`]); the lists and counts above are then its verdict,
    /// and `noise_sigma_px` / `entry_threshold_px` its estimates.
    pub projective: Option<ProjectiveJudgement>,
    /// Best inlier count after each RANSAC iteration (for the recording).
    #[serde(skip)]
    pub inliers_per_iteration: Vec<usize>,
    /// Flagged entries as (frame, track) indices into the input table.
    #[serde(skip)]
    pub flagged_indices: Vec<(usize, usize)>,
    /// Rigid groups seen: 1 (the body reconstructed) plus the other rigid objects, found
    /// by segmenting the kept tracks when the pass shows signs of them
    /// ([`crate::segment`]) or among the tracks the pass rejected or flagged
    /// ([`crate::segment::other_objects`]); 1 when `separate_objects` is off. A group the projective verdict mostly readmits (a part
    /// of the body seen in perspective) is not counted.
    pub rigid_groups_seen: usize,
    /// Tracks of the other rigid objects rejected whole (they are in `outlier_tracks`):
    /// every track of a group the segmentation found, and those the pass had kept (with
    /// flagged entries) of a group found after it.
    pub other_object_tracks: usize,
    pub seconds: f64,
}

/// What the projective verdict changed in the affine robust pass's selection.
#[derive(Debug, Clone, Serialize)]
pub struct ProjectiveJudgement {
    /// Tracks rejected by the affine pass that the projective model explains.
    pub readmitted_tracks: usize,
    /// Tracks kept by the affine pass that the projective model rejects.
    pub rejected_tracks: usize,
    /// Flagged entries before and after.
    pub flagged_before: usize,
    pub flagged_after: usize,
    /// Entry noise σ_e and entry threshold under the projective model, pixels.
    pub noise_sigma_px: f64,
    pub entry_threshold_px: f64,
    /// How many times the fit was run again with a new selection (at most 5,
    /// `PROJECTIVE_VERDICT_ROUNDS`).
    pub refits: usize,
    /// Other rigid objects found by the affine pass that stay rejected whatever the verdict:
    /// their own rigid motion explains their tracks better than the projective cameras
    /// fitted without them ([`crate::segment::projective_evidence`]). The others' tracks
    /// are judged like any track (a piece of the body that only perspective joins to it).
    pub objects_held_out: usize,
    /// Flagged entries the last verdict would readmit that stay flagged (and out of the
    /// fit) because refitting for them could not move the fit beyond its noise
    /// (`readmission_within_noise`).
    pub readmissions_not_refitted: usize,
}

impl RobustReport {
    /// Sets the lists and counts from an inlier flag per kept track and flagged entries
    /// (indices into the kept table, mapped to the input's by `kept_frames`/`kept_tracks`).
    fn update(
        &mut self,
        kept: &TrackTable,
        kept_frames: &[usize],
        kept_tracks: &[usize],
        inlier: &[bool],
        flagged: &[(usize, usize)],
    ) {
        self.outlier_tracks = (0..kept.n_tracks())
            .filter(|&p| !inlier[p])
            .map(|p| kept.track_ids()[p].clone())
            .collect();
        self.flagged_entries = flagged
            .iter()
            .map(|&(f, p)| EntryId {
                frame: kept.frame_ids()[f].clone(),
                track: kept.track_ids()[p].clone(),
            })
            .collect();
        self.n_inlier_tracks = inlier.iter().filter(|&&b| b).count();
        self.n_outlier_tracks = inlier.len() - self.n_inlier_tracks;
        self.n_flagged_entries = flagged.len();
        self.flagged_indices = flagged
            .iter()
            .map(|&(f, p)| (kept_frames[f], kept_tracks[p]))
            .collect();
    }
}

/// The refinement's report.
#[derive(Debug, Clone, Serialize)]
pub struct RefinementReport {
    pub rms_before_px: f64,
    pub rms_after_px: f64,
    pub status: SolverStatus,
    pub iterations: usize,
    pub seconds: f64,
    /// Why the refinement did not run (it could not gain enough), when it did not.
    pub skipped: Option<String>,
}

/// One frame's projective camera.
#[derive(Debug, Clone, Serialize)]
pub struct ProjectiveFrame {
    pub frame: Id,
    /// `P_f` (3×4, rows), unit Frobenius norm, pixels: `w ≃ P_f X`.
    pub p: [[f64; 4]; 3],
    /// RMS reprojection error of this frame's observations, pixels.
    pub rms_px: f64,
    pub n_observations: usize,
}

/// One track's homogeneous point.
#[derive(Debug, Clone, Serialize)]
pub struct ProjectivePoint {
    pub track: Id,
    /// `X_p` (homogeneous, unit norm; NaN when it cannot be triangulated).
    pub x: [f64; 4],
    pub inlier: bool,
    pub rms_px: f64,
    pub n_observations: usize,
}

/// The projective reconstruction: `w_fp ≃ P_f X_p`, defined up to a 4×4 homography.
#[derive(Debug, Clone, Serialize)]
pub struct ProjectiveResult {
    /// Reprojection RMS over the fit's observed scalars, pixels.
    pub rms_px: f64,
    pub start: projective::Start,
    pub stages: Vec<projective::StageReport>,
    pub cameras: Vec<ProjectiveFrame>,
    /// In the input's track order (fitted tracks and outlier tracks, as `points`).
    pub points: Vec<ProjectivePoint>,
    /// Non-zeros of the reduced camera system (lower triangle) of the bundle adjustment; 0
    /// when it was solved by conjugate gradients and never formed.
    pub schur_nnz: usize,
    /// The bridges tried from the affine start when a second one ran
    /// ([`projective::ProjectiveConfig::second_bridge`]): bridge, the projective RMS where
    /// it ended, which one the adjustment started from.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub bridges: Vec<projective::BridgeOutcome>,
    /// The escapes tried after the adjustment ([`projective::ProjectiveConfig::escapes`]).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub escapes: Vec<projective::EscapeOutcome>,
    /// The fitted model (fit frames × fit tracks), for library users.
    #[serde(skip)]
    pub model: projective::ProjectiveModel,
    /// Points of the outlier tracks given the fitted cameras (triangulated, not refined).
    #[serde(skip)]
    pub outlier_points: Vec<[f64; 4]>,
}

impl ProjectiveResult {
    #[allow(clippy::too_many_arguments)]
    fn new(
        pf: projective::ProjectiveFit,
        fit: &TrackTable,
        meas: &Measurements,
        outlier_meas: &Measurements,
        outlier_kept: &[usize],
        kept: &TrackTable,
        kept_tracks: &[usize],
        used_tracks: &[usize],
    ) -> Self {
        let model = pf.model;
        let outlier_points = ProjectiveModel {
            cameras: model.cameras.clone(),
            points: Vec::new(),
        }
        .triangulate(outlier_meas);
        let fitted = |f: usize, p: usize| model.project(f, p);
        let outliers =
            |f: usize, k: usize| projective::project(&model.cameras[f], &outlier_points[k]);
        let (sums, outlier_sums) = (
            ResidualSums::new(&fitted, meas),
            ResidualSums::new(&outliers, outlier_meas),
        );
        let cameras = (0..fit.n_frames())
            .map(|f| {
                let (ss, n) = sums.frames[f];
                ProjectiveFrame {
                    frame: fit.frame_ids()[f].clone(),
                    p: model.camera_matrix(f),
                    rms_px: rms_of(ss, n),
                    n_observations: n,
                }
            })
            .collect();
        let mut points: Vec<(usize, ProjectivePoint)> = Vec::new();
        for (p, &input_p) in used_tracks.iter().enumerate() {
            let (ss, n) = sums.points[p];
            points.push((
                input_p,
                ProjectivePoint {
                    track: fit.track_ids()[p].clone(),
                    x: model.points[p],
                    inlier: true,
                    rms_px: rms_of(ss, n),
                    n_observations: n,
                },
            ));
        }
        for (k, &p) in outlier_kept.iter().enumerate() {
            let (ss, n) = outlier_sums.points[k];
            points.push((
                kept_tracks[p],
                ProjectivePoint {
                    track: kept.track_ids()[p].clone(),
                    x: outlier_points[k],
                    inlier: false,
                    rms_px: rms_of(ss, n),
                    n_observations: n,
                },
            ));
        }
        points.sort_by_key(|(i, _)| *i);
        Self {
            rms_px: pf.rms_px,
            start: pf.start,
            stages: pf.stages,
            cameras,
            points: points.into_iter().map(|(_, p)| p).collect(),
            schur_nnz: pf.schur_nnz,
            bridges: pf.bridges,
            escapes: pf.escapes,
            model,
            outlier_points,
        }
    }
}

impl ProjectiveResult {
    /// The result of [`projective::fit_observations`] on the inlier tracks `inl` of `kept`
    /// (renumbered `0..inl.len()`, every frame of `kept`), with the outlier tracks `out`
    /// triangulated from the fitted cameras; points in `kept`'s track order. Residuals from
    /// `kept`'s rows: `O(observations)`.
    fn from_sparse(
        pf: projective::ProjectiveFit,
        kept: &TrackTable,
        inl: &[usize],
        out: &[usize],
    ) -> Self {
        let model = pf.model;
        let nf = model.cameras.len();
        let mut slot = vec![(usize::MAX, usize::MAX); kept.n_tracks()];
        for (j, &p) in inl.iter().enumerate() {
            slot[p].0 = j;
        }
        for (k, &p) in out.iter().enumerate() {
            slot[p].1 = k;
        }
        let outlier_obs = observations_of(kept, out);
        let outlier_points = ProjectiveModel {
            cameras: model.cameras.clone(),
            points: Vec::new(),
        }
        .triangulate_observations(&outlier_obs, out.len())
        .unwrap_or_else(|_| vec![[f64::NAN; 4]; out.len()]);
        drop(outlier_obs);
        let (frame_ss, track_ss) = sparse_residuals(kept, &slot, nf, |f, j, k| {
            if j != usize::MAX {
                model.project(f, j)
            } else {
                projective::project(&model.cameras[f], &outlier_points[k])
            }
        });
        let cameras = (0..nf)
            .map(|f| ProjectiveFrame {
                frame: kept.frame_ids()[f].clone(),
                p: model.camera_matrix(f),
                rms_px: rms_of(frame_ss[f].0, frame_ss[f].1),
                n_observations: frame_ss[f].1,
            })
            .collect();
        let points = (0..kept.n_tracks())
            .map(|p| {
                let (j, k) = slot[p];
                ProjectivePoint {
                    track: kept.track_ids()[p].clone(),
                    x: if j != usize::MAX {
                        model.points[j]
                    } else {
                        outlier_points[k]
                    },
                    inlier: j != usize::MAX,
                    rms_px: rms_of(track_ss[p].0, track_ss[p].1),
                    n_observations: track_ss[p].1,
                }
            })
            .collect();
        Self {
            rms_px: pf.rms_px,
            start: pf.start,
            stages: pf.stages,
            cameras,
            points,
            schur_nnz: pf.schur_nnz,
            bridges: pf.bridges,
            escapes: pf.escapes,
            model,
            outlier_points,
        }
    }
}

/// One frame's metric perspective camera: `x_cam = R X + t`, `w = π(K x_cam)`.
#[derive(Debug, Clone, Serialize)]
pub struct PerspectiveFrame {
    pub frame: Id,
    /// World-to-camera rotation (rows: the camera axes in world coordinates).
    pub rotation: [[f64; 3]; 3],
    /// World-to-camera translation.
    pub translation: [f64; 3],
    /// Camera centre `−Rᵀ t`, world coordinates.
    pub centre: [f64; 3],
    /// Focal length, pixels.
    pub focal_px: f64,
    /// RMS reprojection error of this frame's observations, pixels.
    pub rms_px: f64,
    pub n_observations: usize,
}

/// The intrinsics of a perspective reconstruction.
#[derive(Debug, Clone, Serialize)]
pub struct PerspectiveIntrinsics {
    /// `"shared"` (one focal length for the sequence), `"per-frame"` or `"given"`.
    pub focal: &'static str,
    /// The focal length (the median over frames when per frame), pixels.
    pub focal_px: f64,
    /// `K` (3×3) of the first frame, pixels.
    pub k: [[f64; 3]; 3],
    pub principal_point: [f64; 2],
    /// `"given"`, `"image centre"`, `"track bounding box"`, or `"estimated"`.
    pub principal_point_source: &'static str,
    /// A principal point estimate rejected as implausible (the principal point is then
    /// held where `principal_point_source` says); absent otherwise.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub principal_point_rejected: Option<perspective::RejectedPrincipalPoint>,
    /// Radial distortion `k₁` of normalised coordinates (0 when not estimated).
    pub k1: f64,
    /// Aspect ratio `f_x / f_y` (1: square pixels); `K₀₀ = aspect_ratio · focal_px`.
    pub aspect_ratio: f64,
    /// `"square pixels"`, `"estimated"`, or [`Reconstruction::aspect_ratio_source`] when
    /// the ratio was given, read or assumed ([`Config::aspect_ratio`]).
    pub aspect_ratio_source: String,
    pub image_size: Option<[u32; 2]>,
}

/// The metric perspective reconstruction ([`crate::perspective`]): world frame = the first
/// camera's, unit = RMS distance of the fitted points from their centroid.
#[derive(Debug, Clone, Serialize)]
pub struct PerspectiveResult {
    /// Reprojection RMS over the fit's observed scalars, pixels.
    pub rms_px: f64,
    pub intrinsics: PerspectiveIntrinsics,
    pub self_calibration: Option<perspective::SelfCalibration>,
    /// The starts of the metric adjustment that were screened, and which was kept.
    pub starts: Vec<perspective::StartReport>,
    pub stages: Vec<projective::StageReport>,
    pub cameras: Vec<PerspectiveFrame>,
    /// In the input's track order (fitted and outlier tracks, as `points`).
    pub points: Vec<PointResult>,
    /// Entries the robust loss down-weights below one half: `[frame, track]` ids.
    pub downweighted: Vec<(Id, Id)>,
    /// Fraction of observations in front of their camera.
    pub in_front: f64,
    /// How far the tracks are from what a camera only turning about its centre would see,
    /// pixels ([`perspective::planar::rotation_parallax_px`]): within
    /// [`ROTATION_ONLY_FACTOR`] times the RMS, the depths and the camera centres are not
    /// determined (a warning says so). `None` when not measured (the long-sequence path, or
    /// no pair of frames sharing 8 tracks).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rotation_parallax_px: Option<f64>,
    /// The fitted model (fit frames × fit tracks), for library users.
    #[serde(skip)]
    pub model: perspective::PerspectiveModel,
    /// Points of the outlier tracks given the fitted cameras.
    #[serde(skip)]
    pub outlier_points: Vec<Vector3<f64>>,
}

impl PerspectiveResult {
    #[allow(clippy::too_many_arguments)]
    fn new(
        pf: perspective::PerspectiveFit,
        cfg: &PerspectiveConfig,
        fit: &TrackTable,
        meas: &Measurements,
        outlier_meas: &Measurements,
        outlier_kept: &[usize],
        kept: &TrackTable,
        kept_tracks: &[usize],
        used_tracks: &[usize],
    ) -> Self {
        let model = &pf.model;
        let nf = model.rotations.len();
        let outlier_points: Vec<Vector3<f64>> = ProjectiveModel {
            cameras: (0..nf).map(|f| model.camera_matrix(f)).collect(),
            points: Vec::new(),
        }
        .triangulate(outlier_meas)
        .iter()
        .map(|x| Vector3::new(x[0] / x[3], x[1] / x[3], x[2] / x[3]))
        .collect();
        let fitted = |f: usize, p: usize| model.project(f, p);
        let outliers = |f: usize, k: usize| model.project_point(f, &outlier_points[k]);
        let (sums, outlier_sums) = (
            ResidualSums::new(&fitted, meas),
            ResidualSums::new(&outliers, outlier_meas),
        );
        let cameras = (0..nf)
            .map(|f| Self::frame(model, f, fit.frame_ids()[f].clone(), sums.frames[f]))
            .collect();
        let points = point_results(
            &TrackSets {
                fit,
                used_tracks,
                kept,
                kept_tracks,
                outlier_kept,
            },
            (&sums, |p| model.points[p]),
            (&outlier_sums, |k| outlier_points[k]),
        );
        let downweighted = pf
            .downweighted
            .iter()
            .map(|&(f, p)| (fit.frame_ids()[f].clone(), fit.track_ids()[p].clone()))
            .collect();
        Self::assemble(pf, cfg, cameras, points, downweighted, outlier_points)
    }

    /// Frame `f`'s block: its pose, focal length and residuals `(Σ r², observations)`.
    fn frame(
        model: &perspective::PerspectiveModel,
        f: usize,
        id: Id,
        res: (f64, usize),
    ) -> PerspectiveFrame {
        let r = model.rotations[f];
        let (t, c) = (model.translations[f], model.centre(f));
        PerspectiveFrame {
            frame: id,
            rotation: std::array::from_fn(|a| std::array::from_fn(|b| r[(a, b)])),
            translation: [t[0], t[1], t[2]],
            centre: [c[0], c[1], c[2]],
            focal_px: model.focal_px[f],
            rms_px: rms_of(res.0, res.1),
            n_observations: res.1,
        }
    }

    /// The result from its parts: the intrinsics block and the fit's reports.
    fn assemble(
        pf: perspective::PerspectiveFit,
        cfg: &PerspectiveConfig,
        cameras: Vec<PerspectiveFrame>,
        points: Vec<PointResult>,
        downweighted: Vec<(Id, Id)>,
        outlier_points: Vec<Vector3<f64>>,
    ) -> Self {
        let model = pf.model;
        let mut focals = model.focal_px.clone();
        focals.sort_by(f64::total_cmp);
        let k0 = model.k(0);
        let intrinsics = PerspectiveIntrinsics {
            focal: if cfg.intrinsics.focal_px.is_some() {
                "given"
            } else if cfg.per_frame_focal {
                "per-frame"
            } else {
                "shared"
            },
            focal_px: focals.get(focals.len() / 2).copied().unwrap_or(f64::NAN),
            k: std::array::from_fn(|a| std::array::from_fn(|b| k0[(a, b)])),
            principal_point: model.principal_point,
            principal_point_source: if pf.principal_point_estimated {
                "estimated"
            } else {
                pf.assumed.principal_point_source
            },
            principal_point_rejected: pf.principal_point_rejected.clone(),
            k1: model.k1,
            aspect_ratio: model.aspect,
            aspect_ratio_source: if cfg.estimate_aspect_ratio {
                "estimated"
            } else {
                SQUARE_PIXELS
            }
            .to_string(),
            image_size: cfg.intrinsics.image_size,
        };
        Self {
            rms_px: pf.rms_px,
            intrinsics,
            self_calibration: pf.selfcal,
            starts: pf.starts,
            stages: pf.stages,
            cameras,
            points,
            downweighted,
            in_front: pf.in_front,
            rotation_parallax_px: None,
            model,
            outlier_points,
        }
    }
}

impl PerspectiveResult {
    /// The result of the sparse path ([`perspective::fit_observations`] on the `inl`
    /// tracks of `kept`, renumbered `0..inl.len()`): per-frame and per-track residuals from
    /// the table's rows, the outlier tracks (`out`) triangulated from the fitted cameras.
    /// `O(observations)`.
    fn from_sparse(
        pf: perspective::PerspectiveFit,
        cfg: &PerspectiveConfig,
        kept: &TrackTable,
        inl: &[usize],
        out: &[usize],
    ) -> Self {
        let model = &pf.model;
        let nf = model.rotations.len();
        // Kept track → (inlier index | outlier index).
        let mut slot = vec![(usize::MAX, usize::MAX); kept.n_tracks()];
        for (j, &p) in inl.iter().enumerate() {
            slot[p].0 = j;
        }
        for (k, &p) in out.iter().enumerate() {
            slot[p].1 = k;
        }
        let outlier_obs = observations_of(kept, out);
        let outlier_points: Vec<Vector3<f64>> = ProjectiveModel {
            cameras: (0..nf).map(|f| model.camera_matrix(f)).collect(),
            points: Vec::new(),
        }
        .triangulate_observations(&outlier_obs, out.len())
        .unwrap_or_else(|_| vec![[f64::NAN; 4]; out.len()])
        .iter()
        .map(|x| Vector3::new(x[0] / x[3], x[1] / x[3], x[2] / x[3]))
        .collect();
        drop(outlier_obs);
        let (frame_ss, track_ss) = sparse_residuals(kept, &slot, nf, |f, j, k| {
            if j != usize::MAX {
                model.project(f, j)
            } else {
                model.project_point(f, &outlier_points[k])
            }
        });
        let cameras = (0..nf)
            .map(|f| Self::frame(model, f, kept.frame_ids()[f].clone(), frame_ss[f]))
            .collect();
        let points = (0..kept.n_tracks())
            .map(|p| {
                let (j, k) = slot[p];
                let x = if j != usize::MAX {
                    model.points[j]
                } else {
                    outlier_points[k]
                };
                PointResult {
                    track: kept.track_ids()[p].clone(),
                    xyz: [x[0], x[1], x[2]],
                    inlier: j != usize::MAX,
                    rms_px: rms_of(track_ss[p].0, track_ss[p].1),
                    n_observations: track_ss[p].1,
                }
            })
            .collect();
        let downweighted = pf
            .downweighted
            .iter()
            .map(|&(f, j)| {
                (
                    kept.frame_ids()[f].clone(),
                    kept.track_ids()[inl[j]].clone(),
                )
            })
            .collect();
        Self::assemble(pf, cfg, cameras, points, downweighted, outlier_points)
    }
}

/// Squared reprojection errors of a sparse fit, summed per frame over the fitted tracks and
/// per track over all its observations: `(Σ d², count)` each. `slot[p]` is the kept track's
/// (inlier index, outlier index), `usize::MAX` where it has none; `project(f, j, k)` predicts
/// it in frame `f`. `O(observations)`.
#[allow(clippy::type_complexity)]
fn sparse_residuals(
    kept: &TrackTable,
    slot: &[(usize, usize)],
    nf: usize,
    project: impl Fn(usize, usize, usize) -> [f64; 2],
) -> (Vec<(f64, usize)>, Vec<(f64, usize)>) {
    let mut frame_ss = vec![(0.0, 0usize); nf];
    let mut track_ss = vec![(0.0, 0usize); kept.n_tracks()];
    for (f, fs) in frame_ss.iter_mut().enumerate() {
        for e in kept.frame_row(f).entries() {
            let p = e.track as usize;
            let (j, k) = slot[p];
            let q = project(f, j, k);
            let d2 = (q[0] - e.x).powi(2) + (q[1] - e.y).powi(2);
            if d2.is_finite() {
                track_ss[p].0 += d2;
                track_ss[p].1 += 1;
                if j != usize::MAX {
                    fs.0 += d2;
                    fs.1 += 1;
                }
            }
        }
    }
    (frame_ss, track_ss)
}

/// The result's RMS: the perspective camera's when it was chosen, else the projective
/// camera's, else the metric (affine-camera) model's.
fn result_rms(
    perspective: Option<&PerspectiveResult>,
    projective: Option<&ProjectiveResult>,
    metric_rms_px: f64,
) -> f64 {
    match (perspective, projective) {
        (Some(p), _) => p.rms_px,
        (None, Some(p)) => p.rms_px,
        _ => metric_rms_px,
    }
}

/// The observations of `kept`'s tracks `tracks` as a list for the sparse solvers, track
/// `tracks[j]` renumbered `j`, frames as in `kept`. `O(observations)`.
fn observations_of(kept: &TrackTable, tracks: &[usize]) -> Vec<projective::Observation> {
    let mut slot = vec![usize::MAX; kept.n_tracks()];
    for (j, &p) in tracks.iter().enumerate() {
        slot[p] = j;
    }
    (0..kept.n_frames())
        .flat_map(|f| {
            let slot = &slot;
            kept.frame_row(f)
                .entries()
                .iter()
                .filter(move |e| slot[e.track as usize] != usize::MAX)
                .map(move |e| projective::Observation {
                    frame: f,
                    track: slot[e.track as usize],
                    xy: [e.x, e.y],
                })
        })
        .collect()
}

/// The automatic choice between the scaled orthographic and the perspective camera.
///
/// Both are fitted to the same observations (`n` scalars). With `SS_a`, `SS_p` their sums
/// of squared residuals and the noise variance estimated from the perspective fit,
/// `σ² = SS_p / (n − k_p)` (`k_p = 6F + 3N + 1 − 7` parameters: poses, points, focal length,
/// minus the similarity gauge), the perspective camera is kept when
///
/// ```text
///   Δχ² = (SS_a − SS_p) / σ²  >  ln n,
/// ```
///
/// the Bayesian information criterion for its one extra parameter (the scaled orthographic
/// camera has 6 per frame, as the perspective pose; the focal length is the difference;
/// Schwarz 1978). A perspective fit that failed keeps the affine camera.
///
/// Before that, the projective fit (made anyway) is tested the same way with its `5F − 8`
/// extra parameters (`11F + 3N − 15` against `6F + 3N − 7`): when
/// `(SS_a − SS_proj)/σ² ≤ (5F − 8) ln n` (σ² from the projective fit) no camera with
/// perspective can explain the tracks significantly better, and the perspective stages are
/// skipped. This saves their cost on affine-looking data, where the focal length of a
/// perspective fit runs off to infinity (the weak-perspective limit) and its adjustment
/// crawls along that valley.
#[derive(Debug, Clone, Serialize)]
pub struct ModelSelection {
    pub chosen: CameraModel,
    pub affine_rms_px: f64,
    pub perspective_rms_px: Option<f64>,
    pub perspective_focal_px: Option<f64>,
    /// `σ` estimated from the perspective fit, pixels.
    pub noise_sigma_px: f64,
    pub delta_chi2: f64,
    /// `ln n`.
    pub threshold: f64,
    pub reason: String,
}

impl ModelSelection {
    /// The scaled orthographic camera kept by a pre-test on parts of the table
    /// ([`part_pretest`]): `(Δχ², threshold, affine RMS, projective RMS)` over the parts,
    /// which `parts` describes.
    fn affine_by_parts(
        (delta, threshold, affine_rms, projective_rms): (f64, f64, f64, f64),
        parts: &str,
    ) -> Self {
        Self {
            chosen: CameraModel::ScaledOrthographic,
            affine_rms_px: affine_rms,
            perspective_rms_px: None,
            perspective_focal_px: None,
            noise_sigma_px: f64::NAN,
            delta_chi2: delta,
            threshold,
            reason: format!(
                "scaled orthographic (no significant perspective) — on {parts} the projective \
                 camera's RMS {projective_rms:.4} px vs {affine_rms:.4} px for the affine camera \
                 fitted to the same observations: Δχ² = {delta:.1} ≤ Σ 2 (3F − 3) = \
                 {threshold:.1}; the perspective stages were skipped"
            ),
        }
    }

    /// The projective pre-test (see the type's documentation); `chosen` is perspective
    /// when the test passes (the perspective stages then decide).
    fn pretest(
        affine_rms: f64,
        projective_rms: f64,
        n_obs: usize,
        n_frames: usize,
        n_points: usize,
    ) -> Self {
        let n = (2 * n_obs) as f64;
        let extra = (5 * n_frames).saturating_sub(8).max(1) as f64;
        let threshold = extra * n.max(1.0).ln();
        let k = projective::degrees_of_freedom(n_frames, n_points);
        let (delta, sigma2) = crate::robust::delta_chi2(affine_rms, projective_rms, n, k);
        let perspective = delta > threshold;
        Self {
            chosen: if perspective {
                CameraModel::Perspective
            } else {
                CameraModel::ScaledOrthographic
            },
            affine_rms_px: affine_rms,
            perspective_rms_px: None,
            perspective_focal_px: None,
            noise_sigma_px: sigma2.sqrt(),
            delta_chi2: delta,
            threshold,
            reason: format!(
                "scaled orthographic (no significant perspective) — the projective camera's \
                 RMS {projective_rms:.4} px vs {affine_rms:.4} px: Δχ² = {delta:.1} ≤ (5F − 8) \
                 ln n = {threshold:.1} (σ ≈ {:.3} px); the perspective stages were skipped",
                sigma2.sqrt()
            ),
        }
    }

    fn judge(
        affine_rms: f64,
        persp: Option<&PerspectiveResult>,
        n_obs: usize,
        n_frames: usize,
        n_points: usize,
    ) -> Self {
        let n = (2 * n_obs) as f64;
        let threshold = n.max(1.0).ln();
        let Some(p) = persp else {
            return Self {
                chosen: CameraModel::ScaledOrthographic,
                affine_rms_px: affine_rms,
                perspective_rms_px: None,
                perspective_focal_px: None,
                noise_sigma_px: f64::NAN,
                delta_chi2: f64::NAN,
                threshold,
                reason: "scaled orthographic (the perspective camera could not be tried or \
                         fitted; the warnings say why)"
                    .into(),
            };
        };
        let k = 6 * n_frames + 3 * n_points + 1;
        let (delta, sigma2) =
            crate::robust::delta_chi2(affine_rms, p.rms_px, n, k.saturating_sub(7));
        let perspective = delta > threshold;
        let reason = format!(
            "{} — perspective RMS {:.4} px (focal {:.0} px) vs scaled orthographic {:.4} px; \
             Δχ² = {:.1} {} ln n = {:.1} (σ ≈ {:.3} px)",
            if perspective {
                "perspective"
            } else {
                "scaled orthographic (no significant perspective)"
            },
            p.rms_px,
            p.intrinsics.focal_px,
            affine_rms,
            delta,
            if perspective { ">" } else { "≤" },
            threshold,
            sigma2.sqrt()
        );
        Self {
            chosen: if perspective {
                CameraModel::Perspective
            } else {
                CameraModel::ScaledOrthographic
            },
            affine_rms_px: affine_rms,
            perspective_rms_px: Some(p.rms_px),
            perspective_focal_px: Some(p.intrinsics.focal_px),
            noise_sigma_px: sigma2.sqrt(),
            delta_chi2: delta,
            threshold,
            reason,
        }
    }
}

/// Input summary.
#[derive(Debug, Clone, Serialize)]
pub struct InputSummary {
    pub frames: usize,
    pub tracks: usize,
    pub observations: usize,
    pub fill: f64,
    pub frames_used: usize,
    pub tracks_used: usize,
}

/// Wall-clock time of a stage.
#[derive(Debug, Clone, Serialize)]
pub struct StageTime {
    pub stage: String,
    pub seconds: f64,
}

/// A metric reconstruction. [`Reconstruction::to_json`] writes it as `reconstruction.json`
/// (its fields after a `schema` key); [`crate::reconstruction_file`] reads that back.
#[derive(Debug, Clone, Serialize)]
pub struct Reconstruction {
    /// The camera model of the result (with [`CameraModel::Auto`], the one chosen).
    pub camera_model: CameraModel,
    /// With [`CameraModel::Auto`]: which camera was kept and why.
    pub model_selection: Option<ModelSelection>,
    pub frames: Vec<FrameResult>,
    pub points: Vec<PointResult>,
    /// `sqrt(Σ_observed r² / #observed scalars)` of the final model, pixels: the projective
    /// model's with the projective camera, the metric model's otherwise.
    pub rms_px: f64,
    /// The same RMS of the metric (affine-family) model in `frames` / `points`, pixels.
    pub metric_rms_px: f64,
    pub metric_upgrade: MetricUpgrade,
    /// Every singular value the factorization computed, descending.
    pub singular_values: Vec<f64>,
    /// σ4/σ3 of the centred measurement matrix: of all tracks for complete data, else of
    /// the largest complete block (consecutive frames × the tracks seen in all of them);
    /// NaN when no block of 2 frames × 4 tracks exists.
    pub rank_ratio: f64,
    /// What `rank_ratio` was computed on.
    pub rank_ratio_source: String,
    pub factorization: FactorizationReport,
    /// Present when the table had missing entries.
    pub completion: Option<CompletionReport>,
    /// Present when the robust pass ran.
    pub robust: Option<RobustReport>,
    pub refinement: Option<RefinementReport>,
    /// Present with the projective and perspective cameras: `P_f`, `X_p` and the stages'
    /// reports. `frames` and `points` then hold the scaled-orthographic model the
    /// projective stages start from.
    pub projective: Option<ProjectiveResult>,
    /// Present with the perspective camera: intrinsics, poses, Euclidean points.
    pub perspective: Option<PerspectiveResult>,
    pub input: InputSummary,
    /// Tracks and frames not used, with reasons.
    pub set_aside: Vec<SetAside>,
    /// Whether the depth-reversal convention mirrored the solution.
    pub mirrored: bool,
    pub warnings: Vec<String>,
    pub timings: Vec<StageTime>,
    /// Present when the sparse pipeline ran ([`crate::sparse`]): the table's dense matrix
    /// did not fit, it is a long sequence of short tracks, or it was asked for. The
    /// dense-only stages (RANSAC robust pass, σ4/σ3, refinement, the projective camera,
    /// completed.txt) did not run; the perspective camera runs on the sparse path
    /// ([`crate::perspective::fit_observations`]).
    pub sparse: Option<crate::sparse::SparseReport>,
    /// Present when the streaming factorization ran ([`crate::stream`], `reconstruct
    /// --stream`): complete tracks read in passes, `W` never held whole. The RANSAC robust
    /// pass, the refinement and the projective cameras did not run.
    pub stream: Option<crate::stream::StreamReport>,
    /// Present when a textured surface was built ([`crate::mesh`]; `rank3 run`, or
    /// `reconstruct --images`): its triangulation, texture and timing report.
    pub mesh: Option<crate::mesh::MeshReport>,
    /// Aspect ratio of the pixels, `f_x / f_y` ([`Config::aspect_ratio`]; 1 = square). The
    /// affine-family cameras project `x = aspect_ratio · scale · rotation[0] · xyz +
    /// translation[0]`, `y = scale · rotation[1] · xyz + translation[1]`; the perspective
    /// intrinsics carry it too. Residuals are in square pixels of the pixel height.
    pub aspect_ratio: f64,
    /// Where the aspect ratio came from: `"square pixels"` (nothing known), `"given"`, or
    /// what [`crate::pixel_aspect`] read or assumed ([`Config::aspect_ratio_source`]).
    pub aspect_ratio_source: String,
    /// The metric model (kept frames × kept tracks), for library users.
    #[serde(skip)]
    pub model: MetricModel,
    /// The affine structure `Ŝ` (3×N', one column per kept track) before the metric upgrade.
    #[serde(skip)]
    pub affine_structure: Mat<f64>,
    /// Affine prediction `M̂Ŝ + t1ᵀ` of every kept frame and track (2F'×N'), entry by entry.
    #[serde(skip)]
    pub affine_prediction: AffinePrediction,
    /// Affine prediction of the outlier tracks in the used frames (2F'×n_outliers).
    #[serde(skip)]
    pub outlier_prediction: Mat<f64>,
    /// The fitted cameras with the outlier tracks' points (triangulated, not refined).
    #[serde(skip)]
    pub outlier_model: MetricModel,
    /// Indices into the input table of the frames and tracks the fit used.
    #[serde(skip)]
    pub kept_frames: Vec<usize>,
    #[serde(skip)]
    pub kept_tracks: Vec<usize>,
    /// Indices into the input table of the outlier tracks.
    #[serde(skip)]
    pub outlier_tracks: Vec<usize>,
    /// Input frame and track ids (for writing outputs in the input's order).
    #[serde(skip)]
    pub input_frame_ids: Vec<Id>,
    #[serde(skip)]
    pub input_track_ids: Vec<Id>,
}

/// The affine factorization `W ≈ M̂Ŝ + t1ᵀ` that the metric upgrade starts from.
struct Affine {
    m_hat: Mat<f64>,
    s_hat: Mat<f64>,
    t: Vec<f64>,
    singular_values: Vec<f64>,
    report: FactorizationReport,
}

/// Forwards events and records the best inlier count of each main RANSAC iteration
/// (`Event::Iteration` of solver `"ransac"`, run 0, whose `lambda` carries that count).
struct InlierCapture<'a, 'b> {
    inner: &'a mut dyn Observer,
    counts: &'b mut Vec<usize>,
}

impl Observer for InlierCapture<'_, '_> {
    fn on_event(&mut self, event: &Event<'_>) {
        if let Event::Iteration {
            solver: "ransac",
            run: 0,
            lambda,
            ..
        } = event
        {
            self.counts.push(*lambda as usize);
        }
        self.inner.on_event(event);
    }
}

struct Timer<'a> {
    observer: &'a mut dyn Observer,
    timings: Vec<StageTime>,
}

impl Timer<'_> {
    fn run<T>(&mut self, stage: &'static str, f: impl FnOnce(&mut dyn Observer) -> T) -> T {
        self.observer.on_event(&Event::StageStarted { stage });
        let t0 = Instant::now();
        let out = f(&mut *self.observer);
        let seconds = t0.elapsed().as_secs_f64();
        self.observer
            .on_event(&Event::StageFinished { stage, seconds });
        self.timings.push(StageTime {
            stage: stage.to_string(),
            seconds,
        });
        out
    }
}

impl Reconstruction {
    /// Runs the pipeline on a track table. See the module documentation.
    pub fn from_tracks(table: &TrackTable, config: &Config) -> Result<Reconstruction> {
        Self::from_tracks_observed(table, config, &mut NoopObserver)
    }

    /// [`Reconstruction::from_tracks`] with progress reported to `observer`.
    pub fn from_tracks_observed(
        table: &TrackTable,
        config: &Config,
        observer: &mut dyn Observer,
    ) -> Result<Reconstruction> {
        validate_config(config)?;
        let mut timer = Timer {
            observer,
            timings: Vec::new(),
        };
        let mut warnings = Vec::new();

        // 1. Set-aside: tracks seen in too few frames, frames with too few tracks. An affine
        //    camera (2×4) needs 4 points per frame when it is estimated jointly with the
        //    translation (missing data); centering needs only 3.
        let min_points = min_points_per_frame(config, table);
        let (kept_cow, set_aside, frames, tracks) = timer.run("set-aside", |_| {
            table.set_aside_cow(config.min_frames_per_track, min_points)
        });
        check_size(&kept_cow)?;
        // Degenerate input is named before the robust pass; the image origin is moved to the
        // centroid of the observations (x also divided by the aspect ratio), and the results
        // are moved back at the end. The kept table is copied once, moved as it is copied.
        let check = degeneracy::check(&kept_cow)?;
        warnings.extend(check.warnings);
        let origin = check.origin;
        let aspect = config.aspect_ratio.unwrap_or(1.0);
        let (shift, scale) = ([-origin[0], -origin[1]], [1.0 / aspect, 1.0]);
        let kept_table = match kept_cow {
            std::borrow::Cow::Borrowed(t) => t.transformed(shift, scale),
            std::borrow::Cow::Owned(mut t) => {
                t.transform(shift, scale);
                t
            }
        };
        let (centred_config, pp_from_image_size) = centred_config(config, origin, aspect);
        let config = centred_config.as_ref().unwrap_or(config);
        let kept = Kept {
            table: &kept_table,
            frames,
            tracks,
            set_aside,
            origin,
        };
        // Long or sparse tables take the sparse pipeline.
        if let Some(reason) = sparse_reason(&kept_table, config)? {
            let mut rec = sparse_reconstruction(table, kept, config, timer, reason, warnings)?;
            restore_image_frame(&mut rec, origin, config, pp_from_image_size);
            warn_rejected_principal_point(&mut rec);
            return Ok(rec);
        }
        // 2. Robust pass (affine): outlier tracks, gross entries, other rigid objects.
        let (mut selection, table_meas) = robust_stage(&kept, config, &mut timer, &mut warnings)?;
        // 3. Fit of the selected tracks: affine factorization, metric upgrade, refinement,
        //    and the projective stages for the projective and perspective cameras.
        let mut fitted = fit_selection(&kept, &selection, config, None, table_meas, &mut timer)?;
        // 4. The projective model judges the tracks again (not when the automatic choice's
        //    pre-test on a subset already kept the scaled orthographic camera).
        if config.camera.is_projective() && fitted.projective.is_some() {
            fitted = projective_verdict_stage(
                &kept,
                &mut selection,
                fitted,
                config,
                &mut timer,
                &mut warnings,
            )?;
        }
        if let Some(r) = &selection.report
            && (r.n_outlier_tracks > 0 || r.n_flagged_entries > 0)
        {
            warnings.push(format!(
                "robust pass: {} outlier track(s) and {} gross entr{} excluded from the fit",
                r.n_outlier_tracks,
                r.n_flagged_entries,
                if r.n_flagged_entries == 1 { "y" } else { "ies" }
            ));
        }
        // Tracks and frames the selection starved, and the fit's warnings.
        let mut kept = kept;
        kept.set_aside.append(&mut fitted.set_aside);
        warnings.extend(set_aside_warning(&kept.set_aside));
        warnings.append(&mut fitted.warnings);
        // 5. The outlier tracks given the fitted cameras (for display and completed.txt).
        let outliers = OutlierTracks::of(&kept_table, &fitted);
        // 6. The camera model: the perspective stages, and the automatic choice.
        let choice = camera_stage(
            &kept,
            &mut fitted,
            &outliers,
            config,
            &mut timer,
            &mut warnings,
        )?;
        // 7. The result, in the input's image coordinates.
        let mut rec = assemble(
            table, kept, selection, fitted, outliers, choice, timer, warnings,
        );
        restore_image_frame(&mut rec, origin, config, pp_from_image_size);
        warn_rejected_principal_point(&mut rec);
        Ok(rec)
    }

    /// The fit's prediction laid out like the input table (2F×N in the input's frame and
    /// track order); rows/columns of set-aside frames/tracks are NaN. With the projective
    /// camera it is `π(P_f X_p)`, otherwise the affine prediction `M̂Ŝ + t1ᵀ`. Outlier
    /// tracks are predicted from their own observations given the fitted cameras.
    ///
    /// A sparse-pipeline reconstruction ([`Reconstruction::sparse`]) has no affine
    /// prediction: its matrix holds the metric model's. `O(F·N)` memory either way;
    /// [`Self::completed_value`] gives its entries without it.
    pub fn completed_matrix(&self) -> Mat<f64> {
        let value = self.completed_value();
        Mat::from_fn(
            2 * self.input_frame_ids.len(),
            self.input_track_ids.len(),
            value,
        )
    }

    /// Entry `(r, c)` of [`Self::completed_matrix`], computed on demand (`O(F + N)` memory
    /// for the index maps; each entry costs one projection).
    pub fn completed_value(&self) -> impl Fn(usize, usize) -> f64 + Sync + '_ {
        /// What an input track is in the fit.
        #[derive(Clone, Copy)]
        enum Track {
            SetAside,
            Kept(usize),
            Outlier(usize),
        }
        let mut frame_pos = vec![None; self.input_frame_ids.len()];
        for (kf, &fi) in self.kept_frames.iter().enumerate() {
            frame_pos[fi] = Some(kf);
        }
        let mut track_pos = vec![Track::SetAside; self.input_track_ids.len()];
        for (kp, &pi) in self.kept_tracks.iter().enumerate() {
            track_pos[pi] = Track::Kept(kp);
        }
        for (k, &pi) in self.outlier_tracks.iter().enumerate() {
            track_pos[pi] = Track::Outlier(k);
        }
        let v2 = |v: nalgebra::Vector2<f64>| [v[0], v[1]];
        // The prediction of kept track `kp` (or outlier `k`) in kept frame `kf`.
        let kept = move |kf: usize, kp: usize| -> [f64; 2] {
            if self.sparse.is_some() {
                v2(self.model.project(kf, kp))
            } else if let Some(pr) = &self.perspective {
                pr.model.project(kf, kp)
            } else if let Some(pr) = &self.projective {
                pr.model.project(kf, kp)
            } else {
                let a = &self.affine_prediction;
                [a.value(2 * kf, kp), a.value(2 * kf + 1, kp)]
            }
        };
        let outlier = move |kf: usize, k: usize| -> [f64; 2] {
            if self.sparse.is_some() {
                v2(self.outlier_model.project(kf, k))
            } else if let Some(pr) = &self.perspective {
                pr.model.project_point(kf, &pr.outlier_points[k])
            } else if let Some(pr) = &self.projective {
                projective::project(&pr.model.cameras[kf], &pr.outlier_points[k])
            } else {
                let o = &self.outlier_prediction;
                [o[(2 * kf, k)], o[(2 * kf + 1, k)]]
            }
        };
        move |r, c| {
            let Some(kf) = frame_pos[r / 2] else {
                return f64::NAN;
            };
            let q = match track_pos[c] {
                Track::SetAside => return f64::NAN,
                Track::Kept(kp) => kept(kf, kp),
                Track::Outlier(k) => outlier(kf, k),
            };
            q[r % 2]
        }
    }

    /// Serializes to the `reconstruction.json` document: `"schema"`
    /// ([`crate::reconstruction_file::SCHEMA`]) first, then this struct's fields. Read it
    /// back with [`crate::reconstruction_file::read`].
    pub fn to_json(&self) -> String {
        #[derive(Serialize)]
        struct Document<'a> {
            schema: &'static str,
            #[serde(flatten)]
            reconstruction: &'a Reconstruction,
        }
        let doc = Document {
            schema: crate::reconstruction_file::SCHEMA,
            reconstruction: self,
        };
        serde_json::to_string_pretty(&doc).unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"))
    }
}

/// What [`fit_selection`] produced: the fit table and every model fitted to it.
/// The tracks the fit uses and why: the robust pass's verdict (affine, then the projective
/// model's) as the stages refine it.
struct Selection {
    /// Per kept track: used by the fit.
    inlier: Vec<bool>,
    /// Gross entries (frame, track) of the kept table, hidden from the fit.
    flagged: Vec<(usize, usize)>,
    /// Other rigid objects the affine pass found (tracks of the kept table).
    other_groups: Vec<crate::segment::OtherObject>,
    /// `None` when the robust pass is off.
    report: Option<RobustReport>,
}

impl Selection {
    /// From a selection of the tracks `bodies.keep` (indices into them) to one of the
    /// kept table's tracks: the other bodies' tracks rejected, their groups first in
    /// `other_groups`.
    fn lift(&mut self, bodies: &OtherBodies) {
        let keep = &bodies.keep;
        let mut inlier = vec![false; bodies.n_tracks];
        for (i, &p) in keep.iter().enumerate() {
            inlier[p] = self.inlier[i];
        }
        self.inlier = inlier;
        // `keep` increases: the entries' order is kept.
        self.flagged.iter_mut().for_each(|e| e.1 = keep[e.1]);
        for g in &mut self.other_groups {
            g.tracks.iter_mut().for_each(|p| *p = keep[*p]);
        }
        self.other_groups
            .splice(0..0, bodies.groups.iter().cloned());
    }
}

/// Rigid bodies besides the scene, found by segmenting the kept tracks before the robust
/// pass ([`other_bodies`]).
struct OtherBodies {
    /// The tracks the robust pass judges (increasing): the largest group's, and those no
    /// group holds (outliers, tracks too short to be scored).
    keep: Vec<usize>,
    /// The other groups, largest first.
    groups: Vec<crate::segment::OtherObject>,
    /// The tracks the segmentation labelled outliers (in `keep`; increasing).
    outliers: Vec<usize>,
    /// Number of kept tracks.
    n_tracks: usize,
}

impl OtherBodies {
    /// Tracks of the other bodies.
    fn n_other_tracks(&self) -> usize {
        self.groups.iter().map(|g| g.tracks.len()).sum()
    }
}

/// The kept tracks' rigid bodies ([`crate::segment::segment_table_sampled`], the number of
/// groups found, [`crate::segment::Objects::Auto`]; on a large table a sample of the tracks
/// segmented, the robust pass's `suspect`s preferred, and the others labelled against its
/// groups: [`crate::segment::search_sample`]). The largest group is the scene; the
/// others are judged against the scene's subspace
/// ([`crate::segment::other_objects_among`]; a member the scene explains as well stays with
/// the scene), and the bodies found are those whose
/// tracks the robust pass rejects whole, whatever part of them the scene's cameras happen
/// to explain (a second body was before kept in part with entries flagged as gross errors
/// one by one: Hopkins `2RT3RC_g12`, 173 entries on its other bodies' tracks; or the robust
/// pass's consensus settled on the smaller body, `truck1`; docs/results.md). `None` with
/// fewer than two groups, groups less separated than
/// [`crate::segment::SegmentConfig::split_separation`] (the median `r_other / r_own` of the
/// least separated pair), no group that passes the judgement, fewer tracks than two groups
/// need, or a table segmented window by window (a long sequence of short tracks: the robust
/// pass's own search for other objects then runs alone, as its cost follows the
/// observations). Its own RNG (from `config.seed`), so that the robust pass's draws do not
/// change when no other body is found. Cost: the segmentation's ([`crate::segment`]), plus
/// that of [`crate::segment::other_objects_among`] on the tracks outside the scene's group;
/// a failed segmentation (too few tracks to score) is no body. `noise_sigma_px` is the
/// robust pass's σ, which bounds a rigid group's noise when it is below the
/// segmentation's own σ of the scene (inflated by the scene's gross entries).
fn other_bodies(
    table: &TrackTable,
    meas: &Measurements,
    config: &Config,
    suspect: &[bool],
    noise_sigma_px: f64,
) -> Option<OtherBodies> {
    let cfg = crate::segment::SegmentConfig {
        image_area: config
            .perspective
            .intrinsics
            .image_size
            .map(|[w, h]| w as f64 * h as f64),
        // No perspective merge test: its fits were most of the cost (the dinosaur: 0.1 s
        // without them, up to 2.3 s with), and the separation rule below leaves the pieces
        // it would join to the robust pass.
        merge_ratio: 0.0,
        ..Default::default()
    };
    let n = table.n_tracks();
    if n < 2 * cfg.min_group_tracks {
        return None;
    }
    let mut rng = rand::rngs::StdRng::seed_from_u64(config.seed ^ 0x00b0_d1e5);
    // On a large table a sample is segmented, the other tracks labelled against its groups.
    let sample = crate::segment::search_sample(
        &(0..n).collect::<Vec<_>>(),
        |p| table.track_len(p),
        |p| suspect.get(p).is_some_and(|&b| b),
        &mut rng,
    );
    let seg = crate::segment::segment_table_sampled(table, &sample, &cfg, &mut rng)
        .ok()
        .flatten()?;
    // Groups told apart only weakly are pieces of one body seen in perspective, which the
    // affine subspaces cut (the dinosaur, one rigid body: 2 or 3 groups by the seed, least
    // separated pair 4.5–7.1; every true split of the Hopkins files ≥ 12.1, docs/results.md).
    // They are left to the robust pass, which judges them with the scene's own cameras.
    if seg.objects.len() < 2 || !seg.separation.is_some_and(|q| q >= cfg.split_separation) {
        return None;
    }
    // Each other group is then judged against the scene's subspace as the search after the
    // pass judges the groups it finds ([`crate::segment::other_objects_among`]: the
    // likelihood ratio of the two models, a group noisier than a rigid body by its rigid
    // consensus, and the tracks an object explains better than the scene joining it): a
    // group of the scene's tracks that carry gross entries, with a few junk tracks, is no
    // body; a member the scene explains as well stays with the scene, for the pass to judge.
    let scene = &seg.objects[0];
    let search = crate::segment::SegmentConfig::default();
    // The scene's noise bounds a rigid group's (`max_group_sigma_ratio`): the robust pass's
    // estimate from its inlier entries when it has one, as the search after the pass uses.
    // The segmentation's own σ of the scene is an RMS over whole tracks, which the scene's
    // gross entries inflate (a 300 × 3000 table with 2 % of them: 7.2 px against the pass's
    // 0.51), and a group of sliding tracks and random walks at 13 px then passed as a body.
    let noise = if noise_sigma_px.is_finite() && noise_sigma_px > 0.0 {
        scene.sigma.min(noise_sigma_px)
    } else {
        scene.sigma
    };
    let groups = crate::segment::other_objects_among(
        meas,
        &scene.model,
        noise,
        &seg.objects[1..],
        &search,
        &mut rng,
    )
    .ok()?;
    if groups.is_empty() {
        return None;
    }
    let mut other = vec![false; n];
    groups
        .iter()
        .flat_map(|g| &g.tracks)
        .for_each(|&p| other[p] = true);
    Some(OtherBodies {
        keep: (0..n).filter(|&p| !other[p]).collect(),
        groups,
        outliers: (0..n)
            .filter(|&p| !other[p] && seg.labels[p] == crate::segment::Label::Outlier)
            .collect(),
        n_tracks: n,
    })
}

/// The least median `r_scene / r_own` over a group's tracks for the search after the pass
/// to count it as another object when the other-bodies segmentation found bodies first and
/// the pass on the scene's tracks still shows the signs of one. Between the scene's own
/// model error (Hopkins `cars3`: 1.72) and the second objects of synthetic tables with
/// mixed outliers (6.6–8.5), near their geometric mean; measured on those four cases only
/// (docs/results.md, 2026-12-02).
const BODIES_THEN_SEARCH_SEPARATION: f64 = 3.5;

/// The selection when other bodies were found ([`other_bodies`]) but the robust pass could
/// not judge the scene's tracks (too few of them, or no non-degenerate sample: a scene
/// moving in a plane, Hopkins `1R2RC_g23`): the other bodies' tracks and those the
/// segmentation labelled outliers are rejected whole, the scene's are all kept, and the
/// report says so (its noise and thresholds are NaN: nothing estimated them).
fn bodies_only(
    sel: Selection,
    bodies: &OtherBodies,
    kept: &Kept<'_>,
    iterations: usize,
    counts: Vec<usize>,
    t0: Instant,
) -> Selection {
    let mut sel = sel;
    sel.lift(bodies);
    bodies.outliers.iter().for_each(|&p| sel.inlier[p] = false);
    sel.report = Some(RobustReport::of_selection(
        kept,
        &sel,
        [f64::NAN; 3],
        iterations,
        counts,
        bodies.n_other_tracks(),
        t0,
    ));
    sel
}

impl RobustReport {
    /// The report of the selection `sel` of the kept tracks: `[σ, τ, entry threshold]` of
    /// the pass, its iterations and inliers per iteration, the other objects' tracks.
    fn of_selection(
        kept: &Kept<'_>,
        sel: &Selection,
        [noise_sigma_px, threshold_px, entry_threshold_px]: [f64; 3],
        iterations: usize,
        counts: Vec<usize>,
        other_object_tracks: usize,
        t0: Instant,
    ) -> Self {
        let mut report = RobustReport {
            outlier_tracks: Vec::new(),
            flagged_entries: Vec::new(),
            n_inlier_tracks: 0,
            n_outlier_tracks: 0,
            n_flagged_entries: 0,
            noise_sigma_px,
            threshold_px,
            entry_threshold_px,
            iterations,
            projective: None,
            inliers_per_iteration: counts,
            flagged_indices: Vec::new(),
            rigid_groups_seen: 1 + sel.other_groups.len(),
            other_object_tracks,
            seconds: t0.elapsed().as_secs_f64(),
        };
        report.update(
            kept.table,
            &kept.frames,
            &kept.tracks,
            &sel.inlier,
            &sel.flagged,
        );
        report
    }
}

/// Stage 2, the affine robust pass ([`crate::robust`]): RANSAC over rigid hypotheses, the
/// trimmed track test and the gross-entry flags. When the pass leaves a sign of another
/// body (no rigid majority, or two groups' worth of tracks rejected, flagged or kept only
/// by the floor) and the kept tracks segment into several rigid bodies
/// ([`other_bodies`]), the pass runs again on the scene's tracks only and the other bodies'
/// tracks are rejected whole (a scene the pass cannot judge — no non-degenerate sample — is
/// kept whole: [`bodies_only`]). Otherwise, or when that second pass still shows a sign of
/// another body (its groups then held to [`BODIES_THEN_SEARCH_SEPARATION`]), other rigid
/// objects are searched for after the pass, among the rejected tracks and those with an
/// ambiguous flag
/// ([`crate::segment::other_objects`]), and among all the kept tracks when many pass the
/// track test only by its floor, and rejected whole. Without a rigid majority the affine
/// cameras stop ([`Error::NoRigidMajority`]); the projective ones go on with every track,
/// for the projective verdict to judge. Cost: the robust pass's ([`crate::robust`]); with
/// signs of another body, plus the segmentation's ([`crate::segment`]) and, with bodies
/// found, a second pass on the scene's tracks. Also returns the kept table's dense
/// measurements, which the pass builds, for the fit to reuse when it keeps the whole table.
fn robust_stage(
    kept: &Kept<'_>,
    config: &Config,
    timer: &mut Timer<'_>,
    warnings: &mut Vec<String>,
) -> Result<(Selection, Option<Measurements>)> {
    let n = kept.table.n_tracks();
    let mut sel = Selection {
        inlier: vec![true; n],
        flagged: Vec::new(),
        other_groups: Vec::new(),
        report: None,
    };
    let Some(rc) = &config.robust else {
        return Ok((sel, None));
    };
    let meas_all = kept.table.measurements();
    let t0 = Instant::now();
    let pass = |meas: &Measurements, counts: &mut Vec<usize>, timer: &mut Timer<'_>| {
        let mut rng = rand::rngs::StdRng::seed_from_u64(config.seed);
        counts.clear();
        let r = timer.run("robust", |obs| {
            let mut capture = InlierCapture { inner: obs, counts };
            robust::robust_filter_observed(meas, rc, &mut rng, &mut capture)
        });
        // The search for other objects after the pass draws on from where it stopped.
        (r, rng)
    };
    let mut counts = Vec::new();
    let (r_all, rng_all) = pass(&meas_all, &mut counts, timer);
    // Other rigid bodies: when the pass over every track leaves a sign of one (no rigid
    // majority, or at least two groups' worth of tracks rejected, with a flagged entry or
    // kept only by the track floor; Hopkins `two_cranes_g12`'s object is kept whole with 52
    // flags far off, none ambiguous), the kept tracks are segmented, and when
    // they hold other bodies ([`other_bodies`]) the pass runs again on the scene's tracks
    // (and those no body explains) only, the other bodies' tracks rejected whole, however
    // well their entries happen to fit the scene's cameras. A clean table is not segmented
    // (its cost is the pass's alone).
    // Rejected, or kept only by the floor: the tracks the scene's model does not explain
    // (a track with a flagged entry is most often one of the scene's with a gross error).
    let suspects = |r: &robust::RobustResult| -> Vec<bool> {
        (0..r.inlier_tracks.len())
            .map(|p| !r.inlier_tracks[p] || r.floor_kept.get(p).is_some_and(|&f| f))
            .collect()
    };
    let signs = |r: &robust::RobustResult, suspect: &[bool]| {
        let mut flagged = suspect.to_vec();
        r.flagged_entries
            .iter()
            .for_each(|&(_, p)| flagged[p] = true);
        !matches!(r.verdict, robust::Verdict::RigidMajority { .. })
            || flagged.iter().filter(|&&b| b).count()
                >= 2 * crate::segment::SegmentConfig::default().min_group_tracks
    };
    let bodies = match &r_all {
        Ok(r) if rc.separate_objects && rc.segment_first => {
            let suspect = suspects(r);
            signs(r, &suspect)
                .then(|| {
                    timer.run("other-bodies", |_| {
                        other_bodies(kept.table, &meas_all, config, &suspect, r.noise_sigma)
                    })
                })
                .flatten()
        }
        _ => None,
    };
    let sub;
    let (meas, r, mut rng) = match &bodies {
        Some(b) => {
            sub = meas_all.select_tracks(&b.keep);
            let (r, rng) = pass(&sub, &mut counts, timer);
            (&sub, r, rng)
        }
        None => (&meas_all, r_all, rng_all),
    };
    let n = meas.n_points();
    sel.inlier = vec![true; n];
    let unjudged = |sel: Selection, iterations: usize, counts: Vec<usize>| match &bodies {
        Some(b) => bodies_only(sel, b, kept, iterations, counts, t0),
        None => sel,
    };
    // A table too small (or too sparse) for the robust pass to judge is fitted whole: it
    // says nothing against the data, and the fit's own checks still apply.
    let skipped = |why: String, warnings: &mut Vec<String>| {
        warnings.push(match &bodies {
            None => format!(
                "robust pass skipped: {why}; every track is fitted (an outlier among them \
                 cannot be detected)"
            ),
            Some(b) => format!(
                "robust pass skipped on the scene's tracks: {why}; the {} tracks of {} other \
                 rigid bod{} the segmentation found and its {} outlier track(s) are rejected, \
                 the scene's {} tracks all fitted (an outlier among them cannot be detected)",
                b.n_other_tracks(),
                b.groups.len(),
                if b.groups.len() == 1 { "y" } else { "ies" },
                b.outliers.len(),
                b.keep.len() - b.outliers.len()
            ),
        });
    };
    let r = match r {
        Err(e @ Error::TooFew { .. }) => {
            skipped(e.to_string(), warnings);
            return Ok((unjudged(sel, 0, counts), Some(meas_all)));
        }
        r => r?,
    };
    let mut other_object_tracks = 0;
    // No hypothesis at all is no verdict on the tracks: an affine camera fits them all; a
    // projective one goes on below, where its own model judges them (as without a rigid
    // majority).
    if let robust::Verdict::NoRigidMajority {
        reason: robust::NoMajorityReason::NoHypothesis,
        ..
    } = &r.verdict
        && !config.camera.is_projective()
    {
        skipped(
            "no non-degenerate sample of 4 tracks could be drawn or fitted (too few tracks \
             share frames, or the tracks span fewer than 3 dimensions: motion in a plane)"
                .into(),
            warnings,
        );
        return Ok((unjudged(sel, r.iterations, counts), Some(meas_all)));
    }
    if let robust::Verdict::NoRigidMajority {
        reason,
        inlier_fraction,
        rival_fraction,
        min_inlier_fraction,
    } = &r.verdict
    {
        if !config.camera.is_projective() {
            return Err(Error::NoRigidMajority {
                reason: format!("{reason:?}"),
                inlier_fraction: *inlier_fraction,
                rival_fraction: *rival_fraction,
                min_inlier_fraction: *min_inlier_fraction,
            });
        }
        // Perspective splits the tracks into affine groups: the projective model judges
        // them instead, starting from all of them.
        warnings.push(format!(
            "the affine robust pass found no rigid majority ({reason:?}: best group \
             {:.0} %, rival {:.0} %); the projective model judges the tracks instead",
            100.0 * inlier_fraction,
            100.0 * rival_fraction
        ));
    } else {
        sel.inlier.clone_from(&r.inlier_tracks);
        sel.flagged.clone_from(&r.flagged_entries);
        // When the segmentation before the pass found the other bodies, its groups stand,
        // and the search runs again only when the pass on the scene's tracks still shows
        // the signs of another body, its groups then held to a separation from the scene:
        // a search among the scene's rejected tracks finds the scene's own model error
        // (Hopkins `cars3`, a nearly planar scene: 95–107 of its 437 tracks taken for a
        // fourth body after the segmentation had found the three right), and a second
        // object the segmentation's sample missed otherwise stays in part, its entries
        // flagged (synthetic tables with mixed outliers: 7–12 of 33–50 tracks).
        if rc.separate_objects
            && (bodies.is_none() || signs(&r, &suspects(&r)))
            && let Some(model) = &r.model
        {
            // Another rigid object's tracks pass the trimmed track test with some of their
            // entries flagged, those where they drift from the main body's motion (near the
            // entry threshold: ambiguous flags): find such objects among the rejected tracks
            // and those with an ambiguous flag, and reject their tracks whole. A track
            // whose flags all land far off carries glitches, and is no candidate: with
            // gross entries spread over a table (2 % of a 300 × 3000 table's) every track
            // with a flag was one before, nearly all, and the search took 35 of the run's
            // 43 s. Without ambiguous flags told apart (`gross_entry_factor` ≤ 1), every
            // flagged track is.
            let mut candidate = r.ambiguous_flags.iter().map(|&a| a > 0).collect::<Vec<_>>();
            if rc.gross_entry_factor <= 1.0 {
                sel.flagged.iter().for_each(|&(_, p)| candidate[p] = true);
            }
            let candidates: Vec<usize> =
                (0..n).filter(|&p| !sel.inlier[p] || candidate[p]).collect();
            let seg_cfg = crate::segment::SegmentConfig::default();
            // Its own entry of `timings`; the recording keeps it on the robust stage.
            sel.other_groups = timer.run("other-objects", |_| {
                let mut groups = crate::segment::other_objects(
                    meas,
                    model,
                    r.noise_sigma,
                    &candidates,
                    &seg_cfg,
                    &mut rng,
                )?;
                // Another object moving close to the scene passes the track test whole,
                // within the floor `min_track_threshold_px`, and carries no flag (Hopkins
                // `1R2RC_g23`: 113 of its 121 tracks kept at a median 0.65 px, where the
                // test without the floor is 0.11 px), so it is never a candidate above.
                // When at least two groups' worth of kept tracks pass only by the floor,
                // every kept track outside the groups found is searched again: the scene's
                // own tracks among them (its model error, perspective under the affine
                // camera) then join the scene's group, which the candidates alone could not
                // do (tried: they merged with the object, or formed groups of the scene
                // that took its tracks along; docs/results.md). The scene's group itself,
                // most of the kept tracks, is not another object whatever its fit.
                let mut taken = vec![false; n];
                groups
                    .iter()
                    .flat_map(|g| &g.tracks)
                    .for_each(|&p| taken[p] = true);
                let floor: Vec<usize> = (0..n)
                    .filter(|&p| r.floor_kept[p] && sel.inlier[p] && !candidate[p] && !taken[p])
                    .collect();
                if floor.len() >= 2 * seg_cfg.min_group_tracks {
                    let rest: Vec<usize> = (0..n).filter(|&p| sel.inlier[p] && !taken[p]).collect();
                    // The object is among the floor-kept tracks: the hypotheses are seeded
                    // there only, as many on each as a search seeded on every kept track,
                    // whose cost followed the whole table (the scene's hypotheses growing
                    // to all its tracks: 31 of a 3 200-frame sequence's 52 s, finding
                    // nothing; 13 s with the whole search seeded here).
                    let more = crate::segment::other_objects_seeded(
                        meas,
                        model,
                        r.noise_sigma,
                        &rest,
                        Some(&floor),
                        &seg_cfg,
                        &mut rng,
                    )?;
                    let more: Vec<_> = more
                        .into_iter()
                        .filter(|g| 2 * g.tracks.len() <= rest.len())
                        .collect();
                    // Groups that would take half the kept tracks or more from the scene
                    // are pieces of it (a body in perspective under the affine camera: two
                    // walls seen from 5 widths, each wall a group), not other objects:
                    // then nothing of this search is kept.
                    let total: usize = more.iter().map(|g| g.tracks.len()).sum();
                    if 2 * total < rest.len() {
                        groups.extend(more);
                        groups.sort_by_key(|g| std::cmp::Reverse(g.tracks.len()));
                    }
                }
                // After bodies were found (the pass above ran on the scene's tracks), a
                // group is another object only when it stands apart from the scene by
                // `BODIES_THEN_SEARCH_SEPARATION`: the scene's own model error forms groups
                // too (Hopkins `cars3`, nearly planar: 105 tracks at a median
                // `r_scene / r_own` of 1.72), where the second objects of synthetic tables
                // with mixed outliers stood at 6.6–8.5 (docs/results.md).
                if bodies.is_some() && !groups.is_empty() {
                    let ts = crate::robust::subspace::TrackSubspace::new(meas, &seg_cfg.subspace);
                    groups.retain(|g| {
                        let mut q: Vec<f64> = g
                            .tracks
                            .iter()
                            .filter_map(|&p| {
                                let own = ts.track_fit(&g.model, p)?.rms;
                                Some(ts.track_fit(model, p)?.rms / own.max(1e-12))
                            })
                            .collect();
                        q.sort_by(f64::total_cmp);
                        q.get(q.len() / 2)
                            .is_some_and(|&m| m >= BODIES_THEN_SEARCH_SEPARATION)
                    });
                }
                Ok::<_, Error>(groups)
            })?;
            for &p in sel.other_groups.iter().flat_map(|g| &g.tracks) {
                if sel.inlier[p] {
                    sel.inlier[p] = false;
                    other_object_tracks += 1;
                }
            }
            let inlier = &sel.inlier;
            sel.flagged.retain(|&(_, p)| inlier[p]);
        }
    }
    if let Some(b) = &bodies {
        sel.lift(b);
        other_object_tracks += b.n_other_tracks();
    }
    let n = sel.inlier.len();
    // The projective cameras need 6 tracks in every frame: an affine selection that starves
    // a frame (the affine pass rejects tracks that only perspective explains, most where
    // few tracks are seen) would leave the projective stages unusable. The projective
    // model judges every track instead, as without a rigid majority.
    if config.camera.is_projective() {
        let nf = meas_all.n_frames();
        let (mut all, mut selected) = (vec![0usize; nf], vec![0usize; nf]);
        let mut is_flagged = std::collections::HashSet::new();
        is_flagged.extend(sel.flagged.iter().copied());
        meas_all.for_each_observed(|f, p| {
            all[f] += 1;
            if sel.inlier[p] && !is_flagged.contains(&(f, p)) {
                selected[f] += 1;
            }
        });
        if let Some(f) = (0..nf).find(|&f| selected[f] < 6 && all[f] >= 6) {
            warnings.push(format!(
                "the affine robust pass leaves {} track(s) in frame {} (of {}), fewer than a \
                 projective camera needs (6); the projective model judges every track instead",
                selected[f],
                kept.table.frame_ids()[f],
                all[f]
            ));
            sel.inlier = vec![true; n];
            sel.flagged.clear();
            sel.other_groups.clear();
            other_object_tracks = 0;
        }
    }
    sel.report = Some(RobustReport::of_selection(
        kept,
        &sel,
        [r.noise_sigma, r.threshold_px, r.entry_threshold_px],
        r.iterations,
        counts,
        other_object_tracks,
        t0,
    ));
    Ok((sel, Some(meas_all)))
}

/// Stage 4, the projective verdict: the projective model judges every kept track again
/// (the affine pass cannot explain perspective, and blames the tracks for it), and the
/// selection is refitted while the verdict changes, at most `PROJECTIVE_VERDICT_ROUNDS`
/// times. Fewer than `min_inlier_fraction` of the tracks kept is
/// [`Error::NoRigidMajority`]. Each refit costs a [`fit_selection`].
fn projective_verdict_stage(
    kept: &Kept<'_>,
    sel: &mut Selection,
    mut fitted: Fitted,
    config: &Config,
    timer: &mut Timer<'_>,
    warnings: &mut Vec<String>,
) -> Result<Fitted> {
    let (Some(rc), Some(mut report)) = (&config.robust, sel.report.take()) else {
        return Ok(fitted);
    };
    let before = sel.inlier.clone();
    let flagged_before = sel.flagged.len();
    // Another object the affine pass found stays out when its own rigid motion explains it
    // better than the projective cameras fitted without it: the cameras' spare degrees of
    // freedom would otherwise bend towards it refit by refit (`projective_evidence`).
    let mut held_out = vec![false; before.len()];
    let mut objects_held_out = 0;
    if let Some(pf) = &fitted.projective
        && !sel.other_groups.is_empty()
    {
        let meas_all = kept.table.measurements();
        let subspace = crate::segment::SegmentConfig::default().subspace;
        for g in &sel.other_groups {
            let e = crate::segment::projective_evidence(
                &meas_all,
                g,
                &fitted.fit_frames,
                &pf.model,
                &subspace,
            );
            if e.apart() {
                g.tracks.iter().for_each(|&p| held_out[p] = true);
                objects_held_out += 1;
            }
        }
    }
    let mut refits = 0;
    let mut last = None;
    let mut readmissions_not_refitted = 0;
    while let Some(pf) = &fitted.projective {
        let mut v = projective_verdict(kept.table, &fitted, pf, &sel.flagged, rc);
        (0..v.0.len())
            .filter(|&p| held_out[p])
            .for_each(|p| v.0[p] = false);
        v.1.retain(|&(_, p)| !held_out[p]);
        let changed = v.0 != sel.inlier || v.1 != sel.flagged;
        last = Some((v.2, v.3));
        if !changed || refits == PROJECTIVE_VERDICT_ROUNDS {
            break;
        }
        if v.0 == sel.inlier
            && let Some(k) = readmission_within_noise(&sel.flagged, &v.1, v.2, v.3, &fitted.meas)
        {
            readmissions_not_refitted = k;
            break;
        }
        let n_in = v.0.iter().filter(|&&b| b).count();
        if n_in < 7 {
            warnings.push(format!(
                "the projective verdict keeps {n_in} track(s): too few to refit; the \
                 previous selection is kept"
            ));
            break;
        }
        sel.inlier = v.0;
        sel.flagged = v.1;
        let previous = fitted
            .projective
            .as_ref()
            .map(|pf| (pf, &fitted.used_frames[..]));
        fitted = fit_selection(kept, sel, config, previous, None, timer)?;
        refits += 1;
    }
    let inlier = &sel.inlier;
    let n_in = inlier.iter().filter(|&&b| b).count();
    let fraction = n_in as f64 / inlier.len().max(1) as f64;
    if fraction < rc.min_inlier_fraction {
        return Err(Error::NoRigidMajority {
            reason: "projective verdict".into(),
            inlier_fraction: fraction,
            rival_fraction: 0.0,
            min_inlier_fraction: rc.min_inlier_fraction,
        });
    }
    let (sigma, tau) = last.unwrap_or((f64::NAN, f64::NAN));
    report.update(kept.table, &kept.frames, &kept.tracks, inlier, &sel.flagged);
    // A group the projective model mostly readmits was a part of the body seen in
    // perspective, not another object.
    for g in sel.other_groups.iter().map(|g| &g.tracks) {
        let back = g.iter().filter(|&&p| inlier[p]).count();
        if 2 * back > g.len() {
            report.rigid_groups_seen -= 1;
        }
        report.other_object_tracks -= g
            .iter()
            .filter(|&&p| inlier[p] && !before[p])
            .count()
            .min(report.other_object_tracks);
    }
    report.noise_sigma_px = sigma;
    report.entry_threshold_px = tau;
    report.projective = Some(ProjectiveJudgement {
        readmitted_tracks: (0..inlier.len())
            .filter(|&p| inlier[p] && !before[p])
            .count(),
        rejected_tracks: (0..inlier.len())
            .filter(|&p| !inlier[p] && before[p])
            .count(),
        flagged_before,
        flagged_after: sel.flagged.len(),
        noise_sigma_px: sigma,
        entry_threshold_px: tau,
        refits,
        objects_held_out,
        readmissions_not_refitted,
    });
    sel.report = Some(report);
    Ok(fitted)
}

/// The outlier tracks given the fitted cameras: their affine and metric points from their
/// own observations in the fit's frames (for display and completed.txt; not in the fit).
/// `O(observations of the outlier tracks)` plus their `2F × n_outliers` prediction.
struct OutlierTracks {
    meas: Measurements,
    /// Affine prediction `M̂ Ŝ_outliers + t`, 2F × n_outliers.
    prediction: Mat<f64>,
    model: MetricModel,
}

impl OutlierTracks {
    fn of(kept: &TrackTable, fitted: &Fitted) -> OutlierTracks {
        let affine = &fitted.affine;
        let meas = kept
            .select(&fitted.fit_frames, &fitted.outlier_kept)
            .measurements();
        let points = affine_points(&meas, affine);
        let prediction = Mat::from_fn(affine.m_hat.nrows(), fitted.outlier_kept.len(), |r, p| {
            affine.t[r]
                + (0..3)
                    .map(|k| affine.m_hat[(r, k)] * points[(k, p)])
                    .sum::<f64>()
        });
        let mut model = MetricModel {
            rotations: fitted.model.rotations.clone(),
            translations: fitted.model.translations.clone(),
            scales: fitted.model.scales.clone(),
            points: vec![Vector3::repeat(f64::NAN); fitted.outlier_kept.len()],
            aspect: fitted.model.aspect,
        };
        model.triangulate(&meas);
        OutlierTracks {
            meas,
            prediction,
            model,
        }
    }
}

/// The camera model of the result and its fits.
struct CameraChoice {
    /// RMS of the metric (affine-camera) model over the fit's observations, pixels.
    metric_rms_px: f64,
    camera_model: CameraModel,
    model_selection: Option<ModelSelection>,
    perspective: Option<PerspectiveResult>,
    projective: Option<ProjectiveResult>,
}

/// Stage 6, the camera model: with the perspective camera the metric perspective stages
/// ([`perspective::fit`] from the projective fit); with the automatic choice first a
/// pre-test of the projective fit against the scaled orthographic one (when even its 5F
/// extra parameters do not explain the tracks significantly better, the perspective stages
/// are skipped), then the judgement of the perspective fit ([`ModelSelection`]). Takes the
/// projective fit out of `fitted`.
fn camera_stage(
    kept: &Kept<'_>,
    fitted: &mut Fitted,
    outliers: &OutlierTracks,
    config: &Config,
    timer: &mut Timer<'_>,
    warnings: &mut Vec<String>,
) -> Result<CameraChoice> {
    let meas = &fitted.meas;
    let metric_rms_px = fitted.model.rms(meas);
    let mut projective = fitted.projective.take();
    let mut pre_selection = fitted.pretest.take();
    if config.camera == CameraModel::Auto
        && let Some(pf) = &projective
    {
        let sel = ModelSelection::pretest(
            metric_rms_px,
            pf.rms_px,
            meas.n_observed(),
            meas.n_frames(),
            meas.n_points(),
        );
        if sel.chosen != CameraModel::Perspective {
            pre_selection = Some(sel);
        }
    }
    let mut perspective = match &projective {
        Some(pf) if config.camera.is_perspective() && pre_selection.is_none() => {
            let per = timer.run("perspective", |obs| {
                perspective::fit(
                    meas,
                    &pf.model,
                    Some(&fitted.model),
                    &config.perspective,
                    0,
                    obs,
                )
            });
            let per = match per {
                Ok(p) => Some(p),
                // With the automatic choice the affine model stands in.
                Err(e) if config.camera == CameraModel::Auto => {
                    warnings.push(format!(
                        "the perspective camera could not be fitted ({e}); the scaled \
                         orthographic camera is kept"
                    ));
                    None
                }
                Err(e) => return Err(e),
            };
            per.map(|per| {
                for st in &per.stages {
                    if st.status == SolverStatus::Stalled {
                        warnings.push(format!(
                            "perspective stage {} stalled after {} iterations",
                            st.stage, st.iterations
                        ));
                    }
                }
                let parallax = perspective::planar::rotation_parallax_px(meas, &per.model);
                let rotation_only =
                    parallax.is_some_and(|px| px <= ROTATION_ONLY_FACTOR * per.rms_px);
                if rotation_only {
                    warnings.push(format!(
                        "the camera only rotates: the best rotation between frames explains \
                         the tracks to {:.3} px (the fit's RMS {:.3} px); the focal length and \
                         the rotations are determined, the depths and the camera centres are \
                         not (a panorama, not a reconstruction)",
                        parallax.unwrap_or(f64::NAN),
                        per.rms_px
                    ));
                } else if per.in_front < 0.95 {
                    warnings.push(format!(
                        "only {:.1} % of the observations are in front of their camera after \
                         the Euclidean upgrade: the self-calibration is unreliable (weak \
                         perspective or degenerate motion)",
                        100.0 * per.in_front
                    ));
                }
                let mut result = PerspectiveResult::new(
                    per,
                    &config.perspective,
                    &fitted.fit,
                    meas,
                    &outliers.meas,
                    &fitted.outlier_kept,
                    kept.table,
                    &kept.tracks,
                    &fitted.used_tracks,
                );
                result.rotation_parallax_px = parallax;
                result
            })
        }
        _ => None,
    };
    let mut camera_model = config.camera;
    let mut model_selection = None;
    if let Some(sel) = pre_selection {
        camera_model = sel.chosen;
        perspective = None;
        projective = None;
        model_selection = Some(sel);
    } else if config.camera == CameraModel::Auto {
        let sel = ModelSelection::judge(
            metric_rms_px,
            perspective.as_ref(),
            meas.n_observed(),
            meas.n_frames(),
            meas.n_points(),
        );
        camera_model = sel.chosen;
        if sel.chosen != CameraModel::Perspective {
            perspective = None;
            projective = None;
        }
        model_selection = Some(sel);
    }
    if let Some(p) = &perspective {
        // (The principal point in the input's image coordinates.)
        let side = p.intrinsics.image_size.map_or(
            2.0 * (p.intrinsics.principal_point[0] + kept.origin[0])
                .max(p.intrinsics.principal_point[1] + kept.origin[1]),
            |[w, h]| w.max(h) as f64,
        );
        if p.intrinsics.focal_px > 20.0 * side {
            warnings.push(format!(
                "focal length {:.0} px, over 20 times the image size: the data are close to \
                 weak perspective and the focal length is poorly determined",
                p.intrinsics.focal_px
            ));
        }
    }
    let projective = projective.map(|pf| {
        ProjectiveResult::new(
            pf,
            &fitted.fit,
            meas,
            &outliers.meas,
            &fitted.outlier_kept,
            kept.table,
            &kept.tracks,
            &fitted.used_tracks,
        )
    });
    Ok(CameraChoice {
        metric_rms_px,
        camera_model,
        model_selection,
        perspective,
        projective,
    })
}

/// Stage 7, the [`Reconstruction`]: per-frame and per-point results (residuals in the
/// input's ids), the reports of every stage, the warnings (also sent to the observer) and
/// the dense predictions. `O(F·N)` for the predictions.
#[allow(clippy::too_many_arguments)]
fn assemble(
    table: &TrackTable,
    kept: Kept<'_>,
    selection: Selection,
    fitted: Fitted,
    outliers: OutlierTracks,
    choice: CameraChoice,
    timer: Timer<'_>,
    warnings: Vec<String>,
) -> Reconstruction {
    let Kept {
        table: kept_table,
        tracks: kept_tracks,
        set_aside,
        ..
    } = kept;
    let Fitted {
        fit,
        meas,
        used_frames,
        used_tracks,
        outlier_kept,
        affine,
        completion_report,
        upgrade,
        model,
        refinement,
        mirrored,
        rank_ratio,
        rank_source,
        ..
    } = fitted;
    let CameraChoice {
        metric_rms_px,
        camera_model,
        model_selection,
        perspective,
        projective,
    } = choice;
    for w in &warnings {
        timer.observer.on_event(&Event::Warning { message: w });
    }
    let affine_prediction = AffinePrediction {
        m: affine.m_hat,
        s: affine.s_hat.clone(),
        t: affine.t,
        aspect: 1.0,
        origin: [0.0, 0.0],
    };
    let outlier_model = outliers.model;
    let (sums, outlier_sums) = (
        ResidualSums::new(&metric_predictor(&model), &meas),
        ResidualSums::new(&metric_predictor(&outlier_model), &outliers.meas),
    );
    let frames = (0..fit.n_frames())
        .map(|f| {
            let (ss, n) = sums.frames[f];
            let r = model.rotations[f].matrix();
            FrameResult {
                frame: fit.frame_ids()[f].clone(),
                rotation: std::array::from_fn(|a| std::array::from_fn(|b| r[(a, b)])),
                translation: [model.translations[f][0], model.translations[f][1]],
                scale: model.scales[f],
                rms_px: rms_of(ss, n),
                n_observations: n,
            }
        })
        .collect();
    let points = point_results(
        &TrackSets {
            fit: &fit,
            used_tracks: &used_tracks,
            kept: kept_table,
            kept_tracks: &kept_tracks,
            outlier_kept: &outlier_kept,
        },
        (&sums, |p| model.points[p]),
        (&outlier_sums, |k| outlier_model.points[k]),
    );
    let outlier_tracks: Vec<usize> = outlier_kept.iter().map(|&p| kept_tracks[p]).collect();
    Reconstruction {
        camera_model,
        model_selection,
        frames,
        points,
        rms_px: result_rms(perspective.as_ref(), projective.as_ref(), metric_rms_px),
        metric_rms_px,
        metric_upgrade: upgrade,
        rank_ratio,
        rank_ratio_source: rank_source,
        singular_values: affine.singular_values,
        factorization: affine.report,
        completion: completion_report,
        robust: selection.report,
        refinement,
        projective,
        perspective,
        input: InputSummary {
            frames: table.n_frames(),
            tracks: table.n_tracks(),
            observations: table.n_observed(),
            fill: table.fill(),
            frames_used: fit.n_frames(),
            tracks_used: fit.n_tracks(),
        },
        set_aside,
        mirrored,
        warnings,
        timings: timer.timings,
        mesh: None,
        aspect_ratio: 1.0,
        aspect_ratio_source: SQUARE_PIXELS.to_string(),
        sparse: None,
        stream: None,
        model,
        affine_structure: affine.s_hat,
        affine_prediction,
        outlier_prediction: outliers.prediction,
        outlier_model,
        kept_frames: used_frames,
        kept_tracks: used_tracks,
        outlier_tracks,
        input_frame_ids: table.frame_ids().to_vec(),
        input_track_ids: table.track_ids().to_vec(),
    }
}

struct Fitted {
    /// The fit's frames and tracks, ids only (no observations: those are in `meas`).
    fit: TrackTable,
    meas: Measurements,
    /// Tracks and frames the selection starved (set aside after hiding entries).
    set_aside: Vec<SetAside>,
    /// Indices into the kept table of the fit's frames; indices into `inlier_idx` of its
    /// tracks.
    fit_frames: Vec<usize>,
    fit_tracks: Vec<usize>,
    /// Kept-table indices of the inlier tracks.
    inlier_idx: Vec<usize>,
    /// Indices into the input table of the fit's frames and tracks.
    used_frames: Vec<usize>,
    used_tracks: Vec<usize>,
    /// Kept-table indices of the outlier tracks.
    outlier_kept: Vec<usize>,
    affine: Affine,
    completion_report: Option<CompletionReport>,
    upgrade: MetricUpgrade,
    model: MetricModel,
    refinement: Option<RefinementReport>,
    mirrored: bool,
    projective: Option<projective::ProjectiveFit>,
    /// With the automatic choice on a large table: the projective pre-test on a subset,
    /// when it kept the scaled orthographic camera (`projective` is then `None`).
    pretest: Option<ModelSelection>,
    /// σ4/σ3 and what it was computed on.
    rank_ratio: f64,
    rank_source: String,
    warnings: Vec<String>,
}

/// Fits the inlier tracks of `kept` with the flagged entries hidden: affine factorization
/// (SVD or completion), metric upgrade, refinement, and with the projective camera the
/// projective stages ([`crate::projective`]). A refit after the projective verdict passes
/// the previous projective fit: when the frames are the same, its cameras (with the
/// selection's points triangulated) start the projective bundle adjustment
/// ([`projective::refine`]), instead of the affine start and the pOSE bridge.
/// `table_meas`, the kept table's measurements when the caller has them, are the fit's when
/// the selection keeps every track and entry and nothing is set aside (no copy is made);
/// otherwise they are dropped before the fit's are built.
fn fit_selection(
    kept: &Kept<'_>,
    selection: &Selection,
    config: &Config,
    previous: Option<(&projective::ProjectiveFit, &[usize])>,
    table_meas: Option<Measurements>,
    timer: &mut Timer<'_>,
) -> Result<Fitted> {
    let (kept_frames, kept_tracks) = (&kept.frames, &kept.tracks);
    let (inlier, flagged) = (&selection.inlier, &selection.flagged);
    let kept = kept.table;
    let mut warnings = Vec::new();
    let affine_camera = config.camera.affine();
    // The table the fit uses: inlier tracks, flagged entries hidden, set aside again
    // (hiding entries can starve a track or a frame).
    let inlier_idx: Vec<usize> = (0..kept.n_tracks()).filter(|&p| inlier[p]).collect();
    // (Every track and entry kept: the kept table itself, borrowed.)
    let fit_table = if inlier_idx.len() == kept.n_tracks() && flagged.is_empty() {
        std::borrow::Cow::Borrowed(kept)
    } else {
        let all_frames: Vec<usize> = (0..kept.n_frames()).collect();
        let mut fit_table = kept.select(&all_frames, &inlier_idx);
        let mut pos = vec![usize::MAX; kept.n_tracks()];
        for (k, &p) in inlier_idx.iter().enumerate() {
            pos[p] = k;
        }
        for &(f, p) in flagged {
            if pos[p] != usize::MAX {
                fit_table.unset(f, pos[p]);
            }
        }
        std::borrow::Cow::Owned(fit_table)
    };
    let min_points = min_points_per_frame(config, &fit_table);
    let (fit, set_aside, fit_frames, fit_tracks) = match fit_table {
        std::borrow::Cow::Borrowed(t) => t.set_aside_cow(config.min_frames_per_track, min_points),
        std::borrow::Cow::Owned(t) => {
            let (t, out, f, p) = t.into_set_aside(config.min_frames_per_track, min_points);
            (std::borrow::Cow::Owned(t), out, f, p)
        }
    };
    check_size(&fit)?;
    let used_frames: Vec<usize> = fit_frames.iter().map(|&f| kept_frames[f]).collect();
    let used_tracks: Vec<usize> = fit_tracks
        .iter()
        .map(|&k| kept_tracks[inlier_idx[k]])
        .collect();
    let outlier_kept: Vec<usize> = (0..kept.n_tracks()).filter(|&p| !inlier[p]).collect();
    let meas = match table_meas {
        Some(m) if matches!(fit, std::borrow::Cow::Borrowed(_)) => m,
        other => {
            drop(other);
            fit.measurements()
        }
    };
    // From here on the fit's observations are in `meas`; the table keeps its ids only (the
    // observations are freed now, not at the end of the function).
    let ids_only = TrackTable::new(fit.frame_ids().to_vec(), fit.track_ids().to_vec());
    drop(fit);
    let fit = ids_only;
    timer.observer.on_event(&Event::FitSelection {
        frames: &used_frames,
        tracks: &used_tracks,
    });

    let mut completion_report = None;
    let affine = timer.run("factorize", |obs| -> Result<Affine> {
        if meas.is_complete() {
            factorize_complete(&meas, &config.svd)
        } else {
            let c = completion::complete(&meas, &config.completion, obs)?;
            completion_report = Some(CompletionReport {
                solver: c.solver,
                model: c.model,
                rms_px: c.rms,
                status: c.report.status,
                iterations: c.report.iterations,
                als_sweeps_first: c.als_sweeps_first,
                runs: c.runs.len(),
                seconds: c.report.seconds,
            });
            factorization_from_completion(&meas, c)
        }
    })?;
    if let Some(c) = &completion_report
        && c.status != SolverStatus::Converged
    {
        warnings.push(format!(
            "missing-data completion ended with status {} after {} iterations",
            crate::output::spelled(&c.status),
            c.iterations
        ));
    }
    if let Some(c) = &completion_report
        && c.solver != config.completion.solver
    {
        warnings.push(format!(
            "missing-data completion: {} ran instead of {}: the latter's dense matrix for \
             {} frames is over the memory budget (crate::budget)",
            crate::output::spelled(&c.solver),
            crate::output::spelled(&config.completion.solver),
            meas.n_frames()
        ));
    }
    let sv = &affine.singular_values;
    let (rank_ratio, rank_source) = if sv.len() >= 4 && sv[2] > 0.0 {
        (sv[3] / sv[2], "all tracks".to_string())
    } else {
        match complete_block_rank_ratio(&meas, &config.svd) {
            Some((r, nf, np, f0)) => (
                r,
                format!(
                    "the largest complete block: {nf} consecutive frames from frame {f0} × {np} \
                     tracks"
                ),
            ),
            None => (
                f64::NAN,
                "not defined (no complete block of 2 frames × 4 tracks)".into(),
            ),
        }
    };
    if rank_ratio > config.rank3_warning_ratio && config.camera.is_affine() {
        warnings.push(format!(
            "σ4/σ3 = {rank_ratio:.3} > {} (on {rank_source}): the tracks are far from rank 3 \
             (strong perspective, non-rigid or independently moving objects, or outlier \
             tracks)",
            config.rank3_warning_ratio
        ));
    }
    if sv.len() >= 3 && sv[1] > 0.0 && sv[2] / sv[1] < config.rank2_warning_ratio {
        warnings.push(format!(
            "σ3/σ2 = {:.4} < {}: the tracks are close to rank 2 (planar scene or \
             degenerate motion such as rotation about the viewing axis only); depth is \
             poorly determined",
            sv[2] / sv[1],
            config.rank2_warning_ratio
        ));
    }

    let upgrade = timer.run("metric-upgrade", |_| {
        metric::upgrade(affine.m_hat.as_ref(), affine_camera, &config.metric)
    })?;
    if upgrade.method == metric::UpgradeMethod::Sdp {
        warnings.push(format!(
            "least-squares L is not positive definite (smallest eigenvalue {:.3e}); solved \
             the PSD-constrained SDP instead",
            upgrade.min_eigenvalue_ls
        ));
    }
    let mut model = initial_model(&meas, &affine, &upgrade, affine_camera)?;
    // The dense refinement's reduced camera matrix is (6F)²: where that outgrows the
    // observations (more than `ITERATIVE_FILL` times the sparse engine's 20 numbers per
    // observation, and more than `ITERATIVE_MIN_NONZEROS`: long sequences whose tracks
    // each span much of them), the sparse engine
    // refines instead, its memory linear in the observations (`refine::refine_sparse`).
    // The dense one is skipped (with a warning) when its matrix exceeds the memory budget
    // rather than aborting on the allocation.
    let refine_dim = 6 * meas.n_frames();
    let sparse_refine = (refine_dim * refine_dim) as f64
        > (crate::projective::bundle::ITERATIVE_FILL * (20 * meas.n_observed()) as f64)
            .max(crate::projective::bundle::ITERATIVE_MIN_NONZEROS);
    const GIB: f64 = (1u64 << 30) as f64;
    let refine_cfg = config.refine.as_ref().filter(|_| {
        let fits = sparse_refine
            || crate::budget::matrix_bytes(refine_dim, refine_dim)
                <= crate::budget::DENSE_MATRIX_BYTES;
        if !fits {
            warnings.push(format!(
                "the metric refinement was skipped: its dense {refine_dim}×{refine_dim} camera \
                 matrix ({:.2} GiB) is over the {:.2} GiB budget for {} frames",
                crate::budget::matrix_bytes(refine_dim, refine_dim) as f64 / GIB,
                crate::budget::DENSE_MATRIX_BYTES as f64 / GIB,
                meas.n_frames()
            ));
        }
        fits
    });
    // The affine fit bounds what a metric model reaches: a refinement that cannot gain more
    // than `min_relative_gain` of it is skipped, and its report says so.
    let mut skipped_refinement = None;
    let refine_cfg = refine_cfg.filter(|rc| {
        let metric_rms = model.rms(&meas);
        let affine_rms = affine.report.rms_px;
        let worth = !(metric_rms - affine_rms <= rc.min_relative_gain * affine_rms);
        if !worth {
            skipped_refinement = Some(RefinementReport {
                rms_before_px: metric_rms,
                rms_after_px: metric_rms,
                status: SolverStatus::Converged,
                iterations: 0,
                seconds: 0.0,
                skipped: Some(format!(
                    "the metric model's RMS {metric_rms:.6} px is within {:.2} % of the affine \
                     fit's {affine_rms:.6} px, which bounds what refining can reach \
                     (refine.min_relative_gain)",
                    100.0 * rc.min_relative_gain
                )),
            });
        }
        worth
    });
    let refinement = match refine_cfg {
        Some(rc) => {
            let r: RefineResult = timer.run("refine", |obs| {
                if sparse_refine {
                    refine::refine_sparse(&meas, &mut model, affine_camera, rc, obs)
                } else {
                    refine::refine(&meas, &mut model, affine_camera, rc, obs)
                }
            })?;
            if r.report.status == SolverStatus::Stalled {
                warnings.push("metric refinement stalled before converging".into());
            }
            Some(RefinementReport {
                rms_before_px: r.rms_before,
                rms_after_px: r.rms_after,
                status: r.report.status,
                iterations: r.report.iterations,
                seconds: r.report.seconds,
                skipped: None,
            })
        }
        None => skipped_refinement,
    };
    refine::fix_gauge(&mut model, affine_camera);
    let mirrored = metric::apply_necker_convention(&mut model);

    // With the automatic choice, a table the projective stages cannot use (a frame with
    // fewer than 6 tracks, …) keeps the affine camera. (The other cameras get the same
    // check, as an error, inside `projective::fit`.)
    let projective_usable = config.camera != CameraModel::Auto
        || match projective::check_observations(&meas) {
            Err(e) => {
                warnings.push(format!(
                    "camera auto: the perspective camera was not tried ({e}); the scaled \
                     orthographic camera is kept"
                ));
                false
            }
            Ok(()) => true,
        };
    // With the automatic choice on a table whose projective adjustment would be costly,
    // the pre-test runs on a subset first (see `pretest_subset`); when it keeps the scaled
    // orthographic camera the projective stages do not run on the whole table.
    let mut pretest = None;
    let whole_flops = if config.camera == CameraModel::Auto && projective_usable {
        projective_iteration_flops(&meas)
    } else {
        0.0
    };
    if whole_flops > PRETEST_FLOPS
        && let Some((frames, tracks)) = pretest_subset(&meas)
    {
        let sub = meas.select(&frames, &tracks);
        let test = timer.run("projective-pretest", |_| part_pretest(&sub, config, None));
        match test {
            Some((delta, threshold, affine_rms, projective_rms)) if delta <= threshold => {
                pretest = Some(ModelSelection::affine_by_parts(
                    (delta, threshold, affine_rms, projective_rms),
                    &format!(
                        "{} frames × {} tracks ({} observations) chosen evenly from the {} × {} \
                         (the projective adjustment of the whole table would cost {:.1e} \
                         operations per iteration)",
                        sub.n_frames(),
                        sub.n_points(),
                        sub.n_observed(),
                        meas.n_frames(),
                        meas.n_points(),
                        whole_flops
                    ),
                ));
            }
            Some(_) => {}
            None => warnings.push(
                "camera auto: the projective pre-test on a subset could not be fitted; the \
                 whole table is fitted"
                    .into(),
            ),
        }
    }
    let projective = if config.camera.is_projective() && projective_usable && pretest.is_none() {
        let start = projective::AffineStart {
            m: affine.m_hat.as_ref(),
            s: affine.s_hat.as_ref(),
            t: &affine.t,
        };
        // The previous fit's cameras, when they are this fit's frames.
        let warm = previous
            .filter(|(_, frames)| *frames == &used_frames[..])
            .map(|(pf, _)| {
                let mut model = ProjectiveModel {
                    cameras: pf.model.cameras.clone(),
                    points: Vec::new(),
                };
                model.points = model.triangulate(&meas);
                model
            })
            .filter(|m| m.points.iter().flatten().all(|v| v.is_finite()));
        // For the perspective camera the projective model only prepares the perspective
        // stages: its adjustment is capped, more tightly when it starts from the previous
        // fit's cameras.
        let mut pcfg = config.projective.clone();
        if config.camera.is_perspective() {
            // Only a start for the perspective stages: one chain, no escapes.
            pcfg.second_bridge = None;
            pcfg.escapes.clear();
            let cap = if warm.is_some() {
                config.perspective.projective_refit_iterations
            } else {
                config.perspective.projective_iterations
            };
            pcfg.refine.max_iterations = pcfg.refine.max_iterations.min(cap.max(1));
        }
        let pf = timer.run("projective", |obs| match &warm {
            Some(model) => projective::refine(&meas, model, &pcfg, 0, obs),
            None => projective::fit(&meas, start, &pcfg, 0, obs),
        })?;
        for st in &pf.stages {
            if st.status != SolverStatus::Converged
                && st.stage != "sturm-triggs"
                && !config.camera.is_perspective()
            {
                warnings.push(format!(
                    "projective stage {} ended with status {} after {} iterations",
                    st.stage,
                    crate::output::spelled(&st.status),
                    st.iterations
                ));
            }
        }
        Some(pf)
    } else {
        None
    };
    Ok(Fitted {
        fit,
        meas,
        set_aside,
        fit_frames,
        fit_tracks,
        inlier_idx,
        used_frames,
        used_tracks,
        outlier_kept,
        affine,
        completion_report,
        upgrade,
        model,
        refinement,
        mirrored,
        projective,
        pretest,
        rank_ratio,
        rank_source,
        warnings,
    })
}

/// Above this estimate of one projective bundle adjustment iteration on the whole table
/// ([`projective_iteration_flops`]), the automatic camera choice runs its projective
/// pre-test on a subset ([`pretest_subset`]). About a second per iteration: every real data
/// set of docs/results.md is below it (the hotel 1.8·10⁸); a complete 300 × 10 000 table
/// is at 1.2·10¹¹, where the whole-table pre-test took over 11 minutes.
const PRETEST_FLOPS: f64 = 1e10;

/// Frames and tracks of the pre-test's subset.
const PRETEST_FRAMES: usize = 150;
const PRETEST_TRACKS: usize = 400;
/// Tracks each subset frame sees at least (when the table has them).
const PRETEST_PER_FRAME: usize = 12;
/// The pre-test's projective adjustment stops when its last [`PRETEST_WINDOW`] accepted
/// steps together lowered `χ²` by less than this many units (its `noise_tolerance`; see
/// [`part_pretest`]).
const PRETEST_CHI2_PRECISION: f64 = 1.0;
/// See [`PRETEST_CHI2_PRECISION`].
const PRETEST_WINDOW: usize = 3;

/// Estimated floating-point operations of one projective bundle adjustment iteration on
/// `meas`: the reduced camera system's assembly, `Σ_p k_p² 11²` over tracks seen in `k_p`
/// frames, plus its dense factorisation `(11F)³/3` (a table whose tracks span the sequence
/// gives a dense system). `O(F N)`.
fn projective_iteration_flops(meas: &Measurements) -> f64 {
    let (nf, np) = (meas.n_frames(), meas.n_points());
    let mut seen = vec![0usize; np];
    meas.for_each_observed(|_, p| seen[p] += 1);
    let assembly: f64 = seen
        .iter()
        .map(|&k| {
            let k = k as f64;
            k * k * 121.0
        })
        .sum();
    assembly + (11.0 * nf as f64).powi(3) / 3.0
}

/// The subset of the automatic choice's projective pre-test on a large table
/// ([`Measurements::spanning_subset`]): at most [`PRETEST_FRAMES`] frames evenly spaced
/// over the sequence, at most [`PRETEST_TRACKS`] tracks seen in at least 3 of them, plus
/// the tracks needed for every subset frame to see [`PRETEST_PER_FRAME`]. `None` when the
/// subset would not be smaller than the table. The test on the subset ([`part_pretest`])
/// has less power than on the whole table. `O(F N)`.
fn pretest_subset(meas: &Measurements) -> Option<(Vec<usize>, Vec<usize>)> {
    meas.spanning_subset(PRETEST_FRAMES, PRETEST_TRACKS, PRETEST_PER_FRAME)
}

/// One projective pre-test on a part of the table (a subset of a large dense table, or a
/// window of a long sparse one): the affine camera (completion, `8F` parameters per part)
/// and the projective camera started from it (`11F`) are both fitted to `meas`, so neither
/// side carries an advantage from being fitted to more data than it is judged on. Returns
/// `(Δχ², threshold, affine RMS, projective RMS)` with Akaike's threshold for the projective
/// camera's `3F − 3` extra parameters, `2 (3F − 3)` (gauge: 12 affine, 15 projective): a
/// part has far fewer observations than the table, and the BIC's `ln n` per parameter
/// missed the perspective of a 130-frame corridor's 40-frame windows (Δχ² 250–530 against
/// 880; AIC threshold 234) that the whole-table test finds. `None` when either fit fails.
///
/// The test only compares `Δχ²` with a threshold of hundreds of units, so its projective
/// adjustment stops at [`PRETEST_CHI2_PRECISION`] (the last [`PRETEST_WINDOW`] accepted
/// steps together lowered `χ²` by less than one unit) instead of the full fit's
/// `0.01` over 10 steps: on #21's 300 × 10 000 table with 40 % missing, 4 solves instead of
/// 15 and `Δχ²` 488.66 instead of 488.68.
///
/// `start`: affine cameras `(M, t)` for `meas`'s frames to start the affine completion from
/// (the sparse path's fitted cameras), else its data-driven start.
fn part_pretest(
    meas: &Measurements,
    config: &Config,
    start: Option<(Mat<f64>, Vec<f64>)>,
) -> Option<(f64, f64, f64, f64)> {
    projective::check_observations(meas).ok()?;
    let mut noop = crate::NoopObserver;
    let c = match &start {
        Some((m, t)) => {
            completion::complete_with_start(meas, &config.completion, m.as_ref(), t, &mut noop)
                .or_else(|_| completion::complete(meas, &config.completion, &mut noop))
        }
        None => completion::complete(meas, &config.completion, &mut noop),
    }
    .ok()?;
    let start = projective::AffineStart {
        m: c.m.as_ref(),
        s: c.s.as_ref(),
        t: &c.t,
    };
    let mut pcfg = config.projective.clone();
    // The pre-test only compares costs: one chain, no escapes.
    pcfg.second_bridge = None;
    pcfg.escapes.clear();
    pcfg.refine.noise_tolerance = pcfg.refine.noise_tolerance.max(PRETEST_CHI2_PRECISION);
    pcfg.refine.noise_window = pcfg.refine.noise_window.min(PRETEST_WINDOW);
    let pf = projective::fit(meas, start, &pcfg, 0, &mut crate::NoopObserver).ok()?;
    let (nf, np) = (meas.n_frames(), meas.n_points());
    let n = (2 * meas.n_observed()) as f64;
    let k = projective::degrees_of_freedom(nf, np);
    let (delta, _) = crate::robust::delta_chi2(c.rms, pf.rms_px, n, k);
    // Akaike's 2 per parameter rather than the BIC's ln n: the pre-test only skips work,
    // so it skips only when even the lenient criterion sees nothing. Without perspective
    // Δχ² is about χ² with 3F − 3 degrees of freedom (mean 3F − 3): twice the mean is
    // over 5 standard deviations, √(2(3F − 3)), above it for F ≥ 10.
    let threshold = 2.0 * (3 * nf).saturating_sub(3).max(1) as f64;
    (delta.is_finite() && threshold.is_finite()).then_some((delta, threshold, c.rms, pf.rms_px))
}

/// The automatic choice's projective pre-test on the sparse path: up to three windows of
/// [`crate::projective::windowed::WindowConfig::window`] frames (the first, the middle and
/// the last) are each fitted by the affine completion — started from `model`'s cameras,
/// the sparse fit's — and the projective camera on their
/// tracks seen in at least 3 of their frames ([`part_pretest`]); their `Δχ²` and
/// thresholds are summed. Returns the scaled orthographic
/// choice when the windows together show no significant perspective — the perspective
/// stages (every window of the sequence fitted, chained and adjusted) are then skipped —
/// and `None` when they do, or when a window cannot be fitted (the perspective stages then
/// decide, as before). Cost: three small dense fits, independent of the length.
fn sparse_pretest(
    kept: &TrackTable,
    inl: &[usize],
    model: &MetricModel,
    config: &Config,
) -> Option<ModelSelection> {
    let nf = kept.n_frames();
    let w = config.sparse.window.window.max(2).min(nf);
    let count = if nf >= 3 * w { 3 } else { (nf / w).max(1) };
    let mut starts: Vec<usize> = (0..count)
        .map(|i| {
            if count == 1 {
                0
            } else {
                i * (nf - w) / (count - 1)
            }
        })
        .collect();
    starts.dedup();
    let (mut delta, mut threshold, mut n_obs) = (0.0, 0.0, 0usize);
    let (mut ss_a, mut ss_p, mut n_scalars) = (0.0, 0.0, 0.0);
    for &a in &starts {
        let frames: Vec<usize> = (a..a + w).collect();
        let window = kept.select(&frames, inl);
        let (ptr, _) = window.by_track();
        let local: Vec<usize> = (0..inl.len())
            .filter(|&j| ptr[j + 1] - ptr[j] >= 3)
            .collect();
        let all_rows: Vec<usize> = (0..w).collect();
        let meas = window.select(&all_rows, &local).measurements();
        // The window's affine completion starts from the fitted cameras' rows: from its
        // own data-driven start it can stop in a local minimum, and the projective camera
        // then "explains" the difference (a 100-frame orthographic corridor: one window at
        // affine RMS 1.37 px, Δχ² 5 853 against 234).
        let start = (model.n_frames() == nf).then(|| {
            let m = Mat::from_fn(2 * w, 3, |r, k| model.camera_row(a + r / 2, r % 2)[k]);
            let t = (0..2 * w)
                .map(|r| model.translations[a + r / 2][r % 2])
                .collect();
            (m, t)
        });
        let (d, t, affine_rms, projective_rms) = part_pretest(&meas, config, start)?;
        delta += d;
        threshold += t;
        n_obs += meas.n_observed();
        let n = (2 * meas.n_observed()) as f64;
        ss_a += affine_rms * affine_rms * n;
        ss_p += projective_rms * projective_rms * n;
        n_scalars += n;
    }
    if delta > threshold {
        return None;
    }
    let (affine_rms, projective_rms) = ((ss_a / n_scalars).sqrt(), (ss_p / n_scalars).sqrt());
    Some(ModelSelection::affine_by_parts(
        (delta, threshold, affine_rms, projective_rms),
        &format!(
            "{} window(s) of {w} frames ({n_obs} observations)",
            starts.len()
        ),
    ))
}

/// σ4/σ3 of the largest complete block of a partial table: a window of consecutive (fit)
/// frames and the tracks seen in all of them, centred. Windows of `F`, 40, 20, 10 and 5
/// frames (those not longer than `F`) are slid by a quarter of their length; the block with
/// the most observations (at least 2 frames × 4 tracks) wins. Returns `(ratio, frames,
/// tracks, first frame)`. The rank diagnostic of complete data, made available to partial
/// tracks (a video's): a rank-3 completion has no σ4. Each track's runs of consecutive
/// visible frames are listed once; for each window length a difference array over the
/// window starts counts the tracks whose run covers the window, `O(runs + F)`, plus one
/// truncated SVD of the block.
fn complete_block_rank_ratio(
    meas: &Measurements,
    svd_cfg: &TruncatedSvdConfig,
) -> Option<(f64, usize, usize, usize)> {
    let (nf, np) = (meas.n_frames(), meas.n_points());
    // (first, end) of every run of consecutive visible frames, with its track.
    let mut runs: Vec<(usize, usize, usize)> = Vec::new();
    for p in 0..np {
        let mut f = 0;
        while f < nf {
            if meas.is_visible(f, p) {
                let a = f;
                while f < nf && meas.is_visible(f, p) {
                    f += 1;
                }
                runs.push((a, f, p));
            } else {
                f += 1;
            }
        }
    }
    let mut best: Option<(usize, usize, usize)> = None; // (observations, start, len)
    for len in [nf, 40, 20, 10, 5] {
        if len > nf || len < 2 {
            continue;
        }
        // covered[s] = tracks seen in every frame of [s, s + len).
        let mut diff = vec![0i64; nf + 1];
        for &(a, b, _) in runs.iter().filter(|r| r.1 - r.0 >= len) {
            diff[a] += 1;
            diff[b - len + 1] -= 1;
        }
        let mut covered = vec![0usize; nf];
        let mut acc = 0i64;
        for (c, d) in covered.iter_mut().zip(&diff) {
            acc += d;
            *c = acc as usize;
        }
        let step = (len / 4).max(1);
        let mut start = 0;
        loop {
            let n = covered[start];
            if n >= 4 && best.is_none_or(|b| n * len > b.0) {
                best = Some((n * len, start, len));
            }
            if start + len >= nf {
                break;
            }
            start = (start + step).min(nf - len);
        }
    }
    let (_, f0, len) = best?;
    let tracks: Vec<usize> = runs
        .iter()
        .filter(|&&(a, b, _)| a <= f0 && f0 + len <= b)
        .map(|&(_, _, p)| p)
        .collect();
    let rows = 2 * len;
    let mean: Vec<f64> = (0..rows)
        .map(|r| tracks.iter().map(|&p| meas.w[(2 * f0 + r, p)]).sum::<f64>() / tracks.len() as f64)
        .collect();
    let block = Mat::from_fn(rows, tracks.len(), |r, k| {
        meas.w[(2 * f0 + r, tracks[k])] - mean[r]
    });
    let svd = svd::truncated_svd(block.as_ref(), 4, svd_cfg).ok()?;
    let s = &svd.s;
    (s.len() >= 4 && s[2] > 0.0).then(|| (s[3] / s[2], len, tracks.len(), f0))
}

/// [`PerspectiveResult::rotation_parallax_px`] at most this many times the fit's RMS: the
/// camera only rotates. The largest median transfer distance of a camera that only rotates
/// is about `1.7 σ` (the distance between two noisy positions, `σ` per coordinate), the
/// fit's RMS about `σ`; 3 leaves room for the largest of many pairs' medians and for a
/// translation too small to show above the noise.
pub const ROTATION_ONLY_FACTOR: f64 = 3.0;

/// Refits the projective verdict may ask for (each a full fit of the new selection).
const PROJECTIVE_VERDICT_ROUNDS: usize = 5;

/// The projective verdict ([`projective::verdict::judge`]) on every kept track, over the
/// fit's frames: (inlier per kept track, flagged entries in kept indices, σ_e, τ_e).
fn projective_verdict(
    kept: &TrackTable,
    fitted: &Fitted,
    pf: &projective::ProjectiveFit,
    flagged: &[(usize, usize)],
    rc: &RobustConfig,
) -> (Vec<bool>, Vec<(usize, usize)>, f64, f64) {
    let all: Vec<usize> = (0..kept.n_tracks()).collect();
    let meas_sub = kept.select(&fitted.fit_frames, &all).measurements();
    let mut frame_pos = vec![usize::MAX; kept.n_frames()];
    for (k, &f) in fitted.fit_frames.iter().enumerate() {
        frame_pos[f] = k;
    }
    let mut in_fit = vec![false; kept.n_tracks()];
    for &k in &fitted.fit_tracks {
        in_fit[fitted.inlier_idx[k]] = true;
    }
    let sub_flags: Vec<(usize, usize)> = flagged
        .iter()
        .filter(|&&(f, _)| frame_pos[f] != usize::MAX)
        .map(|&(f, p)| (frame_pos[f], p))
        .collect();
    let v = projective::verdict::judge(&meas_sub, &pf.model, &in_fit, &sub_flags, rc);
    let flags = v
        .flagged
        .iter()
        .map(|&(f, p)| (fitted.fit_frames[f], p))
        .collect();
    (v.inlier, flags, v.noise_sigma_px, v.entry_threshold_px)
}

/// Whether the projective verdict's only change is to readmit `k` flagged entries too
/// few to move the fit: no track and no new flag (`after ⊂ before`), and the most those
/// entries can add to the fit's cost, `k τ²` (each within the entry threshold `τ` of the
/// current model), within one standard deviation of the cost itself, `σ² √(2ν)` (`ν = 2n
/// − (11F + 3N − 15)` the projective fit's residual degrees of freedom over its `n`
/// observations, `σ` the verdict's entry noise). Refitting for them would move the fit by
/// less than its noise; they stay flagged. A long sequence's last refit was for 2 such
/// entries out of 142 712 observations (800 frames), a seventh of the run. `Some(k)` when
/// so. `meas`: the fit's observations. `O(k log k)` for the `k` flags.
fn readmission_within_noise(
    before: &[(usize, usize)],
    after: &[(usize, usize)],
    sigma: f64,
    tau: f64,
    meas: &Measurements,
) -> Option<usize> {
    let mut b = before.to_vec();
    b.sort_unstable();
    if after.len() >= b.len() || !after.iter().all(|e| b.binary_search(e).is_ok()) {
        return None;
    }
    let k = b.len() - after.len();
    let dof = projective::degrees_of_freedom(meas.n_frames(), meas.n_points());
    let nu = (2 * meas.n_observed()).saturating_sub(dof) as f64;
    (k as f64 * tau * tau <= sigma * sigma * (2.0 * nu).sqrt()).then_some(k)
}

/// Fewest tracks a frame must see: `min_points_per_frame`, at least 4 with missing data
/// (an affine camera estimated jointly with its translation has 4 unknowns per row), at
/// least 6 for the projective camera (11 degrees of freedom, 2 equations per track).
///
/// The automatic choice keeps every frame the affine camera can use — where the projective
/// stages lack tracks it keeps the affine camera instead (`fit_selection`) — except on a
/// long sequence where only a few frames (at most 1 %) see 4 or 5 tracks: those frames are
/// set aside (reported), so that the perspective camera is still tried. Before, two such
/// frames of a 400-frame handheld arc kept the whole sequence affine (structure error
/// 10.0 % against 0.33 % in perspective; docs/results.md).
fn min_points_per_frame(config: &Config, table: &TrackTable) -> usize {
    let mut m = config.min_points_per_frame;
    if !table.is_complete() {
        m = m.max(4);
    }
    if config.camera.is_projective() && config.camera != CameraModel::Auto {
        m = m.max(6);
    } else if config.camera == CameraModel::Auto && m < 6 {
        let nf = table.n_frames();
        let starved = (0..nf)
            .filter(|&f| (m..6).contains(&table.frame_len(f)))
            .count();
        if starved > 0 && starved <= nf / 100 {
            m = 6;
        }
    }
    m
}

fn check_size(t: &TrackTable) -> Result<()> {
    if t.n_frames() < 2 {
        return Err(Error::TooFew {
            what: "usable frames (after setting aside under-observed tracks and frames)",
            needed: 2,
            have: t.n_frames(),
        });
    }
    if t.n_tracks() < 4 {
        return Err(Error::TooFew {
            what: "usable tracks (after setting aside under-observed tracks and frames)",
            needed: 4,
            have: t.n_tracks(),
        });
    }
    Ok(())
}

/// The warning that tracks or frames were set aside, if any were.
fn set_aside_warning(set_aside: &[SetAside]) -> Option<String> {
    let count = |kind| set_aside.iter().filter(|s| s.kind == kind).count();
    (!set_aside.is_empty()).then(|| {
        format!(
            "{} track(s) and {} frame(s) set aside (see `set_aside`)",
            count(crate::table::SetAsideKind::Track),
            count(crate::table::SetAsideKind::Frame)
        )
    })
}

fn rms_of(ss: f64, n_pairs: usize) -> f64 {
    if n_pairs > 0 {
        (ss / (2 * n_pairs) as f64).sqrt()
    } else {
        0.0
    }
}

/// Sum of squared residuals and number of observed pairs among `pairs` (frame, track).
/// Per frame and per track: the sum of squared residuals `‖predict(f, p) − w_fp‖²` over
/// the observed pairs and their number — the per-frame and per-track figures of every
/// camera model. One walk of [`Measurements::for_each_observed`] (each frame's sum in
/// track order, each track's in frame order), `O(F·N)`.
struct ResidualSums {
    frames: Vec<(f64, usize)>,
    points: Vec<(f64, usize)>,
}

impl ResidualSums {
    fn new(predict: &impl Fn(usize, usize) -> [f64; 2], meas: &Measurements) -> Self {
        let mut frames = vec![(0.0, 0); meas.n_frames()];
        let mut points = vec![(0.0, 0); meas.n_points()];
        meas.for_each_observed(|f, p| {
            let q = predict(f, p);
            let (dx, dy) = (q[0] - meas.w[(2 * f, p)], q[1] - meas.w[(2 * f + 1, p)]);
            // (`ss + dx² + dy²`, the order of the sums before the one walk.)
            for acc in [&mut frames[f], &mut points[p]] {
                acc.0 = acc.0 + dx * dx + dy * dy;
                acc.1 += 1;
            }
        });
        Self { frames, points }
    }
}

/// The fit's tracks and the outlier tracks, as the result blocks list them.
struct TrackSets<'a> {
    fit: &'a TrackTable,
    /// Input index of each fit track.
    used_tracks: &'a [usize],
    kept: &'a TrackTable,
    /// Input index of each kept track.
    kept_tracks: &'a [usize],
    /// Kept-table indices of the outlier tracks.
    outlier_kept: &'a [usize],
}

/// Point results in the input's track order: the fit's tracks and the outlier tracks
/// interleaved, each with its 3D point (`(residual sums, xyz)` of the fit's tracks and of the
/// outlier tracks) and its reprojection RMS.
fn point_results(
    t: &TrackSets<'_>,
    fitted: (&ResidualSums, impl Fn(usize) -> Vector3<f64>),
    outliers: (&ResidualSums, impl Fn(usize) -> Vector3<f64>),
) -> Vec<PointResult> {
    let result = |track: Id, x: Vector3<f64>, inlier: bool, (ss, n): (f64, usize)| PointResult {
        track,
        xyz: [x[0], x[1], x[2]],
        inlier,
        rms_px: rms_of(ss, n),
        n_observations: n,
    };
    let mut points: Vec<(usize, PointResult)> =
        Vec::with_capacity(t.used_tracks.len() + t.outlier_kept.len());
    for (p, &input_p) in t.used_tracks.iter().enumerate() {
        let r = fitted.0.points[p];
        points.push((
            input_p,
            result(t.fit.track_ids()[p].clone(), fitted.1(p), true, r),
        ));
    }
    for (k, &p) in t.outlier_kept.iter().enumerate() {
        let r = outliers.0.points[k];
        points.push((
            t.kept_tracks[p],
            result(t.kept.track_ids()[p].clone(), outliers.1(k), false, r),
        ));
    }
    points.sort_by_key(|(i, _)| *i);
    points.into_iter().map(|(_, p)| p).collect()
}

/// [`MetricModel::project`] as a predictor for [`residual_sum`].
fn metric_predictor(model: &MetricModel) -> impl Fn(usize, usize) -> [f64; 2] + '_ {
    move |f, p| {
        let q = model.project(f, p);
        [q[0], q[1]]
    }
}

/// The affine prediction `M̂Ŝ + t1ᵀ` of a fit, in the input's image coordinates
/// (`x ← aspect · x + origin_x`, `y ← y + origin_y`), computed entry by entry: `O(F + N)`
/// memory instead of a 2F×N matrix, three multiply-adds per entry.
#[derive(Debug, Clone)]
pub struct AffinePrediction {
    /// `M̂`, 2F×3 (or 2F×k for a rank-k model).
    pub m: Mat<f64>,
    /// `Ŝ`, 3×N.
    pub s: Mat<f64>,
    /// `t`, 2F.
    pub t: Vec<f64>,
    /// Pixel aspect ratio applied to x, and the image origin added, after the product.
    pub aspect: f64,
    pub origin: [f64; 2],
}

impl Default for AffinePrediction {
    fn default() -> Self {
        Self {
            m: Mat::zeros(0, 0),
            s: Mat::zeros(0, 0),
            t: Vec::new(),
            aspect: 1.0,
            origin: [0.0, 0.0],
        }
    }
}

impl AffinePrediction {
    /// Rows (2F) and columns (N).
    pub fn shape(&self) -> (usize, usize) {
        (self.m.nrows(), self.s.ncols())
    }

    /// Entry `(r, p)`: row `r` (x of frame `r/2` when even, y when odd), track `p`.
    #[inline]
    pub fn value(&self, r: usize, p: usize) -> f64 {
        let mut v = self.t[r];
        for k in 0..self.m.ncols() {
            v += self.m[(r, k)] * self.s[(k, p)];
        }
        if r.is_multiple_of(2) {
            self.aspect * v + self.origin[0]
        } else {
            v + self.origin[1]
        }
    }

    /// The whole 2F×N matrix.
    pub fn to_mat(&self) -> Mat<f64> {
        let (rows, cols) = self.shape();
        Mat::from_fn(rows, cols, |r, p| self.value(r, p))
    }
}

/// Affine factorization from a completion (`W ≈ M̂Ŝ + t1ᵀ` on observed entries). The
/// singular values reported are those of the centered rank-3 fit `M̂Ŝ`.
fn factorization_from_completion(meas: &Measurements, c: completion::Completion) -> Result<Affine> {
    if c.m.ncols() != 3 {
        return Err(Error::InvalidConfig {
            field: "completion.model",
            message: format!(
                "the metric upgrade needs the affine model (rank 3 + translation), got {}",
                crate::output::spelled(&c.model)
            ),
        });
    }
    let pred = c.predict();
    let rms = meas.rms(pred.as_ref());
    // σ of M̂Ŝ = σ of R_M R_Sᵀ from thin QRs: 3×3, cheap.
    let qm = c.m.qr();
    let st = c.s.transpose().to_owned();
    let qs = st.qr();
    let small = qm.R() * qs.R().transpose();
    let mut singular_values: Vec<f64> = small.singular_values().unwrap_or_default();
    singular_values.sort_by(|a, b| b.total_cmp(a));
    Ok(Affine {
        m_hat: c.m,
        s_hat: c.s,
        t: c.t,
        singular_values,
        report: FactorizationReport {
            method: format!("completion ({})", c.solver.name()),
            svd_method: "none".into(),
            svd_fallback_reason: None,
            rms_px: rms,
        },
    })
}

/// Least-squares affine points `ŝ_p = argmin Σ_f ‖M̂_f ŝ + t_f − w_fp‖²` for every track of
/// `meas` (the same frames as `affine`); NaN for tracks seen in fewer than 2 frames.
fn affine_points(meas: &Measurements, affine: &Affine) -> Mat<f64> {
    let mut out = Mat::from_fn(3, meas.n_points(), |_, _| f64::NAN);
    for p in 0..meas.n_points() {
        let mut ata = nalgebra::Matrix3::<f64>::zeros();
        let mut atb = Vector3::<f64>::zeros();
        let mut n = 0;
        for f in 0..meas.n_frames() {
            if !meas.is_visible(f, p) {
                continue;
            }
            n += 1;
            for r in [2 * f, 2 * f + 1] {
                let a = Vector3::new(
                    affine.m_hat[(r, 0)],
                    affine.m_hat[(r, 1)],
                    affine.m_hat[(r, 2)],
                );
                ata += a * a.transpose();
                atb += a * (meas.w[(r, p)] - affine.t[r]);
            }
        }
        if n >= 2
            && let Some(ch) = ata.cholesky()
        {
            let x = ch.solve(&atb);
            for k in 0..3 {
                out[(k, p)] = x[k];
            }
        }
    }
    out
}

fn validate_config(c: &Config) -> Result<()> {
    c.projective.validate()?;
    c.perspective.validate()?;
    c.sparse.lm.validate("sparse.lm")?;
    if let Some(a) = c.aspect_ratio
        && !(a.is_finite() && a > 0.0)
    {
        return Err(Error::InvalidConfig {
            field: "aspect-ratio",
            message: format!("must be a positive number, got {a}"),
        });
    }
    if c.min_frames_per_track < 2 {
        return Err(Error::InvalidConfig {
            field: "min_frames_per_track",
            message: format!(
                "{} < 2: a track seen once has no depth",
                c.min_frames_per_track
            ),
        });
    }
    if c.min_points_per_frame < 3 {
        return Err(Error::InvalidConfig {
            field: "min_points_per_frame",
            message: format!(
                "{} < 3: a frame's camera needs at least 3 points",
                c.min_points_per_frame
            ),
        });
    }
    if !(c.metric.pd_tolerance >= 0.0 && c.metric.pd_tolerance < 1.0) {
        return Err(Error::InvalidConfig {
            field: "metric.pd_tolerance",
            message: format!("{} is not in [0, 1)", c.metric.pd_tolerance),
        });
    }
    Ok(())
}

/// Centering trick + rank-3 truncation for complete measurements.
fn factorize_complete(meas: &Measurements, cfg: &TruncatedSvdConfig) -> Result<Affine> {
    let (rows, n) = (meas.w.nrows(), meas.w.ncols());
    // Row means, summed column by column (each row's sum still in track order).
    let mut t = vec![0.0; rows];
    for p in 0..n {
        for (tr, &w) in t.iter_mut().zip(meas.w.col(p).iter()) {
            *tr += w;
        }
    }
    t.iter_mut().for_each(|tr| *tr /= n as f64);
    let centered = Mat::from_fn(rows, n, |r, p| meas.w[(r, p)] - t[r]);
    let svd = svd::truncated_svd(centered.as_ref(), 4, cfg)?;
    // Rank < 3 up to rounding: σ3 at the level of σ1's rounding errors.
    if svd.s.len() < 3 || !(svd.s[2] > 1e-10 * svd.s[0]) {
        return Err(Error::Degenerate(format!(
            "the centered observation matrix has rank < 3 (singular values {:?}): the points \
             or the motion do not span 3D",
            svd.singular_values.iter().take(4).collect::<Vec<_>>()
        )));
    }
    let m_hat = Mat::from_fn(rows, 3, |r, k| svd.u[(r, k)] * svd.s[k].sqrt());
    let s_hat = Mat::from_fn(3, n, |k, p| svd.v[(p, k)] * svd.s[k].sqrt());
    // The prediction's RMS entry by entry (no 2F×N matrix).
    let pred =
        |r: usize, p: usize| t[r] + (0..3).map(|k| m_hat[(r, k)] * s_hat[(k, p)]).sum::<f64>();
    let rms = meas.rms_of(|f, p| [pred(2 * f, p), pred(2 * f + 1, p)]);
    Ok(Affine {
        m_hat,
        s_hat,
        t,
        report: FactorizationReport {
            method: "svd".into(),
            svd_method: match svd.method {
                SvdMethod::Thin => "thin".into(),
                SvdMethod::Gram => "gram".into(),
                SvdMethod::Randomized { .. } => "randomized".into(),
            },
            svd_fallback_reason: svd.fallback_reason,
            rms_px: rms,
        },
        singular_values: svd.singular_values,
    })
}

/// Metric cameras from `M = M̂Q` projected onto (scaled) rotations, translations from the
/// affine fit, points by least squares given the cameras (falling back to `Q⁻¹Ŝ` where a
/// point's geometry is degenerate).
fn initial_model(
    meas: &Measurements,
    affine: &Affine,
    up: &MetricUpgrade,
    camera: CameraModel,
) -> Result<MetricModel> {
    let q = up.q;
    let mut model = metric::cameras(affine.m_hat.as_ref(), &q, &affine.t, camera)?;
    let qinv = q.try_inverse().ok_or_else(|| Error::Numerical {
        stage: "metric upgrade",
        message: "Q is singular".into(),
    })?;
    model.points = (0..meas.n_points())
        .map(|p| {
            qinv * Vector3::new(
                affine.s_hat[(0, p)],
                affine.s_hat[(1, p)],
                affine.s_hat[(2, p)],
            )
        })
        .collect();
    model.triangulate(meas);
    Ok(model)
}

/// [`crate::sparse::Pipeline::Auto`] treats a table of at least this many frames …
/// (two overlapping windows of the sparse start: 40 frames and a stride of 20). Measured on
/// corridors (`sparse_scaling --compare`, tracks alive ~30 frames): at 100 frames and 300,
/// 650 or 1 000 tracks per frame the dense pipeline's completion stopped at its iteration
/// cap and ended at 70–97 % structure error (RMS 1.4–2.6 px), where the sparse one reached
/// the noise floor (0.47–0.52 %); at 60 and 80 frames both reached the same optimum, the
/// sparse one 5–18× faster (docs/results.md). It was 120 before.
const BANDED_MIN_FRAMES: usize = 60;
/// … filled below this fraction as a video of short tracks: the sparse pipeline.
const BANDED_MAX_FILL: f64 = 0.25;

/// Why the sparse pipeline runs for `kept` (None: the dense one runs), or a
/// [`Error::TooLarge`] when the dense pipeline is forced on a table it cannot hold.
fn sparse_reason(kept: &TrackTable, config: &Config) -> Result<Option<String>> {
    use crate::budget;
    use crate::sparse::Pipeline;
    let dense = kept.dense_bytes();
    let own = kept
        .n_observed()
        .saturating_mul(budget::OBSERVATION_BYTES)
        .saturating_mul(budget::DENSE_TABLE_FACTOR);
    let table_fits = dense <= budget::DENSE_TABLE_BYTES || dense <= own;
    let f = kept.n_frames();
    match config.sparse.pipeline {
        Pipeline::Sparse => Ok(Some("asked for (pipeline = sparse)".into())),
        Pipeline::Dense if !table_fits => Err(Error::TooLarge {
            what: format!(
                "the dense track table ({} frames × {} tracks, {} observations, {:.3} % filled)",
                f,
                kept.n_tracks(),
                kept.n_observed(),
                100.0 * kept.fill()
            ),
            needed_bytes: dense,
            budget_bytes: budget::DENSE_TABLE_BYTES.max(own),
            advice: "use the sparse pipeline (--pipeline auto or sparse)".into(),
        }),
        Pipeline::Dense => Ok(None),
        Pipeline::Auto if !table_fits => Ok(Some(format!(
            "the dense {f}×{} table would take {:.2} GiB for {} observations ({:.3} % filled)",
            kept.n_tracks(),
            dense as f64 / (1u64 << 30) as f64,
            kept.n_observed(),
            100.0 * kept.fill()
        ))),
        // A long table whose tracks are short (a video): the dense pipeline's RANSAC pass
        // needs tracks that span the sequence and finds no rigid majority, and its affine
        // completion drifts (docs/math.md §13). The perspective camera asked for keeps the
        // dense pipeline while the table fits it (its sparse path, which `auto` tries,
        // chains windows and can fail where the dense one does not).
        Pipeline::Auto
            if f >= BANDED_MIN_FRAMES
                && kept.fill() < BANDED_MAX_FILL
                && config.camera != CameraModel::Perspective =>
        {
            Ok(Some(format!(
                "a long sequence of short tracks ({f} frames, {:.1} % filled): the dense \
                 pipeline needs tracks that span the sequence",
                100.0 * kept.fill()
            )))
        }
        Pipeline::Auto => Ok(None),
    }
}

/// The table left after setting aside, with its indices into the input.
struct Kept<'a> {
    table: &'a TrackTable,
    frames: Vec<usize>,
    tracks: Vec<usize>,
    set_aside: Vec<SetAside>,
    /// The input's coordinates of `table`'s origin ([`degeneracy::check`]): `table` holds
    /// the input's positions minus `origin`.
    origin: [f64; 2],
}

/// `config` with the principal point in the coordinates of a table moved by `−origin` and
/// whose x axis is divided by `aspect`: a given principal point is moved with it, and the
/// image centre of a given image size is given explicitly (the second value says so, for
/// [`restore_image_frame`] to name its source again). `None` when no setting depends on the
/// image origin.
fn centred_config(config: &Config, origin: [f64; 2], aspect: f64) -> (Option<Config>, bool) {
    let k = &config.perspective.intrinsics;
    let (pp, from_size) = match (k.principal_point, k.image_size) {
        (Some(c), _) => (c, false),
        // The image centre `perspective::assumed_frame_of` takes.
        (None, Some([w, h])) => ([(w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0], true),
        (None, None) => return (None, false),
    };
    let mut c = config.clone();
    c.perspective.intrinsics.principal_point =
        Some([(pp[0] - origin[0]) / aspect, pp[1] - origin[1]]);
    (Some(c), from_size)
}

/// [`Reconstruction::aspect_ratio_source`] when nothing is known about the pixels.
pub const SQUARE_PIXELS: &str = "square pixels";

/// Moves a reconstruction computed on a table translated by `−origin`, its x axis then
/// divided by `aspect` ([`Config::aspect_ratio`] of `config`, 1 when `None`), back to the
/// input's image coordinates (`x ← aspect·x + origin`):
/// the cameras' translations and x rows, the affine predictions, the projective cameras
/// (`P ← [diag(aspect, 1) origin; 0 1] P`, renormalised to unit Frobenius norm) and the
/// perspective intrinsics. Rotations, scales, points and residuals do not depend on the
/// image frame (residuals stay in square pixels). `O(F·N)` for the predictions.
fn restore_image_frame(
    rec: &mut Reconstruction,
    origin: [f64; 2],
    config: &Config,
    pp_from_image_size: bool,
) {
    let aspect = config.aspect_ratio.unwrap_or(1.0);
    rec.aspect_ratio = aspect;
    let source = match (&config.aspect_ratio_source, config.aspect_ratio) {
        (_, None) => SQUARE_PIXELS.to_string(),
        (Some(s), Some(_)) => s.clone(),
        (None, Some(_)) => "given".to_string(),
    };
    rec.aspect_ratio_source = source.clone();
    if origin == [0.0, 0.0] && aspect == 1.0 {
        return;
    }
    // An image position `v` of the fit's frame in the input's: `diag(aspect, 1) v + origin`.
    let to_input = |v: &mut [f64]| {
        v[0] = aspect * v[0] + origin[0];
        v[1] += origin[1];
    };
    for f in &mut rec.frames {
        to_input(&mut f.translation);
    }
    for m in [&mut rec.model, &mut rec.outlier_model] {
        m.aspect *= aspect;
        m.translations
            .iter_mut()
            .for_each(|t| to_input(t.as_mut_slice()));
    }
    let a = &mut rec.affine_prediction;
    a.origin = [aspect * a.origin[0] + origin[0], a.origin[1] + origin[1]];
    a.aspect *= aspect;
    let m = &mut rec.outlier_prediction;
    for j in 0..m.ncols() {
        for r in (0..m.nrows()).step_by(2) {
            m[(r, j)] = aspect * m[(r, j)] + origin[0];
            m[(r + 1, j)] += origin[1];
        }
    }
    if let Some(pr) = &mut rec.projective {
        // The table's coordinates are the input's minus `origin`, x then divided by
        // `aspect`: `P ← [I₂ origin; 0 1] diag(aspect, 1, 1) P`.
        let shift = projective::Normalization {
            centre: origin,
            scale: 1.0,
        };
        for c in &mut pr.model.cameras {
            c[..4].iter_mut().for_each(|v| *v *= aspect);
            *c = shift.camera_to_pixels(c);
            projective::bundle::normalize(c);
        }
        if pr.cameras.len() == pr.model.cameras.len() {
            for (f, cam) in pr.cameras.iter_mut().enumerate() {
                cam.p = pr.model.camera_matrix(f);
            }
        }
    }
    if let Some(pe) = &mut rec.perspective {
        pe.model.aspect *= aspect;
        to_input(&mut pe.model.principal_point);
        let k = &mut pe.intrinsics;
        to_input(&mut k.principal_point);
        k.k[0][0] *= aspect;
        k.k[0][2] = k.principal_point[0];
        k.k[1][2] = k.principal_point[1];
        k.aspect_ratio *= aspect;
        if aspect != 1.0 && k.aspect_ratio_source == SQUARE_PIXELS {
            k.aspect_ratio_source = source;
        }
        if pp_from_image_size && k.principal_point_source == "given" {
            k.principal_point_source = "image centre";
        }
        if let Some(r) = &mut k.principal_point_rejected {
            to_input(&mut r.principal_point);
        }
    }
}

/// The warning for a principal point estimate the perspective adjustment rejected, in the
/// input's image coordinates (after [`restore_image_frame`]).
fn warn_rejected_principal_point(rec: &mut Reconstruction) {
    if let Some(pe) = &rec.perspective
        && let Some(r) = &pe.intrinsics.principal_point_rejected
    {
        let w = r.warning(pe.intrinsics.principal_point);
        rec.warnings.push(w);
    }
}

/// The sparse pipeline ([`crate::sparse`]) and its [`Reconstruction`]: frames, points,
/// metric upgrade and reports; the dense-only parts are empty (`affine_prediction` 0×0,
/// no completed matrix).
fn sparse_reconstruction(
    table: &TrackTable,
    kept: Kept<'_>,
    config: &Config,
    mut timer: Timer<'_>,
    reason: String,
    mut warnings: Vec<String>,
) -> Result<Reconstruction> {
    let Kept {
        table: kept,
        frames: kept_frames,
        tracks: kept_tracks,
        set_aside,
        ..
    } = kept;
    warnings.insert(
        0,
        format!(
            "sparse pipeline: {reason}; the dense-only stages (RANSAC robust pass, σ4/σ3, \
             metric refinement, completed.txt) do not run"
        ),
    );
    let affine_camera = config.camera.affine();
    let t0 = Instant::now();
    let (prob, fit) = timer.run("sparse-fit", |obs| {
        crate::sparse::fit(kept, &config.sparse, affine_camera, obs)
    })?;
    if let Some(n) = &fit.note {
        warnings.push(format!("sparse pipeline: {n}"));
    }
    if fit.report.status != SolverStatus::Converged {
        warnings.push(format!(
            "sparse bundle adjustment ended with status {} after {} iterations",
            crate::output::spelled(&fit.report.status),
            fit.report.iterations
        ));
    }
    let mut all = prob.metric_model(&fit.cams, &fit.pts);
    // The metric upgrade of the adjusted cameras' rows: a check (Q ≈ I up to scale) and
    // the report the dense pipeline gives.
    let m_rows = Mat::from_fn(2 * kept.n_frames(), 3, |r, k| {
        all.scales[r / 2] * all.rotations[r / 2].matrix()[(r % 2, k)]
    });
    let upgrade = timer.run("metric-upgrade", |_| {
        metric::upgrade(m_rows.as_ref(), affine_camera, &config.metric)
    })?;
    let nf = kept.n_frames();
    prob.triangulate(&mut all);
    let mirrored = metric::apply_necker_convention(&mut all);
    let inlier = &fit.inlier;
    // Frames' residuals over the fit's (inlier) tracks, every track's own.
    let (frame_fit, track_res) = prob.residuals(&all, inlier);
    let inl: Vec<usize> = (0..kept.n_tracks()).filter(|&p| inlier[p]).collect();
    let out: Vec<usize> = (0..kept.n_tracks()).filter(|&p| !inlier[p]).collect();
    let (ss, n): (f64, usize) = inl.iter().fold((0.0, 0), |(s, n), &p| {
        (s + track_res[p].0, n + track_res[p].1)
    });
    let metric_rms_px = rms_of(ss, n);
    // The perspective camera on the sparse path (perspective::fit_observations), asked for
    // or tried by the automatic choice, on the tracks the scaled orthographic fit kept.
    let mut camera_model = affine_camera;
    let mut model_selection = None;
    let mut perspective = None;
    let pretest = if config.camera == CameraModel::Auto {
        timer.run("projective-pretest", |_| {
            sparse_pretest(kept, &inl, &all, config)
        })
    } else {
        None
    };
    if let Some(sel) = pretest {
        camera_model = sel.chosen;
        model_selection = Some(sel);
    } else if config.camera.is_perspective() {
        let obs = observations_of(kept, &inl);
        let n_obs = obs.len();
        let per = timer.run("perspective", |o| {
            perspective::fit_observations(
                &obs,
                nf,
                inl.len(),
                &config.perspective,
                &config.projective,
                &config.sparse.window,
                o,
            )
        });
        drop(obs);
        // Nothing is lost when it fails: the scaled orthographic result stands, and says why.
        let per = match per {
            Ok(p) => Some(p),
            Err(e) => {
                warnings.push(format!(
                    "the perspective camera could not be fitted on the sparse path ({e}); the \
                     scaled orthographic camera is kept"
                ));
                None
            }
        };
        let result = per.map(|pf| {
            if pf.report.status != SolverStatus::Converged {
                warnings.push(format!(
                    "perspective bundle adjustment ended with status {} after {} iterations",
                    crate::output::spelled(&pf.report.status),
                    pf.report.iterations
                ));
            }
            if pf.in_front < 0.95 {
                warnings.push(format!(
                    "only {:.1} % of the observations are in front of their camera: the \
                     perspective reconstruction is unreliable (weak perspective or degenerate \
                     motion)",
                    100.0 * pf.in_front
                ));
            }
            PerspectiveResult::from_sparse(pf, &config.perspective, kept, &inl, &out)
        });
        if config.camera == CameraModel::Auto {
            let sel = ModelSelection::judge(metric_rms_px, result.as_ref(), n_obs, nf, inl.len());
            camera_model = sel.chosen;
            if sel.chosen == CameraModel::Perspective {
                perspective = result;
            }
            model_selection = Some(sel);
        } else if result.is_some() {
            camera_model = CameraModel::Perspective;
            perspective = result;
        }
    }
    // The projective camera on the sparse path (projective::fit_observations: projective
    // windows chained by homographies, then the sparse projective bundle adjustment), on
    // the tracks the scaled orthographic fit kept.
    let mut projective = None;
    if config.camera == CameraModel::Projective {
        let obs = observations_of(kept, &inl);
        let windows = crate::projective::windowed::WindowConfig {
            projective: true,
            ..config.sparse.window.clone()
        };
        let pf = timer.run("projective", |o| {
            projective::fit_observations(&obs, nf, inl.len(), &config.projective, &windows, o)
        });
        drop(obs);
        match pf {
            Ok(pf) => {
                if pf.report.status != SolverStatus::Converged {
                    warnings.push(format!(
                        "projective bundle adjustment ended with status {} after {} iterations",
                        crate::output::spelled(&pf.report.status),
                        pf.report.iterations
                    ));
                }
                camera_model = CameraModel::Projective;
                projective = Some(ProjectiveResult::from_sparse(pf, kept, &inl, &out));
            }
            // Nothing is lost when it fails: the scaled orthographic result stands.
            Err(e) => warnings.push(format!(
                "the projective camera could not be fitted on the sparse path ({e}); the \
                 scaled orthographic camera is kept"
            )),
        }
    }
    let frames: Vec<FrameResult> = (0..nf)
        .map(|f| {
            let r = all.rotations[f].matrix();
            FrameResult {
                frame: kept.frame_ids()[f].clone(),
                rotation: std::array::from_fn(|a| std::array::from_fn(|b| r[(a, b)])),
                translation: [all.translations[f][0], all.translations[f][1]],
                scale: all.scales[f],
                rms_px: rms_of(frame_fit[f].0, frame_fit[f].1),
                n_observations: frame_fit[f].1,
            }
        })
        .collect();
    let points: Vec<PointResult> = (0..kept.n_tracks())
        .map(|p| {
            let x = all.points[p];
            PointResult {
                track: kept.track_ids()[p].clone(),
                xyz: [x[0], x[1], x[2]],
                inlier: inlier[p],
                rms_px: rms_of(track_res[p].0, track_res[p].1),
                n_observations: track_res[p].1,
            }
        })
        .collect();
    let robust = (config.robust.is_some()).then(|| {
        let mut r = RobustReport {
            n_inlier_tracks: 0,
            n_outlier_tracks: 0,
            n_flagged_entries: 0,
            outlier_tracks: Vec::new(),
            flagged_entries: Vec::new(),
            noise_sigma_px: fit.sigma_px,
            threshold_px: fit.threshold_px,
            entry_threshold_px: f64::NAN,
            iterations: fit.rounds,
            projective: None,
            inliers_per_iteration: Vec::new(),
            flagged_indices: Vec::new(),
            rigid_groups_seen: 1,
            other_object_tracks: 0,
            seconds: t0.elapsed().as_secs_f64(),
        };
        r.update(kept, &kept_frames, &kept_tracks, inlier, &[]);
        r
    });
    if !out.is_empty() {
        warnings.push(format!(
            "sparse pipeline: {} outlier track(s) over {:.2} px RMS excluded from the fit",
            out.len(),
            fit.threshold_px
        ));
    }
    warnings.extend(set_aside_warning(&set_aside));
    for w in &warnings {
        timer.observer.on_event(&Event::Warning { message: w });
    }
    let pick = |v: &[usize]| MetricModel {
        rotations: all.rotations.clone(),
        translations: all.translations.clone(),
        scales: all.scales.clone(),
        points: v.iter().map(|&p| all.points[p]).collect(),
        aspect: all.aspect,
    };
    let model = pick(&inl);
    let outlier_model = pick(&out);
    // The structure the factorization gave (metric here: the sparse fit is metric).
    let affine_structure = Mat::from_fn(3, inl.len(), |k, j| all.points[inl[j]][k]);
    let seconds = t0.elapsed().as_secs_f64();
    Ok(Reconstruction {
        camera_model,
        model_selection,
        frames,
        points,
        rms_px: result_rms(perspective.as_ref(), projective.as_ref(), metric_rms_px),
        metric_rms_px,
        metric_upgrade: upgrade,
        singular_values: Vec::new(),
        rank_ratio: f64::NAN,
        rank_ratio_source: "not computed by the sparse pipeline".into(),
        factorization: FactorizationReport {
            method: "sparse-varpro".into(),
            svd_method: "none".into(),
            svd_fallback_reason: None,
            rms_px: fit.rms_px,
        },
        completion: None,
        robust,
        refinement: None,
        projective,
        perspective,
        input: InputSummary {
            frames: table.n_frames(),
            tracks: table.n_tracks(),
            observations: table.n_observed(),
            fill: table.fill(),
            frames_used: nf,
            tracks_used: inl.len(),
        },
        set_aside,
        mirrored,
        warnings,
        timings: timer.timings,
        mesh: None,
        aspect_ratio: 1.0,
        aspect_ratio_source: SQUARE_PIXELS.to_string(),
        sparse: Some(crate::sparse::SparseReport {
            reason,
            observations: prob.graph.n_obs(),
            status: fit.report.status,
            iterations: fit.report.iterations,
            rms_px: fit.rms_px,
            schur_nonzeros: fit.schur_nonzeros,
            extensions: fit.extensions,
            rounds: fit.rounds,
            skipped_windows: fit.skipped_windows,
            seconds,
        }),
        stream: None,
        model,
        affine_structure,
        affine_prediction: AffinePrediction::default(),
        outlier_prediction: Mat::zeros(0, 0),
        outlier_model,
        kept_frames: kept_frames.clone(),
        kept_tracks: inl.iter().map(|&p| kept_tracks[p]).collect(),
        outlier_tracks: out.iter().map(|&p| kept_tracks[p]).collect(),
        input_frame_ids: table.frame_ids().to_vec(),
        input_track_ids: table.track_ids().to_vec(),
    })
}

#[cfg(test)]
mod pretest_tests {
    use super::*;

    /// A 400-frame table of tracks seen in windows of 30–200 frames.
    fn windows(nf: usize, np: usize) -> Measurements {
        let visible: Vec<bool> = (0..nf * np)
            .map(|k| {
                let (f, p) = (k / np, k % np);
                let start = (p * 37) % nf;
                let len = 30 + (p * 13) % 170;
                f >= start && f < start + len
            })
            .collect();
        let w = Mat::from_fn(2 * nf, np, |i, p| (i * 7 + p * 3) as f64);
        Measurements::new(w, visible)
    }

    #[test]
    fn the_pretest_subset_spans_the_sequence_and_covers_every_frame() {
        let meas = windows(400, 3000);
        let (frames, tracks) = pretest_subset(&meas).expect("a subset");
        assert_eq!(frames.len(), PRETEST_FRAMES);
        assert_eq!((frames[0], *frames.last().unwrap()), (0, 399));
        assert!(frames.windows(2).all(|w| w[1] > w[0] && w[1] - w[0] <= 3));
        assert!(tracks.len() >= PRETEST_TRACKS / 2 && tracks.len() < 3000);
        let sub = TrackTable::from_measurements(&meas)
            .select(&frames, &tracks)
            .measurements();
        for (i, &f) in frames.iter().enumerate() {
            let seen = (0..tracks.len()).filter(|&j| sub.is_visible(i, j)).count();
            let available = (0..3000).filter(|&p| meas.is_visible(f, p)).count();
            assert!(
                seen >= PRETEST_PER_FRAME.min(available),
                "frame {f}: {seen} tracks"
            );
            // The subset's entries are the table's.
            for (j, &p) in tracks.iter().enumerate() {
                assert_eq!(sub.is_visible(i, j), meas.is_visible(f, p));
                assert_eq!(sub.w[(2 * i + 1, j)], meas.w[(2 * f + 1, p)]);
            }
        }
        // Only big tables are tested on a subset.
        assert!(projective_iteration_flops(&meas) > PRETEST_FLOPS);
        assert!(projective_iteration_flops(&windows(50, 300)) < PRETEST_FLOPS);
    }
}

#[cfg(test)]
mod set_aside_tests {
    use super::*;

    /// A table of `nf` frames seeing 10 tracks each, except the first `starved` frames,
    /// which see 5.
    fn table(nf: usize, starved: usize) -> TrackTable {
        let mut obs = Vec::new();
        for f in 0..nf {
            let n = if f < starved { 5 } else { 10 };
            for p in 0..n {
                obs.push((f as u32, ((f + p) % 12) as u32, p as f64, f as f64));
            }
        }
        let ids = |n: usize| (0..n).map(Id::from).collect::<Vec<_>>();
        TrackTable::from_observations(ids(nf), ids(12), &obs).unwrap()
    }

    /// The automatic camera sets aside frames with 4 or 5 tracks (so that the perspective
    /// camera can be tried) only when they are at most 1 % of the frames; an affine camera
    /// keeps them, a perspective camera always needs 6.
    #[test]
    fn auto_sets_aside_a_few_frames_the_perspective_camera_cannot_use() {
        let with = |camera| Config {
            camera,
            ..Config::default()
        };
        let auto = with(CameraModel::Auto);
        assert_eq!(min_points_per_frame(&auto, &table(200, 2)), 6);
        assert_eq!(min_points_per_frame(&auto, &table(200, 3)), 4);
        assert_eq!(min_points_per_frame(&auto, &table(50, 1)), 4);
        assert_eq!(min_points_per_frame(&auto, &table(200, 0)), 4);
        let affine = with(CameraModel::ScaledOrthographic);
        assert_eq!(min_points_per_frame(&affine, &table(200, 2)), 4);
        let perspective = with(CameraModel::Perspective);
        assert_eq!(min_points_per_frame(&perspective, &table(50, 10)), 6);
    }

    /// The verdict's readmissions are left unrefitted only when they are all it changed
    /// and `k τ²` is within `σ² √(2ν)`: a complete 200 × 300 table (`ν` = 116 915,
    /// `σ² √(2ν)` = 484 px² at σ = 1 px, τ = 4 px: up to 30 entries).
    #[test]
    fn only_readmissions_within_the_noise_are_left_unrefitted() {
        let meas = Measurements::complete(Mat::zeros(400, 300));
        let before: Vec<(usize, usize)> = (0..40).map(|i| (i, 2 * i)).collect();
        let keep = |k: usize| before[k..].to_vec();
        assert_eq!(
            readmission_within_noise(&before, &keep(2), 1.0, 4.0, &meas),
            Some(2)
        );
        assert_eq!(
            readmission_within_noise(&before, &keep(30), 1.0, 4.0, &meas),
            Some(30)
        );
        assert_eq!(
            readmission_within_noise(&before, &keep(31), 1.0, 4.0, &meas),
            None
        );
        // A new flag, or nothing readmitted: the verdict changed more than readmissions.
        let mut new_flag = keep(2);
        new_flag.push((199, 299));
        assert_eq!(
            readmission_within_noise(&before, &new_flag, 1.0, 4.0, &meas),
            None
        );
        assert_eq!(
            readmission_within_noise(&before, &before, 1.0, 4.0, &meas),
            None
        );
        // A lower noise level leaves less room.
        assert_eq!(
            readmission_within_noise(&before, &keep(2), 0.2, 4.0, &meas),
            None
        );
    }
}
