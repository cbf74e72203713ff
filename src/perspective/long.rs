//! Perspective reconstruction of long sequences ([`fit_observations`]): metric windows of
//! frames, chained by similarities, then one sparse metric bundle adjustment.
//!
//! Why not the projective chain and one self-calibration: a long projective chain is
//! consistent only up to a slowly varying homography until its bundle adjustment has
//! converged (which takes a growing number of solves, docs/results.md), and the absolute
//! dual quadric of all its cameras then fits none of them well — on a 1 000-frame corridor
//! the metric start was 4 px RMS and the metric adjustment stalled at 1.6–1.9 px with the
//! structure lost. A metric window is small and consistent, a similarity between two of
//! them has 7 degrees of freedom that the shared tracks fix, and the chain of similarities
//! is what the scaled orthographic sparse pipeline does (docs/math.md §13).

use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;
use std::borrow::Cow;

use super::{
    Intrinsics, Loss, PerspectiveConfig, PerspectiveFit, PerspectiveModel, adjust_graph,
    assumed_frame_of,
};
use crate::error::{Error, Result};
use crate::projective::windowed::{self, WindowConfig};
use crate::projective::{
    self, AffineStart, Normalization, Observation, ProjectiveConfig, ProjectiveFit, ProjectiveModel,
};
use crate::{Measurements, NoopObserver, Observer};

/// One window of frames ([`windowed::collect_windows`]) and its metric fit (normalised
/// units of the sequence's graph), or why it has none.
struct Window {
    start: usize,
    end: usize,
    tracks: Vec<usize>,
    meas: Measurements,
    fit: std::result::Result<PerspectiveModel, String>,
}

/// Perspective reconstruction of a sparse table of observations (`n_frames` frames,
/// `n_tracks` tracks), for long sequences: nothing is `O(F·N)` or `O(F²)`.
///
/// Objective: as [`super::fit`], the robust reprojection error in pixels over the observed
/// entries, `Σ ρ(‖π(K, R_f, t_f, X_p) − w_fp‖²)`, one focal length for the sequence
/// (given, or estimated) and the principal point at the image centre (or given).
///
/// 1. Overlapping windows of frames ([`WindowConfig`]: 40, overlap 20), each fitted on its
///    own and in parallel: affine completion and its scaled orthographic upgrade,
///    projective factorization ([`projective::fit`], its adjustment capped at
///    [`PerspectiveConfig::projective_iterations`]), then [`super::fit`]'s starts (the
///    self-calibration, and the scaled orthographic model lifted at the focal lengths of
///    [`PerspectiveConfig::focal_grid`], mirrored or not) screened and the best adjusted.
/// 2. Unless the focal length is given, the median of the windows' focal lengths is the
///    sequence's, and every window is adjusted again with it held fixed (windows with
///    their own focal lengths would not chain into one metric frame). Beyond
///    [`PerspectiveConfig::focal_sample_windows`] windows only that many, spread evenly,
///    are fitted in step 1 with a free focal length; the others are fitted once, with the
///    sequence's held fixed.
/// 3. The windows are chained by the similarity (Umeyama, no reflection: the perspective
///    camera has no depth reversal) that carries their points onto the tracks already
///    placed, anchored on the tracks seen in ≥ [`WindowConfig::min_anchor_observations`]
///    frames of both windows. A window that does not fit (shared points off by more than
///    10 % of their spread) is skipped when the next window covers its frames.
/// 4. One metric bundle adjustment of everything ([`super::adjust`]'s, on the sparse
///    camera–point graph), the focal length free unless given.
///
/// Cost: the windows `O(F)` small dense fits (one per window, and one more for each of
/// the windows that estimate the focal length); each adjustment
/// iteration `O(n_obs + F b² c³)` for a half-bandwidth of `b` frames and `c` = 6
/// parameters per camera; memory linear in the observations (the
/// windows' dense measurements are `O(n_obs · window)` in total).
///
/// Returns the perspective fit; its `starts` is empty and its `selfcal` `None` (each
/// window has its own). Errors: [`Error::InvalidConfig`], [`Error::Degenerate`] and
/// [`Error::TooFew`] as [`projective::fit_observations`] for the table;
/// [`Error::Degenerate`] when no window fits, or a frame is covered by no window that fits.
pub fn fit_observations(
    obs: &[Observation],
    n_frames: usize,
    n_tracks: usize,
    cfg: &PerspectiveConfig,
    projective_cfg: &ProjectiveConfig,
    windows: &WindowConfig,
    observer: &mut dyn Observer,
) -> Result<PerspectiveFit> {
    cfg.validate()?;
    projective_cfg.validate()?;
    let (g, assumed) = table_graph(obs, n_frames, n_tracks, cfg)?;
    let s = assumed.scale;
    let t0 = std::time::Instant::now();
    observer.on_event(&crate::Event::StageStarted { stage: "windows" });
    let (focal, (rotations, translations, mut points, placed)) =
        chain_windows(&g, s, cfg, projective_cfg, windows, None)?;
    place_unplaced(&g, focal, &rotations, &translations, &mut points, &placed);
    let seconds = t0.elapsed().as_secs_f64();
    observer.on_event(&crate::Event::StageFinished {
        stage: "windows",
        seconds,
    });
    let start = PerspectiveModel {
        focal_px: vec![focal * s; n_frames],
        principal_point: assumed.principal_point,
        k1: 0.0,
        aspect: 1.0,
        rotations,
        translations,
        points,
    };
    let mut out = adjust_long(&g, start, cfg, &assumed, observer)?;
    out.stages.insert(
        0,
        projective::StageReport {
            stage: "windows".into(),
            status: crate::SolverStatus::Converged,
            iterations: n_frames.div_ceil((windows.window - windows.overlap).max(1)),
            rms_before_px: f64::NAN,
            rms_after_px: f64::NAN,
            seconds,
            linear_solver: None,
            cg_iterations: 0,
        },
    );
    Ok(out)
}

