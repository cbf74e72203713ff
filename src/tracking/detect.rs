//! Shi–Tomasi corner detection ("good features to track").
//!
//! Objective: pick pixels whose structure tensor over a `block × block` window,
//! `M = Σ [Ix² IxIy; IxIy Iy²]`, has a large *minimum* eigenvalue
//! `λmin = (a+c)/2 − sqrt(((a−c)/2)² + b²)` — the condition under which the Lucas–Kanade
//! system is well conditioned (Shi & Tomasi 1994). Candidates must
//! 1. have `λmin ≥ quality_level · max λmin` over the image,
//! 2. be a local maximum of `λmin` in their 3×3 neighbourhood (non-maximum suppression),
//! 3. lie at least `border` pixels inside the image and outside the caller's mask,
//! 4. be at least `min_distance` pixels from every stronger accepted corner
//!    (greedy, strongest first, with a grid of `min_distance`-sized cells),
//!
//! and at most `max_features` are returned, strongest first.
//!
//! References: J. Shi and C. Tomasi, "Good features to track", CVPR 1994.
//!
//! Complexity: O(W·H) for the response (separable running box sums), O(K log K) to sort the
//! K candidates, O(K) expected for the spacing test.

// Negated comparisons are deliberate: they also reject NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use rayon::prelude::*;

use super::pyramid::Level;

/// Rows per parallel task of the response computation (rayon).
const ROWS: usize = 32;
use crate::{Error, Result};

/// Corner detector settings.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DetectConfig {
    /// Maximum number of corners returned (strongest first). Default 500.
    pub max_features: usize,
    /// Minimum accepted response relative to the strongest in the image, in `(0, 1]`.
    /// Default 0.01.
    pub quality_level: f32,
    /// Minimum Euclidean distance between returned corners, pixels. Default 8.
    pub min_distance: f32,
    /// Side of the structure-tensor window, odd, ≥ 3. Default 3 (as OpenCV's
    /// `goodFeaturesToTrack`).
    pub block_size: usize,
    /// Corners closer than this to the image border are rejected, pixels. `None` (default)
    /// uses the tracker's half window + 1 so every new feature's window fits in the image.
    pub border: Option<usize>,
}

impl Default for DetectConfig {
    fn default() -> Self {
        Self {
            max_features: 500,
            quality_level: 0.01,
            min_distance: 8.0,
            block_size: 3,
            border: None,
        }
    }
}

impl DetectConfig {
    pub(crate) fn validate(&self) -> Result<()> {
        if !(self.quality_level > 0.0 && self.quality_level <= 1.0) {
            return Err(Error::InvalidConfig {
                field: "detect.quality_level",
                message: format!("must be in (0, 1], got {}", self.quality_level),
            });
        }
        if !(self.min_distance >= 0.0 && self.min_distance.is_finite()) {
            return Err(Error::InvalidConfig {
                field: "detect.min_distance",
                message: format!("must be finite and ≥ 0, got {}", self.min_distance),
            });
        }
        if self.block_size < 3 || self.block_size.is_multiple_of(2) || self.block_size > 255 {
            return Err(Error::InvalidConfig {
                field: "detect.block_size",
                message: format!("must be odd, ≥ 3 and ≤ 255, got {}", self.block_size),
            });
        }
        if self.max_features > 10_000_000 {
            return Err(Error::InvalidConfig {
                field: "detect.max_features",
                message: format!("must be ≤ 10 000 000, got {}", self.max_features),
            });
        }
        Ok(())
    }
}

/// A detected corner: position (pixel centre coordinates) and its `λmin` response.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Corner {
    pub x: f32,
    pub y: f32,
    pub response: f32,
}

