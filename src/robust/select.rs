//! Order statistics of values produced part by part (e.g. the entry distances of each
//! track), without gathering them all into one buffer.
//!
//! The robust pass takes medians of every entry distance of a table: 2·10⁷ values, a
//! 160 MB buffer for `select_nth`, at 1000 frames × 20 000 tracks. Here the `k`-th
//! smallest value (0-based; ties and NaN ordered by `f64::total_cmp`, NaN last) is found
//! exactly in three passes over the parts, none holding more than a bracket of them:
//!
//! 1. count the values of each part (`n = Σ nᵢ`);
//! 2. a systematic sample of about [`SAMPLE`] values (every `⌈n / SAMPLE⌉`-th in part
//!    order), sorted: the sample values `ε` sample ranks on either side of the wanted ranks'
//!    positions bracket them, `[lo, hi]` (`ε = 4√S + 64`, far beyond a systematic sample's
//!    rank error on any but adversarial orders);
//! 3. count the values below `lo` and gather those within `[lo, hi]`; when the wanted ranks
//!    fall inside, select them from the gathered values. Otherwise (the bracket missed) all
//!    values are gathered and selected, as without this module: the result is exact either
//!    way, only the memory differs.
//!
//! Complexity: `O(n)` work in three passes (parallel over parts, rayon; the result does not
//! depend on the thread count), `O(S + #values in the bracket)` memory, about `2ε/S + 2/S`
//! of `n` (≈ 0.8 % for a large `n`), plus `O(n)` in the rare fallback.
//! Reference: the bracketing is that of Floyd and Rivest's selection, "Expected time bounds
//! for selection", CACM 18(3), 1975, with one sample instead of a recursion.

use rayon::prelude::*;
use std::cmp::Ordering;

/// Sample size of the bracket (pass 2).
pub const SAMPLE: usize = 1 << 16;

/// The `k_lo`-th and `k_hi`-th smallest (0-based, `k_lo ≤ k_hi < n`) of the values
/// `part(0), part(1), …, part(parts − 1)` yield, with their total count `n`; `None` when
/// there are no values or `k_hi ≥ n`. `part(i)` must yield the same values each time it is
/// called (it is called three times).
pub fn order_statistics<I>(
    parts: usize,
    part: impl Fn(usize) -> I + Sync,
    ranks: impl Fn(usize) -> (usize, usize),
) -> Option<([f64; 2], usize)>
where
    I: Iterator<Item = f64>,
{
    let counts: Vec<usize> = (0..parts)
        .into_par_iter()
        .with_min_len(16)
        .map(|i| part(i).count())
        .collect();
    let (n, (k_lo, k_hi)) = total_and_ranks(&counts, ranks)?;
    if n <= 4 * SAMPLE {
        return Some((select(gather_all(parts, &part, n), k_lo, k_hi), n));
    }
    // Pass 2: every `step`-th value in part order.
    let (step, offsets) = sample_step(&counts, n);
    let mut sample: Vec<f64> = Vec::new();
    sample.par_extend(
        (0..parts)
            .into_par_iter()
            .with_min_len(16)
            .flat_map_iter(|i| {
                let first = (step - offsets[i] % step) % step;
                part(i).skip(first).step_by(step)
            }),
    );
    Some((bracket_select(parts, &part, sample, n, (k_lo, k_hi)), n))
}

/// The total count `n` of the parts' values and the wanted ranks; `None` when there are
/// no values or the ranks are not `k_lo ≤ k_hi < n`.
fn total_and_ranks(
    counts: &[usize],
    ranks: impl Fn(usize) -> (usize, usize),
) -> Option<(usize, (usize, usize))> {
    let n: usize = counts.iter().sum();
    if n == 0 {
        return None;
    }
    let (k_lo, k_hi) = ranks(n);
    (k_lo <= k_hi && k_hi < n).then_some((n, (k_lo, k_hi)))
}

/// The systematic sample's step (about [`SAMPLE`] values of `n`) and each part's offset
/// in the concatenation of the parts.
fn sample_step(counts: &[usize], n: usize) -> (usize, Vec<usize>) {
    let mut offsets = Vec::with_capacity(counts.len());
    let mut acc = 0;
    for &c in counts {
        offsets.push(acc);
        acc += c;
    }
    (n.div_ceil(SAMPLE), offsets)
}

