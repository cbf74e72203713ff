//! Synthetic scenes with ground truth: the basis of the tests and the README's first example.
//!
//! A shape (toy house, random cloud, cube) is seen by a (scaled) orthographic or a perspective
//! camera that moves on a turntable or along a handheld arc. Image noise, missing entries
//! (each track visible in one contiguous window, as a tracker loses points), outlier tracks
//! and gross per-entry errors can be added; the truth records which tracks/entries are
//! corrupted.
//!
//! Affine cameras (the same model as [`crate::MetricModel`]):
//! `[x, y] = s_f R_f[0..2] X_p + t_f`.
//!
//! Perspective camera ([`CameraModel::Perspective`]; [`CameraModel::Projective`] generates
//! the same scene): `w ≃ K_f (R_f X_p + t_f)` with `K_f = [[f_f, 0, cx], [0, f_f, cy], [0, 0,
//! 1]]`, `(cx, cy) =` [`PRINCIPAL_POINT`], the same rotations `R_f` as the affine scenes, and
//! the world origin at the object's centroid. The focal length is the same in every frame
//! unless [`SynthConfig::zoom`] is set, and a radial distortion [`SynthConfig::distortion`]
//! (COLMAP's `SIMPLE_RADIAL`) can be added. The camera looks at the centroid from
//! [`SynthConfig::distance`] object radii, with a small deterministic drift (see
//! [`PerspectiveTruth`]). The exact cameras are in [`SynthScene::perspective`];
//! [`SynthScene::truth`] holds their weak-perspective approximation.

use nalgebra::{Matrix3, Rotation3, Vector2, Vector3};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use crate::projective::Observation;
use crate::table::{Id, TrackTable};
use crate::{CameraModel, Error, MetricModel, Result};

/// Scene shape.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Shape {
    /// A toy house: a box (walls at right angles) with a gable roof; points on the walls
    /// and roof.
    #[default]
    House,
    /// Gaussian point cloud with anisotropic spread.
    Cloud,
    /// Points on the faces of a cube.
    Cube,
    /// Points on one plane (a 2 × 2 square, like a wall or the ground), its normal
    /// `(−0.5, 0.2, 1)` normalised: seen 27° off frontal at the start of either motion and
    /// never edge-on. The projective factorization and the absolute dual quadric are not
    /// determined by a plane; the perspective camera's planar start is
    /// ([`crate::perspective::planar`]).
    Plane,
}

/// Camera motion.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Motion {
    /// The object turns about its vertical axis by 90° in front of a camera tilted down by
    /// 20°.
    #[default]
    Turntable,
    /// A handheld camera on an arc: yaw sweeps 60°, with smooth pitch and roll wobble.
    HandheldArc,
}

/// Kind of outlier track.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum OutlierKind {
    /// Cycle through the kinds below.
    #[default]
    Mixed,
    /// A random walk from a true start position.
    RandomWalk,
    /// A point of a second rigid object that moves differently.
    SecondObject,
    /// A point that slides along an image line (as on an edge).
    Sliding,
}

/// How an extra rigid object moves (see [`SynthConfig::objects`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ObjectMotion {
    /// Turns about its own axis while drifting across the image.
    Rotating,
    /// Only drifts across the image, without turning (its tracks span a 2-dimensional
    /// affine subspace, inside the span of a rotating body's: the hard case of motion
    /// segmentation).
    Translating,
}

/// An extra rigid object, moving independently of the main one.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SynthObject {
    /// Fraction of the tracks on it, in (0, 1).
    pub share: f64,
    pub motion: ObjectMotion,
}

/// Settings of a synthetic scene.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SynthConfig {
    pub shape: Shape,
    pub motion: Motion,
    pub camera: CameraModel,
    /// Number of frames F. Default 30.
    pub frames: usize,
    /// Number of tracks N. Default 200.
    pub points: usize,
    /// Image noise standard deviation, pixels. Default 0.5.
    pub noise: f64,
    /// Target fraction of missing (frame, track) entries in [0, 0.9]; each track is visible
    /// in one contiguous window of at least `min_track_length` frames. Default 0.
    pub missing: f64,
    /// Shortest visible window when `missing > 0`. Default 3.
    pub min_track_length: usize,
    /// Fraction of tracks replaced by outlier tracks, in [0, 1). Default 0.
    pub outliers: f64,
    pub outlier_kind: OutlierKind,
    /// Fraction of observed entries (of inlier tracks) given a gross error of 15–60 px.
    /// Default 0.
    pub gross: f64,
    /// Total rotation of the motion in degrees (turntable turn, arc yaw sweep); `None`
    /// for the motion's default (90° turntable, 60° arc). Small sweeps make the metric
    /// upgrade ill-conditioned.
    pub sweep_deg: Option<f64>,
    /// Approximate image extent of the object, pixels. Default 400.
    pub image_size: f64,
    pub seed: u64,
    /// Focal length of the perspective camera, pixels. `None` (the default) for
    /// `distance · image_size / 2`: an object of diameter 2 radii seen from `distance` radii
    /// then spans about `image_size` pixels, and the weak-perspective scale is about 1, as
    /// in the affine scenes. Must be finite and positive. Ignored by the affine cameras.
    #[serde(default)]
    pub focal: Option<f64>,
    /// Distance of the perspective camera's centre from the object's centre (the centroid of
    /// the model points), in object radii (the largest distance of a model point from the
    /// centroid; a ratio, so the same before and after the scaling to `image_size`).
    /// Default [`DEFAULT_DISTANCE`] (4); must be finite and greater than [`MIN_DISTANCE`]
    /// (1.2) so that every point is in front of every camera, drift included. 2–3 is strong
    /// perspective, 20 or more nearly weak perspective. Ignored by the affine cameras.
    #[serde(default = "default_distance")]
    pub distance: f64,
    /// Extra rigid objects moving independently of the main one (motion segmentation);
    /// each is a copy of the shape at 0.35 × its size, placed beside it in the image and
    /// seen by the same camera. Empty by default. Their tracks are drawn among the
    /// non-outlier tracks; shares plus `outliers` must stay below 1.
    #[serde(default)]
    pub objects: Vec<SynthObject>,
    /// Zoom of the perspective camera over the sequence: the focal length of frame `f` is
    /// `focal_px · (1 + zoom)^a`, `a = f / (F − 1)` — a steady (geometric) zoom from
    /// [`SynthConfig::focal_px`] in frame 0 to `(1 + zoom) ·` that in the last frame
    /// ([`SynthConfig::frame_focal_px`]). Default 0 (a fixed focal length); 0.5 zooms in by
    /// half, −0.3 out by 30 %. Must be finite and greater than −1. The camera's distance
    /// does not follow the zoom, so the object's image grows by the same factor. Ignored by
    /// the affine cameras.
    #[serde(default)]
    pub zoom: f64,
    /// Radial distortion coefficient `k₁` of the perspective camera, on normalised
    /// coordinates: the image of a point `X_c = R_f X + t_f` (camera frame) is
    /// `f_f (1 + k₁ ‖n‖²) n + c`, `n = (X_c,1 / X_c,3, X_c,2 / X_c,3)` — COLMAP's
    /// `SIMPLE_RADIAL`, the model of [`crate::perspective::Metric`]. Default 0 (none).
    /// Negative is barrel distortion: −0.2 moves a point at ‖n‖ = 0.4 (the side of a
    /// 640-pixel-wide image at f = 800 px) inwards by 3.2 %. Must be finite and keep the
    /// image monotone over the scene (`1 + 3 k₁ ‖n‖² > 0` for every observed point;
    /// [`generate`] checks it). Ignored by the affine cameras.
    #[serde(default)]
    pub distortion: f64,
}

/// Default [`SynthConfig::distance`], object radii.
pub const DEFAULT_DISTANCE: f64 = 4.0;

/// [`SynthConfig::distance`] must exceed this, object radii.
pub const MIN_DISTANCE: f64 = 1.2;

/// Principal point `(cx, cy)` of the synthetic perspective camera, pixels: the image centre
/// at which the affine scenes' translations start (a 640×480 image).
pub const PRINCIPAL_POINT: [f64; 2] = [320.0, 240.0];

/// Relative depth drift of the perspective camera: the distance to the centroid is
/// `distance · radius · (1 − DEPTH_DRIFT · sin(π a))`, `a = f / (F − 1)`.
const DEPTH_DRIFT: f64 = 0.08;

fn default_distance() -> f64 {
    DEFAULT_DISTANCE
}

impl SynthConfig {
    /// Whether the scene is generated with the perspective camera
    /// ([`CameraModel::Perspective`] or [`CameraModel::Projective`]).
    pub fn is_perspective(&self) -> bool {
        matches!(
            self.camera,
            CameraModel::Perspective | CameraModel::Projective
        )
    }

