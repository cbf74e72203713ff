//! The track estimator: rigid trajectories span a 3-dimensional affine subspace of R^{2F}.
//!
//! Under an affine camera, track `p`'s trajectory `w_p ∈ R^{2F}` (rows `2f`, `2f+1` = x, y
//! in frame `f`) is `w_p = M s_p + t` with the 2F×3 motion `M`, the offset `t` and the
//! point's 3 affine coordinates `s_p` (Tomasi & Kanade 1992). Tracks of one rigid scene
//! therefore lie on a 3-dimensional affine subspace `{M s + t}`; a track that follows the
//! wrong thing (slides, jumps, belongs to an independently moving object) does not.
//!
//! * **Hypothesis** ([`Estimator::fit`]) from a minimal sample of 4 tracks `a, b, c, d`,
//!   on the frames `D` where all four are observed (at least `min_overlap`): offset
//!   `t = w_a`, directions `M = [w_b − w_a, w_c − w_a, w_d − w_a]` restricted to `D`. The
//!   sample is rejected when these directions are ill-conditioned, `σ₃/σ₁ <
//!   min_sample_condition` (the 4 tracks are nearly coplanar in the affine sense, so the
//!   subspace is not determined).
//! * **Sampling with missing data** ([`Estimator::sample`]): the first track is drawn among
//!   tracks seen in ≥ `min_overlap` frames, each further one among tracks sharing ≥
//!   `min_overlap` frames with the intersection of the tracks drawn so far, so `|D| ≥
//!   min_overlap` by construction.
//! * **Residual** ([`Estimator::residual`]) of track `p`: over the frames `O` where `p` is
//!   observed (and not excluded) and the model is defined (`|O| ≥ min_overlap`, otherwise
//!   the track cannot be scored), solve `s = argmin Σ_{f∈O} ‖M_f s + t_f − w_fp‖²` (3×3
//!   normal equations), then *trim*: drop the `⌊α|O|⌋` frames with the largest residual and
//!   refit (twice; `α = trim_fraction`), so a few gross per-entry errors on a good track do
//!   not make the whole track an outlier. The residual is the per-coordinate RMS of the
//!   kept frames, corrected for the 3 fitted parameters and for the trimming:
//!   `r² = Σ_kept ‖e_f‖² / (2k − 3) / c_α`, `c_α = 1 + α ln α / (1 − α)` (the mean of a
//!   χ²₂ variable truncated at its `1 − α` quantile, divided by 2), so that `r ≈ σ` for an
//!   inlier with Gaussian noise of σ per coordinate.
//! * **Threshold**: `r²/σ² ≈ χ²_ν/ν` with `ν = 2k − 3`; the multiple
//!   `κ = sqrt(χ²_ν(p)/ν)` is taken at the smallest scorable overlap `k = min_overlap`
//!   (the most permissive case), e.g. `κ = 1.86` for `min_overlap = 5`, `p = 0.999`.
//!   `σ = median of inlier residuals` (Wilson–Hilferty median correction).
//! * **Refit** ([`Estimator::refit`], local optimization and final fit): an affine
//!   factorization of the inlier tracks over *all* frames. Complete data: the centering
//!   trick and a rank-3 truncated SVD ([`crate::svd`]), except when the current model is
//!   already defined on every frame (a warm start: the local-optimization refits and
//!   [`TrackSubspace::refit_warm_reporting`], used for the final fit), where ALS starts
//!   from it directly. Then, or directly with missing
//!   data, alternating least squares over the observed entries, started from the current
//!   model: `s_p` by 3×3 least squares per track, `[M_f | t_f]` by 4×4 least squares per
//!   frame (a frame is defined when ≥ 4 inliers with well-conditioned coordinates see it).
//!   After every sweep, entries whose distance exceeds `sqrt(χ²₂(0.999)) · σ_e` with
//!   `σ_e = median distance / sqrt(2 ln 2)` are given zero weight in the next sweep (hard
//!   redescending reweighting), so gross entries do not pull the fit; except in a frame
//!   where fewer than half of the entries pass, whose camera is then off rather than
//!   its entries (cutting there would fit the camera exactly through the few entries it
//!   passes near), so all its entries keep their weight for the next sweep. The entries set
//!   aside by the last sweep are reported ([`TrackSubspace::refit_reporting`]) so the
//!   caller can tell whether its own gross-entry flags agree with the fit. The S-step and
//!   the distances are computed in parallel over tracks, the M-step's normal equations
//!   are accumulated over fixed chunks of tracks in parallel and summed in chunk order
//!   (so the result does not depend on the thread count).
//!
//! Hypotheses defined on few frames can only score tracks overlapping them; unscored tracks
//! cost as outliers in the MSAC score, so hypotheses (and refits) covering more frames and
//! explaining more tracks are preferred, and LO's refit extends the best one to all frames.
//!
//! Complexity: fit O(F) for the model's arrays plus O(k) for the sample's shared frames;
//! residual O(k) per track; one MSAC evaluation O(#observations); sampling with missing
//! data O(N · s/64) per draw (bitset intersections over the words a track's frames span,
//! `s` frames); refit O(F·N) for the SVD on complete data without a warm start, plus
//! O(#observations) per ALS sweep (each chunk of tracks sums its normal equations over
//! the frames its tracks span).
//!
//! Memory: the observations per track, 20 bytes an observed entry (16 on a complete
//! table), read from a dense [`Measurements`] or a sparse [`crate::TrackTable`]
//! ([`TrackSubspace::from_table`]) — no `2F × N` matrix — shared by the estimators built
//! from one another ([`TrackSubspace::with_exclusions_shared`]), plus the usable frames'
//! bitsets and, only where entries are excluded, their lists: `O(#observations + N)`. A lookup of one entry by frame is
//! `O(log k)` (`O(1)` for a track seen in every frame); the fits walk a track's entries
//! in order.

use faer::Mat;
use nalgebra::{Matrix3, Matrix4, Vector3, Vector4};
use rand::{Rng, RngExt};
use rayon::prelude::*;
use std::sync::Arc;

use super::ransac::Estimator;
use crate::Measurements;
use crate::svd::{TruncatedSvdConfig, truncated_svd};

/// Settings of the track estimator. Every field has a documented default.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct SubspaceConfig {
    /// Frames a track must share with a hypothesis to be scored, and frames the 4 tracks
    /// of a sample must share. Clamped to the number of frames. Default 5.
    pub min_overlap: usize,
    /// Fraction `α` of each track's frames trimmed from its residual (tolerated gross
    /// entries per track). Default 0.2.
    pub trim_fraction: f64,
    /// Samples whose direction matrix has `σ₃/σ₁` below this are rejected. Default 0.02.
    pub min_sample_condition: f64,
    /// ALS sweeps per local-optimization refit. Default 10.
    pub lo_als_iterations: usize,
    /// ALS sweeps of the final refit. Default 50.
    pub final_als_iterations: usize,
    /// On a complete table, the robust pass's refit after RANSAC uses at most this many
    /// of the inlier tracks, evenly spaced ([`TrackSubspace::refit_tracks`]); every track
    /// is still judged against it. 0 = all. Default 4096: the 8 parameters of a frame's
    /// camera fitted to 4096 tracks move every residual by about `σ √(8/4096) ≈ 0.04 σ`,
    /// and the refit's cost no longer grows with the tracks.
    #[serde(default = "default_max_refit_tracks")]
    pub max_refit_tracks: usize,
}

fn default_max_refit_tracks() -> usize {
    4096
}

impl Default for SubspaceConfig {
    fn default() -> Self {
        Self {
            min_overlap: 5,
            trim_fraction: 0.2,
            min_sample_condition: 0.02,
            lo_als_iterations: 10,
            final_als_iterations: 50,
            max_refit_tracks: default_max_refit_tracks(),
        }
    }
}

