//! The numeric observation matrix that the solvers work on.
//!
//! `W` is 2F×N with row `2f` holding the x coordinates and row `2f+1` the y coordinates
//! of frame `f` (the layout of the Oxford/CMU measurement matrices), one column per track.
//! A visibility mask says which (frame, track) pairs were observed; unobserved entries of
//! `W` hold `0.0` and are never read by the solvers.

use faer::Mat;

/// Tracks per block of [`Measurements::sum_observed`] (its unit of parallel work and of
/// its partial sums): 64 mask bytes, a cache line, per frame.
pub const TILE_TRACKS: usize = 64;

/// Dense 2F×N measurements with an F×N visibility mask.
#[derive(Debug, Clone)]
pub struct Measurements {
    /// 2F×N, row `2f` = x and row `2f+1` = y of frame `f`. Unobserved entries are 0.
    pub w: Mat<f64>,
    /// F×N visibility, row-major: index `f * n_points + p`.
    pub visible: Vec<bool>,
}

impl Measurements {
    /// Builds measurements from a 2F×N matrix and an F×N row-major mask; unobserved
    /// entries of `w` are zeroed.
    ///
    /// # Panics
    /// If the shapes disagree (a programming error, not user input).
    pub fn new(mut w: Mat<f64>, visible: Vec<bool>) -> Self {
        assert!(
            w.nrows().is_multiple_of(2),
            "W must have an even number of rows"
        );
        let (f, n) = (w.nrows() / 2, w.ncols());
        assert_eq!(visible.len(), f * n, "mask must be F×N");
        for fi in 0..f {
            for p in 0..n {
                if !visible[fi * n + p] {
                    w[(2 * fi, p)] = 0.0;
                    w[(2 * fi + 1, p)] = 0.0;
                }
            }
        }
        Self { w, visible }
    }

    /// Complete measurements (every entry observed).
    pub fn complete(w: Mat<f64>) -> Self {
        let n = (w.nrows() / 2) * w.ncols();
        Self::new(w, vec![true; n])
    }

    /// The measurements of the given frames and tracks (indices, in the order given).
    /// `O(F'·N')` for the F' frames and N' tracks.
    pub fn select(&self, frames: &[usize], tracks: &[usize]) -> Measurements {
        let n = self.n_points();
        let w = Mat::from_fn(2 * frames.len(), tracks.len(), |r, j| {
            self.w[(2 * frames[r / 2] + r % 2, tracks[j])]
        });
        let visible = frames
            .iter()
            .flat_map(|&f| tracks.iter().map(move |&p| self.visible[f * n + p]))
            .collect();
        Measurements::new(w, visible)
    }

    /// A subset of frames and tracks spanning the sequence, on which a decision about the
    /// whole table (a model test, the choice of a start) costs a bounded amount: at most
    /// `max_frames` frames evenly spaced over the sequence (so the baseline, which decides
    /// how much perspective shows, is the whole sequence's), and at most `max_tracks`
    /// tracks seen in at least 3 of them, taken evenly in track order, plus the tracks
    /// needed for every subset frame to see `per_frame` (when the table has them).
    /// `None` when fewer than 7 tracks qualify or the subset would not be smaller than the
    /// table. `O(F N)`.
    pub fn spanning_subset(
        &self,
        max_frames: usize,
        max_tracks: usize,
        per_frame: usize,
    ) -> Option<(Vec<usize>, Vec<usize>)> {
        let (nf, np) = (self.n_frames(), self.n_points());
        let frames = crate::degeneracy::spaced(nf, max_frames);
        let seen = |p: usize| frames.iter().filter(|&&f| self.is_visible(f, p)).count();
        let candidates: Vec<usize> = (0..np).filter(|&p| seen(p) >= 3).collect();
        if candidates.len() < 7 {
            return None;
        }
        let step = candidates.len().div_ceil(max_tracks.max(1)).max(1);
        let mut chosen = vec![false; np];
        for &p in candidates.iter().step_by(step) {
            chosen[p] = true;
        }
        for &f in &frames {
            let mut have = candidates
                .iter()
                .filter(|&&p| chosen[p] && self.is_visible(f, p))
                .count();
            for &p in &candidates {
                if have >= per_frame {
                    break;
                }
                if !chosen[p] && self.is_visible(f, p) {
                    chosen[p] = true;
                    have += 1;
                }
            }
        }
        let tracks: Vec<usize> = (0..np).filter(|&p| chosen[p]).collect();
        (frames.len() < nf || tracks.len() < np).then_some((frames, tracks))
    }

    /// The measurements of the given tracks in every frame ([`Measurements::select`] over
    /// all frames). `O(F·N')` for the N' tracks.
    pub fn select_tracks(&self, tracks: &[usize]) -> Measurements {
        let frames: Vec<usize> = (0..self.n_frames()).collect();
        self.select(&frames, tracks)
    }

    /// Number of frames F.
    pub fn n_frames(&self) -> usize {
        self.w.nrows() / 2
    }

    /// Number of tracks N.
    pub fn n_points(&self) -> usize {
        self.w.ncols()
    }

    /// Whether track `p` is observed in frame `f`.
    #[inline]
    pub fn is_visible(&self, f: usize, p: usize) -> bool {
        self.visible[f * self.n_points() + p]
    }

    /// Number of observed (frame, track) pairs; the number of observed scalars is twice that.
    pub fn n_observed(&self) -> usize {
        self.visible.iter().filter(|&&v| v).count()
    }

    /// True when every entry is observed.
    pub fn is_complete(&self) -> bool {
        self.visible.iter().all(|&v| v)
    }

