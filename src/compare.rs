//! Scoring a reconstruction against a reference: the library side of `rank3 eval`.
//!
//! The estimate is a `reconstruction.json` (or the output folder holding it); the reference
//! is the `truth.json` of `rank3 synth` or another `reconstruction.json` (or the folder
//! holding either). Points are matched by track id, cameras by frame id. The figures, all
//! computed by [`crate::eval`]:
//!
//! * **structure error** — the estimate's points are aligned to the reference's by the
//!   least-squares similarity ([`crate::eval::align_similarity`]); the RMS distance that
//!   remains, in % of the reference points' RMS distance from their centroid (and the
//!   largest single distance, same unit). The alignment may be a reflection unless both
//!   sides are Euclidean perspective models: an affine reconstruction is defined only up
//!   to the depth reversal (docs/math.md).
//! * **rotation error** — per common frame, the angle between the estimate's and the
//!   reference's rotation, both taken relative to the first common frame
//!   ([`crate::eval::rotation_errors_deg_with`]; with the depth-reversal branch under the
//!   same rule as the structure), summarised over the other common frames.
//! * **camera centre error** — when both sides are perspective: the estimate's centres
//!   mapped by the structure's similarity, their RMS distance from the reference's, in %
//!   of the RMS distance of the reference's centres from its points' centroid (the
//!   viewing distance).
//! * **focal length error** — when both have one: `(f_est − f_ref) / f_ref`, %.
//! * the reprojection RMS each file stores (`rms_px`; a truth has none).
//!
//! Points that a side marks as outliers (`inlier: false` in a reconstruction; `outlier`,
//! or `object ≠ 0`, in a truth) or whose coordinates are not finite are not compared.

use std::collections::HashMap;
use std::fmt;
use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Rotation3, Vector3};
use serde::{Deserialize, Serialize};

use crate::CameraModel;
use crate::eval::{align_similarity, median, rotation_errors_deg_with};
use crate::reconstruction_file::{self, ReadError, ReconstructionFile};
use crate::table::Id;

/// Fewest common (usable) points a comparison needs: a similarity has 7 degrees of
/// freedom, and 3 points are nearly always fitted exactly.
pub const MIN_COMMON_POINTS: usize = 4;

/// Why a comparison could not be made.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum EvalError {
    /// The reconstruction file could not be read ([`ReadError`]: missing file, bad JSON,
    /// unsupported schema).
    #[error(transparent)]
    Read(#[from] ReadError),
    /// A `truth.json` could not be parsed (`line`, `column` 1-based).
    #[error("{}:{line}:{column}: not a valid rank3 truth.json: {message}", path.display())]
    Truth {
        path: PathBuf,
        line: usize,
        column: usize,
        message: String,
    },
    /// The estimate is a `truth.json`, not a reconstruction.
    #[error(
        "{} is the ground truth of `rank3 synth`, not a reconstruction: give it as \
         --reference, and a reconstruction.json (or its folder) as the estimate",
        path.display()
    )]
    TruthAsEstimate { path: PathBuf },
    /// A folder given as the estimate or the reference holds none of the files expected.
    #[error("{}: a folder without {expected}", path.display())]
    NothingToRead {
        path: PathBuf,
        expected: &'static str,
    },
    /// The two files share no track id.
    #[error(
        "{} and {} have no track id in common ({estimate_tracks} and {reference_tracks} \
         tracks): they are not reconstructions of the same track table",
        estimate.display(),
        reference.display()
    )]
    NoCommonTracks {
        estimate: PathBuf,
        reference: PathBuf,
        estimate_tracks: usize,
        reference_tracks: usize,
    },
    /// Too few common tracks that both sides hold as finite inlier points.
    #[error(
        "{} and {} have {have} comparable points in common (inlier and finite on both \
         sides, of {common} common track ids); at least {needed} needed",
        estimate.display(),
        reference.display()
    )]
    TooFewCommonPoints {
        estimate: PathBuf,
        reference: PathBuf,
        common: usize,
        have: usize,
        needed: usize,
    },
    /// The common points do not determine an alignment (all coincide).
    #[error(
        "{} vs {}: the common points do not determine an alignment ({message})",
        estimate.display(),
        reference.display()
    )]
    Degenerate {
        estimate: PathBuf,
        reference: PathBuf,
        message: String,
    },
}

