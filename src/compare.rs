//! Scoring a reconstruction against a reference: the library side of `rank3 eval`.
//!
//! The estimate is a `reconstruction.json` (or the output folder holding it); the reference
//! is the `truth.json` of `rank3 synth` or another `reconstruction.json` (or the folder
//! holding either), whose points are matched by track id and cameras by frame id — or a
//! COLMAP text model, whose images are matched to frames by name and whose 3D points are
//! matched to tracks by shared observations ([`evaluate_with`] gives the rules). The
//! figures, all computed by [`crate::eval`]:
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
//! * the reprojection RMS each file stores (`rms_px`; a truth and a COLMAP model have
//!   none).
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
    /// A COLMAP reference model, or the track table given as the estimate's observations,
    /// could not be read ([`crate::Error::Parse`] names the file, line and field;
    /// [`crate::Error::Io`] the file).
    #[error(transparent)]
    Input(#[from] crate::Error),
    /// A COLMAP model was given where its points cannot be matched: [`load_reference`]
    /// reads JSON references only (use [`evaluate`]).
    #[error(
        "{} is a COLMAP model: its 3D points are matched to a reconstruction's tracks by \
         their observations, so it is read by rank3::compare::evaluate, not load_reference",
        path.display()
    )]
    ColmapNeedsEstimate { path: PathBuf },
    /// No image name of the COLMAP reference matches a frame id of the estimate.
    #[error(
        "{} and {} share no frame: no image name matches a frame id (reference images {}; \
         estimate frames {}). An image matches a frame when its name is the frame id, or \
         when its name without folder and extension is (`000042.png` is frame 42)",
        estimate.display(),
        reference.display(),
        reference_examples,
        estimate_examples
    )]
    NoCommonFrames {
        estimate: PathBuf,
        reference: PathBuf,
        /// A few names and ids of each side, with their counts.
        reference_examples: String,
        estimate_examples: String,
    },
    /// The estimate's 2D observations, needed to match its tracks to a COLMAP reference's
    /// 3D points, are not available.
    #[error(
        "{}: its tracks cannot be matched to the COLMAP model {}: {reason}",
        estimate.display(),
        reference.display()
    )]
    NoObservations {
        estimate: PathBuf,
        reference: PathBuf,
        reason: String,
    },
    /// No track of the estimate shares observations with a 3D point of the COLMAP
    /// reference.
    #[error(
        "{} vs {}: no track matches a 3D point of the reference ({tracks} tracks observed \
         in the {frames} matched images; a track matches the 3D point that a majority of its \
         observations, at least 2, lie within {tolerance_px} px of keypoints of). Are the \
         observations from the same images and in the same pixel convention (COLMAP's: the \
         centre of the top-left pixel at (0.5, 0.5))?",
        estimate.display(),
        reference.display()
    )]
    NoMatchedPoints {
        estimate: PathBuf,
        reference: PathBuf,
        tracks: usize,
        frames: usize,
        tolerance_px: f64,
    },
    /// [`EvalOptions::match_tolerance_px`] is not a positive number.
    #[error("the matching tolerance must be a positive number of pixels, not {0}")]
    InvalidTolerance(f64),
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
    /// A COLMAP text model (`cameras.txt`, `images.txt`, `points3D.txt`).
    Colmap,
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
    /// Which points: `"perspective.points"`, `"points"`, `"truth points"` or
    /// `"points3D.txt"`.
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

/// What a reference path names.
enum ReferencePath {
    /// A `truth.json` or `reconstruction.json`.
    Json(PathBuf),
    /// The folder of a COLMAP text model.
    Colmap(PathBuf),
}

/// The first line of COLMAP's text files (COLMAP's writer and rank3's).
const COLMAP_HEADERS: [&str; 3] = ["# Camera list", "# Image list", "# 3D point list"];

/// Whether the file at `path` starts like one of COLMAP's text files.
fn starts_like_colmap(path: &Path) -> bool {
    use std::io::{BufRead, Read};
    let Ok(file) = std::fs::File::open(path) else {
        return false;
    };
    let mut line = String::new();
    let mut reader = std::io::BufReader::new(file).take(256);
    if reader.read_line(&mut line).is_err() {
        return false;
    }
    COLMAP_HEADERS.iter().any(|h| line.starts_with(h))
}

