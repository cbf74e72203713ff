//! Synthetic image sequences with known motion, for testing and measuring the tracker.
//!
//! A procedural texture `T(s)` on the scene plane — multi-octave value noise (smooth cubic
//! interpolation of seeded lattice values) plus random discs and rectangles with soft
//! (≈1 px) edges — is seen in frame `k` through a known similarity motion `M_k`:
//! `I_k(x) = T(M_k⁻¹ x)`, with `M_k(s) = c + z_k R(θ_k) (s − c) + t_k` about the image
//! centre `c`. A scene rectangle can be made flat (constant intensity: no texture), and
//! Gaussian noise can be added. The true position in frame `k` of a point seen at `p` in
//! frame 0 is `M_k(M_0⁻¹ p)` ([`Sequence::truth`]).
//!
//! Complexity: O(W·H·(octaves + shapes)) per frame.

// Negated comparisons are deliberate: they also reject NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Normal};

use super::frames::GrayImage;

/// Per-frame motion, increments per frame applied about the image centre.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Motion {
    /// Translation per frame, pixels.
    pub translation: [f64; 2],
    /// Rotation per frame, radians.
    pub rotation: f64,
    /// Zoom factor per frame (1 = none).
    pub zoom: f64,
}

impl Default for Motion {
    fn default() -> Self {
        Self {
            translation: [0.0, 0.0],
            rotation: 0.0,
            zoom: 1.0,
        }
    }
}

/// Sequence settings. Defaults: 160×120, 10 frames, no motion, no flat region, no noise.
#[derive(Debug, Clone, PartialEq)]
pub struct SequenceConfig {
    pub width: usize,
    pub height: usize,
    pub frames: usize,
    pub motion: Motion,
    /// Scene rectangle `[x0, y0, x1, y1]` of constant intensity (no texture), if any.
    pub flat: Option<[f64; 4]>,
    /// Gaussian noise σ added to every pixel, intensities in `[0, 1]`.
    pub noise: f64,
    /// Number of random discs and rectangles. Default 12.
    pub shapes: usize,
    /// Seed for texture, shapes and noise. Default 0.
    pub seed: u64,
}

impl Default for SequenceConfig {
    fn default() -> Self {
        Self {
            width: 160,
            height: 120,
            frames: 10,
            motion: Motion::default(),
            flat: None,
            noise: 0.0,
            shapes: 12,
            seed: 0,
        }
    }
}

#[derive(Debug, Clone)]
enum ShapeKind {
    Disc { cx: f64, cy: f64, r: f64 },
    Rect { x0: f64, y0: f64, x1: f64, y1: f64 },
}

/// A rendered-on-demand sequence.
#[derive(Debug, Clone)]
pub struct Sequence {
    pub cfg: SequenceConfig,
    lattice_seed: u64,
    shapes: Vec<(ShapeKind, f64)>,
}

fn hash(mut x: u64) -> u64 {
    // SplitMix64 finalizer.
    x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^ (x >> 31)
}

fn smooth(t: f64) -> f64 {
    t * t * (3.0 - 2.0 * t)
}

impl Sequence {
    /// Draws the shapes for `cfg`.
    pub fn new(cfg: SequenceConfig) -> Sequence {
        let mut rng = StdRng::seed_from_u64(cfg.seed);
        let (w, h) = (cfg.width as f64, cfg.height as f64);
        let s = w.min(h);
        let shapes = (0..cfg.shapes)
            .map(|i| {
                let level = rng.random_range(0.0..1.0);
                let kind = if i % 2 == 0 {
                    ShapeKind::Disc {
                        cx: rng.random_range(-0.2 * w..1.2 * w),
                        cy: rng.random_range(-0.2 * h..1.2 * h),
                        r: rng.random_range(0.04 * s..0.15 * s),
                    }
                } else {
                    let (x0, y0) = (
                        rng.random_range(-0.2 * w..1.1 * w),
                        rng.random_range(-0.2 * h..1.1 * h),
                    );
                    ShapeKind::Rect {
                        x0,
                        y0,
                        x1: x0 + rng.random_range(0.05 * s..0.3 * s),
                        y1: y0 + rng.random_range(0.05 * s..0.3 * s),
                    }
                };
                (kind, level)
            })
            .collect();
        Sequence {
            lattice_seed: hash(cfg.seed ^ 0x5EED),
            cfg,
            shapes,
        }
    }