/// The metric bundle adjustment of [`fit_observations`] (step 4) started from a given
/// perspective model `start` (pixel units, as [`PerspectiveModel`] holds them) instead of
/// the chained windows: to refine a known reconstruction on a long sparse table, or to
/// measure the accuracy floor of a synthetic sequence (the adjustment started at the truth).
///
/// Objective as [`fit_observations`]: `Σ ρ(‖π(K, R_f, t_f, X_p) − w_fp‖²)` over the observed
/// entries, the focal length(s) free unless `cfg` gives one. Cost per iteration
/// `O(n_obs + F b² c³)` (banded reduced camera system, half-bandwidth `b` frames), memory
/// linear in the observations.
///
/// Errors: as [`fit_observations`] for the table; [`Error::Dimension`] when `start` does
/// not have `n_frames` cameras and `n_tracks` points.
pub fn refine_observations(
    obs: &[Observation],
    n_frames: usize,
    n_tracks: usize,
    start: &PerspectiveModel,
    cfg: &PerspectiveConfig,
    observer: &mut dyn Observer,
) -> Result<PerspectiveFit> {
    cfg.validate()?;
    let cams_ok = start.rotations.len() == n_frames
        && start.translations.len() == n_frames
        && (start.focal_px.len() == n_frames || start.focal_px.len() == 1);
    if !cams_ok || start.points.len() != n_tracks {
        return Err(Error::Dimension {
            context: "perspective::refine_observations: the start vs the table",
            expected: format!("{n_frames} frames, {n_tracks} tracks"),
            got: format!(
                "{} rotations, {} translations, {} focal lengths, {} points",
                start.rotations.len(),
                start.translations.len(),
                start.focal_px.len(),
                start.points.len()
            ),
        });
    }
    let (g, assumed) = table_graph(obs, n_frames, n_tracks, cfg)?;
    let mut start = start.clone();
    if start.focal_px.len() == 1 {
        start.focal_px = vec![start.focal_px[0]; n_frames];
    }
    adjust_long(&g, start, cfg, &assumed, observer)
}

/// The camera–point graph of a sparse table, its positions normalised by the frame
/// `cfg.intrinsics` assume (principal point, scale), and that frame; the table's input
/// errors as [`projective::fit_observations`]. `O(n log n)`.
fn table_graph(
    obs: &[Observation],
    n_frames: usize,
    n_tracks: usize,
    cfg: &PerspectiveConfig,
) -> Result<(projective::bundle::Graph, super::Assumed)> {
    let order = projective::observation_order(obs, n_frames, n_tracks)?;
    let assumed = assumed_frame_of(obs.iter().map(|o| o.xy), &cfg.intrinsics);
    let norm = Normalization {
        centre: assumed.principal_point,
        scale: 1.0 / assumed.scale,
    };
    let g = projective::observation_graph(obs, &order, n_frames, n_tracks, &norm);
    drop(order);
    projective::check_graph(&g)?;
    Ok((g, assumed))
}

