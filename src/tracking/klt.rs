//! Pyramidal Lucas–Kanade feature tracking in Bouguet's formulation, with validity checks.
//!
//! Objective: for a point `u` in image `I`, find the displacement `d` minimizing the sum of
//! squared differences over a `(2r+1)²` window,
//! `ε(d) = Σ_{x ∈ W(u)} (I(x) − J(x + d))²`.
//! Coarse to fine over the pyramid levels `L = Lm … 0` (coordinates `u_L = u / 2^L`), with the
//! guess `g_Lm = 0` (or a caller's guess) and `g_{L−1} = 2 (g_L + d_L)`, each level solves
//! its residual displacement `d_L` by Newton–Raphson iterations with the spatial gradient
//! matrix of the *template* (computed once per level):
//! `G = Σ [Ix² IxIy; IxIy Iy²]`, `b_k = Σ δI_k [Ix, Iy]ᵀ`, `δI_k = I(x) − J(x + g + ν_k)`,
//! `η_k = G⁻¹ b_k`, `ν_{k+1} = ν_k + η_k`, until `‖η_k‖ < epsilon` or `max_iterations`.
//! All window samples are bilinear (sub-pixel); the window's bilinear weights are shared by
//! all its pixels, so sampling is four multiply-adds per pixel on contiguous rows. The
//! template window, its gradients and `G` are sampled once per point and level; each
//! iteration samples `J` and accumulates `b_k` in one fused pass over rows padded to whole
//! 8-lane vectors (AVX2 when the CPU has it, chosen at run time). When two successive
//! updates nearly cancel (`|η_k + η_{k−1}| < epsilon` per coordinate) the iteration is
//! oscillating and stops at the midpoint.
//!
//! Windows may cross the image border: samples are border replicated, and template pixels
//! outside the image get zero gradient (the replicated image is flat there), so they add
//! nothing to `G` or `b`.
//!
//! Validity checks (a failed point is reported with its [`Failure`], never a position):
//! * **Out of image**: the final position must lie inside the image (or `border_margin`
//!   pixels inside it); during the iterations the point may not go more than `r` outside.
//! * **Low texture**: `λmin(G) / (2r+1)² < min_eigenvalue` at level 0 (mean squared gradient
//!   along the weakest direction, intensity units in `[0, 1]`), or `G` singular at any level.
//! * **Residual**: mean absolute intensity error `Σ |I(x) − J(x + d)| / (2r+1)²` at the final
//!   position above `max_residual`.
//! * **Forward–backward**: tracking the result back from `J` to `I` must return within
//!   `fb_threshold` pixels of `u` (Kalal, Mikolajczyk & Matas 2010).
//!
//! References: B. D. Lucas and T. Kanade, "An iterative image registration technique with an
//! application to stereo vision", IJCAI 1981; J.-Y. Bouguet, "Pyramidal implementation of the
//! Lucas Kanade feature tracker", Intel, 2000; Z. Kalal, K. Mikolajczyk, J. Matas,
//! "Forward-backward error: automatic detection of tracking failures", ICPR 2010.
//!
//! Complexity: O(P · L · (2r+1)² · K) for P points, L levels and K iterations per level,
//! doubled by the forward–backward check; parallel over points (rayon), no allocation per
//! point (per-thread scratch buffers).

// Negated comparisons are deliberate: they also reject NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use rayon::prelude::*;

use super::pyramid::{Level, Pyramid};
use crate::{Error, Result};

