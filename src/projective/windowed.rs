//! Starts for long sequences in time linear in the frames: overlapping windows of frames,
//! each factorized on its own and chained into one frame.
//!
//! The dense affine completion ([`crate::completion`]) factorises a `(2F·4)²` camera system
//! and a dense `F×N` start: fine for hundreds of frames, impossible for a 20 000-frame video.
//! A video's tracks are short, so frames far apart share nothing and a window of frames is
//! a small, well-connected problem. Windows are frames `[s, s + window)` for `s = 0, stride,
//! 2·stride, …` (`stride = window − overlap`; the last one ends at the last frame), each with
//! the tracks it sees in ≥ 2 of its frames, completed by the damped Wiberg solver
//! ([`crate::completion::complete`], data-driven start). Window 0 fixes the global frame; a
//! frame's camera comes from the first window that contains it, a track's point from the
//! first window that places it.
//!
//! * [`projective_start`] (the default): each window is fitted projectively
//!   ([`super::fit`]) and mapped by the homography that best carries its points onto the
//!   already placed ones; then a sliding-window bundle adjustment refines it with the
//!   previous window, whose own frames are held fixed. A window whose own fit fails or
//!   ends far above the noise level of the windows before it (a local minimum of its
//!   affine completion: 2 windows in 1 000 on a 20 000-frame corridor) is instead extended
//!   from the chain: its new frames resected from the placed points, its new tracks
//!   triangulated (`extend_chain`). A chain whose cameras, in one frame, no longer fit the
//!   data (the drift of a thousand homographies) is placed again window by window on a
//!   metric reference ([`WindowConfig::drift_ratio`]).
//! * [`affine_start`]: the affine windows are chained by the affine maps `X ↦ A X + b`
//!   between shared tracks (linear least squares, ≥ 4 tracks); the cameras become `M A⁻¹`,
//!   `t − M A⁻¹ b`. Tracks no window placed are left at the origin for the
//!   variable-projection stage that follows.
//!
//! Cost: `Σ_k` (one window's fit and local adjustment) — with a fixed window, linear in the
//! frames and the observations; memory of one window at a time plus `O(F + N)` for the
//! result. How many solves the global bundle adjustment then needs still grows with the
//! sequence (docs/results.md).

use faer::Mat;
use nalgebra::{Matrix3, Matrix4, Vector3, Vector4};
use rayon::prelude::*;

use super::bundle::Graph;
use crate::completion::{self, CompletionConfig};
use crate::{Error, Event, Measurements, NoopObserver, Observer, Result};

/// Settings of [`affine_start`]. Every field has a documented default.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct WindowConfig {
    /// Frames per window. Default 40.
    pub window: usize,
    /// Frames shared by consecutive windows. Default 20.
    pub overlap: usize,
    /// The per-window completion. Default [`CompletionConfig::default`] (affine model,
    /// damped Wiberg, data-driven start).
    pub completion: CompletionConfig,
    /// Fit each window projectively and chain the windows by homographies
    /// ([`projective_start`]) rather than chaining affine windows ([`affine_start`]).
    /// Default true (measured: docs/results.md).
    pub projective: bool,
    /// With `projective`: after chaining each window, a bundle adjustment (at most this
    /// many solves) of it and the previous window, the previous window's own frames held
    /// fixed — a sliding-window bundle adjustment that keeps the chain consistent as it
    /// grows. 0 skips it. Default 20.
    pub local_iterations: usize,
    /// A track shared with the frames already placed anchors a window's map (similarity,
    /// affine map or homography) only when it is seen in at least this many frames of the
    /// window and of the window that placed it: a track seen in two or three frames of a
    /// window has a poorly determined depth there, and such anchors make the chain drift
    /// (a 2 000-frame corridor's sparse start: 3 395 px RMS with every shared track, 0.51 px
    /// with this rule; docs/results.md). When fewer than 8 shared tracks qualify, every
    /// shared track is used. Default 6.
    pub min_anchor_observations: usize,
    /// With `projective`: when the chained windows, mapped into one frame, reproject at
    /// more than this many times the median of the windows' own RMS, the frame has drifted
    /// (a chain of a thousand homographies: a 20 000-frame corridor started its global
    /// adjustment at 76 420 px) and the windows are placed again, each by its own
    /// homography onto a metric reference ([`crate::perspective`]'s windows chained by
    /// similarities, which do not drift into ill-conditioned frames). `None` never does
    /// this (and keeps no window fits for it); `Some(0.0)` always does. Default `Some(3.0)`.
    #[serde(default = "default_drift_ratio")]
    pub drift_ratio: Option<f64>,
    /// The geodesic acceleration (`LmConfig::geodesic_acceleration`'s `α`) of the global
    /// projective adjustment when the windows were placed on the metric reference (see
    /// `drift_ratio`), where the adjustment's own setting is 0. That start's long-range
    /// shape is the metric reference's, and the adjustment then moves it along the
    /// chain's soft modes, a curved valley where the plain damped steps alternate
    /// acceptance and rejection: on a 2 000-frame corridor forced onto the reference, 89
    /// solves without it, 32 with `α = 0.75`, to a lower cost (docs/results.md). From the
    /// chain the start is near the optimum and the adjustment keeps its own setting. 0
    /// disables it. Default 0.75.
    #[serde(default = "default_reference_geodesic_acceleration")]
    pub reference_geodesic_acceleration: f64,
}

fn default_reference_geodesic_acceleration() -> f64 {
    0.75
}

fn default_drift_ratio() -> Option<f64> {
    Some(3.0)
}

impl Default for WindowConfig {
    fn default() -> Self {
        Self {
            window: 40,
            overlap: 20,
            completion: CompletionConfig::default(),
            projective: true,
            local_iterations: 20,
            min_anchor_observations: 6,
            drift_ratio: default_drift_ratio(),
            reference_geodesic_acceleration: default_reference_geodesic_acceleration(),
        }
    }
}

