//! Projective factorization of partial track tables.
//!
//! # Model and objective
//!
//! Each frame is a projective camera `P_f` (3×4) and each track a homogeneous point
//! `X_p ∈ P³`; the image of `X_p` in frame `f` is `π(P_f X_p)`, `π(a, b, c) = (a/c, b/c)`.
//! The objective is the reprojection error in pixels over the observed entries only,
//!
//! ```text
//!   E(P, X) = Σ_{(f,p) observed} ‖π(P_f X_p) − w_fp‖²,    RMS = sqrt(E / #observed scalars),
//! ```
//!
//! defined up to a 4×4 homography `P → P H`, `X → H⁻¹ X` (15 degrees of freedom once the
//! per-camera and per-point scales are fixed). Part 2 (self-calibration) upgrades it to a
//! Euclidean reconstruction.
//!
//! # Pipeline ([`fit`])
//!
//! 1. **Hartley normalization** (Hartley 1997): image coordinates are translated to their
//!    centroid and scaled so the mean distance from it is √2. The scaling is uniform, so the
//!    optimum in normalized coordinates is the pixel optimum; all reported costs are in
//!    pixels.
//! 2. **Start.** Missing data: the affine optimum `W ≈ M S + t 1ᵀ` (rank3's damped Wiberg /
//!    VarPro, which reaches it from random starts; [`crate::completion`]) gives
//!    `P_f = [M_f t_f; 0 0 0 1]`, `X_p = (s_p, 1)`, the warm start of Hong, Zach, Fitzgibbon &
//!    Cipolla (ECCV 2016). Complete data ([`Start::SturmTriggs`]): the projective depths
//!    `λ_fp` are estimated by iterating Sturm & Triggs' factorization (ECCV 1996; iterated as
//!    in Triggs 1996 and Mahamud & Hebert 2000): rescale `[λ_fp w_fp; λ_fp]` (3F×N) to
//!    balance rows and columns, truncate it to rank 4 by SVD, `λ_fp ← (P_f X_p)₃`, repeat.
//! 3. **Bridge** ([`Bridge::Pose`], the default): the pseudo object space error of Hong &
//!    Zach (CVPR 2018), `(1 − η) ‖P₁₂X − (P₃X) w‖² + η ‖P₁₂X − w‖²` with `X = (x̃, 1)`, a
//!    bilinear objective between the affine and the projective ones, minimised by variable
//!    projection from the affine start ([`models::Pose`]).
//! 4. **Projective bundle adjustment** ([`models::Projective`]): `E` itself, by sparse
//!    Levenberg–Marquardt with the points eliminated (variable projection by default; see
//!    [`bundle`]), cameras and points on their unit spheres.
//!
//! Why this chain, and not projective VarPro straight from the affine optimum, is measured in
//! docs/results.md (`examples/projective_benchmark.rs`) and argued in docs/math.md.
//!
//! # Complexity
//!
//! Every stage after the start is linear in the observations per iteration except the
//! factorisation of the sparse reduced camera system, whose cost follows the camera graph
//! (banded for a video; see [`bundle`]). The Sturm–Triggs start is `O(F N)` per iteration
//! (complete data: linear in the observations). No dense `F×F` or `(kF)²` matrix is formed
//! unless every frame shares tracks with every other, where the reduced camera system is
//! dense by nature.
//!
//! # References
//!
//! * P. Sturm and B. Triggs, "A factorization based algorithm for multi-image projective
//!   structure and motion", ECCV 1996; B. Triggs, "Factorization methods for projective
//!   structure and motion", CVPR 1996.
//! * S. Mahamud and M. Hebert, "Iterative projective reconstruction from multiple views",
//!   CVPR 2000.
//! * R. Hartley, "In defense of the eight-point algorithm", PAMI 19(6), 1997.
//! * J. H. Hong, C. Zach, A. Fitzgibbon and R. Cipolla, "Projective bundle adjustment from
//!   arbitrary initialization using the variable projection method", ECCV 2016.
//! * J. H. Hong and C. Zach, "pOSE: Pseudo object space error for initialization-free
//!   bundle adjustment", CVPR 2018.

pub mod bundle;
pub mod models;
mod sturm_triggs;
pub mod verdict;
pub mod windowed;

use std::time::Instant;

use faer::{Mat, MatRef};
use nalgebra::{Matrix4, SymmetricEigen, Vector4};
use serde::{Deserialize, Serialize};

use crate::{Error, Event, Measurements, Observer, Result, SolverReport, SolverStatus};
use bundle::{Graph, LmConfig, Progress};

/// How the affine start reaches the projective bundle adjustment.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Bridge {
    /// Projective bundle adjustment straight from the start.
    Direct,
    /// Minimise the pOSE objective with weight `eta` on the affine term first.
    Pose { eta: f64 },
}

/// How the first projective estimate was obtained.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Start {
    /// From the affine factorization (`P_f = [M_f t_f; 0 0 0 1]`).
    Affine,
    /// Iterated Sturm–Triggs depths (complete data).
    SturmTriggs,
    /// A model given to [`refine`].
    Given,
    /// Overlapping windows of frames, chained ([`windowed`]).
    Windows,
}

/// Settings of the projective stages. Every field has a documented default.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ProjectiveConfig {
    /// Default [`Bridge::Pose`] with `eta = 0.01` (chosen by measurement over the matrices
    /// of Hong et al., ECCV 2016, Tables 6 and 7, from random starts; docs/results.md): the
    /// smaller affine share lets the bridge leave an affine local minimum that a
    /// perspective camera explains better (their synthetic spheres with closed loops: 180/180
    /// starts against 141/180 at `eta = 0.1`; their strong-perspective "dinosaur closer":
    /// 96/100 against 0/100), and no real matrix loses. The one set that prefers 0.1 is the
    /// open sphere seen from closest (27/30 against 20/30).
    pub bridge: Bridge,
    /// A second bridge from the same affine start: both are run, and the projective bundle
    /// adjustment starts from the end whose projective cost is lower (both reported in
    /// [`ProjectiveFit::bridges`]). Default [`Bridge::Pose`] with `eta = 0.1`: the two
    /// weights fail on different starts — over 30 random starts on the open sphere seen
    /// from closest (Hong et al.'s S10.5) `eta = 0.01` alone reached the optimum from 20
    /// and `0.1` alone from 27, picking the lower end from 26; on the loop-closed sphere 30,
    /// 16 and 30; on the strong-perspective dinosaur 30, 0 and 30 (docs/results.md). It
    /// costs a second bridge, not a second adjustment. `None`: one bridge. Not used with
    /// the Sturm–Triggs start (no bridge) nor by the windows of long sequences, the
    /// automatic camera's pre-test and the perspective camera's projective start.
    #[serde(default = "default_second_bridge")]
    pub second_bridge: Option<Bridge>,
    /// Use the Sturm–Triggs start when the table is complete. Default true.
    pub sturm_triggs: bool,
    /// Sturm–Triggs iterations (depth updates). Default 30.
    pub sturm_triggs_iterations: usize,
    /// The pOSE stage's solver. Default: [`LmConfig::default`] (variable projection),
    /// 200 iterations, relative tolerance 1e-10.
    pub pose: LmConfig,
    /// The projective bundle adjustment. Default: [`LmConfig::default`] (variable
    /// projection, 300 iterations, relative tolerance 1e-12) with geodesic acceleration
    /// `α = 0.75` ([`LmConfig::geodesic_acceleration`]): on long sequences with missing data
    /// the adjustment otherwise crawls along a curved valley, alternating accepted and
    /// rejected steps (Wilshire, 190 frames: over 300 iterations without it, 112 to the best
    /// known optimum with it; docs/results.md); 3 step extensions
    /// ([`LmConfig::extension_trials`]) and the long-tail stop at `10⁻⁷` of the cost per
    /// window ([`LmConfig::window_relative_tolerance`], `10⁻⁶` in [`LmConfig::default`]):
    /// near Blue bear's optimum the adjustment lowers the cost by ~10⁻⁶ of itself per
    /// window for over a hundred steps, so the `10⁻⁶` rule stopped it 2·10⁻⁶ of the RMS
    /// above the optimum, outside the benchmark's 10⁻⁶ (docs/results.md, 2026-12-03); and
    /// no stop at the noise level ([`LmConfig::noise_tolerance`] 0, `0.01` in
    /// [`LmConfig::default`]): on small tables that rule ends a linearly converging tail
    /// while the RMS is still ~10⁻⁶ of itself above the optimum (S10.5L, 5·10³ residuals:
    /// 0.862545912 px, 0.007 χ² units above 0.862545158; docs/results.md, forty-second
    /// session), which the escapes' adjustments used to finish and no longer do once they
    /// stop on returning. The tail's rules are then the window above, the Gauss–Newton
    /// decrement and the iteration cap. [`fit_observations`] (long sequences) keeps the
    /// tail at no less than [`LONG_TAIL_TOLERANCE`].
    pub refine: LmConfig,
    /// Escapes from the adjusted end, tried in turn after [`fit`]'s adjustment from an
    /// affine start (not after the Sturm–Triggs start, [`refine`] or the windows of long
    /// sequences): each bridge runs again from the adjusted cameras (its points re-solved for
    /// them), the adjustment runs from where it ends, and the model of lower cost is kept
    /// ([`ProjectiveFit::escapes`] reports each). A homotopy restart: the bridge's
    /// objective, whose affine share smooths the projective cost, moves the cameras out of
    /// a local minimum whose basin the affine start led into. Default `[pOSE η = 0.01,
    /// pOSE η = 0.1]` (the two bridges of the chain). Measured from random starts
    /// (docs/results.md, 2026-12-03), with the adjustment's tail of [`Self::refine`]: Hong et
    /// al.'s open and loop-closed spheres seen from closest (S10.5, S10.5L) went from 45/50
    /// to 49/50 each, Blue bear from 22/30 to 29/30; the escapes cost a bridge and an
    /// adjustment each. An escape's adjustment that comes back into the basin of the
    /// model it left stops there ([`EscapeOutcome::returned`], `back_in_basin`): it would
    /// end at that model. Wilshire: 80 → 31 s per start with it (both escapes return;
    /// docs/results.md, forty-second session). Empty: none. Like the second bridge, not used by the windows of long sequences, the
    /// automatic camera's pre-test and the perspective camera's projective start.
    #[serde(default = "default_escapes")]
    pub escapes: Vec<Bridge>,
}