/// Lucas–Kanade tracker settings.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct KltConfig {
    /// Window side `2r+1`, odd, ≥ 3. Default 21 (as OpenCV's `calcOpticalFlowPyrLK`).
    pub window: usize,
    /// Index of the coarsest pyramid level (0 = no pyramid). Default 3 (as OpenCV). Levels
    /// smaller than the window are not built.
    pub max_level: usize,
    /// Newton iterations per level at most. Default 30 (as OpenCV).
    pub max_iterations: usize,
    /// Stop a level's iterations when the update is shorter than this, pixels. Default 0.01.
    pub epsilon: f32,
    /// Low-texture threshold on `λmin(G) / window area` at level 0, intensities in `[0, 1]`
    /// (so 1e-4 ≈ a gradient of 2.5 gray levels per pixel in the weakest direction).
    /// Default 1e-4.
    pub min_eigenvalue: f32,
    /// Largest accepted mean absolute intensity error over the window at the final position,
    /// intensities in `[0, 1]`. Default 0.06 (≈ 15 gray levels).
    pub max_residual: f32,
    /// Forward–backward round-trip tolerance in pixels; `None` disables the check (twice as
    /// fast). Default `Some(1.0)`.
    pub fb_threshold: Option<f32>,
    /// A point is lost when it comes closer than this to the image border, pixels; `None`
    /// (default) is 0: the point must stay inside the image, its window may cross the
    /// border (as OpenCV's `calcOpticalFlowPyrLK`). `Some(r)` keeps whole windows inside.
    pub border_margin: Option<f32>,
}

impl Default for KltConfig {
    fn default() -> Self {
        Self {
            window: 21,
            max_level: 3,
            max_iterations: 30,
            epsilon: 0.01,
            min_eigenvalue: 1e-4,
            max_residual: 0.06,
            fb_threshold: Some(1.0),
            border_margin: None,
        }
    }
}

impl KltConfig {
    /// Half window `r`.
    pub fn half(&self) -> usize {
        self.window / 2
    }

    /// The effective border margin (see [`KltConfig::border_margin`]).
    pub fn margin(&self) -> f32 {
        self.border_margin.unwrap_or(0.0)
    }

    pub(crate) fn validate(&self) -> Result<()> {
        let bad = |field, message: String| Err(Error::InvalidConfig { field, message });
        if self.window < 3 || self.window.is_multiple_of(2) || self.window > 255 {
            return bad(
                "klt.window",
                format!("must be odd, ≥ 3 and ≤ 255, got {}", self.window),
            );
        }
        if self.max_level > 12 {
            return bad(
                "klt.max_level",
                format!("must be ≤ 12 (a 4096× downscale), got {}", self.max_level),
            );
        }
        if self.max_iterations == 0 || self.max_iterations > 10_000 {
            return bad(
                "klt.max_iterations",
                format!("must be in [1, 10000], got {}", self.max_iterations),
            );
        }
        if !(self.epsilon > 0.0 && self.epsilon.is_finite()) {
            return bad(
                "klt.epsilon",
                format!("must be finite and > 0, got {}", self.epsilon),
            );
        }
        if !(self.min_eigenvalue >= 0.0) {
            return bad(
                "klt.min_eigenvalue",
                format!("must be ≥ 0, got {}", self.min_eigenvalue),
            );
        }
        if !(self.max_residual > 0.0) {
            return bad(
                "klt.max_residual",
                format!("must be > 0, got {}", self.max_residual),
            );
        }
        if let Some(t) = self.fb_threshold
            && !(t > 0.0)
        {
            return bad("klt.fb_threshold", format!("must be > 0, got {t}"));
        }
        if let Some(m) = self.border_margin
            && !(m >= 0.0 && m.is_finite())
        {
            return bad("klt.border_margin", format!("must be ≥ 0, got {m}"));
        }
        Ok(())
    }
}

/// Why a point was not tracked into the next frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Failure {
    /// The point left the image (or came within `border_margin` of its edge), or went more
    /// than a half window outside it during the iterations.
    OutOfImage,
    /// Too little texture: the gradient matrix is (near) singular.
    LowTexture,
    /// Mean absolute intensity error over the window above `max_residual`.
    Residual,
    /// Tracking back did not return to the start within `fb_threshold`.
    ForwardBackward,
}

