//! The pipeline: track table in, metric structure and cameras out.
//!
//! 1. **Set-aside** ([`TrackTable::set_aside`]): tracks seen in too few frames, frames with
//!    too few tracks, and blocks disconnected from the main one are reported, not used.
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
use nalgebra::{Vector2, Vector3};
use serde::Serialize;

use crate::metric::{self, MetricConfig, MetricUpgrade};
use crate::refine::{self, RefineConfig, RefineResult};
use crate::svd::{self, SvdMethod, TruncatedSvdConfig};
use crate::tracks::{Id, SetAside};
use crate::{
    CameraModel, Error, Event, Measurements, MetricModel, NoopObserver, Observer, Result,
    SolverStatus, TrackTable,
};

/// Pipeline settings. Every field has a documented default.
#[derive(Debug, Clone)]
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
    /// Levenberg–Marquardt refinement; `None` skips it. Default on.
    pub refine: Option<RefineConfig>,
    /// Warn "far from rank 3" when σ4/σ3 exceeds this. Default 0.1.
    pub rank3_warning_ratio: f64,
    /// Warn "close to rank 2" when σ3/σ2 is below this. Default 0.05.
    pub rank2_warning_ratio: f64,
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
            refine: Some(RefineConfig::default()),
            rank3_warning_ratio: 0.1,
            rank2_warning_ratio: 0.05,
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

/// The refinement's report.
#[derive(Debug, Clone, Serialize)]
pub struct RefinementReport {
    pub rms_before_px: f64,
    pub rms_after_px: f64,
    pub status: SolverStatus,
    pub iterations: usize,
    pub seconds: f64,
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

/// A metric reconstruction. Serializes to `reconstruction.json`.
#[derive(Debug, Clone, Serialize)]
pub struct Reconstruction {
    pub camera_model: CameraModel,
    pub frames: Vec<FrameResult>,
    pub points: Vec<PointResult>,
    /// `sqrt(Σ_observed r² / #observed scalars)` of the final metric model, pixels.
    pub rms_px: f64,
    pub metric_upgrade: MetricUpgrade,
    /// Every singular value the factorization computed, descending.
    pub singular_values: Vec<f64>,
    /// σ4/σ3 (NaN when fewer than 4 singular values exist).
    pub rank_ratio: f64,
    pub factorization: FactorizationReport,
    pub refinement: Option<RefinementReport>,
    pub input: InputSummary,
    /// Tracks and frames not used, with reasons.
    pub set_aside: Vec<SetAside>,
    /// Whether the depth-reversal convention mirrored the solution.
    pub mirrored: bool,
    pub warnings: Vec<String>,
    pub timings: Vec<StageTime>,
    /// The metric model (kept frames × kept tracks), for library users.
    #[serde(skip)]
    pub model: MetricModel,
    /// The affine structure `Ŝ` (3×N', one column per kept track) before the metric upgrade.
    #[serde(skip)]
    pub affine_structure: Mat<f64>,
    /// Affine prediction `M̂Ŝ + t1ᵀ` of every kept frame and track (2F'×N').
    #[serde(skip)]
    pub affine_prediction: Mat<f64>,
    /// Indices into the input table of the kept frames and tracks.
    #[serde(skip)]
    pub kept_frames: Vec<usize>,
    #[serde(skip)]
    pub kept_tracks: Vec<usize>,
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
        let (kept, set_aside, kept_frames, kept_tracks) = timer.run("set-aside", |_| {
            table.set_aside(config.min_frames_per_track, config.min_points_per_frame)
        });
        if kept.n_frames() < 2 || kept.n_tracks() < 4 {
            return Err(Error::TooFew {
                what: if kept.n_frames() < 2 {
                    "usable frames (after setting aside under-observed tracks and frames)"
                } else {
                    "usable tracks (after setting aside under-observed tracks and frames)"
                },
                needed: if kept.n_frames() < 2 { 2 } else { 4 },
                have: if kept.n_frames() < 2 {
                    kept.n_frames()
                } else {
                    kept.n_tracks()
                },
            });
        }
        if !set_aside.is_empty() {
            warnings.push(format!(
                "{} track(s) and {} frame(s) set aside (see `set_aside`)",
                set_aside
                    .iter()
                    .filter(|s| s.kind == crate::tracks::SetAsideKind::Track)
                    .count(),
                set_aside
                    .iter()
                    .filter(|s| s.kind == crate::tracks::SetAsideKind::Frame)
                    .count()
            ));
        }
        let meas = kept.measurements();