/// Affine cameras (12 per frame: `[M_f t_f; 0 0 0 1]` row-major) and points (3 per track)
/// for the observations of `g`, in `g`'s coordinates.
///
/// Errors: [`Error::InvalidConfig`] for `overlap ≥ window` or `window < 2`;
/// [`Error::Disconnected`]-like gaps as [`Error::Degenerate`] naming the window (fewer than
/// 4 tracks shared with the frames before it), and the completion's input errors for a
/// window (e.g. a frame seeing fewer than 4 of the window's tracks).
pub fn affine_start(g: &Graph, cfg: &WindowConfig) -> Result<(Vec<f64>, Vec<f64>)> {
    let nf = g.n_cams;
    let np = g.n_pts;
    let mut cams = vec![f64::NAN; 12 * nf];
    let mut cam_done = vec![false; nf];
    let mut pts = vec![0.0; 3 * np];
    let mut placed = vec![false; np];
    let mut placed_n = vec![0; np];
    let mut first = true;
    for_each_window(g, cfg, |start, end, tracks, meas| {
        let c = complete_window(start, end, tracks, meas, cfg, None)?;
        let seen = seen_in_window(meas, tracks.len());
        // Map into the global frame: X_glob = A X + b.
        let (a, b) = if first {
            (Matrix3::identity(), Vector3::zeros())
        } else {
            let shared = anchors(tracks, &placed, &seen, &placed_n, cfg);
            if shared.len() < 4 {
                return Err(too_few_shared(start, end, shared.len(), 4));
            }
            let pairs = shared.iter().map(|&k| {
                let p = tracks[k];
                (
                    Vector3::new(c.s[(0, k)], c.s[(1, k)], c.s[(2, k)]),
                    Vector3::new(pts[3 * p], pts[3 * p + 1], pts[3 * p + 2]),
                )
            });
            let (a, b) = fit_affine_map(pairs).ok_or_else(|| {
                Error::Degenerate(format!(
                    "frames {start}..{end}: the tracks shared with earlier frames are coplanar; \
                     the windows cannot be chained"
                ))
            })?;
            (a, b)
        };
        let ainv = a.try_inverse().ok_or_else(|| {
            Error::Degenerate(format!(
                "frames {start}..{end}: the affine map to the earlier frames is singular"
            ))
        })?;
        for f in start..end {
            if cam_done[f] {
                continue;
            }
            let lf = f - start;
            for r in 0..2 {
                let m = Vector3::new(
                    c.m[(2 * lf + r, 0)],
                    c.m[(2 * lf + r, 1)],
                    c.m[(2 * lf + r, 2)],
                );
                // M X + t = M A⁻¹ (X_glob − b) + t.
                let mg = ainv.transpose() * m;
                for k in 0..3 {
                    cams[12 * f + 4 * r + k] = mg[k];
                }
                cams[12 * f + 4 * r + 3] = c.t[2 * lf + r] - mg.dot(&b);
            }
            cams[12 * f + 8..12 * f + 12].copy_from_slice(&[0.0, 0.0, 0.0, 1.0]);
            cam_done[f] = true;
        }
        for (k, &p) in tracks.iter().enumerate() {
            if placed[p] {
                continue;
            }
            let x = a * Vector3::new(c.s[(0, k)], c.s[(1, k)], c.s[(2, k)]) + b;
            pts[3 * p..3 * p + 3].copy_from_slice(&[x[0], x[1], x[2]]);
            placed[p] = true;
            placed_n[p] = seen[k];
        }
        first = false;
        Ok(())
    })?;
    Ok((cams, pts))
}

/// Projective cameras (12 per frame) and points (4 per track; zero for tracks no window
/// places) for the observations of `g`, in `g`'s coordinates: each window is fitted by
/// the projective chain ([`super::fit`]: affine completion, `pcfg`'s bridge, projective
/// bundle adjustment) and mapped into window 0's projective frame by the homography `G`
/// with `X_glob ≃ G X` over the tracks it shares with the windows before it (linear: the
/// smallest eigenvector of `Σ AᵀA` over the rows `X_glob,i (G X)_j − X_glob,j (G X)_i`,
/// ≥ 6 tracks needed); its cameras become `P G⁻¹`. A chain of accurate local projective
/// reconstructions drifts far less than one of affine ones, which leaves the global bundle
/// adjustment only the accumulated inconsistencies to correct.
///
/// **Drift.** The chain is consistent only up to a slowly varying homography, and over a
/// thousand windows the composed homographies leave the early frames numerically lost in
/// one frame (a 20 000-frame corridor: 76 420 px RMS). So the chained cameras are checked:
/// every placed track triangulated from them and reprojected. Above
/// [`WindowConfig::drift_ratio`] times the median of the windows' own RMS, a metric
/// reference is built ([`crate::perspective`]'s windows chained by similarities — a chain of
/// similarities does not drift into ill-conditioned frames — with its points re-solved for
/// the chained cameras) and every window's own fit is placed again by its own homography onto
/// the reference's points (conditioned as Hartley's DLT), with no sliding-window adjustment:
/// those move the chain's frame a little at each window, a random walk along its soft
/// projective modes (on a 300-frame corridor 300 px away from the reference after 14
/// windows), while each window's homography lands it on the reference. The global
/// adjustment starts from there (a 300-frame corridor forced onto the reference: the same
/// optimum, 0.4632 px, in 16 solves against the chain's 12).
///
/// Cost: one window's projective fit per `stride` frames: linear in the frames; with a
/// reference, the perspective windows (each upgraded from the window's own projective fit,
/// kept from the first pass: `O(window · tracks)` memory each), `O(n_obs)` per metric
/// iteration.
///
/// After each window it sends an [`Event::Iteration`] (solver `"windows"`, iteration = the
/// window's index) with the reprojection RMS of the window's observations in the chained
/// frame (`px` converts the graph's units to pixels): a chain that breaks shows where.
///
/// Returns the cameras and points with which route they took
/// ([`ProjectiveStart::on_reference`]): the global adjustment from the reference gets
/// [`WindowConfig::reference_geodesic_acceleration`].
pub fn projective_start(
    g: &Graph,
    cfg: &WindowConfig,
    pcfg: &super::ProjectiveConfig,
    px: f64,
    observer: &mut dyn Observer,
) -> Result<ProjectiveStart> {
    let mut fits = Vec::new();
    let keep = cfg.drift_ratio.map(|r| (r, &mut fits));
    let ratio = keep.as_ref().map(|k| k.0);
    let chained = chain_windows(
        g,
        cfg,
        pcfg,
        px,
        None,
        Fits::Run(keep.map(|k| k.1)),
        observer,
    )?;
    let from_chain = |c: Chained| ProjectiveStart {
        cams: c.cams,
        pts: c.pts,
        on_reference: false,
    };
    let Some(ratio) = ratio else {
        return Ok(from_chain(chained));
    };
    let reference_rms = chained.median_window_rms.max(NOISE_FLOOR);
    let rms = start_rms(g, &chained.cams, &chained.pts);
    if rms <= ratio * reference_rms {
        return Ok(from_chain(chained));
    }
    observer.on_event(&Event::Warning {
        message: &format!(
            "the chained projective windows, mapped into one frame, reproject at {:.3} px RMS \
             ({:.1}× their median window; drift ratio {ratio}): the windows are placed again, \
             each on a metric reference (perspective windows chained by similarities)",
            px * rms,
            rms / reference_rms
        ),
    });
    let t0 = std::time::Instant::now();
    observer.on_event(&Event::StageStarted {
        stage: "metric-reference",
    });
    let reference = crate::perspective::long::metric_reference(g, px, pcfg, cfg, Some(&fits));
    observer.on_event(&Event::StageFinished {
        stage: "metric-reference",
        seconds: t0.elapsed().as_secs_f64(),
    });
    let (_, ref_pts, ref_placed) = match reference {
        Ok(r) => r,
        Err(e) => {
            observer.on_event(&Event::Warning {
                message: &format!(
                    "no metric reference for the projective windows ({e}); the global \
                     adjustment starts from the chain as it is"
                ),
            });
            return Ok(from_chain(chained));
        }
    };
    drop(chained);
    let reference = Reference {
        pts: ref_pts,
        placed: ref_placed,
    };
    let chained = chain_windows(
        g,
        cfg,
        pcfg,
        px,
        Some(&reference),
        Fits::Replay(fits.into_iter()),
        observer,
    )?;
    Ok(ProjectiveStart {
        cams: chained.cams,
        pts: chained.pts,
        on_reference: true,
    })
}

