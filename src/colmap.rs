//! COLMAP sparse models in COLMAP's *text* format: `cameras.txt`, `images.txt` and
//! `points3D.txt` (<https://colmap.github.io/format.html>), written and read back.
//!
//! This is the hand-off from rank3's perspective reconstruction to COLMAP (bundle adjustment,
//! dense stereo, `image_undistorter`) and to tools that read COLMAP models, such as OpenMVS's
//! `InterfaceCOLMAP`. The types here are plain data with no tie to the rest of the pipeline:
//! fill a [`ColmapModel`] and call [`ColmapModel::write_text`].
//!
//! # The format
//!
//! Lines starting with `#` are comments. Fields are written separated by single spaces (COLMAP
//! cuts an image name at its first space); the reader accepts any run of spaces or tabs.
//!
//! * `cameras.txt`, one line per camera: `CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]`. The
//!   models read and written here are `SIMPLE_PINHOLE` (`f cx cy`), `PINHOLE`
//!   (`fx fy cx cy`) and `SIMPLE_RADIAL` (`f cx cy k`); see [`ColmapCameraModel`].
//! * `images.txt`, **two** lines per image: `IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME`,
//!   then the keypoints `POINTS2D[]` as `X Y POINT3D_ID` triples (`-1`: the keypoint has no
//!   3D point). The second line is written even when empty, as COLMAP requires.
//! * `points3D.txt`, one line per 3D point: `POINT3D_ID X Y Z R G B ERROR TRACK[]`, the track
//!   as `IMAGE_ID POINT2D_IDX` pairs, `POINT2D_IDX` being the zero-based position of the
//!   keypoint on its image's `POINTS2D` line.
//!
//! Ids are identifiers, not indices: they need be neither contiguous nor sorted. The files
//! keep the order of the vectors in [`ColmapModel`], so a model read back is equal to the one
//! written (see below for rotations).
//!
//! COLMAP 3.12 added `rigs.txt` and `frames.txt`. They are not written: COLMAP and pycolmap
//! read a model without them as one trivial rig per camera and one frame per image (the
//! format page calls this fully backwards compatible).
//!
//! # Conventions
//!
//! * **Poses are world-to-camera**: `x_cam = R x_world + t`, with the camera looking down its
//!   +Z axis, +X to the right and +Y down the image. The camera centre is `-Rᵀ t`. `R` is
//!   stored as the unit quaternion `QW QX QY QZ` (Hamilton convention, as in Eigen and
//!   nalgebra), written with `QW ≥ 0`. A rotation read back is within about 1e-15 of the
//!   one written, not bit-equal; every other number is written in the shortest form that
//!   parses back to the same `f64` and is read back exactly.
//! * **Pixel coordinates are COLMAP's**: the top-left *corner* of the image is `(0, 0)`, so
//!   the centre of the top-left pixel is `(0.5, 0.5)`. rank3's own tracker (`rank3 track`)
//!   puts the centre of the top-left pixel at `(0, 0)`. Nothing here converts: the caller
//!   passes coordinates already in COLMAP's convention, i.e. adds [`PIXEL_CENTRE_OFFSET`] to
//!   both coordinates of every keypoint **and** of the principal point `(cx, cy)` when they
//!   come from rank3's tracker. (Shifting both leaves every reprojection error unchanged; a
//!   model that shifts only one is off by half a pixel in COLMAP.)
//! * `ERROR` is the point's reprojection error in pixels; COLMAP uses `-1` for "not computed".
//! * Colours are 8-bit sRGB.
//!
//! # Errors and guarantees
//!
//! [`ColmapModel::validate`] checks what COLMAP relies on without checking it (unique ids,
//! references that resolve, tracks that agree with the keypoints' `POINT3D_ID`s, finite
//! numbers, rotation matrices, image names without white space) and returns
//! [`Error::InvalidModel`]. (pycolmap 4.2.1 reads many such models without an error: it cuts
//! an image name at its first space, keeps a keypoint whose 3D point does not exist with only
//! a warning, and lets a track claim a keypoint marked `-1`.) [`ColmapModel::write_text`]
//! validates first and writes nothing for an invalid model. [`ColmapModel::read_text`] never
//! panics on malformed input: every fault, including a dangling reference, is an
//! [`Error::Parse`] naming the file, the 1-based line and the field (`QX`,
//! `POINTS2D[3].POINT3D_ID`, `TRACK[1].IMAGE_ID`, ...).
//!
//! # Tracks of a model
//!
//! [`read_tracks`] reads only `images.txt` into a [`crate::TrackTable`] — one track per 3D
//! point id, one frame per image, ordered by name — so that `rank3 reconstruct DIR` takes a
//! COLMAP model's matches as its input.
//!
//! # A model as a reference
//!
//! [`read_reference`] reads a model to score a reconstruction against (`rank3 eval`,
//! [`crate::compare`]): as [`ColmapModel::read_text`], but its cameras may be of any of
//! COLMAP's camera models ([`ReferenceCamera`]), as in models COLMAP itself makes.
//!
//! # Cost
//!
//! Writing, reading and validating are linear in the number of cameras, images, keypoints
//! and track elements (hash maps for the id look-ups), and stream the files line by line.

use std::collections::{HashMap, HashSet};
use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::str::FromStr;

use nalgebra::{Matrix3, Quaternion, Rotation3, UnitQuaternion, Vector3};

use crate::atomic::FileSet;
use crate::{Error, Result};

/// Add this to both coordinates of a keypoint or principal point in rank3's tracker
/// convention (top-left pixel centre at `(0, 0)`) to get COLMAP's (top-left pixel centre at
/// `(0.5, 0.5)`). The COLMAP writer never applies it itself: see the module docs.
pub const PIXEL_CENTRE_OFFSET: f64 = 0.5;

/// File name of the cameras in a COLMAP text model.
pub const CAMERAS_TXT: &str = "cameras.txt";
/// File name of the images (poses and keypoints) in a COLMAP text model.
pub const IMAGES_TXT: &str = "images.txt";
/// File name of the 3D points in a COLMAP text model.
pub const POINTS3D_TXT: &str = "points3D.txt";

/// Files COLMAP would read instead of, or together with, a text model in the same folder
/// ([`ColmapModel::write_text`] refuses a folder holding one of them).
const CONFLICTING: [&str; 7] = [
    "cameras.bin",
    "images.bin",
    "points3D.bin",
    "rigs.bin",
    "frames.bin",
    "rigs.txt",
    "frames.txt",
];

/// A camera model and its parameters, in pixels, in COLMAP's parameter order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ColmapCameraModel {
    /// `SIMPLE_PINHOLE`: one focal length and the principal point.
    SimplePinhole { f: f64, cx: f64, cy: f64 },
    /// `PINHOLE`: focal lengths along x and y and the principal point.
    Pinhole { fx: f64, fy: f64, cx: f64, cy: f64 },
    /// `SIMPLE_RADIAL`: one focal length, the principal point and one radial distortion
    /// coefficient `k` on normalized coordinates (`u' = u (1 + k r²)`).
    SimpleRadial { f: f64, cx: f64, cy: f64, k: f64 },
    /// `OPENCV`: focal lengths along x and y, the principal point, radial `k1`, `k2` and
    /// tangential `p1`, `p2` on normalized coordinates (rank3 writes it for non-square
    /// pixels with `k₁`; its `k2`, `p1`, `p2` are 0).
    Opencv {
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
        k1: f64,
        k2: f64,
        p1: f64,
        p2: f64,
    },
}

impl ColmapCameraModel {
    /// COLMAP's name of the model (`SIMPLE_PINHOLE`, `PINHOLE`, `SIMPLE_RADIAL`).
    pub fn name(&self) -> &'static str {
        match self {
            Self::SimplePinhole { .. } => "SIMPLE_PINHOLE",
            Self::Pinhole { .. } => "PINHOLE",
            Self::SimpleRadial { .. } => "SIMPLE_RADIAL",
            Self::Opencv { .. } => "OPENCV",
        }
    }

    /// The parameters in COLMAP's order (as on a `cameras.txt` line).
    pub fn params(&self) -> Vec<f64> {
        match *self {
            Self::SimplePinhole { f, cx, cy } => vec![f, cx, cy],
            Self::Pinhole { fx, fy, cx, cy } => vec![fx, fy, cx, cy],
            Self::SimpleRadial { f, cx, cy, k } => vec![f, cx, cy, k],
            Self::Opencv {
                fx,
                fy,
                cx,
                cy,
                k1,
                k2,
                p1,
                p2,
            } => vec![fx, fy, cx, cy, k1, k2, p1, p2],
        }
    }

    /// The names of [`Self::params`], in the same order.
    pub fn param_names(&self) -> &'static [&'static str] {
        Self::names_of(self.name()).unwrap_or(&[])
    }

    fn names_of(model: &str) -> Option<&'static [&'static str]> {
        match model {
            "SIMPLE_PINHOLE" => Some(&["f", "cx", "cy"]),
            "PINHOLE" => Some(&["fx", "fy", "cx", "cy"]),
            "SIMPLE_RADIAL" => Some(&["f", "cx", "cy", "k"]),
            "OPENCV" => Some(&["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"]),
            _ => None,
        }
    }

    /// The model named `model` with parameters `params` (COLMAP's order), or the field at
    /// fault (`MODEL` or `PARAMS`) and a message.
    fn from_colmap(model: &str, params: &[f64]) -> std::result::Result<Self, (String, String)> {
        match (model, params) {
            ("SIMPLE_PINHOLE", &[f, cx, cy]) => Ok(Self::SimplePinhole { f, cx, cy }),
            ("PINHOLE", &[fx, fy, cx, cy]) => Ok(Self::Pinhole { fx, fy, cx, cy }),
            ("SIMPLE_RADIAL", &[f, cx, cy, k]) => Ok(Self::SimpleRadial { f, cx, cy, k }),
            ("OPENCV", &[fx, fy, cx, cy, k1, k2, p1, p2]) => Ok(Self::Opencv {
                fx,
                fy,
                cx,
                cy,
                k1,
                k2,
                p1,
                p2,
            }),
            _ => Err(match Self::names_of(model) {
                None => unsupported(model),
                Some(names) => (
                    "PARAMS".into(),
                    format!(
                        "{model} takes {} parameters ({}), found {}",
                        names.len(),
                        names.join(", "),
                        params.len()
                    ),
                ),
            }),
        }
    }
}

