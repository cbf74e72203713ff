//! Reading `reconstruction.json` back: [`ReconstructionFile`], the document
//! [`crate::Reconstruction::to_json`] writes, with its schema version checked.
//!
//! The document starts with `"schema": "rank3.reconstruction/1"` ([`SCHEMA`]). The reader
//! accepts that version and files without the key (written before it existed, the same
//! layout); it refuses any other schema — a later version of rank3's, or a file that is
//! not a reconstruction — with [`ReadError::UnsupportedSchema`] before reading the rest.
//!
//! JSON has no NaN or infinity: the writer puts `null` where a number is not finite (e.g.
//! `rank_ratio` without a complete block, the coordinates of a point that could not be
//! triangulated), and the reader reads every such `null` back as NaN. Keys the reader does
//! not know are ignored, so a file of the same version with more keys still reads.
//!
//! Frame and track ids keep the type the input gave them ([`Id`]): integers for integer
//! CSV/JSON ids, dense `.txt` matrices, videos and the tracker's tracks; strings for
//! non-integer ids, e.g. the file stems of an image folder (`frame_0007`; a stem `0042`
//! is the integer 42).
//!
//! Every block is typed except the `sparse` and `mesh` reports, kept as JSON values (their
//! layout belongs to [`crate::sparse`] and [`crate::mesh`]; `docs/formats.md` documents
//! them). The tests write reconstructions and check that reading and writing again gives
//! the same document, so a key added to the writer without the reader fails them.

use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;
use serde::{Deserialize, Deserializer, Serialize};

use crate::CameraModel;
use crate::SolverStatus;
use crate::completion::{CompletionModel, CompletionSolverKind};
use crate::metric::UpgradeMethod;
use crate::projective::Start;
use crate::table::{Id, SetAside};

/// The schema this rank3 writes and reads: `"rank3.reconstruction/1"`.
pub const SCHEMA: &str = "rank3.reconstruction/1";

/// The schema's name, before the `/` and its version.
pub const SCHEMA_NAME: &str = "rank3.reconstruction";

/// The schema version this rank3 writes and reads.
pub const SCHEMA_VERSION: u32 = 1;

/// Why a `reconstruction.json` could not be read.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReadError {
    /// The file could not be opened or read.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Not valid JSON, or a key missing or of the wrong type (`line`, `column` 1-based).
    #[error("{}:{line}:{column}: not a valid rank3 reconstruction.json: {message}", path.display())]
    Json {
        path: PathBuf,
        line: usize,
        column: usize,
        message: String,
    },
    /// The `schema` key names another schema or a version this rank3 does not read.
    #[error(
        "{}: schema `{found}` is not supported: this rank3 reads `{supported}`{}",
        path.display(),
        schema_hint(found)
    )]
    UnsupportedSchema {
        path: PathBuf,
        found: String,
        supported: &'static str,
    },
}

fn schema_hint(found: &str) -> &'static str {
    match found
        .strip_prefix(SCHEMA_NAME)
        .and_then(|v| v.strip_prefix('/'))
        .and_then(|v| v.parse::<u32>().ok())
    {
        Some(v) if v > SCHEMA_VERSION => " (the file was written by a newer rank3; update rank3)",
        Some(_) => "",
        None => " (the file is not a rank3 reconstruction)",
    }
}