/// What a loaded file is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum SceneKind {
    /// The `truth.json` of `rank3 synth`.
    Truth,
    /// A `reconstruction.json`.
    Reconstruction,
}

/// One camera of a [`Scene`].
#[derive(Debug, Clone)]
pub struct SceneFrame {
    pub id: Id,
    /// World-to-camera rotation (rows: the camera axes in world coordinates).
    pub rotation: Matrix3<f64>,
    /// The camera centre in world coordinates (perspective cameras only).
    pub centre: Option<Vector3<f64>>,
}

/// One side of a comparison: the points, cameras and figures of a truth or a
/// reconstruction.
#[derive(Debug, Clone)]
pub struct Scene {
    pub path: PathBuf,
    pub kind: SceneKind,
    pub camera_model: CameraModel,
    /// A Euclidean perspective model (no depth-reversal ambiguity).
    pub euclidean: bool,
    /// Which points: `"perspective.points"`, `"points"` or `"truth points"`.
    pub structure: &'static str,
    /// Every listed point by track id; `None` when it is not compared (outlier, other
    /// object, not finite).
    pub points: Vec<(Id, Option<Vector3<f64>>)>,
    pub frames: Vec<SceneFrame>,
    pub focal_px: Option<f64>,
    /// The stored reprojection RMS, pixels (none for a truth).
    pub rms_px: Option<f64>,
}

fn finite3(v: [f64; 3]) -> Option<Vector3<f64>> {
    v.iter()
        .all(|x| x.is_finite())
        .then(|| Vector3::new(v[0], v[1], v[2]))
}

fn matrix3(r: &[[f64; 3]; 3]) -> Matrix3<f64> {
    Matrix3::from_fn(|i, j| r[i][j])
}

impl Scene {
    /// The side of a comparison a `reconstruction.json` gives: the perspective block's
    /// cameras and points when there is one, the metric (affine-family) ones otherwise.
    pub fn from_reconstruction(file: &ReconstructionFile, path: &Path) -> Scene {
        let points = file
            .euclidean_points()
            .iter()
            .map(|p| (p.track.clone(), finite3(p.xyz).filter(|_| p.inlier)))
            .collect();
        let (structure, frames, focal_px) = match &file.perspective {
            Some(per) => (
                "perspective.points",
                per.cameras
                    .iter()
                    .map(|c| SceneFrame {
                        id: c.frame.clone(),
                        rotation: matrix3(&c.rotation),
                        centre: finite3(c.centre),
                    })
                    .collect(),
                Some(per.intrinsics.focal_px).filter(|f| f.is_finite()),
            ),
            None => (
                "points",
                file.frames
                    .iter()
                    .map(|f| SceneFrame {
                        id: f.frame.clone(),
                        rotation: matrix3(&f.rotation),
                        centre: None,
                    })
                    .collect(),
                None,
            ),
        };
        Scene {
            path: path.to_path_buf(),
            kind: SceneKind::Reconstruction,
            camera_model: file.camera_model,
            euclidean: file.perspective.is_some(),
            structure,
            points,
            frames,
            focal_px,
            rms_px: Some(file.rms_px).filter(|r| r.is_finite()),
        }
    }
}

/// `truth.json` as far as a comparison needs it (its layout: docs/formats.md).
#[derive(Deserialize)]
struct TruthDoc {
    camera_model: CameraModel,
    #[serde(default)]
    perspective: Option<TruthPerspectiveDoc>,
    frames: Vec<TruthFrameDoc>,
    points: Vec<TruthPointDoc>,
}

#[derive(Deserialize)]
struct TruthPerspectiveDoc {
    focal_px: f64,
}

