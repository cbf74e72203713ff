//! Spectral clustering of tracks by their preferences over the hypothesis pool.
//!
//! The label search of [`super::segment`] picks subspaces one at a time by the energy `E`;
//! when two motions are partly dependent (the union of two groups nearly fits one
//! subspace) a single subspace fitted to both explains every track almost as well as the
//! right pair, and the greedy search does not find the pair. The pattern of *which*
//! hypotheses explain a track does separate them: the tracks of one body are explained by
//! the same local hypotheses. This module turns that pattern into candidate groups, whose
//! refitted subspaces enter the pool; `E` still chooses among them.
//!
//! # Objective
//!
//! Preference analysis (Toldo & Fusiello, "Robust multiple structures estimation with
//! J-linkage", ECCV 2008; Magri & Fusiello, "T-linkage", CVPR 2014; Chin, Wang & Suter,
//! "The ordered residual kernel for robust motion subspace clustering", NIPS 2009): each
//! track `p` gets a preference vector over the `H` hypotheses,
//!
//! ```text
//! φ^τ_p(h) = exp(−r²_ph / (τ² σ̂²)),     A_pq = Σ_{τ² ∈ {2, 4, 9, 16}} ⟨φ^τ_p, φ^τ_q⟩ / (‖φ^τ_p‖ ‖φ^τ_q‖)
//! ```
//!
//! with `r_ph` the per-coordinate RMS of `p` under hypothesis `h` and `σ̂²` the noise
//! variance (the median of the hypotheses'). The sum over scales is what makes the
//! affinity stable: a single scale suits some sequences and not others (measured on the
//! Hopkins development files, with the count given: `τ² = 4` alone 2.47 % / 3.91 %
//! misclassified on the two- / three-motion files, `τ² = 9` 2.49 % / 3.02 %, the sum
//! 2.35 % / 3.06 %; a per-track scale, the `m`-th smallest residual of the track as in
//! self-tuning spectral clustering (Zelnik-Manor & Perona, NIPS 2004), moved single
//! sequences between 2 % and 85 % as `m` went from `H/100` to `H/10`). The `K` groups are
//! those of normalized spectral clustering (Ng, Jordan & Weiss, NIPS 2001): the `K` leading
//! eigenvectors of `D^{-1/2} A D^{-1/2}`, rows normalized, grouped by k-means
//! (k-means++ seeding, Arthur & Vassilvitskii 2007; best of `restarts`).
//!
//! # Complexity
//!
//! With `n` clustered tracks (at most [`MAX_TRACKS`]; beyond that a random subset, whose
//! groups' subspaces then score every track) and `H` hypotheses: O(n·H) for the
//! preferences, O(n²·H) for the affinity (four scales), O(n³) for the eigendecomposition, and
//! O(restarts · iterations · n · K²) for k-means. Memory O(n·H + n²).

use faer::{Mat, Side};
use rand::{Rng, RngExt};

/// Largest number of tracks clustered at once (the affinity is dense in them).
pub const MAX_TRACKS: usize = 1500;

/// The kernel scales `τ²` (in units of the noise variance `σ̂²`) whose affinities are
/// summed.
const SCALES: [f64; 4] = [2.0, 4.0, 9.0, 16.0];

/// The preference affinity of `tracks` and its normalized spectral embedding.
pub struct Spectral {
    /// The tracks clustered (input column indices).
    pub tracks: Vec<usize>,
    /// Eigenvalues of `D^{-1/2} A D^{-1/2}`, largest first (the first is 1).
    pub eigenvalues: Vec<f64>,
    /// The leading eigenvectors, one column each, largest eigenvalue first.
    vectors: Mat<f64>,
}

impl Spectral {
    /// The spectral embedding of `tracks` under the pool's residuals: `r2(h, p)` is the
    /// per-coordinate squared residual of track `p` under hypothesis `h < h_all`
    /// (`f32::INFINITY` when not scorable), `sigma2` the noise variance `σ̂²`. `None` when
    /// fewer than 4 tracks or 2 hypotheses, or the eigendecomposition fails. Keeps `k_max`
    /// eigenvectors.
    pub fn new(
        r2: impl Fn(usize, usize) -> f32,
        h_all: usize,
        sigma2: f64,
        tracks: Vec<usize>,
        k_max: usize,
    ) -> Option<Self> {
        let n = tracks.len();
        if n < 4 || h_all < 2 || !(sigma2 > 0.0 && sigma2.is_finite()) {
            return None;
        }
        // Preferences at each scale, rows normalized; the affinity sums their cosines.
        let mut a = Mat::<f64>::zeros(n, n);
        let mut phi = Mat::<f64>::zeros(n, h_all);
        for &tau2 in &SCALES {
            let s2 = tau2 * sigma2;
            for (i, &p) in tracks.iter().enumerate() {
                let mut norm = 0.0;
                for h in 0..h_all {
                    let r = r2(h, p);
                    let v = if r.is_finite() {
                        (-(r as f64) / s2).exp()
                    } else {
                        0.0
                    };
                    phi[(i, h)] = v;
                    norm += v * v;
                }
                let inv = if norm > 0.0 { 1.0 / norm.sqrt() } else { 0.0 };
                for h in 0..h_all {
                    phi[(i, h)] *= inv;
                }
            }
            a += &phi * phi.transpose();
        }
        for i in 0..n {
            a[(i, i)] = 0.0;
        }
        let d: Vec<f64> = (0..n)
            .map(|i| {
                let s: f64 = (0..n).map(|j| a[(i, j)]).sum();
                if s > 0.0 { 1.0 / s.sqrt() } else { 0.0 }
            })
            .collect();
        for j in 0..n {
            for i in 0..n {
                a[(i, j)] *= d[i] * d[j];
            }
        }
        let evd = a.self_adjoint_eigen(Side::Lower).ok()?;
        let s = evd.S().column_vector();
        let u = evd.U();
        let k = k_max.clamp(1, n);
        let eigenvalues: Vec<f64> = (0..n).rev().map(|i| s[i]).collect();
        let vectors = Mat::from_fn(n, k, |i, c| u[(i, n - 1 - c)]);
        if eigenvalues.iter().any(|v| !v.is_finite()) {
            return None;
        }
        Some(Spectral {
            tracks,
            eigenvalues,
            vectors,
        })
    }