/// An affine subspace `{M s + t}` of R^{2F}, defined on a subset of the frames.
#[derive(Debug, Clone)]
pub struct AffineSubspace {
    /// Number of frames F.
    pub n_frames: usize,
    /// 2F×3 motion, row-major: row `r` is `m[3r..3r+3]` (rows of undefined frames are 0).
    pub m: Vec<f64>,
    /// Offset, 2F.
    pub t: Vec<f64>,
    /// Frames on which the subspace is defined.
    pub defined: Vec<bool>,
}

impl AffineSubspace {
    /// Number of frames on which the model is defined.
    pub fn n_defined(&self) -> usize {
        self.defined.iter().filter(|&&d| d).count()
    }

    /// Predicted image point of affine coordinates `s` in frame `f`.
    #[inline]
    pub fn predict(&self, f: usize, s: &[f64; 3]) -> [f64; 2] {
        let row = |r: usize| {
            self.t[r] + self.m[3 * r] * s[0] + self.m[3 * r + 1] * s[1] + self.m[3 * r + 2] * s[2]
        };
        [row(2 * f), row(2 * f + 1)]
    }

    /// The motion as a 2F×3 matrix (rows of undefined frames are 0).
    pub fn motion(&self) -> Mat<f64> {
        Mat::from_fn(2 * self.n_frames, 3, |r, k| self.m[3 * r + k])
    }

    /// Sets frame `f`'s camera: its x row to `x = [m_x; t_x]`, its y row to `y`, and marks
    /// the frame defined.
    pub(crate) fn set_camera(&mut self, f: usize, x: &Vector4<f64>, y: &Vector4<f64>) {
        for (row, v) in [(2 * f, x), (2 * f + 1, y)] {
            self.m[3 * row..3 * row + 3].copy_from_slice(&[v[0], v[1], v[2]]);
            self.t[row] = v[3];
        }
        self.defined[f] = true;
    }
}

/// One frame's least-squares camera from its normal equations `A = Σ v vᵀ`, `b_x = Σ v x`,
/// `b_y = Σ v y` over its entries (`v = [s_p; 1]`, `(x, y)` the observation): the rows
/// `([m_x; t_x], [m_y; t_y])`, or `None` when `A` is ill-conditioned or not positive
/// definite: its smallest eigenvalue not above `10⁻¹⁰ tr(A)` (a threshold between 10⁻¹⁰ and
/// 4·10⁻¹⁰ times the largest eigenvalue), tested exactly as the Cholesky factorization of
/// `A − 10⁻¹⁰ tr(A) I` failing.
/// O(1): two 4×4 factorizations (an eigendecomposition here was 30 % of a small table's
/// robust pass and segmentation).
pub(crate) fn solve_camera(
    a: &Matrix4<f64>,
    bx: &Vector4<f64>,
    by: &Vector4<f64>,
) -> Option<(Vector4<f64>, Vector4<f64>)> {
    let shift = 1e-10 * a.trace();
    if !(shift > 0.0) || (a - Matrix4::identity() * shift).cholesky().is_none() {
        return None;
    }
    a.cholesky().map(|c| (c.solve(bx), c.solve(by)))
}

/// Robust least-squares fit of one track to a model.
#[derive(Debug, Clone, Copy)]
pub struct TrackFit {
    /// Affine coordinates.
    pub s: [f64; 3],
    /// Trimmed, dof-corrected per-coordinate RMS (see the module documentation), pixels.
    pub rms: f64,
    /// Frames used for scoring (observed, not excluded, model defined).
    pub overlap: usize,
    /// Frames kept after trimming.
    pub kept: usize,
}

/// Entries a trimmed fit drops from a track seen in `k` frames: `⌊α k⌋` for `α =
/// trim_fraction`, leaving at least 2 (see the module documentation).
pub(crate) fn trim_count(trim_fraction: f64, k: usize) -> usize {
    ((trim_fraction * k as f64).floor() as usize).min(k.saturating_sub(2))
}

/// The per-coordinate squared residual of a track from the sum `ss` of squared image
/// distances over the `kept` of its `k` entries a trimmed fit keeps: `ss / (2 kept − 3) /
/// c_α`, `c_α = 1 + α ln α / (1 − α)` for the dropped fraction `α = (k − kept) / k` (the
/// module documentation), so that it is `≈ σ²` for an inlier with Gaussian noise.
pub(crate) fn trimmed_r2(ss: f64, k: usize, kept: usize) -> f64 {
    let alpha = (k - kept) as f64 / k as f64;
    let c = if alpha > 0.0 {
        1.0 + alpha * alpha.ln() / (1.0 - alpha)
    } else {
        1.0
    };
    ss / (2.0 * kept as f64 - 3.0).max(1.0) / c
}

/// Every observed entry of every track, per track in frame order (compressed by track:
/// track `p`'s entries are `start[p]..start[p + 1]`), shared by the estimators built from
/// one another. `O(n_obs)` memory: 16 bytes an entry for its coordinates and 4 for its
/// frame (no frame list when every track is seen in every frame).
#[derive(Debug)]
struct Columns {
    n_frames: usize,
    start: Vec<usize>,
    /// Frame of each entry; empty when every track is seen in every frame (then entry `i`
    /// of a track is frame `i`, see [`Columns::frames`]).
    frame: Vec<u32>,
    /// `0, 1, …, F − 1`: the frames of a complete track.
    all_frames: Vec<u32>,
    xy: Vec<[f64; 2]>,
}

impl Columns {
    /// From a dense table: `O(F·N)`, on all cores. The mask is read by tiles of tracks,
    /// each tile reading its run of every frame's row in order (as the rows are laid out),
    /// and each track's coordinates from its column of `W`; no copy beyond the result.
    fn from_measurements(meas: &Measurements) -> Self {
        const TILE: usize = 256;
        let (f, n) = (meas.n_frames(), meas.n_points());
        let col = |p: usize| meas.w.col_as_slice(p);
        if meas.is_complete() {
            let mut xy = vec![[0.0; 2]; f * n];
            xy.par_chunks_mut(f.max(1))
                .enumerate()
                .for_each(|(p, dst)| dst.as_flattened_mut().copy_from_slice(col(p)));
            let start = (0..=n).map(|p| p * f).collect();
            return Self::assemble(f, start, Vec::new(), xy);
        }
        let vis = |fr: usize, p0: usize, k: usize| &meas.visible[fr * n + p0..fr * n + p0 + k];
        let mut len = vec![0usize; n];
        len.par_chunks_mut(TILE)
            .enumerate()
            .for_each(|(tile, len)| {
                for fr in 0..f {
                    let row = vis(fr, tile * TILE, len.len());
                    len.iter_mut()
                        .zip(row)
                        .for_each(|(l, &u)| *l += usize::from(u));
                }
            });
        let mut start = Vec::with_capacity(n + 1);
        start.push(0);
        for l in &len {
            start.push(start.last().unwrap() + l);
        }
        let total = start[n];
        let (mut frame, mut xy) = (vec![0u32; total], vec![[0.0; 2]; total]);
        // Each tile's tracks own one contiguous run of the entries.
        let mut parts = Vec::with_capacity(n.div_ceil(TILE));
        let (mut fr_rest, mut xy_rest) = (frame.as_mut_slice(), xy.as_mut_slice());
        for p0 in (0..n).step_by(TILE) {
            let k = start[(p0 + TILE).min(n)] - start[p0];
            let (fa, fb) = fr_rest.split_at_mut(k);
            let (xa, xb) = xy_rest.split_at_mut(k);
            parts.push((p0, fa, xa));
            (fr_rest, xy_rest) = (fb, xb);
        }
        parts.into_par_iter().for_each(|(p0, frames, xy)| {
            let tl = TILE.min(n - p0);
            let base = start[p0];
            let mut at: Vec<usize> = (0..tl).map(|j| start[p0 + j] - base).collect();
            for fr in 0..f {
                for (j, &u) in vis(fr, p0, tl).iter().enumerate() {
                    if u {
                        frames[at[j]] = fr as u32;
                        at[j] += 1;
                    }
                }
            }
            for j in 0..tl {
                let c = col(p0 + j);
                let (a, b) = (start[p0 + j] - base, start[p0 + j + 1] - base);
                for (w, &fr) in xy[a..b].iter_mut().zip(&frames[a..b]) {
                    let r = 2 * fr as usize;
                    *w = [c[r], c[r + 1]];
                }
            }
        });
        Self::assemble(f, start, frame, xy)
    }