#[derive(Deserialize)]
struct TruthFrameDoc {
    frame: Id,
    rotation: [[f64; 3]; 3],
    #[serde(default)]
    camera_centre: Option<[f64; 3]>,
}

#[derive(Deserialize)]
struct TruthPointDoc {
    track: Id,
    xyz: [f64; 3],
    #[serde(default)]
    outlier: bool,
    #[serde(default)]
    object: usize,
}

fn truth_scene(text: &str, path: &Path) -> Result<Scene, EvalError> {
    let doc: TruthDoc = serde_json::from_str(text).map_err(|e| EvalError::Truth {
        path: path.to_path_buf(),
        line: e.line(),
        column: e.column(),
        message: e.to_string(),
    })?;
    let euclidean = doc.perspective.is_some();
    Ok(Scene {
        path: path.to_path_buf(),
        kind: SceneKind::Truth,
        camera_model: doc.camera_model,
        euclidean,
        structure: "truth points",
        points: doc
            .points
            .iter()
            .map(|p| {
                let used = !p.outlier && p.object == 0;
                (p.track.clone(), finite3(p.xyz).filter(|_| used))
            })
            .collect(),
        frames: doc
            .frames
            .iter()
            .map(|f| SceneFrame {
                id: f.frame.clone(),
                rotation: matrix3(&f.rotation),
                centre: f.camera_centre.and_then(finite3),
            })
            .collect(),
        focal_px: doc.perspective.map(|p| p.focal_px),
        rms_px: None,
    })
}

fn read_text(path: &Path) -> Result<String, EvalError> {
    std::fs::read_to_string(path).map_err(|source| {
        ReadError::Io {
            path: path.to_path_buf(),
            source,
        }
        .into()
    })
}

/// The estimate: `path` is a `reconstruction.json`, or a folder holding one.
///
/// Errors: [`EvalError::NothingToRead`] (a folder without it), [`EvalError::TruthAsEstimate`],
/// [`EvalError::Read`].
pub fn load_estimate(path: &Path) -> Result<Scene, EvalError> {
    let file = if path.is_dir() {
        let f = path.join("reconstruction.json");
        if !f.is_file() {
            return Err(EvalError::NothingToRead {
                path: path.to_path_buf(),
                expected: "reconstruction.json",
            });
        }
        f
    } else {
        path.to_path_buf()
    };
    let text = read_text(&file)?;
    if probe(&text).is_truth() {
        return Err(EvalError::TruthAsEstimate { path: file });
    }
    let rec = reconstruction_file::from_json_str(&text, &file)?;
    Ok(Scene::from_reconstruction(&rec, &file))
}

/// The top-level keys that tell a truth from a reconstruction.
#[derive(Deserialize, Default)]
struct Probe {
    schema: Option<serde::de::IgnoredAny>,
    config: Option<serde::de::IgnoredAny>,
}

impl Probe {
    fn is_truth(&self) -> bool {
        self.schema.is_none() && self.config.is_some()
    }
}

/// The probe of a JSON text (empty when it is not a JSON object).
fn probe(text: &str) -> Probe {
    serde_json::from_str(text).unwrap_or_default()
}

/// The reference: a `truth.json` (`rank3 synth`), a `reconstruction.json`, or a folder
/// holding either (`truth.json` first). A JSON file is a reconstruction when it has a
/// `schema` key, a truth when it has a `config` key, else read as a reconstruction
/// written before the schema key existed.
///
/// Errors: [`EvalError::NothingToRead`], [`EvalError::Read`], [`EvalError::Truth`].
pub fn load_reference(path: &Path) -> Result<Scene, EvalError> {
    let file = if path.is_dir() {
        match ["truth.json", "reconstruction.json"]
            .iter()
            .map(|n| path.join(n))
            .find(|f| f.is_file())
        {
            Some(f) => f,
            None => {
                return Err(EvalError::NothingToRead {
                    path: path.to_path_buf(),
                    expected: "truth.json or reconstruction.json",
                });
            }
        }
    } else {
        path.to_path_buf()
    };
    let text = read_text(&file)?;
    if probe(&text).is_truth() {
        truth_scene(&text, &file)
    } else {
        let rec = reconstruction_file::from_json_str(&text, &file)?;
        Ok(Scene::from_reconstruction(&rec, &file))
    }
}