/// The minimum-eigenvalue response of every pixel (zero on the outer `block/2` ring).
/// Box sums are separable: vertical sums of the tensor products row by row, then horizontal
/// sums of shifted rows (branch-free, vectorizable), in parallel blocks of rows.
pub fn min_eigen_response(level: &Level, block: usize) -> Vec<f32> {
    let (w, h) = (level.w, level.h);
    let r = block / 2;
    let mut out = vec![0f32; w * h];
    if w <= 2 * r || h <= 2 * r {
        return out;
    }
    let n = w - 2 * r;
    let norm = 1.0 / (block * block) as f32;
    // Rows r..h−r in parallel blocks, each with its own running sums.
    out[r * w..(h - r) * w]
        .par_chunks_mut(w * ROWS)
        .enumerate()
        .for_each(|(blk, rows)| {
            let (mut vxx, mut vxy, mut vyy) = (vec![0f32; w], vec![0f32; w], vec![0f32; w]);
            let (mut a, mut b, mut c) = (vec![0f32; n], vec![0f32; n], vec![0f32; n]);
            for (k, row) in rows.chunks_exact_mut(w).enumerate() {
                let y = r + blk * ROWS + k;
                vxx.fill(0.0);
                vxy.fill(0.0);
                vyy.fill(0.0);
                for yy in y - r..=y + r {
                    let gx = &level.gx[yy * w..yy * w + w];
                    let gy = &level.gy[yy * w..yy * w + w];
                    for x in 0..w {
                        vxx[x] += gx[x] * gx[x];
                        vxy[x] += gx[x] * gy[x];
                        vyy[x] += gy[x] * gy[x];
                    }
                }
                let dst = &mut row[r..r + n];
                a.fill(0.0);
                b.fill(0.0);
                c.fill(0.0);
                for k in 0..block {
                    let (sx, sxy, sy) = (&vxx[k..k + n], &vxy[k..k + n], &vyy[k..k + n]);
                    for x in 0..n {
                        a[x] += sx[x];
                        b[x] += sxy[x];
                        c[x] += sy[x];
                    }
                }
                for x in 0..n {
                    let (a, b, c) = (a[x] * norm, b[x] * norm, c[x] * norm);
                    let half = 0.5 * (a - c);
                    dst[x] = 0.5 * (a + c) - (half * half + b * b).sqrt();
                }
            }
        });
    out
}

/// Detects Shi–Tomasi corners on a pyramid level (normally level 0). `allowed`, when given,
/// is a `h × w` mask: pixels with `false` are never returned. `border` is the minimum
/// distance to the image edge (see [`DetectConfig::border`]).
pub fn detect_corners(
    level: &Level,
    cfg: &DetectConfig,
    border: usize,
    allowed: Option<&[bool]>,
) -> Vec<Corner> {
    detect_corners_filtered(level, cfg, border, allowed, |_, _| true)
}

