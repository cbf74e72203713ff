//! The metric perspective camera: Euclidean upgrade of a projective reconstruction
//! (self-calibration, [`selfcal`]) and metric bundle adjustment.
//!
//! # Model
//!
//! `w_fp = π_f(X_p) = f_f (1 + k₁‖n‖²) n + c`, `n = dehom(R_f X_p + t_f)`: rotations `R_f`,
//! translations `t_f`, points `X_p ∈ R³`, focal length `f_f` (one for the sequence, or one
//! per frame for a zooming camera), principal point `c` and radial coefficient `k₁`
//! (known, or estimated and shared by all frames), and the aspect ratio `f_x / f_y` (1, or
//! estimated and shared: `π₁` is multiplied by it). Zero skew.
//!
//! # Objective
//!
//! The metric bundle adjustment minimises `Σ_observed ρ(‖π_f(X_p) − w_fp‖²)` with a robust
//! loss `ρ` ([`Loss`], Huber by default), over the observed entries only. It runs on the
//! sparse engine of the projective stages ([`crate::projective::bundle`]): Schur complement
//! over the points, the shared intrinsics as extra unknowns of the sparse reduced camera
//! system, cost and memory linear in the observations. The similarity gauge (7 degrees of
//! freedom) is held by springs on the first two cameras.
//!
//! # Chain
//!
//! projective factorization ([`crate::projective`]) → self-calibration (linear absolute dual
//! quadric, PSD / rank 3 by Clarabel when needed) → metric bundle adjustment with the focal
//! length(s) free (the nonlinear refinement of the calibration), then a second adjustment
//! with the principal point and `k₁` free when asked for. With a known focal length
//! ([`Intrinsics::focal_px`]) the upgrade only has the plane at infinity to find and the
//! adjustment keeps `f` fixed.
//!
//! # Complexity
//!
//! Self-calibration `O(F + N)`; each adjustment iteration as the projective one
//! (`O(n_obs)` linearisation, a sparse Cholesky of the banded reduced system).
//!
//! # References
//!
//! * R. Hartley and A. Zisserman, *Multiple View Geometry*, 2nd ed., ch. 18.1, 19.
//! * B. Triggs, P. McLauchlan, R. Hartley and A. Fitzgibbon, "Bundle adjustment — a modern
//!   synthesis", 1999 (robust losses §3.2, gauge §9).

pub(crate) mod long;
pub mod models;
pub mod planar;
pub mod selfcal;

pub use long::{fit_observations, refine_observations};

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::projective::bundle::{BundleModel, LmConfig};
use crate::projective::{self, Normalization, ProjectiveModel, Stage, StageReport};
use crate::sdp::SdpSettings;
use crate::{Measurements, MetricModel, Observer, SolverReport};
pub use models::{Focal, Loss, Metric, Robust};
pub use selfcal::SelfCalibration;

/// What is known of the intrinsics (all in pixels). Unknown ones are estimated.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Intrinsics {
    /// Focal length, pixels. `None`: self-calibrated. Default `None`.
    pub focal_px: Option<f64>,
    /// Principal point, pixels. `None`: the image centre (`image_size / 2`), or the centre
    /// of the observations' bounding box when the image size is not known either.
    pub principal_point: Option<[f64; 2]>,
    /// Image width and height, pixels (the tracker knows them). Default `None`.
    pub image_size: Option<[u32; 2]>,
}

/// Settings of the perspective stages. Every field has a documented default.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PerspectiveConfig {
    /// Known intrinsics. Default: none known.
    pub intrinsics: Intrinsics,
    /// One focal length per frame (a zooming camera) instead of one for the sequence.
    /// Default false.
    pub per_frame_focal: bool,
    /// Estimate the principal point (shared) in a final adjustment. Default false: it is
    /// weakly determined by tracks and usually better left at the image centre. When
    /// neither the principal point nor the image size is known it is always estimated
    /// (starting from the centre of the tracks' bounding box, which is only a guess).
    pub estimate_principal_point: bool,
    /// Estimate one radial distortion coefficient `k₁` (shared). Default false.
    pub distortion: bool,
    /// Estimate the aspect ratio `f_x / f_y` (shared; non-square pixels, e.g. video
    /// digitised at 512×480 or 720×480 from a 4:3 picture) in a final adjustment, from the
    /// value of the start (1: square pixels). Default false. A known aspect ratio is
    /// [`crate::Config::aspect_ratio`]: the pipeline rescales the image's x axis by it.
    #[serde(default)]
    pub estimate_aspect_ratio: bool,
    /// Robust loss of the metric bundle adjustment, in pixels. Default Huber, δ = 2 px.
    pub loss: Loss,
    /// Settings of the metric bundle adjustment. Default: variable projection (the points
    /// re-solved after every camera step, as in the projective stage), 200 iterations,
    /// tolerances 1e-12. Measured against the joint Levenberg–Marquardt (both blocks
    /// damped): on the Model House every non-mirrored start reaches the optimum within the
    /// 10 screening iterations (joint: none does), and on the hotel it converges in 48
    /// iterations where the joint one stops at 200 with a worse RMS (docs/results.md).
    pub bundle: LmConfig,
    /// Settings of the PSD-constrained self-calibration solve.
    pub sdp: SdpSettings,
    /// Adjustment iterations each start gets before the best is kept and adjusted to
    /// convergence ([`fit`]). Default 5.
    pub screen_iterations: usize,
    /// Cap on the projective bundle adjustment's iterations when it only prepares the
    /// perspective stages (the robust verdict and the self-calibration start; the metric
    /// adjustment is the estimate). Default 20: on a 100-frame handheld sequence the
    /// projective adjustment needed 213 iterations (38 s) to converge, for an RMS 1e-5 px
    /// below the one after 20, while the metric one converged in one iteration from the
    /// affine start (docs/results.md).
    pub projective_iterations: usize,
    /// The same cap when the projective adjustment is refitted after the robust verdict
    /// changed the selection: it starts from the previous fit's cameras (the points
    /// triangulated again), a few tracks and entries away from their optimum. Default 5:
    /// on a 200-frame handheld sequence the refits' 20 iterations moved the RMS by 2·10⁻⁵ px
    /// and took 12 of the pipeline's 35 s (docs/results.md).
    #[serde(default = "default_projective_refit_iterations")]
    pub projective_refit_iterations: usize,
    /// Focal lengths tried by the starts lifted from the affine reconstruction, as
    /// multiples of the larger image side (or of the tracks' extent). Default
    /// `[0.7, 1.5, 3]` (fields of view of about 70°, 37° and 19°); the adjustment moves the
    /// focal length from there.
    pub focal_grid: Vec<f64>,
    /// Build and screen the planar start ([`planar`]: the focal length and the plane from
    /// plane-induced homographies, the frames registered to the plane) when the
    /// self-calibration start is not accepted early. A planar scene (or a camera that only
    /// rotates) determines neither the projective factorization nor the absolute dual
    /// quadric, and the other starts end far from the optimum there; elsewhere the planar
    /// start costs one more screening and is not chosen. Default true.
    #[serde(default = "default_planar_start")]
    pub planar_start: bool,
    /// The geodesic acceleration (`LmConfig::geodesic_acceleration`'s `α`) of the
    /// long-sequence path's global adjustment ([`fit_observations`],
    /// [`refine_observations`]) when `bundle`'s own is 0. Its start is metric windows
    /// chained by similarities, and its tail moves the chain's soft bending modes, where
    /// plain damped steps creep (a 20 000-frame corridor: converged at a cost the
    /// adjustment started at the truth goes below, with 1.04 % structure error against
    /// 0.41 %; docs/results.md). The windows' own small fits keep `bundle`'s setting.
    /// Default 0.75.
    #[serde(default = "default_long_geodesic_acceleration")]
    pub long_geodesic_acceleration: f64,
    /// How many windows of the long-sequence path ([`fit_observations`]) estimate the
    /// sequence's focal length when it is not given: that many, spread evenly, are fitted
    /// with a free focal length and their median is the sequence's; every other window is
    /// fitted once with it held fixed (three screened starts instead of seven, and no
    /// second adjustment). 0: every window estimates it. Default 32 (~650 frames of
    /// 40-frame windows overlapping by 20): on a 2 000-frame corridor the windows took
    /// 36.8 s against 56.3 s with every one, and every printed figure of the result was the
    /// same (docs/results.md).
    #[serde(default = "default_focal_sample_windows")]
    pub focal_sample_windows: usize,
    /// [`fit`]'s early acceptance: the starts lifted from the affine model are not built
    /// or screened when the screened self-calibration start is already within the noise of
    /// the projective fit (a statistical bound; see [`fit`]). Default true: the long
    /// paths' windows are then fitted with one screened start instead of three (focal
    /// length known) or seven, and the projective route's metric reference without the
    /// windows' scaled orthographic completions — a 2 000-frame corridor's reference
    /// 21.2 → 8.6 s, the same optimum (docs/results.md). False: every start is screened.
    #[serde(default = "default_accept_at_noise")]
    pub accept_at_noise: bool,
    /// [`fit`] on a long sequence screens its starts on a subset of the table spanning it
    /// ([`Measurements::spanning_subset`]: at most this many frames, evenly spaced, and at
    /// most [`SCREEN_TRACKS`] tracks seen in 3 of them, every subset frame seeing
    /// [`SCREEN_PER_FRAME`]) when the sequence has more than twice as many frames; the
    /// chosen start is then adjusted on the whole table. 0: always on the whole table.
    /// Default 150 (every real data set of docs/results.md is shorter).
    #[serde(default = "default_screen_frames")]
    pub screen_frames: usize,
}