/// Median, RMS and largest of a list of errors.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Summary {
    pub median: f64,
    pub rms: f64,
    pub max: f64,
    /// How many values.
    pub n: usize,
}

impl Summary {
    fn of(v: &[f64]) -> Option<Summary> {
        if v.is_empty() {
            return None;
        }
        Some(Summary {
            median: median(v),
            rms: (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt(),
            max: v.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            n: v.len(),
        })
    }
}

/// The structure error after the similarity alignment.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StructureError {
    /// RMS distance of the aligned points, % of the reference points' RMS spread.
    pub rms_pct: f64,
    /// Largest single distance, same unit.
    pub max_pct: f64,
    /// RMS distance in the reference's units.
    pub rms: f64,
    /// Scale of the alignment (reference units per estimate unit).
    pub scale: f64,
    /// Whether the alignment could be a reflection (not when both sides are Euclidean
    /// perspective models), and whether it was.
    pub reflection_allowed: bool,
    pub reflected: bool,
}

/// Point and frame counts.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Counts {
    pub estimate: usize,
    pub reference: usize,
    /// Ids in both.
    pub common: usize,
    /// Common and compared (for points: inlier and finite on both sides).
    pub compared: usize,
}

/// The focal lengths, pixels, and the estimate's error, %.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FocalError {
    pub estimate_px: f64,
    pub reference_px: f64,
    pub error_pct: f64,
}

/// The scores of [`compare`] (`rank3 eval --json` prints this).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Comparison {
    pub estimate: PathBuf,
    pub reference: PathBuf,
    pub reference_kind: SceneKind,
    pub estimate_camera: CameraModel,
    pub reference_camera: CameraModel,
    /// Which points were compared on each side (`"perspective.points"`, `"points"`,
    /// `"truth points"`).
    pub estimate_structure: &'static str,
    pub reference_structure: &'static str,
    pub points: Counts,
    pub structure: StructureError,
    pub frames: Counts,
    /// The common frame the rotations are taken relative to (the estimate's first).
    pub reference_frame: Option<Id>,
    /// Rotation errors, degrees, over the common frames but `reference_frame`; `None`
    /// with fewer than 2 common frames.
    pub rotation_deg: Option<Summary>,
    /// Camera centre errors, % of the viewing distance; `None` unless both sides are
    /// perspective.
    pub centre_pct: Option<Summary>,
    /// `None` unless both sides have a focal length.
    pub focal: Option<FocalError>,
    /// The reprojection RMS each file stores, pixels (`None` for a truth).
    pub estimate_rms_px: Option<f64>,
    pub reference_rms_px: Option<f64>,
}