fn unsupported(model: &str) -> (String, String) {
    (
        "MODEL".into(),
        format!(
            "camera model `{model}` is not supported (rank3 reads SIMPLE_PINHOLE, PINHOLE, \
             SIMPLE_RADIAL and OPENCV)"
        ),
    )
}

/// One camera (intrinsics shared by the images that name its id).
#[derive(Debug, Clone, PartialEq)]
pub struct ColmapCamera {
    pub id: u32,
    pub model: ColmapCameraModel,
    /// Image size in pixels.
    pub width: u32,
    pub height: u32,
}

/// One registered image: its pose, camera and keypoints.
#[derive(Debug, Clone, PartialEq)]
pub struct ColmapImage {
    pub id: u32,
    pub camera_id: u32,
    /// File name relative to the image folder COLMAP is given; no white space.
    pub name: String,
    /// World-to-camera rotation and translation: `x_cam = R x_world + t`.
    pub rotation: Matrix3<f64>,
    pub translation: Vector3<f64>,
    /// 2D observations: pixel position (COLMAP's convention, see the module docs) and the
    /// `POINT3D_ID` it belongs to (`None` is written as `-1`).
    pub points2d: Vec<([f64; 2], Option<u64>)>,
}

/// One 3D point and its track.
#[derive(Debug, Clone, PartialEq)]
pub struct ColmapPoint {
    /// At most `i64::MAX`: COLMAP reads 3D point ids as signed 64-bit integers.
    pub id: u64,
    pub xyz: [f64; 3],
    pub rgb: [u8; 3],
    /// Reprojection error in pixels (`-1`: not computed).
    pub error: f64,
    /// `(IMAGE_ID, POINT2D_IDX)` pairs: the keypoints observing this point.
    pub track: Vec<(u32, usize)>,
}

/// A COLMAP sparse model: cameras, images and 3D points.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ColmapModel {
    pub cameras: Vec<ColmapCamera>,
    pub images: Vec<ColmapImage>,
    pub points: Vec<ColmapPoint>,
}

/// Where a problem found by [`ColmapModel::check`] is: an entry of one of the vectors (and so
/// a line of one of the files).
#[derive(Debug, Clone, Copy)]
enum Loc {
    Camera(usize),
    /// The image's first line (pose, camera, name).
    Image(usize),
    /// The image's second line (keypoints).
    Points2d(usize),
    Point(usize),
}

#[derive(Debug)]
struct Problem {
    loc: Loc,
    field: String,
    message: String,
}

fn problem(loc: Loc, field: impl Into<String>, message: impl Into<String>) -> Problem {
    Problem {
        loc,
        field: field.into(),
        message: message.into(),
    }
}

/// Line numbers of the entries of a model read from files, for error messages.
#[derive(Debug, Default)]
struct Lines {
    cameras: Vec<usize>,
    images: Vec<usize>,
    points2d: Vec<usize>,
    points: Vec<usize>,
}

impl ColmapModel {
    /// Writes `cameras.txt`, `images.txt` and `points3D.txt` into `dir` (created if needed),
    /// replacing earlier ones.
    ///
    /// The model is [validated](Self::validate) first; an invalid model writes nothing. Each
    /// file is written to a temporary name in `dir` and renamed into place only after all
    /// three were written and flushed to disk, so a failure leaves no half-written file
    /// (the temporary files are removed).
    ///
    /// Refuses ([`Error::InvalidConfig`]) a folder that holds a binary model
    /// (`cameras.bin`, ...) or `rigs.txt` / `frames.txt`: COLMAP would read those instead of,
    /// or together with, the files written here.
    pub fn write_text(&self, dir: &Path) -> Result<()> {
        self.validate()?;
        for name in CONFLICTING {
            if dir.join(name).symlink_metadata().is_ok() {
                return Err(Error::InvalidConfig {
                    field: "COLMAP model folder",
                    message: format!(
                        "{} already holds {name}, which COLMAP would read instead of (or \
                         together with) the text model; remove it or write to another folder",
                        dir.display()
                    ),
                });
            }
        }
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;

        type Body = fn(&ColmapModel, &mut BufWriter<File>) -> std::io::Result<()>;
        let files: [(&str, Body); 3] = [
            (CAMERAS_TXT, write_cameras),
            (IMAGES_TXT, write_images),
            (POINTS3D_TXT, write_points),
        ];
        // One set: a file that cannot be written replaces none of them.
        let mut set = FileSet::new();
        for (name, body) in files {
            set.add_with(&dir.join(name), |w| body(self, w))?;
        }
        set.commit()
    }

    /// Reads `cameras.txt`, `images.txt` and `points3D.txt` from `dir`.
    ///
    /// A file that cannot be read is an [`Error::Io`]; anything malformed (a wrong number of
    /// fields, a value that is not a number, an unsupported camera model, an incomplete
    /// `POINTS2D` triple or `TRACK` pair) and anything [`Self::validate`] rejects (a
    /// dangling reference, a track that disagrees with its keypoints, a duplicate id) is an
    /// [`Error::Parse`] naming the file, the 1-based line and the field.
    pub fn read_text(dir: &Path) -> Result<ColmapModel> {
        let mut lines = Lines::default();
        let cameras_path = dir.join(CAMERAS_TXT);
        let images_path = dir.join(IMAGES_TXT);
        let points_path = dir.join(POINTS3D_TXT);
        let model = ColmapModel {
            cameras: read_cameras(&cameras_path, &mut lines.cameras)?,
            images: read_images(&images_path, &mut lines.images, &mut lines.points2d)?,
            points: read_points(&points_path, &mut lines.points)?,
        };
        model.check_read(dir, &lines)?;
        Ok(model)
    }

    /// [`Self::check`] on a model read from the files in `dir`, the fault located by file
    /// and line.
    fn check_read(&self, dir: &Path, lines: &Lines) -> Result<()> {
        self.check().map_err(|p| {
            let (name, line) = match p.loc {
                Loc::Camera(i) => (CAMERAS_TXT, lines.cameras[i]),
                Loc::Image(i) => (IMAGES_TXT, lines.images[i]),
                Loc::Points2d(i) => (IMAGES_TXT, lines.points2d[i]),
                Loc::Point(i) => (POINTS3D_TXT, lines.points[i]),
            };
            Error::parse(dir.join(name), line, p.field, p.message)
        })
    }

    /// Checks the model is one COLMAP can use as it is:
    ///
    /// * camera, image and 3D point ids are unique; camera and image ids are not
    ///   `u32::MAX` and 3D point ids are at most `i64::MAX` (COLMAP's reserved and readable
    ///   ranges);
    /// * every image's `camera_id` names a camera; image names are unique, non-empty and
    ///   free of white space (COLMAP ends the line at the first space);
    /// * every track element names an image and one of its keypoints, and that keypoint's
    ///   `POINT3D_ID` is this point; no keypoint is listed twice; every keypoint with a
    ///   `POINT3D_ID` names a 3D point whose track lists it;
    /// * every number is finite and every rotation is a rotation matrix (`RᵀR = I` and
    ///   `det R = 1` within 1e-6).
    ///
    /// Returns [`Error::InvalidModel`] naming the entry (`images[2] (id 5)`) and the field.
    /// Linear in the size of the model.
    pub fn validate(&self) -> Result<()> {
        self.check().map_err(|p| {
            let at = match p.loc {
                Loc::Camera(i) => format!("cameras[{i}] (id {})", self.cameras[i].id),
                Loc::Image(i) | Loc::Points2d(i) => {
                    format!("images[{i}] (id {})", self.images[i].id)
                }
                Loc::Point(i) => format!("points[{i}] (id {})", self.points[i].id),
            };
            Error::InvalidModel(format!("{at}, field `{}`: {}", p.field, p.message))
        })
    }