/// Tracks of [`fit`]'s screening subset ([`PerspectiveConfig::screen_frames`]).
pub const SCREEN_TRACKS: usize = 400;
/// Tracks each frame of [`fit`]'s screening subset sees at least (when the table has them).
pub const SCREEN_PER_FRAME: usize = 12;

fn default_screen_frames() -> usize {
    150
}

fn default_accept_at_noise() -> bool {
    true
}

fn default_focal_sample_windows() -> usize {
    32
}

fn default_planar_start() -> bool {
    true
}

fn default_long_geodesic_acceleration() -> f64 {
    0.75
}

fn default_projective_refit_iterations() -> usize {
    5
}

impl Default for PerspectiveConfig {
    fn default() -> Self {
        Self {
            intrinsics: Intrinsics::default(),
            per_frame_focal: false,
            estimate_principal_point: false,
            distortion: false,
            estimate_aspect_ratio: false,
            loss: Loss::Huber(2.0),
            bundle: LmConfig {
                max_iterations: 200,
                ..LmConfig::default()
            },
            sdp: SdpSettings::default(),
            screen_iterations: 5,
            projective_iterations: 20,
            projective_refit_iterations: 5,
            focal_grid: vec![0.7, 1.5, 3.0],
            planar_start: default_planar_start(),
            long_geodesic_acceleration: default_long_geodesic_acceleration(),
            focal_sample_windows: default_focal_sample_windows(),
            accept_at_noise: default_accept_at_noise(),
            screen_frames: default_screen_frames(),
        }
    }
}

impl PerspectiveConfig {
    /// Whether the adjustment estimates the principal point: when asked to, and always when
    /// neither it nor the image size is known (the tracks' bounding box is only a guess).
    pub fn estimates_principal_point(&self, assumed: &Assumed) -> bool {
        self.estimate_principal_point || assumed.principal_point_source == "track bounding box"
    }

    /// Checks every field; [`Error::InvalidConfig`] names the first bad one.
    pub fn validate(&self) -> Result<()> {
        let bad =
            |field: &'static str, message: String| Err(Error::InvalidConfig { field, message });
        if let Some(f) = self.intrinsics.focal_px
            && !(f.is_finite() && f > 0.0)
        {
            return bad(
                "focal",
                format!("must be a positive number of pixels, got {f}"),
            );
        }
        if let Some(c) = self.intrinsics.principal_point
            && !c.iter().all(|v| v.is_finite())
        {
            return bad("principal-point", format!("must be finite, got {c:?}"));
        }
        if let Some([w, h]) = self.intrinsics.image_size
            && (w == 0 || h == 0)
        {
            return bad("image-size", format!("must be positive, got {w}x{h}"));
        }
        match self.loss {
            Loss::Huber(d) | Loss::Cauchy(d) if !(d.is_finite() && d > 0.0) => {
                return bad("loss", format!("the scale must be positive, got {d}"));
            }
            _ => {}
        }
        self.bundle.validate("bundle")?;
        if let Some(m) = self
            .focal_grid
            .iter()
            .find(|m| !(m.is_finite() && **m > 0.0))
        {
            return bad("focal_grid", format!("multiples must be positive, got {m}"));
        }
        Ok(())
    }
}

/// A metric perspective reconstruction, in pixels: `w_fp = π_f(X_p)`. The world frame is
/// the first camera's (`R_0 = I`, `t_0 = 0`) and the unit is the RMS distance of the
/// points from their centroid.
#[derive(Debug, Clone, PartialEq)]
pub struct PerspectiveModel {
    /// Per frame, the focal length in pixels (all equal unless per-frame focal lengths were
    /// estimated).
    pub focal_px: Vec<f64>,
    /// Principal point, pixels.
    pub principal_point: [f64; 2],
    /// Radial distortion coefficient `k₁` (of normalised coordinates; 0 = none).
    pub k1: f64,
    /// Aspect ratio `f_x / f_y` (1 = square pixels): the focal length in x is
    /// `aspect · focal_px`.
    pub aspect: f64,
    /// World-to-camera rotations.
    pub rotations: Vec<Matrix3<f64>>,
    /// World-to-camera translations: `X_c = R X + t`.
    pub translations: Vec<Vector3<f64>>,
    /// Points, world frame.
    pub points: Vec<Vector3<f64>>,
}

impl PerspectiveModel {
    /// The model of the given frames and tracks (indices, in the order given).
    pub fn select(&self, frames: &[usize], tracks: &[usize]) -> PerspectiveModel {
        PerspectiveModel {
            focal_px: frames.iter().map(|&f| self.focal_px[f]).collect(),
            principal_point: self.principal_point,
            k1: self.k1,
            aspect: self.aspect,
            rotations: frames.iter().map(|&f| self.rotations[f]).collect(),
            translations: frames.iter().map(|&f| self.translations[f]).collect(),
            points: tracks.iter().map(|&p| self.points[p]).collect(),
        }
    }

    /// `π_f(X)` for any point.
    pub fn project_point(&self, f: usize, x: &Vector3<f64>) -> [f64; 2] {
        let xc = self.rotations[f] * x + self.translations[f];
        let (nx, ny) = (xc[0] / xc[2], xc[1] / xc[2]);
        let d = 1.0 + self.k1 * (nx * nx + ny * ny);
        let fo = self.focal_px[f];
        [
            self.aspect * fo * d * nx + self.principal_point[0],
            fo * d * ny + self.principal_point[1],
        ]
    }