fn default_second_bridge() -> Option<Bridge> {
    Some(Bridge::Pose { eta: 0.1 })
}

fn default_escapes() -> Vec<Bridge> {
    vec![Bridge::Pose { eta: 0.01 }, Bridge::Pose { eta: 0.1 }]
}

impl Default for ProjectiveConfig {
    fn default() -> Self {
        Self {
            bridge: Bridge::Pose { eta: 0.01 },
            second_bridge: default_second_bridge(),
            sturm_triggs: true,
            sturm_triggs_iterations: 30,
            pose: LmConfig {
                max_iterations: 200,
                function_tolerance: 1e-10,
                point_iterations: 1,
                ..LmConfig::default()
            },
            refine: LmConfig {
                geodesic_acceleration: 0.75,
                extension_trials: 3,
                window_relative_tolerance: 1e-7,
                noise_tolerance: 0.0,
                ..LmConfig::default()
            },
            escapes: default_escapes(),
        }
    }
}

impl ProjectiveConfig {
    /// Checks ranges; [`Error::InvalidConfig`] names the field.
    pub fn validate(&self) -> Result<()> {
        for (field, b) in [
            ("projective.bridge", Some(self.bridge)),
            ("projective.second_bridge", self.second_bridge),
        ]
        .into_iter()
        .chain(
            self.escapes
                .iter()
                .map(|b| ("projective.escapes", Some(*b))),
        ) {
            if let Some(Bridge::Pose { eta }) = b
                && !(eta > 0.0 && eta <= 1.0)
            {
                return Err(Error::InvalidConfig {
                    field,
                    message: format!("pOSE weight eta = {eta} is not in (0, 1]"),
                });
            }
        }
        for (field, c) in [
            ("projective.pose", &self.pose),
            ("projective.refine", &self.refine),
        ] {
            c.validate(field)?;
        }
        Ok(())
    }
}

/// A projective reconstruction in pixel coordinates: `w_fp ≃ P_f X_p`.
///
/// Gauge of the returned values: every `P_f` has unit Frobenius norm and every `X_p` unit
/// norm, with signs chosen so that the depths `(P_f X_p)₃` are positive for most
/// observations.
#[derive(Debug, Clone, PartialEq)]
pub struct ProjectiveModel {
    /// Per frame, `P_f` row-major (3×4).
    pub cameras: Vec<[f64; 12]>,
    /// Per track, `X_p` (homogeneous).
    pub points: Vec<[f64; 4]>,
}

impl ProjectiveModel {
    /// The model of the given frames and tracks (indices, in the order given).
    pub fn select(&self, frames: &[usize], tracks: &[usize]) -> ProjectiveModel {
        ProjectiveModel {
            cameras: frames.iter().map(|&f| self.cameras[f]).collect(),
            points: tracks.iter().map(|&p| self.points[p]).collect(),
        }
    }

    /// `π(P_f X_p)`.
    #[inline]
    pub fn project(&self, f: usize, p: usize) -> [f64; 2] {
        project(&self.cameras[f], &self.points[p])
    }

    /// `π(P_f X_p)` for every frame and track (2F×N).
    pub fn predict(&self) -> Mat<f64> {
        Mat::from_fn(2 * self.cameras.len(), self.points.len(), |r, p| {
            self.project(r / 2, p)[r % 2]
        })
    }

    /// RMS reprojection error over the observed scalars of `meas` (pixels).
    pub fn rms(&self, meas: &Measurements) -> f64 {
        let (mut ss, mut n) = (0.0, 0usize);
        for (f, p) in meas.observed_pairs() {
            let q = self.project(f, p);
            ss += (q[0] - meas.w[(2 * f, p)]).powi(2) + (q[1] - meas.w[(2 * f + 1, p)]).powi(2);
            n += 2;
        }
        if n == 0 { 0.0 } else { (ss / n as f64).sqrt() }
    }

    /// `P_f` as a 3×4 array of rows.
    pub fn camera_matrix(&self, f: usize) -> [[f64; 4]; 3] {
        let c = &self.cameras[f];
        std::array::from_fn(|r| std::array::from_fn(|k| c[4 * r + k]))
    }

    /// Points of the tracks of `meas` (same frames as `self`) given the cameras: linear
    /// triangulation (the smallest eigenvector of `Σ aᵀa` over the rows `x P₃ − P₁`,
    /// `y P₃ − P₂`, in normalized coordinates) refined by Gauss–Newton on the reprojection
    /// error. Tracks seen in fewer than 2 frames get NaN. `O(observations)`.
    pub fn triangulate(&self, meas: &Measurements) -> Vec<[f64; 4]> {
        let norm = Normalization::of(meas);
        self.triangulate_graph(&graph(meas, &norm), &norm)
    }

    /// [`Self::triangulate`] for a list of observations of `n_tracks` tracks in this
    /// model's frames (sparse: `O(observations)` time and memory). Errors as
    /// [`fit_observations`] for indices out of range, non-finite or repeated entries.
    pub fn triangulate_observations(
        &self,
        obs: &[Observation],
        n_tracks: usize,
    ) -> Result<Vec<[f64; 4]>> {
        let order = observation_order(obs, self.cameras.len(), n_tracks)?;
        let norm = Normalization::of_points(|| obs.iter().map(|o| o.xy));
        let g = observation_graph(obs, &order, self.cameras.len(), n_tracks, &norm);
        Ok(self.triangulate_graph(&g, &norm))
    }