    /// The checks of [`Self::validate`], locating the first fault.
    fn check(&self) -> std::result::Result<(), Problem> {
        let mut cameras: HashMap<u32, usize> = HashMap::with_capacity(self.cameras.len());
        for (i, c) in self.cameras.iter().enumerate() {
            let at = Loc::Camera(i);
            if c.id == u32::MAX {
                return Err(problem(
                    at,
                    "CAMERA_ID",
                    "4294967295 is COLMAP's invalid-camera marker",
                ));
            }
            if cameras.insert(c.id, i).is_some() {
                return Err(problem(
                    at,
                    "CAMERA_ID",
                    format!("camera id {} is used twice", c.id),
                ));
            }
            let names = c.model.param_names();
            for (k, v) in c.model.params().into_iter().enumerate() {
                if !v.is_finite() {
                    return Err(problem(
                        at,
                        format!("PARAMS[{k}]"),
                        format!("{} = {v} is not finite", names[k]),
                    ));
                }
            }
        }

        let mut images: HashMap<u32, usize> = HashMap::with_capacity(self.images.len());
        let mut names: HashSet<&str> = HashSet::with_capacity(self.images.len());
        for (i, im) in self.images.iter().enumerate() {
            let at = Loc::Image(i);
            if im.id == u32::MAX {
                return Err(problem(
                    at,
                    "IMAGE_ID",
                    "4294967295 is COLMAP's invalid-image marker",
                ));
            }
            if images.insert(im.id, i).is_some() {
                return Err(problem(
                    at,
                    "IMAGE_ID",
                    format!("image id {} is used twice", im.id),
                ));
            }
            if !cameras.contains_key(&im.camera_id) {
                return Err(problem(
                    at,
                    "CAMERA_ID",
                    format!("no camera has id {}", im.camera_id),
                ));
            }
            if im.name.is_empty() {
                return Err(problem(at, "NAME", "empty image name"));
            }
            if im.name.chars().any(char::is_whitespace) {
                return Err(problem(
                    at,
                    "NAME",
                    format!(
                        "image name {:?} contains white space, which COLMAP's text format \
                         cannot hold",
                        im.name
                    ),
                ));
            }
            if !names.insert(&im.name) {
                return Err(problem(
                    at,
                    "NAME",
                    format!("image name {:?} is used twice", im.name),
                ));
            }
            if !is_rotation(&im.rotation) {
                return Err(problem(
                    at,
                    "rotation (QW QX QY QZ)",
                    format!(
                        "not a rotation matrix (RᵀR = I and det R = 1 within 1e-6): {:?}",
                        im.rotation
                    ),
                ));
            }
            for (k, field) in ["TX", "TY", "TZ"].into_iter().enumerate() {
                if !im.translation[k].is_finite() {
                    return Err(problem(
                        at,
                        field,
                        format!("{} is not finite", im.translation[k]),
                    ));
                }
            }
        }

        let n_tracked = self.points.iter().map(|p| p.track.len()).sum();
        let mut tracked: HashSet<(u32, usize)> = HashSet::with_capacity(n_tracked);
        let mut points: HashMap<u64, usize> = HashMap::with_capacity(self.points.len());
        for (i, p) in self.points.iter().enumerate() {
            let at = Loc::Point(i);
            if p.id > i64::MAX as u64 {
                return Err(problem(
                    at,
                    "POINT3D_ID",
                    format!(
                        "{} is above 9223372036854775807: COLMAP reads 3D point ids as signed \
                         64-bit integers",
                        p.id
                    ),
                ));
            }
            if points.insert(p.id, i).is_some() {
                return Err(problem(
                    at,
                    "POINT3D_ID",
                    format!("3D point id {} is used twice", p.id),
                ));
            }
            for (k, field) in ["X", "Y", "Z"].into_iter().enumerate() {
                if !p.xyz[k].is_finite() {
                    return Err(problem(at, field, format!("{} is not finite", p.xyz[k])));
                }
            }
            if !p.error.is_finite() {
                return Err(problem(
                    at,
                    "ERROR",
                    format!("{} is not finite (COLMAP writes -1 for unknown)", p.error),
                ));
            }
            for (k, &(image_id, idx)) in p.track.iter().enumerate() {
                let Some(&ii) = images.get(&image_id) else {
                    return Err(problem(
                        at,
                        format!("TRACK[{k}].IMAGE_ID"),
                        format!("no image has id {image_id}"),
                    ));
                };
                let keypoints = &self.images[ii].points2d;
                let Some(&(_, owner)) = keypoints.get(idx) else {
                    return Err(problem(
                        at,
                        format!("TRACK[{k}].POINT2D_IDX"),
                        format!(
                            "image {image_id} has {} keypoints: index {idx} is out of range",
                            keypoints.len()
                        ),
                    ));
                };
                if owner != Some(p.id) {
                    let owner = match owner {
                        Some(o) => format!("belongs to 3D point {o}"),
                        None => "has POINT3D_ID -1".to_string(),
                    };
                    return Err(problem(
                        at,
                        format!("TRACK[{k}].POINT2D_IDX"),
                        format!("keypoint {idx} of image {image_id} {owner}, not {}", p.id),
                    ));
                }
                if !tracked.insert((image_id, idx)) {
                    return Err(problem(
                        at,
                        format!("TRACK[{k}]"),
                        format!("keypoint {idx} of image {image_id} is listed twice"),
                    ));
                }
            }
        }

        for (i, im) in self.images.iter().enumerate() {
            let at = Loc::Points2d(i);
            for (k, &([x, y], owner)) in im.points2d.iter().enumerate() {
                for (v, axis) in [(x, "X"), (y, "Y")] {
                    if !v.is_finite() {
                        return Err(problem(
                            at,
                            format!("POINTS2D[{k}].{axis}"),
                            format!("{v} is not finite"),
                        ));
                    }
                }
                let Some(pid) = owner else { continue };
                if !points.contains_key(&pid) {
                    return Err(problem(
                        at,
                        format!("POINTS2D[{k}].POINT3D_ID"),
                        format!("no 3D point has id {pid}"),
                    ));
                }
                if !tracked.contains(&(im.id, k)) {
                    return Err(problem(
                        at,
                        format!("POINTS2D[{k}].POINT3D_ID"),
                        format!(
                            "the track of 3D point {pid} does not list keypoint {k} of image {}",
                            im.id
                        ),
                    ));
                }
            }
        }
        Ok(())
    }
}

/// `RᵀR = I` and `det R = 1` within 1e-6, all entries finite.
fn is_rotation(r: &Matrix3<f64>) -> bool {
    r.iter().all(|v| v.is_finite())
        && (r.transpose() * r - Matrix3::identity()).amax() <= 1e-6
        && (r.determinant() - 1.0).abs() <= 1e-6
}

/// The unit quaternion `[w, x, y, z]` (Hamilton) of rotation `r`, with `w ≥ 0`.
fn quaternion_of(r: &Matrix3<f64>) -> [f64; 4] {
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*r));
    // Renormalize: `r` may be a rotation only to within the tolerance of `is_rotation`.
    let q = UnitQuaternion::new_normalize(q.into_inner()).into_inner();
    let s = if q.w < 0.0 { -1.0 } else { 1.0 };
    [s * q.w, s * q.i, s * q.j, s * q.k]
}

// Numbers are written with `{:?}`: the shortest text that parses back to the same f64
// (`0.1`, `1e-7`, `1.0`), which COLMAP's `std::stold` reads.

fn write_cameras(m: &ColmapModel, w: &mut BufWriter<File>) -> std::io::Result<()> {
    writeln!(w, "# Camera list with one line of data per camera:")?;
    writeln!(w, "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]")?;
    writeln!(w, "# Number of cameras: {}", m.cameras.len())?;
    for c in &m.cameras {
        write!(w, "{} {} {} {}", c.id, c.model.name(), c.width, c.height)?;
        for p in c.model.params() {
            write!(w, " {p:?}")?;
        }
        writeln!(w)?;
    }
    Ok(())
}

fn write_images(m: &ColmapModel, w: &mut BufWriter<File>) -> std::io::Result<()> {
    let observations: usize = m
        .images
        .iter()
        .map(|im| im.points2d.iter().filter(|(_, p)| p.is_some()).count())
        .sum();
    let mean = if m.images.is_empty() {
        0.0
    } else {
        observations as f64 / m.images.len() as f64
    };
    writeln!(w, "# Image list with two lines of data per image:")?;
    writeln!(
        w,
        "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME"
    )?;
    writeln!(w, "#   POINTS2D[] as (X, Y, POINT3D_ID)")?;
    writeln!(
        w,
        "# Number of images: {}, mean observations per image: {mean}",
        m.images.len()
    )?;
    for im in &m.images {
        let [qw, qx, qy, qz] = quaternion_of(&im.rotation);
        let t = &im.translation;
        writeln!(
            w,
            "{} {qw:?} {qx:?} {qy:?} {qz:?} {:?} {:?} {:?} {} {}",
            im.id, t[0], t[1], t[2], im.camera_id, im.name
        )?;
        for (k, ([x, y], p)) in im.points2d.iter().enumerate() {
            let sep = if k == 0 { "" } else { " " };
            match p {
                Some(p) => write!(w, "{sep}{x:?} {y:?} {p}")?,
                None => write!(w, "{sep}{x:?} {y:?} -1")?,
            }
        }
        writeln!(w)?;
    }
    Ok(())
}

