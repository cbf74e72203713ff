//! Gaussian image pyramid with precomputed gradients per level.
//!
//! Level 0 is the image; level `l+1` is level `l` smoothed by the separable binomial kernel
//! `[1 4 6 4 1]/16` (border replicated) and subsampled by 2 (Bouguet 2000, §2.1, which uses
//! the same 5-tap low-pass filter). Each level stores its Scharr gradients
//! `Ix, Iy` (kernel `[3 10 3]/32` across, `[-1 0 1]/2` along: a derivative in intensity per
//! pixel), computed once per frame and reused by every point and by both the forward and the
//! backward pass of the tracker.
//!
//! Reference: J.-Y. Bouguet, "Pyramidal implementation of the Lucas Kanade feature tracker:
//! description of the algorithm", Intel Corporation, 2000. H. Scharr, "Optimal operators in
//! digital image processing", PhD thesis, Heidelberg, 2000.
//!
//! Complexity: O(W·H) time and memory for the whole pyramid (geometric series 4/3); rows
//! are processed in parallel blocks (rayon).

// Negated comparisons are deliberate: they also reject NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use rayon::prelude::*;

use super::frames::GrayImage;

/// Rows per parallel task when building a level (rayon).
const ROWS: usize = 32;

/// One pyramid level: image and its x/y gradients, all `h × w` row-major, and padded copies
/// for the tracker.
///
/// The padded planes are `(h + 2·pad) × (w + 2·pad)` (row stride [`Level::pw`]), pixel
/// `(x, y)` at `(y + pad)·pw + x + pad`: the image border replicated, the gradients zero
/// outside the image (the replicated image is flat across the border, and pixels outside
/// carry no information). With them, a tracking window that crosses the border is sampled
/// with the same branch-free code as one inside.
#[derive(Debug, Clone)]
pub struct Level {
    pub w: usize,
    pub h: usize,
    pub img: Vec<f32>,
    pub gx: Vec<f32>,
    pub gy: Vec<f32>,
    /// Border width of the padded planes, pixels.
    pub pad: usize,
    /// Row stride of the padded planes, `w + 2·pad`.
    pub pw: usize,
    /// Padded image (border replicated).
    pub pimg: Vec<f32>,
    /// Padded x gradient (zero outside the image).
    pub pgx: Vec<f32>,
    /// Padded y gradient (zero outside the image).
    pub pgy: Vec<f32>,
}

/// Image pyramid; `levels[0]` is full resolution.
#[derive(Debug, Clone)]
pub struct Pyramid {
    pub levels: Vec<Level>,
    /// Border width of every level's padded planes (see [`Level`]).
    pub pad: usize,
}

impl Pyramid {
    /// Builds up to `max_level + 1` levels, stopping early when a level would be smaller than
    /// `min_size` pixels on a side; no padding (see [`Pyramid::with_padding`]).
    pub fn new(image: &GrayImage, max_level: usize, min_size: usize) -> Pyramid {
        Pyramid::with_padding(image, max_level, min_size, 0)
    }

    /// As [`Pyramid::new`], with padded planes of border `pad` on every level (the tracker
    /// uses [`padding_for_window`](super::klt::padding_for_window)).
    pub fn with_padding(
        image: &GrayImage,
        max_level: usize,
        min_size: usize,
        pad: usize,
    ) -> Pyramid {
        let mut p = Pyramid {
            levels: Vec::new(),
            pad,
        };
        p.rebuild(image, max_level, min_size);
        p
    }