    fn lattice(&self, octave: u64, i: i64, j: i64) -> f64 {
        let h =
            hash(self.lattice_seed ^ hash(octave) ^ hash(i as u64).rotate_left(17) ^ (j as u64));
        (h >> 11) as f64 / (1u64 << 53) as f64
    }

    fn value_noise(&self, octave: u64, cell: f64, x: f64, y: f64) -> f64 {
        let (u, v) = (x / cell, y / cell);
        let (i, j) = (u.floor(), v.floor());
        let (a, b) = (smooth(u - i), smooth(v - j));
        let (i, j) = (i as i64, j as i64);
        let l = |di, dj| self.lattice(octave, i + di, j + dj);
        let top = l(0, 0) * (1.0 - a) + l(1, 0) * a;
        let bot = l(0, 1) * (1.0 - a) + l(1, 1) * a;
        top * (1.0 - b) + bot * b
    }

    /// The scene texture at scene point `(x, y)`, in `[0, 1]`.
    pub fn texture(&self, x: f64, y: f64) -> f64 {
        if let Some([x0, y0, x1, y1]) = self.cfg.flat
            && x >= x0
            && x <= x1
            && y >= y0
            && y <= y1
        {
            return 0.5;
        }
        let mut v = 0.35 * self.value_noise(1, 24.0, x, y)
            + 0.25 * self.value_noise(2, 11.0, x, y)
            + 0.15 * self.value_noise(3, 5.0, x, y);
        v /= 0.75;
        for (shape, level) in &self.shapes {
            // Signed distance (negative inside) → soft coverage over ≈1 px.
            let d = match *shape {
                ShapeKind::Disc { cx, cy, r } => ((x - cx).hypot(y - cy)) - r,
                ShapeKind::Rect { x0, y0, x1, y1 } => {
                    let dx = (x0 - x).max(x - x1);
                    let dy = (y0 - y).max(y - y1);
                    if dx > 0.0 && dy > 0.0 {
                        dx.hypot(dy)
                    } else {
                        dx.max(dy)
                    }
                }
            };
            let cover = (0.5 - d).clamp(0.0, 1.0);
            v = v * (1.0 - 0.7 * cover) + 0.7 * cover * level;
        }
        v.clamp(0.0, 1.0)
    }

    fn centre(&self) -> [f64; 2] {
        [
            (self.cfg.width as f64 - 1.0) / 2.0,
            (self.cfg.height as f64 - 1.0) / 2.0,
        ]
    }

    /// `M_k(s)`: scene point to image point in frame `k`.
    pub fn to_image(&self, k: usize, s: [f64; 2]) -> [f64; 2] {
        let m = &self.cfg.motion;
        let c = self.centre();
        let z = m.zoom.powi(k as i32);
        let (sn, cs) = (m.rotation * k as f64).sin_cos();
        let (dx, dy) = (s[0] - c[0], s[1] - c[1]);
        [
            c[0] + z * (cs * dx - sn * dy) + m.translation[0] * k as f64,
            c[1] + z * (sn * dx + cs * dy) + m.translation[1] * k as f64,
        ]
    }

    /// `M_k⁻¹(x)`: image point in frame `k` to scene point.
    pub fn to_scene(&self, k: usize, x: [f64; 2]) -> [f64; 2] {
        let m = &self.cfg.motion;
        let c = self.centre();
        let z = m.zoom.powi(k as i32);
        let (sn, cs) = (m.rotation * k as f64).sin_cos();
        let (dx, dy) = (
            x[0] - c[0] - m.translation[0] * k as f64,
            x[1] - c[1] - m.translation[1] * k as f64,
        );
        [
            c[0] + (cs * dx + sn * dy) / z,
            c[1] + (-sn * dx + cs * dy) / z,
        ]
    }