/// Resolves a reference path: a folder holding `truth.json` or `reconstruction.json` (in
/// that order) or a COLMAP text model (`cameras.txt`, `images.txt`, `points3D.txt`, or a
/// binary model, refused with a hint when read); a file named like one of COLMAP's three, or
/// starting with COLMAP's header comment, is its folder's model; any other file is JSON.
fn resolve_reference(path: &Path) -> Result<ReferencePath, EvalError> {
    use crate::colmap::{CAMERAS_TXT, IMAGES_TXT, POINTS3D_TXT};
    if path.is_dir() {
        if let Some(f) = ["truth.json", "reconstruction.json"]
            .iter()
            .map(|n| path.join(n))
            .find(|f| f.is_file())
        {
            return Ok(ReferencePath::Json(f));
        }
        if [IMAGES_TXT, CAMERAS_TXT, POINTS3D_TXT, "images.bin"]
            .iter()
            .any(|n| path.join(n).is_file())
        {
            return Ok(ReferencePath::Colmap(path.to_path_buf()));
        }
        return Err(EvalError::NothingToRead {
            path: path.to_path_buf(),
            expected: "truth.json, reconstruction.json or a COLMAP text model (cameras.txt, \
                       images.txt, points3D.txt)",
        });
    }
    let named = path
        .file_name()
        .and_then(|n| n.to_str())
        .is_some_and(|n| [CAMERAS_TXT, IMAGES_TXT, POINTS3D_TXT].contains(&n));
    if named || (path.is_file() && starts_like_colmap(path)) {
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        return Ok(ReferencePath::Colmap(dir));
    }
    Ok(ReferencePath::Json(path.to_path_buf()))
}

/// A JSON reference: a `truth.json` (`rank3 synth`), a `reconstruction.json`, or a folder
/// holding either (`truth.json` first). A JSON file is a reconstruction when it has a
/// `schema` key, a truth when it has a `config` key, else read as a reconstruction
/// written before the schema key existed.
///
/// A COLMAP model (see [`evaluate`]) is matched to an estimate's tracks, so it is not a
/// [`Scene`] on its own: this returns [`EvalError::ColmapNeedsEstimate`] for one.
///
/// Errors: [`EvalError::NothingToRead`], [`EvalError::Read`], [`EvalError::Truth`],
/// [`EvalError::ColmapNeedsEstimate`].
pub fn load_reference(path: &Path) -> Result<Scene, EvalError> {
    match resolve_reference(path)? {
        ReferencePath::Json(file) => load_json_reference(&file),
        ReferencePath::Colmap(_) => Err(EvalError::ColmapNeedsEstimate {
            path: path.to_path_buf(),
        }),
    }
}

fn load_json_reference(file: &Path) -> Result<Scene, EvalError> {
    let text = read_text(file)?;
    if probe(&text).is_truth() {
        truth_scene(&text, file)
    } else {
        let rec = reconstruction_file::from_json_str(&text, file)?;
        Ok(Scene::from_reconstruction(&rec, file))
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
    /// The reprojection RMS each file stores, pixels (`None` for a truth and a COLMAP
    /// model).
    pub estimate_rms_px: Option<f64>,
    pub reference_rms_px: Option<f64>,
    /// With a COLMAP reference: how its images and 3D points were matched to the
    /// estimate's frames and tracks.
    pub matching: Option<ColmapMatching>,
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
        matching: None,
    })
}

/// [`evaluate_with`] with the default [`EvalOptions`].
pub fn evaluate(estimate: &Path, reference: &Path) -> Result<Comparison, EvalError> {
    evaluate_with(estimate, reference, &EvalOptions::default())
}

/// Default of [`EvalOptions::match_tolerance_px`], pixels.
pub const MATCH_TOLERANCE_PX: f64 = 2.0;

/// How [`evaluate_with`] matches a COLMAP reference.
#[derive(Debug, Clone, PartialEq)]
pub struct EvalOptions {
    /// The track table the estimate was reconstructed from (any format `rank3 reconstruct`
    /// reads, a COLMAP model folder included), as the estimate's 2D observations. Without
    /// it they are read from the estimate's own COLMAP export (`colmap/` next to its
    /// `reconstruction.json`), which only a perspective result has. Used only with a COLMAP
    /// reference.
    pub tracks: Option<PathBuf>,
    /// How far, in pixels, an observation may lie from a reference keypoint to vote for
    /// its 3D point ([`MATCH_TOLERANCE_PX`]).
    pub match_tolerance_px: f64,
}