/// Reads `reconstruction.json` at `path`.
///
/// Errors: [`ReadError::Io`] (missing or unreadable file), [`ReadError::UnsupportedSchema`],
/// [`ReadError::Json`] (with line and column).
pub fn read(path: &Path) -> Result<ReconstructionFile, ReadError> {
    let text = std::fs::read_to_string(path).map_err(|source| ReadError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    from_json_str(&text, path)
}

/// Parses a `reconstruction.json` document; `path` names it in errors.
pub fn from_json_str(text: &str, path: &Path) -> Result<ReconstructionFile, ReadError> {
    let json_err = |e: serde_json::Error| ReadError::Json {
        path: path.to_path_buf(),
        line: e.line(),
        column: e.column(),
        message: e.to_string(),
    };
    #[derive(Deserialize)]
    struct Probe {
        schema: Option<serde_json::Value>,
    }
    let probe: Probe = serde_json::from_str(text).map_err(json_err)?;
    match probe.schema {
        None => {}
        Some(serde_json::Value::String(s)) if s == SCHEMA => {}
        Some(other) => {
            return Err(ReadError::UnsupportedSchema {
                path: path.to_path_buf(),
                found: match other {
                    serde_json::Value::String(s) => s,
                    v => v.to_string(),
                },
                supported: SCHEMA,
            });
        }
    }
    let mut file: ReconstructionFile = serde_json::from_str(text).map_err(json_err)?;
    file.schema = SCHEMA.to_string();
    Ok(file)
}

/// Reads a number that may be `null` (not finite when written) as NaN; arrays and vectors
/// of them element by element.
pub trait Nullable: Sized {
    /// The JSON form, with `Option` where a number may be `null`.
    type Raw: DeserializeOwned;
    /// `None` → NaN.
    fn from_raw(raw: Self::Raw) -> Self;
}

impl Nullable for f64 {
    type Raw = Option<f64>;
    fn from_raw(raw: Option<f64>) -> f64 {
        raw.unwrap_or(f64::NAN)
    }
}

impl<T: Nullable, const N: usize> Nullable for [T; N]
where
    [T::Raw; N]: DeserializeOwned,
{
    type Raw = [T::Raw; N];
    fn from_raw(raw: Self::Raw) -> Self {
        raw.map(T::from_raw)
    }
}

impl<T: Nullable> Nullable for Vec<T> {
    type Raw = Vec<T::Raw>;
    fn from_raw(raw: Self::Raw) -> Self {
        raw.into_iter().map(T::from_raw).collect()
    }
}

impl<T: Nullable> Nullable for Option<T> {
    type Raw = Option<T::Raw>;
    fn from_raw(raw: Self::Raw) -> Self {
        raw.map(T::from_raw)
    }
}

/// `deserialize_with` for [`Nullable`] fields.
fn nullable<'de, D: Deserializer<'de>, T: Nullable>(d: D) -> Result<T, D::Error> {
    T::Raw::deserialize(d).map(T::from_raw)
}

/// `reconstruction.json` as read back (schema [`SCHEMA`]). Serializing it gives the same
/// JSON document it was read from (keys it does not know aside). Every key is documented
/// in `docs/formats.md`, "`DIR/reconstruction.json`".
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReconstructionFile {
    /// [`SCHEMA`] (also for a file that had no `schema` key).
    #[serde(default)]
    pub schema: String,
    /// The camera model of the result (with `auto`, the one chosen).
    pub camera_model: CameraModel,
    /// Present with `--camera auto`.
    pub model_selection: Option<ModelSelectionRecord>,
    /// The metric (affine-family) cameras of the fitted frames.
    pub frames: Vec<FrameRecord>,
    /// The metric (affine-family) points of the fitted tracks and the outlier tracks.
    pub points: Vec<PointRecord>,
    /// RMS reprojection error of the final model, pixels.
    #[serde(deserialize_with = "nullable")]
    pub rms_px: f64,
    /// The same RMS of the metric model in `frames` / `points`, pixels.
    #[serde(deserialize_with = "nullable")]
    pub metric_rms_px: f64,
    pub metric_upgrade: MetricUpgradeRecord,
    #[serde(deserialize_with = "nullable")]
    pub singular_values: Vec<f64>,
    /// σ4/σ3; NaN (`null` in the file) when there was no complete block to compute it on.
    #[serde(deserialize_with = "nullable")]
    pub rank_ratio: f64,
    pub rank_ratio_source: String,
    pub factorization: FactorizationRecord,
    pub completion: Option<CompletionRecord>,
    pub robust: Option<RobustRecord>,
    pub refinement: Option<RefinementRecord>,
    pub projective: Option<ProjectiveRecord>,
    pub perspective: Option<PerspectiveRecord>,
    pub input: InputRecord,
    pub set_aside: Vec<SetAside>,
    pub mirrored: bool,
    pub warnings: Vec<String>,
    pub timings: Vec<TimingRecord>,
    /// The sparse pipeline's report (layout: `docs/formats.md`), kept as JSON.
    pub sparse: Option<serde_json::Value>,
    /// The streaming factorization's report ([`crate::stream::StreamReport`]), kept as
    /// JSON; absent in files written before it existed.
    #[serde(default)]
    pub stream: Option<serde_json::Value>,
    /// The textured mesh's report (layout: `docs/formats.md`), kept as JSON.
    pub mesh: Option<serde_json::Value>,
    /// Aspect ratio of the pixels, `f_x / f_y` (1 in files written before it existed).
    #[serde(default = "one")]
    pub aspect_ratio: f64,
    /// Where the aspect ratio came from (`"square pixels"` in files written before it
    /// existed).
    #[serde(default = "square_pixels")]
    pub aspect_ratio_source: String,
}

fn one() -> f64 {
    1.0
}

impl ReconstructionFile {
    /// The points of the final Euclidean model: the perspective block's with a perspective
    /// result, the metric (affine-family) `points` otherwise.
    pub fn euclidean_points(&self) -> &[PointRecord] {
        self.perspective
            .as_ref()
            .map_or(&self.points, |p| &p.points)
    }

    /// Serializes like [`crate::Reconstruction::to_json`] (pretty JSON).
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"))
    }
}