/// Border of the padded pyramid planes that keeps every window the tracker samples (window
/// centre at most `r` pixels outside the image, rows padded to whole lanes) on the
/// branch-free path: `stride(window) + 2`.
pub fn padding_for_window(window: usize) -> usize {
    stride(window) + 2
}

/// Lanes of the inner loops (8 × f32 = one AVX2 register).
const LANES: usize = 8;

/// Row stride of a sampled `side`-wide window: `side` rounded up to whole lanes. The padding
/// columns of the template carry zero gradients, so they add nothing to `G` or `b` and every
/// inner loop runs over whole lanes.
fn stride(side: usize) -> usize {
    side.div_ceil(LANES) * LANES
}

/// Per-thread scratch: template window values and gradients, sampled target window, all
/// `side × stride(side)`.
struct Scratch {
    iw: Vec<f32>,
    gxw: Vec<f32>,
    gyw: Vec<f32>,
    jw: Vec<f32>,
}

impl Scratch {
    fn new(n: usize) -> Scratch {
        Scratch {
            iw: vec![0.0; n],
            gxw: vec![0.0; n],
            gyw: vec![0.0; n],
            jw: vec![0.0; n],
        }
    }
}

/// Bilinear sampling setup of a window whose top-left sample is at `(x, y)`.
#[derive(Clone, Copy)]
struct Bilinear {
    x0: isize,
    y0: isize,
    w00: f32,
    w01: f32,
    w10: f32,
    w11: f32,
}

impl Bilinear {
    #[inline(always)]
    fn new(x: f32, y: f32) -> Bilinear {
        let (fx, fy) = (x.floor(), y.floor());
        let (ax, ay) = (x - fx, y - fy);
        Bilinear {
            x0: fx as isize,
            y0: fy as isize,
            w00: (1.0 - ax) * (1.0 - ay),
            w01: ax * (1.0 - ay),
            w10: (1.0 - ax) * ay,
            w11: ax * ay,
        }
    }

    /// Whether all four neighbours of every sample of a `cols × rows` window are inside the
    /// padded planes of `lv`.
    #[inline(always)]
    fn inside(&self, cols: usize, rows: usize, lv: &Level) -> bool {
        let (xp, yp) = (self.x0 + lv.pad as isize, self.y0 + lv.pad as isize);
        xp >= 0
            && yp >= 0
            && (xp as usize + cols) < lv.pw
            && (yp as usize + rows) < lv.h + 2 * lv.pad
    }

    /// Samples `src` (one of the padded planes of `lv`) into `dst` (`side` rows of `sw`
    /// columns; all `sw` columns are sampled). Returns `false` when the window is not inside
    /// the padded plane: then the image part is sampled border replicated (clamped indices).
    #[inline(always)]
    fn sample(&self, src: &[f32], lv: &Level, side: usize, sw: usize, dst: &mut [f32]) -> bool {
        let pw = lv.pw;
        if self.inside(sw, side, lv) {
            let (x0, y0) = (
                (self.x0 + lv.pad as isize) as usize,
                (self.y0 + lv.pad as isize) as usize,
            );
            let (w00, w01, w10, w11) = (self.w00, self.w01, self.w10, self.w11);
            for (r, out) in dst.chunks_exact_mut(sw).enumerate() {
                let a = (y0 + r) * pw + x0;
                // Equal-length slices let the compiler drop bounds checks and vectorize.
                let (p00, p01) = (&src[a..a + sw], &src[a + 1..a + 1 + sw]);
                let (p10, p11) = (&src[a + pw..a + pw + sw], &src[a + pw + 1..a + pw + 1 + sw]);
                let out = &mut out[..sw];
                for c in 0..sw {
                    out[c] = w00 * p00[c] + w01 * p01[c] + w10 * p10[c] + w11 * p11[c];
                }
            }
            true
        } else {
            // Border replicated: clamp the column indices once per window, not per pixel.
            let (w, h, pad) = (lv.w as isize, lv.h as isize, lv.pad);
            let cx = |x: isize| x.clamp(0, w - 1) as usize + pad;
            let cy = |y: isize| (y.clamp(0, h - 1) as usize + pad) * pw;
            let mut cols = [0usize; 65];
            for (r, out) in dst.chunks_exact_mut(sw).enumerate() {
                let ya = cy(self.y0 + r as isize);
                let yb = cy(self.y0 + r as isize + 1);
                for (c0, out) in out.chunks_mut(64).enumerate() {
                    let base = self.x0 + (c0 * 64) as isize;
                    let n = out.len();
                    for (k, col) in cols[..n + 1].iter_mut().enumerate() {
                        *col = cx(base + k as isize);
                    }
                    for c in 0..n {
                        let (xa, xb) = (cols[c], cols[c + 1]);
                        out[c] = self.w00 * src[ya + xa]
                            + self.w01 * src[ya + xb]
                            + self.w10 * src[yb + xa]
                            + self.w11 * src[yb + xb];
                    }
                }
            }
            false
        }
    }