/// What [`projective_start`] returns: cameras (12 per frame) and points (4 per track), and
/// whether the windows were placed on the metric reference (the chain had drifted).
#[derive(Debug, Clone)]
pub struct ProjectiveStart {
    pub cams: Vec<f64>,
    pub pts: Vec<f64>,
    pub on_reference: bool,
}

/// Reprojection RMS (graph units) of the chained cameras `cams`: each placed track (`pts`
/// non-zero) triangulated from them ([`super::dlt_views`]) and reprojected — the cameras'
/// figure, as the variable-projection adjustment that follows sees them (a point the
/// chain placed with a poor depth does not count against them). `O(n_obs)`.
fn start_rms(g: &Graph, cams: &[f64], pts: &[f64]) -> f64 {
    let (mut cost, mut n) = (0.0, 0usize);
    for p in 0..g.n_pts {
        if pts[4 * p..4 * p + 4].iter().all(|v| *v == 0.0) || g.track(p).len() < 2 {
            continue;
        }
        let x = super::dlt_views(
            g.track(p)
                .map(|o| (&cams[12 * g.cam[o]..12 * g.cam[o] + 12], g.w[o])),
        );
        for o in g.track(p) {
            let f = g.cam[o];
            let c: [f64; 12] = cams[12 * f..12 * f + 12].try_into().expect("12 entries");
            let y = super::project(&c, &x);
            let e = (y[0] - g.w[o][0]).powi(2) + (y[1] - g.w[o][1]).powi(2);
            cost += if e.is_finite() { e } else { f64::MAX.sqrt() };
            n += 2;
        }
    }
    (cost / n.max(1) as f64).sqrt()
}

/// Points (4 per track, `w = 1`, graph units) of a drift-free reference reconstruction and
/// which tracks it placed: the target of every window's homography in
/// [`chain_windows`]'s second pass.
struct Reference {
    pts: Vec<f64>,
    placed: Vec<bool>,
}

/// Where [`chain_windows`] gets each window's own projective fit: fitted now (in parallel
/// batches; kept, in order, when a vector is given), or replayed from an earlier pass.
enum Fits<'a> {
    Run(Option<&'a mut Vec<std::result::Result<super::ProjectiveFit, String>>>),
    Replay(std::vec::IntoIter<std::result::Result<super::ProjectiveFit, String>>),
}

/// What [`chain_windows`] built: cameras (12 per frame), points (4 per track) and the
/// median of the windows' own reprojection RMS (graph units).
struct Chained {
    cams: Vec<f64>,
    pts: Vec<f64>,
    median_window_rms: f64,
}

/// The homography `G` with `y ≃ G x` over `pairs` (linear: the smallest eigenvector of
/// `Σ AᵀA` over the rows `y_i (G x)_j − y_j (G x)_i`; ≥ 5 pairs in general position).
/// `O(n)`.
fn dlt_homography(pairs: impl Iterator<Item = (Vector4<f64>, Vector4<f64>)>) -> Matrix4<f64> {
    let mut ata = nalgebra::SMatrix::<f64, 16, 16>::zeros();
    for (x, y) in pairs {
        for i in 0..4 {
            for j in i + 1..4 {
                // y_i (G x)_j − y_j (G x)_i = Σ_l (y_i x_l G_jl − y_j x_l G_il).
                let mut row = nalgebra::SVector::<f64, 16>::zeros();
                for l in 0..4 {
                    row[4 * j + l] += y[i] * x[l];
                    row[4 * i + l] -= y[j] * x[l];
                }
                ata += row * row.transpose();
            }
        }
    }
    let e = nalgebra::SymmetricEigen::new(ata);
    let v = e.eigenvectors.column(e.eigenvalues.imin());
    Matrix4::from_fn(|r, c| v[4 * r + c])
}

/// The homography carrying a window's points `x` onto finite reference points `y`
/// (`w = 1`): [`dlt_homography`] after centring the `y` at their centroid and scaling them
/// to unit RMS distance (Hartley's conditioning; a window's reference points can lie far
/// from the reference frame's origin), then undone. `None` for fewer than 6 pairs or
/// coincident points.
fn homography_to_reference(pairs: &[(Vector4<f64>, Vector4<f64>)]) -> Option<Matrix4<f64>> {
    if pairs.len() < 6 {
        return None;
    }
    let n = pairs.len() as f64;
    let c = pairs.iter().map(|(_, y)| y.xyz()).sum::<Vector3<f64>>() / n;
    let spread = (pairs
        .iter()
        .map(|(_, y)| (y.xyz() - c).norm_squared())
        .sum::<f64>()
        / n)
        .sqrt();
    if !(spread > 0.0 && spread.is_finite()) {
        return None;
    }
    let s = 1.0 / spread;
    let mut t = Matrix4::<f64>::identity() * s;
    t[(3, 3)] = 1.0;
    for k in 0..3 {
        t[(k, 3)] = -s * c[k];
    }
    let g = dlt_homography(pairs.iter().map(|(x, y)| (*x, t * y)));
    Some(t.try_inverse()? * g)
}