/// `model_selection`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelSelectionRecord {
    pub chosen: CameraModel,
    #[serde(deserialize_with = "nullable")]
    pub affine_rms_px: f64,
    pub perspective_rms_px: Option<f64>,
    pub perspective_focal_px: Option<f64>,
    #[serde(deserialize_with = "nullable")]
    pub noise_sigma_px: f64,
    #[serde(deserialize_with = "nullable")]
    pub delta_chi2: f64,
    #[serde(deserialize_with = "nullable")]
    pub threshold: f64,
    pub reason: String,
}

/// One entry of `frames`: `[x, y] = scale · rotation[rows 0..2] · xyz + translation`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameRecord {
    pub frame: Id,
    #[serde(deserialize_with = "nullable")]
    pub rotation: [[f64; 3]; 3],
    #[serde(deserialize_with = "nullable")]
    pub translation: [f64; 2],
    #[serde(deserialize_with = "nullable")]
    pub scale: f64,
    #[serde(deserialize_with = "nullable")]
    pub rms_px: f64,
    pub n_observations: usize,
}

/// One entry of `points` (and of `perspective.points`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PointRecord {
    pub track: Id,
    #[serde(deserialize_with = "nullable")]
    pub xyz: [f64; 3],
    pub inlier: bool,
    #[serde(deserialize_with = "nullable")]
    pub rms_px: f64,
    pub n_observations: usize,
}

/// `metric_upgrade`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MetricUpgradeRecord {
    pub method: UpgradeMethod,
    #[serde(deserialize_with = "nullable")]
    pub min_eigenvalue_ls: f64,
    #[serde(deserialize_with = "nullable")]
    pub eigenvalues_ls: [f64; 3],
    #[serde(deserialize_with = "nullable")]
    pub eigenvalues: [f64; 3],
    #[serde(deserialize_with = "nullable")]
    pub l: [[f64; 3]; 3],
    #[serde(deserialize_with = "nullable")]
    pub constraint_rms: f64,
    pub sdp_status: Option<String>,
    pub sdp_iterations: Option<u32>,
}

/// `factorization`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FactorizationRecord {
    pub method: String,
    pub svd_method: String,
    pub svd_fallback_reason: Option<String>,
    #[serde(deserialize_with = "nullable")]
    pub rms_px: f64,
}

/// `completion`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CompletionRecord {
    pub solver: CompletionSolverKind,
    pub model: CompletionModel,
    #[serde(deserialize_with = "nullable")]
    pub rms_px: f64,
    pub status: SolverStatus,
    pub iterations: usize,
    /// ALS sweeps run before `solver` on a big table (absent in files written before it).
    #[serde(default)]
    pub als_sweeps_first: usize,
    pub runs: usize,
    #[serde(deserialize_with = "nullable")]
    pub seconds: f64,
}

/// An entry (frame, track) by id.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EntryRecord {
    pub frame: Id,
    pub track: Id,
}