    /// Samples a gradient plane for the template: zero in the padding columns `≥ side`, and,
    /// when the window is outside the padded plane, zero where a sample is not interpolated
    /// from pixels inside the image.
    #[inline(always)]
    fn sample_gradient(&self, src: &[f32], lv: &Level, side: usize, sw: usize, dst: &mut [f32]) {
        if self.sample(src, lv, side, sw, dst) {
            for row in dst.chunks_exact_mut(sw) {
                row[side..].fill(0.0);
            }
        } else {
            self.mask_outside(lv.w, lv.h, side, sw, dst);
        }
    }

    /// Zeroes the entries of a sampled `side × sw` window (gradients) whose sample is not
    /// interpolated from pixels inside the `w × h` image, and the padding columns `≥ side`.
    /// Outside the image the border-replicated intensity is flat, so its true gradient is
    /// zero: such pixels then add nothing to `G` or `b` (the window may cross the border).
    #[inline(always)]
    fn mask_outside(&self, w: usize, h: usize, side: usize, sw: usize, dst: &mut [f32]) {
        // Largest valid top-left neighbour: the last pixel itself when its weight is all.
        let xmax = w as isize - if self.w01 == 0.0 { 1 } else { 2 };
        let ymax = h as isize - if self.w10 == 0.0 { 1 } else { 2 };
        let range = |v0: isize, vmax: isize| {
            let lo = (-v0).clamp(0, side as isize);
            let hi = (vmax - v0 + 1).clamp(lo, side as isize);
            (lo as usize, hi as usize)
        };
        let (c_lo, c_hi) = range(self.x0, xmax);
        let (r_lo, r_hi) = range(self.y0, ymax);
        for (r, row) in dst.chunks_exact_mut(sw).enumerate() {
            if r < r_lo || r >= r_hi {
                row.fill(0.0);
            } else {
                row[..c_lo].fill(0.0);
                row[c_hi..].fill(0.0);
            }
        }
    }
}