/// Scores `est` against `reference` (see the module documentation).
///
/// Errors: [`EvalError::NoCommonTracks`], [`EvalError::TooFewCommonPoints`] (fewer than
/// [`MIN_COMMON_POINTS`]), [`EvalError::Degenerate`].
pub fn compare(est: &Scene, reference: &Scene) -> Result<Comparison, EvalError> {
    let ref_points: HashMap<&Id, Option<Vector3<f64>>> =
        reference.points.iter().map(|(id, p)| (id, *p)).collect();
    let mut common = 0;
    let (mut e_pts, mut r_pts) = (Vec::new(), Vec::new());
    for (id, p) in &est.points {
        let Some(r) = ref_points.get(id) else {
            continue;
        };
        common += 1;
        if let (Some(p), Some(r)) = (p, r) {
            e_pts.push(*p);
            r_pts.push(*r);
        }
    }
    if common == 0 {
        return Err(EvalError::NoCommonTracks {
            estimate: est.path.clone(),
            reference: reference.path.clone(),
            estimate_tracks: est.points.len(),
            reference_tracks: reference.points.len(),
        });
    }
    if e_pts.len() < MIN_COMMON_POINTS {
        return Err(EvalError::TooFewCommonPoints {
            estimate: est.path.clone(),
            reference: reference.path.clone(),
            common,
            have: e_pts.len(),
            needed: MIN_COMMON_POINTS,
        });
    }
    let reflection_allowed = !(est.euclidean && reference.euclidean);
    let degenerate = |message: &str| EvalError::Degenerate {
        estimate: est.path.clone(),
        reference: reference.path.clone(),
        message: message.to_string(),
    };
    let al = align_similarity(&e_pts, &r_pts, reflection_allowed)
        .ok_or_else(|| degenerate("zero spread"))?;
    let map = |e: &Vector3<f64>| al.rotation * e * al.scale + al.translation;
    let spread = al.rms / al.relative_rms;
    if !(spread > 0.0 && spread.is_finite()) {
        return Err(degenerate("the reference points coincide"));
    }
    let max_dist = e_pts
        .iter()
        .zip(&r_pts)
        .map(|(e, r)| (r - map(e)).norm())
        .fold(0.0, f64::max);
    let structure = StructureError {
        rms_pct: 100.0 * al.relative_rms,
        max_pct: 100.0 * max_dist / spread,
        rms: al.rms,
        scale: al.scale,
        reflection_allowed,
        reflected: al.rotation.determinant() < 0.0,
    };

    // Frames by id, in the estimate's order (with finite rotations).
    let finite = |f: &&SceneFrame| f.rotation.iter().all(|x| x.is_finite());
    let ref_frames: HashMap<&Id, &SceneFrame> = reference
        .frames
        .iter()
        .filter(finite)
        .map(|f| (&f.id, f))
        .collect();
    let pairs: Vec<(&SceneFrame, &SceneFrame)> = est
        .frames
        .iter()
        .filter(finite)
        .filter_map(|f| ref_frames.get(&f.id).map(|r| (f, *r)))
        .collect();
    let rot = |m: &Matrix3<f64>| Rotation3::from_matrix_unchecked(*m);
    let (e_rot, r_rot): (Vec<_>, Vec<_>) = pairs
        .iter()
        .map(|(e, r)| (rot(&e.rotation), rot(&r.rotation)))
        .unzip();
    let rotation_deg = if pairs.len() >= 2 {
        rotation_errors_deg_with(&e_rot, &r_rot, reflection_allowed)
            .get(1..)
            .and_then(Summary::of)
    } else {
        None
    };
    let centre_pct = if est.euclidean && reference.euclidean {
        let centroid = r_pts.iter().fold(Vector3::zeros(), |a, p| a + p) / r_pts.len() as f64;
        let with_centres: Vec<(Vector3<f64>, Vector3<f64>)> = pairs
            .iter()
            .filter_map(|(e, r)| Some((e.centre?, r.centre?)))
            .collect();
        let dist = (with_centres
            .iter()
            .map(|(_, r)| (r - centroid).norm_squared())
            .sum::<f64>()
            / with_centres.len().max(1) as f64)
            .sqrt();
        let errs: Vec<f64> = with_centres
            .iter()
            .map(|(e, r)| 100.0 * (r - map(e)).norm() / dist)
            .collect();
        if dist > 0.0 { Summary::of(&errs) } else { None }
    } else {
        None
    };
    let focal = match (est.focal_px, reference.focal_px) {
        (Some(e), Some(r)) if r != 0.0 => Some(FocalError {
            estimate_px: e,
            reference_px: r,
            error_pct: 100.0 * (e - r) / r,
        }),
        _ => None,
    };
    Ok(Comparison {
        estimate: est.path.clone(),
        reference: reference.path.clone(),
        reference_kind: reference.kind,
        estimate_camera: est.camera_model,
        reference_camera: reference.camera_model,
        estimate_structure: est.structure,
        reference_structure: reference.structure,
        points: Counts {
            estimate: est.points.len(),
            reference: reference.points.len(),
            common,
            compared: e_pts.len(),
        },
        structure,
        frames: Counts {
            estimate: est.frames.len(),
            reference: reference.frames.len(),
            common: pairs.len(),
            compared: pairs.len(),
        },
        reference_frame: pairs.first().map(|(e, _)| e.id.clone()),
        rotation_deg,
        centre_pct,
        focal,
        estimate_rms_px: est.rms_px,
        reference_rms_px: reference.rms_px,
    })
}