/// The `a`-th and `b`-th smallest of `v` (`a ≤ b < v.len()`), by selection.
fn select(mut v: Vec<f64>, a: usize, b: usize) -> [f64; 2] {
    let cmp = |a: &f64, b: &f64| a.total_cmp(b);
    let (left, hi, _) = v.select_nth_unstable_by(b, cmp);
    let hi = *hi;
    let lo = if a == b {
        hi
    } else {
        // The a-th is the (b − 1 − a)-th largest of the b values left of the b-th.
        let m = b - 1 - a;
        *left.select_nth_unstable_by(m, |x, y| y.total_cmp(x)).1
    };
    [lo, hi]
}

/// Every value of the parts, in one buffer of `n`.
fn gather_all<I: Iterator<Item = f64>>(
    parts: usize,
    part: &(impl Fn(usize) -> I + Sync),
    n: usize,
) -> Vec<f64> {
    let mut all = Vec::with_capacity(n);
    all.par_extend(
        (0..parts)
            .into_par_iter()
            .with_min_len(16)
            .flat_map_iter(part),
    );
    all
}

/// Passes 2 (the sample's bracket) and 3 of [`order_statistics`]: from the unsorted
/// systematic `sample` of the `n` values, the ranks `(k_lo, k_hi)`.
fn bracket_select<I: Iterator<Item = f64>>(
    parts: usize,
    part: &(impl Fn(usize) -> I + Sync),
    mut sample: Vec<f64>,
    n: usize,
    (k_lo, k_hi): (usize, usize),
) -> [f64; 2] {
    sample.sort_unstable_by(|a, b| a.total_cmp(b));
    let s = sample.len();
    let eps = 4.0 * (s as f64).sqrt() + 64.0;
    let at = |k: usize, shift: f64| {
        let pos = (k as f64 / n as f64 * s as f64 + shift).clamp(0.0, (s - 1) as f64);
        sample[pos as usize]
    };
    let (lo, hi) = (at(k_lo, -eps), at(k_hi, eps));
    // Pass 3: below the bracket counted, within it gathered.
    let (below, inside) = (0..parts)
        .into_par_iter()
        .with_min_len(16)
        .map(|i| {
            let (mut below, mut inside) = (0usize, Vec::new());
            for x in part(i) {
                if x.total_cmp(&lo) == Ordering::Less {
                    below += 1;
                } else if x.total_cmp(&hi) != Ordering::Greater {
                    inside.push(x);
                }
            }
            (below, inside)
        })
        .reduce(
            || (0, Vec::new()),
            |(b1, mut v1), (b2, v2)| {
                v1.extend(v2);
                (b1 + b2, v1)
            },
        );
    if below <= k_lo && k_hi < below + inside.len() {
        select(inside, k_lo - below, k_hi - below)
    } else {
        select(gather_all(parts, part, n), k_lo, k_hi)
    }
}

/// [`order_statistics`] for parts whose values are known by index: part `i` holds
/// `counts[i]` values, the `j`-th of them `value(i, j)`. The counting pass is not needed
/// and the sample (pass 2) evaluates only the sampled values, so the values are computed
/// about once each (pass 3) instead of three times: for values that cost more than
/// reading them (e.g. an entry's distance to a model) this is most of the work. Same
/// result as [`order_statistics`] on the same values, to the bit.
pub fn order_statistics_indexed(
    counts: &[usize],
    value: impl Fn(usize, usize) -> f64 + Sync,
    ranks: impl Fn(usize) -> (usize, usize),
) -> Option<([f64; 2], usize)> {
    let value = &value;
    let part = |i: usize| (0..counts[i]).map(move |j| value(i, j));
    let (n, (k_lo, k_hi)) = total_and_ranks(counts, ranks)?;
    if n <= 4 * SAMPLE {
        return Some((select(gather_all(counts.len(), &part, n), k_lo, k_hi), n));
    }
    let (step, offsets) = sample_step(counts, n);
    let mut sample: Vec<f64> = Vec::new();
    sample.par_extend(
        (0..counts.len())
            .into_par_iter()
            .with_min_len(16)
            .flat_map_iter(|i| {
                let first = (step - offsets[i] % step) % step;
                (first..counts[i]).step_by(step).map(move |j| value(i, j))
            }),
    );
    Some((
        bracket_select(counts.len(), &part, sample, n, (k_lo, k_hi)),
        n,
    ))
}

