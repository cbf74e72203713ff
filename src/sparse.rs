//! The sparse pipeline: tables whose dense `2F×N` matrix does not fit (a long video with
//! short tracks, a huge table) or that are long sequences of short tracks are reconstructed
//! with memory linear in the observations (docs/math.md §13).
//!
//! # Objective
//!
//! The scaled orthographic (orthographic: `s_f ≡ 1`) reprojection error over the observed
//! entries — the dense pipeline's metric objective:
//!
//! ```text
//!   minimise over R_f ∈ SO(3), s_f, t_f, X_p:  Σ_{(f,p) observed} ‖s_f R_f[1:2] X_p + t_f − w_fp‖²,
//! ```
//!
//! in coordinates centred on the observations' mean and (not for the orthographic camera)
//! scaled to unit RMS spread, undone on output.
//!
//! # Method
//!
//! 1. **Start** ([`SparseProblem::start`]): overlapping windows of frames, each completed by
//!    the dense damped Wiberg solver (a window is small; runs of consecutive windows in
//!    parallel, each window started from the one before it), upgraded
//!    to metric on its own and chained by similarities over the tracks they share; a window
//!    that does not fit is restarted, then bridged by an affine map. Linear in the frames.
//!    (Chaining affine windows and upgrading once does not work on long sequences: the
//!    affine chain drifts by shear and stretch that one `L = QQᵀ` cannot undo.)
//! 2. **Adjustment**: the sparse Levenberg–Marquardt engine of
//!    [`crate::projective::bundle`] with the [`ScaledOrthographic`] residual — rotations on
//!    SO(3), points eliminated by the Schur complement and re-solved after every camera step
//!    (variable projection), the reduced camera system (6 unknowns per frame) banded for a
//!    video and factorised by sparse Cholesky, `O(F b² 6³)` for a half-bandwidth of `b`
//!    frames. The 7-dimensional similarity gauge is held by springs on frames 0 and 1.
//!    Small damping from the start, and each accepted step extended along its path while
//!    the cost keeps falling (docs/math.md §13, "Damping and extension along the path").
//! 3. **Outlier tracks**: when the adjustment converged, a track whose RMS residual exceeds
//!    [`SparseConfig::outlier_sigmas`] robust standard deviations of all residuals (and
//!    [`SparseConfig::min_outlier_px`]) is rejected whole and the fit is repeated once from
//!    the current cameras — the linear-cost substitute for the dense RANSAC pass. A
//!    rejection that would starve a frame is not made (reported in [`SparseFit::note`]).
//! 4. **Output**: the metric model (cameras in pixels, points re-triangulated per track),
//!    and a metric upgrade of its camera rows as a check (`Q ≈ I`).
//!
//! # Complexity
//!
//! Memory: the table (24 bytes per observation), the graph (24), the windows' dense
//! measurements during the start, and the engine's per-observation blocks (the residual
//! and the tangent-space Jacobians, 2×6 camera and 2×3 point: 160 bytes), plus the
//! non-zeros of the reduced camera system and its factor (`O(F b 36)`); nothing is
//! `O(F·N)` or `O(F²)`. Time: the window fits, linear in the frames, then per iteration
//! linear in the observations plus the banded factorisation. The number of iterations
//! still grows on long sequences (docs/results.md).
//!
//! # References
//!
//! * C. Tomasi and T. Kanade, "Shape and motion from image streams under orthography: a
//!   factorization method", IJCV 9(2), 1992.
//! * T. Okatani and K. Deguchi, "On the Wiberg algorithm for matrix factorization in the
//!   presence of missing components", IJCV 72(3), 2007.
//! * J. H. Hong, C. Zach and A. Fitzgibbon, "Revisiting the variable projection method for
//!   separable nonlinear least squares problems", CVPR 2017.
//! * B. Triggs, P. McLauchlan, R. Hartley and A. Fitzgibbon, "Bundle adjustment — a modern
//!   synthesis", 1999 (the Schur complement).
//! * S. Umeyama, "Least-squares estimation of transformation parameters between two point
//!   patterns", PAMI 13(4), 1991 (the windows' similarities).

use faer::Mat;
use nalgebra::{Matrix3, Rotation3, Vector2, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::projective::bundle::{self, BundleModel, Graph, Jacobians, LmConfig, Progress};
use crate::projective::windowed::{self, WindowConfig};
use crate::table::TrackTable;
use crate::{CameraModel, Error, MetricModel, Observer, Result, SolverReport};

/// Which pipeline runs: the dense one (every stage, `O(F·N)` memory) or the sparse one.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Pipeline {
    /// Sparse when the dense `2F×N` matrix exceeds both
    /// [`crate::budget::DENSE_TABLE_BYTES`] and [`crate::budget::DENSE_TABLE_FACTOR`] times
    /// the observations' own size, or when the table is a long sequence of short tracks
    /// (≥ 60 frames, < 25 % filled) and the camera is not perspective;
    /// dense otherwise (the default).
    #[default]
    Auto,
    /// Always the dense pipeline (an input too large for it is a typed error).
    Dense,
    /// Always the sparse pipeline.
    Sparse,
}

/// Settings of the sparse pipeline. Every field has a documented default.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct SparseConfig {
    /// Which pipeline runs. Default [`Pipeline::Auto`].
    pub pipeline: Pipeline,
    /// The windowed start. Default: windows of 40 frames overlapping by 20, affine chaining
    /// (`projective: false`), each window's completion stopped at a relative cost decrease
    /// of 1e-4 (the adjustment refines every window; the start's RMS moves by 5·10⁻⁵ of
    /// itself and the windows take a third less time than at 1e-10, docs/results.md).
    pub window: WindowConfig,
    /// The variable-projection adjustment. Default: [`LmConfig::default`] with at most 100
    /// solves, a relative cost tolerance of 1e-10 and geodesic acceleration (`α = 0.75`:
    /// the long corridors' tails of rejected steps along their soft modes shrink from 58 to
    /// 17 solves at 5 000 frames, to the same RMS; docs/results.md), and a small damping
    /// from the start: initial `λ = 10⁻⁸`, divided by 20 after each good step. The start
    /// is every window at its own optimum, so what is left is the chain's long-range
    /// bending, whose curvature is 10⁻⁸ of the diagonal and less; the default damping
    /// (10⁻⁴, divided by 5) blocked those modes until it had decayed, for 8–10 steps of
    /// little gain. Measured on the corridors of `sparse_scaling`, to the same or a lower
    /// RMS: 16 → 8 solves at 5 000 frames; 20 → 13 solves (337 → 252 s) at 20 000 frames
    /// (docs/results.md). Each accepted step is extended along its path while the cost
    /// keeps falling, at most 6 extra cost evaluations (`extension_trials`): Gauss–Newton
    /// converges only linearly along those modes (docs/math.md §13).
    pub lm: LmConfig,
    /// Reject a track whose RMS residual exceeds this many robust standard deviations
    /// (1.4826 × the median absolute residual) of all residuals. Default 4. `f64::INFINITY`
    /// keeps every track.
    pub outlier_sigmas: f64,
    /// ... and exceeds this many pixels. Default 2 (as the dense pass's track floor).
    pub min_outlier_px: f64,
    /// Largest RMS distance, relative to their spread, between a window's shared points
    /// and the points already placed after the best similarity, for the window to be
    /// chained. Default 0.1 (windows that fit leave 1–3 %).
    pub max_window_mismatch: f64,
    /// Random restarts of a window's completion when it ended in a local minimum (see
    /// `window_rms_ratio`). Default 4.
    pub window_restarts: usize,
    /// A window whose completion's RMS exceeds this many times the median window's is
    /// taken for a local minimum and completed again from random starts. Default 1.5
    /// (windows at the optimum are within 5 % of the median on the synthetic corridors;
    /// local minima 2.5×).
    pub window_rms_ratio: f64,
    /// Start each window's completion from the window before it — the frames both windows
    /// hold keep its cameras, each new frame is resected from its points by linear least
    /// squares — rather than from the window's own data-driven start (row means, SVD and
    /// hard-impute sweeps, far from the optimum: a 100-frame corridor's window starts at
    /// 2 000× its optimal cost from there, at 1.75× from its neighbour). The windows are
    /// then fitted as `4 × threads` runs of consecutive windows, the runs in parallel; a
    /// window whose warm start cannot be built or fails starts cold. Measured on the
    /// 20 000-frame corridor (10⁷ observations, 2 threads, back to back): 13.9 → 5.6
    /// Wiberg iterations per window, the restarts of windows left in local minima 7.3 →
    /// 0.1 s, the start 58 → 25 s, the whole run 139 → 99 s, the same final RMS to
    /// 10⁻⁸ (docs/results.md). Default true.
    pub warm_windows: bool,
}