    /// The perspective camera's focal length, pixels: [`SynthConfig::focal`] or its default
    /// `distance · image_size / 2`.
    pub fn focal_px(&self) -> f64 {
        self.focal.unwrap_or(0.5 * self.distance * self.image_size)
    }

    /// The perspective camera's focal length in frame `frame`, pixels:
    /// `focal_px · (1 + zoom)^a`, `a = frame / (frames − 1)` ([`SynthConfig::zoom`]).
    pub fn frame_focal_px(&self, frame: usize) -> f64 {
        let a = frame as f64 / self.frames.saturating_sub(1).max(1) as f64;
        self.focal_px() * (1.0 + self.zoom).powf(a)
    }
}

impl Default for SynthConfig {
    fn default() -> Self {
        Self {
            shape: Shape::House,
            motion: Motion::Turntable,
            camera: CameraModel::Orthographic,
            frames: 30,
            points: 200,
            noise: 0.5,
            missing: 0.0,
            min_track_length: 3,
            outliers: 0.0,
            outlier_kind: OutlierKind::Mixed,
            gross: 0.0,
            sweep_deg: None,
            image_size: 400.0,
            seed: 0,
            focal: None,
            distance: DEFAULT_DISTANCE,
            objects: Vec::new(),
            zoom: 0.0,
            distortion: 0.0,
        }
    }
}

/// A generated scene: the observed table and the truth.
#[derive(Debug, Clone)]
pub struct SynthScene {
    pub config: SynthConfig,
    pub table: TrackTable,
    /// The true cameras and points. Affine scenes: their noise-free projections are the
    /// inlier observations (outlier tracks: the projection of the true point they replaced).
    /// Perspective scenes: the points are centred at their centroid (the world origin), the
    /// rotations are the true `R_f`, and the scales and translations are the
    /// weak-perspective approximation of the true cameras about the centroid:
    /// `scales[f] = f_px / z̄_f` (`z̄_f` the centroid's depth) and `translations[f]` the
    /// centroid's perspective projection, so that [`MetricModel::project`] is the
    /// first-order approximation of [`PerspectiveTruth::project`].
    pub truth: MetricModel,
    /// The exact pinhole cameras of a perspective scene (`None` for the affine cameras).
    pub perspective: Option<PerspectiveTruth>,
    /// Which tracks are outliers, and of which kind.
    pub outlier_tracks: Vec<Option<OutlierKind>>,
    /// Observed entries with a gross error, as (frame, track) indices.
    pub gross_entries: Vec<(usize, usize)>,
    /// The object of every track: 0 = the main one (whose cameras and points `truth`
    /// holds), `k ≥ 1` = `config.objects[k − 1]` (its `truth` point is the shape point it
    /// was made from, not its position).
    pub objects: Vec<usize>,
}

/// The true pinhole cameras of a perspective scene: `w ≃ K_f (R_f X + t_f)`, pixels, with
/// `X` in the world frame of [`SynthScene::truth`]'s points (origin at the object's
/// centroid, world units = the units of the points).
///
/// Camera motion: `R_f` is the scene's rotation (turntable or handheld arc, as for the
/// affine cameras); `t_f = (δx_f, δy_f, z̄_f)ᵀ` is the centroid in camera coordinates, with
/// depth `z̄_f = distance · radius · (1 − 0.08 sin(π a))`, `a = f / (F − 1)` (the camera
/// comes up to 8 % closer mid-sequence and goes back), and a lateral drift
/// `(δx_f, δy_f) = (40 a, −25 a) · z̄_f / f_px` that moves the centroid's image from the
/// principal point by `(40 a, −25 a)` pixels, as the affine scenes' translations do. The
/// drift is perpendicular to the optical axis, so every point's depth is at least
/// `z̄_f − radius > 0` for `distance > 1.2`. The camera centre is `C_f = −R_fᵀ t_f`.
///
/// With a radial distortion `k₁` ([`SynthConfig::distortion`]) the image is
/// `f_f (1 + k₁ ‖n‖²) n + c`, `n` the dehomogenised `R_f X + t_f`
/// ([`PerspectiveTruth::project`]); [`PerspectiveTruth::projection`] is the undistorted
/// camera.
#[derive(Debug, Clone, PartialEq)]
pub struct PerspectiveTruth {
    /// Intrinsics `K_f = [[f_f, 0, cx], [0, f_f, cy], [0, 0, 1]]` per frame, pixels: focal
    /// length [`SynthConfig::frame_focal_px`] (all equal to [`SynthConfig::focal_px`]
    /// without zoom), principal point [`PRINCIPAL_POINT`].
    pub intrinsics: Vec<Matrix3<f64>>,
    /// World-to-camera rotations `R_f` (rows: the camera axes in world coordinates), the
    /// same as `SynthScene::truth.rotations`.
    pub rotations: Vec<Rotation3<f64>>,
    /// World-to-camera translations `t_f` (the world origin in camera coordinates), world
    /// units.
    pub translations: Vec<Vector3<f64>>,
    /// The object radius, world units: the largest distance of a true point from the
    /// centroid.
    pub radius: f64,
    /// Radial distortion coefficient `k₁` on normalised coordinates
    /// ([`SynthConfig::distortion`]; 0 = none).
    pub k1: f64,
}

impl PerspectiveTruth {
    /// Number of frames.
    pub fn n_frames(&self) -> usize {
        self.rotations.len()
    }

    /// The projection matrix `P_f = K_f [R_f | t_f]`, pixels: `w ≃ P_f (X, 1)ᵀ` (exactly
    /// when `k1` is 0; the undistorted image otherwise).
    pub fn projection(&self, f: usize) -> [[f64; 4]; 3] {
        let kr = self.intrinsics[f] * self.rotations[f].matrix();
        let kt = self.intrinsics[f] * self.translations[f];
        std::array::from_fn(|i| std::array::from_fn(|j| if j < 3 { kr[(i, j)] } else { kt[i] }))
    }

    /// The point `x` in frame `f`'s camera coordinates: `R_f x + t_f` (its third component
    /// is the depth).
    pub fn to_camera(&self, f: usize, x: &Vector3<f64>) -> Vector3<f64> {
        self.rotations[f] * x + self.translations[f]
    }

    /// Image position (pixels) of the world point `x` in frame `f`, distortion included.
    pub fn project(&self, f: usize, x: &Vector3<f64>) -> Vector2<f64> {
        pinhole(&self.intrinsics[f], self.k1, &self.to_camera(f, x))
    }

    /// Camera centre of frame `f` in world coordinates: `C_f = −R_fᵀ t_f`.
    pub fn centre(&self, f: usize) -> Vector3<f64> {
        -(self.rotations[f].inverse() * self.translations[f])
    }
}

/// Pixel position of the camera-frame point `xc` (in front of the camera) under `k` (zero
/// skew) with the radial distortion `k1`: `f (1 + k₁ ‖n‖²) n + c`, `n = dehom(xc)`.
fn pinhole(k: &Matrix3<f64>, k1: f64, xc: &Vector3<f64>) -> Vector2<f64> {
    let n = Vector2::new(xc[0] / xc[2], xc[1] / xc[2]);
    let d = 1.0 + k1 * n.norm_squared();
    Vector2::new(
        k[(0, 0)] * d * n[0] + k[(0, 2)],
        k[(1, 1)] * d * n[1] + k[(1, 2)],
    )
}

#[derive(Serialize)]
struct TruthFrame {
    frame: usize,
    rotation: [[f64; 3]; 3],
    translation: [f64; 2],
    scale: f64,
    #[serde(flatten)]
    perspective: Option<TruthPinhole>,
}

/// A perspective frame's exact camera in `truth.json`.
#[derive(Serialize)]
struct TruthPinhole {
    #[serde(rename = "K")]
    k: [[f64; 3]; 3],
    #[serde(rename = "R")]
    r: [[f64; 3]; 3],
    t: [f64; 3],
    #[serde(rename = "P")]
    p: [[f64; 4]; 3],
    camera_centre: [f64; 3],
}

/// Scene-wide perspective settings in `truth.json`.
#[derive(Serialize)]
struct TruthPerspective {
    /// Frame 0's focal length (every frame's without zoom; the frames' `K` give each).
    focal_px: f64,
    principal_point: [f64; 2],
    distance_radii: f64,
    radius: f64,
    /// Radial distortion coefficient (COLMAP `SIMPLE_RADIAL`), 0 = none.
    k1: f64,
}

#[derive(Serialize)]
struct TruthPoint {
    track: usize,
    xyz: [f64; 3],
    outlier: bool,
    outlier_kind: Option<OutlierKind>,
    /// 0 = the main object, k = `config.objects[k − 1]`.
    object: usize,
}