        let affine = timer.run("factorize", |_| -> Result<Affine> {
            if meas.is_complete() {
                factorize_complete(&meas, &config.svd)
            } else {
                Err(Error::MissingData {
                    observed: meas.n_observed(),
                    total: meas.visible.len(),
                    message: "this build's pipeline factorizes complete tables only: keep the \
                              frames and tracks seen everywhere, or use a missing-data solver"
                        .into(),
                })
            }
        })?;
        let sv = &affine.singular_values;
        let rank_ratio = if sv.len() >= 4 && sv[2] > 0.0 {
            sv[3] / sv[2]
        } else {
            f64::NAN
        };
        if rank_ratio > config.rank3_warning_ratio {
            warnings.push(format!(
                "σ4/σ3 = {rank_ratio:.3} > {}: the tracks are far from rank 3 (strong \
                 perspective, non-rigid or independently moving objects, or outlier tracks)",
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
        let affine_prediction = Mat::from_fn(affine.m_hat.nrows(), affine.s_hat.ncols(), |r, p| {
            let mut v = affine.t[r];
            for k in 0..affine.m_hat.ncols() {
                v += affine.m_hat[(r, k)] * affine.s_hat[(k, p)];
            }
            v
        });

        let upgrade = timer.run("metric-upgrade", |_| {
            metric::upgrade(affine.m_hat.as_ref(), config.camera, &config.metric)
        })?;
        if upgrade.method == metric::UpgradeMethod::Sdp {
            warnings.push(format!(
                "least-squares L is not positive definite (smallest eigenvalue {:.3e}); solved \
                 the PSD-constrained SDP instead",
                upgrade.min_eigenvalue_ls
            ));
        }
        let mut model = initial_model(&meas, &affine, &upgrade, config.camera)?;

        let refinement = match &config.refine {
            Some(rc) => {
                let r: RefineResult = timer.run("refine", |obs| {
                    refine::refine(&meas, &mut model, config.camera, rc, obs)
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
                })
            }
            None => None,
        };
        refine::fix_gauge(&mut model, config.camera);
        let mirrored = metric::apply_necker_convention(&mut model);
        let rms_px = model.rms(&meas);

        for w in &warnings {
            timer.observer.on_event(&Event::Warning { message: w });
        }
        let frames = (0..kept.n_frames())
            .map(|f| {
                let (mut ss, mut n) = (0.0, 0usize);
                for p in 0..kept.n_tracks() {
                    if meas.is_visible(f, p) {
                        ss += residual2(&model, &meas, f, p);
                        n += 1;
                    }
                }
                let r = model.rotations[f].matrix();
                FrameResult {
                    frame: kept.frame_ids()[f].clone(),
                    rotation: std::array::from_fn(|a| std::array::from_fn(|b| r[(a, b)])),
                    translation: [model.translations[f][0], model.translations[f][1]],
                    scale: model.scales[f],
                    rms_px: if n > 0 {
                        (ss / (2 * n) as f64).sqrt()
                    } else {
                        0.0
                    },
                    n_observations: n,
                }
            })
            .collect();
        let points = (0..kept.n_tracks())
            .map(|p| {
                let (mut ss, mut n) = (0.0, 0usize);
                for f in 0..kept.n_frames() {
                    if meas.is_visible(f, p) {
                        ss += residual2(&model, &meas, f, p);
                        n += 1;
                    }
                }
                let x = model.points[p];
                PointResult {
                    track: kept.track_ids()[p].clone(),
                    xyz: [x[0], x[1], x[2]],
                    inlier: true,
                    rms_px: if n > 0 {
                        (ss / (2 * n) as f64).sqrt()
                    } else {
                        0.0
                    },
                    n_observations: n,
                }
            })
            .collect();
        Ok(Reconstruction {
            camera_model: config.camera,
            frames,
            points,
            rms_px,
            metric_upgrade: upgrade,
            rank_ratio,
            singular_values: affine.singular_values,
            factorization: affine.report,
            refinement,
            input: InputSummary {
                frames: table.n_frames(),
                tracks: table.n_tracks(),
                observations: table.n_observed(),
                fill: table.fill(),
                frames_used: kept.n_frames(),
                tracks_used: kept.n_tracks(),
            },
            set_aside,
            mirrored,
            warnings,
            timings: timer.timings,
            model,
            affine_structure: affine.s_hat.clone(),
            affine_prediction,
            kept_frames,
            kept_tracks,
            input_frame_ids: table.frame_ids().to_vec(),
            input_track_ids: table.track_ids().to_vec(),
        })
    }

    /// The affine prediction laid out like the input table (2F×N in the input's frame and
    /// track order); rows/columns of set-aside frames/tracks are NaN.
    pub fn completed_matrix(&self) -> Mat<f64> {
        let (f, n) = (self.input_frame_ids.len(), self.input_track_ids.len());
        let mut out = Mat::from_fn(2 * f, n, |_, _| f64::NAN);
        for (kf, &fi) in self.kept_frames.iter().enumerate() {
            for (kp, &pi) in self.kept_tracks.iter().enumerate() {
                out[(2 * fi, pi)] = self.affine_prediction[(2 * kf, kp)];
                out[(2 * fi + 1, pi)] = self.affine_prediction[(2 * kf + 1, kp)];
            }
        }
        out
    }

    /// Serializes to the `reconstruction.json` document.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"))
    }
}

fn residual2(model: &MetricModel, meas: &Measurements, f: usize, p: usize) -> f64 {
    let q = model.project(f, p);
    let dx = q[0] - meas.w[(2 * f, p)];
    let dy = q[1] - meas.w[(2 * f + 1, p)];
    dx * dx + dy * dy
}

fn validate_config(c: &Config) -> Result<()> {
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
    let t: Vec<f64> = (0..rows)
        .map(|r| (0..n).map(|p| meas.w[(r, p)]).sum::<f64>() / n as f64)
        .collect();
    let centered = Mat::from_fn(rows, n, |r, p| meas.w[(r, p)] - t[r]);
    let svd = svd::truncated_svd(centered.as_ref(), 4, cfg)?;
    if svd.s.len() < 3 || !(svd.s[2] > 0.0) {
        return Err(Error::Degenerate(format!(
            "the centered observation matrix has rank < 3 (singular values {:?}): the points \
             or the motion do not span 3D",
            svd.singular_values.iter().take(4).collect::<Vec<_>>()
        )));
    }
    let m_hat = Mat::from_fn(rows, 3, |r, k| svd.u[(r, k)] * svd.s[k].sqrt());
    let s_hat = Mat::from_fn(3, n, |k, p| svd.v[(p, k)] * svd.s[k].sqrt());
    let pred = Mat::from_fn(rows, n, |r, p| {
        t[r] + (0..3).map(|k| m_hat[(r, k)] * s_hat[(k, p)]).sum::<f64>()
    });
    let rms = meas.rms(pred.as_ref());
    Ok(Affine {
        m_hat,
        s_hat,
        t,
        report: FactorizationReport {
            method: "svd".into(),
            svd_method: match svd.method {
                SvdMethod::Thin => "thin".into(),
                _ => "randomized".into(),
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
    let f = meas.n_frames();
    let q = up.q;
    let mut rotations = Vec::with_capacity(f);
    let mut scales = Vec::with_capacity(f);
    let mut translations = Vec::with_capacity(f);
    for k in 0..f {
        let row = |r: usize| {
            Vector3::new(
                affine.m_hat[(r, 0)],
                affine.m_hat[(r, 1)],
                affine.m_hat[(r, 2)],
            )
        };
        let i = q.transpose() * row(2 * k);
        let j = q.transpose() * row(2 * k + 1);
        let (r, s) = metric::nearest_camera(&i, &j).ok_or_else(|| {
            Error::Degenerate(format!(
                "frame {k}: the metric camera rows are linearly dependent (the frame's \
                 image motion is degenerate)"
            ))
        })?;
        rotations.push(r);
        scales.push(match camera {
            CameraModel::Orthographic => 1.0,
            CameraModel::ScaledOrthographic => s,
        });
        translations.push(Vector2::new(affine.t[2 * k], affine.t[2 * k + 1]));
    }
    let qinv = q.try_inverse().ok_or_else(|| Error::Numerical {
        stage: "metric upgrade",
        message: "Q is singular".into(),
    })?;
    let points = (0..meas.n_points())
        .map(|p| {
            qinv * Vector3::new(
                affine.s_hat[(0, p)],
                affine.s_hat[(1, p)],
                affine.s_hat[(2, p)],
            )
        })
        .collect();
    let mut model = MetricModel {
        rotations,
        translations,
        scales,
        points,
    };
    model.triangulate(meas);
    Ok(model)
}