impl Default for EvalOptions {
    fn default() -> Self {
        EvalOptions {
            tracks: None,
            match_tolerance_px: MATCH_TOLERANCE_PX,
        }
    }
}

/// How a COLMAP reference was matched to the estimate (`matching` in `rank3 eval --json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ColmapMatching {
    /// Where the estimate's 2D observations were read: its own COLMAP export
    /// (`DIR/colmap`) or the track table given.
    pub observations: PathBuf,
    pub tolerance_px: f64,
    /// Images of the reference; matched to an estimate frame by their exact name, by their
    /// stem (name without folder and extension, a number without its leading zeros); not
    /// matched.
    pub images: usize,
    pub images_by_name: usize,
    pub images_by_stem: usize,
    pub images_unmatched: usize,
    /// Estimate tracks observed in the matched images; matched to a 3D point; left
    /// unmatched (no point with a majority of at least 2 of their observations); ambiguous
    /// (the point they chose was chosen by another track as often).
    pub tracks: usize,
    pub tracks_matched: usize,
    pub tracks_unmatched: usize,
    pub tracks_ambiguous: usize,
    /// Up to 10 ids of the unmatched and ambiguous tracks.
    pub unmatched_examples: Vec<Id>,
    /// Of the matched tracks' observations in matched images, the fraction within the
    /// tolerance of a keypoint of their 3D point.
    pub agreement: f64,
    /// The reference's camera models (distinct, in file order).
    pub camera_models: Vec<String>,
    /// Why the focal length is not compared, or how the reference's was formed; `None`
    /// when one focal length was compared as it is.
    pub intrinsics_note: Option<String>,
}

/// The estimate's 2D observations in COLMAP's pixel convention, by frame id: `(index into
/// the estimate's points, [x, y])`.
struct Observations {
    source: PathBuf,
    by_frame: HashMap<Id, Vec<(usize, [f64; 2])>>,
}

/// The file stem of an image name: without its folders and its last extension.
fn image_stem(name: &str) -> &str {
    let file = name.rsplit(['/', '\\']).next().unwrap_or(name);
    match file.rfind('.') {
        Some(k) if k > 0 => &file[..k],
        _ => file,
    }
}

/// The text rank3's COLMAP export names frame `id`'s image (white space as `_`).
fn export_name(id: &Id) -> String {
    id.to_string()
        .chars()
        .map(|c| if c.is_whitespace() { '_' } else { c })
        .collect()
}

/// Frame `id` is the frame an image of stem `stem` shows: the stem is the id's text, or a
/// number equal to an integer id (`000042` is 42).
fn stem_matches(stem: &str, id: &Id) -> bool {
    stem == export_name(id) || matches!((Id::parse(stem), id), (Id::Int(a), Id::Int(b)) if a == *b)
}

/// Which frame (index into `ids`) each image (by `names`) shows, and whether by its exact
/// name (`true`) or its stem. First every image whose name is a frame id's text; then,
/// among the images and frames left, the pairs whose stem matches ([`stem_matches`]) one to
/// one: an image whose stem matches two frames, or a frame two images match, is left out.
fn match_frames(names: &[&str], ids: &[Id]) -> Vec<Option<(usize, bool)>> {
    let mut by_text: HashMap<String, Vec<usize>> = HashMap::new();
    for (f, id) in ids.iter().enumerate() {
        by_text.entry(export_name(id)).or_default().push(f);
    }
    let mut taken = vec![false; ids.len()];
    let mut out: Vec<Option<(usize, bool)>> = names
        .iter()
        .map(|n| match by_text.get(*n).map(Vec::as_slice) {
            Some(&[f]) => {
                taken[f] = true;
                Some((f, true))
            }
            _ => None,
        })
        .collect();
    // Integer ids by value, the others by text, for the stems.
    let mut by_int: HashMap<i64, Vec<usize>> = HashMap::new();
    for (f, id) in ids.iter().enumerate().filter(|(f, _)| !taken[*f]) {
        if let Id::Int(v) = id {
            by_int.entry(*v).or_default().push(f);
        }
    }
    let mut claims: Vec<Vec<usize>> = vec![Vec::new(); ids.len()];
    let mut wants: Vec<Vec<usize>> = vec![Vec::new(); names.len()];
    for (i, name) in names.iter().enumerate().filter(|(i, _)| out[*i].is_none()) {
        let stem = image_stem(name);
        let mut fs: Vec<usize> = by_text.get(stem).cloned().unwrap_or_default();
        if let Id::Int(v) = Id::parse(stem) {
            fs.extend(by_int.get(&v).into_iter().flatten());
        }
        fs.retain(|&f| !taken[f] && stem_matches(stem, &ids[f]));
        fs.sort_unstable();
        fs.dedup();
        for &f in &fs {
            claims[f].push(i);
        }
        wants[i] = fs;
    }
    for (i, fs) in wants.iter().enumerate() {
        if let &[f] = fs.as_slice()
            && claims[f].len() == 1
        {
            out[i] = Some((f, false));
        }
    }
    out
}