    fn triangulate_graph(&self, g: &Graph, norm: &Normalization) -> Vec<[f64; 4]> {
        let cams: Vec<f64> = self
            .cameras
            .iter()
            .flat_map(|c| {
                let mut n = norm.camera_to_normalized(c);
                bundle::normalize(&mut n);
                n
            })
            .collect();
        let mut pts = vec![0.0; 4 * g.n_pts];
        for p in 0..g.n_pts {
            let x = dlt_point(g, &cams, p);
            pts[4 * p..4 * p + 4].copy_from_slice(&x);
        }
        bundle::solve_points(&models::Projective, g, &cams, &[], &mut pts, 20);
        (0..g.n_pts)
            .map(|p| {
                if g.track(p).len() < 2 {
                    [f64::NAN; 4]
                } else {
                    std::array::from_fn(|k| pts[4 * p + k])
                }
            })
            .collect()
    }
}

/// Degrees of freedom of a projective reconstruction of `n_frames` cameras and `n_points`
/// points: `11F + 3N − 15` (3×4 cameras and homogeneous points up to scale, less the 4×4
/// homography of the projective gauge); 0 when that is negative.
pub fn degrees_of_freedom(n_frames: usize, n_points: usize) -> usize {
    (11 * n_frames + 3 * n_points).saturating_sub(15)
}

/// `π(P X)` for a row-major 3×4 `P`: `(P₁X / P₃X, P₂X / P₃X)`.
#[inline]
pub fn project(c: &[f64; 12], x: &[f64; 4]) -> [f64; 2] {
    let d = c[8] * x[0] + c[9] * x[1] + c[10] * x[2] + c[11] * x[3];
    [
        (c[0] * x[0] + c[1] * x[1] + c[2] * x[2] + c[3] * x[3]) / d,
        (c[4] * x[0] + c[5] * x[1] + c[6] * x[2] + c[7] * x[3]) / d,
    ]
}

/// One stage's outcome.
#[derive(Debug, Clone, Serialize)]
pub struct StageReport {
    /// `"sturm-triggs"`, `"pose"` or `"projective-ba"`.
    pub stage: String,
    pub status: SolverStatus,
    pub iterations: usize,
    /// RMS over observed scalars, pixels, before and after the stage (for `"pose"`: of the
    /// pOSE objective's residuals, i.e. `sqrt(ℓ / #observed scalars)`).
    pub rms_before_px: f64,
    pub rms_after_px: f64,
    pub seconds: f64,
    /// How the stage's reduced camera systems were solved (`"direct"` or `"iterative"`;
    /// `null` for a stage that solves none) and the conjugate-gradient products the
    /// iterative solver took (0 otherwise).
    pub linear_solver: Option<bundle::LinearSolver>,
    pub cg_iterations: usize,
}

/// Result of [`fit`].
#[derive(Debug, Clone)]
pub struct ProjectiveFit {
    pub model: ProjectiveModel,
    /// Final reprojection RMS over observed scalars, pixels.
    pub rms_px: f64,
    pub start: Start,
    pub stages: Vec<StageReport>,
    /// Report of the final (projective bundle adjustment) stage.
    pub report: SolverReport,
    /// Non-zeros of the reduced camera system's lower triangle (0: solved by conjugate
    /// gradients, never formed).
    pub schur_nnz: usize,
    /// With [`ProjectiveConfig::second_bridge`], each bridge tried from the affine start
    /// (the configured one first); empty when one ran.
    pub bridges: Vec<BridgeOutcome>,
    /// With [`ProjectiveConfig::escapes`], each escape tried after the adjustment, in order.
    pub escapes: Vec<EscapeOutcome>,
}

/// One escape tried from the adjusted end ([`ProjectiveConfig::escapes`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EscapeOutcome {
    pub bridge: Bridge,
    /// Reprojection RMS of the model escaped from (the best so far), pixels.
    pub from_rms_px: f64,
    /// Where the bridge ended (the adjustment's start), pixels (NaN when it failed).
    pub bridge_rms_px: f64,
    /// Where the adjustment after it ended, pixels (NaN when it failed).
    pub rms_px: f64,
    /// Iterations of the bridge and the adjustment together.
    pub iterations: usize,
    pub seconds: f64,
    /// Whether the model it reached was lower and replaced the one escaped from.
    pub kept: bool,
    /// Whether the adjustment stopped once back in the basin of the model escaped from
    /// (`back_in_basin`): it would have ended there, so it is not kept, and `rms_px` is
    /// where it stopped.
    #[serde(default)]
    pub returned: bool,
}

/// One bridge tried from the affine start ([`ProjectiveConfig::second_bridge`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BridgeOutcome {
    pub bridge: Bridge,
    /// Reprojection RMS of the projective model where the bridge ended (the adjustment's
    /// start), over the observed scalars, pixels (NaN when the bridge failed).
    pub start_rms_px: f64,
    /// Iterations of the bridge (0 for [`Bridge::Direct`]).
    pub iterations: usize,
    pub seconds: f64,
    /// Whether the adjustment started from its end (the lower cost).
    pub kept: bool,
}

/// An affine factorization `W ≈ M S + t 1ᵀ` in pixels (M 2F×3, S 3×N, t length 2F), the
/// warm start of [`fit`].
#[derive(Debug, Clone, Copy)]
pub struct AffineStart<'a> {
    pub m: MatRef<'a, f64>,
    pub s: MatRef<'a, f64>,
    pub t: &'a [f64],
}

/// Hartley's similarity normalization of image coordinates: `w' = s (w − c)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Normalization {
    pub centre: [f64; 2],
    pub scale: f64,
}

impl Normalization {
    /// Centroid of the observed points and the scale that makes their mean distance from it
    /// √2 (1 for a single point or coincident points).
    pub fn of(meas: &Measurements) -> Self {
        Self::of_points(|| {
            meas.observed_pairs()
                .map(|(f, p)| [meas.w[(2 * f, p)], meas.w[(2 * f + 1, p)]])
        })
    }

    /// [`Normalization::of`] for any set of image points (`points()` is iterated twice).
    pub fn of_points<I: Iterator<Item = [f64; 2]>>(points: impl Fn() -> I) -> Self {
        let (mut cx, mut cy, mut n) = (0.0, 0.0, 0usize);
        for q in points() {
            cx += q[0];
            cy += q[1];
            n += 1;
        }
        let n = n.max(1) as f64;
        let (cx, cy) = (cx / n, cy / n);
        let d = points().map(|q| (q[0] - cx).hypot(q[1] - cy)).sum::<f64>() / n;
        let scale = if d > 0.0 && d.is_finite() {
            std::f64::consts::SQRT_2 / d
        } else {
            1.0
        };
        Self {
            centre: [cx, cy],
            scale,
        }
    }

    /// `T P` for `T = [s 0 −s cx; 0 s −s cy; 0 0 1]`.
    pub fn camera_to_normalized(&self, c: &[f64; 12]) -> Vec<f64> {
        let s = self.scale;
        let mut out = c.to_vec();
        for k in 0..4 {
            out[k] = s * (c[k] - self.centre[0] * c[8 + k]);
            out[4 + k] = s * (c[4 + k] - self.centre[1] * c[8 + k]);
        }
        out
    }

    /// `T⁻¹ P`.
    pub fn camera_to_pixels(&self, c: &[f64]) -> [f64; 12] {
        let s = self.scale;
        let mut out = [0.0; 12];
        for k in 0..4 {
            out[k] = c[k] / s + self.centre[0] * c[8 + k];
            out[4 + k] = c[4 + k] / s + self.centre[1] * c[8 + k];
            out[8 + k] = c[8 + k];
        }
        out
    }
}