    /// Observed pairs `(f, p)` in frame-major order.
    pub fn observed_pairs(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        let n = self.n_points();
        self.visible
            .iter()
            .enumerate()
            .filter(|(_, v)| **v)
            .map(move |(i, _)| (i / n, i % n))
    }

    /// Calls `visit(f, p)` for every observed pair, track by track, each track's frames in
    /// order. Every frame's pairs are then visited in increasing track order and every
    /// track's in increasing frame order, as by [`Self::observed_pairs`], so sums kept per
    /// frame or per track come out bit for bit the same. Unlike that frame-by-frame walk,
    /// which strides `16·F` bytes in `W` (column-major) per entry (a TLB miss each at 1000
    /// frames), it reads `W` in order; the mask (row-major) is read one byte per frame,
    /// and consecutive tracks share its cache lines (`F` lines, in cache across 64
    /// tracks). `O(F·N)`.
    pub fn for_each_observed(&self, mut visit: impl FnMut(usize, usize)) {
        let (nf, n) = (self.n_frames(), self.n_points());
        for p in 0..n {
            for f in 0..nf {
                if self.visible[f * n + p] {
                    visit(f, p);
                }
            }
        }
    }

    /// `Σ term(f, p)` over the observed pairs and their number, in the order of
    /// [`Self::for_each_observed`] within blocks of [`TILE_TRACKS`] tracks summed on all
    /// cores; the blocks' sums are added in block order, so the result does not depend on
    /// the number of threads. `O(F·N / threads)`.
    pub fn sum_observed(&self, term: impl Fn(usize, usize) -> f64 + Sync) -> (f64, usize) {
        use rayon::prelude::*;
        let (nf, n) = (self.n_frames(), self.n_points());
        let blocks: Vec<(f64, usize)> = (0..n.div_ceil(TILE_TRACKS))
            .into_par_iter()
            .map(|b| {
                let (p0, p1) = (b * TILE_TRACKS, ((b + 1) * TILE_TRACKS).min(n));
                let (mut ss, mut count) = (0.0, 0usize);
                for p in p0..p1 {
                    for f in 0..nf {
                        if self.visible[f * n + p] {
                            ss += term(f, p);
                            count += 1;
                        }
                    }
                }
                (ss, count)
            })
            .collect();
        blocks
            .into_iter()
            .fold((0.0, 0), |(s, c), (bs, bc)| (s + bs, c + bc))
    }

    /// RMS of `pred - W` over observed scalars (x and y counted separately), the measure of
    /// the literature: `sqrt(Σ_observed r² / #observed scalars)`. `pred` must be 2F×N.
    pub fn rms(&self, pred: faer::MatRef<'_, f64>) -> f64 {
        self.rms_of(|f, p| [pred[(2 * f, p)], pred[(2 * f + 1, p)]])
    }

    /// [`Self::rms`] of a prediction given entry by entry, `predict(f, p) = [x, y]`, without
    /// a 2F×N matrix ([`Self::sum_observed`]).
    pub fn rms_of(&self, predict: impl Fn(usize, usize) -> [f64; 2] + Sync) -> f64 {
        let (ss, pairs) = self.sum_observed(|f, p| {
            let q = predict(f, p);
            let (dx, dy) = (q[0] - self.w[(2 * f, p)], q[1] - self.w[(2 * f + 1, p)]);
            dx * dx + dy * dy
        });
        if pairs == 0 {
            0.0
        } else {
            (ss / (2 * pairs) as f64).sqrt()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(f: usize, n: usize) -> Measurements {
        // A deterministic pattern with about a third of the entries missing.
        let w = Mat::from_fn(2 * f, n, |r, p| {
            ((r * 7919 + p * 104_729) % 1000) as f64 / 7.0
        });
        let visible = (0..f * n).map(|i| (i * 2_654_435_761) % 3 != 0).collect();
        Measurements::new(w, visible)
    }

    /// The tiled walk visits each observed pair once, each frame's pairs in track order and
    /// each track's in frame order; the block sums match a plain sum.
    #[test]
    fn tiled_walk_visits_every_observed_pair_in_order() {
        for &(f, n) in &[(1usize, 1usize), (3, 64), (17, 65), (9, 300)] {
            let m = sample(f, n);
            let mut visits = Vec::new();
            m.for_each_observed(|fr, p| visits.push((fr, p)));
            let mut sorted = visits.clone();
            sorted.sort_unstable();
            let all: Vec<(usize, usize)> = m.observed_pairs().collect();
            assert_eq!(sorted, all);
            let (mut last_p, mut last_f) = (vec![None; f], vec![None; n]);
            for &(fr, p) in &visits {
                assert!(last_p[fr].is_none_or(|q| q < p), "frame {fr}: track order");
                assert!(last_f[p].is_none_or(|g| g < fr), "track {p}: frame order");
                last_p[fr] = Some(p);
                last_f[p] = Some(fr);
            }
            let (sum, count) = m.sum_observed(|fr, p| m.w[(2 * fr, p)] - m.w[(2 * fr + 1, p)]);
            let plain: f64 = all
                .iter()
                .map(|&(fr, p)| m.w[(2 * fr, p)] - m.w[(2 * fr + 1, p)])
                .sum();
            assert_eq!(count, all.len());
            assert!((sum - plain).abs() <= 1e-12 * plain.abs().max(1.0));
            let pred = Mat::from_fn(2 * f, n, |r, p| {
                m.w[(r, p)] + if r % 2 == 0 { 3.0 } else { -4.0 }
            });
            // Every observed pair is off by (3, −4): RMS per scalar sqrt(25 / 2).
            if count > 0 {
                assert!((m.rms(pred.as_ref()) - 12.5f64.sqrt()).abs() < 1e-12);
            }
        }
    }
}