fn write_points(m: &ColmapModel, w: &mut BufWriter<File>) -> std::io::Result<()> {
    let elements: usize = m.points.iter().map(|p| p.track.len()).sum();
    let mean = if m.points.is_empty() {
        0.0
    } else {
        elements as f64 / m.points.len() as f64
    };
    writeln!(w, "# 3D point list with one line of data per point:")?;
    writeln!(
        w,
        "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)"
    )?;
    writeln!(
        w,
        "# Number of points: {}, mean track length: {mean}",
        m.points.len()
    )?;
    for p in &m.points {
        let [x, y, z] = p.xyz;
        let [r, g, b] = p.rgb;
        write!(w, "{} {x:?} {y:?} {z:?} {r} {g} {b} {:?}", p.id, p.error)?;
        for (image_id, idx) in &p.track {
            write!(w, " {image_id} {idx}")?;
        }
        writeln!(w)?;
    }
    Ok(())
}

/// A text file read line by line with 1-based line numbers.
struct LineReader {
    path: PathBuf,
    lines: std::io::Lines<BufReader<File>>,
    line: usize,
}

impl LineReader {
    fn open(path: &Path) -> Result<Self> {
        let file = File::open(path).map_err(|e| Error::io(path, e))?;
        Ok(Self {
            path: path.to_path_buf(),
            lines: BufReader::new(file).lines(),
            line: 0,
        })
    }

    /// The next line, trimmed, whatever it holds.
    fn next_raw(&mut self) -> Result<Option<(usize, String)>> {
        match self.lines.next() {
            None => Ok(None),
            Some(Ok(text)) => {
                self.line += 1;
                Ok(Some((self.line, text.trim().to_string())))
            }
            Some(Err(e)) if e.kind() == std::io::ErrorKind::InvalidData => {
                self.line += 1;
                Err(Error::parse(
                    &self.path,
                    self.line,
                    "line",
                    "not valid UTF-8 text",
                ))
            }
            Some(Err(e)) => Err(Error::io(&self.path, e)),
        }
    }

    /// The next line that is neither empty nor a `#` comment.
    fn next_data(&mut self) -> Result<Option<(usize, String)>> {
        while let Some((n, text)) = self.next_raw()? {
            if !text.is_empty() && !text.starts_with('#') {
                return Ok(Some((n, text)));
            }
        }
        Ok(None)
    }
}

/// Parses `token` as field `field` of line `line`; `expected` describes a valid value.
fn parse_field<T: FromStr>(
    path: &Path,
    line: usize,
    field: &str,
    token: &str,
    expected: &str,
) -> Result<T> {
    token
        .parse()
        .map_err(|_| Error::parse(path, line, field, format!("`{token}` is not {expected}")))
}

const NUMBER: &str = "a number";

/// The fields of a fixed-layout line, or an error naming the first missing one.
fn fields<'a>(path: &Path, line: usize, text: &'a str, names: &[&str]) -> Result<Vec<&'a str>> {
    let tokens: Vec<&str> = text.split_ascii_whitespace().collect();
    if tokens.len() < names.len() {
        return Err(Error::parse(
            path,
            line,
            names[tokens.len()],
            format!(
                "missing: the line has {} fields, expected {}",
                tokens.len(),
                names.join(" ")
            ),
        ));
    }
    Ok(tokens)
}

fn read_cameras(path: &Path, lines: &mut Vec<usize>) -> Result<Vec<ColmapCamera>> {
    const NAMES: [&str; 4] = ["CAMERA_ID", "MODEL", "WIDTH", "HEIGHT"];
    let mut reader = LineReader::open(path)?;
    let mut cameras = Vec::new();
    while let Some((n, text)) = reader.next_data()? {
        let t = fields(path, n, &text, &NAMES)?;
        if ColmapCameraModel::names_of(t[1]).is_none() {
            let (field, message) = unsupported(t[1]);
            return Err(Error::parse(path, n, field, message));
        }
        let id = parse_field(path, n, "CAMERA_ID", t[0], "a camera id (0 to 4294967295)")?;
        let width = parse_field(
            path,
            n,
            "WIDTH",
            t[2],
            "a width in pixels (0 to 4294967295)",
        )?;
        let height = parse_field(
            path,
            n,
            "HEIGHT",
            t[3],
            "a height in pixels (0 to 4294967295)",
        )?;
        let params = t[4..]
            .iter()
            .enumerate()
            .map(|(k, s)| parse_field(path, n, &format!("PARAMS[{k}]"), s, NUMBER))
            .collect::<Result<Vec<f64>>>()?;
        let model = ColmapCameraModel::from_colmap(t[1], &params)
            .map_err(|(field, message)| Error::parse(path, n, field, message))?;
        cameras.push(ColmapCamera {
            id,
            model,
            width,
            height,
        });
        lines.push(n);
    }
    Ok(cameras)
}

fn read_images(
    path: &Path,
    lines: &mut Vec<usize>,
    points_lines: &mut Vec<usize>,
) -> Result<Vec<ColmapImage>> {
    const NAMES: [&str; 10] = [
        "IMAGE_ID",
        "QW",
        "QX",
        "QY",
        "QZ",
        "TX",
        "TY",
        "TZ",
        "CAMERA_ID",
        "NAME",
    ];
    let mut reader = LineReader::open(path)?;
    let mut images = Vec::new();
    while let Some((n, text)) = reader.next_data()? {
        let t = fields(path, n, &text, &NAMES)?;
        if t.len() > NAMES.len() {
            return Err(Error::parse(
                path,
                n,
                "NAME",
                format!(
                    "{} more field(s) after the name `{}`: the line ends at NAME, and image \
                     names cannot hold spaces",
                    t.len() - NAMES.len(),
                    t[9]
                ),
            ));
        }
        let id = parse_field(path, n, "IMAGE_ID", t[0], "an image id (0 to 4294967295)")?;
        let mut v = [0.0f64; 7];
        for k in 0..7 {
            v[k] = parse_field(path, n, NAMES[k + 1], t[k + 1], NUMBER)?;
        }
        let q = Quaternion::new(v[0], v[1], v[2], v[3]);
        let norm = q.norm();
        if !(norm.is_finite() && norm > 1e-12) {
            return Err(Error::parse(
                path,
                n,
                "QW",
                format!("the quaternion (QW, QX, QY, QZ) has norm {norm}: not a rotation"),
            ));
        }
        let rotation = UnitQuaternion::from_quaternion(q)
            .to_rotation_matrix()
            .into_inner();
        let camera_id = parse_field(path, n, "CAMERA_ID", t[8], "a camera id (0 to 4294967295)")?;

        // The keypoints are the next physical line, even if empty (COLMAP's layout). A file
        // that ends right after the first line is cut short: COLMAP drops that image.
        let Some((pn, ptext)) = reader.next_raw()? else {
            return Err(Error::parse(
                path,
                n + 1,
                "POINTS2D",
                "missing: the file ends after the image's first line (every image has a \
                 second, possibly empty, line of keypoints)",
            ));
        };
        let tokens: Vec<&str> = ptext.split_ascii_whitespace().collect();
        if !tokens.len().is_multiple_of(3) {
            let k = tokens.len() / 3;
            let missing = ["X", "Y", "POINT3D_ID"][tokens.len() % 3];
            return Err(Error::parse(
                path,
                pn,
                format!("POINTS2D[{k}].{missing}"),
                format!(
                    "missing: {} values is not a whole number of (X, Y, POINT3D_ID) triples",
                    tokens.len()
                ),
            ));
        }
        let mut points2d = Vec::with_capacity(tokens.len() / 3);
        for (k, c) in tokens.chunks_exact(3).enumerate() {
            let x = parse_field(path, pn, &format!("POINTS2D[{k}].X"), c[0], NUMBER)?;
            let y = parse_field(path, pn, &format!("POINTS2D[{k}].Y"), c[1], NUMBER)?;
            let owner = if c[2] == "-1" {
                None
            } else {
                Some(parse_field(
                    path,
                    pn,
                    &format!("POINTS2D[{k}].POINT3D_ID"),
                    c[2],
                    "a 3D point id (a non-negative integer) or -1",
                )?)
            };
            points2d.push(([x, y], owner));
        }
        images.push(ColmapImage {
            id,
            camera_id,
            name: t[9].to_string(),
            rotation,
            translation: Vector3::new(v[4], v[5], v[6]),
            points2d,
        });
        lines.push(n);
        points_lines.push(pn);
    }
    Ok(images)
}

fn read_points(path: &Path, lines: &mut Vec<usize>) -> Result<Vec<ColmapPoint>> {
    const NAMES: [&str; 8] = ["POINT3D_ID", "X", "Y", "Z", "R", "G", "B", "ERROR"];
    let mut reader = LineReader::open(path)?;
    let mut points = Vec::new();
    while let Some((n, text)) = reader.next_data()? {
        let t = fields(path, n, &text, &NAMES)?;
        let id = parse_field(
            path,
            n,
            "POINT3D_ID",
            t[0],
            "a 3D point id (a non-negative integer)",
        )?;
        let mut xyz = [0.0; 3];
        for k in 0..3 {
            xyz[k] = parse_field(path, n, NAMES[k + 1], t[k + 1], NUMBER)?;
        }
        let mut rgb = [0u8; 3];
        for k in 0..3 {
            rgb[k] = parse_field(path, n, NAMES[k + 4], t[k + 4], "a colour value (0 to 255)")?;
        }
        let error = parse_field(path, n, "ERROR", t[7], NUMBER)?;
        let rest = &t[8..];
        if !rest.len().is_multiple_of(2) {
            return Err(Error::parse(
                path,
                n,
                format!("TRACK[{}].POINT2D_IDX", rest.len() / 2),
                "missing: the track lists (IMAGE_ID, POINT2D_IDX) pairs",
            ));
        }
        let mut track = Vec::with_capacity(rest.len() / 2);
        for (k, c) in rest.chunks_exact(2).enumerate() {
            let image_id = parse_field(
                path,
                n,
                &format!("TRACK[{k}].IMAGE_ID"),
                c[0],
                "an image id (0 to 4294967295)",
            )?;
            let idx = parse_field(
                path,
                n,
                &format!("TRACK[{k}].POINT2D_IDX"),
                c[1],
                "a keypoint index (a non-negative integer)",
            )?;
            track.push((image_id, idx));
        }
        points.push(ColmapPoint {
            id,
            xyz,
            rgb,
            error,
            track,
        });
        lines.push(n);
    }
    Ok(points)
}