/// The observations of `meas` in normalized coordinates, by track.
pub(crate) fn graph(meas: &Measurements, norm: &Normalization) -> Graph {
    let (nf, np) = (meas.n_frames(), meas.n_points());
    let mut pt_ptr = Vec::with_capacity(np + 1);
    let mut cam = Vec::new();
    let mut w = Vec::new();
    pt_ptr.push(0);
    for p in 0..np {
        for f in 0..nf {
            if meas.is_visible(f, p) {
                cam.push(f);
                w.push([
                    norm.scale * (meas.w[(2 * f, p)] - norm.centre[0]),
                    norm.scale * (meas.w[(2 * f + 1, p)] - norm.centre[1]),
                ]);
            }
        }
        pt_ptr.push(cam.len());
    }
    Graph {
        n_cams: nf,
        n_pts: np,
        pt_ptr,
        cam,
        w,
    }
}

/// Linear triangulation of track `p` from unit-norm normalized cameras (flat, 12 per frame).
fn dlt_point(g: &Graph, cams: &[f64], p: usize) -> [f64; 4] {
    dlt_views(
        g.track(p)
            .map(|o| (&cams[12 * g.cam[o]..12 * g.cam[o] + 12], g.w[o])),
    )
}

/// Linear triangulation of one point from its views `(P, w)` (`P` row-major 3×4): the
/// smallest eigenvector of `Σ aᵀa` over the rows `x P₃ − P₁`, `y P₃ − P₂` (Hartley &
/// Zisserman §12.2), or the second smallest when that reprojects closer. A common centre of
/// the cameras `C` (`P_f C = 0` for every frame) zeroes every row, so it is the smallest
/// eigenvector of every track, and it projects nowhere: the projective cameras of a planar
/// scene can drift towards one (a plane's views are also those of a camera turning about
/// its centre), and every track's point would be that centre. `O(views)`.
pub(crate) fn dlt_views<'a>(
    views: impl Iterator<Item = (&'a [f64], [f64; 2])> + Clone,
) -> [f64; 4] {
    let mut a = Matrix4::<f64>::zeros();
    for (c, w) in views.clone() {
        for (row, wk) in [(0usize, w[0]), (4, w[1])] {
            let v = Vector4::new(
                wk * c[8] - c[row],
                wk * c[9] - c[row + 1],
                wk * c[10] - c[row + 2],
                wk * c[11] - c[row + 3],
            );
            a += v * v.transpose();
        }
    }
    let e = SymmetricEigen::new(a);
    let mut order = [0usize, 1, 2, 3];
    order.sort_by(|&i, &j| e.eigenvalues[i].total_cmp(&e.eigenvalues[j]));
    let candidate = |k: usize| {
        let x = e.eigenvectors.column(k);
        [x[0], x[1], x[2], x[3]]
    };
    // Squared reprojection error in the views' (normalised) units; infinite when a view
    // sees the point at depth 0.
    let error = |x: &[f64; 4]| {
        views
            .clone()
            .map(|(c, w)| {
                let c: &[f64; 12] = c.try_into().unwrap_or(&[0.0; 12]);
                let q = project(c, x);
                (q[0] - w[0]).powi(2) + (q[1] - w[1]).powi(2)
            })
            .fold(
                0.0,
                |s, d| if d.is_finite() { s + d } else { f64::INFINITY },
            )
    };
    let first = candidate(order[0]);
    let second = candidate(order[1]);
    if error(&second) < error(&first) {
        second
    } else {
        first
    }
}

/// Checks that a projective model is determined by the observations: at least 2 frames,
/// every frame seeing ≥ 6 tracks (11 parameters, 2 equations per track), every track seen
/// in ≥ 2 frames, and at least 7 tracks in all (a fundamental matrix needs 7).
pub fn check_observations(meas: &Measurements) -> Result<()> {
    // One tiled walk (no graph of the observations is built): the first non-finite value in
    // frame-major order, and the counts per frame and per track.
    let (nf, np) = (meas.n_frames(), meas.n_points());
    let (mut per_frame, mut per_track) = (vec![0usize; nf], vec![0usize; np]);
    let mut bad: Option<(usize, usize)> = None;
    meas.for_each_observed(|f, p| {
        if !(meas.w[(2 * f, p)].is_finite() && meas.w[(2 * f + 1, p)].is_finite())
            && bad.is_none_or(|b| (f, p) < b)
        {
            bad = Some((f, p));
        }
        per_frame[f] += 1;
        per_track[p] += 1;
    });
    if let Some((f, p)) = bad {
        return Err(Error::Degenerate(format!(
            "observed value of track {p} in frame {f} is not finite"
        )));
    }
    check_counts(&per_frame, &per_track)
}

/// Projective reconstruction of `meas` from an affine factorization of the same
/// observations (see the module documentation for the stages).
///
/// Errors: [`Error::TooFew`] / [`Error::Degenerate`] from [`check_observations`],
/// [`Error::Dimension`] for an affine start of the wrong shape, [`Error::InvalidConfig`],
/// and [`Error::Numerical`] if the reduced camera system cannot be analysed. How each stage
/// ended is data in [`ProjectiveFit::stages`].
pub fn fit(
    meas: &Measurements,
    affine: AffineStart<'_>,
    cfg: &ProjectiveConfig,
    run: usize,
    observer: &mut dyn Observer,
) -> Result<ProjectiveFit> {
    cfg.validate()?;
    check_observations(meas)?;
    let (nf, np) = (meas.n_frames(), meas.n_points());
    if affine.m.nrows() != 2 * nf
        || affine.m.ncols() != 3
        || affine.s.nrows() != 3
        || affine.s.ncols() != np
        || affine.t.len() != 2 * nf
    {
        return Err(Error::Dimension {
            context: "projective fit: affine start",
            expected: format!("M {}×3, S 3×{np}, t {}", 2 * nf, 2 * nf),
            got: format!(
                "M {}×{}, S {}×{}, t {}",
                affine.m.nrows(),
                affine.m.ncols(),
                affine.s.nrows(),
                affine.s.ncols(),
                affine.t.len()
            ),
        });
    }
    let norm = Normalization::of(meas);
    let g = graph(meas, &norm);
    let px = 1.0 / norm.scale;
    let mut stages = Vec::new();

    // Start: cameras (12 per frame) and points (4 per track), normalized coordinates.
    let (cams, pts, start) = if cfg.sturm_triggs && meas.is_complete() {
        let t0 = Instant::now();
        observer.on_event(&Event::StageStarted {
            stage: "sturm-triggs",
        });
        let st = sturm_triggs::run(&g, cfg.sturm_triggs_iterations)?;
        let mut c = st.cameras;
        let mut x = st.points;
        let before = rms_of_cost(&g, px, bundle::cost(&models::Projective, &g, &c, &x, &[]));
        for v in c.chunks_mut(12) {
            bundle::normalize(v);
        }
        for v in x.chunks_mut(4) {
            bundle::normalize(v);
        }
        let seconds = t0.elapsed().as_secs_f64();
        observer.on_event(&Event::StageFinished {
            stage: "sturm-triggs",
            seconds,
        });
        stages.push(StageReport {
            stage: "sturm-triggs".into(),
            status: st.status,
            iterations: st.iterations,
            rms_before_px: f64::NAN,
            rms_after_px: before,
            seconds,
            linear_solver: None,
            cg_iterations: 0,
        });
        (c, x, Start::SturmTriggs)
    } else {
        let (c, x) = affine_start(&affine, &norm);
        let end = bridges(&g, px, c, x, cfg, run, observer, &mut stages)?;
        let mut fit = bundle_adjust(
            &g,
            &norm,
            end.cams,
            end.pts,
            Start::Affine,
            stages,
            cfg,
            end.run,
            observer,
            None,
        )?;
        fit.bridges = end.outcomes;
        escape(&g, &norm, px, &mut fit, cfg, end.run, observer);
        return Ok(fit);
    };

    bundle_adjust(
        &g, &norm, cams, pts, start, stages, cfg, run, observer, None,
    )
}