#[derive(Serialize)]
struct TruthEntry {
    frame: usize,
    track: usize,
}

#[derive(Serialize)]
struct TruthFile<'a> {
    config: &'a SynthConfig,
    camera_model: CameraModel,
    #[serde(skip_serializing_if = "Option::is_none")]
    perspective: Option<TruthPerspective>,
    frames: Vec<TruthFrame>,
    points: Vec<TruthPoint>,
    gross_entries: Vec<TruthEntry>,
    observations: usize,
    fill: f64,
}

impl SynthScene {
    /// `truth.json`: config, true cameras and points, corrupted tracks and entries.
    pub fn truth_json(&self) -> String {
        let m = &self.truth;
        let m3 = |a: &Matrix3<f64>| -> [[f64; 3]; 3] {
            std::array::from_fn(|i| std::array::from_fn(|j| a[(i, j)]))
        };
        let v3 = |v: &Vector3<f64>| [v[0], v[1], v[2]];
        let file = TruthFile {
            config: &self.config,
            camera_model: self.config.camera,
            perspective: self.perspective.as_ref().map(|pt| TruthPerspective {
                focal_px: self.config.focal_px(),
                principal_point: PRINCIPAL_POINT,
                distance_radii: self.config.distance,
                radius: pt.radius,
                k1: pt.k1,
            }),
            frames: (0..m.n_frames())
                .map(|f| TruthFrame {
                    frame: f,
                    rotation: m3(m.rotations[f].matrix()),
                    translation: [m.translations[f][0], m.translations[f][1]],
                    scale: m.scales[f],
                    perspective: self.perspective.as_ref().map(|pt| TruthPinhole {
                        k: m3(&pt.intrinsics[f]),
                        r: m3(pt.rotations[f].matrix()),
                        t: v3(&pt.translations[f]),
                        p: pt.projection(f),
                        camera_centre: v3(&pt.centre(f)),
                    }),
                })
                .collect(),
            points: (0..m.n_points())
                .map(|p| TruthPoint {
                    track: p,
                    xyz: [m.points[p][0], m.points[p][1], m.points[p][2]],
                    outlier: self.outlier_tracks[p].is_some(),
                    outlier_kind: self.outlier_tracks[p],
                    object: self.objects.get(p).copied().unwrap_or(0),
                })
                .collect(),
            gross_entries: self
                .gross_entries
                .iter()
                .map(|&(frame, track)| TruthEntry { frame, track })
                .collect(),
            observations: self.table.n_observed(),
            fill: self.table.fill(),
        };
        serde_json::to_string_pretty(&file).unwrap_or_default()
    }
}

fn check(cfg: &SynthConfig) -> Result<()> {
    if cfg.camera == CameraModel::Auto {
        return Err(Error::InvalidConfig {
            field: "camera",
            message: "a synthetic scene needs a definite camera (orthographic, \
                      scaled-orthographic or perspective), not auto"
                .into(),
        });
    }
    let bad = |field: &'static str, message: String| Err(Error::InvalidConfig { field, message });
    if cfg.frames < 3 {
        return bad("frames", format!("{} < 3", cfg.frames));
    }
    if cfg.points < 4 {
        return bad("points", format!("{} < 4", cfg.points));
    }
    // The scene's table is dense (F×N): sized against the table budget before anything is
    // allocated or written.
    let entries = cfg.frames.saturating_mul(cfg.points);
    if entries.saturating_mul(crate::budget::TABLE_ENTRY_BYTES) > crate::budget::DENSE_TABLE_BYTES {
        return Err(Error::TooLarge {
            what: format!(
                "a synthetic scene of {} frames × {} points",
                cfg.frames, cfg.points
            ),
            needed_bytes: entries.saturating_mul(crate::budget::TABLE_ENTRY_BYTES),
            budget_bytes: crate::budget::DENSE_TABLE_BYTES,
            advice: "choose fewer frames or points".into(),
        });
    }
    if !(cfg.noise >= 0.0 && cfg.noise.is_finite()) {
        return bad(
            "noise",
            format!("{} is not a non-negative number", cfg.noise),
        );
    }
    if !(0.0..=0.9).contains(&cfg.missing) {
        return bad("missing", format!("{} is not in [0, 0.9]", cfg.missing));
    }
    if cfg.min_track_length < 2 || cfg.min_track_length > cfg.frames {
        return bad(
            "min_track_length",
            format!("{} is not in [2, frames]", cfg.min_track_length),
        );
    }
    if !(0.0..1.0).contains(&cfg.outliers) {
        return bad("outliers", format!("{} is not in [0, 1)", cfg.outliers));
    }
    if cfg.objects.len() > 20 {
        return bad(
            "objects",
            format!("{} extra objects (at most 20)", cfg.objects.len()),
        );
    }
    if let Some(o) = cfg
        .objects
        .iter()
        .find(|o| !(o.share > 0.0 && o.share < 1.0))
    {
        return bad("objects", format!("share {} is not in (0, 1)", o.share));
    }
    let shares: f64 = cfg.objects.iter().map(|o| o.share).sum();
    if !(shares + cfg.outliers < 1.0) {
        return bad(
            "objects",
            format!(
                "the objects' shares ({shares}) and the outliers ({}) leave no track for the main object",
                cfg.outliers
            ),
        );
    }
    if !(0.0..0.5).contains(&cfg.gross) {
        return bad("gross", format!("{} is not in [0, 0.5)", cfg.gross));
    }
    if let Some(s) = cfg.sweep_deg
        && !(s.is_finite() && s.abs() <= 360.0)
    {
        return bad("sweep_deg", format!("{s} is not in [-360, 360]"));
    }
    if !(cfg.image_size > 0.0 && cfg.image_size.is_finite()) {
        return bad("image_size", format!("{} is not positive", cfg.image_size));
    }
    if let Some(f) = cfg.focal
        && !(f > 0.0 && f.is_finite())
    {
        return bad("focal", format!("{f} is not a positive number of pixels"));
    }
    if !(cfg.zoom > -1.0 && cfg.zoom.is_finite()) {
        return bad(
            "zoom",
            format!("{} is not a finite number greater than −1", cfg.zoom),
        );
    }
    if !cfg.distortion.is_finite() {
        return bad("distortion", format!("{} is not finite", cfg.distortion));
    }
    if !(cfg.distance > MIN_DISTANCE && cfg.distance.is_finite()) {
        return bad(
            "distance",
            format!(
                "{} is not a finite number of object radii > {MIN_DISTANCE}",
                cfg.distance
            ),
        );
    }
    Ok(())
}

fn shape_points(shape: Shape, n: usize, rng: &mut StdRng) -> Vec<Vector3<f64>> {
    let u = |rng: &mut StdRng, a: f64, b: f64| rng.random_range(a..b);
    (0..n)
        .map(|_| match shape {
            Shape::House => {
                // Box 2 (x) × 1.2 (y, up is -y in image terms: y down) × 1.4 (z), roof
                // ridge along x at height 0.6 above the walls.
                let (hw, hd, hh, rh) = (1.0, 0.7, 0.6, 0.6);
                let face = rng.random_range(0..6u32);
                match face {
                    0 | 1 => {
                        let z = if face == 0 { -hd } else { hd };
                        Vector3::new(u(rng, -hw, hw), u(rng, -hh, hh), z)
                    }
                    2 | 3 => {
                        let x = if face == 2 { -hw } else { hw };
                        Vector3::new(x, u(rng, -hh, hh), u(rng, -hd, hd))
                    }
                    _ => {
                        // Roof planes from the wall tops (y = -hh, z = ±hd) to the ridge
                        // (y = -hh - rh, z = 0).
                        let a = u(rng, 0.0, 1.0);
                        let side = if face == 4 { -1.0 } else { 1.0 };
                        Vector3::new(u(rng, -hw, hw), -hh - rh * a, side * hd * (1.0 - a))
                    }
                }
            }
            Shape::Cloud => {
                let g = Normal::new(0.0, 1.0).unwrap_or_else(|_| unreachable!());
                Vector3::new(
                    g.sample(rng) * 1.0,
                    g.sample(rng) * 0.7,
                    g.sample(rng) * 0.5,
                )
            }
            Shape::Plane => {
                let n = Vector3::new(-0.5, 0.2, 1.0).normalize();
                let a = n.cross(&Vector3::y()).normalize();
                let b = n.cross(&a);
                a * u(rng, -1.0, 1.0) + b * u(rng, -1.0, 1.0)
            }
            Shape::Cube => {
                let face = rng.random_range(0..6usize);
                let mut v = Vector3::new(u(rng, -1.0, 1.0), u(rng, -1.0, 1.0), u(rng, -1.0, 1.0));
                v[face / 2] = if face % 2 == 0 { -1.0 } else { 1.0 };
                v
            }
        })
        .collect()
}