/// [`load_estimate`], [`load_reference`], then [`compare`].
pub fn evaluate(estimate: &Path, reference: &Path) -> Result<Comparison, EvalError> {
    let est = load_estimate(estimate)?;
    let reference = load_reference(reference)?;
    compare(&est, &reference)
}

fn camera_name(c: CameraModel) -> String {
    serde_json::to_value(c)
        .ok()
        .and_then(|v| v.as_str().map(str::to_string))
        .unwrap_or_else(|| format!("{c:?}"))
}

/// The readable table `rank3 eval` prints.
impl fmt::Display for Comparison {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let kind = match self.reference_kind {
            SceneKind::Truth => "ground truth",
            SceneKind::Reconstruction => "reconstruction",
        };
        writeln!(f, "estimate   {}", self.estimate.display())?;
        writeln!(f, "reference  {} ({kind})", self.reference.display())?;
        writeln!(f)?;
        let row = |f: &mut fmt::Formatter<'_>, k: &str, v: String| writeln!(f, "{k:<18} {v}");
        row(
            f,
            "camera",
            format!(
                "{} vs {}",
                camera_name(self.estimate_camera),
                camera_name(self.reference_camera)
            ),
        )?;
        let p = &self.points;
        row(
            f,
            "points",
            format!(
                "{} compared of {} common track ids (estimate {}, reference {}; {} vs {})",
                p.compared,
                p.common,
                p.estimate,
                p.reference,
                self.estimate_structure,
                self.reference_structure
            ),
        )?;
        let s = &self.structure;
        row(
            f,
            "structure error",
            format!(
                "{:.3} % RMS, {:.3} % max (of the reference points' RMS spread; similarity \
                 alignment, scale {:.4}{})",
                s.rms_pct,
                s.max_pct,
                s.scale,
                match (s.reflection_allowed, s.reflected) {
                    (false, _) => ", no reflection",
                    (true, false) => ", reflection allowed, not used",
                    (true, true) => ", reflected",
                }
            ),
        )?;
        let fr = &self.frames;
        row(
            f,
            "frames",
            format!(
                "{} common frame ids (estimate {}, reference {})",
                fr.common, fr.estimate, fr.reference
            ),
        )?;
        let none = |why: &str| format!("— ({why})");
        row(
            f,
            "rotation error",
            match (&self.rotation_deg, &self.reference_frame) {
                (Some(r), Some(id)) => format!(
                    "{:.3}° median, {:.3}° RMS, {:.3}° max over {} frames (relative to frame \
                     {id})",
                    r.median, r.rms, r.max, r.n
                ),
                _ => none("fewer than 2 common frames"),
            },
        )?;
        row(
            f,
            "camera centres",
            match &self.centre_pct {
                Some(c) => format!(
                    "{:.3} % RMS, {:.3} % max (of the viewing distance) over {} frames",
                    c.rms, c.max, c.n
                ),
                None => none("perspective on both sides only"),
            },
        )?;
        row(
            f,
            "focal length",
            match &self.focal {
                Some(x) => format!(
                    "{:.2} px vs {:.2} px: {:+.3} %",
                    x.estimate_px, x.reference_px, x.error_pct
                ),
                None => none("both sides need one"),
            },
        )?;
        let rms = |r: Option<f64>| r.map_or("—".to_string(), |r| format!("{r:.4} px"));
        row(
            f,
            "reprojection RMS",
            format!(
                "{} (estimate), {} (reference)",
                rms(self.estimate_rms_px),
                rms(self.reference_rms_px)
            ),
        )
    }
}