/// The projective chain of [`projective_start`]: every window's own fit (`fits`), placed in
/// order — onto the tracks already placed (re-anchoring the working frame as it goes) or,
/// with a `reference`, onto the reference's points (one frame throughout: no drift).
#[allow(clippy::too_many_arguments)]
fn chain_windows(
    g: &Graph,
    cfg: &WindowConfig,
    pcfg: &super::ProjectiveConfig,
    px: f64,
    reference: Option<&Reference>,
    fits: Fits<'_>,
    observer: &mut dyn Observer,
) -> Result<Chained> {
    let nf = g.n_cams;
    let np = g.n_pts;
    let mut cams = vec![f64::NAN; 12 * nf];
    let mut cam_done = vec![false; nf];
    let mut pts = vec![0.0; 4 * np];
    let mut placed = vec![false; np];
    let mut placed_n = vec![0; np];
    let mut first = true;
    let mut index = 0;
    let mut window_rms: Vec<f64> = Vec::new();
    let mut frame = WorkingFrame::new(g);
    let mut place = |start: usize,
                     end: usize,
                     tracks: &[usize],
                     meas: &Measurements,
                     fit: Result<super::ProjectiveFit>|
     -> Result<()> {
        let seen = seen_in_window(meas, tracks.len());
        // A window whose own fit failed, or ended far above the chain's noise level (a
        // local minimum of its affine completion), is extended from the chain instead.
        let noise = median(&window_rms).max(NOISE_FLOOR);
        let failed = match &fit {
            Err(_) => true,
            Ok(f) => !first && !(f.rms_px <= FAILED_WINDOW_RATIO * noise),
        };
        let reanchor = if failed && !first {
            let why = match &fit {
                Err(e) => e.to_string(),
                Ok(f) => format!(
                    "its own fit ended at {:.3} px RMS, {:.1}× the chain's median window",
                    px * f.rms_px,
                    f.rms_px / noise
                ),
            };
            extend_chain(
                ChainState {
                    cams: &mut cams,
                    cam_done: &mut cam_done,
                    pts: &mut pts,
                    placed: &mut placed,
                    placed_n: &mut placed_n,
                },
                start,
                tracks,
                meas,
                &seen,
                noise,
            )
            .map_err(|e| {
                Error::Degenerate(format!(
                    "window of frames {start}..{end}: {why}; extending the chain failed too: {e}"
                ))
            })?;
            observer.on_event(&Event::Warning {
                message: &format!(
                    "window of frames {start}..{end}: {why}; its frames and tracks were \
                     extended from the chain instead (resection and triangulation)"
                ),
            });
            None
        } else {
            let fit = fit?;
            window_rms.push(fit.rms_px);
            let model = fit.model;
            let on_reference = reference.and_then(|r| {
                let pairs: Vec<_> = reference_anchors(tracks, &r.placed, &seen, cfg)
                    .into_iter()
                    .map(|k| {
                        let p = tracks[k];
                        (
                            Vector4::from(model.points[k]),
                            Vector4::from_column_slice(&r.pts[4 * p..4 * p + 4]),
                        )
                    })
                    .collect();
                homography_to_reference(&pairs)
            });
            let gm = if let Some(gm) = on_reference {
                gm
            } else if first {
                Matrix4::identity()
            } else {
                let shared = anchors(tracks, &placed, &seen, &placed_n, cfg);
                if shared.len() < 6 {
                    return Err(too_few_shared(start, end, shared.len(), 6));
                }
                dlt_homography(shared.iter().map(|&k| {
                    let p = tracks[k];
                    (
                        Vector4::from(model.points[k]),
                        Vector4::from_column_slice(&pts[4 * p..4 * p + 4]),
                    )
                }))
            };
            let ginv = gm.try_inverse().ok_or_else(|| {
                Error::Degenerate(format!(
                    "frames {start}..{end}: the homography to the earlier frames is singular"
                ))
            })?;
            for f in start..end {
                if cam_done[f] {
                    continue;
                }
                let p = model.cameras[f - start];
                for r in 0..3 {
                    for col in 0..4 {
                        cams[12 * f + 4 * r + col] =
                            (0..4).map(|k| p[4 * r + k] * ginv[(k, col)]).sum();
                    }
                }
                super::bundle::normalize(&mut cams[12 * f..12 * f + 12]);
                cam_done[f] = true;
            }
            for (k, &p) in tracks.iter().enumerate() {
                if placed[p] {
                    continue;
                }
                let x = Vector4::from(model.points[k]);
                let y = gm * x;
                pts[4 * p..4 * p + 4].copy_from_slice(y.as_slice());
                super::bundle::normalize(&mut pts[4 * p..4 * p + 4]);
                placed[p] = true;
                placed_n[p] = seen[k];
            }
            // On the reference the frame is one throughout: no re-anchoring.
            reference.is_none().then_some((ginv, gm))
        };
        if !first && cfg.local_iterations > 0 && reference.is_none() {
            // Sliding-window bundle adjustment: this window and the previous one, the
            // previous window's own frames held fixed (they anchor the gauge). Not on a
            // reference: these adjustments move the chain's frame a little at each window
            // (a random walk along the chain's soft projective modes: 300 px between the
            // chain and the reference after 14 windows of a 300-frame corridor), while each
            // window's homography lands it on the reference.
            let lo = start.saturating_sub(cfg.window - cfg.overlap);
            local_refine(
                g,
                &mut cams,
                &mut pts,
                lo,
                start,
                end,
                cfg.local_iterations,
                pcfg,
            )?;
        }
        let (cost, n) = window_cost(&cams, &pts, start, tracks, meas);
        observer.on_event(&Event::Iteration {
            solver: "windows",
            run: 0,
            iteration: index,
            cost,
            rms: px * (cost / n.max(1) as f64).sqrt(),
            lambda: f64::NAN,
        });
        frame.activate(tracks, &placed);
        if let Some((h, h_inv)) = reanchor.filter(|_| !first) {
            // The chain goes on in this window's own frame (`X_win = G⁻¹ X`).
            frame.reanchor(&h, &h_inv, start, &mut cams, &cam_done, &mut pts);
        }
        index += 1;
        first = false;
        Ok(())
    };
    // The windows' own fits are independent: a batch of them runs in parallel, then the
    // batch is chained in order (memory: one batch of windows).
    let batch_size = 4 * rayon::current_num_threads().max(1);
    let mut batch: Vec<Window> = Vec::new();
    let mut fits = fits;
    let mut flush = |batch: &mut Vec<Window>| -> Result<()> {
        let fitted: Vec<Result<super::ProjectiveFit>> = match &mut fits {
            Fits::Run(keep) => {
                let fitted: Vec<_> = batch
                    .par_iter()
                    .map(|(start, end, tracks, meas)| {
                        fit_window(*start, *end, tracks, meas, cfg, pcfg)
                    })
                    .collect();
                if let Some(keep) = keep {
                    keep.extend(fitted.iter().map(|f| match f {
                        Ok(f) => Ok(f.clone()),
                        Err(e) => Err(e.to_string()),
                    }));
                }
                fitted
            }
            Fits::Replay(it) => (0..batch.len())
                .map(|_| match it.next() {
                    Some(Ok(f)) => Ok(f),
                    Some(Err(e)) => Err(Error::Degenerate(e)),
                    None => Err(Error::Degenerate("window fit not recorded".into())),
                })
                .collect(),
        };
        for ((start, end, tracks, meas), fit) in batch.drain(..).zip(fitted) {
            place(start, end, &tracks, &meas, fit)?;
        }
        Ok(())
    };
    for_each_window(g, cfg, |start, end, tracks, meas| {
        batch.push((start, end, tracks.to_vec(), meas.clone()));
        if batch.len() >= batch_size {
            flush(&mut batch)?;
        }
        Ok(())
    })?;
    flush(&mut batch)?;
    frame.finish(&mut cams, &mut pts);
    Ok(Chained {
        cams,
        pts,
        median_window_rms: median(&window_rms),
    })
}

/// The window's tracks (indices into `tracks`) that anchor its homography onto the
/// reference: placed there and seen in ≥ [`WindowConfig::min_anchor_observations`] frames
/// of the window; every placed one when fewer than 8 qualify.
fn reference_anchors(
    tracks: &[usize],
    placed: &[bool],
    seen: &[usize],
    cfg: &WindowConfig,
) -> Vec<usize> {
    let strong: Vec<usize> = (0..tracks.len())
        .filter(|&k| placed[tracks[k]] && seen[k] >= cfg.min_anchor_observations)
        .collect();
    if strong.len() >= 8 {
        return strong;
    }
    (0..tracks.len()).filter(|&k| placed[tracks[k]]).collect()
}