impl Default for SparseConfig {
    fn default() -> Self {
        Self {
            pipeline: Pipeline::Auto,
            window: WindowConfig {
                projective: false,
                completion: crate::completion::CompletionConfig {
                    function_tolerance: 1e-4,
                    ..Default::default()
                },
                ..WindowConfig::default()
            },
            lm: LmConfig {
                max_iterations: 100,
                function_tolerance: 1e-10,
                geodesic_acceleration: 0.75,
                initial_lambda: 1e-8,
                lambda_decrease: 20.0,
                extension_trials: 6,
                ..LmConfig::default()
            },
            outlier_sigmas: 4.0,
            min_outlier_px: 2.0,
            max_window_mismatch: 0.1,
            window_restarts: 4,
            window_rms_ratio: 1.5,
            warm_windows: true,
        }
    }
}

/// What the sparse pipeline did, in `reconstruction.json` (`sparse`).
#[derive(Debug, Clone, Serialize)]
pub struct SparseReport {
    /// Why the sparse pipeline ran.
    pub reason: String,
    /// Observations fitted.
    pub observations: usize,
    /// The variable-projection adjustment of the final round.
    pub status: crate::SolverStatus,
    pub iterations: usize,
    /// RMS of the affine fit over observed scalars, pixels.
    pub rms_px: f64,
    /// Non-zeros of the reduced camera system (lower triangle).
    pub schur_nonzeros: usize,
    /// Of `iterations`, the accepted steps extended along their path
    /// (`LmConfig::extension_trials`).
    pub extensions: usize,
    /// Rounds of fit + outlier rejection (1 or 2).
    pub rounds: usize,
    /// Windows of the start that did not fit and were skipped.
    pub skipped_windows: usize,
    pub seconds: f64,
}

/// The scaled orthographic camera residual `r = s R₁₂ x + t − w` for the sparse engine
/// (orthographic: `s ≡ 1`). Camera stored as `[R (9, row-major), s, t (2)]` with `R` on
/// SO(3) (tangent `R [δ]ₓ`, re-orthonormalised after each step), point `x ∈ R³`: 6 (5)
/// tangent parameters per camera, 3 per point.
#[derive(Debug, Clone, Copy)]
pub struct ScaledOrthographic {
    /// Whether the scale is a parameter (false: orthographic, `s` stays as given).
    pub scaled: bool,
    /// Whether each camera carries its pivot `c` (stored after `t`, constant): the residual
    /// is then `s R₁₂ (x − c) + t − w`, so that a rotation step turns the camera about the
    /// points it sees rather than about the world origin (see [`SparseProblem::adjust`]).
    pub pivoted: bool,
}

impl ScaledOrthographic {
    /// `R [e_k]ₓ` flattened (row-major), the rotation's tangent direction `k`.
    fn rot_dir(c: &[f64], k: usize) -> [f64; 9] {
        let mut e = [[0.0; 3]; 3];
        // [e_k]ₓ
        let (a, b) = ((k + 1) % 3, (k + 2) % 3);
        e[a][b] = -1.0;
        e[b][a] = 1.0;
        let mut out = [0.0; 9];
        for i in 0..3 {
            for j in 0..3 {
                out[3 * i + j] = (0..3).map(|m| c[3 * i + m] * e[m][j]).sum();
            }
        }
        out
    }
}

impl BundleModel for ScaledOrthographic {
    fn cam_len(&self) -> usize {
        if self.pivoted { 15 } else { 12 }
    }
    fn cam_dim(&self) -> usize {
        if self.scaled { 6 } else { 5 }
    }
    fn pt_len(&self) -> usize {
        3
    }
    fn pt_dim(&self) -> usize {
        3
    }
    fn res_dim(&self) -> usize {
        2
    }

    #[inline]
    fn eval(
        &self,
        c: &[f64],
        x: &[f64],
        _glob: &[f64],
        w: [f64; 2],
        r: &mut [f64],
        jac: Option<Jacobians<'_>>,
    ) {
        let s = c[9];
        let x = if self.pivoted {
            [x[0] - c[12], x[1] - c[13], x[2] - c[14]]
        } else {
            [x[0], x[1], x[2]]
        };
        let a = c[0] * x[0] + c[1] * x[1] + c[2] * x[2];
        let b = c[3] * x[0] + c[4] * x[1] + c[5] * x[2];
        r[0] = s * a + c[10] - w[0];
        r[1] = s * b + c[11] - w[1];
        if let Some(Jacobians {
            cam: jc, pt: jp, ..
        }) = jac
        {
            jc.fill(0.0);
            let n = self.cam_len();
            for k in 0..3 {
                jc[k] = s * x[k];
                jc[n + 3 + k] = s * x[k];
                jp[k] = s * c[k];
                jp[3 + k] = s * c[3 + k];
            }
            jc[9] = a;
            jc[n + 9] = b;
            jc[10] = 1.0;
            jc[n + 11] = 1.0;
        }
    }

    /// `s R₁₂ (x − c) + t − w` is affine in `x`.
    fn points_linear(&self) -> bool {
        true
    }