    /// From a sparse table: `O(n_obs)`.
    fn from_table(table: &crate::TrackTable) -> Self {
        let (start, entries) = table.by_track();
        let frame = entries.iter().map(|e| e.0).collect();
        let xy = entries.iter().map(|e| [e.1, e.2]).collect();
        drop(entries);
        Self::assemble(table.n_frames(), start, frame, xy)
    }

    /// The columns; the frame list dropped when every track is seen in every frame.
    fn assemble(f: usize, start: Vec<usize>, mut frame: Vec<u32>, xy: Vec<[f64; 2]>) -> Self {
        let n = start.len() - 1;
        if xy.len() == f * n {
            frame = Vec::new();
        }
        Self {
            n_frames: f,
            start,
            frame,
            all_frames: (0..f as u32).collect(),
            xy,
        }
    }

    fn n_tracks(&self) -> usize {
        self.start.len() - 1
    }

    /// Track `p`'s observed frames, in order.
    #[inline]
    fn frames(&self, p: usize) -> &[u32] {
        if self.frame.is_empty() {
            &self.all_frames[..self.start[p + 1] - self.start[p]]
        } else {
            &self.frame[self.start[p]..self.start[p + 1]]
        }
    }

    /// Track `p`'s observations, aligned with [`Self::frames`].
    #[inline]
    fn xy(&self, p: usize) -> &[[f64; 2]] {
        &self.xy[self.start[p]..self.start[p + 1]]
    }

    /// Track `p`'s observation in frame `f`, `[0, 0]` when it has none there (as the dense
    /// W holds). `O(1)` for a track seen in every frame of its span (a track that enters
    /// and leaves once), else `O(log k)`.
    #[inline]
    fn get(&self, p: usize, f: usize) -> [f64; 2] {
        let (a, b) = (self.start[p], self.start[p + 1]);
        let k = b - a;
        if k == self.n_frames {
            return self.xy[a + f];
        }
        let fr = &self.frame[a..b];
        let (Some(&first), Some(&last)) = (fr.first(), fr.last()) else {
            return [0.0, 0.0];
        };
        let (first, last) = (first as usize, last as usize);
        if f < first || f > last {
            return [0.0, 0.0];
        }
        if last - first + 1 == k {
            return self.xy[a + f - first];
        }
        match fr.binary_search(&(f as u32)) {
            Ok(i) => self.xy[a + i],
            Err(_) => [0.0, 0.0],
        }
    }

    /// The tracks `tracks` on the frames `a..b` (renumbered from 0): `O(Σ log k + n_obs of
    /// the result)`.
    fn select(&self, a: usize, b: usize, tracks: &[usize]) -> Self {
        let mut start = Vec::with_capacity(tracks.len() + 1);
        start.push(0);
        let (mut frame, mut xy) = (Vec::new(), Vec::new());
        for &p in tracks {
            let fr = self.frames(p);
            let lo = fr.partition_point(|&x| (x as usize) < a);
            let hi = fr.partition_point(|&x| (x as usize) < b);
            frame.extend(fr[lo..hi].iter().map(|&x| x - a as u32));
            xy.extend_from_slice(&self.xy(p)[lo..hi]);
            start.push(xy.len());
        }
        Self::assemble(b - a, start, frame, xy)
    }
}

/// Track `p`'s usable frames: its own list when entries were excluded (`usable`), else its
/// observed frames.
#[inline]
fn usable_frames<'a>(cols: &'a Columns, usable: Option<&'a [Vec<u32>]>, p: usize) -> &'a [u32] {
    match usable {
        Some(u) => &u[p],
        None => cols.frames(p),
    }
}

/// Track `p`'s usable entries `(frame, observation)` in frame order: its usable frames
/// walked beside its observed ones (a subset of them, both sorted).
struct Usable<'a> {
    usable: std::slice::Iter<'a, u32>,
    frames: &'a [u32],
    xy: &'a [[f64; 2]],
    j: usize,
    /// Every observed entry is usable: the `j`-th usable entry is the `j`-th observed one.
    all: bool,
}

impl Iterator for Usable<'_> {
    type Item = (u32, [f64; 2]);

    #[inline]
    fn next(&mut self) -> Option<(u32, [f64; 2])> {
        let f = *self.usable.next()?;
        if !self.all {
            while self.frames[self.j] != f {
                self.j += 1;
            }
        }
        let out = (f, self.xy[self.j]);
        self.j += 1;
        Some(out)
    }
}

/// Per track, a bitset of its usable frames over the words its frames span: track `p`'s
/// words `bits[start[p]..start[p + 1]]` cover frames from `64 · lo[p]` on. `O(Σ span/64)`
/// memory, at most one word per usable entry plus one per track.
#[derive(Debug, Clone)]
struct Spans {
    lo: Vec<usize>,
    start: Vec<usize>,
    bits: Vec<u64>,
}

/// A bitset over frames, from word `lo` on.
#[derive(Debug, Clone)]
struct FrameMask {
    lo: usize,
    words: Vec<u64>,
}

impl Spans {
    /// The bitsets of `n` tracks whose usable frames are `frames_of(p)`.
    fn new<'a>(n: usize, frames_of: impl Fn(usize) -> &'a [u32]) -> Self {
        let (mut lo, mut start) = (Vec::with_capacity(n), Vec::with_capacity(n + 1));
        start.push(0);
        let mut bits = Vec::new();
        for fr in (0..n).map(frames_of) {
            let (first, last) = match (fr.first(), fr.last()) {
                (Some(&a), Some(&b)) => (a as usize / 64, b as usize / 64 + 1),
                _ => (0, 0),
            };
            let base = bits.len();
            bits.resize(base + last - first, 0);
            for &f in fr {
                bits[base + f as usize / 64 - first] |= 1u64 << (f % 64);
            }
            lo.push(first);
            start.push(bits.len());
        }
        Self { lo, start, bits }
    }

    fn words(&self, p: usize) -> &[u64] {
        &self.bits[self.start[p]..self.start[p + 1]]
    }

    fn mask(&self, p: usize) -> FrameMask {
        FrameMask {
            lo: self.lo[p],
            words: self.words(p).to_vec(),
        }
    }

    /// Usable frames of `p` in `mask`.
    fn overlap(&self, p: usize, mask: &FrameMask) -> usize {
        let w = self.words(p);
        let (a, b) = (
            self.lo[p].max(mask.lo),
            (self.lo[p] + w.len()).min(mask.lo + mask.words.len()),
        );
        (a..b)
            .map(|k| (w[k - self.lo[p]] & mask.words[k - mask.lo]).count_ones() as usize)
            .sum()
    }

    /// `mask ∩ (usable frames of p)`.
    fn intersect(&self, p: usize, mask: &mut FrameMask) {
        let w = self.words(p);
        for (k, m) in mask.words.iter_mut().enumerate() {
            let g = mask.lo + k;
            *m &= if g >= self.lo[p] && g < self.lo[p] + w.len() {
                w[g - self.lo[p]]
            } else {
                0
            };
        }
    }

    /// Whether frame `f` is a usable frame of `p`.
    #[inline]
    fn has(&self, p: usize, f: usize) -> bool {
        let k = f / 64;
        let w = self.words(p);
        k >= self.lo[p] && k < self.lo[p] + w.len() && w[k - self.lo[p]] & (1u64 << (f % 64)) != 0
    }
}