/// [`detect_corners`] with an extra acceptance test `keep(x, y)` applied, strongest first,
/// before the spacing test (e.g. the tracker's own low-texture test over its window).
pub fn detect_corners_filtered(
    level: &Level,
    cfg: &DetectConfig,
    border: usize,
    allowed: Option<&[bool]>,
    mut keep: impl FnMut(usize, usize) -> bool,
) -> Vec<Corner> {
    let (w, h) = (level.w, level.h);
    if cfg.max_features == 0 {
        return Vec::new();
    }
    let resp = min_eigen_response(level, cfg.block_size);
    let max = resp.iter().copied().fold(0f32, f32::max);
    if max <= 0.0 {
        return Vec::new();
    }
    let thr = cfg.quality_level * max;
    let b = border.max(cfg.block_size / 2 + 1);
    if w <= 2 * b || h <= 2 * b {
        return Vec::new();
    }
    let mut cand: Vec<(f32, u32)> = Vec::new();
    for y in b..h - b {
        for x in b..w - b {
            let i = y * w + x;
            let v = resp[i];
            if v < thr || allowed.is_some_and(|m| !m[i]) {
                continue;
            }
            // 3×3 non-maximum suppression (ties kept; the spacing test separates them).
            let is_max = (y - 1..=y + 1).all(|yy| {
                let row = &resp[yy * w + x - 1..yy * w + x + 2];
                row.iter().all(|&u| u <= v)
            });
            if is_max {
                cand.push((v, i as u32));
            }
        }
    }
    cand.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    let md = cfg.min_distance;
    let md2 = md * md;
    let cell = md.max(1.0);
    let gw = (w as f32 / cell).ceil() as usize + 1;
    let gh = (h as f32 / cell).ceil() as usize + 1;
    let mut grid: Vec<Vec<(f32, f32)>> = vec![Vec::new(); gw * gh];
    let mut out = Vec::with_capacity(cfg.max_features.min(cand.len()));
    for (v, i) in cand {
        let (x, y) = ((i as usize % w) as f32, (i as usize / w) as f32);
        let (cx, cy) = ((x / cell) as usize, (y / cell) as usize);
        let mut ok = true;
        if md > 0.0 {
            'outer: for gy in cy.saturating_sub(1)..=(cy + 1).min(gh - 1) {
                for gx in cx.saturating_sub(1)..=(cx + 1).min(gw - 1) {
                    for &(px, py) in &grid[gy * gw + gx] {
                        if (px - x) * (px - x) + (py - y) * (py - y) < md2 {
                            ok = false;
                            break 'outer;
                        }
                    }
                }
            }
        }
        // The acceptance test after the (cheaper) spacing test: same result, as a corner
        // failing either is dropped and only accepted corners enter the grid.
        if ok && keep(i as usize % w, i as usize / w) {
            grid[cy * gw + cx].push((x, y));
            out.push(Corner { x, y, response: v });
            if out.len() == cfg.max_features {
                break;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tracking::frames::GrayImage;
    use crate::tracking::pyramid::Pyramid;

    /// A bright square on a dark background: exactly its four corners, strongest first,
    /// within a pixel of the true corners; the cap and the spacing are honoured.
    #[test]
    fn square_has_four_corners() {
        let (w, h) = (64, 48);
        let mut data = vec![0.1f32; w * h];
        for y in 15..35 {
            for x in 20..44 {
                data[y * w + x] = 0.9;
            }
        }
        let img = GrayImage::new(w, h, data).unwrap();
        let pyr = Pyramid::new(&img, 0, 8);
        let cfg = DetectConfig {
            quality_level: 0.1,
            ..DetectConfig::default()
        };
        let c = detect_corners(&pyr.levels[0], &cfg, 3, None);
        assert_eq!(c.len(), 4, "{c:?}");
        for (tx, ty) in [(19.5, 14.5), (43.5, 14.5), (19.5, 34.5), (43.5, 34.5)] {
            assert!(
                c.iter()
                    .any(|k| (k.x - tx).abs() <= 1.0 && (k.y - ty).abs() <= 1.0),
                "no corner near ({tx}, {ty}): {c:?}"
            );
        }
        assert!(c.windows(2).all(|p| p[0].response >= p[1].response));
        let capped = detect_corners(
            &pyr.levels[0],
            &DetectConfig {
                max_features: 2,
                ..cfg.clone()
            },
            3,
            None,
        );
        assert_eq!(capped.len(), 2);
        // A spacing larger than the square's height keeps one corner per vertical edge pair.
        let spaced = detect_corners(
            &pyr.levels[0],
            &DetectConfig {
                min_distance: 22.0,
                ..cfg.clone()
            },
            3,
            None,
        );
        assert_eq!(spaced.len(), 2, "{spaced:?}");
        // A mask hides the left half.
        let mut allowed = vec![true; w * h];
        for y in 0..h {
            for x in 0..32 {
                allowed[y * w + x] = false;
            }
        }
        let masked = detect_corners(&pyr.levels[0], &cfg, 3, Some(&allowed));
        assert_eq!(masked.len(), 2);
        assert!(masked.iter().all(|k| k.x > 32.0));
    }
}