/// The long path's global adjustment (step 4 of [`fit_observations`]) of `start` on `g`:
/// `cfg`'s, with [`PerspectiveConfig::long_geodesic_acceleration`] when `bundle`'s own
/// geodesic acceleration is 0.
fn adjust_long(
    g: &projective::bundle::Graph,
    start: PerspectiveModel,
    cfg: &PerspectiveConfig,
    assumed: &super::Assumed,
    observer: &mut dyn Observer,
) -> Result<PerspectiveFit> {
    let estimate_pp = cfg.estimates_principal_point(assumed);
    let cfg = PerspectiveConfig {
        bundle: cfg.bundle.or_geodesic(cfg.long_geodesic_acceleration),
        ..cfg.clone()
    };
    adjust_graph(g, start, &cfg, assumed, estimate_pp, 0, observer)
}

/// Steps 1–3 of [`fit_observations`] on the graph `g` (normalised: principal point at 0,
/// `s` pixels per unit): the windows fitted, the sequence's focal length (normalised units)
/// and the windows chained by similarities. `O(F)` window fits, `O(n_obs)` chaining.
fn chain_windows(
    g: &projective::bundle::Graph,
    s: f64,
    cfg: &PerspectiveConfig,
    projective_cfg: &ProjectiveConfig,
    windows: &WindowConfig,
    own: Option<&OwnFits<'_>>,
) -> Result<(f64, Chained)> {
    let mut list: Vec<Window> = windowed::collect_windows(g, windows)?
        .into_iter()
        .map(|(start, end, tracks, meas)| Window {
            start,
            end,
            tracks,
            meas,
            fit: Err("not fitted".into()),
        })
        .collect();
    // The caller's projective fits of the same windows, mapped into this graph's units when
    // a window is fitted; a missing one, or one far above the others (a local minimum), is
    // fitted again.
    let reuse = match own {
        Some(o) if o.fits.len() == list.len() => o.reusable(),
        _ => vec![false; list.len()],
    };
    let own_model = |i: usize| own.filter(|_| reuse[i]).and_then(|o| o.mapped(i));
    // Window settings in the graph's normalised units: principal point 0, scale 1.
    let window_cfg = |focal: Option<f64>| PerspectiveConfig {
        intrinsics: Intrinsics {
            focal_px: focal,
            principal_point: Some([0.0, 0.0]),
            image_size: None,
        },
        per_frame_focal: false,
        estimate_principal_point: false,
        distortion: false,
        estimate_aspect_ratio: false,
        loss: match cfg.loss {
            Loss::Squared => Loss::Squared,
            Loss::Huber(d) => Loss::Huber(d / s),
            Loss::Cauchy(d) => Loss::Cauchy(d / s),
        },
        ..cfg.clone()
    };
    let known = cfg.intrinsics.focal_px.map(|f| f / s);
    let first_cfg = window_cfg(known);
    // With the focal length given every window is fitted with it; otherwise a sample of
    // the windows estimates it (all of them when none of the sample fits).
    let sample = match known {
        Some(_) => vec![true; list.len()],
        None => focal_sample(list.len(), cfg.focal_sample_windows),
    };
    let fit_free = |list: &mut [Window], which: &(dyn Fn(usize) -> bool + Sync)| {
        let fits: Vec<_> = list
            .par_iter()
            .enumerate()
            .map(|(i, w)| {
                if which(i) {
                    fit_window(
                        w,
                        own_model(i).as_ref(),
                        windows,
                        projective_cfg,
                        &first_cfg,
                    )
                    .map_err(|e| e.to_string())
                } else {
                    Err("not fitted".into())
                }
            })
            .collect();
        for (i, (w, f)) in list.iter_mut().zip(fits).enumerate() {
            if which(i) {
                w.fit = f;
            }
        }
    };
    fit_free(&mut list, &|i| sample[i]);
    let focal = match known {
        Some(f) => f,
        None => {
            let focals = |list: &[Window]| -> Vec<f64> {
                list.iter()
                    .filter_map(|w| w.fit.as_ref().ok().map(|m| m.focal_px[0]))
                    .filter(|f| f.is_finite() && *f > 0.0)
                    .collect()
            };
            let mut f = focals(&list);
            if f.is_empty() && sample.iter().any(|&k| !k) {
                fit_free(&mut list, &|i| !sample[i]);
                f = focals(&list);
            }
            if f.is_empty() {
                return Err(Error::Degenerate(
                    "no window of frames could be reconstructed in perspective".into(),
                ));
            }
            f.sort_by(f64::total_cmp);
            let median = f[f.len() / 2];
            // Every window again with the sequence's focal length.
            let fixed = window_cfg(Some(median));
            let refits: Vec<_> = list
                .par_iter()
                .enumerate()
                .map(|(i, w)| {
                    match &w.fit {
                        Ok(m) => {
                            super::adjust(&w.meas, m, &fixed, 0, &mut NoopObserver).map(|r| r.model)
                        }
                        Err(_) => {
                            fit_window(w, own_model(i).as_ref(), windows, projective_cfg, &fixed)
                        }
                    }
                    .map_err(|e| e.to_string())
                })
                .collect();
            for (w, f) in list.iter_mut().zip(refits) {
                w.fit = f;
            }
            median
        }
    };
    let chained = chain(&list, g.n_cams, g.n_pts, windows)?;
    Ok((focal, chained))
}