/// The track estimator over the columns of a [`Measurements`] or a sparse
/// [`crate::TrackTable`]; items are track indices.
#[derive(Debug, Clone)]
pub struct TrackSubspace {
    f: usize,
    n: usize,
    /// Every observed entry per track, shared by the estimators built from one another
    /// ([`Self::with_exclusions_shared`], clones).
    cols: Arc<Columns>,
    /// Usable frames per track when entries were excluded; `None`: every observed entry
    /// is usable, and a track's usable frames are its observed ones ([`Columns::frames`]).
    usable: Option<Vec<Vec<u32>>>,
    /// Bitsets of the usable frames per track, over the words each track spans.
    spans: Spans,
    /// Tracks with at least `min_overlap` usable frames.
    eligible: Vec<usize>,
    complete: bool,
    cfg: SubspaceConfig,
    min_overlap: usize,
    /// Degrees of freedom of a track of median length (for the σ median correction).
    nu_typical: f64,
}

/// ALS stops when a sweep changes the cost `Σ kept d²` by less than this, relatively.
/// 1e-6 moves the fit by far less than the noise (the cost's relative standard error is
/// `~1/sqrt(#entries)`), and stops the slow linear tail of ALS early.
const ALS_TOLERANCE: f64 = 1e-6;

/// Tracks per chunk of the ALS M-step's parallel accumulation.
const ALS_CHUNK: usize = 256;

/// Chunks of the ALS M-step whose partial sums are held at once.
const ALS_BATCH: usize = 64;

/// `sqrt(2 ln 2)`: the median of the distance of a 2D standard Gaussian.
const RAYLEIGH_MEDIAN: f64 = 1.177_410_022_515_474_8;

fn solve3(g: &Matrix3<f64>, b: &Vector3<f64>) -> Option<Vector3<f64>> {
    let scale = g.diagonal().max();
    if !(scale > 0.0) {
        return None;
    }
    // Cholesky pivots squared bound the smallest eigenvalue from above; a tiny pivot means
    // the coordinates are not determined (relative tolerance 1e-10).
    let c = g.cholesky()?;
    let l = c.l_dirty();
    let min_pivot = (0..3)
        .map(|i| l[(i, i)] * l[(i, i)])
        .fold(f64::INFINITY, f64::min);
    if !(min_pivot > 1e-10 * scale) {
        return None;
    }
    Some(c.solve(b))
}

/// Per-thread scratch of [`TrackSubspace::track_fit`]: the usable frames of the track, its
/// observations minus the model offset, and (distance², local index) pairs for trimming.
#[derive(Default)]
struct Scratch {
    fr: Vec<u32>,
    y: Vec<[f64; 2]>,
    d2: Vec<(f64, u32)>,
}

thread_local! {
    static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::new(Scratch::default());
}

/// `‖M_f s − y‖²` for frame `fr` of a row-major 2F×3 motion `m`.
#[inline]
fn frame_dist2(m: &[f64], fr: u32, y: &[f64; 2], s: &[f64; 3]) -> f64 {
    let r = &m[6 * fr as usize..6 * fr as usize + 6];
    let ex = r[0] * s[0] + r[1] * s[1] + r[2] * s[2] - y[0];
    let ey = r[3] * s[0] + r[4] * s[1] + r[5] * s[2] - y[1];
    ex * ex + ey * ey
}

/// Squared image distance of the observation `w` in frame `fr` to `M_f s + t_f`.
#[inline]
fn dist2_to(model: &AffineSubspace, fr: usize, s: &[f64; 3], w: [f64; 2]) -> f64 {
    let q = model.predict(fr, s);
    let dx = q[0] - w[0];
    let dy = q[1] - w[1];
    dx * dx + dy * dy
}

/// Least-squares `s = argmin Σ_i ‖M_{fr_i} s − y_i‖²` over the local indices `idx`
/// (normal equations, [`solve3`]).
#[inline]
fn normal_solve(
    m: &[f64],
    fr: &[u32],
    y: &[[f64; 2]],
    idx: impl Iterator<Item = usize>,
) -> Option<[f64; 3]> {
    normal_solve_rows(m, idx.map(|i| (fr[i] as usize, y[i])))
}

/// Least-squares `s = argmin Σ ‖M_f s − y‖²` over `(frame f, y)` pairs of a row-major 2F×3
/// motion `m` (normal equations, [`solve3`]). O(#pairs).
#[inline]
fn normal_solve_rows(m: &[f64], rows: impl Iterator<Item = (usize, [f64; 2])>) -> Option<[f64; 3]> {
    let (mut g00, mut g01, mut g02, mut g11, mut g12, mut g22) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    let (mut b0, mut b1, mut b2) = (0.0, 0.0, 0.0);
    for (f, [yx, yy]) in rows {
        let r = &m[6 * f..6 * f + 6];
        g00 += r[0] * r[0] + r[3] * r[3];
        g01 += r[0] * r[1] + r[3] * r[4];
        g02 += r[0] * r[2] + r[3] * r[5];
        g11 += r[1] * r[1] + r[4] * r[4];
        g12 += r[1] * r[2] + r[4] * r[5];
        g22 += r[2] * r[2] + r[5] * r[5];
        b0 += r[0] * yx + r[3] * yy;
        b1 += r[1] * yx + r[4] * yy;
        b2 += r[2] * yx + r[5] * yy;
    }
    let g = Matrix3::new(g00, g01, g02, g01, g11, g12, g02, g12, g22);
    solve3(&g, &Vector3::new(b0, b1, b2)).map(|s| [s[0], s[1], s[2]])
}

impl TrackSubspace {
    /// Builds the estimator for all tracks of `meas`, with no excluded entry. O(F·N).
    pub fn new(meas: &Measurements, cfg: &SubspaceConfig) -> Self {
        Self::with_exclusions(meas, cfg, &[])
    }

    /// Builds the estimator for all tracks of a sparse `table`, with no excluded entry:
    /// `O(n_obs)` time and memory (no `2F × N` matrix).
    pub fn from_table(table: &crate::TrackTable, cfg: &SubspaceConfig) -> Self {
        Self::build(Arc::new(Columns::from_table(table)), cfg, &[])
    }

    /// Builds the estimator with the given (frame, track) entries treated as unobserved.
    pub fn with_exclusions(
        meas: &Measurements,
        cfg: &SubspaceConfig,
        excluded: &[(usize, usize)],
    ) -> Self {
        Self::build(Arc::new(Columns::from_measurements(meas)), cfg, excluded)
    }

    /// [`Self::with_exclusions`] of the measurements this estimator was built from (`meas`
    /// must be them) and its settings, sharing its copy of the observations instead of
    /// making another: `O(n_obs + E log E)` for `E` exclusions.
    pub fn with_exclusions_shared(&self, meas: &Measurements, excluded: &[(usize, usize)]) -> Self {
        debug_assert_eq!((meas.n_frames(), meas.n_points()), (self.f, self.n));
        Self::build(Arc::clone(&self.cols), &self.cfg, excluded)
    }

    /// The estimator of the tracks `tracks` (indices here) on the frames `a..b` (renumbered
    /// from 0), every observed entry of theirs there usable, with the same settings:
    /// what [`Self::new`] builds from `meas.select(a..b, tracks)`, in `O(n_obs` of the
    /// result `+ Σ log k)` instead of `O((b − a) · |tracks|)`.
    pub fn select(&self, a: usize, b: usize, tracks: &[usize]) -> Self {
        Self::build(Arc::new(self.cols.select(a, b, tracks)), &self.cfg, &[])
    }