/// The projective frame the chain is built in. A chain kept in window 0's frame drifts
/// into a frame where the far end of a long sequence is badly conditioned (its points
/// close to that frame's plane at infinity): on a 20 000-frame corridor the homographies
/// and sliding-window adjustments past frame 8 000 broke the chain in four places (up to
/// 950 px RMS) though each of those stretches chains at the noise level on its own. So
/// after each window is placed the chain continues in that window's own frame (fitted
/// from an affine start, well conditioned where the work goes on): the entities the next
/// windows can touch — cameras from the window's first frame on, points of tracks seen
/// there or later — are mapped into it; the others are frozen with the index of their
/// frame (an *epoch*), and [`Self::finish`] maps every frozen entity into the last epoch's
/// frame once, by the product of the epochs' homographies. The result is the same
/// reconstruction up to one homography, built in well-conditioned coordinates. (That last
/// mapping is itself ill-conditioned over a thousand windows: at 20 000 frames the early
/// frames are lost in the last window's frame; docs/math.md §8.) Cost:
/// `O(active entities)` per window and `O(F + N)` at the end (linear in the frames for
/// tracks of bounded length).
struct WorkingFrame {
    /// Per track, the last frame that sees it.
    last_frame: Vec<usize>,
    /// Placed tracks not frozen yet (each once: `is_active`).
    active: Vec<usize>,
    is_active: Vec<bool>,
    /// Frames below this are frozen.
    frozen_below: usize,
    /// Epoch a frozen camera / point was stored in (`u32::MAX`: not frozen).
    epoch_cam: Vec<u32>,
    epoch_pt: Vec<u32>,
    /// Per epoch, the homography `H_e` from its frame to the next (`X_{e+1} = H_e X_e`).
    epochs: Vec<Matrix4<f64>>,
}

impl WorkingFrame {
    fn new(g: &Graph) -> Self {
        let last_frame = (0..g.n_pts)
            .map(|p| g.track(p).map(|o| g.cam[o]).max().unwrap_or(0))
            .collect();
        Self {
            last_frame,
            active: Vec::new(),
            is_active: vec![false; g.n_pts],
            frozen_below: 0,
            epoch_cam: vec![u32::MAX; g.n_cams],
            epoch_pt: vec![u32::MAX; g.n_pts],
            epochs: Vec::new(),
        }
    }

    /// Marks the placed ones of `tracks` active (they live in the working frame).
    fn activate(&mut self, tracks: &[usize], placed: &[bool]) {
        for &p in tracks {
            if placed[p] && !self.is_active[p] && self.epoch_pt[p] == u32::MAX {
                self.is_active[p] = true;
                self.active.push(p);
            }
        }
    }

    /// Continues in a new frame, `X' = h X`, `P' = P h⁻¹`, after a window starting at
    /// frame `start` was placed: cameras before `start` and points of tracks last seen
    /// before it are frozen in the current epoch; the rest is mapped.
    fn reanchor(
        &mut self,
        h: &Matrix4<f64>,
        h_inv: &Matrix4<f64>,
        start: usize,
        cams: &mut [f64],
        cam_done: &[bool],
        pts: &mut [f64],
    ) {
        let e = self.epochs.len() as u32;
        for f in self.frozen_below..start {
            self.epoch_cam[f] = e;
        }
        self.frozen_below = self.frozen_below.max(start);
        for f in self.frozen_below..cam_done.len() {
            if !cam_done[f] {
                break;
            }
            map_camera(&mut cams[12 * f..12 * f + 12], h_inv);
        }
        let (last, epoch_pt, is_active) =
            (&self.last_frame, &mut self.epoch_pt, &mut self.is_active);
        self.active.retain(|&p| {
            if last[p] < start {
                epoch_pt[p] = e;
                is_active[p] = false;
                return false;
            }
            map_point(&mut pts[4 * p..4 * p + 4], h);
            true
        });
        self.epochs.push(*h);
    }

    /// Maps every frozen camera and point into the last epoch's frame.
    fn finish(&self, cams: &mut [f64], pts: &mut [f64]) {
        let n = self.epochs.len();
        // to_last[e] = H_{n−1} ⋯ H_e, to_last[n] = I.
        let mut to_last = vec![Matrix4::<f64>::identity(); n + 1];
        for e in (0..n).rev() {
            to_last[e] = to_last[e + 1] * self.epochs[e];
            let scale = to_last[e].norm();
            if scale > 0.0 {
                to_last[e] /= scale;
            }
        }
        let inverse: Vec<Option<Matrix4<f64>>> = to_last.iter().map(|m| m.try_inverse()).collect();
        for (f, &e) in self.epoch_cam.iter().enumerate() {
            if let Some(Some(m)) = (e != u32::MAX).then(|| inverse[e as usize]) {
                map_camera(&mut cams[12 * f..12 * f + 12], &m);
            }
        }
        for (p, &e) in self.epoch_pt.iter().enumerate() {
            if e != u32::MAX {
                map_point(&mut pts[4 * p..4 * p + 4], &to_last[e as usize]);
            }
        }
    }
}

/// `P ← P m` (row-major 3×4), normalized.
fn map_camera(c: &mut [f64], m: &Matrix4<f64>) {
    let p: [f64; 12] = c.try_into().expect("12 entries");
    for r in 0..3 {
        for col in 0..4 {
            c[4 * r + col] = (0..4).map(|k| p[4 * r + k] * m[(k, col)]).sum();
        }
    }
    super::bundle::normalize(c);
}

/// `X ← m X`, normalized.
fn map_point(x: &mut [f64], m: &Matrix4<f64>) {
    let y = m * Vector4::new(x[0], x[1], x[2], x[3]);
    x.copy_from_slice(y.as_slice());
    super::bundle::normalize(x);
}

/// One window's own projective fit: its affine completion, then [`super::fit`] (`pcfg`'s
/// bridge and bundle adjustment), errors naming the window.
pub(crate) fn fit_window(
    start: usize,
    end: usize,
    tracks: &[usize],
    meas: &Measurements,
    cfg: &WindowConfig,
    pcfg: &super::ProjectiveConfig,
) -> Result<super::ProjectiveFit> {
    let c = complete_window(start, end, tracks, meas, cfg, None)?;
    // One chain per window, no escapes (either would double the windows' cost).
    let pcfg = super::ProjectiveConfig {
        second_bridge: None,
        escapes: Vec::new(),
        ..pcfg.clone()
    };
    super::fit(
        meas,
        super::AffineStart {
            m: c.m.as_ref(),
            s: c.s.as_ref(),
            t: &c.t,
        },
        &pcfg,
        0,
        &mut NoopObserver,
    )
    .map_err(|e| {
        Error::Degenerate(format!(
            "window of frames {start}..{end} ({} tracks): projective fit failed: {e}",
            tracks.len()
        ))
    })
}