/// Iterations of the metric adjustment of [`metric_reference`]: none — only its start, the
/// placed tracks' points re-solved for the chained cameras (the adjustment's variable
/// projection), is kept. The projective windows are each placed on these points by their
/// own homography and the global projective adjustment follows, which iterations here do
/// not shorten: on a 20 000-frame corridor 10 of them took 45 of the reference's 87 s and
/// moved the projective start from 0.4858 to 0.4845 px, and the adjustment took the same 33
/// solves to the same optimum either way (2 000 frames: 32 solves with 0, 1, 3, 10 or 20;
/// docs/results.md). Without the re-solve (the chain's points as placed) the start was
/// 0.4851 px against 0.4769 at 2 000 frames.
const REFERENCE_ITERATIONS: usize = 0;

/// A metric reconstruction of the projective graph `g` (any similarity normalization of the
/// pixels) by steps 1–3 of [`fit_observations`] — metric windows chained by similarities, no
/// global adjustment — as cameras `K [R | t]` (12 per frame, row-major, in `g`'s image
/// units; `px` pixels per unit) and points (4 per track, `w = 1`), with which tracks a window placed (the others
/// are zero). The principal point is assumed at the centre of the observations' bounding
/// box and the focal length is the windows' median, as in [`fit_observations`] without
/// intrinsics.
///
/// The placed tracks' points are then re-solved for the chained cameras (the start of a
/// metric adjustment of [`REFERENCE_ITERATIONS`] = 0 iterations).
///
/// Its use: a drift-free reference frame for the projective chain of a long sequence
/// ([`windowed::projective_start`]). A chain of similarities stays well conditioned however
/// long it is — a similarity's drift is a slow rotation, translation and scale — while a
/// chain of projective windows drifts in the 15-dimensional group of homographies, and a
/// thousand such links leave the early frames numerically lost in the last one's frame.
///
/// `own`: the windows' projective fits when the caller has them (the projective chain's
/// first pass, in `g`'s units): each window's metric fit then starts from its own instead
/// of fitting it again (with [`PerspectiveConfig::focal_sample_windows`], the reference's
/// time on a 2 000-frame corridor 62.8 → 33.2 s).
///
/// Cost: as steps 1–3 of [`fit_observations`]: `O(F)` small window fits; memory a copy of
/// `g`'s positions plus the windows' measurements.
pub(crate) fn metric_reference(
    g: &projective::bundle::Graph,
    px: f64,
    projective_cfg: &ProjectiveConfig,
    windows: &WindowConfig,
    own: Option<&[std::result::Result<ProjectiveFit, String>]>,
) -> Result<(Vec<f64>, Vec<f64>, Vec<bool>)> {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for w in &g.w {
        for d in 0..2 {
            lo[d] = lo[d].min(w[d]);
            hi[d] = hi[d].max(w[d]);
        }
    }
    let side = (hi[0] - lo[0]).max(hi[1] - lo[1]);
    if !(side > 0.0 && side.is_finite()) {
        return Err(Error::Degenerate(
            "the observations span no area: no metric reference".into(),
        ));
    }
    let pp = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
    let local = projective::bundle::Graph {
        n_cams: g.n_cams,
        n_pts: g.n_pts,
        pt_ptr: g.pt_ptr.clone(),
        cam: g.cam.clone(),
        w: g.w
            .iter()
            .map(|w| [(w[0] - pp[0]) / side, (w[1] - pp[1]) / side])
            .collect(),
    };
    let cfg = PerspectiveConfig::default();
    // Pixels per local unit.
    let sp = side * px;
    let (focal, (rotations, translations, points, placed)) = chain_windows(
        &local,
        sp,
        &cfg,
        projective_cfg,
        windows,
        own.map(|fits| OwnFits {
            fits,
            // w_local = (w − pp) / side.
            to_local: Normalization {
                centre: pp,
                scale: 1.0 / side,
            },
        })
        .as_ref(),
    )?;
    // The points re-solved for the chained cameras (each projective window is mapped onto
    // them): the metric adjustment's start, on the placed tracks only (a track no window
    // placed would sit on a ray at a guessed depth).
    let kept: Vec<usize> = (0..g.n_pts).filter(|&p| placed[p]).collect();
    let sub = {
        let mut pt_ptr = Vec::with_capacity(kept.len() + 1);
        pt_ptr.push(0);
        let (mut cam, mut w) = (Vec::new(), Vec::new());
        for &p in &kept {
            for o in local.track(p) {
                cam.push(local.cam[o]);
                w.push(local.w[o]);
            }
            pt_ptr.push(cam.len());
        }
        projective::bundle::Graph {
            n_cams: g.n_cams,
            n_pts: kept.len(),
            pt_ptr,
            cam,
            w,
        }
    };
    drop(local);
    let start = PerspectiveModel {
        focal_px: vec![focal * sp; g.n_cams],
        principal_point: [0.0, 0.0],
        k1: 0.0,
        aspect: 1.0,
        rotations,
        translations,
        points: kept.iter().map(|&p| points[p]).collect(),
    };
    let assumed = super::Assumed {
        principal_point: [0.0, 0.0],
        principal_point_source: "track bounding box",
        scale: sp,
    };
    let mut adjust_cfg = cfg.clone();
    adjust_cfg.bundle.max_iterations = REFERENCE_ITERATIONS;
    let fit = adjust_graph(
        &sub,
        start,
        &adjust_cfg,
        &assumed,
        false,
        0,
        &mut NoopObserver,
    )?;
    drop(sub);
    let focal = fit.model.focal_px[0] / sp;
    let mut points = points;
    for (k, &p) in kept.iter().enumerate() {
        points[p] = fit.model.points[k];
    }
    let PerspectiveModel {
        rotations,
        translations,
        ..
    } = fit.model;
    // P = T diag(f, f, 1) [R | t], T = [[side, 0, pp_x], [0, side, pp_y], [0, 0, 1]]: the
    // local units back to g's.
    let t = Matrix3::new(side, 0.0, pp[0], 0.0, side, pp[1], 0.0, 0.0, 1.0)
        * Matrix3::from_diagonal(&Vector3::new(focal, focal, 1.0));
    let mut cams = Vec::with_capacity(12 * g.n_cams);
    for (r, tr) in rotations.iter().zip(&translations) {
        let m = t * r;
        let c = t * tr;
        for i in 0..3 {
            cams.extend_from_slice(&[m[(i, 0)], m[(i, 1)], m[(i, 2)], c[i]]);
        }
    }
    let mut pts = vec![0.0; 4 * g.n_pts];
    for (p, x) in points.iter().enumerate() {
        if placed[p] {
            pts[4 * p..4 * p + 4].copy_from_slice(&[x[0], x[1], x[2], 1.0]);
        }
    }
    Ok((cams, pts, placed))
}