    fn build(cols: Arc<Columns>, cfg: &SubspaceConfig, excluded: &[(usize, usize)]) -> Self {
        let (f, n) = (cols.n_frames, cols.n_tracks());
        // The exclusions by track, then each track's observed frames without them.
        let mut by_track: Vec<(usize, u32)> = excluded
            .iter()
            .filter(|&&(fr, p)| fr < f && p < n)
            .map(|&(fr, p)| (p, fr as u32))
            .collect();
        by_track.sort_unstable();
        let usable = (!by_track.is_empty()).then(|| {
            let mut e = 0;
            (0..n)
                .map(|p| {
                    let fr = cols.frames(p);
                    let b = e + by_track[e..].partition_point(|x| x.0 == p);
                    let ex = &by_track[e..b];
                    e = b;
                    fr.iter()
                        .copied()
                        .filter(|x| ex.binary_search(&(p, *x)).is_err())
                        .collect::<Vec<u32>>()
                })
                .collect::<Vec<_>>()
        });
        let frames_of = |p: usize| usable_frames(&cols, usable.as_deref(), p);
        let spans = Spans::new(n, frames_of);
        let min_overlap = cfg.min_overlap.clamp(2, f.max(2));
        let eligible: Vec<usize> = (0..n)
            .filter(|&p| frames_of(p).len() >= min_overlap)
            .collect();
        let complete = (0..n).all(|p| frames_of(p).len() == f);
        let mut lens: Vec<f64> = (0..n).map(|p| frames_of(p).len() as f64).collect();
        let med = if lens.is_empty() {
            min_overlap as f64
        } else {
            let k = lens.len() / 2;
            *lens.select_nth_unstable_by(k, |a, b| a.total_cmp(b)).1
        };
        Self {
            f,
            n,
            cols,
            usable,
            spans,
            eligible,
            complete,
            cfg: cfg.clone(),
            min_overlap,
            nu_typical: (2.0 * med - 3.0).max(1.0),
        }
    }

    /// Number of tracks.
    pub fn n_tracks(&self) -> usize {
        self.n
    }

    /// Number of frames.
    pub fn n_frames(&self) -> usize {
        self.f
    }

    /// Tracks seen in at least `min_overlap` frames (the ones that can be sampled).
    pub fn n_eligible(&self) -> usize {
        self.eligible.len()
    }

    /// The effective `min_overlap` (clamped to the number of frames).
    pub fn min_overlap(&self) -> usize {
        self.min_overlap
    }

    /// Usable frames of track `p`.
    #[inline]
    pub fn frames_of(&self, p: usize) -> &[u32] {
        usable_frames(&self.cols, self.usable.as_deref(), p)
    }