    fn cam_basis(&self, cam: &[f64], out: &mut [f64]) -> bool {
        let d = self.cam_dim();
        out[..self.cam_len() * d].fill(0.0);
        for k in 0..3 {
            let v = Self::rot_dir(cam, k);
            for i in 0..9 {
                out[i * d + k] = v[i];
            }
        }
        let mut col = 3;
        if self.scaled {
            out[9 * d + col] = 1.0;
            col += 1;
        }
        out[10 * d + col] = 1.0;
        out[11 * d + col + 1] = 1.0;
        true
    }

    fn normalize_cam(&self, cam: &mut [f64]) {
        crate::perspective::models::orthonormalize(&mut cam[..9]);
    }

    /// The similarity gauge `x ↦ c A x + b`: every direction of camera 0, and for camera 1
    /// the translation of the world along camera 0's viewing axis `k₀` (which camera 0
    /// does not see): `t₁ ↦ t₁ − s₁ R₁₂ k₀`.
    fn gauge_pins(&self, cams: &[f64], n_cams: usize) -> Vec<(usize, Vec<Vec<f64>>)> {
        if n_cams < 2 {
            return Vec::new();
        }
        let n = self.cam_len();
        let mut all: Vec<Vec<f64>> = (0..3)
            .map(|k| {
                let mut v = vec![0.0; n];
                v[..9].copy_from_slice(&Self::rot_dir(&cams[..n], k));
                v
            })
            .collect();
        let unit = |i: usize| (0..n).map(|j| if i == j { 1.0 } else { 0.0 }).collect();
        if self.scaled {
            all.push(unit(9));
        }
        all.push(unit(10));
        all.push(unit(11));
        let k0 = [cams[6], cams[7], cams[8]];
        let c1 = &cams[n..2 * n];
        let mut v = vec![0.0; n];
        for r in 0..2 {
            v[10 + r] = c1[9] * (0..3).map(|k| c1[3 * r + k] * k0[k]).sum::<f64>();
        }
        vec![(0, all), (1, vec![v])]
    }
}

/// The centroid `c` of `points` and their RMS spread per coordinate, `σ = sqrt(Σ ‖w − c‖² /
/// 2n)` — or 1 when `normalize_scale` is false or the spread is zero or not finite: the
/// normalization `(w − c) / σ` of the sparse engine's scaled orthographic problems.
/// `points()` is iterated twice. `O(n)`.
pub(crate) fn centre_and_spread<I: Iterator<Item = [f64; 2]>>(
    points: impl Fn() -> I,
    normalize_scale: bool,
) -> ([f64; 2], f64) {
    let (mut n, mut cx, mut cy) = (0usize, 0.0, 0.0);
    for q in points() {
        n += 1;
        cx += q[0];
        cy += q[1];
    }
    let n = n.max(1) as f64;
    let centre = [cx / n, cy / n];
    let ss: f64 = points()
        .map(|q| (q[0] - centre[0]).powi(2) + (q[1] - centre[1]).powi(2))
        .sum();
    let scale = (ss / (2.0 * n)).sqrt();
    let scale = if normalize_scale && scale > 0.0 && scale.is_finite() {
        scale
    } else {
        1.0
    };
    (centre, scale)
}

/// A table as the sparse engine's graph, in normalized coordinates `(w − centre) / scale`.
pub struct SparseProblem {
    pub graph: Graph,
    pub centre: [f64; 2],
    pub scale: f64,
}

impl SparseProblem {
    /// The observations of `table`, by track, centred, and scaled to unit RMS spread when
    /// `normalize_scale` (not for the orthographic camera, whose unit scale is in pixels).
    /// `O(n_obs)`.
    pub fn new(table: &TrackTable, normalize_scale: bool) -> Self {
        let (centre, scale) = centre_and_spread(
            || {
                (0..table.n_frames())
                    .flat_map(|f| table.frame_row(f).entries())
                    .map(|e| [e.x, e.y])
            },
            normalize_scale,
        );
        Self::with_normalization(table, centre, scale)
    }

    /// The observations of `table`, by track, as `(w − centre) / scale`. `O(n_obs)`.
    pub fn with_normalization(table: &TrackTable, centre: [f64; 2], scale: f64) -> Self {
        let (ptr, obs) = table.by_track();
        let graph = Graph {
            n_cams: table.n_frames(),
            n_pts: table.n_tracks(),
            pt_ptr: ptr,
            cam: obs.iter().map(|o| o.0 as usize).collect(),
            w: obs
                .iter()
                .map(|&(_, x, y)| [(x - centre[0]) / scale, (y - centre[1]) / scale])
                .collect(),
        };
        Self {
            graph,
            centre,
            scale,
        }
    }

    /// The windowed metric start: cameras (12 per frame, see [`ScaledOrthographic`]) and
    /// points (3 per track).
    ///
    /// Each window of frames is completed (dense damped Wiberg, small; runs of consecutive
    /// windows in parallel, each window warm-started from the one before it, see
    /// [`SparseConfig::warm_windows`]), upgraded to metric on its own
    /// ([`crate::metric::upgrade`]); a window whose
    /// completion ended in a local minimum (its RMS over
    /// [`SparseConfig::window_rms_ratio`] times the median window's) is completed again from
    /// up to [`SparseConfig::window_restarts`] random starts. Then, in order, each window is
    /// mapped into window 0's frame by the similarity `X = c A x + b` (reflection allowed:
    /// each window has its own depth reversal) that best carries its points onto the tracks
    /// already placed (Umeyama, ≥ 4 shared tracks). A window whose similarity leaves the
    /// shared points off by more than [`SparseConfig::max_window_mismatch`] of their spread
    /// (its motion is too weak for its own metric upgrade, or no start found its optimum)
    /// is skipped and counted: when the next window begins at or before its first frame not
    /// yet placed, that window places its frames; otherwise its new frames are bridged by
    /// an affine map onto the placed points (`affine_bridge`, only approximately metric).
    /// The similarity is anchored on the shared tracks seen in at least
    /// [`WindowConfig::min_anchor_observations`](crate::projective::windowed::WindowConfig)
    /// frames of both windows (a track seen in two or three frames of a window has a
    /// poorly determined depth there; with every shared track, a 2 000-frame corridor's
    /// start was 3 395 px RMS, with the rule 0.51 px).
    ///
    /// Why metric windows: a chain of affine windows accumulates shear and stretch that no
    /// global metric upgrade undoes, and mapping windows affinely onto metric points loses
    /// the depth of thin scenes (start RMS 70 px and 720 px at 300 frames against 1–5 px;
    /// docs/results.md). Linear in the frames.
    pub fn start(
        &self,
        cfg: &SparseConfig,
        camera: CameraModel,
    ) -> Result<(Vec<f64>, Vec<f64>, usize)> {
        start_windows(&self.graph, cfg, camera)
    }