    /// Rebuilds this pyramid for another image (same padding), reusing its buffers (no new
    /// pages when the image size is unchanged: the tracker rebuilds the pyramid of two frames
    /// ago).
    pub fn rebuild(&mut self, image: &GrayImage, max_level: usize, min_size: usize) {
        let mut dims = vec![(image.width, image.height)];
        for _ in 0..max_level {
            let &(w, h) = dims.last().expect("level 0 exists");
            let (w2, h2) = (w.div_ceil(2), h.div_ceil(2));
            if w2 < min_size || h2 < min_size {
                break;
            }
            dims.push((w2, h2));
        }
        self.levels.truncate(dims.len());
        while self.levels.len() < dims.len() {
            self.levels.push(Level {
                w: 0,
                h: 0,
                img: Vec::new(),
                gx: Vec::new(),
                gy: Vec::new(),
                pad: 0,
                pw: 0,
                pimg: Vec::new(),
                pgx: Vec::new(),
                pgy: Vec::new(),
            });
        }
        for (l, &(w, h)) in dims.iter().enumerate() {
            let (done, rest) = self.levels.split_at_mut(l);
            let level = &mut rest[0];
            level.w = w;
            level.h = h;
            level.img.resize(w * h, 0.0);
            if l == 0 {
                level.img.copy_from_slice(&image.data);
            } else {
                let prev = &done[l - 1];
                downsample(&prev.img, prev.w, prev.h, &mut level.img);
            }
            level.gx.resize(w * h, 0.0);
            level.gy.resize(w * h, 0.0);
            scharr(&level.img, w, h, &mut level.gx, &mut level.gy);
            let pad = self.pad;
            level.pad = pad;
            level.pw = w + 2 * pad;
            let n = level.pw * (h + 2 * pad);
            for (plane, src, replicate) in [
                (&mut level.pimg, &level.img, true),
                (&mut level.pgx, &level.gx, false),
                (&mut level.pgy, &level.gy, false),
            ] {
                plane.resize(n, 0.0);
                pad_plane(src, w, h, pad, replicate, plane);
            }
        }
    }
}

/// Writes `src` (`w × h`) into `dst` (`(w + 2·pad) × (h + 2·pad)`) with a border of `pad`
/// pixels: replicated when `replicate`, else zero.
fn pad_plane(src: &[f32], w: usize, h: usize, pad: usize, replicate: bool, dst: &mut [f32]) {
    let pw = w + 2 * pad;
    if w == 0 || h == 0 {
        dst.fill(0.0);
        return;
    }
    dst.par_chunks_mut(pw * ROWS)
        .enumerate()
        .for_each(|(blk, block)| {
            for (k, row) in block.chunks_exact_mut(pw).enumerate() {
                let y = (blk * ROWS + k) as isize - pad as isize;
                let inside = y >= 0 && y < h as isize;
                if !inside && !replicate {
                    row.fill(0.0);
                    continue;
                }
                let ys = y.clamp(0, h as isize - 1) as usize;
                let s = &src[ys * w..ys * w + w];
                let (left, rest) = row.split_at_mut(pad);
                let (mid, right) = rest.split_at_mut(w);
                mid.copy_from_slice(s);
                if replicate {
                    left.fill(s[0]);
                    right.fill(s[w - 1]);
                } else {
                    left.fill(0.0);
                    right.fill(0.0);
                }
            }
        });
}