/// A window's metric fit from scratch (normalised units; `cfg` its settings), from its
/// projective fit `own` when one is given (else fitted here from the window's scaled
/// orthographic completion). With `own`, that completion is made only if [`super::fit`]
/// needs its affine starts (no early acceptance of the self-calibration).
fn fit_window(
    w: &Window,
    own: Option<&ProjectiveModel>,
    windows: &WindowConfig,
    projective_cfg: &ProjectiveConfig,
    cfg: &PerspectiveConfig,
) -> Result<PerspectiveModel> {
    let metric_window = || {
        crate::sparse::metric_window(
            w.start,
            w.end,
            &w.tracks,
            &w.meas,
            windows,
            crate::CameraModel::ScaledOrthographic,
            None,
        )
    };
    // The starts of super::fit: the self-calibration, and the window's scaled orthographic
    // model lifted at several focal lengths, mirrored or not (the self-calibration of a
    // window with weak perspective can land on the depth-reversed reconstruction).
    if let Some(proj) = own {
        let affine = || metric_window().ok().map(|mw| Cow::Owned(mw.model()));
        return Ok(super::fit_lazy(&w.meas, proj, affine, cfg, 0, &mut NoopObserver)?.model);
    }
    let mw = metric_window()?;
    let c = &mw.affine;
    let pcfg = ProjectiveConfig {
        refine: crate::projective::bundle::LmConfig {
            max_iterations: cfg.projective_iterations,
            ..projective_cfg.refine.clone()
        },
        second_bridge: None,
        escapes: Vec::new(),
        ..projective_cfg.clone()
    };
    let proj = projective::fit(
        &w.meas,
        AffineStart {
            m: c.m.as_ref(),
            s: c.s.as_ref(),
            t: &c.t,
        },
        &pcfg,
        0,
        &mut NoopObserver,
    )?
    .model;
    let affine = mw.model();
    Ok(super::fit(&w.meas, &proj, Some(&affine), cfg, 0, &mut NoopObserver)?.model)
}