/// Rotations `R_f` and the affine cameras' scales and translations.
fn camera_motion(cfg: &SynthConfig) -> (Vec<Rotation3<f64>>, Vec<f64>, Vec<Vector2<f64>>) {
    let f = cfg.frames;
    let mut rots = Vec::with_capacity(f);
    let mut scales = Vec::with_capacity(f);
    let mut trans = Vec::with_capacity(f);
    for k in 0..f {
        let a = k as f64 / (f - 1) as f64; // 0..1
        let r = match cfg.motion {
            Motion::Turntable => {
                let tilt = Rotation3::from_axis_angle(&Vector3::x_axis(), (-20.0f64).to_radians());
                let sweep = cfg.sweep_deg.unwrap_or(90.0);
                let turn = Rotation3::from_axis_angle(&Vector3::y_axis(), (sweep * a).to_radians());
                tilt * turn
            }
            Motion::HandheldArc => {
                let sweep = cfg.sweep_deg.unwrap_or(60.0);
                let w = sweep / 60.0;
                let yaw = (sweep * (a - 0.5)).to_radians();
                let pitch = (w * 10.0 * (2.0 * std::f64::consts::PI * a).sin() - 15.0).to_radians();
                let roll = (w * 5.0 * (3.0 * std::f64::consts::PI * a).cos()).to_radians();
                Rotation3::from_euler_angles(pitch, yaw, roll)
            }
        };
        rots.push(r);
        scales.push(match cfg.camera {
            CameraModel::Orthographic => 1.0,
            // The camera comes closer and goes back: magnification 1 → 1.3 → 1.
            CameraModel::ScaledOrthographic => 1.0 + 0.3 * (std::f64::consts::PI * a).sin(),
            // Replaced by the weak-perspective scale in `perspective_cameras`.
            CameraModel::Projective | CameraModel::Perspective | CameraModel::Auto => 1.0,
        });
        trans.push(Vector2::new(320.0 + 40.0 * a, 240.0 - 25.0 * a));
    }
    (rots, scales, trans)
}

/// The pinhole cameras of a perspective scene (see [`PerspectiveTruth`]) for points
/// centred at their centroid with the given radius, and their weak-perspective scales and
/// translations.
fn perspective_cameras(
    cfg: &SynthConfig,
    rotations: &[Rotation3<f64>],
    radius: f64,
) -> (PerspectiveTruth, Vec<f64>, Vec<Vector2<f64>>) {
    let [cx, cy] = PRINCIPAL_POINT;
    let n = rotations.len();
    let mut intrinsics = Vec::with_capacity(n);
    let mut translations = Vec::with_capacity(n);
    let mut scales = Vec::with_capacity(n);
    let mut image_translations = Vec::with_capacity(n);
    for fi in 0..n {
        let f_px = cfg.frame_focal_px(fi);
        let k = Matrix3::new(f_px, 0.0, cx, 0.0, f_px, cy, 0.0, 0.0, 1.0);
        let a = fi as f64 / (n - 1) as f64;
        let z = cfg.distance * radius * (1.0 - DEPTH_DRIFT * (std::f64::consts::PI * a).sin());
        let drift = Vector2::new(40.0 * a, -25.0 * a);
        let t = Vector3::new(drift[0] * z / f_px, drift[1] * z / f_px, z);
        scales.push(f_px / z);
        image_translations.push(pinhole(&k, cfg.distortion, &t));
        translations.push(t);
        intrinsics.push(k);
    }
    let truth = PerspectiveTruth {
        intrinsics,
        rotations: rotations.to_vec(),
        translations,
        radius,
        k1: cfg.distortion,
    };
    (truth, scales, image_translations)
}

/// The cameras that make the observations: every image position in [`generate`] comes from
/// [`Imaging::image`].
enum Imaging<'a> {
    /// `s_f R[0..2] x + t_f` with the scales and translations of the model.
    Affine(&'a MetricModel),
    /// `K_f (R x + t_f)`, dehomogenized.
    Perspective(&'a PerspectiveTruth),
}

impl Imaging<'_> {
    /// Image position of the point `x` turned by `r` (instead of `R_f`) and seen by frame
    /// `f`'s camera. With `r = R_f` this is the noise-free observation of `x` in frame `f`.
    fn image(&self, f: usize, r: &Rotation3<f64>, x: &Vector3<f64>) -> Vector2<f64> {
        match self {
            Imaging::Affine(m) => {
                let r = r.matrix();
                let s = m.scales[f];
                Vector2::new(
                    s * (r[(0, 0)] * x[0] + r[(0, 1)] * x[1] + r[(0, 2)] * x[2]),
                    s * (r[(1, 0)] * x[0] + r[(1, 1)] * x[1] + r[(1, 2)] * x[2]),
                ) + m.translations[f]
            }
            Imaging::Perspective(p) => {
                pinhole(&p.intrinsics[f], p.k1, &(r * x + p.translations[f]))
            }
        }
    }
}