    /// Variable-projection adjustment from `(cams, pts)` (updated in place).
    pub fn adjust(
        &self,
        cams: &mut [f64],
        pts: &mut [f64],
        cfg: &SparseConfig,
        camera: CameraModel,
        run: usize,
        observer: &mut dyn Observer,
    ) -> Result<bundle::LmResult> {
        let mut progress = Progress {
            observer,
            name: "sparse-varpro",
            run,
            rms_scale: self.scale,
            stop: None,
        };
        let model = ScaledOrthographic {
            scaled: camera != CameraModel::Orthographic,
            pivoted: true,
        };
        let mut pivoted = self.pivot(cams, pts);
        let result = bundle::minimize(
            &model,
            &self.graph,
            &mut pivoted,
            pts,
            &cfg.lm,
            &mut progress,
        )
        .map_err(|message| Error::Numerical {
            stage: "sparse variable projection",
            message,
        });
        for (c, p) in cams.chunks_exact_mut(12).zip(pivoted.chunks_exact(15)) {
            c.copy_from_slice(&p[..12]);
            // t = t' − s R₁₂ c.
            for r in 0..2 {
                c[10 + r] -= p[9] * (0..3).map(|k| p[3 * r + k] * p[12 + k]).sum::<f64>();
            }
        }
        result
    }

    /// The cameras with their pivots: `c_f` the mean of the points frame `f` sees, and
    /// `t' = t + s R₁₂ c_f` so that every projection is unchanged. `O(n_obs)`.
    ///
    /// Why: a video's world frame is its first window's, so a camera a thousand frames on
    /// sees points far from the origin. A rotation step about the origin then moves its
    /// projections by `s |x| |δ|` and its second-order error `s |x| |δ|²/2` grows with
    /// the distance travelled — the gain ratio of the damped steps falls, the damping
    /// stays high and the adjustment creeps. Turning each camera about its own points
    /// removes that lever arm (the model is the same; only its coordinates change).
    fn pivot(&self, cams: &[f64], pts: &[f64]) -> Vec<f64> {
        let g = &self.graph;
        let mut sum = vec![[0.0f64; 4]; g.n_cams];
        for p in 0..g.n_pts {
            for o in g.pt_ptr[p]..g.pt_ptr[p + 1] {
                let acc = &mut sum[g.cam[o]];
                for k in 0..3 {
                    acc[k] += pts[3 * p + k];
                }
                acc[3] += 1.0;
            }
        }
        let mut out = vec![0.0; 15 * g.n_cams];
        for (f, (o, c)) in out
            .chunks_exact_mut(15)
            .zip(cams.chunks_exact(12))
            .enumerate()
        {
            o[..12].copy_from_slice(c);
            let n = sum[f][3].max(1.0);
            for k in 0..3 {
                o[12 + k] = sum[f][k] / n;
            }
            for r in 0..2 {
                o[10 + r] += c[9] * (0..3).map(|k| c[3 * r + k] * o[12 + k]).sum::<f64>();
            }
        }
        out
    }

    /// The residual of observation `o` (of track `p`), normalized units.
    #[inline]
    fn residual(&self, cams: &[f64], pts: &[f64], p: usize, o: usize) -> [f64; 2] {
        let g = &self.graph;
        let mut r = [0.0; 2];
        ScaledOrthographic {
            scaled: true,
            pivoted: false,
        }
        .eval(
            &cams[12 * g.cam[o]..12 * g.cam[o] + 12],
            &pts[3 * p..3 * p + 3],
            &[],
            g.w[o],
            &mut r,
            None,
        );
        r
    }

    /// Per track, the sum of squared residuals (normalized units).
    pub fn track_costs(&self, cams: &[f64], pts: &[f64]) -> Vec<f64> {
        (0..self.graph.n_pts)
            .map(|p| {
                self.graph
                    .track(p)
                    .map(|o| {
                        let r = self.residual(cams, pts, p, o);
                        r[0] * r[0] + r[1] * r[1]
                    })
                    .sum()
            })
            .collect()
    }

    /// Robust standard deviation of one residual scalar, pixels: 1.4826 × the median of
    /// `|r|` over every observed scalar (selection in `O(n_obs)`).
    pub fn robust_sigma_px(&self, cams: &[f64], pts: &[f64]) -> f64 {
        let g = &self.graph;
        let mut abs = Vec::with_capacity(2 * g.n_obs());
        for p in 0..g.n_pts {
            for o in g.track(p) {
                let r = self.residual(cams, pts, p, o);
                abs.push(r[0].abs());
                abs.push(r[1].abs());
            }
        }
        if abs.is_empty() {
            return 0.0;
        }
        let mid = abs.len() / 2;
        let (_, m, _) = abs.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
        1.4826 * *m * self.scale
    }

    /// The metric model in pixels: cameras `s R`, `t` scaled back (`s·scale`,
    /// `t·scale + centre`), points unchanged.
    pub fn metric_model(&self, cams: &[f64], pts: &[f64]) -> MetricModel {
        let (nf, np) = (self.graph.n_cams, self.graph.n_pts);
        MetricModel {
            rotations: (0..nf)
                .map(|f| {
                    Rotation3::from_matrix_unchecked(Matrix3::from_row_slice(
                        &cams[12 * f..12 * f + 9],
                    ))
                })
                .collect(),
            scales: (0..nf).map(|f| cams[12 * f + 9] * self.scale).collect(),
            translations: (0..nf)
                .map(|f| {
                    Vector2::new(
                        cams[12 * f + 10] * self.scale + self.centre[0],
                        cams[12 * f + 11] * self.scale + self.centre[1],
                    )
                })
                .collect(),
            points: (0..np)
                .map(|p| Vector3::new(pts[3 * p], pts[3 * p + 1], pts[3 * p + 2]))
                .collect(),
            aspect: 1.0,
        }
    }

    /// The inverse of [`Self::metric_model`]: the cameras of `model`'s frames `frames[i]`
    /// (camera `i` of the graph; 12 per frame, normalized units) and its points `tracks[k]`
    /// (3 per track). Square pixels assumed. For starting an adjustment at a known model
    /// (e.g. a synthetic scene's truth).
    pub fn cams_and_points(
        &self,
        model: &MetricModel,
        frames: &[usize],
        tracks: &[usize],
    ) -> (Vec<f64>, Vec<f64>) {
        let mut cams = vec![0.0; 12 * frames.len()];
        for (c, &f) in cams.chunks_exact_mut(12).zip(frames) {
            let r = model.rotations[f].matrix();
            for i in 0..3 {
                for j in 0..3 {
                    c[3 * i + j] = r[(i, j)];
                }
            }
            c[9] = model.scales[f] / self.scale;
            c[10] = (model.translations[f][0] - self.centre[0]) / self.scale;
            c[11] = (model.translations[f][1] - self.centre[1]) / self.scale;
        }
        let pts = tracks
            .iter()
            .flat_map(|&p| model.points[p].iter().copied())
            .collect();
        (cams, pts)
    }

