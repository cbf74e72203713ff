//! The numeric observation matrix that the solvers work on.
//!
//! `W` is 2F×N with row `2f` holding the x coordinates and row `2f+1` the y coordinates
//! of frame `f` (the layout of the Oxford/CMU measurement matrices), one column per track.
//! A visibility mask says which (frame, track) pairs were observed; unobserved entries of
//! `W` hold `0.0` and are never read by the solvers.

use faer::Mat;

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

    /// RMS of `pred - W` over observed scalars (x and y counted separately), the measure of
    /// the literature: `sqrt(Σ_observed r² / #observed scalars)`. `pred` must be 2F×N.
    pub fn rms(&self, pred: faer::MatRef<'_, f64>) -> f64 {
        let mut ss = 0.0;
        let mut count = 0usize;
        for (f, p) in self.observed_pairs() {
            for r in [2 * f, 2 * f + 1] {
                let d = pred[(r, p)] - self.w[(r, p)];
                ss += d * d;
            }
            count += 2;
        }
        if count == 0 {
            0.0
        } else {
            (ss / count as f64).sqrt()
        }
    }
}