/// Which of `n` windows estimate the sequence's focal length
/// ([`PerspectiveConfig::focal_sample_windows`] = `m`): all of them when `m` is 0 or
/// `n ≤ m`, else `m` spread evenly from the first to the last (the middle one for `m` = 1).
/// The others are fitted with the sample's median held fixed: three screened starts each
/// ([`super::fit`] with a known focal length: the self-calibration and the affine lift,
/// mirrored or not) against seven, and no second adjustment.
fn focal_sample(n: usize, m: usize) -> Vec<bool> {
    if m == 0 || n <= m {
        return vec![true; n];
    }
    let mut keep = vec![false; n];
    if m == 1 {
        keep[(n - 1) / 2] = true;
        return keep;
    }
    for j in crate::degeneracy::spaced(n, m) {
        keep[j] = true;
    }
    keep
}

/// Projective fits of the same windows ([`windowed::collect_windows`] of the same graph
/// and [`WindowConfig`]) that a caller already has — the first pass of
/// [`windowed::projective_start`] — in its graph's units, and the similarity `to_local`
/// of those image units to the ones [`metric_reference`] works in (`P ↦ T P`).
pub(crate) struct OwnFits<'a> {
    pub fits: &'a [std::result::Result<ProjectiveFit, String>],
    pub to_local: Normalization,
}

impl OwnFits<'_> {
    /// Which windows' fits are reused: not where the fit failed or ended above
    /// [`windowed::FAILED_WINDOW_RATIO`] times the (lower) median window's RMS, the
    /// projective chain's own rule (the window is then fitted again from its affine
    /// completion).
    fn reusable(&self) -> Vec<bool> {
        let mut rms: Vec<f64> = self
            .fits
            .iter()
            .filter_map(|f| f.as_ref().ok().map(|f| f.rms_px))
            .filter(|r| r.is_finite())
            .collect();
        rms.sort_by(f64::total_cmp);
        // The lower median (of two fits, the better one).
        let median = rms
            .get(rms.len().saturating_sub(1) / 2)
            .copied()
            .unwrap_or(f64::NAN);
        self.fits
            .iter()
            .map(|f| {
                f.as_ref()
                    .is_ok_and(|f| f.rms_px <= windowed::FAILED_WINDOW_RATIO * median)
            })
            .collect()
    }

    /// Window `i`'s projective model in the local units (`None` where its fit failed). A
    /// copy, made only when the window is fitted.
    fn mapped(&self, i: usize) -> Option<ProjectiveModel> {
        let f = self.fits[i].as_ref().ok()?;
        let cameras = f
            .model
            .cameras
            .iter()
            .map(|p| {
                let q = self.to_local.camera_to_normalized(p);
                std::array::from_fn(|k| q[k])
            })
            .collect();
        Some(ProjectiveModel {
            cameras,
            points: f.model.points.clone(),
        })
    }
}

type Chained = (
    Vec<Matrix3<f64>>,
    Vec<Vector3<f64>>,
    Vec<Vector3<f64>>,
    Vec<bool>,
);