/// Reprojection RMS of `cost` (a sum of squared residuals over `g`'s observed scalars),
/// `scale` units per normalized unit (pixels: `1 / norm.scale`).
fn rms_of_cost(g: &Graph, scale: f64, cost: f64) -> f64 {
    (cost / (2 * g.n_obs()).max(1) as f64).sqrt() * scale
}

/// [`ProjectiveConfig::escapes`]: from the adjusted model in `fit`, each bridge in turn
/// (pOSE re-solves the points for the adjusted cameras; the direct bridge starts from the
/// model's affine points `X/w`), then the adjustment; the lower model replaces `fit`'s
/// (its stages and report with it, the affine stage's bridges kept). An adjustment that
/// comes back into the basin of the model it left ([`back_in_basin`]) stops there and is
/// not kept. A bridge or adjustment that fails is reported and loses. Cost: one bridge and
/// one adjustment per escape, each linear in the observations per iteration as in [`fit`]
/// (the return test: one projection per observation after an accepted step within the
/// gate).
#[allow(clippy::too_many_arguments)]
fn escape(
    g: &Graph,
    norm: &Normalization,
    px: f64,
    fit: &mut ProjectiveFit,
    cfg: &ProjectiveConfig,
    run: usize,
    observer: &mut dyn Observer,
) {
    for &b in &cfg.escapes {
        let t0 = Instant::now();
        let (cams, pts) = normalized_start(&fit.model, norm);
        // Finite affine points for the bridge's parameterisation; a point at infinity is
        // pushed far along its direction (pOSE re-solves every point first).
        let mut x3 = Vec::with_capacity(3 * g.n_pts);
        for v in pts.chunks(4) {
            let w = if v[3].abs() > 1e-9 {
                v[3]
            } else {
                1e-9_f64.copysign(v[3])
            };
            x3.extend_from_slice(&[v[0] / w, v[1] / w, v[2] / w]);
        }
        let mut stages = Vec::new();
        let mut outcome = EscapeOutcome {
            bridge: b,
            from_rms_px: fit.rms_px,
            bridge_rms_px: f64::NAN,
            rms_px: f64::NAN,
            iterations: 0,
            seconds: 0.0,
            kept: false,
            returned: false,
        };
        // The model escaped from, for the test of a return to its basin.
        let left_cost = bundle::cost(&models::Projective, g, &cams, &pts, &[]);
        let left = predictions(g, &cams, &pts);
        let mut returned = |c: &[f64], x: &[f64], cost: f64| {
            outcome.returned = back_in_basin(g, &left, left_cost, c, x, cost);
            outcome.returned
        };
        let end = bridge(g, px, cams, x3, b, cfg, run, observer, &mut stages);
        let adjusted = end.ok().map(|(c, x)| {
            let cost = bundle::cost(&models::Projective, g, &c, &x, &[]);
            let bridge_rms_px = rms_of_cost(g, px, cost);
            let bridge_iterations = stages.iter().map(|s| s.iterations).sum();
            let f = bundle_adjust(
                g,
                norm,
                c,
                x,
                fit.start,
                stages,
                cfg,
                run,
                observer,
                Some(&mut returned),
            )
            .ok();
            (f, bridge_rms_px, bridge_iterations)
        });
        outcome.seconds = t0.elapsed().as_secs_f64();
        let adjusted = adjusted.and_then(|(f, rms, it)| {
            outcome.bridge_rms_px = rms;
            outcome.iterations = it;
            f
        });
        if let Some(mut f) = adjusted {
            outcome.rms_px = f.rms_px;
            outcome.iterations += f.report.iterations;
            if !outcome.returned && f.rms_px < fit.rms_px {
                outcome.kept = true;
                f.bridges = std::mem::take(&mut fit.bridges);
                f.escapes = std::mem::take(&mut fit.escapes);
                // The chain that led here: the stages escaped from, then this escape's.
                let mut chain = std::mem::take(&mut fit.stages);
                chain.append(&mut f.stages);
                f.stages = chain;
                *fit = f;
            }
        }
        fit.escapes.push(outcome);
    }
}

/// `π(P_f X_p)` at each observation of `g`, in its order (2 numbers per observation):
/// normalized cameras (12 each) and points (4 each).
fn predictions(g: &Graph, cams: &[f64], pts: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; 2 * g.n_obs()];
    for p in 0..g.n_pts {
        let x: &[f64; 4] = pts[4 * p..4 * p + 4].try_into().unwrap_or(&[0.0; 4]);
        for o in g.track(p) {
            let f = g.cam[o];
            let c: &[f64; 12] = cams[12 * f..12 * f + 12].try_into().unwrap_or(&[0.0; 12]);
            out[2 * o..2 * o + 2].copy_from_slice(&project(c, x));
        }
    }
    out
}

/// How near in cost an escape's adjustment must come to the model it left before
/// [`back_in_basin`] compares their predictions: this fraction of that model's cost. The
/// predictions of a model in its basin then differ by an RMS of at most `√(2·10⁻³)` ≈ 4.5 %
/// of its residuals' (0.02 px at 0.45 px), where the Gauss–Newton model of the minimum holds.
const RETURN_GATE: f64 = 1e-3;

/// Whether the model (`cams`, `pts`) of cost `cost` is back in the basin of the adjusted
/// model it escaped from (predictions `left`, cost `left_cost`), so that the adjustment
/// from it would end where that one did. Near a local minimum `b` of `E(x) = ‖P(x) − w‖²`,
/// `E(x) − E(b) = ‖P(x) − P(b)‖² + 2 (P(b) − w)ᵀ(P(x) − P(b))`, whose second term vanishes
/// to first order at a minimum (the residual is orthogonal to the model's tangent space):
/// in `b`'s basin and near it the excess cost is the predictions' squared distance (the
/// Gauss–Newton model of the minimum), while a model at the same cost in another basin
/// predicts differently by much more. The test: `0 ≤ E(x) − E(b) ≤` [`RETURN_GATE`]`·E(b)`
/// and `‖P(x) − P(b)‖² ≤ 2 (E(x) − E(b))`. A model below `b` never returns (it may end
/// lower); one whose predictions are farther than the quadratic model allows (a curved
/// valley, another basin) goes on, as it would without the test. Predictions are invariant
/// to the projective gauge, so the two models need no alignment. Cost: one projection per
/// observation, `O(#observations)`, once the cost is within the gate.
fn back_in_basin(
    g: &Graph,
    left: &[f64],
    left_cost: f64,
    cams: &[f64],
    pts: &[f64],
    cost: f64,
) -> bool {
    let excess = cost - left_cost;
    if !(excess >= 0.0 && excess <= RETURN_GATE * left_cost) {
        return false;
    }
    let d2: f64 = predictions(g, cams, pts)
        .iter()
        .zip(left)
        .map(|(a, b)| (a - b).powi(2))
        .sum();
    d2.is_finite() && d2 <= 2.0 * excess
}

/// Where [`bridges`] leaves the adjustment to start: cameras and points (projective
/// parameters), the bridges' outcomes, the run number the adjustment is reported under.
struct BridgeEnd {
    cams: Vec<f64>,
    pts: Vec<f64>,
    outcomes: Vec<BridgeOutcome>,
    run: usize,
}