/// The median of the values the parts yield: the middle one, or for an even count the
/// mean of the two middle ones; NaN when there are none. See [`order_statistics`].
pub fn median_of_parts<I>(parts: usize, part: impl Fn(usize) -> I + Sync) -> f64
where
    I: Iterator<Item = f64>,
{
    median_of(order_statistics(parts, part, median_ranks))
}

/// [`median_of_parts`] for parts whose values are known by index (see
/// [`order_statistics_indexed`]): each value is computed once.
pub fn median_indexed(counts: &[usize], value: impl Fn(usize, usize) -> f64 + Sync) -> f64 {
    median_of(order_statistics_indexed(counts, value, median_ranks))
}

/// The ranks of the median of `n ≥ 1` values: the middle one, or the two middle ones.
fn median_ranks(n: usize) -> (usize, usize) {
    let mid = n / 2;
    if n % 2 == 1 {
        (mid, mid)
    } else {
        (mid - 1, mid)
    }
}

/// The median from the order statistics at [`median_ranks`]: the middle value, or the
/// mean of the two middle ones; NaN when there are no values.
fn median_of(stats: Option<([f64; 2], usize)>) -> f64 {
    match stats {
        Some(([a, b], _)) if a.total_cmp(&b) == Ordering::Equal => b,
        Some(([a, b], _)) => 0.5 * (a + b),
        None => f64::NAN,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    fn check(parts: &[Vec<f64>]) {
        let mut all: Vec<f64> = parts.iter().flatten().copied().collect();
        all.sort_by(|a, b| a.total_cmp(b));
        let n = all.len();
        let want = if n % 2 == 1 {
            all[n / 2]
        } else {
            0.5 * (all[n / 2 - 1] + all[n / 2])
        };
        let got = median_of_parts(parts.len(), |i| parts[i].iter().copied());
        assert_eq!(got.to_bits(), want.to_bits(), "n = {n}");
        let counts: Vec<usize> = parts.iter().map(|p| p.len()).collect();
        let mid = |n: usize| (n.saturating_sub(1) / 2, n / 2);
        if n > 0 {
            let ([a, b], count) =
                order_statistics_indexed(&counts, |i, j| parts[i][j], mid).unwrap();
            assert_eq!(count, n);
            assert_eq!(
                [a.to_bits(), b.to_bits()],
                [all[(n - 1) / 2].to_bits(), all[n / 2].to_bits()],
                "indexed, n = {n}"
            );
        } else {
            assert!(order_statistics_indexed(&counts, |i, j| parts[i][j], mid).is_none());
        }
        let k = n / 3;
        let (v, count) =
            order_statistics(parts.len(), |i| parts[i].iter().copied(), |_| (k, k + 1)).unwrap();
        assert_eq!(count, n);
        assert_eq!(
            [v[0].to_bits(), v[1].to_bits()],
            [all[k].to_bits(), all[k + 1].to_bits()]
        );
    }

    /// Exact against a full sort, by iterators and by index: small and large counts
    /// (bracketed and not), ties, parts sorted in the order of their values (a systematic
    /// sample's worst case), and empty.
    #[test]
    fn order_statistics_are_exact() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        for &(parts, per) in &[(7usize, 3usize), (300, 1000), (2000, 257)] {
            let random: Vec<Vec<f64>> = (0..parts)
                .map(|_| {
                    (0..per)
                        .map(|_| rng.random_range(0.0..1.0f64).powi(3))
                        .collect()
                })
                .collect();
            check(&random);
            let ties: Vec<Vec<f64>> = (0..parts)
                .map(|_| (0..per).map(|_| rng.random_range(0..5) as f64).collect())
                .collect();
            check(&ties);
            let sorted: Vec<Vec<f64>> = (0..parts)
                .map(|i| (0..per).map(|j| (i * per + j) as f64).collect())
                .collect();
            check(&sorted);
        }
        assert!(median_of_parts(3, |_| std::iter::empty()).is_nan());
    }
}