    /// `π_f(X_p)`.
    pub fn project(&self, f: usize, p: usize) -> [f64; 2] {
        self.project_point(f, &self.points[p])
    }

    /// Camera centre `−Rᵀ t`.
    pub fn centre(&self, f: usize) -> Vector3<f64> {
        -(self.rotations[f].transpose() * self.translations[f])
    }

    /// Intrinsic matrix of frame `f` (distortion aside).
    pub fn k(&self, f: usize) -> Matrix3<f64> {
        let fo = self.focal_px[f];
        Matrix3::new(
            self.aspect * fo,
            0.0,
            self.principal_point[0],
            0.0,
            fo,
            self.principal_point[1],
            0.0,
            0.0,
            1.0,
        )
    }

    /// The projective camera `K [R | t]` of frame `f` (distortion aside), row-major 3×4.
    pub fn camera_matrix(&self, f: usize) -> [f64; 12] {
        let kr = self.k(f) * self.rotations[f];
        let kt = self.k(f) * self.translations[f];
        std::array::from_fn(|i| {
            let (r, c) = (i / 4, i % 4);
            if c < 3 { kr[(r, c)] } else { kt[r] }
        })
    }

    /// Depth of point `X` in frame `f` (positive in front of the camera).
    pub fn depth(&self, f: usize, x: &Vector3<f64>) -> f64 {
        (self.rotations[f] * x + self.translations[f])[2]
    }
}

/// Outcome of [`fit`].
#[derive(Debug, Clone)]
pub struct PerspectiveFit {
    pub model: PerspectiveModel,
    /// Reprojection RMS over the observed scalars, pixels (plain, not the robust cost).
    pub rms_px: f64,
    /// What the self-calibration found (its focal lengths are the linear estimate's);
    /// `None` from [`adjust`].
    pub selfcal: Option<SelfCalibration>,
    /// The stages: `metric-ba`, and `metric-ba-intrinsics` when the principal point or
    /// `k₁` were estimated (`metric-ba-intrinsics-rejected` for a stage whose principal
    /// point estimate was rejected, see [`PerspectiveFit::principal_point_rejected`]).
    pub stages: Vec<StageReport>,
    /// Report of the last adjustment.
    pub report: SolverReport,
    /// The principal point and scale the upgrade assumed (pixels), and where they came from.
    pub assumed: Assumed,
    /// Entries the robust loss down-weights below one half (residual beyond twice its
    /// scale), (frame, track) of `meas`.
    pub downweighted: Vec<(usize, usize)>,
    /// Fraction of observed points in front of their camera.
    pub in_front: f64,
    /// Whether the principal point was estimated.
    pub principal_point_estimated: bool,
    /// The principal point estimate rejected as implausible (outside the image, or with a
    /// focal length below a tenth of its side): the fit then holds the assumed principal
    /// point, and `principal_point_estimated` is false.
    pub principal_point_rejected: Option<RejectedPrincipalPoint>,
    /// The starts [`fit`] screened (empty from [`adjust`]).
    pub starts: Vec<StartReport>,
}

/// The principal point and image scale the upgrade used, and their source.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Assumed {
    pub principal_point: [f64; 2],
    /// `"given"`, `"image centre"` or `"track bounding box"`.
    pub principal_point_source: &'static str,
    /// The normalising scale (the known focal length, else the larger image side).
    pub scale: f64,
}

/// The principal point and scale of the upgrade: given, else the image size's, else the
/// observations' bounding box.
pub fn assumed_frame(meas: &Measurements, k: &Intrinsics) -> Assumed {
    assumed_frame_of(
        meas.observed_pairs()
            .map(|(f, p)| [meas.w[(2 * f, p)], meas.w[(2 * f + 1, p)]]),
        k,
    )
}

/// The smallest and largest coordinates of `positions` (infinite when there are none).
fn bounding_box(positions: impl Iterator<Item = [f64; 2]>) -> ([f64; 2], [f64; 2]) {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for v in positions {
        for d in 0..2 {
            lo[d] = lo[d].min(v[d]);
            hi[d] = hi[d].max(v[d]);
        }
    }
    (lo, hi)
}