/// Compares image names in natural order: runs of digits by their value (`img2` before
/// `img10`), everything else character by character; equal-valued runs (`01`, `1`) by their
/// text, so the order is total.
pub fn natural_cmp(a: &str, b: &str) -> std::cmp::Ordering {
    use std::cmp::Ordering;
    let (mut x, mut y) = (a, b);
    loop {
        match (x.chars().next(), y.chars().next()) {
            (None, None) => return a.cmp(b),
            (None, Some(_)) => return Ordering::Less,
            (Some(_), None) => return Ordering::Greater,
            (Some(c), Some(d)) if c.is_ascii_digit() && d.is_ascii_digit() => {
                let run = |s: &str| s.find(|c: char| !c.is_ascii_digit()).unwrap_or(s.len());
                let (rx, ry) = (run(x), run(y));
                let (dx, dy) = (
                    x[..rx].trim_start_matches('0'),
                    y[..ry].trim_start_matches('0'),
                );
                let o = dx.len().cmp(&dy.len()).then_with(|| dx.cmp(dy));
                if o != Ordering::Equal {
                    return o;
                }
                (x, y) = (&x[rx..], &y[ry..]);
            }
            (Some(c), Some(d)) => {
                if c != d {
                    return c.cmp(&d);
                }
                (x, y) = (&x[c.len_utf8()..], &y[d.len_utf8()..]);
            }
        }
    }
}

/// The tracks of a COLMAP text model in `dir`, read from its `images.txt` alone (the
/// cameras and 3D points are not needed): every `POINT3D_ID` a keypoint names becomes one
/// track (id = the 3D point id, tracks in ascending id), every image one frame (id = its
/// `NAME`, an integer id when the name is one, frames in the natural order of the names,
/// [`natural_cmp`]). Keypoints with `POINT3D_ID` `-1` are unmatched: they are no
/// observation, and their number is reported in the warnings. Coordinates are converted to
/// rank3's convention (top-left pixel centre at `(0, 0)`): `x − 0.5`, `y − 0.5`
/// ([`PIXEL_CENTRE_OFFSET`]), the inverse of what [`crate::output::colmap_model`] writes.
///
/// A 3D point seen twice in one image (COLMAP allows it; a track table cannot hold it) keeps
/// its first keypoint there, and the others are reported in the warnings. Returns the table
/// and the warnings.
///
/// Errors: [`Error::Io`] when `images.txt` cannot be read (the message says so when the
/// folder holds a binary model, `images.bin`, instead); [`Error::Parse`] naming the line and
/// field for a malformed line, a coordinate that is not finite, or two images with the same
/// name; [`Error::EmptyTable`] when no keypoint names a 3D point.
pub fn read_tracks(dir: &Path) -> Result<(crate::TrackTable, Vec<String>)> {
    use crate::table::Id;
    let path = dir.join(IMAGES_TXT);
    if !path.is_file() {
        let hint = if dir.join("images.bin").is_file() {
            "the folder holds a binary COLMAP model (images.bin): convert it to text with \
             `colmap model_converter --input_path DIR --output_path DIR --output_type TXT`"
                .to_string()
        } else if dir.join("sparse").is_dir() {
            "a folder given as a track table must hold a COLMAP text model; COLMAP puts its \
             models in sparse/0, sparse/1, ...: give that folder"
                .to_string()
        } else {
            "a folder given as a track table must hold a COLMAP text model (images.txt)".into()
        };
        return Err(Error::io(
            &path,
            std::io::Error::new(std::io::ErrorKind::NotFound, hint),
        ));
    }
    let (mut lines, mut points_lines) = (Vec::new(), Vec::new());
    let images = read_images(&path, &mut lines, &mut points_lines)?;
    // Frames: images in natural order of their names, which must be unique.
    let mut order: Vec<usize> = (0..images.len()).collect();
    order.sort_by(|&a, &b| natural_cmp(&images[a].name, &images[b].name));
    for w in order.windows(2) {
        let (a, b) = (w[0].min(w[1]), w[0].max(w[1]));
        if images[a].name == images[b].name {
            return Err(Error::parse(
                &path,
                lines[b],
                "NAME",
                format!(
                    "image name `{}` is also the name of the image on line {}",
                    images[b].name, lines[a]
                ),
            ));
        }
    }
    // Tracks: the 3D point ids, ascending.
    let mut ids: Vec<u64> = images
        .iter()
        .flat_map(|im| im.points2d.iter().filter_map(|kp| kp.1))
        .collect();
    ids.sort_unstable();
    ids.dedup();
    if ids.is_empty() {
        return Err(Error::EmptyTable {
            path: Some(path),
            reason: "no keypoint names a 3D point (every POINT3D_ID is -1)".into(),
        });
    }
    let mut obs: Vec<(u32, u32, f64, f64)> = Vec::new();
    let (mut unmatched, mut repeated) = (0usize, Vec::new());
    let mut seen = vec![u32::MAX; ids.len()];
    for (frame, &i) in order.iter().enumerate() {
        let im = &images[i];
        for (k, &([x, y], owner)) in im.points2d.iter().enumerate() {
            for (v, c) in [(x, "X"), (y, "Y")] {
                if !v.is_finite() {
                    return Err(Error::parse(
                        &path,
                        points_lines[i],
                        format!("POINTS2D[{k}].{c}"),
                        format!("{v} is not a finite pixel coordinate"),
                    ));
                }
            }
            let Some(owner) = owner else {
                unmatched += 1;
                continue;
            };
            let track = ids.binary_search(&owner).unwrap_or_default();
            if seen[track] == frame as u32 {
                repeated.push((points_lines[i], k, owner));
                continue;
            }
            seen[track] = frame as u32;
            obs.push((
                frame as u32,
                track as u32,
                x - PIXEL_CENTRE_OFFSET,
                y - PIXEL_CENTRE_OFFSET,
            ));
        }
    }
    let frame_ids: Vec<Id> = order.iter().map(|&i| Id::parse(&images[i].name)).collect();
    let track_ids: Vec<Id> = ids
        .iter()
        .map(|&id| match i64::try_from(id) {
            Ok(v) => Id::Int(v),
            Err(_) => Id::Str(id.to_string()),
        })
        .collect();
    // Distinct names can still parse to the same id (`01` and `1`): keep the names then.
    let mut distinct = frame_ids.clone();
    distinct.sort();
    distinct.dedup();
    let frame_ids = if distinct.len() == frame_ids.len() {
        frame_ids
    } else {
        order
            .iter()
            .map(|&i| Id::Str(images[i].name.clone()))
            .collect()
    };
    let table = crate::TrackTable::from_observations(frame_ids, track_ids, &obs)
        .map_err(|_| Error::InvalidModel("a keypoint was counted twice".into()))?;
    let mut warnings = Vec::new();
    if unmatched > 0 {
        warnings.push(format!(
            "{}: {unmatched} keypoint(s) without a 3D point (POINT3D_ID -1) are not track \
             observations",
            path.display()
        ));
    }
    if let Some(&(line, k, owner)) = repeated.first() {
        warnings.push(format!(
            "{}: {} keypoint(s) name a 3D point already seen in the same image; the first \
             keypoint of each was kept (first: line {line}, POINTS2D[{k}], 3D point {owner})",
            path.display(),
            repeated.len()
        ));
    }
    Ok((table, warnings))
}

/// One camera of a COLMAP model read as a reference ([`read_reference`]): any of COLMAP's
/// camera models, its parameters in COLMAP's order.
#[derive(Debug, Clone, PartialEq)]
pub struct ReferenceCamera {
    pub id: u32,
    /// COLMAP's model name as written (`OPENCV`, `SIMPLE_RADIAL_FISHEYE`, ...).
    pub model: String,
    pub width: u32,
    pub height: u32,
    pub params: Vec<f64>,
}

/// COLMAP's perspective (pinhole-based) camera models whose focal length `rank3 eval`
/// compares, with their parameter counts: the focal length is `PARAMS[0]` for the
/// single-focal models, `(fx + fy) / 2` (`PARAMS[0]`, `PARAMS[1]`) for the others. The
/// fisheye models' focal lengths belong to another projection and are not compared.
const FOCAL_MODELS: [(&str, usize, bool); 6] = [
    ("SIMPLE_PINHOLE", 3, false),
    ("PINHOLE", 4, true),
    ("SIMPLE_RADIAL", 4, false),
    ("RADIAL", 5, false),
    ("OPENCV", 8, true),
    ("FULL_OPENCV", 12, true),
];