    /// Re-triangulates every point from its observations given the metric cameras (3×3
    /// normal equations per track, pixels); points with a singular system keep their value
    /// and are returned.
    pub fn triangulate(&self, model: &mut MetricModel) -> Vec<usize> {
        let g = &self.graph;
        let mut failed = Vec::new();
        for p in 0..g.n_pts {
            let mut ata = Matrix3::<f64>::zeros();
            let mut atb = Vector3::<f64>::zeros();
            for o in g.track(p) {
                let w = self.pixel(o);
                model.accumulate(g.cam[o], [w[0], w[1]], &mut ata, &mut atb);
            }
            match crate::camera::solve_point(&ata, &atb) {
                Some(x) => model.points[p] = x,
                None => failed.push(p),
            }
        }
        failed
    }

    /// Observation `o` in pixels.
    #[inline]
    pub fn pixel(&self, o: usize) -> Vector2<f64> {
        let w = self.graph.w[o];
        Vector2::new(
            w[0] * self.scale + self.centre[0],
            w[1] * self.scale + self.centre[1],
        )
    }

    /// Per frame and per track, `(Σ r², #observations)` of a metric model, pixels; the
    /// frames' sums over the tracks with `counted[p]` only (the fit's), in one pass.
    pub fn residuals(&self, model: &MetricModel, counted: &[bool]) -> (Vec<SumSq>, Vec<SumSq>) {
        let g = &self.graph;
        let mut frames = vec![(0.0, 0usize); g.n_cams];
        let mut tracks = vec![(0.0, 0usize); g.n_pts];
        for (p, tr) in tracks.iter_mut().enumerate() {
            for o in g.track(p) {
                let f = g.cam[o];
                let d = model.project(f, p) - self.pixel(o);
                let ss = d.norm_squared();
                if counted[p] {
                    frames[f].0 += ss;
                    frames[f].1 += 1;
                }
                tr.0 += ss;
                tr.1 += 1;
            }
        }
        (frames, tracks)
    }
}

/// One window's metric reconstruction: per local frame `(R, s, t)`, per track its point.
pub(crate) struct MetricWindow {
    cameras: Vec<(Rotation3<f64>, f64, [f64; 2])>,
    points: Vec<Vector3<f64>>,
    /// The window's affine completion.
    pub(crate) affine: crate::completion::Completion,
}

impl MetricWindow {
    /// The window's scaled orthographic model (its own frame and units).
    pub(crate) fn model(&self) -> MetricModel {
        MetricModel {
            rotations: self.cameras.iter().map(|c| c.0).collect(),
            translations: self
                .cameras
                .iter()
                .map(|c| nalgebra::Vector2::new(c.2[0], c.2[1]))
                .collect(),
            scales: self.cameras.iter().map(|c| c.1).collect(),
            points: self.points.clone(),
            aspect: 1.0,
        }
    }
}

/// The chained-window start of [`SparseProblem::start`] on a graph (see there).
fn start_windows(
    g: &Graph,
    cfg: &SparseConfig,
    camera: CameraModel,
) -> Result<(Vec<f64>, Vec<f64>, usize)> {
    let (nf, np) = (g.n_cams, g.n_pts);
    let mut cams = vec![f64::NAN; 12 * nf];
    let mut cam_done = vec![false; nf];
    let mut pts = vec![0.0; 3 * np];
    let mut placed = vec![false; np];
    let mut placed_n = vec![0usize; np];
    let mut first = true;
    let mut skipped = 0;
    // The windows' completions and metric upgrades are independent: computed in
    // parallel (memory: every window's dense measurements, O(n_obs · window)), then
    // chained in order.
    let windows = windowed::collect_windows(g, &cfg.window)?;
    let fitted = fit_windows(&windows, cfg, camera);
    let fitted = restart_poor_windows(&windows, fitted, cfg, camera);
    for (wi, ((start, end, tracks, meas), window)) in windows.iter().zip(fitted).enumerate() {
        let (start, end, tracks) = (*start, *end, tracks.as_slice());
        let seen = windowed::seen_in_window(meas, tracks.len());
        let window = match window {
            Ok(w) => w,
            Err(e) if first => return Err(e),
            Err(_) => {
                skipped += 1;
                continue;
            }
        };
        // X_glob = sc · A x + b; None: the window does not fit and is bridged.
        let map = 'map: {
            if first {
                break 'map Some((1.0, Matrix3::identity(), Vector3::zeros()));
            }
            let shared = windowed::anchors(tracks, &placed, &seen, &placed_n, &cfg.window);
            if shared.len() < 4 {
                break 'map None;
            }
            let glob: Vec<_> = shared
                .iter()
                .map(|&k| {
                    let p = tracks[k];
                    Vector3::new(pts[3 * p], pts[3 * p + 1], pts[3 * p + 2])
                })
                .collect();
            let align = |w: &MetricWindow| {
                let est: Vec<_> = shared.iter().map(|&k| w.points[k]).collect();
                crate::eval::align_similarity(&est, &glob, true)
            };
            let al = align(&window);
            al.filter(|a| a.relative_rms <= cfg.max_window_mismatch)
                .map(|a| (a.scale, a.rotation, a.translation))
        };
        let Some(map) = map else {
            skipped += 1;
            // The next window overlaps every frame this one would place: leave them to it
            // (a bridged window's cameras are only approximately metric).
            let first_new = (start..end).find(|&f| !cam_done[f]).unwrap_or(end);
            if windows.get(wi + 1).is_some_and(|w| w.0 <= first_new) {
                continue;
            }
            affine_bridge(
                start,
                tracks,
                &window.affine,
                camera,
                &mut cams,
                &mut cam_done,
                &mut pts,
                &mut placed,
            );
            continue;
        };
        let (sc, a, b) = map;
        for f in start..end {
            if cam_done[f] {
                continue;
            }
            let (rot, s, t) = &window.cameras[f - start];
            // s R₁₂ x + t = (s / sc) (A R₁₂ᵀ)ᵀ (X_glob − b) + t.
            let rm = rot.matrix();
            let i = a * Vector3::new(rm[(0, 0)], rm[(0, 1)], rm[(0, 2)]);
            let j = a * Vector3::new(rm[(1, 0)], rm[(1, 1)], rm[(1, 2)]);
            let k = i.cross(&j);
            let sg = s / sc;
            let cam = &mut cams[12 * f..12 * f + 12];
            for (r, v) in [i, j, k].iter().enumerate() {
                cam[3 * r..3 * r + 3].copy_from_slice(&[v[0], v[1], v[2]]);
            }
            cam[9] = if camera == CameraModel::Orthographic {
                1.0
            } else {
                sg
            };
            cam[10] = t[0] - sg * i.dot(&b);
            cam[11] = t[1] - sg * j.dot(&b);
            cam_done[f] = true;
        }
        for (k, &p) in tracks.iter().enumerate() {
            if !placed[p] {
                placed_n[p] = seen[k];
                let x = a * window.points[k] * sc + b;
                pts[3 * p..3 * p + 3].copy_from_slice(&[x[0], x[1], x[2]]);
                placed[p] = true;
            }
        }
        first = false;
    }
    if let Some(f) = cam_done.iter().position(|d| !d) {
        return Err(Error::Degenerate(format!(
            "frame {f}: no window of frames around it could be reconstructed \
             ({skipped} window(s) skipped)"
        )));
    }
    Ok((cams, pts, skipped))
}