/// [`assumed_frame`] of any set of observed positions (pixels).
pub fn assumed_frame_of(positions: impl Iterator<Item = [f64; 2]>, k: &Intrinsics) -> Assumed {
    let Some([w, h]) = k.image_size else {
        // Without the image size, the observations' bounding box stands in for it.
        let (lo, hi) = bounding_box(positions);
        let side = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(1.0);
        let (pp, source) = match k.principal_point {
            Some(c) => (c, "given"),
            None => (
                [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0],
                "track bounding box",
            ),
        };
        return Assumed {
            principal_point: pp,
            principal_point_source: source,
            scale: k.focal_px.unwrap_or(side),
        };
    };
    let (pp, source) = match k.principal_point {
        Some(c) => (c, "given"),
        // Pixel centres at integer coordinates (rank3's tracker): the centre of a W×H
        // image is ((W − 1)/2, (H − 1)/2).
        None => (
            [(w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0],
            "image centre",
        ),
    };
    let side = w.max(h) as f64;
    Assumed {
        principal_point: pp,
        principal_point_source: source,
        scale: k.focal_px.unwrap_or(side),
    }
}

/// One start of the metric adjustment, screened by [`fit`].
#[derive(Debug, Clone, Serialize)]
pub struct StartReport {
    /// `"self-calibration"`, `"affine"` (lifted from the scaled-orthographic model) or
    /// `"plane"` ([`planar`]).
    pub kind: &'static str,
    /// Focal length of the start, pixels (the median over frames for self-calibration).
    pub focal_px: f64,
    /// Whether the affine model was mirrored (depth reversal) for this start.
    pub mirrored: bool,
    /// Reprojection RMS after the screening iterations, pixels (robust cost as RMS), over
    /// the observations of the frames and tracks screened.
    pub rms_px: f64,
    /// Whether it was kept.
    pub chosen: bool,
    /// Frames and tracks the screening used: the whole table's, or on a long sequence a
    /// subset spanning it ([`PerspectiveConfig::screen_frames`]).
    pub screen_frames: usize,
    pub screen_tracks: usize,
}

/// Upgrades the projective model of `meas` to a metric perspective one and refines it.
///
/// Starts, each screened by [`PerspectiveConfig::screen_iterations`] adjustment iterations,
/// the one with the lowest cost then adjusted to convergence ([`adjust`]):
/// * the self-calibration of the projective model ([`selfcal`]: absolute dual quadric);
/// * when the scaled-orthographic metric model of the same tracks is given (`affine`), its
///   lift to a pinhole camera for each focal length of [`PerspectiveConfig::focal_grid`]
///   (or the known one), and its mirror image: with focal `f` and frame scale `s_f`, the
///   depth of the points' centroid is `f / s_f` and the image of the centroid is kept.
///   Self-calibration is ill-conditioned for weak perspective and small rotations
///   (the absolute dual quadric is then close to rank 2); the affine model is not, and
///   under weak perspective it is the first-order approximation of the true cameras;
/// * the planar start ([`planar`], when [`PerspectiveConfig::planar_start`]): the focal
///   length and a plane from plane-induced homographies, every frame registered to that
///   plane. Neither of the others is near the optimum when the tracks lie on a plane (the
///   projective factorization and the absolute dual quadric are then not determined, the
///   affine model has rank 2).
///
/// **Early acceptance** ([`PerspectiveConfig::accept_at_noise`]): the metric model is a
/// special case of the projective one, so no metric start can end below the projective
/// optimum, and the projective fit's cost `C_P` is at or near it. When the screened self-calibration start already explains the data as
/// well as the projective fit up to what its fewer parameters cost — `C_M − C_P ≤ σ̂² (d +
/// 3 √(2d))`, the mean plus three standard deviations of the `σ² χ²_d` by which a true
/// metric model's optimum exceeds the projective one's, `d` the difference of the two
/// models' degrees of freedom and `σ̂² = C_P / (2n − dof_P)` (plain squared costs over the
/// `n` observations) — the other starts are not built or screened: none could be better by
/// more than the noise. Their reports are then absent from [`PerspectiveFit::starts`].
///
/// `meas` are the observations the projective model was fitted to (same frames and
/// tracks). Errors: bad settings ([`Error::InvalidConfig`]), no usable start
/// ([`Error::Degenerate`]), a numerical failure of a solver's setup. How the adjustment
/// ended is in the report.
///
/// **Long sequences** ([`PerspectiveConfig::screen_frames`]): the starts are screened on a
/// subset of frames and tracks spanning the sequence (the early acceptance judged there
/// against the projective model restricted to it), and the chosen start is adjusted on the
/// whole table from its unscreened self.
///
/// Cost: the self-calibration `O(F + N)`, then `O(n_obs)` per adjustment iteration:
/// [`PerspectiveConfig::screen_iterations`] per screened start (1, or 1 + 2 × the focal
/// grid's length + 1 for the planar start, whose homographies and grid cost `O(n_obs)` plus
/// a constant) on the screened observations (bounded on a long sequence), then the
/// final adjustment's.
pub fn fit(
    meas: &Measurements,
    proj: &ProjectiveModel,
    affine: Option<&MetricModel>,
    cfg: &PerspectiveConfig,
    run: usize,
    observer: &mut dyn Observer,
) -> Result<PerspectiveFit> {
    fit_lazy(
        meas,
        proj,
        || affine.map(std::borrow::Cow::Borrowed),
        cfg,
        run,
        observer,
    )
}

/// [`fit`] with the scaled-orthographic model made only when the affine starts are needed
/// (not when the self-calibration start is accepted early): `affine` is called at most once.
pub(crate) fn fit_lazy<'a>(
    meas: &Measurements,
    proj: &ProjectiveModel,
    affine: impl FnOnce() -> Option<std::borrow::Cow<'a, MetricModel>>,
    cfg: &PerspectiveConfig,
    run: usize,
    observer: &mut dyn Observer,
) -> Result<PerspectiveFit> {
    cfg.validate()?;
    let (nf, np) = (meas.n_frames(), meas.n_points());
    if proj.cameras.len() != nf || proj.points.len() != np {
        return Err(Error::Dimension {
            context: "perspective::fit: the projective model vs the measurements",
            expected: format!("{nf} frames, {np} tracks"),
            got: format!(
                "{} frames, {} tracks",
                proj.cameras.len(),
                proj.points.len()
            ),
        });
    }
    let assumed = assumed_frame(meas, &cfg.intrinsics);
    let s = assumed.scale;
    let known_focal = cfg.intrinsics.focal_px.is_some();
    let obs: Vec<(usize, usize)> = meas.observed_pairs().collect();
    let mut starts: Vec<(StartReport, PerspectiveModel)> = Vec::new();
    let mut selfcal_report = None;
    let mut selfcal_error = None;
    match selfcal::upgrade(
        &proj.cameras,
        &proj.points,
        &obs,
        &selfcal::Frame {
            principal_point: assumed.principal_point,
            scale: s,
            known_focal,
        },
        &cfg.sdp,
    ) {
        Ok(up) => {
            let (report, model, selfcal) = selfcal_start(up, cfg, &assumed, nf);
            starts.push((report, model));
            selfcal_report = Some(selfcal);
        }
        Err(e) => selfcal_error = Some(e),
    }
    // Screen every start; keep the lowest cost.
    let screen_cfg = PerspectiveConfig {
        bundle: LmConfig {
            max_iterations: cfg.screen_iterations.max(1),
            ..cfg.bundle.clone()
        },
        distortion: false,
        estimate_aspect_ratio: false,
        ..cfg.clone()
    };
    // One graph for every start and the final adjustment (the same assumed frame).
    let g = normalised_graph(meas, &assumed);
    // A long sequence screens its starts on a subset spanning it (same assumed frame).
    let subset = screening_subset(meas, cfg.screen_frames).map(|(frames, tracks)| {
        let m = meas.select(&frames, &tracks);
        let g = normalised_graph(&m, &assumed);
        Subset {
            frames,
            tracks,
            meas: m,
            graph: g,
        }
    });
    // The best start: its index, screened cost, and screened model when that is the
    // whole table's (a subset's is not a start for the whole table: the start itself is).
    let mut best: Option<(usize, f64, Option<PerspectiveModel>)> = None;
    // Screens `starts[from..]` (on `subset` when given); returns the plain RMS of the best
    // of them.
    let screen = |starts: &mut [(StartReport, PerspectiveModel)],
                  from: usize,
                  best: &mut Option<(usize, f64, Option<PerspectiveModel>)>,
                  subset: Option<&Subset>| {
        let mut plain = f64::INFINITY;
        let (screen_frames, screen_tracks, screen_obs) = match subset {
            Some(sub) => (sub.frames.len(), sub.tracks.len(), sub.meas.n_observed()),
            None => (nf, np, obs.len()),
        };
        for (i, (report, start)) in starts.iter_mut().enumerate().skip(from) {
            (report.screen_frames, report.screen_tracks) = (screen_frames, screen_tracks);
            let (graph, start) = match subset {
                Some(sub) => (&sub.graph, start.select(&sub.frames, &sub.tracks)),
                None => (&g, start.clone()),
            };
            let screened = adjust_graph(
                graph,
                start,
                &screen_cfg,
                &assumed,
                false,
                run,
                &mut crate::NoopObserver,
            );
            let Ok(sc) = screened else { continue };
            let cost = sc.report.final_cost;
            let n_res = (2 * screen_obs).max(1) as f64;
            report.rms_px = (cost / n_res).sqrt() * s;
            if cost.is_finite() && best.as_ref().is_none_or(|b| cost < b.1) {
                plain = sc.rms_px;
                *best = Some((i, cost, subset.is_none().then_some(sc.model)));
            }
        }
        plain
    };
    let selfcal_rms = screen(&mut starts, 0, &mut best, subset.as_ref());
    let accepted = cfg.accept_at_noise
        && best.is_some()
        && match &subset {
            Some(sub) => within_noise_of_projective(
                &sub.meas,
                &proj.select(&sub.frames, &sub.tracks),
                selfcal_rms,
                cfg,
                &assumed,
            ),
            None => within_noise_of_projective(meas, proj, selfcal_rms, cfg, &assumed),
        };
    // The image's larger side (the normalising scale without the image size): what the
    // focal lengths tried by the affine and planar starts are multiples of.
    let side = match cfg.intrinsics.image_size {
        Some([w, h]) => w.max(h) as f64,
        None => s,
    };
    if !accepted && let Some(a) = affine() {
        let a: &MetricModel = &a;
        if a.rotations.len() == nf && a.points.len() == np {
            let focals: Vec<f64> = match cfg.intrinsics.focal_px {
                Some(f) => vec![f],
                None => cfg.focal_grid.iter().map(|m| m * side).collect(),
            };
            let from = starts.len();
            for &f in &focals {
                for mirrored in [false, true] {
                    starts.push((
                        StartReport {
                            kind: "affine",
                            focal_px: f,
                            mirrored,
                            rms_px: f64::NAN,
                            chosen: false,
                            screen_frames: 0,
                            screen_tracks: 0,
                        },
                        lift_affine(a, f, mirrored, assumed.principal_point),
                    ));
                }
            }
            screen(&mut starts, from, &mut best, subset.as_ref());
        }
    }
    // The planar start: when the tracks lie on a plane (or the camera only rotates) the
    // other starts are far from the optimum (module `planar`).
    if !accepted
        && cfg.planar_start
        && let Some((model, calib)) =
            planar::start(meas, assumed.principal_point, side, cfg.intrinsics.focal_px)
    {
        let from = starts.len();
        starts.push((
            StartReport {
                kind: "plane",
                focal_px: calib.focal_px,
                mirrored: false,
                rms_px: f64::NAN,
                chosen: false,
                screen_frames: 0,
                screen_tracks: 0,
            },
            model,
        ));
        screen(&mut starts, from, &mut best, subset.as_ref());
    }
    // No start could be adjusted on the subset: the whole table screens them.
    if best.is_none() && subset.is_some() {
        screen(&mut starts, 0, &mut best, None);
    }
    if starts.is_empty() {
        return Err(selfcal_error.unwrap_or_else(|| {
            Error::Degenerate("perspective::fit: no start for the metric adjustment".into())
        }));
    }
    let Some((chosen, _, screened)) = best else {
        return Err(Error::Numerical {
            stage: "metric bundle adjustment",
            message: "no start could be adjusted".into(),
        });
    };
    starts[chosen].0.chosen = true;
    let start = screened.unwrap_or_else(|| starts[chosen].1.clone());
    let estimate_pp = cfg.estimates_principal_point(&assumed);
    let mut out = adjust_graph(&g, start, cfg, &assumed, estimate_pp, run, observer)?;
    out.selfcal = selfcal_report;
    out.starts = starts.into_iter().map(|(r, _)| r).collect();
    Ok(out)
}