/// `(Σ (I−J)·gx, Σ (I−J)·gy)` over a window, with `J` sampled from the padded image of `lv`
/// by `bj` on the fly (fused: one pass over the four source rows and the template per window
/// row), in 8 independent lanes the compiler vectorizes. Falls back to sampling into `jw`
/// when the window is not inside the padded plane.
#[inline(always)]
fn mismatch(bj: &Bilinear, lv: &Level, side: usize, s: &mut Scratch) -> (f32, f32) {
    let sw = stride(side);
    let mut sx = [0f32; LANES];
    let mut sy = [0f32; LANES];
    if bj.inside(sw, side, lv) {
        let (w, src) = (lv.pw, &lv.pimg);
        let (x0, y0) = (
            (bj.x0 + lv.pad as isize) as usize,
            (bj.y0 + lv.pad as isize) as usize,
        );
        let (w00, w01, w10, w11) = (bj.w00, bj.w01, bj.w10, bj.w11);
        let rows =
            s.iw.chunks_exact(sw)
                .zip(s.gxw.chunks_exact(sw))
                .zip(s.gyw.chunks_exact(sw));
        for (r, ((t, gx), gy)) in rows.enumerate() {
            let a = (y0 + r) * w + x0;
            let (p00, p01) = (&src[a..a + sw], &src[a + 1..a + 1 + sw]);
            let (p10, p11) = (&src[a + w..a + w + sw], &src[a + w + 1..a + w + 1 + sw]);
            let lanes = p00
                .chunks_exact(LANES)
                .zip(p01.chunks_exact(LANES))
                .zip(p10.chunks_exact(LANES))
                .zip(p11.chunks_exact(LANES))
                .zip(t.chunks_exact(LANES))
                .zip(gx.chunks_exact(LANES))
                .zip(gy.chunks_exact(LANES));
            for ((((((q00, q01), q10), q11), t), gx), gy) in lanes {
                for l in 0..LANES {
                    let j = w00 * q00[l] + w01 * q01[l] + w10 * q10[l] + w11 * q11[l];
                    let d = t[l] - j;
                    sx[l] += d * gx[l];
                    sy[l] += d * gy[l];
                }
            }
        }
    } else {
        bj.sample(&lv.pimg, lv, side, sw, &mut s.jw);
        let lanes =
            s.iw.chunks_exact(LANES)
                .zip(s.jw.chunks_exact(LANES))
                .zip(s.gxw.chunks_exact(LANES))
                .zip(s.gyw.chunks_exact(LANES));
        for (((t, j), gx), gy) in lanes {
            for l in 0..LANES {
                let d = t[l] - j[l];
                sx[l] += d * gx[l];
                sy[l] += d * gy[l];
            }
        }
    }
    (sx.iter().sum(), sy.iter().sum())
}

/// Mean absolute difference over the first `side` columns of `side × sw` windows.
fn mean_abs_diff(a: &[f32], b: &[f32], side: usize, sw: usize) -> f32 {
    let mut t = 0f32;
    for (ra, rb) in a.chunks_exact(sw).zip(b.chunks_exact(sw)) {
        t += ra[..side]
            .iter()
            .zip(&rb[..side])
            .map(|(x, y)| (x - y).abs())
            .sum::<f32>();
    }
    t / (side * side) as f32
}

/// Gradient matrix `[gxx gxy; gxy gyy]` of the sampled template window.
#[inline(always)]
fn gradient_matrix(gx: &[f32], gy: &[f32]) -> (f32, f32, f32) {
    let mut a = [0f32; 8];
    let mut b = [0f32; 8];
    let mut c = [0f32; 8];
    let n = gx.len() / 8 * 8;
    for k in (0..n).step_by(8) {
        for l in 0..8 {
            let (x, y) = (gx[k + l], gy[k + l]);
            a[l] += x * x;
            b[l] += x * y;
            c[l] += y * y;
        }
    }
    let (mut xx, mut xy, mut yy) = (a.iter().sum(), b.iter().sum(), c.iter().sum::<f32>());
    for k in n..gx.len() {
        let (x, y) = (gx[k], gy[k]);
        xx += x * x;
        xy += x * y;
        yy += y * y;
    }
    (xx, xy, yy)
}