    /// Track `p`'s usable entries `(frame, observation)`, in frame order.
    #[inline]
    fn usable(&self, p: usize) -> Usable<'_> {
        let (frames, usable) = (self.cols.frames(p), self.frames_of(p));
        Usable {
            usable: usable.iter(),
            frames,
            xy: self.cols.xy(p),
            j: 0,
            all: frames.len() == usable.len(),
        }
    }

    /// Observed image point of track `p` in frame `f` (whether usable or not; `[0, 0]`
    /// where it is not observed).
    #[inline]
    pub fn observation(&self, f: usize, p: usize) -> [f64; 2] {
        self.cols.get(p, f)
    }

    /// Least-squares coordinates of track `p` from `frames` (which must be defined);
    /// `None` when they are not determined.
    pub fn ls_coords(&self, model: &AffineSubspace, p: usize, frames: &[u32]) -> Option<[f64; 3]> {
        let t = &model.t;
        normal_solve_rows(
            &model.m,
            frames.iter().map(|&fr| {
                let f = fr as usize;
                let w = self.cols.get(p, f);
                (f, [w[0] - t[2 * f], w[1] - t[2 * f + 1]])
            }),
        )
    }

    /// Squared image distance of track `p`'s observation in frame `fr` to `M_f s + t_f`.
    #[inline]
    pub fn dist2(&self, model: &AffineSubspace, p: usize, fr: usize, s: &[f64; 3]) -> f64 {
        dist2_to(model, fr, s, self.cols.get(p, fr))
    }

    /// Trimmed robust fit of track `p` (see the module documentation); `None` when the
    /// track shares fewer than `min_overlap` usable frames with the model or its
    /// coordinates are not determined. Allocation-free after a thread's first call (a
    /// thread-local scratch holds the track's centred observations); O(k) with k the
    /// overlap (three 3×3 solves, two linear-time selections).
    pub fn track_fit(&self, model: &AffineSubspace, p: usize) -> Option<TrackFit> {
        SCRATCH.with_borrow_mut(|sc| self.track_fit_in(model, p, sc))
    }

    fn track_fit_in(&self, model: &AffineSubspace, p: usize, sc: &mut Scratch) -> Option<TrackFit> {
        sc.fr.clear();
        sc.y.clear();
        for (fr, w) in self.usable(p) {
            let f = fr as usize;
            if model.defined[f] {
                sc.fr.push(fr);
                sc.y.push([w[0] - model.t[2 * f], w[1] - model.t[2 * f + 1]]);
            }
        }
        let k = sc.fr.len();
        if k < self.min_overlap {
            return None;
        }
        let (fr, y) = (&sc.fr, &sc.y);
        let mut s = normal_solve(&model.m, fr, y, 0..k)?;
        let trim = trim_count(self.cfg.trim_fraction, k);
        let kk = k - trim;
        if trim > 0 {
            for _ in 0..2 {
                sc.d2.clear();
                sc.d2
                    .extend((0..k).map(|i| (frame_dist2(&model.m, fr[i], &y[i], &s), i as u32)));
                sc.d2
                    .select_nth_unstable_by(kk - 1, |a, b| a.0.total_cmp(&b.0));
                match normal_solve(&model.m, fr, y, sc.d2[..kk].iter().map(|x| x.1 as usize)) {
                    Some(s2) => s = s2,
                    None => break,
                }
            }
        } else {
            sc.d2.clear();
            sc.d2.extend((0..k).map(|i| (0.0, i as u32)));
        }
        let ss: f64 = sc.d2[..kk]
            .iter()
            .map(|x| {
                let i = x.1 as usize;
                frame_dist2(&model.m, fr[i], &y[i], &s)
            })
            .sum();
        Some(TrackFit {
            s,
            rms: trimmed_r2(ss, k, kk).sqrt(),
            overlap: k,
            kept: kk,
        })
    }

    /// Affine factorization of `inliers` over all frames, started from `model`, with
    /// `sweeps` ALS sweeps (see the module documentation). Public for the final refit.
    pub fn refit_with(
        &self,
        model: &AffineSubspace,
        inliers: &[usize],
        sweeps: usize,
    ) -> Option<AffineSubspace> {
        self.refit_reporting(model, inliers, sweeps).map(|(m, _)| m)
    }

    /// [`TrackSubspace::refit_with`], also returning the usable (frame, track) entries of
    /// `inliers`, in frames where the returned model is defined, that the last ALS sweep
    /// gave zero weight (sorted): the returned model is the least-squares fit to the
    /// usable entries of `inliers` without these (up to the ALS tolerance).
    pub fn refit_reporting(
        &self,
        model: &AffineSubspace,
        inliers: &[usize],
        sweeps: usize,
    ) -> Option<(AffineSubspace, Vec<(usize, usize)>)> {
        if inliers.len() < 4 {
            return None;
        }
        let mut init = model.clone();
        if self.complete {
            init = self.svd_fit(inliers)?;
        }
        self.als(init, inliers, sweeps)
    }

    /// [`TrackSubspace::refit_reporting`] started from `model` itself when it is a warm
    /// start: on complete data with `model` defined on every frame (e.g. the RANSAC
    /// model, already a refit on a subset of the same inliers) the SVD initialization is
    /// skipped and the ALS sweeps converge from `model` (at the rate `σ₄/σ₃ ≪ 1` of a
    /// rank-3-plus-noise matrix) to the same least-squares fit; otherwise identical to
    /// `refit_reporting`. Saves the O(F·N) SVD.
    pub fn refit_warm_reporting(
        &self,
        model: &AffineSubspace,
        inliers: &[usize],
        sweeps: usize,
    ) -> Option<(AffineSubspace, Vec<(usize, usize)>)> {
        if self.complete && model.n_defined() == self.f {
            if inliers.len() < 4 {
                return None;
            }
            return self.als(model.clone(), inliers, sweeps);
        }
        self.refit_reporting(model, inliers, sweeps)
    }

    /// The tracks of `inliers` (sorted) a refit uses: all of them, or on a complete table
    /// at most `max` (> 0) evenly spaced ones (every frame sees each of them).
    pub fn refit_tracks<'a>(
        &self,
        inliers: &'a [usize],
        max: usize,
    ) -> std::borrow::Cow<'a, [usize]> {
        if !self.complete || max == 0 || inliers.len() <= max {
            return std::borrow::Cow::Borrowed(inliers);
        }
        std::borrow::Cow::Owned(
            crate::degeneracy::spaced(inliers.len(), max)
                .into_iter()
                .map(|i| inliers[i])
                .collect(),
        )
    }

    /// Centering + rank-3 truncated SVD of the (complete) inlier columns.
    fn svd_fit(&self, inliers: &[usize]) -> Option<AffineSubspace> {
        let rows = 2 * self.f;
        let k = inliers.len() as f64;
        // Row means, summed column by column (each row's sum still in inlier order).
        let mut t = vec![0.0; rows];
        // Complete: each column is its track's observations in frame order.
        let col = |p: usize| self.cols.xy(p).as_flattened();
        for &p in inliers {
            t.iter_mut().zip(col(p)).for_each(|(tr, &w)| *tr += w);
        }
        t.iter_mut().for_each(|tr| *tr /= k);
        let x = Mat::from_fn(rows, inliers.len(), |r, j| col(inliers[j])[r] - t[r]);
        let svd = truncated_svd(x.as_ref(), 3, &TruncatedSvdConfig::default()).ok()?;
        if svd.s.len() < 3 || !(svd.s[2] > 0.0) {
            return None;
        }
        let mut m = vec![0.0; rows * 3];
        for r in 0..rows {
            for c in 0..3 {
                m[3 * r + c] = svd.u[(r, c)] * svd.s[c];
            }
        }
        Some(AffineSubspace {
            n_frames: self.f,
            m,
            t,
            defined: vec![true; self.f],
        })
    }

    /// The frames `lo..hi` the usable entries of `tracks` span (`0..0` when none).
    fn span_of(&self, tracks: &[usize]) -> (usize, usize) {
        let lo = tracks
            .iter()
            .filter_map(|&p| self.frames_of(p).first())
            .min();
        let hi = tracks
            .iter()
            .filter_map(|&p| self.frames_of(p).last())
            .max();
        match (lo, hi) {
            (Some(&lo), Some(&hi)) => (lo as usize, hi as usize + 1),
            _ => (0, 0),
        }
    }

    /// Alternating least squares with hard rejection of outlying entries; also returns the
    /// entries the last sweep gave zero weight (see [`TrackSubspace::refit_reporting`]).
    fn als(
        &self,
        mut model: AffineSubspace,
        inliers: &[usize],
        sweeps: usize,
    ) -> Option<(AffineSubspace, Vec<(usize, usize)>)> {
        if inliers.is_empty() {
            return None;
        }
        let f = self.f;
        // Entry weights, aligned with frames_of of each inlier.
        let mut keep: Vec<Vec<bool>> = inliers
            .iter()
            .map(|&p| vec![true; self.frames_of(p).len()])
            .collect();
        let mut coords: Vec<Option<[f64; 3]>> = vec![None; inliers.len()];
        // The weights used by the last sweep's S- and M-steps.
        let mut used: Vec<Vec<bool>> = Vec::new();
        let mut d2s: Vec<Vec<f64>> = vec![Vec::new(); inliers.len()];
        let mut last_cost = f64::INFINITY;
        let chi2_cut = super::chi2_quantile(2.0, 0.999);
        for sweep in 0..sweeps.max(1) {
            // S-step (parallel over tracks; each solve is independent).
            coords = inliers
                .par_iter()
                .zip(keep.par_iter())
                .with_min_len(64)
                .map(|(&p, kp)| {
                    let used = |fr: u32, k: bool| k && model.defined[fr as usize];
                    let count = self
                        .frames_of(p)
                        .iter()
                        .zip(kp)
                        .filter(|(fr, k)| used(**fr, **k))
                        .count();
                    if count < 2 {
                        return None;
                    }
                    let t = &model.t;
                    normal_solve_rows(
                        &model.m,
                        self.usable(p)
                            .zip(kp)
                            .filter(|((fr, _), k)| used(*fr, **k))
                            .map(|((fr, w), _)| {
                                let f = fr as usize;
                                (f, [w[0] - t[2 * f], w[1] - t[2 * f + 1]])
                            }),
                    )
                })
                .collect();
            // M-step: per frame, [m_x t_x; m_y t_y] from Σ [s;1][s;1]ᵀ.
            // Accumulated in parallel over fixed chunks of tracks, then summed in chunk
            // order (the result does not depend on the thread count).
            // Each chunk's sums cover the frames its tracks span, and the chunks are taken
            // ALS_BATCH at a time: memory O(ALS_BATCH · span + F), not O(F · N / chunk).
            let mut a = vec![Matrix4::<f64>::zeros(); f];
            let mut bx = vec![Vector4::<f64>::zeros(); f];
            let mut by = vec![Vector4::<f64>::zeros(); f];
            let mut cnt = vec![0usize; f];
            let n_chunks = inliers.len().div_ceil(ALS_CHUNK);
            for b0 in (0..n_chunks).step_by(ALS_BATCH) {
                let parts: Vec<_> = (b0..(b0 + ALS_BATCH).min(n_chunks))
                    .into_par_iter()
                    .map(|c| {
                        let j0 = c * ALS_CHUNK;
                        let chunk = &inliers[j0..(j0 + ALS_CHUNK).min(inliers.len())];
                        let (lo, hi) = self.span_of(chunk);
                        let mut a = vec![Matrix4::<f64>::zeros(); hi - lo];
                        let mut bx = vec![Vector4::<f64>::zeros(); hi - lo];
                        let mut by = vec![Vector4::<f64>::zeros(); hi - lo];
                        let mut cnt = vec![0usize; hi - lo];
                        for (jj, &p) in chunk.iter().enumerate() {
                            let j = j0 + jj;
                            let Some(s) = coords[j] else { continue };
                            let v = Vector4::new(s[0], s[1], s[2], 1.0);
                            let vv = v * v.transpose();
                            for ((fr, w), &k) in self.usable(p).zip(&keep[j]) {
                                if !k {
                                    continue;
                                }
                                let i = fr as usize - lo;
                                a[i] += vv;
                                bx[i] += v * w[0];
                                by[i] += v * w[1];
                                cnt[i] += 1;
                            }
                        }
                        (lo, a, bx, by, cnt)
                    })
                    .collect();
                // Summed in chunk order (adding a chunk's zeros elsewhere changes nothing).
                for (lo, pa, pbx, pby, pc) in parts {
                    for i in 0..pa.len() {
                        a[lo + i] += pa[i];
                        bx[lo + i] += pbx[i];
                        by[lo + i] += pby[i];
                        cnt[lo + i] += pc[i];
                    }
                }
            }
            for fr in 0..f {
                let sol = if cnt[fr] >= 4 {
                    solve_camera(&a[fr], &bx[fr], &by[fr])
                } else {
                    None
                };
                match sol {
                    Some((x, y)) => model.set_camera(fr, &x, &y),
                    None => {
                        model.defined[fr] = false;
                        for row in [2 * fr, 2 * fr + 1] {
                            model.m[3 * row..3 * row + 3].fill(0.0);
                            model.t[row] = 0.0;
                        }
                    }
                }
            }
            used.clone_from(&keep);
            // Re-weighting: distances of all inlier entries, robust scale, hard cut.
            // Squared distances per entry (NaN: not scored), in parallel over tracks.
            d2s.par_iter_mut()
                .zip(inliers.par_iter().zip(coords.par_iter()))
                .with_min_len(ALS_CHUNK)
                .for_each(|(d2, (&p, s))| {
                    d2.clear();
                    d2.extend(self.usable(p).map(|(fr, w)| match s {
                        Some(s) if model.defined[fr as usize] => {
                            dist2_to(&model, fr as usize, s, w)
                        }
                        _ => f64::NAN,
                    }));
                });
            // The median scored distance, on all cores, without a buffer of them all
            // ([`super::select::order_statistics`]; exact).
            let ([med, _], _) = super::select::order_statistics(
                d2s.len(),
                |j| d2s[j].iter().copied().filter(|x| !x.is_nan()),
                |n| (n / 2, n / 2),
            )?;
            let sigma_e = med.sqrt() / RAYLEIGH_MEDIAN;
            let cut2 = chi2_cut * sigma_e * sigma_e;
            // Per frame: scored entries, and those within the cut. A frame whose camera
            // is far off (a poor start where few tracks are seen) would keep only the few
            // entries it happens to pass near, and the next M-step would fit the camera
            // through them exactly (4 entries determine it), a fixed point with every
            // other entry "gross". Inlier tracks agree with the true camera in most of
            // their entries, so when fewer than half of a frame's entries pass, the cut is
            // not applied there: the next M-step fits all of them (least squares, pulled
            // only by the frame's few gross entries), and the cut applies again from it.
            // (Counted over chunks of tracks on all cores; integer counts, exact.)
            let (scored, within) = inliers
                .par_chunks(ALS_CHUNK)
                .zip(d2s.par_chunks(ALS_CHUNK))
                .fold(
                    || (vec![0usize; f], vec![0usize; f]),
                    |(mut scored, mut within), (ps, ds)| {
                        for (&p, d2s) in ps.iter().zip(ds) {
                            for (&fr, &d2) in self.frames_of(p).iter().zip(d2s) {
                                if !d2.is_nan() {
                                    scored[fr as usize] += 1;
                                    within[fr as usize] += usize::from(d2 <= cut2 || cut2 == 0.0);
                                }
                            }
                        }
                        (scored, within)
                    },
                )
                .reduce(
                    || (vec![0usize; f], vec![0usize; f]),
                    |(mut s, mut w), (s2, w2)| {
                        s.iter_mut().zip(s2).for_each(|(a, b)| *a += b);
                        w.iter_mut().zip(w2).for_each(|(a, b)| *a += b);
                        (s, w)
                    },
                );
            let cut_frame: Vec<bool> = (0..f).map(|fr| 2 * within[fr] >= scored[fr]).collect();
            // Per track (on all cores) the new weights and the kept entries' cost, the
            // tracks' costs then added in track order (independent of the thread count).
            let track_cost: Vec<f64> = keep
                .par_iter_mut()
                .zip(d2s.par_iter().zip(inliers.par_iter()))
                .with_min_len(ALS_CHUNK)
                .map(|(kp, (d2s, &p))| {
                    let mut c = 0.0;
                    for ((k, &d2), &fr) in kp.iter_mut().zip(d2s).zip(self.frames_of(p)) {
                        if !d2.is_nan() {
                            *k = d2 <= cut2 || cut2 == 0.0 || !cut_frame[fr as usize];
                            if *k {
                                c += d2;
                            }
                        }
                    }
                    c
                })
                .collect();
            let cost: f64 = track_cost.iter().sum();
            if sweep > 1 && (last_cost - cost).abs() <= ALS_TOLERANCE * last_cost.max(1e-300) {
                break;
            }
            last_cost = cost;
        }
        if model.n_defined() < self.min_overlap {
            return None;
        }
        let mut excluded: Vec<(usize, usize)> = Vec::new();
        for (j, &p) in inliers.iter().enumerate() {
            for (&fr, &k) in self.frames_of(p).iter().zip(&used[j]) {
                if !k && model.defined[fr as usize] {
                    excluded.push((fr as usize, p));
                }
            }
        }
        excluded.sort_unstable();
        Some((model, excluded))
    }
}