/// [`fit`]'s screening subset of a long sequence: frames, tracks, their measurements and
/// graph.
struct Subset {
    frames: Vec<usize>,
    tracks: Vec<usize>,
    meas: Measurements,
    graph: projective::bundle::Graph,
}

/// The frames and tracks [`fit`] screens its starts on: `None` (the whole table) unless the
/// sequence has more than `2 · screen_frames` frames (`screen_frames` > 0) and
/// [`Measurements::spanning_subset`] finds one whose every frame sees at least 6 of its
/// tracks (a perspective camera's minimum) and whose frames are linked by the tracks they
/// share (one reconstruction, not several with gauges of their own: consecutive subset
/// frames sharing no track, as short tracks sampled sparsely would leave them, fall back to
/// the whole table). `O(F' N')` for the subset's frames and tracks.
fn screening_subset(meas: &Measurements, screen_frames: usize) -> Option<(Vec<usize>, Vec<usize>)> {
    if screen_frames == 0 || meas.n_frames() <= 2 * screen_frames {
        return None;
    }
    let (frames, tracks) = meas.spanning_subset(screen_frames, SCREEN_TRACKS, SCREEN_PER_FRAME)?;
    // Connected: a frame reached from the first through a shared track reaches every
    // frame that sees that track.
    let mut reached = vec![false; frames.len()];
    let mut track_seen = vec![false; tracks.len()];
    let mut stack = vec![0usize];
    reached[0] = true;
    while let Some(i) = stack.pop() {
        for (j, &p) in tracks.iter().enumerate() {
            if track_seen[j] || !meas.is_visible(frames[i], p) {
                continue;
            }
            track_seen[j] = true;
            for (k, &f) in frames.iter().enumerate() {
                if !reached[k] && meas.is_visible(f, p) {
                    reached[k] = true;
                    stack.push(k);
                }
            }
        }
    }
    (reached.iter().all(|&r| r)
        && frames
            .iter()
            .all(|&f| tracks.iter().filter(|&&p| meas.is_visible(f, p)).count() >= 6))
    .then_some((frames, tracks))
}

/// [`fit`]'s early acceptance: whether a metric model at plain RMS `metric_rms` (pixels)
/// is within the noise of the projective model `proj` on `meas` — its squared cost above
/// the projective one by at most `σ̂² (d + 3 √(2d))`, `d = dof_P − dof_M` the models'
/// difference in degrees of freedom (projective `11F + 3N − 15`; metric `6F + 3N − 7` plus
/// the intrinsics `cfg` estimates) and `σ̂² = C_P / (2n − dof_P)`: the camera choice's
/// [`crate::robust::delta_chi2`] at most `d + 3 √(2d)`. False where `d ≤ 0` or the
/// projective model leaves no residual degrees of freedom. `O(n_obs)`.
fn within_noise_of_projective(
    meas: &Measurements,
    proj: &ProjectiveModel,
    metric_rms: f64,
    cfg: &PerspectiveConfig,
    assumed: &Assumed,
) -> bool {
    let (nf, np) = (meas.n_frames() as f64, meas.n_points() as f64);
    let n_res = 2.0 * meas.n_observed() as f64;
    let dof_p = projective::degrees_of_freedom(meas.n_frames(), meas.n_points());
    let intrinsics = if cfg.intrinsics.focal_px.is_some() {
        0.0
    } else if cfg.per_frame_focal {
        nf
    } else {
        1.0
    } + if cfg.estimates_principal_point(assumed) {
        2.0
    } else {
        0.0
    } + if cfg.distortion { 1.0 } else { 0.0 }
        + if cfg.estimate_aspect_ratio { 1.0 } else { 0.0 };
    let dof_m = 6.0 * nf + 3.0 * np - 7.0 + intrinsics;
    let d = dof_p as f64 - dof_m;
    if !(d > 0.0 && n_res > dof_p as f64 && metric_rms.is_finite()) {
        return false;
    }
    let proj_rms = proj.rms(meas);
    if !proj_rms.is_finite() {
        return false;
    }
    let (delta, _) = crate::robust::delta_chi2(metric_rms, proj_rms, n_res, dof_p);
    delta <= d + 3.0 * (2.0 * d).sqrt()
}

/// The metric start of a self-calibrated reconstruction `up` (normalised units of
/// `assumed`): a shared focal length starts at the median of the frames', per-frame ones
/// at each frame's (the median where a frame's is not positive), a known one as given.
fn selfcal_start(
    up: selfcal::Upgraded,
    cfg: &PerspectiveConfig,
    assumed: &Assumed,
    nf: usize,
) -> (StartReport, PerspectiveModel, SelfCalibration) {
    let s = assumed.scale;
    let known_focal = cfg.intrinsics.focal_px.is_some();
    let mut f: Vec<f64> = up
        .focal
        .iter()
        .copied()
        .filter(|f| f.is_finite() && *f > 0.0)
        .collect();
    f.sort_by(f64::total_cmp);
    let median = f.get(f.len() / 2).copied().unwrap_or(1.0) * s;
    let focal_px: Vec<f64> = if known_focal {
        vec![s; nf]
    } else if cfg.per_frame_focal {
        up.focal
            .iter()
            .map(|&f| {
                if f.is_finite() && f > 0.0 {
                    f * s
                } else {
                    median
                }
            })
            .collect()
    } else {
        vec![median; nf]
    };
    let report = StartReport {
        kind: "self-calibration",
        focal_px: if known_focal { s } else { median },
        mirrored: false,
        rms_px: f64::NAN,
        chosen: false,
        // Set by `fit` once it knows what it screens on.
        screen_frames: 0,
        screen_tracks: 0,
    };
    let model = PerspectiveModel {
        focal_px,
        principal_point: assumed.principal_point,
        k1: 0.0,
        aspect: 1.0,
        rotations: up.rotations,
        translations: up.translations,
        points: up.points,
    };
    (report, model, up.report)
}