/// Bit patterns of a point, to find a point written by two exact (shortest round-trip)
/// writers.
fn xyz_key(v: &Vector3<f64>) -> [u64; 3] {
    [v.x.to_bits(), v.y.to_bits(), v.z.to_bits()]
}

/// The estimate's observations: from the track table given, else from its own COLMAP
/// export (`colmap/` next to its `reconstruction.json`), whose 3D points are its tracks'
/// points to the last bit (both files write numbers in their shortest exact form).
fn estimate_observations(
    est: &Scene,
    reference: &Path,
    opts: &EvalOptions,
) -> Result<Observations, EvalError> {
    let track_index: HashMap<&Id, usize> = est
        .points
        .iter()
        .enumerate()
        .map(|(k, (id, _))| (id, k))
        .collect();
    let mut by_frame: HashMap<Id, Vec<(usize, [f64; 2])>> = HashMap::new();
    let off = crate::colmap::PIXEL_CENTRE_OFFSET;
    if let Some(path) = &opts.tracks {
        let table = crate::table::read_tracks(path)?.table;
        for f in 0..table.n_frames() {
            let list = by_frame.entry(table.frame_ids()[f].clone()).or_default();
            for e in table.frame_row(f).entries() {
                if let Some(&k) = track_index.get(&table.track_ids()[e.track as usize]) {
                    list.push((k, [e.x + off, e.y + off]));
                }
            }
        }
        return Ok(Observations {
            source: path.clone(),
            by_frame,
        });
    }
    let folder = match est.path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let dir = folder.join("colmap");
    let no_obs = |reason: String| EvalError::NoObservations {
        estimate: est.path.clone(),
        reference: reference.to_path_buf(),
        reason,
    };
    if !dir.join(crate::colmap::IMAGES_TXT).is_file() {
        return Err(no_obs(format!(
            "reconstruction.json holds no 2D observations, and {} has no COLMAP export \
             (colmap/images.txt, written with a perspective result) to read them from; give \
             the track table the reconstruction was made from (rank3 eval --tracks FILE)",
            folder.display()
        )));
    }
    let export = crate::colmap::read_reference(&dir)?;
    let by_xyz: HashMap<[u64; 3], usize> = est
        .points
        .iter()
        .enumerate()
        .filter_map(|(k, (_, p))| p.map(|p| (xyz_key(&p), k)))
        .collect();
    let point_of: HashMap<u64, usize> = export
        .points
        .iter()
        .filter_map(|p| {
            let key = xyz_key(&Vector3::from(p.xyz));
            by_xyz.get(&key).map(|&k| (p.id, k))
        })
        .collect();
    if point_of.is_empty() && !export.points.is_empty() {
        return Err(no_obs(format!(
            "none of the {} 3D points of its COLMAP export {} is a point of the \
             reconstruction (written by another run?); give the track table the \
             reconstruction was made from (rank3 eval --tracks FILE)",
            export.points.len(),
            dir.display()
        )));
    }
    let ids: Vec<Id> = est.frames.iter().map(|f| f.id.clone()).collect();
    let names: Vec<&str> = export.images.iter().map(|im| im.name.as_str()).collect();
    for (im, frame) in export.images.iter().zip(match_frames(&names, &ids)) {
        let Some((f, _)) = frame else { continue };
        let list = by_frame.entry(ids[f].clone()).or_default();
        for &(xy, owner) in &im.points2d {
            if let Some(&k) = owner.and_then(|pid| point_of.get(&pid)) {
                list.push((k, xy));
            }
        }
    }
    Ok(Observations {
        source: dir,
        by_frame,
    })
}