/// Every window's metric fit ([`metric_window`]). With [`SparseConfig::warm_windows`], the
/// windows are cut into runs of consecutive windows, the runs fitted in parallel; in a run,
/// each window's completion starts from the window before it ([`windowed::warm_start`]:
/// the shared frames' cameras as they are, the new frames resected), and from the
/// data-driven start when that cannot be built or its fit fails. Otherwise every window
/// starts cold, the windows in parallel.
fn fit_windows(
    windows: &[windowed::Window],
    cfg: &SparseConfig,
    camera: CameraModel,
) -> Vec<Result<MetricWindow>> {
    let cold =
        |w: &windowed::Window| metric_window(w.0, w.1, &w.2, &w.3, &cfg.window, camera, None);
    if !cfg.warm_windows {
        return windows.par_iter().map(cold).collect();
    }
    let runs = (4 * rayon::current_num_threads()).clamp(1, windows.len().max(1));
    let per_run = windows.len().div_ceil(runs).max(1);
    let fitted: Vec<Vec<Result<MetricWindow>>> = windows
        .par_chunks(per_run)
        .map(|run| {
            let mut out: Vec<Result<MetricWindow>> = Vec::with_capacity(run.len());
            for (i, w) in run.iter().enumerate() {
                let warm = match i.checked_sub(1).map(|j| (&run[j], &out[j])) {
                    Some((prev, Ok(fit))) => {
                        windowed::warm_start(prev, &fit.affine, w, WARM_MIN_TRACKS)
                    }
                    _ => None,
                };
                let fit = match &warm {
                    Some(start) => {
                        metric_window(w.0, w.1, &w.2, &w.3, &cfg.window, camera, Some(start))
                            .or_else(|_| cold(w))
                    }
                    None => cold(w),
                };
                out.push(fit);
            }
            out
        })
        .collect();
    fitted.into_iter().flatten().collect()
}

/// Fewest tracks with a known point that resect a frame new to a warm-started window.
const WARM_MIN_TRACKS: usize = 8;

/// The windows whose completion ended in a local minimum — an RMS over
/// [`SparseConfig::window_rms_ratio`] times the median window's (every window sees the same
/// noise), or no fit at all — are completed again from random starts, the windows in
/// parallel, one start at a time until one reaches that level (at most
/// [`SparseConfig::window_restarts`]); the best fit is kept. Measured on a 2 000-frame
/// corridor: 6 of 99 windows ended at 2.5× the median RMS; restarted here rather than one by
/// one in the chaining, the start took 8.5 s instead of 18.8 s, with the same result
/// (docs/results.md).
fn restart_poor_windows(
    windows: &[windowed::Window],
    fitted: Vec<Result<MetricWindow>>,
    cfg: &SparseConfig,
    camera: CameraModel,
) -> Vec<Result<MetricWindow>> {
    let mut rms: Vec<f64> = fitted
        .iter()
        .filter_map(|w| w.as_ref().ok().map(|w| w.affine.rms))
        .filter(|r| r.is_finite())
        .collect();
    if rms.is_empty() || cfg.window_restarts == 0 {
        return fitted;
    }
    let mid = rms.len() / 2;
    let (_, median, _) = rms.select_nth_unstable_by(mid, f64::total_cmp);
    let target = cfg.window_rms_ratio * *median;
    fitted
        .into_par_iter()
        .zip(windows.par_iter())
        .map(|(fit, (start, end, tracks, meas))| {
            if fit.as_ref().is_ok_and(|w| w.affine.rms <= target) {
                return fit;
            }
            let mut best = fit;
            for r in 0..cfg.window_restarts {
                let mut wc = cfg.window.clone();
                wc.completion.init = crate::completion::Init::Random;
                wc.completion.runs = 1;
                wc.completion.seed = ((*start as u64) << 8) ^ r as u64;
                let Ok(w) = metric_window(*start, *end, tracks, meas, &wc, camera, None) else {
                    continue;
                };
                let reached = w.affine.rms <= target;
                if best.as_ref().is_err()
                    || best.as_ref().is_ok_and(|b| w.affine.rms < b.affine.rms)
                {
                    best = Ok(w);
                }
                if reached {
                    break;
                }
            }
            best
        })
        .collect()
}

/// A window whose own metric reconstruction does not fit the points already placed
/// (typically its motion is too weak to fix depth on its own) is mapped by the affine map
/// `X = A x + b` that carries its *affine* points onto the placed ones (linear least
/// squares over ≥ 4 shared tracks; the map absorbs the window's affine ambiguity, so its
/// frames take the metric frame of their neighbours): its new frames' cameras become the
/// nearest scaled rotations of `A⁻ᵀ m`, its new tracks `A x + b`. Returns false when the
/// shared tracks are too few or coplanar.
#[allow(clippy::too_many_arguments)]
fn affine_bridge(
    start: usize,
    tracks: &[usize],
    c: &crate::completion::Completion,
    camera: CameraModel,
    cams: &mut [f64],
    cam_done: &mut [bool],
    pts: &mut [f64],
    placed: &mut [bool],
) -> bool {
    let shared: Vec<usize> = (0..tracks.len()).filter(|&k| placed[tracks[k]]).collect();
    if shared.len() < 4 {
        return false;
    }
    let pairs = shared.iter().map(|&k| {
        let p = tracks[k];
        (
            Vector3::new(c.s[(0, k)], c.s[(1, k)], c.s[(2, k)]),
            Vector3::new(pts[3 * p], pts[3 * p + 1], pts[3 * p + 2]),
        )
    });
    let Some((a, b)) = windowed::fit_affine_map(pairs) else {
        return false;
    };
    let Some(ainv) = a.try_inverse() else {
        return false;
    };
    let nw = c.m.nrows() / 2;
    for lf in 0..nw {
        let f = start + lf;
        if cam_done[f] {
            continue;
        }
        // m·x + t = (A⁻ᵀ m)·(X − b) + t.
        let row = |r: usize| ainv.transpose() * Vector3::new(c.m[(r, 0)], c.m[(r, 1)], c.m[(r, 2)]);
        let (mi, mj) = (row(2 * lf), row(2 * lf + 1));
        let Some((rot, s)) = crate::metric::nearest_camera(&mi, &mj) else {
            continue;
        };
        let s = if camera == CameraModel::Orthographic {
            1.0
        } else {
            s
        };
        let rm = rot.matrix();
        let cam = &mut cams[12 * f..12 * f + 12];
        for i in 0..3 {
            for j in 0..3 {
                cam[3 * i + j] = rm[(i, j)];
            }
        }
        cam[9] = s;
        cam[10] = c.t[2 * lf] - mi.dot(&b);
        cam[11] = c.t[2 * lf + 1] - mj.dot(&b);
        cam_done[f] = true;
    }
    for (k, &p) in tracks.iter().enumerate() {
        if !placed[p] {
            let x = a * Vector3::new(c.s[(0, k)], c.s[(1, k)], c.s[(2, k)]) + b;
            pts[3 * p..3 * p + 3].copy_from_slice(&[x[0], x[1], x[2]]);
            placed[p] = true;
        }
    }
    true
}