/// The scaled-orthographic metric model `w = s_f R_f[0..2] X + t_f` lifted to a pinhole
/// camera of focal `f` (pixels) and principal point `c`: points centred at their
/// centroid (mirrored by `D = diag(1, 1, −1)` when asked: `X → D X`, `R_f → D R_f D`), the
/// centroid at depth `f / s_f` and at its affine image.
pub fn lift_affine(a: &MetricModel, f: f64, mirrored: bool, c: [f64; 2]) -> PerspectiveModel {
    let n = a.points.len().max(1) as f64;
    let centroid = a.points.iter().fold(Vector3::zeros(), |acc, x| acc + x) / n;
    let d = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0));
    let points = a
        .points
        .iter()
        .map(|x| {
            if mirrored {
                d * (x - centroid)
            } else {
                x - centroid
            }
        })
        .collect();
    let nf = a.rotations.len();
    let mut rotations = Vec::with_capacity(nf);
    let mut translations = Vec::with_capacity(nf);
    for k in 0..nf {
        let r = *a.rotations[k].matrix();
        let sf = if a.scales[k] > 0.0 { a.scales[k] } else { 1.0 };
        let rc = r * centroid;
        let t2 = [
            a.translations[k][0] + sf * rc[0],
            a.translations[k][1] + sf * rc[1],
        ];
        let tz = f / sf;
        translations.push(Vector3::new((t2[0] - c[0]) / sf, (t2[1] - c[1]) / sf, tz));
        rotations.push(if mirrored { d * r * d } else { r });
    }
    PerspectiveModel {
        focal_px: vec![f; nf],
        principal_point: c,
        k1: 0.0,
        aspect: 1.0,
        rotations,
        translations,
        points,
    }
}

/// Metric bundle adjustment of `meas` from a given perspective model (e.g. a previous
/// result, another tool's cameras, or the truth for an accuracy floor): the stages of
/// [`fit`] after the self-calibration. The focal length is held fixed when
/// `cfg.intrinsics.focal_px` is given, else refined (shared, or per frame); the principal
/// point and `k₁` are refined as `cfg` says.
pub fn adjust(
    meas: &Measurements,
    start: &PerspectiveModel,
    cfg: &PerspectiveConfig,
    run: usize,
    observer: &mut dyn Observer,
) -> Result<PerspectiveFit> {
    cfg.validate()?;
    let (nf, np) = (meas.n_frames(), meas.n_points());
    if start.rotations.len() != nf || start.points.len() != np || start.focal_px.len() != nf {
        return Err(Error::Dimension {
            context: "perspective::adjust: the start model vs the measurements",
            expected: format!("{nf} frames, {np} tracks"),
            got: format!(
                "{} frames, {} tracks",
                start.rotations.len(),
                start.points.len()
            ),
        });
    }
    let mut assumed = assumed_frame(meas, &cfg.intrinsics);
    assumed.principal_point = start.principal_point;
    let estimate_pp = cfg.estimates_principal_point(&assumed);
    adjust_graph(
        &normalised_graph(meas, &assumed),
        start.clone(),
        cfg,
        &assumed,
        estimate_pp,
        run,
        observer,
    )
}

/// The camera–point graph of `meas`, its positions normalised by `assumed`
/// (`ŵ = (w − c)/s`, `c` the assumed principal point, `s` the assumed scale): the units
/// of [`adjust_graph`]. `O(F·N)` for dense measurements; built once per fit.
fn normalised_graph(meas: &Measurements, assumed: &Assumed) -> projective::bundle::Graph {
    let norm = Normalization {
        centre: assumed.principal_point,
        scale: 1.0 / assumed.scale,
    };
    projective::graph(meas, &norm)
}

/// The adjustment stages on the camera–point graph `g`, its positions normalised by
/// `assumed` ([`normalised_graph`]); a second stage frees the principal point when
/// `estimate_pp`, and `k₁` when `cfg.distortion`. Cost per iteration and memory linear in
/// the observations for a banded camera graph (a video's).
fn adjust_graph(
    g: &projective::bundle::Graph,
    start: PerspectiveModel,
    cfg: &PerspectiveConfig,
    assumed: &Assumed,
    estimate_pp: bool,
    run: usize,
    observer: &mut dyn Observer,
) -> Result<PerspectiveFit> {
    let (nf, np) = (g.n_cams, g.n_pts);
    if nf < 2 {
        return Err(Error::TooFew {
            what: "frames for a metric bundle adjustment",
            needed: 2,
            have: nf,
        });
    }
    let s = assumed.scale;
    let known_focal = cfg.intrinsics.focal_px.is_some();
    let focal = if known_focal {
        Focal::Fixed(cfg.intrinsics.focal_px.unwrap_or(s) / s)
    } else if cfg.per_frame_focal {
        Focal::PerFrame
    } else {
        Focal::Shared
    };
    let pp0 = [
        (start.principal_point[0] - assumed.principal_point[0]) / s,
        (start.principal_point[1] - assumed.principal_point[1]) / s,
    ];
    let mut metric = Metric {
        focal,
        principal_point: Some(pp0),
        k1: Some(start.k1),
        aspect: Some(start.aspect),
    };
    let cl = metric.cam_len();
    let mut cams = vec![0.0; nf * cl];
    for f in 0..nf {
        let c = &mut cams[f * cl..(f + 1) * cl];
        for i in 0..3 {
            for j in 0..3 {
                c[3 * i + j] = start.rotations[f][(i, j)];
            }
            c[9 + i] = start.translations[f][i];
        }
        if focal == Focal::PerFrame {
            c[12] = start.focal_px[f] / s;
        }
    }
    let mut pts: Vec<f64> = start
        .points
        .iter()
        .flat_map(|x| [x[0], x[1], x[2]])
        .collect();
    let mut glob = metric.glob(start.focal_px[0] / s, pp0, start.k1, start.aspect);
    let loss = match cfg.loss {
        Loss::Squared => Loss::Squared,
        Loss::Huber(d) => Loss::Huber(d / s),
        Loss::Cauchy(d) => Loss::Cauchy(d / s),
    };
    let mut stages = Vec::new();
    let stage = Stage {
        name: "metric-ba",
        what: "metric bundle adjustment",
        rms_scale: s,
    };
    let mut report = stage
        .run(
            &Robust {
                inner: metric,
                loss,
            },
            g,
            &mut cams,
            &mut pts,
            &mut glob,
            &cfg.bundle,
            run,
            observer,
            &mut stages,
            None,
        )?
        .report;
    let mut principal_point_rejected = None;
    if estimate_pp || cfg.distortion || cfg.estimate_aspect_ratio {
        let (f_now, _, k_now) = metric.intrinsics(&cams[..cl], &glob);
        let a_now = metric.aspect(&glob);
        // The first stage's end, to return to when the freed principal point is implausible.
        let mut held = estimate_pp.then(|| (cams.clone(), pts.clone(), report.clone()));
        let mut pp_free = estimate_pp;
        loop {
            let free = Metric {
                focal,
                principal_point: (!pp_free).then_some(pp0),
                k1: (!cfg.distortion).then_some(k_now),
                aspect: (!cfg.estimate_aspect_ratio).then_some(a_now),
            };
            let mut glob2 = free.glob(f_now, pp0, k_now, a_now);
            let stage = Stage {
                name: "metric-ba-intrinsics",
                what: "metric bundle adjustment (principal point, distortion, aspect ratio)",
                rms_scale: s,
            };
            let r = stage
                .run(
                    &Robust { inner: free, loss },
                    g,
                    &mut cams,
                    &mut pts,
                    &mut glob2,
                    &cfg.bundle,
                    run,
                    observer,
                    &mut stages,
                    None,
                )?
                .report;
            if pp_free
                && let Some(rejected) =
                    implausible_intrinsics(&free, &cams, &glob2, g, assumed, cfg)
                && let Some((c, x, r0)) = held.take()
            {
                // Back to the principal point held (COLMAP's rule for bogus cameras):
                // the first stage's end, and the other intrinsics freed again from it.
                if let Some(last) = stages.last_mut() {
                    last.stage = "metric-ba-intrinsics-rejected".into();
                }
                principal_point_rejected = Some(rejected);
                (cams, pts, report) = (c, x, r0);
                pp_free = false;
                if cfg.distortion || cfg.estimate_aspect_ratio {
                    continue;
                }
                break;
            }
            report = r;
            metric = free;
            glob = glob2;
            break;
        }
    }
    let estimate_pp = estimate_pp && principal_point_rejected.is_none();
    // Which entries the loss down-weights (residual beyond 2δ), and the plain RMS.
    let mut downweighted = Vec::new();
    let (mut ss, mut n) = (0.0, 0usize);
    let mut r = [0.0; 2];
    for p in 0..np {
        for o in g.track(p) {
            let f = g.cam[o];
            metric.eval(
                &cams[f * cl..(f + 1) * cl],
                &pts[3 * p..3 * p + 3],
                &glob,
                g.w[o],
                &mut r,
                None,
            );
            let e2 = r[0] * r[0] + r[1] * r[1];
            ss += e2;
            n += 2;
            if loss.weight(e2) < 0.5 {
                downweighted.push((f, p));
            }
        }
    }
    downweighted.sort_unstable();
    let rms_px = (ss / n.max(1) as f64).sqrt() * s;
    let model = to_pixels(&metric, &cams, &pts, &glob, nf, assumed);
    let front = (0..np)
        .map(|p| {
            g.track(p)
                .filter(|&o| model.depth(g.cam[o], &model.points[p]) > 0.0)
                .count()
        })
        .sum::<usize>();
    Ok(PerspectiveFit {
        in_front: front as f64 / g.n_obs().max(1) as f64,
        model,
        rms_px,
        selfcal: None,
        stages,
        report,
        assumed: *assumed,
        downweighted,
        principal_point_estimated: estimate_pp,
        principal_point_rejected,
        starts: Vec::new(),
    })
}