/// Keypoints of one image that have a 3D point, in a grid of `cell`-pixel cells.
struct KeypointGrid<'a> {
    cell: f64,
    cells: HashMap<(i64, i64), Vec<usize>>,
    keypoints: &'a [([f64; 2], Option<u64>)],
}

impl<'a> KeypointGrid<'a> {
    fn new(keypoints: &'a [([f64; 2], Option<u64>)], cell: f64) -> Self {
        let mut cells: HashMap<(i64, i64), Vec<usize>> = HashMap::new();
        for (k, (xy, owner)) in keypoints.iter().enumerate() {
            if owner.is_some() {
                cells.entry(Self::key(xy, cell)).or_default().push(k);
            }
        }
        KeypointGrid {
            cell,
            cells,
            keypoints,
        }
    }

    fn key(xy: &[f64; 2], cell: f64) -> (i64, i64) {
        ((xy[0] / cell).floor() as i64, (xy[1] / cell).floor() as i64)
    }

    /// The 3D point of the keypoint nearest to `xy`, if one lies within the cell size.
    fn nearest(&self, xy: &[f64; 2]) -> Option<u64> {
        if !(xy[0].is_finite() && xy[1].is_finite()) {
            return None;
        }
        let (cx, cy) = Self::key(xy, self.cell);
        let mut best: Option<(f64, u64)> = None;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for &k in self.cells.get(&(cx + dx, cy + dy)).into_iter().flatten() {
                    let (p, owner) = &self.keypoints[k];
                    let d = (p[0] - xy[0]).hypot(p[1] - xy[1]);
                    if d <= self.cell && best.is_none_or(|(bd, _)| d < bd) {
                        best = owner.map(|o| (d, o));
                    }
                }
            }
        }
        best.map(|(_, o)| o)
    }
}

/// A few items of a list, and its length, for error messages.
fn examples<T: fmt::Display>(items: impl ExactSizeIterator<Item = T>) -> String {
    let n = items.len();
    let shown: Vec<String> = items.take(4).map(|x| format!("`{x}`")).collect();
    let more = if n > shown.len() { ", …" } else { "" };
    format!("{n}: {}{more}", shown.join(", "))
}