/// Chains the fitted windows into window 0's frame (see [`fit_observations`], step 3):
/// rotations, translations, points and which points a window placed. `O(n_obs)`.
fn chain(list: &[Window], nf: usize, np: usize, cfg: &WindowConfig) -> Result<Chained> {
    let mut rotations = vec![Matrix3::identity(); nf];
    let mut translations = vec![Vector3::zeros(); nf];
    let mut cam_done = vec![false; nf];
    let mut points = vec![Vector3::zeros(); np];
    let mut placed = vec![false; np];
    let mut placed_n = vec![0usize; np];
    let mut first = true;
    let mut skipped = 0;
    for (wi, w) in list.iter().enumerate() {
        let seen = windowed::seen_in_window(&w.meas, w.tracks.len());
        // X_glob = sc · A x + b.
        let map = w.fit.as_ref().map_err(String::clone).and_then(|m| {
            if first {
                return Ok((1.0, Matrix3::identity(), Vector3::zeros(), m));
            }
            let shared = windowed::anchors(&w.tracks, &placed, &seen, &placed_n, cfg);
            if shared.len() < 4 {
                return Err(format!(
                    "{} track(s) shared with the frames before it (4 needed)",
                    shared.len()
                ));
            }
            let est: Vec<_> = shared.iter().map(|&k| m.points[k]).collect();
            let glob: Vec<_> = shared.iter().map(|&k| points[w.tracks[k]]).collect();
            match crate::eval::align_similarity(&est, &glob, false) {
                Some(a) if a.relative_rms <= 0.1 => Ok((a.scale, a.rotation, a.translation, m)),
                Some(a) => Err(format!(
                    "its shared points are {:.1} % of their spread off the placed ones after \
                     the best similarity (10 % allowed)",
                    100.0 * a.relative_rms
                )),
                None => Err("its shared points are degenerate".into()),
            }
        });
        let (sc, a, b, m) = match map {
            Ok(map) => map,
            Err(why) => {
                skipped += 1;
                let first_new = (w.start..w.end).find(|&f| !cam_done[f]).unwrap_or(w.end);
                if first || list.get(wi + 1).is_none_or(|n| n.start > first_new) {
                    return Err(Error::Degenerate(format!(
                        "frames {}..{}: no perspective window covers frame {first_new} (this \
                         window: {why})",
                        w.start, w.end
                    )));
                }
                continue;
            }
        };
        for f in w.start..w.end {
            if cam_done[f] {
                continue;
            }
            // X_c = R x + t with x = Aᵀ (X − b) / sc; scaled by sc (same projection):
            // R' = R Aᵀ, t' = sc t − R' b.
            let r = m.rotations[f - w.start] * a.transpose();
            translations[f] = m.translations[f - w.start] * sc - r * b;
            rotations[f] = r;
            cam_done[f] = true;
        }
        for (k, &p) in w.tracks.iter().enumerate() {
            if !placed[p] {
                points[p] = a * m.points[k] * sc + b;
                placed[p] = true;
                placed_n[p] = seen[k];
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
    Ok((rotations, translations, points, placed))
}

/// Tracks no window placed (seen in fewer than 2 frames of every window: re-acquired far
/// apart) start on the ray of their first observation, at the median depth of the placed
/// points in frame 0; the adjustment's point solve then moves them. `O(n_obs)`.
fn place_unplaced(
    g: &projective::bundle::Graph,
    focal: f64,
    rotations: &[Matrix3<f64>],
    translations: &[Vector3<f64>],
    points: &mut [Vector3<f64>],
    placed: &[bool],
) {
    if placed.iter().all(|&p| p) {
        return;
    }
    let mut depths: Vec<f64> = (0..g.n_pts)
        .filter(|&p| placed[p] && g.track(p).next().is_some_and(|o| g.cam[o] == 0))
        .map(|p| (rotations[0] * points[p] + translations[0])[2])
        .filter(|z| z.is_finite() && *z > 0.0)
        .collect();
    depths.sort_by(f64::total_cmp);
    let depth = depths.get(depths.len() / 2).copied().unwrap_or(1.0);
    for p in 0..g.n_pts {
        if placed[p] {
            continue;
        }
        let Some(o) = g.track(p).next() else { continue };
        let f = g.cam[o];
        let ray = Vector3::new(g.w[o][0] / focal, g.w[o][1] / focal, 1.0) * depth;
        // X = Rᵀ (X_c − t).
        points[p] = rotations[f].transpose() * (ray - translations[f]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// On a noise-free corridor the metric reference's cameras, mapped back into the
    /// projective graph's units, reproject every placed track to within a tenth of a pixel
    /// of its observations, and its points are the truth up to a similarity to within 1 %
    /// of their spread (a drifted chain would be off by pixels and by tens of %).
    ///
    /// Both ways: each window's projective fit made here, and the windows' projective fits
    /// given (as the projective chain's first pass gives them), one of them failed and one
    /// far off (both fitted again).
    #[test]
    fn the_metric_reference_reprojects_a_noise_free_corridor() {
        let frames = 80;
        let (obs, truth) = crate::synth::perspective_corridor(frames, 60, 0.0, 1);
        let n_tracks = truth.len();
        let order = projective::observation_order(&obs, frames, n_tracks).unwrap();
        let norm = Normalization::of_points(|| obs.iter().map(|o| o.xy));
        let g = projective::observation_graph(&obs, &order, frames, n_tracks, &norm);
        let px = 1.0 / norm.scale;
        let (wcfg, pcfg) = (WindowConfig::default(), ProjectiveConfig::default());
        let mut own: Vec<std::result::Result<ProjectiveFit, String>> =
            windowed::collect_windows(&g, &wcfg)
                .unwrap()
                .iter()
                .map(|(start, end, tracks, meas)| {
                    windowed::fit_window(*start, *end, tracks, meas, &wcfg, &pcfg)
                        .map_err(|e| e.to_string())
                })
                .collect();
        assert!(own.len() >= 3 && own.iter().all(|f| f.is_ok()));
        own[1] = Err("failed".into());
        if let Some(Ok(f)) = own.last_mut() {
            f.rms_px = 1e3;
            f.model.points.iter_mut().for_each(|x| x[0] += 1.0);
        }
        // The given fits, mapped into other image units, reproject the windows' measurements
        // mapped likewise; the failed and the far-off ones are not used.
        let to_local = Normalization {
            centre: [-0.12, 0.28],
            scale: 2.5,
        };
        let t = Matrix3::new(2.5, 0.0, 0.3, 0.0, 2.5, -0.7, 0.0, 0.0, 1.0);
        let given = OwnFits {
            fits: &own,
            to_local,
        };
        let reuse = given.reusable();
        assert_eq!(reuse.iter().filter(|&&r| r).count(), own.len() - 2);
        assert!(!reuse[1] && !reuse[own.len() - 1]);
        for (k, (_, _, tracks, meas)) in windowed::collect_windows(&g, &wcfg)
            .unwrap()
            .iter()
            .enumerate()
        {
            let Some(m) = given.mapped(k).filter(|_| reuse[k]) else {
                continue;
            };
            for (i, _) in meas.visible.iter().enumerate().filter(|v| *v.1) {
                let (f, k) = (i / tracks.len(), i % tracks.len());
                let y = projective::project(&m.cameras[f], &m.points[k]);
                let w = t * Vector3::new(meas.w[(2 * f, k)], meas.w[(2 * f + 1, k)], 1.0);
                assert!((y[0] - w[0]).hypot(y[1] - w[1]) < 1e-6, "{y:?} vs {w:?}");
            }
        }
        for given in [None, Some(&own[..])] {
            check_reference(
                &g,
                px,
                &truth,
                metric_reference(&g, px, &pcfg, &wcfg, given),
            );
        }
    }

    fn check_reference(
        g: &projective::bundle::Graph,
        px: f64,
        truth: &[Vector3<f64>],
        reference: Result<(Vec<f64>, Vec<f64>, Vec<bool>)>,
    ) {
        let n_tracks = truth.len();
        let (cams, pts, placed) = reference.unwrap();
        let mut worst: f64 = 0.0;
        let (mut est, mut tru) = (Vec::new(), Vec::new());
        for p in (0..n_tracks).filter(|&p| placed[p]) {
            let x: [f64; 4] = pts[4 * p..4 * p + 4].try_into().unwrap();
            for o in g.track(p) {
                let c: [f64; 12] = cams[12 * g.cam[o]..12 * g.cam[o] + 12].try_into().unwrap();
                let y = projective::project(&c, &x);
                worst = worst.max(px * (y[0] - g.w[o][0]).hypot(y[1] - g.w[o][1]));
            }
            est.push(Vector3::new(x[0], x[1], x[2]));
            tru.push(truth[p]);
        }
        assert!(
            est.len() > n_tracks / 2,
            "{} of {n_tracks} placed",
            est.len()
        );
        // Not exact: the principal point is assumed at the tracks' bounding-box centre (the
        // truth's is (320, 240)) and the chained windows are not adjusted together (only
        // the points re-solved): they disagree a little where they meet. Measured: worst
        // 0.113 px (0.040 px with the ten metric iterations of before), structure 0.30 %
        // (the same).
        assert!(worst < 0.25, "worst reprojection {worst} px");
        let a = crate::eval::align_similarity(&est, &tru, false).unwrap();
        assert!(a.relative_rms < 0.01, "structure off by {}", a.relative_rms);
    }

    /// The focal length's sample: every window up to `m` (or with `m` = 0); beyond,
    /// exactly `m` of them, the first and the last included, evenly spread.
    #[test]
    fn the_focal_sample_spreads_over_the_sequence() {
        for (n, m) in [(0, 32), (1, 32), (5, 32), (32, 32), (99, 0)] {
            assert!(focal_sample(n, m).iter().all(|&k| k) && focal_sample(n, m).len() == n);
        }
        assert_eq!(focal_sample(5, 1), [false, false, true, false, false]);
        for (n, m) in [(33, 32), (99, 32), (999, 32), (5000, 32), (5, 2), (7, 3)] {
            let k = focal_sample(n, m);
            let idx: Vec<usize> = (0..n).filter(|&i| k[i]).collect();
            assert_eq!(idx.len(), m, "n = {n}");
            assert_eq!((idx[0], idx[m - 1]), (0, n - 1));
            let step = (n - 1) as f64 / (m - 1) as f64;
            for w in idx.windows(2) {
                assert!(((w[1] - w[0]) as f64 - step).abs() <= 1.0, "n = {n}: {w:?}");
            }
        }
    }
}