/// A principal point estimate the adjustment rejected, and why.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct RejectedPrincipalPoint {
    /// The estimate, pixels.
    pub principal_point: [f64; 2],
    /// The focal length that came with it (the smallest over the frames), pixels.
    pub focal_px: f64,
    /// Why it was rejected.
    pub reason: String,
}

impl RejectedPrincipalPoint {
    /// The warning the pipeline reports, `held` the principal point the fit kept (pixels).
    pub fn warning(&self, held: [f64; 2]) -> String {
        format!(
            "the principal point estimate ({:.1}, {:.1}) px, with a focal length of {:.3} px, \
             was rejected: {}; the principal point is held at ({:.1}, {:.1}) px (give \
             --image-size or --principal-point if it is known)",
            self.principal_point[0],
            self.principal_point[1],
            self.focal_px,
            self.reason,
            held[0],
            held[1]
        )
    }
}

/// Whether the intrinsics of a stage that freed the principal point are physically
/// implausible, by COLMAP's rule for "bogus" cameras (Schönberger & Frahm, CVPR 2016;
/// `Camera::HasBogusParams`): the principal point outside the image (the observations'
/// bounding box, and with a known size the square of the image's larger side around the
/// assumed principal point), or a focal length below 0.1 of that region's larger side (a
/// field of view above 157°). A turntable or a short
/// arc leaves the principal point nearly unobservable (it trades against the rotation);
/// the adjustment can then descend a valley towards a degenerate camera whose cost is a
/// little lower — measured: focal 0.7 px, principal point 500 px off, on a 10-frame arc
/// whose truth is 500 px. `O(n_obs)` for the bounding box.
fn implausible_intrinsics(
    m: &Metric,
    cams: &[f64],
    glob: &[f64],
    g: &projective::bundle::Graph,
    assumed: &Assumed,
    cfg: &PerspectiveConfig,
) -> Option<RejectedPrincipalPoint> {
    let s = assumed.scale;
    let cl = m.cam_len();
    let (_, pp, _) = m.intrinsics(&cams[..cl], glob);
    let pp_px = [
        assumed.principal_point[0] + s * pp[0],
        assumed.principal_point[1] + s * pp[1],
    ];
    let focal_px = (0..g.n_cams)
        .map(|f| m.intrinsics(&cams[f * cl..(f + 1) * cl], glob).0 * s)
        .fold(f64::INFINITY, f64::min);
    // The observations' bounding box, and with a known image size also the square of the
    // image's larger side centred on the assumed principal point (the fit's coordinates are
    // the input's moved and, with an aspect ratio, scaled: the image's own corners are not
    // known here).
    let c = assumed.principal_point;
    let (mut lo, mut hi) = bounding_box(g.w.iter().map(|w| [c[0] + s * w[0], c[1] + s * w[1]]));
    let what = match cfg.intrinsics.image_size {
        Some([w, h]) => {
            let half = w.max(h) as f64 / 2.0;
            for d in 0..2 {
                lo[d] = lo[d].min(assumed.principal_point[d] - half);
                hi[d] = hi[d].max(assumed.principal_point[d] + half);
            }
            "the image"
        }
        None => "the observations' bounding box",
    };
    let side = (hi[0] - lo[0]).max(hi[1] - lo[1]);
    let inside = (0..2).all(|d| pp_px[d] >= lo[d] && pp_px[d] <= hi[d]);
    let reason = if !inside {
        format!("outside {what}")
    } else if !(focal_px >= 0.1 * side) {
        format!("focal length below 0.1 of {what}'s larger side ({side:.1} px)")
    } else {
        return None;
    };
    Some(RejectedPrincipalPoint {
        principal_point: pp_px,
        focal_px,
        reason,
    })
}