/// Completes a window and upgrades it to metric on its own.
pub(crate) fn metric_window(
    start: usize,
    end: usize,
    tracks: &[usize],
    meas: &crate::Measurements,
    cfg: &WindowConfig,
    camera: CameraModel,
    warm: Option<&(Mat<f64>, Vec<f64>)>,
) -> Result<MetricWindow> {
    let c = windowed::complete_window(start, end, tracks, meas, cfg, warm)?;
    let up = crate::metric::upgrade(
        c.m.as_ref(),
        camera,
        &crate::metric::MetricConfig::default(),
    )
    .map_err(|e| {
        Error::Degenerate(format!(
            "window of frames {start}..{end}: metric upgrade failed: {e}"
        ))
    })?;
    let qinv = up.q.try_inverse().ok_or_else(|| {
        Error::Degenerate(format!("window of frames {start}..{end}: Q is singular"))
    })?;
    let cameras = (0..end - start)
        .map(|lf| {
            let row =
                |r: usize| up.q.transpose() * Vector3::new(c.m[(r, 0)], c.m[(r, 1)], c.m[(r, 2)]);
            let (rot, s) = crate::metric::nearest_camera(&row(2 * lf), &row(2 * lf + 1))
                .ok_or_else(|| {
                    Error::Degenerate(format!(
                        "frame {}: the metric camera rows are linearly dependent",
                        start + lf
                    ))
                })?;
            Ok((rot, s, [c.t[2 * lf], c.t[2 * lf + 1]]))
        })
        .collect::<Result<Vec<_>>>()?;
    let points = (0..tracks.len())
        .map(|k| qinv * Vector3::new(c.s[(0, k)], c.s[(1, k)], c.s[(2, k)]))
        .collect();
    Ok(MetricWindow {
        cameras,
        points,
        affine: c,
    })
}

/// A sum of squared residuals (pixels²) and the number of observations in it.
pub type SumSq = (f64, usize);

/// The result of [`fit`]: the affine fit (normalized units) and which tracks it kept.
pub struct SparseFit {
    pub cams: Vec<f64>,
    pub pts: Vec<f64>,
    /// Per track of the table: kept (true) or rejected as an outlier.
    pub inlier: Vec<bool>,
    pub report: SolverReport,
    pub rms_px: f64,
    pub sigma_px: f64,
    pub threshold_px: f64,
    pub schur_nonzeros: usize,
    /// Accepted steps of the final round's adjustment extended along their path.
    pub extensions: usize,
    pub rounds: usize,
    /// Windows of the start that did not fit and were skipped.
    pub skipped_windows: usize,
    /// Why the outlier rejection did not run, when it did not.
    pub note: Option<String>,
}