/// [`bridge`] with [`ProjectiveConfig::bridge`] and, when set (and different),
/// [`ProjectiveConfig::second_bridge`] from the same affine start (reported as run
/// `run + 1`): the end of lower projective cost, the outcomes (empty with one bridge), and
/// the run number its adjustment is reported under. A bridge that fails or ends at a
/// non-finite cost loses; when both fail, the first's error.
#[allow(clippy::too_many_arguments)]
fn bridges(
    g: &Graph,
    px: f64,
    c: Vec<f64>,
    x: Vec<f64>,
    cfg: &ProjectiveConfig,
    run: usize,
    observer: &mut dyn Observer,
    stages: &mut Vec<StageReport>,
) -> Result<BridgeEnd> {
    let Some(second) = cfg.second_bridge.filter(|b| *b != cfg.bridge) else {
        let (cams, pts) = bridge(g, px, c, x, cfg.bridge, cfg, run, observer, stages)?;
        return Ok(BridgeEnd {
            cams,
            pts,
            outcomes: Vec::new(),
            run,
        });
    };
    let mut ends = Vec::with_capacity(2);
    for (b, r) in [(cfg.bridge, run), (second, run + 1)] {
        let t0 = Instant::now();
        let mut st = Vec::new();
        let out = bridge(g, px, c.clone(), x.clone(), b, cfg, r, observer, &mut st);
        let cost = out.as_ref().map_or(f64::NAN, |(cams, pts)| {
            bundle::cost(&models::Projective, g, cams, pts, &[])
        });
        let outcome = BridgeOutcome {
            bridge: b,
            start_rms_px: rms_of_cost(g, px, cost),
            iterations: st.iter().map(|s| s.iterations).sum(),
            seconds: t0.elapsed().as_secs_f64(),
            kept: false,
        };
        ends.push((out, st, outcome));
    }
    let second_wins = {
        let (a, b) = (ends[0].2.start_rms_px, ends[1].2.start_rms_px);
        b.is_finite() && !(a <= b)
    };
    let k = usize::from(second_wins);
    ends[k].2.kept = true;
    let outcomes: Vec<BridgeOutcome> = ends.iter().map(|e| e.2.clone()).collect();
    let (out, st, _) = ends.swap_remove(k);
    stages.extend(st);
    let (cams, pts) = out?;
    Ok(BridgeEnd {
        cams,
        pts,
        outcomes,
        run: run + k,
    })
}

/// From affine cameras (12 per frame, normalized coordinates) and points (3 per track) to
/// the projective parameterisation, through the pOSE stage when [`Bridge::Pose`].
#[allow(clippy::too_many_arguments)]
fn bridge(
    g: &Graph,
    px: f64,
    c: Vec<f64>,
    x: Vec<f64>,
    which: Bridge,
    cfg: &ProjectiveConfig,
    run: usize,
    observer: &mut dyn Observer,
    stages: &mut Vec<StageReport>,
) -> Result<(Vec<f64>, Vec<f64>)> {
    let (c, x) = match which {
        Bridge::Direct => (c, x),
        Bridge::Pose { eta } => {
            let (mut c, mut x) = (c, x);
            let stage = Stage {
                name: "pose",
                what: "pOSE",
                rms_scale: px,
            };
            stage.run(
                &models::Pose { eta },
                g,
                &mut c,
                &mut x,
                &mut [],
                &cfg.pose,
                run,
                observer,
                stages,
                None,
            )?;
            (c, x)
        }
    };
    // Projective parameters: unit-norm cameras and homogeneous points.
    let mut cams = c;
    for v in cams.chunks_mut(12) {
        bundle::normalize(v);
    }
    let mut pts = Vec::with_capacity(4 * g.n_pts);
    for p in 0..g.n_pts {
        let mut v = [x[3 * p], x[3 * p + 1], x[3 * p + 2], 1.0];
        bundle::normalize(&mut v);
        pts.extend_from_slice(&v);
    }
    Ok((cams, pts))
}

/// The long-tail stop of [`fit_observations`]' adjustment is never tighter than this
/// fraction of the cost per window ([`LmConfig::window_relative_tolerance`]): at 10 000
/// frames (3.3·10⁶ residuals) the adjustment lowers `χ²` by ~0.05 per solve for over 80
/// solves while the RMS moves in its seventh digit (docs/results.md), and each solve costs
/// seconds.
pub const LONG_TAIL_TOLERANCE: f64 = 1e-6;

/// One observation of a sparse track table: frame and track indices, pixel position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    pub frame: usize,
    pub track: usize,
    pub xy: [f64; 2],
}

/// Projective reconstruction of a sparse table of observations (`n_frames` frames,
/// `n_tracks` tracks), for long sequences: nothing is `O(F·N)`. The affine start comes
/// from overlapping windows of frames ([`windowed::affine_start`]), then the pOSE bridge and
/// the projective bundle adjustment as in [`fit`]. Time and memory are linear in the
/// observations for a fixed window and bounded track length (the reduced camera system of a
/// video is banded).
///
/// Errors: [`Error::InvalidConfig`] for indices out of range or a bad configuration,
/// [`Error::Degenerate`] for a repeated (frame, track) pair, a non-finite position or a
/// window that cannot be factorized or chained, [`Error::TooFew`] as in
/// [`check_observations`].
pub fn fit_observations(
    obs: &[Observation],
    n_frames: usize,
    n_tracks: usize,
    cfg: &ProjectiveConfig,
    windows: &windowed::WindowConfig,
    observer: &mut dyn Observer,
) -> Result<ProjectiveFit> {
    cfg.validate()?;
    let order = observation_order(obs, n_frames, n_tracks)?;
    let norm = Normalization::of_points(|| obs.iter().map(|o| o.xy));
    let g = observation_graph(obs, &order, n_frames, n_tracks, &norm);
    check_graph(&g)?;
    let px = 1.0 / norm.scale;
    let t0 = Instant::now();
    observer.on_event(&Event::StageStarted { stage: "windows" });
    let mut on_reference = false;
    let start = if windows.projective {
        let s = windowed::projective_start(&g, windows, cfg, px, observer)?;
        on_reference = s.on_reference;
        (s.cams, s.pts)
    } else {
        let (mut c, mut x) = windowed::affine_start(&g, windows)?;
        condition(&mut c, &mut x);
        (c, x)
    };
    let seconds = t0.elapsed().as_secs_f64();
    observer.on_event(&Event::StageFinished {
        stage: "windows",
        seconds,
    });
    let mut stages = vec![StageReport {
        stage: "windows".into(),
        status: SolverStatus::Converged,
        iterations: n_frames.div_ceil((windows.window - windows.overlap).max(1)),
        rms_before_px: f64::NAN,
        rms_after_px: f64::NAN,
        seconds,
        linear_solver: None,
        cg_iterations: 0,
    }];
    let (cams, pts) = if windows.projective {
        start
    } else {
        bridge(
            &g,
            px,
            start.0,
            start.1,
            cfg.bridge,
            cfg,
            0,
            observer,
            &mut stages,
        )?
    };
    // Started on the metric reference, the adjustment follows the chain's soft modes from
    // the reference's shape: geodesic acceleration (WindowConfig's setting). The long tail
    // stops at no less than LONG_TAIL_TOLERANCE of the cost.
    let mut refine = if on_reference {
        cfg.refine
            .or_geodesic(windows.reference_geodesic_acceleration)
    } else {
        cfg.refine.clone()
    };
    if refine.window_relative_tolerance > 0.0 {
        refine.window_relative_tolerance =
            refine.window_relative_tolerance.max(LONG_TAIL_TOLERANCE);
    }
    let cfg = &ProjectiveConfig {
        refine,
        ..cfg.clone()
    };
    bundle_adjust(
        &g,
        &norm,
        cams,
        pts,
        Start::Windows,
        stages,
        cfg,
        0,
        observer,
        None,
    )
}