/// Sum of squared reprojection errors of a window's observations (`meas`, frames from
/// `start`, `tracks` in the graph's numbering) under the chained projective `cams` / `pts`,
/// and the number of scalars. `O(window · tracks)`.
fn window_cost(
    cams: &[f64],
    pts: &[f64],
    start: usize,
    tracks: &[usize],
    meas: &Measurements,
) -> (f64, usize) {
    let n = tracks.len();
    let (mut cost, mut count) = (0.0, 0);
    for (i, &v) in meas.visible.iter().enumerate() {
        if !v {
            continue;
        }
        let (lf, k) = (i / n, i % n);
        let p = &cams[12 * (start + lf)..12 * (start + lf) + 12];
        let x = &pts[4 * tracks[k]..4 * tracks[k] + 4];
        let row = |r: usize| (0..4).map(|c| p[4 * r + c] * x[c]).sum::<f64>();
        let z = row(2);
        let du = row(0) / z - meas.w[(2 * lf, k)];
        let dv = row(1) / z - meas.w[(2 * lf + 1, k)];
        cost += du * du + dv * dv;
        count += 2;
    }
    (cost, count)
}

/// A window whose own fit ends above this many times the median RMS of the windows fitted
/// before it is extended from the chain ([`extend_chain`]). A fit at the noise level is
/// within a few percent of the median; a local minimum of the window's affine completion
/// measured 13× (a 20 000-frame corridor, frames 740..780).
pub(crate) const FAILED_WINDOW_RATIO: f64 = 3.0;

/// The least noise level (graph units, about 2·10⁻⁴ px) the failed-window test and the
/// extension's trimming assume: noise-free windows end at RMS 10⁻¹²–10⁻¹⁰, and a ratio of
/// such figures means nothing.
const NOISE_FLOOR: f64 = 1e-6;

/// Median of `v` (NaN when empty).
fn median(v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    s[s.len() / 2]
}

/// The chain built so far: cameras (12 per frame) and points (4 per track) in the global
/// frame, and which of them are placed (`placed_n`: frames of the window that placed the
/// track).
struct ChainState<'a> {
    cams: &'a mut [f64],
    cam_done: &'a mut [bool],
    pts: &'a mut [f64],
    placed: &'a mut [bool],
    placed_n: &'a mut [usize],
}

/// Places a window's new frames and tracks from the chain itself, for a window whose own
/// fit failed: frame by frame in order, the camera is re-estimated from the placed points
/// it sees ([`super::verdict::resect`], trimmed at `6·rms`, started from the previous
/// frame's camera — consecutive video frames are close), then the window's tracks seen in
/// ≥ 2 of its placed frames are triangulated ([`super::dlt_views`]). `rms` is the chain's
/// noise level (graph units). The sliding-window adjustment that follows refines both.
/// Errors when a frame sees fewer than 6 placed points. `O(window · tracks)`.
fn extend_chain(
    st: ChainState<'_>,
    start: usize,
    tracks: &[usize],
    meas: &Measurements,
    seen: &[usize],
    rms: f64,
) -> Result<()> {
    let n = tracks.len();
    let nw = meas.n_frames();
    let xy = |lf: usize, k: usize| [meas.w[(2 * lf, k)], meas.w[(2 * lf + 1, k)]];
    for lf in 0..nw {
        let f = start + lf;
        if st.cam_done[f] {
            continue;
        }
        if f == 0 || !st.cam_done[f - 1] {
            return Err(Error::Degenerate(format!(
                "frame {f} has no placed frame before it"
            )));
        }
        let entries: Vec<([f64; 4], [f64; 2])> = (0..n)
            .filter(|&k| meas.visible[lf * n + k] && st.placed[tracks[k]])
            .map(|k| {
                let p = tracks[k];
                let x = &st.pts[4 * p..4 * p + 4];
                ([x[0], x[1], x[2], x[3]], xy(lf, k))
            })
            .collect();
        if entries.len() < 6 {
            return Err(Error::Degenerate(format!(
                "frame {f} sees {} placed point(s) (6 needed for its camera)",
                entries.len()
            )));
        }
        let prev: [f64; 12] = st.cams[12 * (f - 1)..12 * f]
            .try_into()
            .expect("12 entries");
        let mut c = super::verdict::resect(&prev, &entries, 6.0 * rms);
        super::bundle::normalize(&mut c);
        st.cams[12 * f..12 * f + 12].copy_from_slice(&c);
        st.cam_done[f] = true;
        // Tracks now seen in two placed frames of the window.
        for k in 0..n {
            let p = tracks[k];
            if st.placed[p] {
                continue;
            }
            let views: Vec<usize> = (0..=lf)
                .filter(|&l| meas.visible[l * n + k] && st.cam_done[start + l])
                .collect();
            if views.len() < 2 {
                continue;
            }
            let mut x = super::dlt_views(
                views
                    .iter()
                    .map(|&l| (&st.cams[12 * (start + l)..12 * (start + l) + 12], xy(l, k))),
            );
            super::bundle::normalize(&mut x);
            st.pts[4 * p..4 * p + 4].copy_from_slice(&x);
            st.placed[p] = true;
            st.placed_n[p] = seen[k];
        }
    }
    Ok(())
}

/// Projective bundle adjustment of frames `lo..hi` and of every track seen in ≥ 2 of them,
/// with the cameras of frames `lo..fixed_below` held fixed; results written back into
/// `cams` / `pts` (flat, 12 per frame, 4 per track, in `g`'s numbering).
#[allow(clippy::too_many_arguments)]
fn local_refine(
    g: &Graph,
    cams: &mut [f64],
    pts: &mut [f64],
    lo: usize,
    fixed_below: usize,
    hi: usize,
    iterations: usize,
    pcfg: &super::ProjectiveConfig,
) -> Result<()> {
    let mut tracks = Vec::new();
    let mut pt_ptr = vec![0usize];
    let mut cam = Vec::new();
    let mut w = Vec::new();
    for p in 0..g.n_pts {
        let r: Vec<usize> = g
            .track(p)
            .filter(|&o| (lo..hi).contains(&g.cam[o]))
            .collect();
        if r.len() < 2 {
            continue;
        }
        tracks.push(p);
        for o in r {
            cam.push(g.cam[o] - lo);
            w.push(g.w[o]);
        }
        pt_ptr.push(cam.len());
    }
    let local = Graph {
        n_cams: hi - lo,
        n_pts: tracks.len(),
        pt_ptr,
        cam,
        w,
    };
    let mut c = cams[12 * lo..12 * hi].to_vec();
    let mut x: Vec<f64> = tracks
        .iter()
        .flat_map(|&p| pts[4 * p..4 * p + 4].iter().copied())
        .collect();
    let fixed: Vec<bool> = (lo..hi).map(|f| f < fixed_below).collect();
    let cfg = super::bundle::LmConfig {
        max_iterations: iterations,
        ..pcfg.refine.clone()
    };
    super::bundle::minimize_fixed(
        &super::models::Projective,
        &local,
        &mut c,
        &mut x,
        &fixed,
        &cfg,
        &mut super::bundle::Progress {
            observer: &mut NoopObserver,
            name: "local-ba",
            run: 0,
            rms_scale: 1.0,
            stop: None,
        },
    )
    .map_err(|message| Error::Numerical {
        stage: "sliding-window bundle adjustment",
        message,
    })?;
    cams[12 * fixed_below..12 * hi].copy_from_slice(&c[12 * (fixed_below - lo)..]);
    for (k, &p) in tracks.iter().enumerate() {
        pts[4 * p..4 * p + 4].copy_from_slice(&x[4 * k..4 * k + 4]);
    }
    Ok(())
}