/// Start, adjust, reject outlier tracks, adjust again (see the module documentation).
/// `table` must be connected with every frame seeing ≥ 4 tracks and every track ≥ 2 frames
/// (what [`TrackTable::set_aside`] leaves). Returns the fit on `table`'s tracks (outliers
/// included, with their points from the first round).
pub fn fit(
    table: &TrackTable,
    cfg: &SparseConfig,
    camera: CameraModel,
    observer: &mut dyn Observer,
) -> Result<(SparseProblem, SparseFit)> {
    let prob = SparseProblem::new(table, camera != CameraModel::Orthographic);
    let (mut cams, mut pts, skipped_windows) = prob.start(cfg, camera)?;
    let lm = prob.adjust(&mut cams, &mut pts, cfg, camera, 0, observer)?;
    let n_res = (2 * prob.graph.n_obs()).max(1) as f64;
    let scale = prob.scale;
    let rms = |c: f64| (c / n_res).sqrt() * scale;
    let sigma = prob.robust_sigma_px(&cams, &pts);
    let threshold = (cfg.outlier_sigmas * sigma).max(cfg.min_outlier_px);
    let costs = prob.track_costs(&cams, &pts);
    let mut inlier: Vec<bool> = (0..prob.graph.n_pts)
        .map(|p| {
            let k = prob.graph.track(p).len().max(1) as f64;
            (costs[p] / (2.0 * k)).sqrt() * prob.scale <= threshold
        })
        .collect();
    let mut n_out = inlier.iter().filter(|&&b| !b).count();
    let keep: Vec<usize> = (0..prob.graph.n_pts).filter(|&p| inlier[p]).collect();
    let all_frames: Vec<usize> = (0..table.n_frames()).collect();
    let sub = table.select(&all_frames, &keep);
    // Residuals judge tracks only at an optimum; and a rejection that starves a frame
    // would lose it. Either way every track is kept and the report says why.
    let mut note = None;
    if n_out > 0 && lm.report.status != crate::SolverStatus::Converged {
        note = Some(format!(
            "no outlier rejection: the adjustment ended with status {} ({n_out} track(s) \
             over {threshold:.2} px would have been rejected)",
            crate::output::spelled(&lm.report.status)
        ));
    } else if n_out > 0 && (0..sub.n_frames()).any(|f| sub.frame_len(f) < 4) {
        note = Some(format!(
            "no outlier rejection: rejecting the {n_out} track(s) over {threshold:.2} px \
             would leave a frame with fewer than 4 tracks"
        ));
    }
    if note.is_some() {
        inlier.iter_mut().for_each(|b| *b = true);
        n_out = 0;
    }
    if n_out == 0 {
        return Ok((
            prob,
            SparseFit {
                cams,
                pts,
                inlier,
                rms_px: rms(lm.report.final_cost),
                report: lm.report,
                sigma_px: sigma,
                threshold_px: threshold,
                schur_nonzeros: lm.schur_nnz,
                extensions: lm.extensions,
                rounds: 1,
                skipped_windows,
                note,
            },
        ));
    }
    // Second round without the outlier tracks, from the current cameras.
    // The first round's normalization, so that the cameras carry over.
    let prob2 = SparseProblem::with_normalization(&sub, prob.centre, prob.scale);
    let mut pts2: Vec<f64> = keep
        .iter()
        .flat_map(|&p| pts[3 * p..3 * p + 3].to_vec())
        .collect();
    let lm2 = prob2.adjust(&mut cams, &mut pts2, cfg, camera, 1, observer)?;
    for (k, &p) in keep.iter().enumerate() {
        pts[3 * p..3 * p + 3].copy_from_slice(&pts2[3 * k..3 * k + 3]);
    }
    let n_res2 = (2 * prob2.graph.n_obs()).max(1) as f64;
    Ok((
        prob,
        SparseFit {
            cams,
            pts,
            inlier,
            rms_px: (lm2.report.final_cost / n_res2).sqrt() * prob2.scale,
            report: lm2.report,
            sigma_px: sigma,
            threshold_px: threshold,
            schur_nonzeros: lm2.schur_nnz,
            extensions: lm2.extensions,
            rounds: 2,
            skipped_windows,
            note: None,
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::{CorridorConfig, corridor};

    /// The points' one-solve optimum (`points_linear`) is the damped iterations' optimum:
    /// on a corridor's start, with the points moved off, both re-solves give the same
    /// points and cost (the damped ones to their own tolerance).
    #[test]
    fn linear_point_solve_matches_the_damped_iterations() {
        struct Damped(ScaledOrthographic);
        impl BundleModel for Damped {
            fn cam_len(&self) -> usize {
                self.0.cam_len()
            }
            fn cam_dim(&self) -> usize {
                self.0.cam_dim()
            }
            fn pt_len(&self) -> usize {
                3
            }
            fn pt_dim(&self) -> usize {
                3
            }
            fn res_dim(&self) -> usize {
                2
            }
            fn eval(
                &self,
                c: &[f64],
                x: &[f64],
                glob: &[f64],
                w: [f64; 2],
                r: &mut [f64],
                jac: Option<Jacobians<'_>>,
            ) {
                self.0.eval(c, x, glob, w, r, jac)
            }
        }
        let (table, _) = corridor(&CorridorConfig {
            frames: 60,
            ..CorridorConfig::default()
        })
        .unwrap();
        let prob = SparseProblem::new(&table, true);
        let (cams, mut pts, _) = prob
            .start(&SparseConfig::default(), CameraModel::ScaledOrthographic)
            .unwrap();
        for (i, v) in pts.iter_mut().enumerate() {
            *v += 0.05 * ((i * 7919 % 13) as f64 - 6.0);
        }
        let model = ScaledOrthographic {
            scaled: true,
            pivoted: false,
        };
        assert!(model.points_linear());
        let g = &prob.graph;
        let (mut a, mut b) = (pts.clone(), pts.clone());
        let ca = bundle::solve_points(&model, g, &cams, &[], &mut a, 10);
        let cb = bundle::solve_points(&Damped(model), g, &cams, &[], &mut b, 10);
        assert!((ca - cb).abs() <= 1e-10 * cb, "{ca} vs {cb}");
        assert!(ca <= cb * (1.0 + 1e-12), "{ca} vs {cb}");
        let spread = (pts.iter().map(|v| v * v).sum::<f64>() / pts.len() as f64).sqrt();
        let worst = a
            .iter()
            .zip(&b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max);
        assert!(
            worst <= 1e-6 * spread,
            "points differ by {worst} (spread {spread})"
        );
    }

    /// A window started from the window before it (the shared frames' cameras as they are,
    /// the new frames resected from its points) starts near the noise level and reaches the
    /// optimum of its cold, data-driven start in fewer iterations; windows that do not
    /// overlap give no warm start.
    #[test]
    fn a_warm_started_window_reaches_the_cold_optimum_sooner() {
        let (table, _) = corridor(&CorridorConfig {
            frames: 100,
            ..CorridorConfig::default()
        })
        .unwrap();
        let prob = SparseProblem::new(&table, true);
        let mut cfg = SparseConfig::default().window;
        cfg.completion.function_tolerance = 1e-10;
        let windows = windowed::collect_windows(&prob.graph, &cfg).unwrap();
        let complete = |w: &windowed::Window, warm| {
            windowed::complete_window(w.0, w.1, &w.2, &w.3, &cfg, warm).unwrap()
        };
        let first = complete(&windows[0], None);
        let start = windowed::warm_start(&windows[0], &first, &windows[1], WARM_MIN_TRACKS)
            .expect("overlapping windows give a warm start");
        let cold = complete(&windows[1], None);
        let warm = complete(&windows[1], Some(&start));
        assert!(
            (warm.rms - cold.rms).abs() <= 1e-6 * cold.rms,
            "warm {} against cold {}",
            warm.rms,
            cold.rms
        );
        assert!(
            warm.report.initial_cost <= 2.0 * warm.report.final_cost
                && warm.report.initial_cost < cold.report.initial_cost,
            "the warm start is near the noise level: cost {} against {} at the optimum and {} \
             at the cold start",
            warm.report.initial_cost,
            warm.report.final_cost,
            cold.report.initial_cost
        );
        assert!(
            warm.report.iterations < cold.report.iterations,
            "{} warm iterations against {} cold",
            warm.report.iterations,
            cold.report.iterations
        );
        assert!(windows[3].0 >= windows[0].1);
        assert!(windowed::warm_start(&windows[0], &first, &windows[3], WARM_MIN_TRACKS).is_none());
    }

    /// A window left in a local minimum (its completion stopped after one iteration from a
    /// random start) is found by its RMS against the other windows' and completed again to
    /// their level; the windows at their optimum are kept as they are.
    #[test]
    fn a_window_in_a_local_minimum_is_completed_again() {
        let (table, _) = corridor(&CorridorConfig {
            frames: 100,
            ..CorridorConfig::default()
        })
        .unwrap();
        let camera = CameraModel::ScaledOrthographic;
        let prob = SparseProblem::new(&table, true);
        let cfg = SparseConfig::default();
        let windows = windowed::collect_windows(&prob.graph, &cfg.window).unwrap();
        assert!(windows.len() >= 4);
        let fit = |w: &windowed::Window, c: &WindowConfig| {
            metric_window(w.0, w.1, &w.2, &w.3, c, camera, None)
        };
        let mut fitted: Vec<_> = windows.iter().map(|w| fit(w, &cfg.window)).collect();
        let rms: Vec<f64> = fitted
            .iter()
            .map(|w| w.as_ref().unwrap().affine.rms)
            .collect();
        let (lo, hi) = rms
            .iter()
            .fold((f64::MAX, 0.0f64), |(a, b), &r| (a.min(r), b.max(r)));
        assert!(hi < 1.2 * lo, "windows at their optimum: RMS {rms:?}");
        let mut spoil = cfg.window.clone();
        spoil.completion.init = crate::completion::Init::Random;
        spoil.completion.max_iterations = 1;
        spoil.completion.seed = 7;
        fitted[2] = fit(&windows[2], &spoil);
        if let Ok(w) = &fitted[2] {
            assert!(
                w.affine.rms > 3.0 * hi,
                "spoiled window: RMS {}",
                w.affine.rms
            );
        }
        let out = restart_poor_windows(&windows, fitted, &cfg, camera);
        for (i, w) in out.iter().enumerate() {
            let r = w.as_ref().unwrap().affine.rms;
            if i == 2 {
                assert!(
                    r <= cfg.window_rms_ratio * hi,
                    "window 2 completed again: RMS {r}"
                );
            } else {
                assert_eq!(r, rms[i], "window {i} kept");
            }
        }
    }
}