/// Generates a scene. Errors only for out-of-range settings.
///
/// Cost O(F·N).
pub fn generate(cfg: &SynthConfig) -> Result<SynthScene> {
    check(cfg)?;
    let mut rng = StdRng::seed_from_u64(cfg.seed);
    let (f, n) = (cfg.frames, cfg.points);
    let unit = shape_points(cfg.shape, n, &mut rng);
    // Scale so the object spans about image_size pixels.
    let extent = unit
        .iter()
        .map(|p| p.norm())
        .fold(0.0f64, f64::max)
        .max(1e-9);
    let k = 0.5 * cfg.image_size / extent;
    let mut points: Vec<Vector3<f64>> = unit.iter().map(|p| p * k).collect();
    let (rotations, mut scales, mut translations) = camera_motion(cfg);
    let mut perspective = None;
    if cfg.is_perspective() {
        // The world origin at the object's centroid, the camera looking at it.
        let centroid = points.iter().sum::<Vector3<f64>>() / n as f64;
        points.iter_mut().for_each(|p| *p -= centroid);
        let radius = points
            .iter()
            .map(|p| p.norm())
            .fold(0.0f64, f64::max)
            .max(1e-9);
        let (pt, s, t) = perspective_cameras(cfg, &rotations, radius);
        // A barrel distortion must keep the image monotone in the radius over the scene:
        // d/dr [r (1 + k₁ r²)] = 1 + 3 k₁ r² > 0 at every point's normalised radius.
        if cfg.distortion < 0.0 {
            let r2 = (0..f)
                .flat_map(|fi| points.iter().map(move |x| (fi, x)))
                .map(|(fi, x)| {
                    let xc = pt.to_camera(fi, x);
                    (xc[0] * xc[0] + xc[1] * xc[1]) / (xc[2] * xc[2])
                })
                .fold(0.0f64, f64::max);
            if 1.0 + 3.0 * cfg.distortion * r2 <= 0.0 {
                return Err(Error::InvalidConfig {
                    field: "distortion",
                    message: format!(
                        "k₁ = {} folds the image over (1 + 3 k₁ ‖n‖² ≤ 0 at ‖n‖ = {:.3}); \
                         the scene needs k₁ > {:.4}",
                        cfg.distortion,
                        r2.sqrt(),
                        -1.0 / (3.0 * r2)
                    ),
                });
            }
        }
        (scales, translations) = (s, t);
        perspective = Some(pt);
    }
    let truth = MetricModel {
        rotations,
        translations,
        scales,
        points,
        aspect: 1.0,
    };
    let imaging = match &perspective {
        Some(pt) => Imaging::Perspective(pt),
        None => Imaging::Affine(&truth),
    };

    // Visibility windows.
    let mut visible = vec![true; f * n];
    if cfg.missing > 0.0 {
        let mean_len = ((1.0 - cfg.missing) * f as f64).max(cfg.min_track_length as f64);
        let spread = (mean_len - cfg.min_track_length as f64).min(f as f64 - mean_len);
        for p in 0..n {
            let len = (mean_len + rng.random_range(-spread..=spread))
                .round()
                .clamp(cfg.min_track_length as f64, f as f64) as usize;
            let start = rng.random_range(0..=(f - len));
            for fi in 0..f {
                visible[fi * n + p] = fi >= start && fi < start + len;
            }
        }
    }

    let noise = Normal::new(0.0, cfg.noise.max(0.0)).map_err(|e| Error::InvalidConfig {
        field: "noise",
        message: e.to_string(),
    })?;
    let mut table = TrackTable::new(
        (0..f).map(Id::from).collect(),
        (0..n).map(Id::from).collect(),
    );

    // Outlier tracks.
    let n_out = (cfg.outliers * n as f64).round() as usize;
    let mut order: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        let j = rng.random_range(0..=i);
        order.swap(i, j);
    }
    let mut outlier_tracks = vec![None; n];
    let kinds = [
        OutlierKind::RandomWalk,
        OutlierKind::SecondObject,
        OutlierKind::Sliding,
    ];
    for (i, &p) in order.iter().take(n_out).enumerate() {
        outlier_tracks[p] = Some(match cfg.outlier_kind {
            OutlierKind::Mixed => kinds[i % 3],
            k => k,
        });
    }
    // Extra rigid objects: the next tracks in the shuffled order.
    let mut objects = vec![0usize; n];
    let mut next = n_out;
    for (j, o) in cfg.objects.iter().enumerate() {
        let count = (o.share * n as f64).round() as usize;
        for &p in order.iter().skip(next).take(count) {
            objects[p] = j + 1;
        }
        next += count;
    }
    // Their motions: object j turns about its own axis (or not), starts beside the main
    // object and drifts.
    // (axis, total turn in radians, image offset, image drift) per object.
    type Path = (
        nalgebra::Unit<Vector3<f64>>,
        f64,
        Vector2<f64>,
        Vector2<f64>,
    );
    let object_motion: Vec<Path> = cfg
        .objects
        .iter()
        .enumerate()
        .map(|(j, o)| {
            let a = 2.4 * (j as f64 + 1.0);
            let axis = nalgebra::Unit::new_normalize(Vector3::new(a.cos(), 0.8, a.sin()));
            let turn = match o.motion {
                ObjectMotion::Rotating => 0.9 + 0.3 * j as f64,
                ObjectMotion::Translating => 0.0,
            };
            let side = if j % 2 == 0 { 1.0 } else { -1.0 };
            let offset = Vector2::new(side * 0.55, 0.25 * (j / 2) as f64) * cfg.image_size;
            let drift = Vector2::new(-side * 0.15, 0.1) * cfg.image_size;
            (axis, turn, offset, drift)
        })
        .collect();
    // An independently moving body's point `x` turned by `r`, in frame `fi`: seen by frame
    // 0's camera (the affine scenes keep frame `fi`'s scale), without the main camera's
    // image drift.
    let independent = |fi: usize, r: &Rotation3<f64>, x: &Vector3<f64>| {
        let cam = if perspective.is_some() { 0 } else { fi };
        imaging.image(cam, r, x) + (truth.translations[0] - truth.translations[cam])
    };
    // A second rigid object: spins the other way about a tilted axis.
    let second_axis = nalgebra::Unit::new_normalize(Vector3::new(0.3, 1.0, 0.4));
    for p in 0..n {
        let step = 0.02 * cfg.image_size;
        let mut walk = Vector2::zeros();
        let dir = {
            let a: f64 = rng.random_range(0.0..std::f64::consts::TAU);
            Vector2::new(a.cos(), a.sin())
        };
        let slide_speed =
            rng.random_range(1.0..4.0) * if rng.random_bool(0.5) { 1.0 } else { -1.0 };
        let x = &truth.points[p];
        for fi in 0..f {
            let clean = imaging.image(fi, &truth.rotations[fi], x);
            let xy = match outlier_tracks[p] {
                None if objects[p] > 0 => {
                    // Scaled down about the origin, turned, seen as the second object is.
                    let (axis, turn, offset, drift) = &object_motion[objects[p] - 1];
                    let a = fi as f64 / (f - 1).max(1) as f64;
                    let r2 = Rotation3::from_axis_angle(axis, turn * a) * truth.rotations[0];
                    independent(fi, &r2, &(x * 0.35)) + offset + drift * a
                }
                None | Some(OutlierKind::Mixed) => clean,
                Some(OutlierKind::RandomWalk) => {
                    walk +=
                        Vector2::new(rng.random_range(-step..step), rng.random_range(-step..step));
                    imaging.image(0, &truth.rotations[0], x) + walk
                }
                Some(OutlierKind::SecondObject) => {
                    // Turned about the world origin, seen by frame 0's camera (the affine
                    // scenes keep frame `fi`'s scale), drifting right.
                    let a = fi as f64 / (f - 1) as f64;
                    let r2 =
                        Rotation3::from_axis_angle(&second_axis, -1.2 * a) * truth.rotations[0];
                    independent(fi, &r2, x) + Vector2::new(60.0 * a, 0.0)
                }
                Some(OutlierKind::Sliding) => {
                    clean + dir * (slide_speed * fi as f64 * (cfg.image_size / 400.0))
                }
            };
            if visible[fi * n + p] {
                table.set(
                    fi,
                    p,
                    xy[0] + noise.sample(&mut rng),
                    xy[1] + noise.sample(&mut rng),
                );
            }
        }
    }

    // Gross per-entry errors on inlier tracks.
    let mut gross_entries = Vec::new();
    if cfg.gross > 0.0 {
        for fi in 0..f {
            for p in 0..n {
                if outlier_tracks[p].is_none()
                    && table.is_visible(fi, p)
                    && rng.random_bool(cfg.gross)
                {
                    let [x, y] = table.get(fi, p).unwrap_or([0.0, 0.0]);
                    let mag = rng.random_range(15.0..60.0) * (cfg.image_size / 400.0);
                    let a: f64 = rng.random_range(0.0..std::f64::consts::TAU);
                    table.set(fi, p, x + mag * a.cos(), y + mag * a.sin());
                    gross_entries.push((fi, p));
                }
            }
        }
    }

    Ok(SynthScene {
        config: cfg.clone(),
        table,
        truth,
        perspective,
        outlier_tracks,
        gross_entries,
        objects,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Extra objects take their share of the tracks, and each object's noise-free tracks
    /// are rigid (their centred trajectories have rank ≤ 3; the translating object's ≤ 2)
    /// while the union of two objects is not.
    #[test]
    fn extra_objects_are_rigid_and_independent() {
        let cfg = SynthConfig {
            noise: 0.0,
            points: 200,
            objects: vec![
                SynthObject {
                    share: 0.25,
                    motion: ObjectMotion::Rotating,
                },
                SynthObject {
                    share: 0.2,
                    motion: ObjectMotion::Translating,
                },
            ],
            ..Default::default()
        };
        let s = generate(&cfg).unwrap();
        let count = |k: usize| s.objects.iter().filter(|&&o| o == k).count();
        assert_eq!((count(0), count(1), count(2)), (110, 50, 40));
        let w = s.table.measurements().w;
        let sv = |cols: &[usize]| {
            let m = cols.len() as f64;
            let x = faer::Mat::from_fn(w.nrows(), cols.len(), |r, j| {
                w[(r, cols[j])] - cols.iter().map(|&c| w[(r, c)]).sum::<f64>() / m
            });
            x.singular_values().unwrap()
        };
        let of = |k: usize| (0..200).filter(|&p| s.objects[p] == k).collect::<Vec<_>>();
        for (k, rank) in [(0, 3), (1, 3), (2, 2)] {
            let v = sv(&of(k));
            assert!(v[rank] < 1e-8 * v[0], "object {k}: {:?}", &v[..4]);
            assert!(v[rank - 1] > 1e-3 * v[0], "object {k}: {:?}", &v[..4]);
        }
        let mut u = of(0);
        u.extend(of(1));
        let v = sv(&u);
        assert!(v[3] > 1e-3 * v[0], "union of two objects: {:?}", &v[..5]);
    }

    #[test]
    fn noise_free_complete_scene_matches_truth() {
        let cfg = SynthConfig {
            noise: 0.0,
            ..Default::default()
        };
        let s = generate(&cfg).unwrap();
        assert!(s.table.is_complete());
        let m = s.table.measurements();
        assert!(s.truth.rms(&m) < 1e-12);
    }

    #[test]
    fn missing_fraction_and_windows() {
        for target in [0.3, 0.5, 0.7] {
            let cfg = SynthConfig {
                frames: 40,
                points: 300,
                missing: target,
                seed: 7,
                ..Default::default()
            };
            let s = generate(&cfg).unwrap();
            let missing = 1.0 - s.table.fill();
            assert!((missing - target).abs() < 0.08, "{missing} vs {target}");
            for p in 0..s.table.n_tracks() {
                let vis: Vec<bool> = (0..40).map(|f| s.table.is_visible(f, p)).collect();
                let len = vis.iter().filter(|&&v| v).count();
                assert!(len >= 3);
                let first = vis.iter().position(|&v| v).unwrap();
                assert!(vis[first..first + len].iter().all(|&v| v), "contiguous");
            }
        }
    }

    #[test]
    fn outliers_and_gross_entries_are_recorded() {
        let cfg = SynthConfig {
            outliers: 0.3,
            gross: 0.02,
            seed: 3,
            ..Default::default()
        };
        let s = generate(&cfg).unwrap();
        let n_out = s.outlier_tracks.iter().filter(|o| o.is_some()).count();
        assert_eq!(n_out, 60);
        assert!(!s.gross_entries.is_empty());
        let m = s.table.measurements();
        for &(f, p) in &s.gross_entries {
            let d =
                (s.truth.project(f, p) - Vector2::new(m.w[(2 * f, p)], m.w[(2 * f + 1, p)])).norm();
            assert!(d > 10.0);
        }
        let v: serde_json::Value = serde_json::from_str(&s.truth_json()).unwrap();
        assert_eq!(v["points"].as_array().unwrap().len(), 200);
    }

    #[test]
    fn bad_settings_are_errors() {
        for cfg in [
            SynthConfig {
                frames: 2,
                ..Default::default()
            },
            SynthConfig {
                missing: 0.95,
                ..Default::default()
            },
            SynthConfig {
                noise: -1.0,
                ..Default::default()
            },
            SynthConfig {
                outliers: 1.0,
                ..Default::default()
            },
        ] {
            assert!(matches!(generate(&cfg), Err(Error::InvalidConfig { .. })));
        }
    }

    fn perspective(distance: f64) -> SynthConfig {
        SynthConfig {
            camera: CameraModel::Perspective,
            distance,
            noise: 0.0,
            frames: 12,
            points: 80,
            seed: 5,
            ..Default::default()
        }
    }

    /// `P_f (X, 1)ᵀ`, dehomogenized.
    fn apply(p: &[[f64; 4]; 3], x: &Vector3<f64>) -> Vector2<f64> {
        let h: [f64; 3] =
            std::array::from_fn(|i| p[i][0] * x[0] + p[i][1] * x[1] + p[i][2] * x[2] + p[i][3]);
        Vector2::new(h[0] / h[2], h[1] / h[2])
    }

    /// RMS over all entries of the perspective minus the weak-perspective image, pixels.
    fn weak_perspective_rms(s: &SynthScene) -> f64 {
        let pt = s.perspective.as_ref().unwrap();
        let (nf, np) = (s.truth.n_frames(), s.truth.n_points());
        let mut ss = 0.0;
        for f in 0..nf {
            for p in 0..np {
                ss += (pt.project(f, &s.truth.points[p]) - s.truth.project(f, p)).norm_squared();
            }
        }
        (ss / (2 * nf * np) as f64).sqrt()
    }

    #[test]
    fn noise_free_perspective_observations_are_p_times_x() {
        for (shape, motion) in [
            (Shape::House, Motion::Turntable),
            (Shape::Cloud, Motion::HandheldArc),
        ] {
            let s = generate(&SynthConfig {
                shape,
                motion,
                ..perspective(2.5)
            })
            .unwrap();
            let pt = s.perspective.as_ref().unwrap();
            assert!(s.table.is_complete());
            let m = s.table.measurements();
            let mut worst = 0.0f64;
            for f in 0..pt.n_frames() {
                let pm = pt.projection(f);
                for (p, x) in s.truth.points.iter().enumerate() {
                    assert!(pt.to_camera(f, x)[2] > 0.0, "in front");
                    let w = Vector2::new(m.w[(2 * f, p)], m.w[(2 * f + 1, p)]);
                    assert_eq!(w, pt.project(f, x), "observation = project");
                    worst = worst.max((apply(&pm, x) - w).norm());
                }
                // The camera centre is a null vector of P_f.
                let c = pt.centre(f);
                for row in pm {
                    let v = row[0] * c[0] + row[1] * c[1] + row[2] * c[2] + row[3];
                    let scale = row.iter().map(|a| a.abs()).sum::<f64>() * (c.norm() + 1.0);
                    assert!(v.abs() < 1e-12 * scale, "{v}");
                }
            }
            // Measured: 1.6e-13 px (house, turntable), 1.7e-13 px (cloud, arc).
            assert!(worst < 1e-9, "{worst} px");
            // Frame 0: no drift yet, the camera at `distance` radii from the centroid.
            assert!((pt.centre(0).norm() - 2.5 * pt.radius).abs() < 1e-9 * pt.radius);
            // The centroid is the world origin and projects to the truth's translation.
            let c = s.truth.points.iter().sum::<Vector3<f64>>() / s.truth.n_points() as f64;
            assert!(c.norm() < 1e-9 * pt.radius);
            for f in 0..pt.n_frames() {
                let o = pt.project(f, &Vector3::zeros());
                assert!((o - s.truth.translations[f]).norm() < 1e-9);
                let s_f = s.config.focal_px() / pt.translations[f][2];
                assert!((s.truth.scales[f] - s_f).abs() < 1e-12 * s_f);
            }
        }
    }

    /// RMS over all entries (house, turntable, 12 frames × 80 points, default focal) of the
    /// perspective image minus its weak-perspective approximation `s_f R_f X + t_f` about the
    /// centroid, measured: 16.2 px at distance 2.5, 9.4 px at 4 (the default), 0.69 px at
    /// 50 (about 1/distance, as the first-order theory says).
    #[test]
    fn perspective_differs_from_weak_perspective_by_distance() {
        let strong = weak_perspective_rms(&generate(&perspective(2.5)).unwrap());
        let default = weak_perspective_rms(&generate(&perspective(DEFAULT_DISTANCE)).unwrap());
        let weak = weak_perspective_rms(&generate(&perspective(50.0)).unwrap());
        eprintln!(
            "RMS perspective − weak perspective: D=2.5 {strong:.3} px, D=4 {default:.3} px, D=50 {weak:.3} px"
        );
        assert!(strong > 10.0, "{strong}");
        assert!(weak < 2.0, "{weak}");
        assert!(strong > default && default > weak);
    }

    #[test]
    fn default_focal_keeps_the_image_size() {
        let cfg = SynthConfig {
            camera: CameraModel::Perspective,
            ..Default::default()
        };
        assert_eq!(cfg.focal_px(), 800.0);
        let s = generate(&cfg).unwrap();
        let k = s.perspective.as_ref().unwrap().intrinsics[0];
        assert_eq!(
            k,
            Matrix3::new(800.0, 0.0, 320.0, 0.0, 800.0, 240.0, 0.0, 0.0, 1.0)
        );
        // The object spans about image_size pixels in frame 0.
        let m = s.table.measurements();
        let (lo, hi) = (0..s.table.n_tracks()).fold((f64::MAX, f64::MIN), |(lo, hi), p| {
            (lo.min(m.w[(0, p)]), hi.max(m.w[(0, p)]))
        });
        // Measured: 316 px across in x (the radius is the house's half-diagonal).
        assert!((250.0..500.0).contains(&(hi - lo)), "{}", hi - lo);
        // An explicit focal length is used as given.
        let s = generate(&SynthConfig {
            focal: Some(1234.0),
            ..cfg
        })
        .unwrap();
        assert_eq!(s.perspective.unwrap().intrinsics[3][(1, 1)], 1234.0);
    }

    #[test]
    fn projective_generates_the_perspective_scene() {
        let a = generate(&perspective(3.0)).unwrap();
        let b = generate(&SynthConfig {
            camera: CameraModel::Projective,
            ..perspective(3.0)
        })
        .unwrap();
        assert_eq!(a.perspective, b.perspective);
        assert_eq!(a.table.measurements().w, b.table.measurements().w);
        assert!(
            generate(&SynthConfig::default())
                .unwrap()
                .perspective
                .is_none()
        );
    }

    #[test]
    fn perspective_missing_outliers_and_gross_entries() {
        let cfg = SynthConfig {
            frames: 30,
            points: 200,
            missing: 0.5,
            outliers: 0.3,
            gross: 0.03,
            seed: 11,
            ..perspective(2.5)
        };
        let s = generate(&cfg).unwrap();
        let pt = s.perspective.as_ref().unwrap();
        let missing = 1.0 - s.table.fill();
        assert!((missing - 0.5).abs() < 0.08, "{missing}");
        assert_eq!(s.outlier_tracks.iter().filter(|o| o.is_some()).count(), 60);
        assert!(!s.gross_entries.is_empty());
        let gross: std::collections::HashSet<_> = s.gross_entries.iter().copied().collect();
        let mut outlier_offsets = Vec::new();
        for p in 0..s.table.n_tracks() {
            let vis: Vec<bool> = (0..30).map(|f| s.table.is_visible(f, p)).collect();
            let len = vis.iter().filter(|&&v| v).count();
            let first = vis.iter().position(|&v| v).unwrap();
            assert!(len >= 3 && vis[first..first + len].iter().all(|&v| v));
            for f in first..first + len {
                let [x, y] = s.table.get(f, p).unwrap();
                let d = (Vector2::new(x, y) - pt.project(f, &s.truth.points[p])).norm();
                match s.outlier_tracks[p] {
                    None if gross.contains(&(f, p)) => assert!(d > 10.0, "gross {d}"),
                    None => assert!(d < 1e-9, "inlier {d}"),
                    Some(_) => outlier_offsets.push(d),
                }
            }
        }
        // Outlier tracks leave the true track (all but their first frames).
        let far = outlier_offsets.iter().filter(|&&d| d > 5.0).count();
        assert!(
            far * 2 > outlier_offsets.len(),
            "{far} of {}",
            outlier_offsets.len()
        );
        // truth.json carries the exact cameras.
        let v: serde_json::Value = serde_json::from_str(&s.truth_json()).unwrap();
        let f3 = &v["frames"][3];
        for key in [
            "K",
            "R",
            "t",
            "P",
            "camera_centre",
            "rotation",
            "translation",
            "scale",
        ] {
            assert!(!f3[key].is_null(), "{key}");
        }
        let p3 = pt.projection(3);
        assert_eq!(f3["P"][1][3].as_f64().unwrap(), p3[1][3]);
        assert_eq!(
            v["perspective"]["focal_px"].as_f64().unwrap(),
            0.5 * 2.5 * 400.0
        );
        assert_eq!(v["config"]["distance"].as_f64().unwrap(), 2.5);
        let affine: serde_json::Value =
            serde_json::from_str(&generate(&SynthConfig::default()).unwrap().truth_json()).unwrap();
        assert!(affine["frames"][0]["P"].is_null() && affine["perspective"].is_null());
    }

    #[test]
    fn bad_focal_and_distance_name_the_field() {
        for (field, cfg) in [
            (
                "focal",
                SynthConfig {
                    focal: Some(0.0),
                    ..Default::default()
                },
            ),
            (
                "focal",
                SynthConfig {
                    focal: Some(-500.0),
                    ..Default::default()
                },
            ),
            (
                "focal",
                SynthConfig {
                    focal: Some(f64::NAN),
                    ..Default::default()
                },
            ),
            (
                "focal",
                SynthConfig {
                    focal: Some(f64::INFINITY),
                    ..Default::default()
                },
            ),
            (
                "distance",
                SynthConfig {
                    distance: 1.2,
                    ..Default::default()
                },
            ),
            (
                "distance",
                SynthConfig {
                    distance: 0.5,
                    ..Default::default()
                },
            ),
            (
                "distance",
                SynthConfig {
                    distance: -4.0,
                    ..Default::default()
                },
            ),
            (
                "distance",
                SynthConfig {
                    distance: f64::NAN,
                    ..Default::default()
                },
            ),
            (
                "distance",
                SynthConfig {
                    distance: f64::INFINITY,
                    ..Default::default()
                },
            ),
        ] {
            for camera in [CameraModel::Perspective, CameraModel::Orthographic] {
                match generate(&SynthConfig {
                    camera,
                    ..cfg.clone()
                }) {
                    Err(Error::InvalidConfig { field: f, .. }) => assert_eq!(f, field),
                    other => panic!("{field}: {other:?}"),
                }
            }
        }
        assert!(generate(&perspective(1.25)).is_ok());
    }

    /// Zoom: frame `f`'s focal length is `focal · (1 + zoom)^(f/(F−1))`, in `K_f`, in the
    /// weak-perspective scale and in the observations; without zoom every `K_f` is equal.
    #[test]
    fn zoom_sets_per_frame_focal_lengths() {
        let cfg = SynthConfig {
            zoom: 0.5,
            ..perspective(3.0)
        };
        let s = generate(&cfg).unwrap();
        let pt = s.perspective.as_ref().unwrap();
        let f0 = cfg.focal_px();
        assert_eq!(pt.intrinsics[0][(0, 0)], f0);
        assert!((pt.intrinsics[11][(1, 1)] - 1.5 * f0).abs() < 1e-9 * f0);
        let mid = f0 * 1.5f64.powf(5.0 / 11.0);
        assert!((cfg.frame_focal_px(5) - mid).abs() < 1e-9 * f0);
        assert_eq!(pt.intrinsics[5][(0, 0)], cfg.frame_focal_px(5));
        let m = s.table.measurements();
        for f in [0, 5, 11] {
            let z = pt.translations[f][2];
            assert!((s.truth.scales[f] - cfg.frame_focal_px(f) / z).abs() < 1e-12);
            for (p, x) in s.truth.points.iter().enumerate() {
                let w = Vector2::new(m.w[(2 * f, p)], m.w[(2 * f + 1, p)]);
                assert!((apply(&pt.projection(f), x) - w).norm() < 1e-9);
            }
        }
        let fixed = generate(&perspective(3.0)).unwrap();
        let k = &fixed.perspective.as_ref().unwrap().intrinsics;
        assert!(k.iter().all(|ki| *ki == k[0]));
    }

    /// Distortion: the observations are `f (1 + k₁ ‖n‖²) n + c` (COLMAP `SIMPLE_RADIAL`)
    /// of the undistorted camera's normalised coordinates; `k₁ = 0` leaves the scene as it
    /// was; a coefficient that folds the image over is refused.
    #[test]
    fn distortion_is_simple_radial() {
        let k1 = -0.2;
        let s = generate(&SynthConfig {
            distortion: k1,
            ..perspective(2.5)
        })
        .unwrap();
        let pt = s.perspective.as_ref().unwrap();
        assert_eq!(pt.k1, k1);
        let m = s.table.measurements();
        let (mut largest, mut radius) = (0.0f64, 0.0f64);
        for f in 0..pt.n_frames() {
            let k = pt.intrinsics[f];
            for (p, x) in s.truth.points.iter().enumerate() {
                let xc = pt.to_camera(f, x);
                let n = Vector2::new(xc[0] / xc[2], xc[1] / xc[2]);
                radius = radius.max(n.norm());
                let want = n * k[(0, 0)] * (1.0 + k1 * n.norm_squared())
                    + Vector2::new(k[(0, 2)], k[(1, 2)]);
                let w = Vector2::new(m.w[(2 * f, p)], m.w[(2 * f + 1, p)]);
                assert!((w - want).norm() < 1e-9);
                largest = largest.max((w - apply(&pt.projection(f), x)).norm());
            }
        }
        eprintln!("k₁ = {k1}: largest shift {largest:.2} px, largest ‖n‖ {radius:.3}");
        // Measured: up to 11.3 px from the undistorted image at distance 2.5 (‖n‖ up to
        // 0.48).
        assert!(largest > 3.0, "{largest}");
        let plain = generate(&perspective(2.5)).unwrap();
        let zero = generate(&SynthConfig {
            distortion: 0.0,
            zoom: 0.0,
            ..perspective(2.5)
        })
        .unwrap();
        assert_eq!(plain.table.measurements().w, zero.table.measurements().w);
        let v: serde_json::Value = serde_json::from_str(&s.truth_json()).unwrap();
        assert_eq!(v["perspective"]["k1"].as_f64().unwrap(), k1);
        assert_eq!(v["config"]["distortion"].as_f64().unwrap(), k1);
        for (field, cfg) in [
            (
                "distortion",
                SynthConfig {
                    distortion: -5.0,
                    ..perspective(2.5)
                },
            ),
            (
                "distortion",
                SynthConfig {
                    distortion: f64::NAN,
                    ..perspective(2.5)
                },
            ),
            (
                "zoom",
                SynthConfig {
                    zoom: -1.0,
                    ..perspective(2.5)
                },
            ),
            (
                "zoom",
                SynthConfig {
                    zoom: f64::INFINITY,
                    ..perspective(2.5)
                },
            ),
        ] {
            match generate(&cfg) {
                Err(Error::InvalidConfig { field: f, .. }) => assert_eq!(f, field),
                other => panic!("{field}: {other:?}"),
            }
        }
    }
}

/// Frame f's camera of [`perspective_corridor`]: `(K, R, c)` with `P = K [R | −R c]`,
/// moving along +x at 0.25 units per frame, looking +z with a slow yaw/pitch wobble.
pub fn perspective_corridor_camera(f: usize) -> (Matrix3<f64>, Rotation3<f64>, Vector3<f64>) {
    let k = Matrix3::new(500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0);
    let a = f as f64;
    let r = Rotation3::from_euler_angles(
        0.05 * (a / 37.0).sin(),
        0.08 * (a / 53.0).sin(),
        0.02 * (a / 71.0).cos(),
    );
    let c = Vector3::new(0.25 * a, 0.3 * (a / 90.0).sin(), 0.2 * (a / 60.0).cos());
    (k, r, c)
}

/// A long, sparse, video-like table seen in strong perspective, with its true points: a
/// camera (`K` = 500 px focal length, principal point (320, 240), 640×480 image) moving along
/// +x at 0.25 units per frame past points at depth 3–7, looking +z with a slow yaw/pitch
/// wobble ([`perspective_corridor_camera`]). Each point is observed (with Gaussian noise of
/// `noise` px) in every frame where it projects inside the image; a track ends when it
/// leaves the view or, with probability 3 % per frame, is lost; tracks seen once are
/// dropped. About `per_frame` tracks per frame, 2–40 frames each. Returns the observations
/// (tracks numbered from 0) and, per track, its true point. For the long-sequence
/// projective and perspective tests and benchmarks.
pub fn perspective_corridor(
    frames: usize,
    per_frame: usize,
    noise: f64,
    seed: u64,
) -> (Vec<Observation>, Vec<Vector3<f64>>) {
    let mut rng = StdRng::seed_from_u64(seed);
    let noise = Normal::new(0.0, if noise > 0.0 { noise } else { 0.0 })
        .unwrap_or_else(|_| Normal::new(0.0, 0.0).expect("a zero deviation is valid"));
    let length = 0.25 * frames as f64 + 20.0;
    // A point at depth z is in view for about 2·0.64·z / 0.25 ≈ 25 frames at z = 5.
    let n = (per_frame as f64 * frames as f64 / 22.0) as usize;
    let pts: Vec<Vector3<f64>> = (0..n)
        .map(|_| {
            Vector3::new(
                rng.random_range(-10.0..length),
                rng.random_range(-1.5..1.5),
                rng.random_range(3.0..7.0),
            )
        })
        .collect();
    let cams: Vec<_> = (0..frames).map(perspective_corridor_camera).collect();
    let mut obs = Vec::new();
    let mut next_track = 0;
    let mut truth = Vec::new();
    for p in &pts {
        // Frames where the point is visible, in order; split at losses.
        let first = ((p[0] - 5.0) / 0.25).floor().max(0.0) as usize;
        let last = (((p[0] + 5.0) / 0.25).ceil() as usize).min(frames);
        let mut id: Option<usize> = None;
        for (f, (k, r, c)) in cams.iter().enumerate().take(last).skip(first) {
            let x = r * (p - c);
            let q = k * x;
            let (u, v) = (q[0] / q[2], q[1] / q[2]);
            let visible = x[2] > 0.5 && (0.0..640.0).contains(&u) && (0.0..480.0).contains(&v);
            if !visible || rng.random_range(0.0..1.0) < 0.03 {
                id = None;
                continue;
            }
            let t = *id.get_or_insert_with(|| {
                next_track += 1;
                truth.push(*p);
                next_track - 1
            });
            obs.push(Observation {
                frame: f,
                track: t,
                xy: [u + noise.sample(&mut rng), v + noise.sample(&mut rng)],
            });
        }
    }
    // Tracks seen once carry no depth: drop them and renumber.
    let mut count = vec![0usize; next_track];
    for o in &obs {
        count[o.track] += 1;
    }
    let mut map = vec![usize::MAX; next_track];
    let mut n_tracks = 0;
    for t in 0..next_track {
        if count[t] >= 2 {
            map[t] = n_tracks;
            n_tracks += 1;
        }
    }
    obs.retain(|o| count[o.track] >= 2);
    for o in &mut obs {
        o.track = map[o.track];
    }
    let truth = (0..next_track)
        .filter(|&t| count[t] >= 2)
        .map(|t| truth[t])
        .collect();
    (obs, truth)
}

/// A long, sparse, video-like table under the scaled orthographic camera (the affine model
/// holds exactly), with its ground truth: a camera travelling along a corridor of points,
/// each track seen while it is in the 640-pixel-wide view (about `view_frames` frames) or
/// until it is lost (2 % per frame). For the sparse pipeline's tests and benchmarks.
#[derive(Debug, Clone, PartialEq)]
pub struct CorridorConfig {
    pub frames: usize,
    /// Tracks visible in a frame, on average. Default 150.
    pub per_frame: usize,
    /// Frames a point stays in view (before losses). Default 30.
    pub view_frames: usize,
    /// Image noise σ, pixels. Default 0.5.
    pub noise: f64,
    pub seed: u64,
}

impl Default for CorridorConfig {
    fn default() -> Self {
        Self {
            frames: 1000,
            per_frame: 150,
            view_frames: 30,
            noise: 0.5,
            seed: 0,
        }
    }
}

/// [`CorridorConfig`]'s table and the true metric model (frames × tracks of the table).
///
/// Camera `f`: rotation wobbling by up to 0.5 rad about the corridor's axis and the
/// vertical (periods of ~70–80 frames), scale 40 px per unit varying by ±10 %, moving 640 / `view_frames` pixels per
/// frame along the corridor. Points fill a slab 2 units deep, so depth is well determined
/// by the rotation. `O(n_obs)` time and memory.
pub fn corridor(cfg: &CorridorConfig) -> Result<(TrackTable, MetricModel)> {
    if cfg.frames < 2 || cfg.per_frame < 4 || cfg.view_frames < 2 {
        return Err(Error::InvalidConfig {
            field: "corridor",
            message: "frames ≥ 2, per_frame ≥ 4 and view_frames ≥ 2 needed".into(),
        });
    }
    let mut rng = StdRng::seed_from_u64(cfg.seed);
    let noise = Normal::new(0.0, cfg.noise.max(0.0)).map_err(|e| Error::InvalidConfig {
        field: "noise",
        message: e.to_string(),
    })?;
    let scale0 = 40.0;
    let width = 640.0 / scale0; // view width, units
    let speed = width / cfg.view_frames as f64; // units per frame
    let rotations: Vec<Rotation3<f64>> = (0..cfg.frames)
        .map(|f| {
            let a = f as f64;
            Rotation3::from_euler_angles(
                0.5 * (a / 11.0).sin(),
                0.5 * (a / 13.0).cos(),
                0.1 * (a / 47.0).sin(),
            )
        })
        .collect();
    let scales: Vec<f64> = (0..cfg.frames)
        .map(|f| scale0 * (1.0 + 0.1 * (f as f64 / 97.0).sin()))
        .collect();
    // Camera centre along x; t_f = 320 − s R (c, 0, 0) so that the centre projects mid-image.
    let centres: Vec<Vector3<f64>> = (0..cfg.frames)
        .map(|f| Vector3::new(speed * f as f64, 0.0, 0.0))
        .collect();
    let translations: Vec<Vector2<f64>> = (0..cfg.frames)
        .map(|f| {
            let r = rotations[f].matrix();
            let p = r * centres[f] * scales[f];
            Vector2::new(320.0 - p[0], 240.0 - p[1])
        })
        .collect();
    let length = speed * cfg.frames as f64 + width;
    let n = ((cfg.per_frame as f64) * length / width).ceil() as usize;
    let mut pts = Vec::with_capacity(n);
    let mut obs: Vec<(u32, u32, f64, f64)> = Vec::new();
    for _ in 0..n {
        let x = Vector3::new(
            rng.random_range(-width / 2.0..length - width / 2.0),
            rng.random_range(-5.0..5.0),
            rng.random_range(-1.0..1.0),
        );
        // Frames where the point is inside the view, then a random loss.
        let first = ((x[0] - width / 2.0) / speed).ceil().max(0.0) as usize;
        let mut track = Vec::new();
        for f in first..cfg.frames {
            let r = rotations[f].matrix();
            let q = (r * x * scales[f]).xy() + translations[f];
            if q[0] < 0.0 || q[0] > 640.0 {
                if f > first + 2 {
                    break;
                }
                continue;
            }
            track.push((f, q));
            if rng.random::<f64>() < 0.02 {
                break;
            }
        }
        if track.len() < 2 {
            continue;
        }
        let p = pts.len() as u32;
        pts.push(x);
        for (f, q) in track {
            obs.push((
                f as u32,
                p,
                q[0] + noise.sample(&mut rng),
                q[1] + noise.sample(&mut rng),
            ));
        }
    }
    let table = TrackTable::from_observations(
        (0..cfg.frames).map(Id::from).collect(),
        (0..pts.len()).map(Id::from).collect(),
        &obs,
    )
    .unwrap_or_else(|_| unreachable!("one observation per frame and track"));
    Ok((
        table,
        MetricModel {
            rotations,
            translations,
            scales,
            points: pts,
            aspect: 1.0,
        },
    ))
}