    /// True position in frame `k` of the point seen at `p` in frame 0.
    pub fn truth(&self, k: usize, p: [f64; 2]) -> [f64; 2] {
        self.to_image(k, self.to_scene(0, p))
    }

    /// Renders frame `k` (2×2 supersampled, plus noise seeded by `(seed, k)`).
    pub fn render(&self, k: usize) -> GrayImage {
        let (w, h) = (self.cfg.width, self.cfg.height);
        let mut data = vec![0f32; w * h];
        let mut rng = StdRng::seed_from_u64(hash(self.cfg.seed ^ hash(k as u64 + 1)));
        let sigma = if self.cfg.noise.is_finite() && self.cfg.noise > 0.0 {
            self.cfg.noise
        } else {
            0.0
        };
        let normal = Normal::new(0.0, sigma).expect("finite σ ≥ 0 is valid");
        for y in 0..h {
            for x in 0..w {
                let mut v = 0.0;
                for (ox, oy) in [(-0.25, -0.25), (0.25, -0.25), (-0.25, 0.25), (0.25, 0.25)] {
                    let s = self.to_scene(k, [x as f64 + ox, y as f64 + oy]);
                    v += 0.25 * self.texture(s[0], s[1]);
                }
                if sigma > 0.0 {
                    v += normal.sample(&mut rng);
                }
                data[y * w + x] = v.clamp(0.0, 1.0) as f32;
            }
        }
        GrayImage {
            width: w,
            height: h,
            data,
        }
    }
}

/// Endpoint errors of a track table against a [`Sequence`]'s true motion.
#[derive(Debug, Clone, PartialEq)]
pub struct Score {
    /// Distance to the truth of every observation after each track's first, pixels. The
    /// truth of a track first seen at `p` in frame `f0` is `M_k(M_f0⁻¹ p)` in frame `k`
    /// (table column `k` = frame `k`).
    pub errors: Vec<f64>,
    /// Tracks with at least two observations.
    pub tracks: usize,
    /// Of those, tracks with some observation farther than `wrong_px` from the truth
    /// (wrong tracks that the tracker kept).
    pub wrong_tracks: usize,
}

impl Score {
    /// Median endpoint error (NaN when empty).
    pub fn median(&self) -> f64 {
        self.quantile(0.5)
    }

    /// `q`-quantile of the endpoint errors (nearest rank; NaN when empty).
    pub fn quantile(&self, q: f64) -> f64 {
        if self.errors.is_empty() {
            return f64::NAN;
        }
        let mut e = self.errors.clone();
        e.sort_by(f64::total_cmp);
        let i = ((q * e.len() as f64).ceil() as usize).clamp(1, e.len()) - 1;
        e[i]
    }

    /// Fraction of tracks that are wrong somewhere.
    pub fn wrong_fraction(&self) -> f64 {
        if self.tracks == 0 {
            0.0
        } else {
            self.wrong_tracks as f64 / self.tracks as f64
        }
    }
}

impl Sequence {
    /// Scores `table` (frames in rendering order) against the true motion.
    pub fn score(&self, table: &crate::TrackTable, wrong_px: f64) -> Score {
        let mut errors = Vec::new();
        let (mut tracks, mut wrong_tracks) = (0, 0);
        for p in 0..table.n_tracks() {
            let mut first: Option<[f64; 2]> = None;
            let mut n = 0;
            let mut wrong = false;
            for f in 0..table.n_frames() {
                let Some(xy) = table.get(f, p) else { continue };
                match first {
                    None => first = Some(self.to_scene(f, xy)),
                    Some(s) => {
                        let t = self.to_image(f, s);
                        let e = (xy[0] - t[0]).hypot(xy[1] - t[1]);
                        wrong |= e > wrong_px;
                        errors.push(e);
                        n += 1;
                    }
                }
            }
            if n > 0 {
                tracks += 1;
                wrong_tracks += usize::from(wrong);
            }
        }
        Score {
            errors,
            tracks,
            wrong_tracks,
        }
    }
}