/// The affine map `y ≈ A x + b` that best carries the points `x` onto `y` (linear least
/// squares, per output coordinate over the 4×4 normal matrix of `(x, 1)`); `None` when the
/// `x` are coplanar (or fewer than 4). `O(n)`.
pub(crate) fn fit_affine_map(
    pairs: impl Iterator<Item = (Vector3<f64>, Vector3<f64>)>,
) -> Option<(Matrix3<f64>, Vector3<f64>)> {
    let mut ata = Matrix4::<f64>::zeros();
    let mut aty = [Vector4::<f64>::zeros(); 3];
    for (x, y) in pairs {
        let h = Vector4::new(x[0], x[1], x[2], 1.0);
        ata += h * h.transpose();
        for r in 0..3 {
            aty[r] += h * y[r];
        }
    }
    let ch = ata.cholesky()?;
    let mut a = Matrix3::zeros();
    let mut b = Vector3::zeros();
    for r in 0..3 {
        let sol = ch.solve(&aty[r]);
        for k in 0..3 {
            a[(r, k)] = sol[k];
        }
        b[r] = sol[3];
    }
    Some((a, b))
}

/// Observations of each of a window's `n_tracks` tracks inside the window. `O(window · n)`.
pub(crate) fn seen_in_window(meas: &Measurements, n_tracks: usize) -> Vec<usize> {
    let mut seen = vec![0; n_tracks];
    for (i, &v) in meas.visible.iter().enumerate() {
        seen[i % n_tracks.max(1)] += usize::from(v);
    }
    seen
}

/// The window's tracks (indices into `tracks`) that anchor its map onto the placed ones:
/// placed, and seen in ≥ [`WindowConfig::min_anchor_observations`] frames of this window
/// (`seen`) and of the window that placed them (`placed_n`, by track); every placed one
/// when fewer than 8 qualify.
pub(crate) fn anchors(
    tracks: &[usize],
    placed: &[bool],
    seen: &[usize],
    placed_n: &[usize],
    cfg: &WindowConfig,
) -> Vec<usize> {
    let min = cfg.min_anchor_observations;
    let strong: Vec<usize> = (0..tracks.len())
        .filter(|&k| placed[tracks[k]] && seen[k] >= min && placed_n[tracks[k]] >= min)
        .collect();
    if strong.len() >= 8 {
        return strong;
    }
    (0..tracks.len()).filter(|&k| placed[tracks[k]]).collect()
}

pub(crate) fn too_few_shared(start: usize, end: usize, have: usize, need: usize) -> Error {
    Error::Degenerate(format!(
        "frames {start}..{end} share {have} track(s) with the frames before them ({need} \
         needed to chain the windows)"
    ))
}

/// The window's affine completion, errors naming the window.
pub(crate) fn complete_window(
    start: usize,
    end: usize,
    tracks: &[usize],
    meas: &Measurements,
    cfg: &WindowConfig,
    warm: Option<&(Mat<f64>, Vec<f64>)>,
) -> Result<completion::Completion> {
    let done = match warm {
        Some((m, t)) => {
            completion::complete_with_start(meas, &cfg.completion, m.as_ref(), t, &mut NoopObserver)
        }
        None => completion::complete(meas, &cfg.completion, &mut NoopObserver),
    };
    done.map_err(|e| {
        Error::Degenerate(format!(
            "window of frames {start}..{end} ({} tracks) cannot be factorized: {e}",
            tracks.len()
        ))
    })
}

/// A warm start for window `next`'s affine completion from the overlapping window `prev`
/// already completed (`prev_fit`): the cameras `[M t]` of the frames both windows hold are
/// `prev_fit`'s rows; each frame new to `next` is resected by linear least squares,
/// `min Σ_p ‖[M_f t_f] [s_p; 1] − w_fp‖²` over the tracks it sees whose points `s_p`
/// `prev_fit` holds. `None` (start cold) when the windows do not overlap, the model is not
/// affine, or a new frame sees fewer than `min_tracks` such tracks (or they are
/// degenerate: [`crate::robust::subspace::solve_camera`] solves each frame). Cost:
/// `O(n_obs(next))` plus a sort of `prev`'s tracks.
pub(crate) fn warm_start(
    prev: &Window,
    prev_fit: &completion::Completion,
    next: &Window,
    min_tracks: usize,
) -> Option<(Mat<f64>, Vec<f64>)> {
    let (sa, ea, ta, _) = prev;
    let (sb, eb, tb, mb) = next;
    let (sa, ea, sb, eb) = (*sa, *ea, *sb, *eb);
    let r = prev_fit.m.ncols();
    if !prev_fit.model.is_affine() || r != 3 || sb < sa || sb >= ea {
        return None;
    }
    let mut index: Vec<(usize, usize)> = ta.iter().enumerate().map(|(k, &p)| (p, k)).collect();
    index.sort_unstable();
    let known: Vec<Option<usize>> = tb
        .iter()
        .map(|&p| {
            let i = index.binary_search_by_key(&p, |e| e.0).ok()?;
            Some(index[i].1)
        })
        .collect();
    let (nb, nt) = (eb - sb, tb.len());
    let mut m = Mat::<f64>::zeros(2 * nb, r);
    let mut t = vec![0.0; 2 * nb];
    for lf in 0..nb {
        let f = sb + lf;
        if f < ea {
            for k in 0..2 {
                let row = 2 * (f - sa) + k;
                for c in 0..r {
                    m[(2 * lf + k, c)] = prev_fit.m[(row, c)];
                }
                t[2 * lf + k] = prev_fit.t[row];
            }
            continue;
        }
        let (mut a, mut bx, mut by, mut n) =
            (Matrix4::zeros(), Vector4::zeros(), Vector4::zeros(), 0);
        for (k, ka) in known.iter().enumerate() {
            let Some(ka) = *ka else { continue };
            if !mb.visible[lf * nt + k] {
                continue;
            }
            let v = Vector4::new(
                prev_fit.s[(0, ka)],
                prev_fit.s[(1, ka)],
                prev_fit.s[(2, ka)],
                1.0,
            );
            a += v * v.transpose();
            bx += v * mb.w[(2 * lf, k)];
            by += v * mb.w[(2 * lf + 1, k)];
            n += 1;
        }
        if n < min_tracks.max(4) {
            return None;
        }
        let (cx, cy) = crate::robust::subspace::solve_camera(&a, &bx, &by)?;
        for (j, row) in [cx, cy].iter().enumerate() {
            if row.iter().any(|v| !v.is_finite()) {
                return None;
            }
            for c in 0..3 {
                m[(2 * lf + j, c)] = row[c];
            }
            t[2 * lf + j] = row[3];
        }
    }
    Some((m, t))
}