/// Checks a list of observations of an `n_frames × n_tracks` table (indices in range,
/// finite positions, no (frame, track) pair twice) and returns their order by (track,
/// frame). `O(n log n)`.
///
/// Errors: [`Error::InvalidConfig`] for an index out of range, [`Error::Degenerate`] for
/// a non-finite position or a repeated pair.
pub(crate) fn observation_order(
    obs: &[Observation],
    n_frames: usize,
    n_tracks: usize,
) -> Result<Vec<usize>> {
    for o in obs {
        if o.frame >= n_frames || o.track >= n_tracks {
            return Err(Error::InvalidConfig {
                field: "observations",
                message: format!(
                    "observation of track {} in frame {} is outside the {n_frames}×{n_tracks} table",
                    o.track, o.frame
                ),
            });
        }
        if !(o.xy[0].is_finite() && o.xy[1].is_finite()) {
            return Err(Error::Degenerate(format!(
                "observed value of track {} in frame {} is not finite",
                o.track, o.frame
            )));
        }
    }
    let mut order: Vec<usize> = (0..obs.len()).collect();
    order.sort_unstable_by_key(|&i| (obs[i].track, obs[i].frame));
    if let Some(w) = order
        .windows(2)
        .find(|w| (obs[w[0]].track, obs[w[0]].frame) == (obs[w[1]].track, obs[w[1]].frame))
    {
        let o = obs[w[0]];
        return Err(Error::Degenerate(format!(
            "track {} is observed twice in frame {}",
            o.track, o.frame
        )));
    }
    Ok(order)
}

/// The camera–point graph of observations taken in `order` ([`observation_order`]), their
/// positions normalized by `norm`. `O(n)`.
pub(crate) fn observation_graph(
    obs: &[Observation],
    order: &[usize],
    n_frames: usize,
    n_tracks: usize,
    norm: &Normalization,
) -> Graph {
    let mut pt_ptr = vec![0usize; n_tracks + 1];
    for o in obs {
        pt_ptr[o.track + 1] += 1;
    }
    for p in 0..n_tracks {
        pt_ptr[p + 1] += pt_ptr[p];
    }
    Graph {
        n_cams: n_frames,
        n_pts: n_tracks,
        pt_ptr,
        cam: order.iter().map(|&i| obs[i].frame).collect(),
        w: order
            .iter()
            .map(|&i| {
                let o = obs[i];
                [
                    norm.scale * (o.xy[0] - norm.centre[0]),
                    norm.scale * (o.xy[1] - norm.centre[1]),
                ]
            })
            .collect(),
    }
}

/// The counts of [`check_observations`] on a graph.
pub(crate) fn check_graph(g: &Graph) -> Result<()> {
    let mut per_frame = vec![0usize; g.n_cams];
    for &c in &g.cam {
        per_frame[c] += 1;
    }
    let per_track: Vec<usize> = (0..g.n_pts).map(|p| g.track(p).len()).collect();
    check_counts(&per_frame, &per_track)
}

/// [`check_graph`] from the number of observations of each frame and of each track.
fn check_counts(per_frame: &[usize], per_track: &[usize]) -> Result<()> {
    if per_frame.len() < 2 {
        return Err(Error::TooFew {
            what: "frames for a projective reconstruction",
            needed: 2,
            have: per_frame.len(),
        });
    }
    if per_track.len() < 7 {
        return Err(Error::TooFew {
            what: "tracks for a projective reconstruction",
            needed: 7,
            have: per_track.len(),
        });
    }
    if let Some(&have) = per_frame.iter().min()
        && have < 6
    {
        return Err(Error::TooFew {
            what: "tracks seen in a frame (a projective camera has 11 degrees of freedom)",
            needed: 6,
            have,
        });
    }
    if let Some(&have) = per_track.iter().min()
        && have < 2
    {
        return Err(Error::TooFew {
            what: "frames observing a track",
            needed: 2,
            have,
        });
    }
    Ok(())
}

/// Centres and scales affine points to unit RMS (3 per track) and folds the map into the
/// cameras (12 per frame): the conditioning of [`affine_start`]. Untouched if degenerate.
fn condition(cams: &mut [f64], pts: &mut [f64]) {
    let np = pts.len() / 3;
    if np == 0 {
        return;
    }
    let mu: [f64; 3] =
        std::array::from_fn(|k| (0..np).map(|p| pts[3 * p + k]).sum::<f64>() / np as f64);
    let sigma = ((0..np)
        .map(|p| {
            (0..3)
                .map(|k| (pts[3 * p + k] - mu[k]).powi(2))
                .sum::<f64>()
        })
        .sum::<f64>()
        / np as f64)
        .sqrt();
    if !(sigma > 0.0 && sigma.is_finite()) {
        return;
    }
    for c in cams.chunks_mut(12) {
        for r in 0..3 {
            let shift: f64 = (0..3).map(|k| c[4 * r + k] * mu[k]).sum();
            c[4 * r + 3] += shift;
            for k in 0..3 {
                c[4 * r + k] *= sigma;
            }
        }
    }
    for p in 0..np {
        for k in 0..3 {
            pts[3 * p + k] = (pts[3 * p + k] - mu[k]) / sigma;
        }
    }
}

/// Projective bundle adjustment of `meas` from a given projective model (pixel
/// coordinates; `start.points` one per track of `meas`, `start.cameras` one per frame): the
/// last stage of [`fit`] alone, e.g. to refine a model from elsewhere or from the truth.
pub fn refine(
    meas: &Measurements,
    start: &ProjectiveModel,
    cfg: &ProjectiveConfig,
    run: usize,
    observer: &mut dyn Observer,
) -> Result<ProjectiveFit> {
    cfg.validate()?;
    check_observations(meas)?;
    check_start_size(start, meas.n_frames(), meas.n_points())?;
    let norm = Normalization::of(meas);
    let g = graph(meas, &norm);
    adjust_from(&g, &norm, start, cfg, run, observer)
}

/// [`refine`] for a sparse table of observations (`n_frames` frames, `n_tracks` tracks): the
/// projective bundle adjustment from a given model (`start.cameras` one per frame,
/// `start.points` one per track, pixel coordinates), e.g. the projective cameras
/// `K [R | t]` of a metric reconstruction. Cost and memory as [`fit_observations`]'s
/// adjustment: linear in the observations for a banded camera graph.
///
/// Errors: as [`fit_observations`] for the observations; [`Error::Dimension`] for a start
/// of the wrong size; [`Error::Degenerate`] for a non-finite start.
pub fn refine_observations(
    obs: &[Observation],
    n_frames: usize,
    n_tracks: usize,
    start: &ProjectiveModel,
    cfg: &ProjectiveConfig,
    observer: &mut dyn Observer,
) -> Result<ProjectiveFit> {
    cfg.validate()?;
    check_start_size(start, n_frames, n_tracks)?;
    if start.cameras.iter().flatten().any(|v| !v.is_finite())
        || start.points.iter().flatten().any(|v| !v.is_finite())
    {
        return Err(Error::Degenerate(
            "projective refine: the start model has a non-finite camera or point".into(),
        ));
    }
    let order = observation_order(obs, n_frames, n_tracks)?;
    let norm = Normalization::of_points(|| obs.iter().map(|o| o.xy));
    let g = observation_graph(obs, &order, n_frames, n_tracks, &norm);
    drop(order);
    check_graph(&g)?;
    adjust_from(&g, &norm, start, cfg, 0, observer)
}

/// [`Error::Dimension`] unless `start` has `n_frames` cameras and `n_tracks` points: the
/// start check of [`refine`] and [`refine_observations`].
fn check_start_size(start: &ProjectiveModel, n_frames: usize, n_tracks: usize) -> Result<()> {
    if start.cameras.len() != n_frames || start.points.len() != n_tracks {
        return Err(Error::Dimension {
            context: "projective refine: start model",
            expected: format!("{n_frames} cameras, {n_tracks} points"),
            got: format!(
                "{} cameras, {} points",
                start.cameras.len(),
                start.points.len()
            ),
        });
    }
    Ok(())
}