/// `λmin(G) / (2r+1)²` of the gradient matrix over the `window × window` window centred on
/// the integer pixel `(x, y)` of `level` (0 when the window does not fit). The tracker's
/// low-texture test, used to keep detection from starting tracks that would die at once.
pub fn window_min_eigenvalue(level: &Level, x: usize, y: usize, window: usize) -> f32 {
    let r = window / 2;
    if x < r || y < r || x + r >= level.w || y + r >= level.h {
        return 0.0;
    }
    let (mut a, mut b, mut c) = (0f32, 0f32, 0f32);
    for yy in y - r..=y + r {
        let row = yy * level.w;
        let gx = &level.gx[row + x - r..=row + x + r];
        let gy = &level.gy[row + x - r..=row + x + r];
        let (xx, xy, yy2) = gradient_matrix(gx, gy);
        a += xx;
        b += xy;
        c += yy2;
    }
    let half = 0.5 * (a - c);
    (0.5 * (a + c) - (half * half + b * b).sqrt()) / (window * window) as f32
}

type TrackOne = std::result::Result<([f32; 2], f32), Failure>;

/// Tracks one point `u` from `prev` to `next` starting from the level-0 displacement guess
/// `guess`; returns the new position and the final mean absolute residual. Dispatches to an
/// AVX2 build of the same code when the CPU has it (8-lane inner loops).
fn track_one(
    prev: &Pyramid,
    next: &Pyramid,
    u: [f32; 2],
    guess: [f32; 2],
    cfg: &KltConfig,
    s: &mut Scratch,
) -> TrackOne {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (checked at run time just above).
        return unsafe { track_one_avx2(prev, next, u, guess, cfg, s) };
    }
    track_one_impl(prev, next, u, guess, cfg, s)
}

/// [`track_one_impl`] compiled with AVX2 enabled.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn track_one_avx2(
    prev: &Pyramid,
    next: &Pyramid,
    u: [f32; 2],
    guess: [f32; 2],
    cfg: &KltConfig,
    s: &mut Scratch,
) -> TrackOne {
    track_one_impl(prev, next, u, guess, cfg, s)
}

#[inline(always)]
fn track_one_impl(
    prev: &Pyramid,
    next: &Pyramid,
    u: [f32; 2],
    guess: [f32; 2],
    cfg: &KltConfig,
    s: &mut Scratch,
) -> TrackOne {
    let r = cfg.half();
    let side = cfg.window;
    let sw = stride(side);
    let area = (side * side) as f32;
    let top = cfg
        .max_level
        .min(prev.levels.len() - 1)
        .min(next.levels.len() - 1);
    let top_scale = (1u32 << top) as f32;
    let mut g = [guess[0] / top_scale, guess[1] / top_scale];
    let mut d = [0f32; 2];
    for l in (0..=top).rev() {
        let scale = 1.0 / (1u32 << l) as f32;
        let (li, lj): (&Level, &Level) = (&prev.levels[l], &next.levels[l]);
        let p = [u[0] * scale, u[1] * scale];
        // Template window and gradients at p, sampled once per level (Bouguet).
        let bi = Bilinear::new(p[0] - r as f32, p[1] - r as f32);
        bi.sample(&li.pimg, li, side, sw, &mut s.iw);
        bi.sample_gradient(&li.pgx, li, side, sw, &mut s.gxw);
        bi.sample_gradient(&li.pgy, li, side, sw, &mut s.gyw);
        let (gxx, gxy, gyy) = gradient_matrix(&s.gxw, &s.gyw);
        let det = gxx * gyy - gxy * gxy;
        let tr = 0.5 * (gxx + gyy);
        let lmin = tr - (tr * tr - det).max(0.0).sqrt();
        if l == 0 && lmin / area < cfg.min_eigenvalue {
            return Err(Failure::LowTexture);
        }
        if !(det > f32::EPSILON * (gxx + gyy) * (gxx + gyy)) || lmin <= 0.0 {
            return Err(Failure::LowTexture);
        }
        let inv_det = 1.0 / det;
        let (wj, hj) = (lj.w as f32, lj.h as f32);
        let rf = r as f32;
        let mut nu = [0f32; 2];
        let mut prev_eta = [0f32; 2];
        for k in 0..cfg.max_iterations {
            let q = [p[0] + g[0] + nu[0], p[1] + g[1] + nu[1]];
            if !(q[0] > -rf && q[1] > -rf && q[0] < wj + rf && q[1] < hj + rf) {
                return Err(Failure::OutOfImage);
            }
            let bj = Bilinear::new(q[0] - rf, q[1] - rf);
            let (bx, by) = mismatch(&bj, lj, side, s);
            let eta = [
                (gyy * bx - gxy * by) * inv_det,
                (gxx * by - gxy * bx) * inv_det,
            ];
            nu[0] += eta[0];
            nu[1] += eta[1];
            if eta[0] * eta[0] + eta[1] * eta[1] < cfg.epsilon * cfg.epsilon {
                break;
            }
            // Oscillation between two positions: stop at their midpoint.
            if k > 0
                && (eta[0] + prev_eta[0]).abs() < cfg.epsilon
                && (eta[1] + prev_eta[1]).abs() < cfg.epsilon
            {
                nu[0] -= 0.5 * eta[0];
                nu[1] -= 0.5 * eta[1];
                break;
            }
            prev_eta = eta;
        }
        d = nu;
        if l > 0 {
            g = [2.0 * (g[0] + d[0]), 2.0 * (g[1] + d[1])];
        }
    }
    let v = [u[0] + g[0] + d[0], u[1] + g[1] + d[1]];
    let l0 = &next.levels[0];
    let m = cfg.margin();
    if !(v[0] >= m && v[1] >= m && v[0] <= (l0.w - 1) as f32 - m && v[1] <= (l0.h - 1) as f32 - m) {
        return Err(Failure::OutOfImage);
    }
    // Residual at the final position (template window of level 0 is still in s.iw).
    let bj = Bilinear::new(v[0] - r as f32, v[1] - r as f32);
    bj.sample(&l0.pimg, l0, side, sw, &mut s.jw);
    let res = mean_abs_diff(&s.iw, &s.jw, side, sw);
    if !(res <= cfg.max_residual) {
        return Err(Failure::Residual);
    }
    Ok((v, res))
}