/// Scores `est` against the COLMAP model `model` (see [`evaluate_with`]).
fn compare_colmap(
    est: &Scene,
    model: &crate::colmap::ColmapReference,
    obs: &Observations,
    tolerance_px: f64,
) -> Result<Comparison, EvalError> {
    let ids: Vec<Id> = est.frames.iter().map(|f| f.id.clone()).collect();
    let names: Vec<&str> = model.images.iter().map(|im| im.name.as_str()).collect();
    let frame_of = match_frames(&names, &ids);
    let by_name = frame_of
        .iter()
        .flatten()
        .filter(|(_, exact)| *exact)
        .count();
    let by_stem = frame_of.iter().flatten().count() - by_name;
    if by_name + by_stem == 0 {
        return Err(EvalError::NoCommonFrames {
            estimate: est.path.clone(),
            reference: model.dir.clone(),
            reference_examples: examples(names.iter()),
            estimate_examples: examples(ids.iter()),
        });
    }

    // Votes: every observation of a track in a matched image for the 3D point of the
    // nearest keypoint within the tolerance.
    let point_index: HashMap<u64, usize> = model
        .points
        .iter()
        .enumerate()
        .map(|(k, p)| (p.id, k))
        .collect();
    let n = est.points.len();
    let mut seen = vec![0u32; n];
    let mut cast = vec![0u32; n];
    let mut votes: HashMap<(usize, usize), u32> = HashMap::new();
    for (im, frame) in model.images.iter().zip(&frame_of) {
        let Some((f, _)) = frame else { continue };
        let Some(list) = obs.by_frame.get(&ids[*f]) else {
            continue;
        };
        let grid = KeypointGrid::new(&im.points2d, tolerance_px);
        for (k, xy) in list {
            seen[*k] += 1;
            if let Some(&q) = grid.nearest(xy).and_then(|pid| point_index.get(&pid)) {
                cast[*k] += 1;
                *votes.entry((*k, q)).or_default() += 1;
            }
        }
    }
    // Each track's choice: the point holding a strict majority of its votes, at least 2.
    let mut best: Vec<Option<(usize, u32)>> = vec![None; n];
    for (&(k, q), &v) in &votes {
        if best[k].is_none_or(|(_, b)| v > b) {
            best[k] = Some((q, v));
        }
    }
    let mut claims: HashMap<usize, Vec<(usize, u32)>> = HashMap::new();
    for (k, b) in best.iter().enumerate() {
        if let Some((q, v)) = *b
            && v >= 2
            && 2 * v > cast[k]
        {
            claims.entry(q).or_default().push((k, v));
        }
    }
    // One track per point: the one with the most votes, none on a tie.
    let mut matched: Vec<(usize, usize)> = Vec::new();
    let mut ambiguous = vec![false; n];
    for (&q, tracks) in &claims {
        let top = tracks.iter().map(|t| t.1).max().unwrap_or(0);
        let winners: Vec<usize> = tracks.iter().filter(|t| t.1 == top).map(|t| t.0).collect();
        if winners.len() == 1 {
            matched.push((winners[0], q));
        }
        for &(k, _) in tracks {
            ambiguous[k] = winners.len() > 1 || k != winners[0];
        }
    }
    matched.sort_unstable();
    let tracks = seen.iter().filter(|&&s| s > 0).count();
    if matched.is_empty() {
        return Err(EvalError::NoMatchedPoints {
            estimate: est.path.clone(),
            reference: model.dir.clone(),
            tracks,
            frames: by_name + by_stem,
            tolerance_px,
        });
    }
    let is_matched: std::collections::HashSet<usize> = matched.iter().map(|m| m.0).collect();
    let unmatched: Vec<usize> = (0..n)
        .filter(|k| seen[*k] > 0 && !is_matched.contains(k))
        .collect();
    let (agree, total) = matched.iter().fold((0u64, 0u64), |(a, t), &(k, q)| {
        (a + votes[&(k, q)] as u64, t + seen[k] as u64)
    });

    // The reference side, with the estimate's ids.
    let cameras: HashMap<u32, &crate::colmap::ReferenceCamera> =
        model.cameras.iter().map(|c| (c.id, c)).collect();
    let mut frames = Vec::new();
    let mut focals: Vec<(u32, Option<f64>)> = Vec::new();
    for (im, frame) in model.images.iter().zip(&frame_of) {
        let Some((f, _)) = frame else { continue };
        frames.push(SceneFrame {
            id: ids[*f].clone(),
            rotation: im.rotation,
            centre: Some(-im.rotation.transpose() * im.translation),
        });
        focals.push((
            im.camera_id,
            cameras.get(&im.camera_id).and_then(|c| c.focal_px()),
        ));
    }
    let mut camera_models: Vec<String> = Vec::new();
    for c in &model.cameras {
        if !camera_models.contains(&c.model) {
            camera_models.push(c.model.clone());
        }
    }
    let (focal_px, intrinsics_note) = match focals.iter().find(|(_, f)| f.is_none()) {
        Some((id, _)) => (
            None,
            Some(format!(
                "camera {id} is a {} camera: intrinsics not compared (focal lengths are \
                 compared for SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV and \
                 FULL_OPENCV cameras)",
                cameras.get(id).map_or("?", |c| c.model.as_str())
            )),
        ),
        None => {
            let mut fs: Vec<f64> = focals.iter().filter_map(|f| f.1).collect();
            fs.sort_by(f64::total_cmp);
            let distinct = fs.windows(2).filter(|w| w[0] != w[1]).count() + 1;
            let note = (distinct > 1).then(|| {
                format!(
                    "the median of the focal lengths of the {} matched images",
                    fs.len()
                )
            });
            (Some(median(&fs)), note)
        }
    };
    let reference = Scene {
        path: model.dir.clone(),
        kind: SceneKind::Colmap,
        camera_model: CameraModel::Perspective,
        euclidean: true,
        structure: "points3D.txt",
        points: matched
            .iter()
            .map(|&(k, q)| {
                let p = &model.points[q];
                (est.points[k].0.clone(), finite3(p.xyz))
            })
            .collect(),
        frames,
        focal_px,
        rms_px: None,
    };
    let mut c = compare(est, &reference)?;
    c.points.reference = model.points.len();
    c.frames.reference = model.images.len();
    let unmatched_examples: Vec<Id> = unmatched
        .iter()
        .take(10)
        .map(|&k| est.points[k].0.clone())
        .collect();
    c.matching = Some(ColmapMatching {
        observations: obs.source.clone(),
        tolerance_px,
        images: model.images.len(),
        images_by_name: by_name,
        images_by_stem: by_stem,
        images_unmatched: model.images.len() - by_name - by_stem,
        tracks,
        tracks_matched: matched.len(),
        tracks_unmatched: unmatched.iter().filter(|&&k| !ambiguous[k]).count(),
        tracks_ambiguous: unmatched.iter().filter(|&&k| ambiguous[k]).count(),
        unmatched_examples,
        agreement: if total > 0 {
            agree as f64 / total as f64
        } else {
            0.0
        },
        camera_models,
        intrinsics_note,
    });
    Ok(c)
}