/// The projective bundle adjustment of the graph `g` (normalized by `norm`) from a given
/// pixel-coordinate model: the common last step of [`refine`] and [`refine_observations`].
fn adjust_from(
    g: &Graph,
    norm: &Normalization,
    start: &ProjectiveModel,
    cfg: &ProjectiveConfig,
    run: usize,
    observer: &mut dyn Observer,
) -> Result<ProjectiveFit> {
    let (cams, pts) = normalized_start(start, norm);
    bundle_adjust(
        g,
        norm,
        cams,
        pts,
        Start::Given,
        Vec::new(),
        cfg,
        run,
        observer,
        None,
    )
}

/// A pixel-coordinate model in `norm`'s coordinates, cameras (12 each) and points (4 each)
/// on their unit spheres: the start of [`adjust_from`].
fn normalized_start(start: &ProjectiveModel, norm: &Normalization) -> (Vec<f64>, Vec<f64>) {
    let mut cams = Vec::with_capacity(12 * start.cameras.len());
    for c in &start.cameras {
        let mut n = norm.camera_to_normalized(c);
        bundle::normalize(&mut n);
        cams.extend(n);
    }
    let mut pts = Vec::with_capacity(4 * start.points.len());
    for x in &start.points {
        let mut v = *x;
        bundle::normalize(&mut v);
        pts.extend_from_slice(&v);
    }
    (cams, pts)
}

/// The projective bundle adjustment stage shared by [`fit`] and [`refine`]: cameras and
/// points in normalized coordinates on their unit spheres.
#[allow(clippy::too_many_arguments)]
fn bundle_adjust(
    g: &Graph,
    norm: &Normalization,
    mut cams: Vec<f64>,
    mut pts: Vec<f64>,
    start: Start,
    mut stages: Vec<StageReport>,
    cfg: &ProjectiveConfig,
    run: usize,
    observer: &mut dyn Observer,
    stop: Option<&mut bundle::StopTest<'_>>,
) -> Result<ProjectiveFit> {
    let px = 1.0 / norm.scale;
    let stage = Stage {
        name: "projective-ba",
        what: "projective bundle adjustment",
        rms_scale: px,
    };
    let r = stage.run(
        &models::Projective,
        g,
        &mut cams,
        &mut pts,
        &mut [],
        &cfg.refine,
        run,
        observer,
        &mut stages,
        stop,
    )?;
    let rms_px = rms_of_cost(g, px, r.report.final_cost);
    let model = to_pixels(&cams, &pts, g, norm);
    Ok(ProjectiveFit {
        model,
        rms_px,
        start,
        stages,
        report: r.report,
        schur_nnz: r.schur_nnz,
        bridges: Vec::new(),
        escapes: Vec::new(),
    })
}

/// One solver stage of the chain: its events, its run of [`bundle::minimize`] and its
/// [`StageReport`] (RMS before and after: `rms_scale` × `sqrt(cost / #observed scalars)`,
/// `rms_scale` = pixels per normalized unit).
pub(crate) struct Stage {
    /// Stage and solver name in events and reports.
    pub name: &'static str,
    /// Stage name in a numerical error.
    pub what: &'static str,
    pub rms_scale: f64,
}

impl Stage {
    /// Runs [`bundle::minimize_shared`] with `stop`, the caller's stopping test
    /// ([`Progress::stop`]; `None`: none), and pushes the stage's report.
    #[allow(clippy::too_many_arguments)]
    pub fn run<M: bundle::BundleModel>(
        &self,
        model: &M,
        g: &Graph,
        cams: &mut [f64],
        pts: &mut [f64],
        glob: &mut [f64],
        cfg: &LmConfig,
        run: usize,
        observer: &mut dyn Observer,
        stages: &mut Vec<StageReport>,
        stop: Option<&mut bundle::StopTest<'_>>,
    ) -> Result<bundle::LmResult> {
        let rms = |cost: f64| rms_of_cost(g, self.rms_scale, cost);
        let t0 = Instant::now();
        observer.on_event(&Event::StageStarted { stage: self.name });
        let before = rms(bundle::cost(model, g, cams, pts, glob));
        let r = bundle::minimize_shared(
            model,
            g,
            cams,
            pts,
            glob,
            &[],
            cfg,
            &mut Progress {
                observer: &mut *observer,
                name: self.name,
                run,
                // The engine divides by its residual count (m per observation).
                rms_scale: self.rms_scale * (model.res_dim() as f64 / 2.0).sqrt(),
                stop: stop.map(|s| &mut *s as &mut bundle::StopTest<'_>),
            },
        )
        .map_err(|message| Error::Numerical {
            stage: self.what,
            message,
        })?;
        let seconds = t0.elapsed().as_secs_f64();
        observer.on_event(&Event::StageFinished {
            stage: self.name,
            seconds,
        });
        stages.push(StageReport {
            stage: self.name.into(),
            status: r.report.status,
            iterations: r.report.iterations,
            rms_before_px: before,
            rms_after_px: rms(r.report.final_cost),
            seconds,
            linear_solver: Some(r.linear_solver),
            cg_iterations: r.cg_iterations,
        });
        Ok(r)
    }
}

/// `P_f = T [M_f t_f; 0 0 0 1] H`, `X_p = H⁻¹ (s_p, 1)` with `H` centring and scaling the
/// affine points to unit RMS ([`condition`]), in normalized image coordinates. Returns
/// (cameras 12 per frame, points 3 per track: the pOSE parameterisation).
fn affine_start(a: &AffineStart<'_>, norm: &Normalization) -> (Vec<f64>, Vec<f64>) {
    let (nf, np) = (a.m.nrows() / 2, a.s.ncols());
    let mut cams = Vec::with_capacity(12 * nf);
    for f in 0..nf {
        let mut c = [0.0; 12];
        for r in 0..2 {
            for k in 0..3 {
                c[4 * r + k] = a.m[(2 * f + r, k)];
            }
            c[4 * r + 3] = a.t[2 * f + r];
        }
        c[11] = 1.0;
        cams.extend(norm.camera_to_normalized(&c));
    }
    let mut pts: Vec<f64> = (0..np)
        .flat_map(|p| (0..3).map(move |k| (p, k)))
        .map(|(p, k)| a.s[(k, p)])
        .collect();
    condition(&mut cams, &mut pts);
    (cams, pts)
}

/// Cameras to pixels, unit norms, and the sign convention of [`ProjectiveModel`].
fn to_pixels(cams: &[f64], pts: &[f64], g: &Graph, norm: &Normalization) -> ProjectiveModel {
    let mut cameras: Vec<[f64; 12]> = cams
        .chunks(12)
        .map(|c| {
            let mut p = norm.camera_to_pixels(c);
            bundle::normalize(&mut p);
            p
        })
        .collect();
    let mut points: Vec<[f64; 4]> = pts
        .chunks(4)
        .map(|x| {
            let mut v = [x[0], x[1], x[2], x[3]];
            bundle::normalize(&mut v);
            v
        })
        .collect();
    let depth =
        |c: &[f64; 12], x: &[f64; 4]| c[8] * x[0] + c[9] * x[1] + c[10] * x[2] + c[11] * x[3];
    // Points: positive depth in the majority of their frames; then cameras likewise.
    for p in 0..g.n_pts {
        let neg = g
            .track(p)
            .filter(|&o| depth(&cameras[g.cam[o]], &points[p]) < 0.0)
            .count();
        if 2 * neg > g.track(p).len() {
            points[p].iter_mut().for_each(|v| *v = -*v);
        }
    }
    let mut neg = vec![0isize; g.n_cams];
    for p in 0..g.n_pts {
        for o in g.track(p) {
            let f = g.cam[o];
            neg[f] += if depth(&cameras[f], &points[p]) < 0.0 {
                1
            } else {
                -1
            };
        }
    }
    for (f, c) in cameras.iter_mut().enumerate() {
        if neg[f] > 0 {
            c.iter_mut().for_each(|v| *v = -*v);
        }
    }
    ProjectiveModel { cameras, points }
}

#[cfg(test)]
mod tests;