/// Every window of [`for_each_window`], collected — `(start, end, tracks, measurements)` —
/// for chains that fit the windows in parallel before chaining them in order. Memory:
/// every window's dense measurements, `O(n_obs · window)` in total.
pub(crate) type Window = (usize, usize, Vec<usize>, Measurements);

/// See [`Window`].
pub(crate) fn collect_windows(g: &Graph, cfg: &WindowConfig) -> Result<Vec<Window>> {
    let mut windows = Vec::new();
    for_each_window(g, cfg, |start, end, tracks, meas| {
        windows.push((start, end, tracks.to_vec(), meas.clone()));
        Ok(())
    })?;
    Ok(windows)
}

/// Calls `each(start, end, tracks, meas)` for every window in order: frames
/// `start..end`, the tracks seen in ≥ 2 of them (indices into `g`) and their dense
/// measurements (window frames × those tracks).
pub(crate) fn for_each_window(
    g: &Graph,
    cfg: &WindowConfig,
    mut each: impl FnMut(usize, usize, &[usize], &Measurements) -> Result<()>,
) -> Result<()> {
    if cfg.window < 2 || cfg.overlap >= cfg.window {
        return Err(Error::InvalidConfig {
            field: "projective.windows",
            message: format!(
                "window {} and overlap {}: need window ≥ 2 and overlap < window",
                cfg.window, cfg.overlap
            ),
        });
    }
    let (nf, np) = (g.n_cams, g.n_pts);
    let (fptr, ftracks) = g.by_camera();
    let stride = cfg.window - cfg.overlap;
    let mut local = vec![usize::MAX; np];
    let mut start = 0;
    loop {
        let end = (start + cfg.window).min(nf);
        let mut count: Vec<(usize, usize)> = Vec::new();
        for f in start..end {
            for &p in &ftracks[fptr[f]..fptr[f + 1]] {
                if local[p] == usize::MAX {
                    local[p] = count.len();
                    count.push((p, 0));
                }
                count[local[p]].1 += 1;
            }
        }
        let tracks: Vec<usize> = count.iter().filter(|c| c.1 >= 2).map(|c| c.0).collect();
        for c in &count {
            local[c.0] = usize::MAX;
        }
        let nw = end - start;
        let mut w = Mat::<f64>::zeros(2 * nw, tracks.len());
        let mut vis = vec![false; nw * tracks.len()];
        for (k, &p) in tracks.iter().enumerate() {
            // The track's frames are sorted: find the window's first, then walk.
            let r = g.track(p);
            let first = r.start + g.cam[r.clone()].partition_point(|&f| f < start);
            for o in first..r.end {
                let f = g.cam[o];
                if f >= end {
                    break;
                }
                w[(2 * (f - start), k)] = g.w[o][0];
                w[(2 * (f - start) + 1, k)] = g.w[o][1];
                vis[(f - start) * tracks.len() + k] = true;
            }
        }
        each(start, end, &tracks, &Measurements::new(w, vis))?;
        if end == nf {
            return Ok(());
        }
        start += stride;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::{RngExt, SeedableRng};

    /// Re-anchoring the working frame after every window and mapping the frozen entities at
    /// the end changes the reconstruction by one homography only: every reprojection
    /// `π(P_f X_p)` of an observed pair is unchanged.
    #[test]
    fn reanchoring_changes_the_reconstruction_by_one_homography() {
        let mut rng = StdRng::seed_from_u64(3);
        // 12 frames, tracks of 3 consecutive frames starting at every frame.
        let (nf, span) = (12, 3);
        let mut pt_ptr = vec![0];
        let mut cam = Vec::new();
        for s in 0..nf - span + 1 {
            cam.extend(s..s + span);
            pt_ptr.push(cam.len());
        }
        let np = pt_ptr.len() - 1;
        let g = Graph {
            n_cams: nf,
            n_pts: np,
            w: vec![[0.0, 0.0]; cam.len()],
            pt_ptr,
            cam,
        };
        let mut cams: Vec<f64> = (0..12 * nf).map(|_| rng.random_range(-1.0..1.0)).collect();
        let mut pts: Vec<f64> = (0..4 * np).map(|_| rng.random_range(-1.0..1.0)).collect();
        let project = |cams: &[f64], pts: &[f64], f: usize, p: usize| {
            let c: [f64; 12] = cams[12 * f..12 * f + 12].try_into().unwrap();
            let x: [f64; 4] = pts[4 * p..4 * p + 4].try_into().unwrap();
            super::super::project(&c, &x)
        };
        let before: Vec<[f64; 2]> = (0..np)
            .flat_map(|p| g.track(p).map(move |o| (p, o)))
            .map(|(p, o)| project(&cams, &pts, g.cam[o], p))
            .collect();
        // Windows of 4 frames, stride 2. What a window places is written in the working
        // frame, `X = T X₀`, `P = P₀ T⁻¹`, as the chain does.
        let mut frame = WorkingFrame::new(&g);
        let mut cam_done = vec![false; nf];
        let mut placed = vec![false; np];
        let mut t = Matrix4::<f64>::identity();
        let mut start = 0;
        while start + 2 <= nf {
            let end = (start + 4).min(nf);
            let t_inv = t.try_inverse().unwrap();
            for f in start..end {
                if !cam_done[f] {
                    map_camera(&mut cams[12 * f..12 * f + 12], &t_inv);
                    cam_done[f] = true;
                }
            }
            let tracks: Vec<usize> = (0..np)
                .filter(|&p| g.track(p).any(|o| (start..end).contains(&g.cam[o])))
                .collect();
            for &p in &tracks {
                if !placed[p] {
                    map_point(&mut pts[4 * p..4 * p + 4], &t);
                    placed[p] = true;
                }
            }
            frame.activate(&tracks, &placed);
            if start > 0 {
                let h = Matrix4::from_fn(|r, c| {
                    f64::from(u8::from(r == c)) + rng.random_range(-0.3..0.3)
                });
                let h_inv = h.try_inverse().unwrap();
                frame.reanchor(&h, &h_inv, start, &mut cams, &cam_done, &mut pts);
                t = h * t;
            }
            if end == nf {
                break;
            }
            start += 2;
        }
        assert!(frame.epochs.len() >= 4);
        frame.finish(&mut cams, &mut pts);
        let after: Vec<[f64; 2]> = (0..np)
            .flat_map(|p| g.track(p).map(move |o| (p, o)))
            .map(|(p, o)| project(&cams, &pts, g.cam[o], p))
            .collect();
        for (a, b) in before.iter().zip(&after) {
            let d = (a[0] - b[0]).hypot(a[1] - b[1]);
            assert!(d < 1e-9 * (1.0 + a[0].abs() + a[1].abs()), "{a:?} → {b:?}");
        }
    }
}