/// `robust`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RobustRecord {
    pub n_inlier_tracks: usize,
    pub n_outlier_tracks: usize,
    pub n_flagged_entries: usize,
    pub outlier_tracks: Vec<Id>,
    pub flagged_entries: Vec<EntryRecord>,
    #[serde(deserialize_with = "nullable")]
    pub noise_sigma_px: f64,
    #[serde(deserialize_with = "nullable")]
    pub threshold_px: f64,
    #[serde(deserialize_with = "nullable")]
    pub entry_threshold_px: f64,
    pub iterations: usize,
    pub projective: Option<ProjectiveJudgementRecord>,
    pub rigid_groups_seen: usize,
    pub other_object_tracks: usize,
    #[serde(deserialize_with = "nullable")]
    pub seconds: f64,
}

/// `robust.projective`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProjectiveJudgementRecord {
    pub readmitted_tracks: usize,
    pub rejected_tracks: usize,
    pub flagged_before: usize,
    pub flagged_after: usize,
    #[serde(deserialize_with = "nullable")]
    pub noise_sigma_px: f64,
    #[serde(deserialize_with = "nullable")]
    pub entry_threshold_px: f64,
    pub refits: usize,
    /// Absent from files written before 2026-11-29 (read as 0).
    #[serde(default)]
    pub objects_held_out: usize,
    /// Absent from files written before 2026-11-30 (read as 0).
    #[serde(default)]
    pub readmissions_not_refitted: usize,
}

/// `refinement`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RefinementRecord {
    #[serde(deserialize_with = "nullable")]
    pub rms_before_px: f64,
    #[serde(deserialize_with = "nullable")]
    pub rms_after_px: f64,
    pub status: SolverStatus,
    pub iterations: usize,
    #[serde(deserialize_with = "nullable")]
    pub seconds: f64,
    pub skipped: Option<String>,
}

/// One stage of the projective or perspective fit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StageRecord {
    pub stage: String,
    pub status: SolverStatus,
    pub iterations: usize,
    #[serde(deserialize_with = "nullable")]
    pub rms_before_px: f64,
    #[serde(deserialize_with = "nullable")]
    pub rms_after_px: f64,
    #[serde(deserialize_with = "nullable")]
    pub seconds: f64,
    #[serde(default)]
    pub linear_solver: Option<crate::projective::bundle::LinearSolver>,
    #[serde(default)]
    pub cg_iterations: usize,
}

/// `projective`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProjectiveRecord {
    #[serde(deserialize_with = "nullable")]
    pub rms_px: f64,
    pub start: Start,
    pub stages: Vec<StageRecord>,
    pub cameras: Vec<ProjectiveCameraRecord>,
    pub points: Vec<ProjectivePointRecord>,
    pub schur_nnz: usize,
}

/// One entry of `projective.cameras`: `P_f` (3×4, rows), unit Frobenius norm.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProjectiveCameraRecord {
    pub frame: Id,
    #[serde(deserialize_with = "nullable")]
    pub p: [[f64; 4]; 3],
    #[serde(deserialize_with = "nullable")]
    pub rms_px: f64,
    pub n_observations: usize,
}

/// One entry of `projective.points`: homogeneous `X_p`, unit norm (NaN when it could not
/// be triangulated).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProjectivePointRecord {
    pub track: Id,
    #[serde(deserialize_with = "nullable")]
    pub x: [f64; 4],
    pub inlier: bool,
    #[serde(deserialize_with = "nullable")]
    pub rms_px: f64,
    pub n_observations: usize,
}

/// `perspective`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PerspectiveRecord {
    #[serde(deserialize_with = "nullable")]
    pub rms_px: f64,
    pub intrinsics: IntrinsicsRecord,
    pub self_calibration: Option<SelfCalibrationRecord>,
    pub starts: Vec<StartRecord>,
    pub stages: Vec<StageRecord>,
    pub cameras: Vec<PerspectiveCameraRecord>,
    pub points: Vec<PointRecord>,
    /// `[frame, track]` ids.
    pub downweighted: Vec<(Id, Id)>,
    #[serde(deserialize_with = "nullable")]
    pub in_front: f64,
    /// Absent when not measured (and from files written before it was).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotation_parallax_px: Option<f64>,
}