/// Smooths with `[1 4 6 4 1]/16` in both directions and keeps even pixels (border
/// replicated). Interior pixels take a branch-free path the compiler vectorizes.
fn downsample(src: &[f32], w: usize, h: usize, out: &mut [f32]) {
    let (w2, h2) = (w.div_ceil(2), h.div_ceil(2));
    // Vertical pass at even rows (all columns): contiguous row arithmetic.
    let mut tmp = vec![0f32; w * h2];
    let clampy = |y: isize| y.clamp(0, h as isize - 1) as usize;
    tmp.par_chunks_mut(w * ROWS)
        .enumerate()
        .for_each(|(blk, block)| {
            for (k, dst) in block.chunks_exact_mut(w).enumerate() {
                let y = (2 * (blk * ROWS + k)) as isize;
                let r = [
                    clampy(y - 2),
                    clampy(y - 1),
                    y as usize,
                    clampy(y + 1),
                    clampy(y + 2),
                ];
                let (a, b, c, d, e) = (
                    &src[r[0] * w..r[0] * w + w],
                    &src[r[1] * w..r[1] * w + w],
                    &src[r[2] * w..r[2] * w + w],
                    &src[r[3] * w..r[3] * w + w],
                    &src[r[4] * w..r[4] * w + w],
                );
                for x in 0..w {
                    dst[x] = (a[x] + e[x] + 4.0 * (b[x] + d[x]) + 6.0 * c[x]) * (1.0 / 16.0);
                }
            }
        });
    // Horizontal pass at even columns.
    let clampx = |x: isize| x.clamp(0, w as isize - 1) as usize;
    // Interior: 2·x2 − 2 ≥ 0 and 2·x2 + 2 ≤ w − 1.
    let lo = 1.min(w2);
    let hi = if w >= 3 {
        ((w - 3) / 2 + 1).max(lo)
    } else {
        lo
    };
    out[..w2 * h2]
        .par_chunks_mut(w2 * ROWS)
        .zip(tmp.par_chunks(w * ROWS))
        .for_each(|(oblock, tblock)| {
            for (dst, row) in oblock.chunks_exact_mut(w2).zip(tblock.chunks_exact(w)) {
                let tap = |x2: usize| {
                    let x = (2 * x2) as isize;
                    (row[clampx(x - 2)]
                        + row[clampx(x + 2)]
                        + 4.0 * (row[clampx(x - 1)] + row[clampx(x + 1)])
                        + 6.0 * row[x as usize])
                        * (1.0 / 16.0)
                };
                for x2 in 0..lo {
                    dst[x2] = tap(x2);
                }
                for x2 in lo..hi.min(w2) {
                    let x = 2 * x2;
                    let v = &row[x - 2..x + 3];
                    dst[x2] = (v[0] + v[4] + 4.0 * (v[1] + v[3]) + 6.0 * v[2]) * (1.0 / 16.0);
                }
                for x2 in hi.min(w2)..w2 {
                    dst[x2] = tap(x2);
                }
            }
        });
}

/// Scharr gradients (border replicated), scaled to intensity per pixel, written to `gx`,
/// `gy` (each `w × h`).
pub fn scharr(img: &[f32], w: usize, h: usize, gx: &mut [f32], gy: &mut [f32]) {
    if w == 0 || h == 0 {
        return;
    }
    const S: f32 = 1.0 / 32.0;
    // Per row: s = [3 10 3]ᵀ-smoothed column values, d = central column differences; then
    // gx = horizontal difference of s, gy = [3 10 3]-smoothing of d.
    gx[..w * h]
        .par_chunks_mut(w * ROWS)
        .zip(gy[..w * h].par_chunks_mut(w * ROWS))
        .enumerate()
        .for_each(|(b, (gxb, gyb))| {
            let mut sm = vec![0f32; w];
            let mut df = vec![0f32; w];
            let rows = gxb.chunks_exact_mut(w).zip(gyb.chunks_exact_mut(w));
            for (k, (gxr, gyr)) in rows.enumerate() {
                let y = b * ROWS + k;
                let ym = y.saturating_sub(1);
                let yp = (y + 1).min(h - 1);
                let rm = &img[ym * w..ym * w + w];
                let r0 = &img[y * w..y * w + w];
                let rp = &img[yp * w..yp * w + w];
                for x in 0..w {
                    sm[x] = 3.0 * (rm[x] + rp[x]) + 10.0 * r0[x];
                    df[x] = rp[x] - rm[x];
                }
                if w >= 3 {
                    let n = w - 2;
                    let (s0, s2) = (&sm[..n], &sm[2..n + 2]);
                    let (d0, d1, d2) = (&df[..n], &df[1..n + 1], &df[2..n + 2]);
                    let (ox, oy) = (&mut gxr[1..n + 1], &mut gyr[1..n + 1]);
                    for x in 0..n {
                        ox[x] = (s2[x] - s0[x]) * S;
                        oy[x] = (3.0 * (d0[x] + d2[x]) + 10.0 * d1[x]) * S;
                    }
                }
                for x in [0, w - 1] {
                    let (xm, xp) = (x.saturating_sub(1), (x + 1).min(w - 1));
                    gxr[x] = (sm[xp] - sm[xm]) * S;
                    gyr[x] = (3.0 * (df[xm] + df[xp]) + 10.0 * df[x]) * S;
                }
            }
        });
}