/// Tracks `points` from `prev` to `next`. `guesses`, when given, are level-0 displacement
/// guesses per point (missing entries count as zero). Each result is the new position or the reason the point was lost.
/// See the module documentation for the objective and checks. Pyramids built with
/// [`Pyramid::with_padding`] and a padding of at least [`padding_for_window`] keep every
/// window on the fast path (the tracker does this); others work, more slowly near borders.
pub fn track_points(
    prev: &Pyramid,
    next: &Pyramid,
    points: &[[f32; 2]],
    guesses: Option<&[[f32; 2]]>,
    cfg: &KltConfig,
) -> Vec<std::result::Result<[f32; 2], Failure>> {
    let n = cfg.window * stride(cfg.window);
    let l0 = &prev.levels[0];
    let m = cfg.margin();
    points
        .par_iter()
        .enumerate()
        .map_init(
            || Scratch::new(n),
            |s, (i, &u)| {
                if !(u[0] >= m
                    && u[1] >= m
                    && u[0] <= (l0.w - 1) as f32 - m
                    && u[1] <= (l0.h - 1) as f32 - m)
                {
                    return Err(Failure::OutOfImage);
                }
                let guess = guesses
                    .and_then(|g| g.get(i))
                    .copied()
                    .unwrap_or([0.0, 0.0]);
                let (v, _) = track_one(prev, next, u, guess, cfg, s)?;
                if let Some(t) = cfg.fb_threshold {
                    // Independent backward pass (no guess), so a wrong forward match cannot
                    // simply retrace its steps.
                    let (w, _) = track_one(next, prev, v, [0.0, 0.0], cfg, s)
                        .map_err(|_| Failure::ForwardBackward)?;
                    let e = [w[0] - u[0], w[1] - u[1]];
                    if e[0] * e[0] + e[1] * e[1] > t * t {
                        return Err(Failure::ForwardBackward);
                    }
                }
                Ok(v)
            },
        )
        .collect()
}