impl Estimator for TrackSubspace {
    type Model = AffineSubspace;

    fn min_sample_size(&self) -> usize {
        4
    }

    fn sample<R: Rng + ?Sized>(&self, _n: usize, rng: &mut R, out: &mut Vec<usize>) -> bool {
        out.clear();
        let e = &self.eligible;
        if e.len() < 4 {
            return false;
        }
        let first = e[rng.random_range(0..e.len())];
        out.push(first);
        if self.complete {
            while out.len() < 4 {
                let c = e[rng.random_range(0..e.len())];
                if !out.contains(&c) {
                    out.push(c);
                }
            }
            return true;
        }
        let mut mask = self.spans.mask(first);
        let mut cand = Vec::new();
        while out.len() < 4 {
            cand.clear();
            cand.extend(
                e.iter().copied().filter(|c| {
                    !out.contains(c) && self.spans.overlap(*c, &mask) >= self.min_overlap
                }),
            );
            if cand.is_empty() {
                return false;
            }
            let c = cand[rng.random_range(0..cand.len())];
            self.spans.intersect(c, &mut mask);
            out.push(c);
        }
        true
    }

    fn fit(&self, sample: &[usize]) -> Option<AffineSubspace> {
        if sample.len() != 4 {
            return None;
        }
        let f = self.f;
        // The frames all four use, and the four tracks' observations there (a cursor in
        // each track's observed frames).
        let shared: Vec<u32> = self
            .frames_of(sample[0])
            .iter()
            .copied()
            .filter(|&fr| sample[1..].iter().all(|&p| self.spans.has(p, fr as usize)))
            .collect();
        if shared.len() < self.min_overlap {
            return None;
        }
        let mut defined = vec![false; f];
        let mut m = vec![0.0; 6 * f];
        let mut t = vec![0.0; 2 * f];
        let mut g = Matrix3::<f64>::zeros();
        let mut cursor = [0usize; 4];
        for &fr in &shared {
            let mut w = [[0.0; 2]; 4];
            for (k, &p) in sample.iter().enumerate() {
                let frames = self.cols.frames(p);
                while frames[cursor[k]] != fr {
                    cursor[k] += 1;
                }
                w[k] = self.cols.xy(p)[cursor[k]];
            }
            let fr = fr as usize;
            defined[fr] = true;
            for c in 0..2 {
                let r = 2 * fr + c;
                t[r] = w[0][c];
                let v = Vector3::new(w[1][c] - t[r], w[2][c] - t[r], w[3][c] - t[r]);
                m[3 * r..3 * r + 3].copy_from_slice(v.as_slice());
                g += v * v.transpose();
            }
        }
        let e = g.symmetric_eigenvalues();
        let (lo, hi) = (e.min(), e.max());
        if !(hi > 0.0) || !(lo >= 0.0) || (lo / hi).sqrt() < self.cfg.min_sample_condition {
            return None;
        }
        Some(AffineSubspace {
            n_frames: f,
            m,
            t,
            defined,
        })
    }

    fn residual(&self, model: &AffineSubspace, item: usize) -> Option<f64> {
        self.track_fit(model, item).map(|t| t.rms)
    }

    /// The given tracks' residuals, in parallel over tracks when their frames are many
    /// enough to pay for it (as [`Self::residuals`]).
    fn residuals_of(&self, model: &AffineSubspace, items: &[usize]) -> Vec<Option<f64>> {
        let frames: usize = items.iter().map(|&p| self.frames_of(p).len()).sum();
        if frames < 4096 {
            return items.iter().map(|&p| self.residual(model, p)).collect();
        }
        items
            .par_iter()
            .with_min_len(4)
            .map(|&p| self.residual(model, p))
            .collect()
    }