    /// `k` groups of [`Spectral::tracks`] (input column indices; some may be empty) by
    /// k-means on the `k` leading eigenvectors' rows, normalized, best of `restarts`.
    pub fn clusters<R: Rng + ?Sized>(
        &self,
        k: usize,
        restarts: usize,
        rng: &mut R,
    ) -> Vec<Vec<usize>> {
        let n = self.tracks.len();
        let k = k.clamp(1, self.vectors.ncols());
        let rows: Vec<Vec<f64>> = (0..n)
            .map(|i| {
                let r: Vec<f64> = (0..k).map(|c| self.vectors[(i, c)]).collect();
                let norm = r.iter().map(|v| v * v).sum::<f64>().sqrt();
                if norm > 0.0 {
                    r.iter().map(|v| v / norm).collect()
                } else {
                    r
                }
            })
            .collect();
        let labels = kmeans(&rows, k, restarts.max(1), rng);
        let mut out = vec![Vec::new(); k];
        for (i, &l) in labels.iter().enumerate() {
            out[l].push(self.tracks[i]);
        }
        out
    }
}

/// Lloyd's k-means with k-means++ seeding, best (least within-cluster sum of squares) of
/// `restarts` runs of at most 100 iterations each.
fn kmeans<R: Rng + ?Sized>(x: &[Vec<f64>], k: usize, restarts: usize, rng: &mut R) -> Vec<usize> {
    let n = x.len();
    let d2 = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(u, v)| (u - v) * (u - v)).sum::<f64>();
    let mut best: (f64, Vec<usize>) = (f64::INFINITY, vec![0; n]);
    if n == 0 || k <= 1 {
        return vec![0; n];
    }
    for _ in 0..restarts {
        // k-means++ seeding.
        let mut centres: Vec<Vec<f64>> = vec![x[rng.random_range(0..n)].clone()];
        let mut near: Vec<f64> = x.iter().map(|p| d2(p, &centres[0])).collect();
        while centres.len() < k {
            let total: f64 = near.iter().sum();
            let pick = if total > 0.0 {
                let mut t = rng.random::<f64>() * total;
                let mut idx = n - 1;
                for (i, &w) in near.iter().enumerate() {
                    if t < w {
                        idx = i;
                        break;
                    }
                    t -= w;
                }
                idx
            } else {
                rng.random_range(0..n)
            };
            centres.push(x[pick].clone());
            for (i, p) in x.iter().enumerate() {
                near[i] = near[i].min(d2(p, &centres[centres.len() - 1]));
            }
        }
        let mut labels = vec![0usize; n];
        let mut cost = f64::INFINITY;
        for _ in 0..100 {
            let mut changed = false;
            cost = 0.0;
            for (i, p) in x.iter().enumerate() {
                let (mut bl, mut bd) = (0, f64::INFINITY);
                for (c, m) in centres.iter().enumerate() {
                    let dd = d2(p, m);
                    if dd < bd {
                        bd = dd;
                        bl = c;
                    }
                }
                cost += bd;
                if labels[i] != bl {
                    labels[i] = bl;
                    changed = true;
                }
            }
            let dim = x[0].len();
            let mut sums = vec![vec![0.0; dim]; k];
            let mut counts = vec![0usize; k];
            for (i, p) in x.iter().enumerate() {
                counts[labels[i]] += 1;
                for (s, v) in sums[labels[i]].iter_mut().zip(p) {
                    *s += v;
                }
            }
            for c in 0..k {
                if counts[c] > 0 {
                    centres[c] = sums[c].iter().map(|s| s / counts[c] as f64).collect();
                }
            }
            if !changed {
                break;
            }
        }
        if cost < best.0 {
            best = (cost, labels);
        }
    }
    best.1
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand::rngs::StdRng;

    #[test]
    fn two_blocks_of_preferences_are_two_clusters() {
        // 10 tracks preferring hypotheses 0..5, 10 preferring 5..10.
        let h = 10;
        let n = 20;
        let r2: Vec<Vec<f32>> = (0..h)
            .map(|hh| {
                (0..n)
                    .map(|p| if (p < 10) == (hh < 5) { 1.0 } else { 50.0 })
                    .collect()
            })
            .collect();
        let sp = Spectral::new(|hh, p| r2[hh][p], h, 1.0, (0..n).collect(), 3).unwrap();
        assert!((sp.eigenvalues[0] - 1.0).abs() < 1e-9);
        assert!(sp.eigenvalues[1] > 0.9, "{:?}", &sp.eigenvalues[..3]);
        assert!(sp.eigenvalues[2] < 0.5, "{:?}", &sp.eigenvalues[..3]);
        let mut c = sp.clusters(2, 5, &mut StdRng::seed_from_u64(1));
        c.sort();
        assert_eq!(c[0], (0..10).collect::<Vec<_>>());
        assert_eq!(c[1], (10..20).collect::<Vec<_>>());
    }
}