/// The adjusted parameters (normalised units) as a [`PerspectiveModel`] in pixels, in the
/// first camera's frame, unit = RMS point spread.
fn to_pixels(
    m: &Metric,
    cams: &[f64],
    pts: &[f64],
    glob: &[f64],
    nf: usize,
    a: &Assumed,
) -> PerspectiveModel {
    let cl = m.cam_len();
    let s = a.scale;
    let rot = |f: usize| Matrix3::from_row_slice(&cams[f * cl..f * cl + 9]);
    let tr = |f: usize| Vector3::new(cams[f * cl + 9], cams[f * cl + 10], cams[f * cl + 11]);
    let (r0, t0) = (rot(0), tr(0));
    // World = camera 0's frame: X' = R0 X + t0; R_f' = R_f R0ᵀ, t_f' = t_f − R_f' t0.
    let mut points: Vec<Vector3<f64>> = pts
        .chunks(3)
        .map(|x| r0 * Vector3::new(x[0], x[1], x[2]) + t0)
        .collect();
    let mut rotations = Vec::with_capacity(nf);
    let mut translations = Vec::with_capacity(nf);
    for f in 0..nf {
        let rf = rot(f) * r0.transpose();
        translations.push(tr(f) - rf * t0);
        rotations.push(rf);
    }
    let n = points.len().max(1) as f64;
    let centroid = points.iter().fold(Vector3::zeros(), |a, x| a + x) / n;
    let spread = (points
        .iter()
        .map(|x| (x - centroid).norm_squared())
        .sum::<f64>()
        / n)
        .sqrt();
    if spread > 0.0 && spread.is_finite() {
        points.iter_mut().for_each(|x| *x /= spread);
        translations.iter_mut().for_each(|t| *t /= spread);
    }
    let focal_px = (0..nf)
        .map(|f| m.intrinsics(&cams[f * cl..(f + 1) * cl], glob).0 * s)
        .collect();
    // The principal point and k₁ are shared by every frame.
    let (_, cn, k1) = m.intrinsics(&cams[..cl], glob);
    PerspectiveModel {
        focal_px,
        principal_point: [
            a.principal_point[0] + s * cn[0],
            a.principal_point[1] + s * cn[1],
        ],
        k1,
        aspect: m.aspect(glob),
        rotations,
        translations,
        points,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// A complete table of `nf` frames and `np` tracks seen by simple projective cameras,
    /// with Gaussian noise of `sigma` pixels: the model and the measurements.
    fn noisy(nf: usize, np: usize, sigma: f64) -> (ProjectiveModel, Measurements) {
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let noise = Normal::new(0.0, sigma).unwrap();
        let cameras: Vec<[f64; 12]> = (0..nf)
            .map(|f| {
                let a = 0.05 * f as f64;
                let (c, s) = (a.cos(), a.sin());
                [
                    500.0 * c,
                    0.0,
                    500.0 * s,
                    320.0 * 5.0,
                    0.0,
                    500.0,
                    0.0,
                    240.0 * 5.0,
                    -s,
                    0.0,
                    c,
                    5.0,
                ]
            })
            .collect();
        let points: Vec<[f64; 4]> = (0..np)
            .map(|p| {
                let t = p as f64;
                [(t * 0.37).sin(), (t * 0.73).cos(), (t * 1.31).sin(), 1.0]
            })
            .collect();
        let proj = ProjectiveModel { cameras, points };
        let w = faer::Mat::from_fn(2 * nf, np, |r, p| {
            proj.project(r / 2, p)[r % 2] + noise.sample(&mut rng)
        });
        (proj, Measurements::complete(w))
    }

    /// The metric adjustment with a shared focal length (an unknown coupled to every
    /// camera in the reduced system) and the principal point estimated gives the same
    /// optimum whether the reduced system is factorized or solved by conjugate gradients.
    #[test]
    fn the_iterative_reduced_solver_matches_the_direct_one() {
        use crate::projective::bundle::LinearSolver;
        let (nf, np) = (16, 80);
        let (proj, meas) = noisy(nf, np, 0.5);
        // `noisy`'s cameras are K [R_f | t] with K = diag(500, 500, 1), R_f a rotation
        // about y by 0.05 f and t = (3.2, 2.4, 5); started at a focal length of 520 px.
        let start = PerspectiveModel {
            focal_px: vec![520.0; nf],
            principal_point: [0.0, 0.0],
            k1: 0.0,
            aspect: 1.0,
            rotations: (0..nf)
                .map(|f| {
                    let (s, c) = (0.05 * f as f64).sin_cos();
                    Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c)
                })
                .collect(),
            translations: vec![Vector3::new(3.2, 2.4, 5.0); nf],
            points: proj
                .points
                .iter()
                .map(|x| Vector3::new(x[0], x[1], x[2]))
                .collect(),
        };
        let adjust_with = |solver: LinearSolver| {
            let mut cfg = PerspectiveConfig {
                intrinsics: Intrinsics {
                    principal_point: Some([0.0, 0.0]),
                    ..Intrinsics::default()
                },
                estimate_principal_point: true,
                ..PerspectiveConfig::default()
            };
            cfg.bundle.linear_solver = solver;
            adjust(&meas, &start, &cfg, 0, &mut crate::NoopObserver).unwrap()
        };
        let (d, i) = (
            adjust_with(LinearSolver::Direct),
            adjust_with(LinearSolver::Iterative),
        );
        assert!(d.rms_px > 0.2 && d.rms_px < 0.5, "rms {}", d.rms_px);
        assert!(
            (d.rms_px - i.rms_px).abs() <= 1e-7 * d.rms_px,
            "{} vs {}",
            d.rms_px,
            i.rms_px
        );
        assert!(
            (d.model.focal_px[0] - 500.0).abs() < 10.0,
            "{}",
            d.model.focal_px[0]
        );
        assert!((d.model.focal_px[0] - i.model.focal_px[0]).abs() < 1e-4);
        for s in &i.stages {
            assert_eq!(s.linear_solver, Some(LinearSolver::Iterative), "{s:?}");
            assert!(s.cg_iterations > 0, "{s:?}");
        }
    }

    /// The screening subset of a long sequence: 150 frames spanning it when its tracks
    /// link them; none (the whole table) when two halves of the sequence share no track,
    /// or when the sequence is short.
    #[test]
    fn the_screening_subset_spans_a_linked_sequence_only() {
        let table = |nf: usize, bridge: bool| {
            // 20 tracks in each half of the sequence, and 10 over all of it (`bridge`).
            let np = 50;
            let visible: Vec<bool> = (0..nf)
                .flat_map(|f| {
                    (0..np).map(move |p| match p {
                        0..20 => f < nf / 2,
                        20..40 => f >= nf / 2,
                        _ => bridge,
                    })
                })
                .collect();
            Measurements::new(faer::Mat::zeros(2 * nf, np), visible)
        };
        let (frames, tracks) = screening_subset(&table(400, true), 150).expect("a subset");
        assert_eq!(frames.len(), 150);
        assert_eq!((frames[0], *frames.last().unwrap()), (0, 399));
        assert_eq!(tracks.len(), 50);
        assert!(screening_subset(&table(400, false), 150).is_none());
        assert!(screening_subset(&table(300, true), 150).is_none());
        assert!(screening_subset(&table(400, true), 0).is_none());
    }

    #[test]
    fn early_acceptance_is_a_noise_level_bound() {
        let (nf, np) = (12, 60);
        let (proj, meas) = noisy(nf, np, 0.5);
        let cfg = PerspectiveConfig {
            intrinsics: Intrinsics {
                principal_point: Some([320.0, 240.0]),
                ..Intrinsics::default()
            },
            ..PerspectiveConfig::default()
        };
        let assumed = assumed_frame(&meas, &cfg.intrinsics);
        let rms_p = proj.rms(&meas);
        // The bound in RMS: C_M ≤ C_P + σ̂² (d + 3√(2d)), d = 5F − 8 + 1 (a shared focal).
        let n_res = 2.0 * (nf * np) as f64;
        let dof_p = 11.0 * nf as f64 + 3.0 * np as f64 - 15.0;
        let d = 5.0 * nf as f64 - 8.0 - 1.0;
        let c_p = rms_p * rms_p * n_res;
        let bound = c_p + c_p / (n_res - dof_p) * (d + 3.0 * (2.0 * d).sqrt());
        let at = |c: f64| (c / n_res).sqrt();
        let accept = |rms: f64| within_noise_of_projective(&meas, &proj, rms, &cfg, &assumed);
        assert!(accept(rms_p));
        assert!(accept(at(0.999 * bound)));
        assert!(!accept(at(1.001 * bound)));
        assert!(!accept(1.2 * rms_p));
        assert!(!accept(f64::NAN));
    }
}