    /// All tracks' residuals, in parallel over tracks (rayon; each residual is independent
    /// of the others, so the result does not depend on the thread count).
    fn residuals(&self, model: &AffineSubspace, n: usize) -> Vec<Option<f64>> {
        (0..n)
            .into_par_iter()
            .with_min_len(128)
            .map(|p| self.track_fit(model, p).map(|t| t.rms))
            .collect()
    }

    /// Local-optimization refit: ALS started from `model` (`lo_als_iterations` sweeps).
    /// On complete data a model defined on every frame is a warm start close to the
    /// inliers' rank-3 fit (ALS on a rank-3-plus-noise matrix converges at the rate
    /// `σ₄/σ₃ ≪ 1`), so the SVD initialization of [`TrackSubspace::refit_with`], which
    /// would cost more than the sweeps themselves, is skipped; otherwise as `refit_with`.
    fn refit(&self, model: &AffineSubspace, inliers: &[usize]) -> Option<AffineSubspace> {
        self.refit_warm_reporting(model, inliers, self.cfg.lo_als_iterations)
            .map(|(m, _)| m)
    }

    /// `σ = median(r) / m_ν` with the Wilson–Hilferty median of `sqrt(χ²_ν/ν)`,
    /// `m_ν = (1 − 2/(9ν))^{3/2}`, at the median track's `ν = 2k − 3`.
    fn sigma_from_residuals(&self, r: &[f64]) -> f64 {
        let nu = self.nu_typical;
        crate::eval::median(r) / (1.0 - 2.0 / (9.0 * nu)).powf(1.5)
    }

    /// `κ = sqrt(χ²_ν(p)/ν)` with `ν = 2·min_overlap − 3`.
    fn threshold_multiple(&self, p: f64) -> f64 {
        let nu = (2 * self.min_overlap) as f64 - 3.0;
        (super::chi2_quantile(nu, p) / nu).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::{OutlierKind, SynthConfig, generate};
    use rand::SeedableRng;
    use rand::rngs::StdRng;

    fn table(missing: f64, seed: u64) -> crate::TrackTable {
        generate(&SynthConfig {
            frames: 150,
            points: 120,
            missing,
            outliers: 0.1,
            outlier_kind: OutlierKind::RandomWalk,
            gross: 0.02,
            seed,
            ..Default::default()
        })
        .unwrap()
        .table
    }

    fn same_model(a: &AffineSubspace, b: &AffineSubspace) {
        assert_eq!(a.defined, b.defined);
        assert!(
            a.m.iter()
                .zip(&b.m)
                .all(|(x, y)| x.to_bits() == y.to_bits())
        );
        assert!(
            a.t.iter()
                .zip(&b.t)
                .all(|(x, y)| x.to_bits() == y.to_bits())
        );
    }

    /// Two estimators of the same tracks agree in every usable frame, observation, sample,
    /// hypothesis, residual and refit, bit for bit.
    fn same_estimator(a: &TrackSubspace, b: &TrackSubspace, seed: u64) {
        assert_eq!((a.n_frames(), a.n_tracks()), (b.n_frames(), b.n_tracks()));
        assert_eq!(a.complete, b.complete);
        for p in 0..a.n_tracks() {
            assert_eq!(a.frames_of(p), b.frames_of(p), "track {p}");
            for f in 0..a.n_frames() {
                assert_eq!(a.observation(f, p), b.observation(f, p), "({f}, {p})");
            }
        }
        let (mut ra, mut rb) = (StdRng::seed_from_u64(seed), StdRng::seed_from_u64(seed));
        let (mut sa, mut sb) = (Vec::new(), Vec::new());
        let mut fitted = 0;
        for _ in 0..40 {
            assert_eq!(a.sample(4, &mut ra, &mut sa), b.sample(4, &mut rb, &mut sb));
            assert_eq!(sa, sb);
            let (Some(ma), Some(mb)) = (a.fit(&sa), b.fit(&sb)) else {
                continue;
            };
            same_model(&ma, &mb);
            let (fa, fb) = (
                a.residuals(&ma, a.n_tracks()),
                b.residuals(&mb, b.n_tracks()),
            );
            assert_eq!(fa, fb);
            let inliers: Vec<usize> = (0..a.n_tracks()).filter(|&p| fa[p].is_some()).collect();
            let (Some((ra2, ea)), Some((rb2, eb))) = (
                a.refit_reporting(&ma, &inliers, 8),
                b.refit_reporting(&mb, &inliers, 8),
            ) else {
                continue;
            };
            same_model(&ra2, &rb2);
            assert_eq!(ea, eb);
            fitted += 1;
        }
        assert!(fitted >= 5, "{fitted} refits compared");
    }

    /// The estimator of a sparse table is the one of its dense matrix: with entries
    /// missing, complete, and with exclusions.
    #[test]
    fn the_sparse_tables_estimator_is_the_dense_ones() {
        let cfg = SubspaceConfig::default();
        for (missing, seed) in [(0.5, 1), (0.0, 2)] {
            let t = table(missing, seed);
            let meas = t.measurements();
            let dense = TrackSubspace::new(&meas, &cfg);
            let sparse = TrackSubspace::from_table(&t, &cfg);
            same_estimator(&dense, &sparse, seed);
            // Every 7th observed entry excluded, on both (shared columns and a fresh copy).
            let excluded: Vec<(usize, usize)> = meas
                .observed_pairs()
                .enumerate()
                .filter(|(i, _)| i % 7 == 0)
                .map(|(_, e)| e)
                .collect();
            let a = TrackSubspace::with_exclusions(&meas, &cfg, &excluded);
            let b = sparse.with_exclusions_shared(&meas, &excluded);
            assert!(b.frames_of(0).len() < t.track_len(0) || t.track_len(0) == 0);
            same_estimator(&a, &b, seed + 10);
        }
    }

    /// [`TrackSubspace::select`] is the estimator of the selected sub-table, and the
    /// per-track bitsets count the frames two tracks share as their frame lists do.
    #[test]
    fn a_selected_window_is_the_estimator_of_its_sub_table() {
        let cfg = SubspaceConfig::default();
        let t = table(0.6, 3);
        let meas = t.measurements();
        let all = TrackSubspace::from_table(&t, &cfg);
        let (a, b) = (40, 110);
        let tracks: Vec<usize> = (0..t.n_tracks())
            .filter(|&p| {
                let fr = all.frames_of(p);
                fr.iter()
                    .filter(|&&x| (a..b).contains(&(x as usize)))
                    .count()
                    >= 3
            })
            .collect();
        let frames: Vec<usize> = (a..b).collect();
        let want = TrackSubspace::new(&meas.select(&frames, &tracks), &cfg);
        same_estimator(&want, &all.select(a, b, &tracks), 4);
        for p in (0..t.n_tracks()).step_by(7) {
            let mut mask = all.spans.mask(p);
            for q in 0..t.n_tracks() {
                let shared = all
                    .frames_of(q)
                    .iter()
                    .filter(|f| all.frames_of(p).binary_search(f).is_ok())
                    .count();
                assert_eq!(all.spans.overlap(q, &mask), shared, "({p}, {q})");
                for f in 0..t.n_frames() {
                    assert_eq!(
                        all.spans.has(q, f),
                        all.frames_of(q).binary_search(&(f as u32)).is_ok()
                    );
                }
            }
            let q = (p + 1) % t.n_tracks();
            all.spans.intersect(q, &mut mask);
            let both = all
                .frames_of(q)
                .iter()
                .filter(|f| all.frames_of(p).binary_search(f).is_ok())
                .count();
            assert_eq!(all.spans.overlap(p, &mask), both);
        }
    }
}