impl ReferenceCamera {
    /// The focal length in pixels for the models of `FOCAL_MODELS` (`(fx + fy) / 2` when
    /// there are two, COLMAP's mean focal length); `None` for any other model.
    pub fn focal_px(&self) -> Option<f64> {
        let &(_, _, two) = FOCAL_MODELS.iter().find(|(m, _, _)| *m == self.model)?;
        if two {
            Some(0.5 * (self.params[0] + self.params[1]))
        } else {
            Some(self.params[0])
        }
    }
}

/// A COLMAP text model read as a reference for `rank3 eval` ([`read_reference`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ColmapReference {
    /// The folder holding the three files.
    pub dir: PathBuf,
    pub cameras: Vec<ReferenceCamera>,
    pub images: Vec<ColmapImage>,
    pub points: Vec<ColmapPoint>,
}

/// Reads the COLMAP text model in `dir` (`cameras.txt`, `images.txt`, `points3D.txt`) as
/// [`ColmapModel::read_text`] does, except that the cameras may be of any of COLMAP's camera
/// models (a model made by COLMAP has `OPENCV`, `RADIAL`, fisheye cameras, ...): the model
/// name is kept as written and its parameters as numbers; the count is checked for the
/// models of [`ReferenceCamera::focal_px`]. Images and 3D points are read and checked as by
/// [`ColmapModel::read_text`] (ids, references, tracks that agree with the keypoints).
/// `rigs.txt` and `frames.txt` (COLMAP ≥ 3.12) are not read.
///
/// Errors: [`Error::Io`] for a missing or unreadable file (with a hint when the folder
/// holds a binary model instead); [`Error::Parse`] naming the file, the 1-based line and
/// the field for anything malformed.
pub fn read_reference(dir: &Path) -> Result<ColmapReference> {
    let images_path = dir.join(IMAGES_TXT);
    if !images_path.is_file() && dir.join("images.bin").is_file() {
        return Err(Error::io(
            &images_path,
            std::io::Error::new(
                std::io::ErrorKind::NotFound,
                "the folder holds a binary COLMAP model (images.bin): convert it to text with \
                 `colmap model_converter --input_path DIR --output_path DIR --output_type TXT`",
            ),
        ));
    }
    let mut lines = Lines::default();
    let cameras = read_any_cameras(&dir.join(CAMERAS_TXT), &mut lines.cameras)?;
    let images = read_images(&images_path, &mut lines.images, &mut lines.points2d)?;
    let points = read_points(&dir.join(POINTS3D_TXT), &mut lines.points)?;
    // The checks of `read_text`, the cameras standing in as pinholes (their own numbers
    // were checked when read).
    let model = ColmapModel {
        cameras: cameras
            .iter()
            .map(|c| ColmapCamera {
                id: c.id,
                model: ColmapCameraModel::SimplePinhole {
                    f: 1.0,
                    cx: 0.0,
                    cy: 0.0,
                },
                width: c.width,
                height: c.height,
            })
            .collect(),
        images,
        points,
    };
    model.check_read(dir, &lines)?;
    Ok(ColmapReference {
        dir: dir.to_path_buf(),
        cameras,
        images: model.images,
        points: model.points,
    })
}