/// Scores the reconstruction at `estimate` ([`load_estimate`]) against `reference`: a
/// `truth.json` or `reconstruction.json` ([`load_reference`], then [`compare`]), or a
/// COLMAP text model — its folder, or one of its three files (a file named `cameras.txt`,
/// `images.txt` or `points3D.txt`, or starting with COLMAP's header comment, stands for
/// its folder). Against a COLMAP model:
///
/// * **frames**: an image matches the estimate frame whose id is its name (rank3's export
///   names images by frame id), or else — one to one — the frame whose id is its stem (the
///   name without folder and extension; a number equals an integer id whatever its leading
///   zeros: `frames/000042.png` is frame 42);
/// * **points**: the estimate's 2D observations are read from its own COLMAP export
///   (`colmap/` next to `reconstruction.json`) or from [`EvalOptions::tracks`]. In each
///   matched image, each observation of a track votes for the 3D point of the nearest
///   keypoint within [`EvalOptions::match_tolerance_px`]; a track matches the point
///   holding a strict majority of its votes, at least 2; a point chosen by several tracks
///   goes to the one with the most votes (to none on a tie). [`ColmapMatching`] reports the
///   counts;
/// * the reference is then a Euclidean perspective side (no reflection against a
///   perspective estimate), with camera centres `−Rᵀt` and the focal length of its
///   cameras ([`crate::colmap::ReferenceCamera::focal_px`]); the figures are
///   [`compare`]'s.
///
/// Errors: those of [`load_estimate`] and [`load_reference`]; [`EvalError::Input`]
/// (a malformed COLMAP model: file, line and field); [`EvalError::NoCommonFrames`],
/// [`EvalError::NoObservations`], [`EvalError::NoMatchedPoints`],
/// [`EvalError::InvalidTolerance`]; [`compare`]'s.
pub fn evaluate_with(
    estimate: &Path,
    reference: &Path,
    opts: &EvalOptions,
) -> Result<Comparison, EvalError> {
    let tol = opts.match_tolerance_px;
    if !(tol > 0.0 && tol.is_finite()) {
        return Err(EvalError::InvalidTolerance(tol));
    }
    let est = load_estimate(estimate)?;
    match resolve_reference(reference)? {
        ReferencePath::Json(file) => compare(&est, &load_json_reference(&file)?),
        ReferencePath::Colmap(dir) => {
            let model = crate::colmap::read_reference(&dir)?;
            let obs = estimate_observations(&est, &dir, opts)?;
            compare_colmap(&est, &model, &obs, tol)
        }
    }
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
            SceneKind::Colmap => "COLMAP model",
        };
        let m = self.matching.as_ref();
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
        let (common, sides) = match m {
            Some(_) => ("tracks matched to 3D points", (" tracks", " 3D points")),
            None => ("common track ids", ("", "")),
        };
        row(
            f,
            "points",
            format!(
                "{} compared of {} {common} (estimate {}{}, reference {}{}; {} vs {})",
                p.compared,
                p.common,
                p.estimate,
                sides.0,
                p.reference,
                sides.1,
                self.estimate_structure,
                self.reference_structure
            ),
        )?;
        if let Some(m) = m {
            row(
                f,
                "matching",
                format!(
                    "{} of {} tracks seen in the matched images matched ({} unmatched, {} \
                     ambiguous{}); {:.1} % of their observations within {} px of their 3D \
                     point's keypoints (observations from {})",
                    m.tracks_matched,
                    m.tracks,
                    m.tracks_unmatched,
                    m.tracks_ambiguous,
                    if m.unmatched_examples.is_empty() {
                        String::new()
                    } else {
                        let ids: Vec<String> =
                            m.unmatched_examples.iter().map(|i| i.to_string()).collect();
                        format!(
                            ": {}{}",
                            ids.join(", "),
                            if m.tracks_unmatched + m.tracks_ambiguous > ids.len() {
                                ", …"
                            } else {
                                ""
                            }
                        )
                    },
                    100.0 * m.agreement,
                    m.tolerance_px,
                    m.observations.display()
                ),
            )?;
        }
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
            match m {
                Some(m) => format!(
                    "{} matched images (estimate {} frames, reference {} images: {} by name, \
                     {} by stem, {} unmatched)",
                    fr.common,
                    fr.estimate,
                    fr.reference,
                    m.images_by_name,
                    m.images_by_stem,
                    m.images_unmatched
                ),
                None => format!(
                    "{} common frame ids (estimate {}, reference {})",
                    fr.common, fr.estimate, fr.reference
                ),
            },
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
        let note = m.and_then(|m| m.intrinsics_note.as_deref());
        row(
            f,
            "focal length",
            match (&self.focal, note) {
                (Some(x), note) => format!(
                    "{:.2} px vs {:.2} px: {:+.3} %{}",
                    x.estimate_px,
                    x.reference_px,
                    x.error_pct,
                    note.map_or(String::new(), |n| format!(" (reference: {n})"))
                ),
                (None, Some(n)) => none(n),
                (None, None) => none("both sides need one"),
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

#[cfg(test)]
mod tests {
    use super::*;

    fn ids(v: &[&str]) -> Vec<Id> {
        v.iter().map(|s| Id::parse(s)).collect()
    }

    #[test]
    fn image_names_match_frame_ids_by_name_then_stem() {
        assert_eq!(image_stem("frames/000042.png"), "000042");
        assert_eq!(image_stem("a\\b\\img.v2.jpg"), "img.v2");
        assert_eq!(image_stem(".hidden"), ".hidden");
        assert_eq!(image_stem("7"), "7");
        // rank3's export names images by their frame id: exact names first.
        let frames = ids(&["0", "1", "2", "frame_0007"]);
        let got = match_frames(&["2", "000001.png", "x/frame_0007.jpg", "zz.png"], &frames);
        assert_eq!(
            got,
            vec![Some((2, true)), Some((1, false)), Some((3, false)), None]
        );
        // A frame two stems claim, and a stem whose frame was taken by its exact name, are
        // left out.
        let got = match_frames(&["1.png", "01.jpg", "0", "0.png"], &frames);
        assert_eq!(got, vec![None, None, Some((0, true)), None]);
        // String ids that look like numbers match their text.
        let frames = vec![Id::Str("0042".into()), Id::Str("a b".into())];
        let got = match_frames(&["0042.png", "a_b"], &frames);
        assert_eq!(got, vec![Some((0, false)), Some((1, true))]);
    }

    #[test]
    fn the_nearest_keypoint_with_a_point_within_the_tolerance_votes() {
        let kps = vec![
            ([10.0, 10.0], Some(1)),
            ([11.0, 10.0], None),
            ([12.5, 10.0], Some(2)),
            ([-3.0, -3.0], Some(3)),
        ];
        let g = KeypointGrid::new(&kps, 2.0);
        assert_eq!(g.nearest(&[10.9, 10.0]), Some(1));
        assert_eq!(g.nearest(&[11.9, 10.0]), Some(2));
        assert_eq!(g.nearest(&[14.6, 10.0]), None);
        assert_eq!(g.nearest(&[-1.5, -2.5]), Some(3));
        assert_eq!(g.nearest(&[f64::NAN, 0.0]), None);
    }
}