/// `perspective.intrinsics`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IntrinsicsRecord {
    /// `"shared"`, `"per-frame"` or `"given"`.
    pub focal: String,
    #[serde(deserialize_with = "nullable")]
    pub focal_px: f64,
    #[serde(deserialize_with = "nullable")]
    pub k: [[f64; 3]; 3],
    #[serde(deserialize_with = "nullable")]
    pub principal_point: [f64; 2],
    pub principal_point_source: String,
    /// A principal point estimate rejected as implausible (absent when none was).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub principal_point_rejected: Option<crate::perspective::RejectedPrincipalPoint>,
    #[serde(deserialize_with = "nullable")]
    pub k1: f64,
    /// `f_x / f_y` (1 in files written before it existed).
    #[serde(default = "one")]
    pub aspect_ratio: f64,
    /// `"square pixels"`, `"given"`, `"estimated"`, or where the ratio was read or assumed
    /// from.
    #[serde(default = "square_pixels")]
    pub aspect_ratio_source: String,
    pub image_size: Option<[u32; 2]>,
}

fn square_pixels() -> String {
    "square pixels".into()
}

/// `perspective.self_calibration`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SelfCalibrationRecord {
    #[serde(deserialize_with = "nullable")]
    pub quadric: [f64; 16],
    #[serde(deserialize_with = "nullable")]
    pub linear_eigenvalues: [f64; 4],
    pub sdp: bool,
    pub sdp_status: Option<String>,
    #[serde(deserialize_with = "nullable")]
    pub focal_px: Vec<f64>,
    #[serde(deserialize_with = "nullable")]
    pub in_front: f64,
}

/// One entry of `perspective.starts`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StartRecord {
    /// `"self-calibration"`, `"affine"` or `"plane"`.
    pub kind: String,
    #[serde(deserialize_with = "nullable")]
    pub focal_px: f64,
    pub mirrored: bool,
    #[serde(deserialize_with = "nullable")]
    pub rms_px: f64,
    pub chosen: bool,
    /// Frames and tracks the screening used (absent from files written before they were
    /// reported: 0).
    #[serde(default)]
    pub screen_frames: usize,
    #[serde(default)]
    pub screen_tracks: usize,
}

/// One entry of `perspective.cameras`: `x_cam = rotation · X + translation`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PerspectiveCameraRecord {
    pub frame: Id,
    #[serde(deserialize_with = "nullable")]
    pub rotation: [[f64; 3]; 3],
    #[serde(deserialize_with = "nullable")]
    pub translation: [f64; 3],
    #[serde(deserialize_with = "nullable")]
    pub centre: [f64; 3],
    #[serde(deserialize_with = "nullable")]
    pub focal_px: f64,
    #[serde(deserialize_with = "nullable")]
    pub rms_px: f64,
    pub n_observations: usize,
}

/// `input`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InputRecord {
    pub frames: usize,
    pub tracks: usize,
    pub observations: usize,
    #[serde(deserialize_with = "nullable")]
    pub fill: f64,
    pub frames_used: usize,
    pub tracks_used: usize,
}

/// One entry of `timings`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TimingRecord {
    pub stage: String,
    #[serde(deserialize_with = "nullable")]
    pub seconds: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nulls_read_as_nan_and_schema_is_checked() {
        #[derive(Deserialize)]
        struct T {
            #[serde(deserialize_with = "nullable")]
            a: [f64; 3],
            #[serde(deserialize_with = "nullable")]
            b: f64,
        }
        let t: T = serde_json::from_str(r#"{"a": [1.0, null, 3.0], "b": null}"#).unwrap();
        assert!(t.a[1].is_nan() && t.b.is_nan() && t.a[2] == 3.0);
        let p = Path::new("r.json");
        let e = from_json_str(r#"{"schema": "rank3.reconstruction/2"}"#, p).unwrap_err();
        assert!(
            matches!(&e, ReadError::UnsupportedSchema { found, .. } if found == "rank3.reconstruction/2"),
            "{e}"
        );
        assert!(e.to_string().contains("newer rank3"), "{e}");
        let e = from_json_str(r#"{"schema": 7}"#, p).unwrap_err();
        assert!(matches!(e, ReadError::UnsupportedSchema { .. }), "{e}");
        let e = from_json_str(r#"{"schema": "rank3.reconstruction/1"}"#, p).unwrap_err();
        assert!(matches!(e, ReadError::Json { line: 1, .. }), "{e}");
    }
}