/// `cameras.txt` with any camera model (see [`read_reference`]).
fn read_any_cameras(path: &Path, lines: &mut Vec<usize>) -> Result<Vec<ReferenceCamera>> {
    const NAMES: [&str; 4] = ["CAMERA_ID", "MODEL", "WIDTH", "HEIGHT"];
    let mut reader = LineReader::open(path)?;
    let mut cameras = Vec::new();
    while let Some((n, text)) = reader.next_data()? {
        let t = fields(path, n, &text, &NAMES)?;
        let id = parse_field(path, n, "CAMERA_ID", t[0], "a camera id (0 to 4294967295)")?;
        let model = t[1].to_string();
        if !model
            .chars()
            .all(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || c == '_')
        {
            return Err(Error::parse(
                path,
                n,
                "MODEL",
                format!("`{model}` is not a COLMAP camera model name (e.g. SIMPLE_RADIAL)"),
            ));
        }
        let width = parse_field(path, n, "WIDTH", t[2], "a width in pixels")?;
        let height = parse_field(path, n, "HEIGHT", t[3], "a height in pixels")?;
        let mut params = Vec::with_capacity(t.len() - 4);
        for (k, s) in t[4..].iter().enumerate() {
            let field = format!("PARAMS[{k}]");
            let v: f64 = parse_field(path, n, &field, s, NUMBER)?;
            if !v.is_finite() {
                return Err(Error::parse(path, n, field, format!("{v} is not finite")));
            }
            params.push(v);
        }
        let count = FOCAL_MODELS
            .iter()
            .find(|(m, _, _)| *m == model)
            .map(|&(_, count, _)| count);
        if let Some(count) = count.filter(|&c| c != params.len()) {
            return Err(Error::parse(
                path,
                n,
                "PARAMS",
                format!("{model} takes {count} parameters, found {}", params.len()),
            ));
        }
        cameras.push(ReferenceCamera {
            id,
            model,
            width,
            height,
            params,
        });
        lines.push(n);
    }
    Ok(cameras)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Unit;

    fn rot(axis: [f64; 3], angle: f64) -> Matrix3<f64> {
        Rotation3::from_axis_angle(&Unit::new_normalize(Vector3::from(axis)), angle).into_inner()
    }

    /// Three cameras (one per model), three images, five 3D points with non-contiguous ids,
    /// and one keypoint without a 3D point (image 1, keypoint 3).
    fn model() -> ColmapModel {
        let cameras = vec![
            ColmapCamera {
                id: 1,
                model: ColmapCameraModel::SimplePinhole {
                    f: 500.25,
                    cx: 320.5,
                    cy: 240.5,
                },
                width: 640,
                height: 480,
            },
            ColmapCamera {
                id: 7,
                model: ColmapCameraModel::SimpleRadial {
                    f: 812.123456789012,
                    cx: 400.0,
                    cy: 300.0,
                    k: -0.012345678901234567,
                },
                width: 800,
                height: 600,
            },
            ColmapCamera {
                id: 3,
                model: ColmapCameraModel::Pinhole {
                    fx: 1000.1,
                    fy: 999.9,
                    cx: 512.0,
                    cy: 384.0,
                },
                width: 1024,
                height: 768,
            },
        ];
        let image =
            |id, camera_id, name: &str, r, t: [f64; 3], kp: &[(f64, f64, i64)]| ColmapImage {
                id,
                camera_id,
                name: name.to_string(),
                rotation: r,
                translation: Vector3::from(t),
                points2d: kp
                    .iter()
                    .map(|&(x, y, p)| ([x, y], u64::try_from(p).ok()))
                    .collect(),
            };
        let images = vec![
            image(
                1,
                1,
                "frames/000001.png",
                Matrix3::identity(),
                [0.0, -0.0, 1e-7],
                &[
                    (10.5, 20.25, 10),
                    (0.1, 0.2, 11),
                    (639.999, 479.001, 25),
                    (1.0 / 3.0, 2.0 / 3.0, -1),
                ],
            ),
            image(
                2,
                7,
                "frames/000002.png",
                rot([0.2, -1.0, 0.3], 0.7),
                [0.123456789012345, 1e20, -3.5],
                &[
                    (100.0, 200.0, 11),
                    (101.5, 201.5, 10),
                    (5e-5, 7.0, 26),
                    (8.0, 9.0, 1000),
                ],
            ),
            image(
                5,
                3,
                "frames/000005.png",
                // Rotation by π: the quaternion has w = 0.
                rot([1.0, 1.0, 0.0], std::f64::consts::PI),
                [-1.0, 2.0, 3.0],
                &[
                    (1.0, 2.0, 1000),
                    (3.0, 4.0, 25),
                    (5.0, 6.0, 26),
                    (7.0, 8.0, 10),
                ],
            ),
        ];
        let point = |id, xyz, rgb, error, track: &[(u32, usize)]| ColmapPoint {
            id,
            xyz,
            rgb,
            error,
            track: track.to_vec(),
        };
        let points = vec![
            point(
                10,
                [0.1, 0.2, 0.3],
                [255, 0, 7],
                0.5,
                &[(1, 0), (2, 1), (5, 3)],
            ),
            point(
                11,
                [-1e-300, 1e300, 4.0],
                [1, 2, 3],
                -1.0,
                &[(1, 1), (2, 0)],
            ),
            point(25, [1.0, 2.0, 3.0], [0, 0, 0], 0.0, &[(1, 2), (5, 1)]),
            point(26, [4.0, 5.0, 6.0], [9, 9, 9], 1.25, &[(2, 2), (5, 2)]),
            point(1000, [7.0, 8.0, 9.0], [128, 64, 32], 2.0, &[(2, 3), (5, 0)]),
        ];
        ColmapModel {
            cameras,
            images,
            points,
        }
    }

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("rank3-colmap-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    /// `read` equals `written` with floats bit-equal, rotations within 1e-12.
    fn assert_same(read: &ColmapModel, written: &ColmapModel) {
        assert_eq!(read.cameras, written.cameras);
        assert_eq!(read.points, written.points);
        assert_eq!(read.images.len(), written.images.len());
        for (a, b) in read.images.iter().zip(&written.images) {
            assert_eq!(
                (a.id, a.camera_id, &a.name, &a.translation, &a.points2d),
                (b.id, b.camera_id, &b.name, &b.translation, &b.points2d)
            );
            let d = (a.rotation - b.rotation).amax();
            assert!(d <= 1e-12, "image {}: rotation off by {d:e}", a.id);
        }
    }

    #[test]
    fn writes_and_reads_back_the_same_model() {
        let dir = tmp("roundtrip");
        let m = model();
        m.validate().unwrap();
        m.write_text(&dir).unwrap();
        let back = ColmapModel::read_text(&dir).unwrap();
        assert_same(&back, &m);
        // Bit-equal, not merely close: shortest round-trip formatting.
        assert_eq!(back.points[1].xyz[0].to_bits(), (-1e-300f64).to_bits());
        assert_eq!(back.images[0].translation[1].to_bits(), (-0.0f64).to_bits());

        // Writing again replaces the files and leaves no temporary file behind.
        let mut m2 = m.clone();
        m2.points[0].rgb = [1, 1, 1];
        m2.write_text(&dir).unwrap();
        assert_same(&ColmapModel::read_text(&dir).unwrap(), &m2);
        let mut names: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        names.sort();
        assert_eq!(names, ["cameras.txt", "images.txt", "points3D.txt"]);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn files_follow_colmaps_layout() {
        let dir = tmp("layout");
        let mut m = model();
        // 90° about +z: Hamilton quaternion (cos 45°, 0, 0, sin 45°).
        m.images[0].rotation = Matrix3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
        m.write_text(&dir).unwrap();
        let cameras = std::fs::read_to_string(dir.join(CAMERAS_TXT)).unwrap();
        let lines: Vec<&str> = cameras.lines().collect();
        assert_eq!(lines[0], "# Camera list with one line of data per camera:");
        assert_eq!(lines[2], "# Number of cameras: 3");
        assert_eq!(lines[3], "1 SIMPLE_PINHOLE 640 480 500.25 320.5 240.5");
        assert_eq!(
            lines[4],
            "7 SIMPLE_RADIAL 800 600 812.123456789012 400.0 300.0 -0.012345678901234567"
        );
        assert_eq!(lines[5], "3 PINHOLE 1024 768 1000.1 999.9 512.0 384.0");

        let images = std::fs::read_to_string(dir.join(IMAGES_TXT)).unwrap();
        let lines: Vec<&str> = images.lines().collect();
        assert_eq!(
            lines[3],
            "# Number of images: 3, mean observations per image: 3.6666666666666665"
        );
        let h: Vec<&str> = lines[4].split(' ').collect();
        assert_eq!((h[0], h[8], h[9]), ("1", "1", "frames/000001.png"));
        let q: Vec<f64> = h[1..5].iter().map(|s| s.parse().unwrap()).collect();
        let s = std::f64::consts::FRAC_1_SQRT_2;
        for (a, b) in q.iter().zip([s, 0.0, 0.0, s]) {
            assert!((a - b).abs() < 1e-15, "{q:?}");
        }
        assert_eq!(&h[5..8], &["0.0", "-0.0", "1e-7"]);
        assert_eq!(
            lines[5],
            "10.5 20.25 10 0.1 0.2 11 639.999 479.001 25 0.3333333333333333 0.6666666666666666 -1"
        );
        // The rotation by π has w = 0 up to rounding, written with w ≥ 0.
        let w: f64 = lines[8].split(' ').nth(1).unwrap().parse().unwrap();
        assert!((0.0..1e-15).contains(&w), "{w}");

        let points = std::fs::read_to_string(dir.join(POINTS3D_TXT)).unwrap();
        let lines: Vec<&str> = points.lines().collect();
        assert_eq!(lines[2], "# Number of points: 5, mean track length: 2.2");
        assert_eq!(lines[3], "10 0.1 0.2 0.3 255 0 7 0.5 1 0 2 1 5 3");
        assert_eq!(lines[4], "11 -1e-300 1e300 4.0 1 2 3 -1.0 1 1 2 0");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn an_image_without_keypoints_keeps_its_empty_line() {
        let dir = tmp("empty-keypoints");
        let mut m = model();
        m.points.clear();
        for im in &mut m.images {
            im.points2d.clear();
        }
        m.write_text(&dir).unwrap();
        let images = std::fs::read_to_string(dir.join(IMAGES_TXT)).unwrap();
        assert_eq!(images.lines().count(), 4 + 2 * 3);
        assert_same(&ColmapModel::read_text(&dir).unwrap(), &m);
        std::fs::remove_dir_all(&dir).ok();
    }

    /// Writes the model, replaces line `line` (1-based) of `file` with `text`, reads back and
    /// returns (file name, line, field) of the parse error.
    fn parse_error(name: &str, file: &str, line: usize, text: &str) -> (String, usize, String) {
        let dir = tmp(name);
        model().write_text(&dir).unwrap();
        let path = dir.join(file);
        let old = std::fs::read_to_string(&path).unwrap();
        let mut lines: Vec<&str> = old.lines().collect();
        lines[line - 1] = text;
        std::fs::write(&path, lines.join("\n") + "\n").unwrap();
        let err = ColmapModel::read_text(&dir).unwrap_err();
        std::fs::remove_dir_all(&dir).ok();
        match err {
            Error::Parse {
                path, line, field, ..
            } => (
                path.file_name().unwrap().to_string_lossy().into_owned(),
                line,
                field,
            ),
            other => panic!("expected a parse error, got {other}"),
        }
    }

    fn expect(got: (String, usize, String), file: &str, line: usize, field: &str) {
        assert_eq!(got, (file.to_string(), line, field.to_string()));
    }

    #[test]
    fn malformed_cameras_name_line_and_field() {
        let c = CAMERAS_TXT;
        // Lines 1-3 are comments; camera 1 is line 4, camera 7 line 5, camera 3 line 6.
        expect(
            parse_error("c-model", c, 5, "7 OPENCV_FISHEYE 800 600 1 2 3 4 5 6 7 8"),
            c,
            5,
            "MODEL",
        );
        expect(
            parse_error("c-nparams", c, 5, "7 SIMPLE_RADIAL 800 600 1 2 3"),
            c,
            5,
            "PARAMS",
        );
        expect(
            parse_error("c-width", c, 4, "1 SIMPLE_PINHOLE abc 480 1 2 3"),
            c,
            4,
            "WIDTH",
        );
        expect(
            parse_error("c-id", c, 4, "-1 SIMPLE_PINHOLE 640 480 1 2 3"),
            c,
            4,
            "CAMERA_ID",
        );
        expect(
            parse_error("c-short", c, 6, "3 PINHOLE 1024"),
            c,
            6,
            "HEIGHT",
        );
        expect(
            parse_error("c-param", c, 6, "3 PINHOLE 1024 768 1 x 3 4"),
            c,
            6,
            "PARAMS[1]",
        );
        expect(
            parse_error("c-dup", c, 6, "1 PINHOLE 1024 768 1 2 3 4"),
            c,
            6,
            "CAMERA_ID",
        );
        expect(
            parse_error("c-nan", c, 6, "3 PINHOLE 1024 768 1 2 NaN 4"),
            c,
            6,
            "PARAMS[2]",
        );
    }

    #[test]
    fn malformed_images_name_line_and_field() {
        let i = IMAGES_TXT;
        // Lines 1-4 are comments; image 1 is lines 5-6, image 2 lines 7-8, image 5 lines 9-10.
        let header = "2 1 0 0 0 0 0 0 7 frames/000002.png";
        expect(
            parse_error("i-qx", i, 7, &header.replace("1 0 0 0", "1 zero 0 0")),
            i,
            7,
            "QX",
        );
        expect(
            parse_error("i-name", i, 7, "2 1 0 0 0 0 0 0 7"),
            i,
            7,
            "NAME",
        );
        expect(
            parse_error("i-space", i, 7, &format!("{header} copy.png")),
            i,
            7,
            "NAME",
        );
        expect(
            parse_error("i-cam", i, 7, &header.replace(" 7 ", " 8 ")),
            i,
            7,
            "CAMERA_ID",
        );
        expect(
            parse_error("i-zero-q", i, 7, &header.replace("2 1 0", "2 0 0")),
            i,
            7,
            "QW",
        );
        // Odd-length keypoints: the last triple lacks its POINT3D_ID.
        expect(
            parse_error("i-odd", i, 8, "100 200 11 101.5 201.5"),
            i,
            8,
            "POINTS2D[1].POINT3D_ID",
        );
        expect(parse_error("i-x", i, 8, "1e 200 11"), i, 8, "POINTS2D[0].X");
        expect(
            parse_error("i-id", i, 8, "100 200 -2"),
            i,
            8,
            "POINTS2D[0].POINT3D_ID",
        );
        // A keypoint naming a 3D point that does not exist.
        let line = "10.5 20.25 10 0.1 0.2 11 639.999 479.001 25 0.5 0.5 999";
        expect(
            parse_error("i-dangling", i, 6, line),
            i,
            6,
            "POINTS2D[3].POINT3D_ID",
        );
        // A keypoint naming an existing 3D point whose track does not list it.
        let line = "100.0 200.0 11 101.5 201.5 10 5e-5 7.0 26 8.0 9.0 1000 1 1 25";
        expect(
            parse_error("i-untracked", i, 8, line),
            i,
            8,
            "POINTS2D[4].POINT3D_ID",
        );
    }

    #[test]
    fn malformed_points_name_line_and_field() {
        let p = POINTS3D_TXT;
        // Lines 1-3 are comments; point 10 is line 4, ..., point 1000 line 8.
        let base = "10 0.1 0.2 0.3 255 0 7 0.5";
        expect(
            parse_error("p-odd", p, 4, &format!("{base} 1 0 2")),
            p,
            4,
            "TRACK[1].POINT2D_IDX",
        );
        expect(
            parse_error("p-rgb", p, 4, "10 0.1 0.2 0.3 300 0 7 0.5 1 0 2 1 5 3"),
            p,
            4,
            "R",
        );
        expect(
            parse_error("p-short", p, 5, "11 1 2 3 4 5 6"),
            p,
            5,
            "ERROR",
        );
        expect(
            parse_error("p-z", p, 4, "10 0.1 0.2 z 255 0 7 0.5 1 0 2 1 5 3"),
            p,
            4,
            "Z",
        );
        // Dangling references and a track that disagrees with the keypoints.
        let t = |track: &str| format!("{base} {track}");
        expect(
            parse_error("p-img", p, 4, &t("1 0 99 1 5 3")),
            p,
            4,
            "TRACK[1].IMAGE_ID",
        );
        expect(
            parse_error("p-idx", p, 4, &t("1 0 2 4 5 3")),
            p,
            4,
            "TRACK[1].POINT2D_IDX",
        );
        expect(
            parse_error("p-owner", p, 4, &t("1 0 2 0 5 3")),
            p,
            4,
            "TRACK[1].POINT2D_IDX",
        );
        expect(
            parse_error("p-none", p, 4, &t("1 0 1 3 2 1 5 3")),
            p,
            4,
            "TRACK[1].POINT2D_IDX",
        );
        expect(
            parse_error("p-twice", p, 4, &t("1 0 2 1 5 3 2 1")),
            p,
            4,
            "TRACK[3]",
        );
        // Keypoint (5, 3) names point 10, whose track no longer lists it.
        expect(
            parse_error("p-missing", p, 4, &t("1 0 2 1")),
            IMAGES_TXT,
            10,
            "POINTS2D[3].POINT3D_ID",
        );
        expect(
            parse_error("p-dup", p, 8, "10 7 8 9 1 1 1 2 2 3 5 0"),
            p,
            8,
            "POINT3D_ID",
        );
        expect(
            parse_error("p-big", p, 8, "18446744073709551615 7 8 9 1 1 1 2"),
            p,
            8,
            "POINT3D_ID",
        );
    }

    #[test]
    fn missing_files_and_bad_bytes_are_errors_not_panics() {
        let dir = tmp("missing");
        assert!(matches!(
            ColmapModel::read_text(&dir),
            Err(Error::Io { .. })
        ));
        model().write_text(&dir).unwrap();
        std::fs::write(dir.join(POINTS3D_TXT), b"# ok\n\xff\xfe\n").unwrap();
        match ColmapModel::read_text(&dir) {
            Err(Error::Parse { line, .. }) => assert_eq!(line, 2),
            other => panic!("{other:?}"),
        }
        // Images without keypoints have an empty second line; a file ending right after an
        // image's first line is cut short (COLMAP drops that image).
        std::fs::write(dir.join(POINTS3D_TXT), "").unwrap();
        let images = "# c\n1 1 0 0 0 0 0 0 1 a.png\n\n2 1 0 0 0 0 0 0 7 b.png\n";
        std::fs::write(dir.join(IMAGES_TXT), format!("{images}\n")).unwrap();
        let m = ColmapModel::read_text(&dir).unwrap();
        assert_eq!(m.images.len(), 2);
        assert!(m.images.iter().all(|im| im.points2d.is_empty()));
        std::fs::write(dir.join(IMAGES_TXT), images).unwrap();
        match ColmapModel::read_text(&dir) {
            Err(Error::Parse { line, field, .. }) => {
                assert_eq!((line, field.as_str()), (5, "POINTS2D"))
            }
            other => panic!("{other:?}"),
        }
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn validate_catches_dangling_references_and_inconsistent_tracks() {
        let invalid = |m: ColmapModel, needle: &str| match m.validate() {
            Err(Error::InvalidModel(msg)) => assert!(msg.contains(needle), "{msg}"),
            other => panic!("expected InvalidModel containing {needle:?}, got {other:?}"),
        };
        let mut m = model();
        m.images[1].camera_id = 42;
        invalid(
            m,
            "images[1] (id 2), field `CAMERA_ID`: no camera has id 42",
        );
        let mut m = model();
        m.points[2].track[0].0 = 4;
        invalid(
            m,
            "points[2] (id 25), field `TRACK[0].IMAGE_ID`: no image has id 4",
        );
        let mut m = model();
        m.images[0].points2d[3].1 = Some(77);
        invalid(m, "field `POINTS2D[3].POINT3D_ID`: no 3D point has id 77");
        let mut m = model();
        m.points[0].track.pop();
        invalid(m, "does not list keypoint 3 of image 5");
        let mut m = model();
        m.cameras[2].id = 1;
        invalid(m, "camera id 1 is used twice");
        let mut m = model();
        m.images[2].name = "frames/000001.png".into();
        invalid(m, "is used twice");
        let mut m = model();
        m.images[0].rotation[(0, 0)] = 2.0;
        invalid(m, "not a rotation matrix");
        let mut m = model();
        m.points[4].xyz[1] = f64::NAN;
        invalid(m, "field `Y`: NaN is not finite");

        // An invalid model writes nothing.
        let dir = tmp("invalid");
        let mut m = model();
        m.points[0].track.push((1, 3));
        assert!(matches!(m.write_text(&dir), Err(Error::InvalidModel(_))));
        assert!(!dir.exists());
    }

    #[test]
    fn refuses_a_folder_holding_a_binary_model() {
        let dir = tmp("binary");
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("cameras.bin"), b"").unwrap();
        let err = model().write_text(&dir).unwrap_err();
        assert!(matches!(err, Error::InvalidConfig { .. }), "{err}");
        assert!(!dir.join(CAMERAS_TXT).exists());
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_reference_model_may_have_any_camera_model() {
        let dir = tmp("reference");
        let m = model();
        m.write_text(&dir).unwrap();
        let r = read_reference(&dir).unwrap();
        let strict = ColmapModel::read_text(&dir).unwrap();
        assert_eq!((&r.images, &r.points), (&strict.images, &strict.points));
        let focal: Vec<Option<f64>> = r.cameras.iter().map(|c| c.focal_px()).collect();
        assert_eq!(focal, [Some(500.25), Some(812.123456789012), Some(1000.0)]);
        // Lines 4-6 are the cameras.
        let cams = dir.join(CAMERAS_TXT);
        let write = |line: &str| {
            let text = std::fs::read_to_string(&cams).unwrap();
            let mut lines: Vec<&str> = text.lines().collect();
            lines[4] = line;
            std::fs::write(&cams, lines.join("\n") + "\n").unwrap();
        };
        write("7 OPENCV 800 600 810 790 400 300 0.1 0.2 0 0");
        assert_eq!(
            read_reference(&dir).unwrap().cameras[1].focal_px(),
            Some(800.0)
        );
        write("7 THIN_PRISM_FISHEYE 800 600 1 2 3 4 5 6 7 8 9 10 11 12");
        let r = read_reference(&dir).unwrap();
        assert_eq!(
            (r.cameras[1].model.as_str(), r.cameras[1].focal_px()),
            ("THIN_PRISM_FISHEYE", None)
        );
        for (line, field) in [
            ("7 OPENCV 800 600 810 790 400 300", "PARAMS"),
            ("7 RADIAL 800 600 1 2 x 4 5", "PARAMS[2]"),
            ("7 RADIAL 800 600 1 2 3 4 inf", "PARAMS[4]"),
            ("7 radial? 800 600 1", "MODEL"),
        ] {
            write(line);
            match read_reference(&dir) {
                Err(Error::Parse { line, field: f, .. }) => {
                    assert_eq!((line, f.as_str()), (5, field))
                }
                other => panic!("{other:?}"),
            }
        }
        // The other files are checked as by `read_text`.
        write("7 SIMPLE_RADIAL 800 600 1 2 3 4");
        std::fs::write(dir.join(POINTS3D_TXT), "10 0 0 0 1 2 3 0 1 0\n").unwrap();
        assert!(matches!(read_reference(&dir), Err(Error::Parse { .. })));
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn natural_order_of_image_names() {
        let mut names = vec![
            "img10.png",
            "img2.png",
            "img1.png",
            "img01.png",
            "b",
            "a10b",
            "a9c",
            "",
            "9",
            "10",
        ];
        names.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(
            names,
            [
                "",
                "9",
                "10",
                "a9c",
                "a10b",
                "b",
                "img01.png",
                "img1.png",
                "img2.png",
                "img10.png"
            ]
        );
        assert_eq!(natural_cmp("x", "x"), std::cmp::Ordering::Equal);
    }
}
