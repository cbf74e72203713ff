//! Degenerate input named as such before the robust pass, and the image origin taken out.
//!
//! [`check`] runs on the table the set-aside kept, before the robust pass and the fit
//! ([`crate::Reconstruction::from_tracks`]). It returns the centroid of the observations,
//! which the pipeline subtracts from every coordinate before any other stage and adds back
//! to its results (translations, predictions, projective cameras, principal point): results
//! do not depend on where the image origin is, and coordinates far from it (`x + 10¹⁰`) lose
//! nothing to the stages that are not translation invariant in floating point (the
//! missing-data completion, the RANSAC hypotheses). Pixel scale is not normalized: the
//! robust pass's thresholds and floors are pixel quantities.
//!
//! Then it refuses, as [`Error::Degenerate`] with the numbers, the input from which no depth
//! can be recovered, in this order:
//!
//! 1. **Non-finite coordinates** (a library caller's table; the readers refuse them).
//! 2. **Coordinates too large for double precision**: neighbouring doubles at the largest
//!    `|coordinate|` are `q` apart (`q ≈ 2.2·10⁻¹⁶ |x|`), and the median track moves by `m`
//!    (RMS distance of its positions from their mean). `q > m / 10` ([`PRECISION_STEPS`]) —
//!    the motion spans fewer than 10 representable steps, and the input was rounded to them
//!    before rank3 read it — is refused. A warning says when `q > m / 1000`.
//! 3. **Noise level** `σ̂` (per coordinate) from the *reference block*: a complete block of
//!    frames × the tracks seen in all of them, at least [`MIN_BLOCK_FRAMES`] = 4 ×
//!    [`MIN_BLOCK_TRACKS`] = 8 — of the blocks of consecutive frames (windows of all
//!    frames, 40, 20, 10, 5, 4) and one grown greedily over any frames, the one with the
//!    most observations; at most 100 of its frames and 1000 of its tracks, evenly spaced —
//!    each row centred. Below its three largest singular values lie those of noise (and of
//!    model error such as perspective or outlier tracks, which adds a few large ones).
//!    Two estimates come from them: `σ̂`, the median over the k-th smallest
//!    singular values `y_k` (all but the three largest) of `y_k / sqrt(n Q_β((k − ½)/m))`,
//!    `Q_β` the quantile function of the Marchenko–Pastur law with ratio `β = m/n` (the law
//!    of the eigenvalues of `XXᵀ/n` for an `m × n` matrix `X` of unit-variance noise; `m ≤ n`
//!    after transposing, `n` one less than the tracks for the centring) — Gavish & Donoho's
//!    median estimate (IEEE Trans. Inf. Theory 60(8), 2014), fitted to the quantiles of the
//!    values it uses, robust to a few large singular values but up to 10 % high on small
//!    blocks — and `sqrt(Σ_{k>3} y_k² / ((m − 3)(n − 3)))`, unbiased for a rank-3 scene in
//!    noise but inflated by outlier tracks and low when the scene has rank < 3. The tracks'
//!    motion and spread are measured against `σ̂`; the *noise edge* `σ̂_e (sqrt(m) +
//!    sqrt(n))`, the largest singular value noise alone gives the block (the upper edge of
//!    the Marchenko–Pastur law), takes the smaller estimate `σ̂_e`, so that a third
//!    dimension is not called noise on a high estimate. (Measured on rank-2 signal plus
//!    unit noise: median of `σ̂` 1.09 and of `σ̂_e` 0.94 on 12 × 20 blocks, 1.01 and 0.99 on
//!    60 × 200.) Rounding of the input (`q/√12`) is the floor of both. Without a block
//!    (tracks too short) steps 4–6 are skipped.
//! 4. **Static camera**: a track seen in `k` frames that does not move has an RMS distance
//!    from its mean position of `σ sqrt(2(k − 1)/k)` (2 coordinates). When the median over
//!    the tracks of their RMS distance over that value is at most [`STATIC_RATIO`] = 1.5 —
//!    the tracks move by no more than half again what noise alone moves them; the median
//!    ignores a minority of moving tracks (a person walking through a static shot) — and
//!    the block's tracks whose ratio is at most 3 show no third dimension clearly above the
//!    noise (their σ3 at most [`CORROBORATION_EDGE_FACTOR`] = 1.1 times their noise edge,
//!    which a rank-2 block's σ3 exceeds in about 1 % of draws on blocks of 12 × 20 and
//!    more, see 6: a rotation too slow to move the tracks beyond the noise can still stand
//!    out of it when all the entries are pooled, and is not refused), the camera is
//!    static.
//! 5. **Collinear points**: in a frame of `k ≥ 3` points on a line, the smaller eigenvalue
//!    of their 2×2 covariance is about `σ²(k − 2)/k`. When its square root over
//!    `σ̂ sqrt((k − 2)/k)` is at most [`COLLINEAR_RATIO`] = 1.5 (or it is at most
//!    [`EXACT`] = 10⁻⁶ of the larger one's) in at least 90 % of the frames
//!    ([`COLLINEAR_FRAME_SHARE`]) and the block's σ3 is not clearly above the noise (as in
//!    4), the points are collinear.
//! 6. **Rank < 3**, only when the reference block holds every kept frame and at least half
//!    the kept tracks (always for complete tables): the block's third singular value `σ3`
//!    is at the noise level when it is not above [`RANK_EDGE_FACTOR`] = 1 times the noise
//!    edge, or at most [`EXACT`] times σ1 (noise-free input written
//!    with a few decimals). Coplanar points, or image motion with no parallax (translation,
//!    rotation about the viewing axis, zoom): refused, naming a pure image translation
//!    when, after removing each frame's shift, the median track moves by at most 1.5 times
//!    what noise alone gives (as in 4). The threshold is the noise edge itself, not a margin
//!    above
//!    it: a rank-2 table's σ3 falls below it in 80–92 % of draws (block sizes 8 × 8 to
//!    200 × 1000; the `calibration` test prints these figures), and a weak third dimension
//!    just above it — a 10° sweep seen through 2 px of noise — is reconstructed, not
//!    refused, as before.
//!
//! Every threshold sits at the noise level, so a motion that the data resolve, however
//! small, is not refused: on the toy house, the Oxford dinosaur, the Model House and 18
//! Hopkins 155 sequences σ3 is 30 to 2700 times the noise edge (docs/math.md §7).
//!
//! Cost: two passes over the observations, `O(runs + F)` for the consecutive blocks,
//! `O(F'² N / 64)` for the greedy block (`F' ≤ 200` frames), and the singular values of the
//! block (at most 200 × 1000).

use faer::Mat;

use crate::table::TrackTable;
use crate::{Error, Result};

/// Refused as a static camera when the median track moves by at most this many times what
/// noise alone moves it.
pub const STATIC_RATIO: f64 = 1.5;
/// A frame's points are on a line when their spread across it is at most this many times
/// the noise's.
pub const COLLINEAR_RATIO: f64 = 1.5;
/// Share of the frames whose points must be on a line for the table to be refused.
pub const COLLINEAR_FRAME_SHARE: f64 = 0.9;
/// σ3 at most this many times the largest singular value of noise alone is at the noise
/// level.
pub const RANK_EDGE_FACTOR: f64 = 1.0;
/// A static camera or collinear points, found by their own statistic, are refused when σ3
/// is not clearly above the noise either: at most this many times the noise edge.
pub const CORROBORATION_EDGE_FACTOR: f64 = 1.1;
/// A dimension whose extent is at most this fraction of the largest one's is absent, whatever
/// the noise estimate (exact input: a depth a millionth of the image's extent is no depth).
pub const EXACT: f64 = 1e-6;
/// The median track motion must span at least this many representable steps.
pub const PRECISION_STEPS: f64 = 10.0;
/// The smallest reference block: frames and tracks.
pub const MIN_BLOCK_FRAMES: usize = 4;
pub const MIN_BLOCK_TRACKS: usize = 8;
const MAX_BLOCK_FRAMES: usize = 100;
const MAX_BLOCK_TRACKS: usize = 1000;

/// What [`check`] measured on a table it let through.
#[derive(Debug, Clone)]
pub struct Check {
    /// Centroid of the observations, pixels: the pipeline subtracts it from every coordinate
    /// first and adds it back to its results.
    pub origin: [f64; 2],
    /// Median over the tracks of the RMS distance of their positions from their mean,
    /// pixels.
    pub median_motion_px: f64,
    /// Noise σ per coordinate from the reference block, pixels (`None` without a block).
    pub noise_sigma_px: Option<f64>,
    /// The reference block's size (frames, tracks) before subsampling, when there is one.
    pub block: Option<(usize, usize)>,
    /// The block's σ3 over the largest singular value noise alone gives it (`None` without a
    /// block): how far the third dimension stands out of the noise.
    pub depth_margin: Option<f64>,
    /// Warnings for the report (coordinates large enough for rounding to show).
    pub warnings: Vec<String>,
}

/// Checks `table` for input from which no depth can be recovered (see the module
/// documentation for the rules and thresholds) and measures its centroid.
///
/// Errors: [`Error::Degenerate`] naming the case (non-finite coordinate, coordinates too
/// large for double precision, static camera, collinear points, rank < 3) with the numbers
/// that decided it.
pub fn check(table: &TrackTable) -> Result<Check> {
    let (nf, nt) = (table.n_frames(), table.n_tracks());
    // One pass over the observations, both cores: the centroid (relative to the first
    // observation, so that huge coordinates lose nothing to the sum), the largest
    // magnitude, finiteness, and per track the frames seen, the mean position and the sum
    // of squared distances from it.
    let stats = track_stats(table);
    if !stats.finite {
        for f in 0..nf {
            if let Some(e) = table
                .frame_row(f)
                .entries()
                .iter()
                .find(|e| !(e.x.is_finite() && e.y.is_finite()))
            {
                return Err(Error::Degenerate(format!(
                    "the observation of track {} in frame {} is not finite ({}, {})",
                    table.track_ids()[e.track as usize],
                    table.frame_ids()[f],
                    e.x,
                    e.y
                )));
            }
        }
    }
    let Some(r) = stats.reference else {
        return Ok(Check {
            origin: [0.0, 0.0],
            median_motion_px: 0.0,
            noise_sigma_px: None,
            block: None,
            depth_margin: None,
            warnings: Vec::new(),
        });
    };
    let max_abs = stats.max_abs;
    let (k, ss) = (stats.count, stats.m2);
    // Σ_p k_p (mean_p − r) / Σ_p k_p.
    let (mut sum, mut count) = ([0.0f64; 2], 0usize);
    for p in 0..nt {
        if k[p] > 0 {
            sum[0] += k[p] as f64 * (stats.mean[p][0] - r[0]);
            sum[1] += k[p] as f64 * (stats.mean[p][1] - r[1]);
            count += k[p];
        }
    }
    let origin = [r[0] + sum[0] / count as f64, r[1] + sum[1] / count as f64];
    let moving: Vec<usize> = (0..nt).filter(|&p| k[p] >= 2).collect();
    let motion: Vec<f64> = moving
        .iter()
        .map(|&p| (ss[p] / k[p] as f64).sqrt())
        .collect();
    let median_motion = median(motion.clone()).unwrap_or(0.0);

    // 2. Precision (1, finiteness, was checked above).
    let mut warnings = Vec::new();
    let q = ulp(max_abs);
    if median_motion > 0.0 && q > median_motion / PRECISION_STEPS {
        return Err(Error::Degenerate(format!(
            "coordinates too large for double precision: at values up to {max_abs:.3e} px \
             neighbouring doubles are {q:.3e} px apart, and the tracks move by a median of \
             {} px (RMS distance from their mean position) — fewer than \
             {PRECISION_STEPS} representable steps, so the motion was rounded away before \
             rank3 read it; subtract a constant from the coordinates (e.g. the first frame's \
             centroid) before writing them",
            px(median_motion)
        )));
    }
    if median_motion > 0.0 && q > median_motion / 1000.0 {
        warnings.push(format!(
            "coordinates up to {max_abs:.3e} px are stored {q:.3e} px apart (rounding error \
             {:.3e} px RMS), against a median track motion of {} px: subtract a \
             constant from them before writing them to keep their precision",
            q / 12f64.sqrt(),
            px(median_motion)
        ));
    }

    // 3. Noise level from the reference block.
    let no_block = |warnings, block| Check {
        origin,
        median_motion_px: median_motion,
        noise_sigma_px: None,
        block,
        depth_margin: None,
        warnings,
    };
    let Some(block) = reference_block(table) else {
        return Ok(no_block(warnings, None));
    };
    let size = (block.frames.len(), block.tracks.len());
    let frames: Vec<usize> = spaced(block.frames.len(), MAX_BLOCK_FRAMES)
        .into_iter()
        .map(|i| block.frames[i])
        .collect();
    let tracks: Vec<usize> = spaced(block.tracks.len(), MAX_BLOCK_TRACKS)
        .into_iter()
        .map(|i| block.tracks[i])
        .collect();
    let Some(c) = centred_block(table, &frames, &tracks, origin) else {
        return Ok(no_block(warnings, Some(size)));
    };
    let Some(s) = singular_values(&c) else {
        return Ok(no_block(warnings, Some(size)));
    };
    let (m, n) = block_dims(&c);
    // Rounding of the input is the least noise there is (noise-free synthetic data).
    let floor = (q / 12f64.sqrt()).max(f64::MIN_POSITIVE);
    // The robust estimate measures the tracks' motion and spread against the noise; the
    // smaller of the two sets the noise edge, so that no third dimension is called noise
    // on a high estimate.
    let (robust, residual) = (noise_sigma(&s, m, n), residual_sigma(&s, m, n));
    let sigma = robust.or(residual).unwrap_or(0.0).max(floor);
    let sigma_edge = match (robust, residual) {
        (Some(a), Some(b)) => a.min(b),
        (a, b) => a.or(b).unwrap_or(0.0),
    }
    .max(floor);
    // The largest singular value noise alone gives an m × n block (the Marchenko–Pastur
    // edge); σ3 below `RANK_EDGE_FACTOR` times it is at the noise level.
    let edge = |m: usize, n: usize| sigma_edge * ((m as f64).sqrt() + (n as f64).sqrt());
    // (Or at rounding level against σ1: noise-free input written with a few decimals has
    // rounding noise in some coordinates and none in others, which no noise law describes.)
    let flat_within = |factor: f64, s: &[f64], m: usize, n: usize| {
        s.len() < 3 || s[2] <= factor * edge(m, n) || s[2] <= EXACT * s[0]
    };
    let flat = |s: &[f64], m: usize, n: usize| flat_within(RANK_EDGE_FACTOR, s, m, n);
    let no_clear_depth =
        |s: &[f64], m: usize, n: usize| flat_within(CORROBORATION_EDGE_FACTOR, s, m, n);
    let describe_block = format!(
        "σ ≈ {} px per coordinate, estimated from the singular values of {} frames × {} \
         tracks",
        px(sigma),
        frames.len(),
        tracks.len()
    );

    // 4. Static camera: the median track moves at the noise level, and the block's tracks
    //    that do (ratio ≤ 3: a few fast tracks are movers, not the camera) show no third
    //    dimension.
    let ratio_of = |p: usize| {
        let kp = k[p] as f64;
        (ss[p] / kp).sqrt() / (sigma * (2.0 * (kp - 1.0) / kp).sqrt())
    };
    let ratio = median(moving.iter().map(|&p| ratio_of(p)).collect());
    if let Some(ratio) = ratio
        && ratio <= STATIC_RATIO
    {
        let slow: Vec<usize> = tracks
            .iter()
            .copied()
            .filter(|&p| ratio_of(p) <= 2.0 * STATIC_RATIO)
            .collect();
        let still = slow.len() >= MIN_BLOCK_TRACKS
            && centred_block(table, &frames, &slow, origin)
                .and_then(|c| {
                    let (m, n) = block_dims(&c);
                    singular_values(&c).map(|s| no_clear_depth(&s, m, n))
                })
                .unwrap_or(false);
        if still {
            let expected = median(
                moving
                    .iter()
                    .map(|&p| sigma * (2.0 * (k[p] as f64 - 1.0) / k[p] as f64).sqrt())
                    .collect(),
            );
            return Err(Error::Degenerate(format!(
                "static camera — the tracks move by a median of {} px across the frames (RMS \
                 distance from their mean position), at the noise level ({} px from noise \
                 alone, {describe_block}; up to {STATIC_RATIO} times that, with no third \
                 dimension above the noise, is refused); no depth can be recovered",
                px(median_motion),
                px(expected.unwrap_or(f64::NAN))
            )));
        }
    }

    // 5. Collinear points: on a line in (nearly) every frame, and no third dimension.
    let mut line_ratio = Vec::new();
    let mut spread = Vec::new();
    for f in 0..nf {
        let row = table.frame_row(f).entries();
        if row.len() < 3 {
            continue;
        }
        let kf = row.len() as f64;
        let (mx, my) = (
            row.iter().map(|e| e.x - origin[0]).sum::<f64>() / kf,
            row.iter().map(|e| e.y - origin[1]).sum::<f64>() / kf,
        );
        let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
        for e in row {
            let (dx, dy) = (e.x - origin[0] - mx, e.y - origin[1] - my);
            sxx += dx * dx;
            syy += dy * dy;
            sxy += dx * dy;
        }
        let (sxx, syy, sxy) = (sxx / kf, syy / kf, sxy / kf);
        let half = 0.5 * (sxx - syy);
        let l2 = (0.5 * (sxx + syy) - (half * half + sxy * sxy).sqrt()).max(0.0);
        let l1 = 0.5 * (sxx + syy) + (half * half + sxy * sxy).sqrt();
        spread.push(l2.sqrt());
        line_ratio.push(if l2.sqrt() <= EXACT * l1.sqrt() {
            0.0
        } else {
            l2.sqrt() / (sigma * ((kf - 2.0) / kf).sqrt())
        });
    }
    let on_line = line_ratio.iter().filter(|&&r| r <= COLLINEAR_RATIO).count();
    if !line_ratio.is_empty()
        && on_line as f64 >= COLLINEAR_FRAME_SHARE * line_ratio.len() as f64
        && no_clear_depth(&s, m, n)
    {
        return Err(Error::Degenerate(format!(
            "collinear points — in {on_line} of {} frames the points lie on a line to within \
             the noise (median RMS distance from the frame's best line {} px; \
             {describe_block}): the points do not span 3D, so no depth can be recovered",
            line_ratio.len(),
            px(median(spread).unwrap_or(f64::NAN))
        )));
    }

    // 6. Rank < 3, where the block stands for the whole table.
    if block.frames.len() == nf && 2 * block.tracks.len() >= nt {
        let e = edge(m, n);
        let shift = translation_residual(&c, frames.len(), sigma);
        let values = s
            .iter()
            .take(4)
            .map(|&v| px(v))
            .collect::<Vec<_>>()
            .join(", ");
        if flat(&s, m, n) {
            let case = if s.len() < 2 || s[1] <= RANK_EDGE_FACTOR * e {
                "the points are collinear or coincide"
            } else if shift.is_some_and(|(r, ..)| r <= STATIC_RATIO) {
                "the image only translates: every track moves by the same shift in each \
                 frame, so there is no parallax"
            } else {
                "the points are coplanar, or the camera moves only in the image plane \
                 (rotation about the viewing axis, zoom)"
            };
            return Err(Error::Degenerate(format!(
                "the points or the motion do not span 3D (rank < 3): σ3 = {} of the centred \
                 observation matrix is at the noise level, not above {}, the largest singular \
                 value that noise of σ ≈ {} px alone gives a block of {} frames × {} tracks \
                 (singular values {values}); {case}; no depth can be recovered",
                px(s.get(2).copied().unwrap_or(0.0)),
                px(RANK_EDGE_FACTOR * e),
                px(sigma_edge),
                frames.len(),
                tracks.len()
            )));
        }
    }
    Ok(Check {
        origin,
        median_motion_px: median_motion,
        noise_sigma_px: Some(sigma),
        block: Some(size),
        depth_margin: s.get(2).map(|s3| s3 / edge(m, n)),
        warnings,
    })
}

/// The block of `frames` × `tracks` (all observed) minus `origin`, each row centred
/// (2 rows per frame). `None` with fewer than 2 tracks.
fn centred_block(
    table: &TrackTable,
    frames: &[usize],
    tracks: &[usize],
    origin: [f64; 2],
) -> Option<Mat<f64>> {
    if tracks.len() < 2 {
        return None;
    }
    let (rows, cols) = (2 * frames.len(), tracks.len());
    let mut c = Mat::zeros(rows, cols);
    for (i, &f) in frames.iter().enumerate() {
        let row = table.frame_row(f);
        for (j, &p) in tracks.iter().enumerate() {
            let w = row.get(p)?;
            c[(2 * i, j)] = w[0] - origin[0];
            c[(2 * i + 1, j)] = w[1] - origin[1];
        }
    }
    for r in 0..rows {
        let m = (0..cols).map(|j| c[(r, j)]).sum::<f64>() / cols as f64;
        for j in 0..cols {
            c[(r, j)] -= m;
        }
    }
    Some(c)
}

/// `(m, n)`, `m ≤ n`, of a row-centred block: the centring removes one dimension of its
/// rows' space.
fn block_dims(c: &Mat<f64>) -> (usize, usize) {
    let (rows, cols) = (c.nrows(), c.ncols() - 1);
    (rows.min(cols), rows.max(cols))
}

/// The `m` (see [`block_dims`]) largest singular values of `c`, descending.
fn singular_values(c: &Mat<f64>) -> Option<Vec<f64>> {
    let mut s = c.as_ref().singular_values().ok()?;
    s.sort_by(|a, b| b.total_cmp(a));
    s.truncate(block_dims(c).0);
    Some(s)
}

/// How far the row-centred block `c` (2·`frames` rows) is from the frames' translations
/// alone: per track, the RMS distance of its centred positions from their mean over the
/// frames, against what noise `sigma` alone gives. Returns the median ratio, the median
/// distance and the expected one, pixels (`None` for fewer than 2 frames).
fn translation_residual(c: &Mat<f64>, frames: usize, sigma: f64) -> Option<(f64, f64, f64)> {
    let cols = c.ncols();
    if frames < 2 {
        return None;
    }
    let expected = sigma
        * (2.0 * (frames as f64 - 1.0) / frames as f64 * (cols as f64 - 1.0) / cols as f64).sqrt();
    let moved: Vec<f64> = (0..cols)
        .map(|j| {
            let mut ss = 0.0;
            for d in 0..2 {
                let mean = (0..frames).map(|f| c[(2 * f + d, j)]).sum::<f64>() / frames as f64;
                ss += (0..frames)
                    .map(|f| (c[(2 * f + d, j)] - mean).powi(2))
                    .sum::<f64>();
            }
            (ss / frames as f64).sqrt()
        })
        .collect();
    let moved = median(moved)?;
    Some((moved / expected, moved, expected))
}

/// A complete block: frames (ascending) × the tracks seen in all of them.
struct Block {
    frames: Vec<usize>,
    tracks: Vec<usize>,
}

/// The reference block: of the consecutive-frame blocks ([`consecutive_block`], a video's)
/// and the greedy one ([`greedy_block`], scattered missing entries), the one with the most
/// observations, at least [`MIN_BLOCK_FRAMES`] × [`MIN_BLOCK_TRACKS`].
fn reference_block(table: &TrackTable) -> Option<Block> {
    let a = consecutive_block(table);
    // No block holds more observations than the table: a complete table's whole block.
    if a.as_ref()
        .is_some_and(|a| a.frames.len() * a.tracks.len() == table.n_observed())
    {
        return a;
    }
    let b = greedy_block(table);
    let size = |b: &Option<Block>| b.as_ref().map_or(0, |b| b.frames.len() * b.tracks.len());
    if size(&b) > size(&a) { b } else { a }
}

/// The block of consecutive frames × the tracks seen in all of them with the most
/// observations, over window lengths of all frames, 40, 20, 10, 5 and 4 frames.
/// `O(runs + F)` per length.
fn consecutive_block(table: &TrackTable) -> Option<Block> {
    let (nf, nt) = (table.n_frames(), table.n_tracks());
    // (first, end, track) of every run of consecutive frames a track is seen in.
    let mut runs: Vec<(usize, usize, usize)> = Vec::new();
    let mut open: Vec<Option<(usize, usize)>> = vec![None; nt]; // (first, last)
    for f in 0..nf {
        for e in table.frame_row(f).entries() {
            let p = e.track as usize;
            open[p] = match open[p] {
                Some((a, last)) if last + 1 == f => Some((a, f)),
                Some((a, last)) => {
                    runs.push((a, last + 1, p));
                    Some((f, f))
                }
                None => Some((f, f)),
            };
        }
    }
    for (p, o) in open.iter().enumerate() {
        if let Some((a, last)) = o {
            runs.push((*a, last + 1, p));
        }
    }
    let mut best: Option<(usize, usize, usize)> = None; // (observations, first, len)
    for len in [nf, 40, 20, 10, 5, 4] {
        if len > nf || len < MIN_BLOCK_FRAMES {
            continue;
        }
        let mut diff = vec![0i64; nf + 1];
        for &(a, b, _) in runs.iter().filter(|r| r.1 - r.0 >= len) {
            diff[a] += 1;
            diff[b - len + 1] -= 1;
        }
        let mut acc = 0i64;
        for (start, d) in diff.iter().enumerate().take(nf - len + 1) {
            acc += d;
            let n = acc as usize;
            if n >= MIN_BLOCK_TRACKS && best.is_none_or(|b| n * len > b.0) {
                best = Some((n * len, start, len));
            }
        }
    }
    let (_, first, len) = best?;
    Some(Block {
        frames: (first..first + len).collect(),
        tracks: runs
            .iter()
            .filter(|&&(a, b, _)| a <= first && first + len <= b)
            .map(|&(_, _, p)| p)
            .collect(),
    })
}

/// A complete block grown greedily over (at most 200, evenly spaced) frames in any order:
/// from the frame with the most tracks, add the frame that keeps the most tracks in common,
/// and keep the step with the most observations. `O(F'² N / 64)` with bitsets.
fn greedy_block(table: &TrackTable) -> Option<Block> {
    let (nf, nt) = (table.n_frames(), table.n_tracks());
    let words = nt.div_ceil(64);
    let candidates = spaced(nf, 200);
    let bits: Vec<Vec<u64>> = candidates
        .iter()
        .map(|&f| {
            let mut b = vec![0u64; words];
            for e in table.frame_row(f).entries() {
                b[e.track as usize / 64] |= 1 << (e.track % 64);
            }
            b
        })
        .collect();
    let count = |a: &[u64], b: &[u64]| -> usize {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x & y).count_ones() as usize)
            .sum()
    };
    let first = (0..candidates.len()).max_by_key(|&i| count(&bits[i], &bits[i]))?;
    let mut chosen = vec![first];
    let mut used = vec![false; candidates.len()];
    used[first] = true;
    let mut common = bits[first].clone();
    let mut best: Option<(usize, Vec<usize>, Vec<u64>)> = None;
    loop {
        let next = (0..candidates.len())
            .filter(|&i| !used[i])
            .max_by_key(|&i| count(&common, &bits[i]));
        let Some(i) = next else { break };
        let n = count(&common, &bits[i]);
        if n < MIN_BLOCK_TRACKS {
            break;
        }
        used[i] = true;
        chosen.push(i);
        common.iter_mut().zip(&bits[i]).for_each(|(c, b)| *c &= b);
        if chosen.len() >= MIN_BLOCK_FRAMES && best.as_ref().is_none_or(|b| n * chosen.len() > b.0)
        {
            best = Some((n * chosen.len(), chosen.clone(), common.clone()));
        }
    }
    let (_, chosen, common) = best?;
    let mut frames: Vec<usize> = chosen.iter().map(|&i| candidates[i]).collect();
    frames.sort_unstable();
    Some(Block {
        frames,
        tracks: (0..nt)
            .filter(|&p| common[p / 64] >> (p % 64) & 1 == 1)
            .collect(),
    })
}

/// Per-track statistics of [`check`]'s pass over the observations.
struct TrackStats {
    /// The first observation (frame order), `None` for an empty table.
    reference: Option<[f64; 2]>,
    max_abs: f64,
    finite: bool,
    /// Frames seen, mean position and `Σ |w − mean|²` per track.
    count: Vec<usize>,
    mean: Vec<[f64; 2]>,
    m2: Vec<f64>,
}

/// [`TrackStats`] in one pass over the observations, in chunks of frames on all cores:
/// each chunk sums per track relative to the track's first observation in it (so that the
/// sums cancel nothing when the coordinates are far from the origin), and the chunks are
/// merged by Chan, Golub & LeVeque's pairwise update of the mean and the sum of squares
/// ("Algorithms for computing the sample variance", Am. Stat. 37(3), 1983). `O(observations
/// + N · chunks)`.
fn track_stats(table: &TrackTable) -> TrackStats {
    use rayon::prelude::*;
    let (nf, nt) = (table.n_frames(), table.n_tracks());
    // A chunk's statistics: `mean` holds each track's shift (its first observation in
    // the chunk) until the end of the chunk.
    let chunk_of = |frames: std::ops::Range<usize>| -> TrackStats {
        let mut c = TrackStats {
            reference: None,
            max_abs: 0.0,
            finite: true,
            count: vec![0; nt],
            mean: vec![[0.0; 2]; nt],
            m2: vec![0.0; nt],
        };
        let mut s1 = vec![[0.0f64; 2]; nt];
        for f in frames {
            for e in table.frame_row(f).entries() {
                if !(e.x.is_finite() && e.y.is_finite()) {
                    c.finite = false;
                    continue;
                }
                let p = e.track as usize;
                if c.count[p] == 0 {
                    c.mean[p] = [e.x, e.y];
                }
                c.reference.get_or_insert([e.x, e.y]);
                c.count[p] += 1;
                let (dx, dy) = (e.x - c.mean[p][0], e.y - c.mean[p][1]);
                s1[p][0] += dx;
                s1[p][1] += dy;
                c.m2[p] += dx * dx + dy * dy;
                c.max_abs = c.max_abs.max(e.x.abs()).max(e.y.abs());
            }
        }
        for p in 0..nt {
            if c.count[p] > 0 {
                let n = c.count[p] as f64;
                let (mx, my) = (s1[p][0] / n, s1[p][1] / n);
                c.mean[p][0] += mx;
                c.mean[p][1] += my;
                c.m2[p] = (c.m2[p] - n * (mx * mx + my * my)).max(0.0);
            }
        }
        c
    };
    let threads = rayon::current_num_threads().max(1);
    let per = nf.div_ceil(threads).max(1);
    let chunks: Vec<TrackStats> = (0..nf.div_ceil(per))
        .into_par_iter()
        .map(|i| chunk_of(i * per..((i + 1) * per).min(nf)))
        .collect();
    let mut it = chunks.into_iter();
    let mut acc = it.next().unwrap_or_else(|| chunk_of(0..0));
    for b in it {
        acc.reference = acc.reference.or(b.reference);
        acc.max_abs = acc.max_abs.max(b.max_abs);
        acc.finite &= b.finite;
        for p in 0..nt {
            let (na, nb) = (acc.count[p], b.count[p]);
            if nb == 0 {
                continue;
            }
            if na == 0 {
                acc.count[p] = nb;
                acc.mean[p] = b.mean[p];
                acc.m2[p] = b.m2[p];
                continue;
            }
            let n = (na + nb) as f64;
            let (fa, fb) = (na as f64, nb as f64);
            let d = [b.mean[p][0] - acc.mean[p][0], b.mean[p][1] - acc.mean[p][1]];
            acc.mean[p][0] += d[0] * fb / n;
            acc.mean[p][1] += d[1] * fb / n;
            acc.m2[p] += b.m2[p] + (d[0] * d[0] + d[1] * d[1]) * fa * fb / n;
            acc.count[p] = na + nb;
        }
    }
    acc
}

/// At most `max` indices of `0..len`, evenly spaced (rounded to nearest), first and last
/// included (`max = 1`: the first only), ascending and distinct.
pub(crate) fn spaced(len: usize, max: usize) -> Vec<usize> {
    if len <= max {
        return (0..len).collect();
    }
    (0..max)
        .map(|i| (i * (len - 1) + (max - 1) / 2) / (max - 1).max(1))
        .collect()
}

/// Noise σ from the singular values `s` (descending, `m` of them) of an `m × n` (`m ≤ n`)
/// matrix of signal of rank ≤ 3 plus noise: the median over the values below the three
/// largest of their ratio to the Marchenko–Pastur quantile at their rank. `None` with fewer
/// than 3 such values.
fn noise_sigma(s: &[f64], m: usize, n: usize) -> Option<f64> {
    if m < 6 || s.len() < m {
        return None;
    }
    let mp = MarchenkoPastur::new(m as f64 / n as f64);
    let ratios: Vec<f64> = (1..=m - 3)
        .filter_map(|k| {
            let y = s[m - k];
            let q = (n as f64 * mp.quantile((k as f64 - 0.5) / m as f64)).sqrt();
            (q > 0.0).then(|| y / q)
        })
        .collect();
    median(ratios)
}

/// Noise σ from the energy the three largest singular values leave, `Σ_{k>3} y_k²`, over
/// its degrees of freedom `(m − 3)(n − 3)`. `None` without such values.
fn residual_sigma(s: &[f64], m: usize, n: usize) -> Option<f64> {
    if m <= 3 || s.len() <= 3 {
        return None;
    }
    let rest: f64 = s[3..].iter().map(|y| y * y).sum();
    Some((rest / ((m - 3) * (n - 3)) as f64).sqrt())
}

/// The Marchenko–Pastur law with ratio `β ∈ (0, 1]`: the limit law of the eigenvalues of
/// `XXᵀ/n` for an `m × n` matrix `X` of unit-variance entries, `β = m/n`; density
/// `sqrt((b − x)(x − a)) / (2πβx)` on `[a, b] = [(1 − √β)², (1 + √β)²]`. The CDF is
/// tabulated in `x = (a + b)/2 − (b − a)/2 · cos θ`, which removes the square roots.
struct MarchenkoPastur {
    a: f64,
    b: f64,
    /// CDF at `θ = π i / (len − 1)`.
    cdf: Vec<f64>,
}

impl MarchenkoPastur {
    const STEPS: usize = 4096;

    fn new(beta: f64) -> Self {
        let beta = beta.clamp(1e-6, 1.0);
        let (a, b) = ((1.0 - beta.sqrt()).powi(2), (1.0 + beta.sqrt()).powi(2));
        let h = std::f64::consts::PI / Self::STEPS as f64;
        let half = (b - a) / 2.0;
        let mut cdf = Vec::with_capacity(Self::STEPS + 1);
        let mut acc = 0.0;
        cdf.push(0.0);
        for i in 0..Self::STEPS {
            // Midpoint rule: θ never 0, so x > 0 even for β = 1.
            let t = (i as f64 + 0.5) * h;
            let x = (a + b) / 2.0 - half * t.cos();
            acc += half * half * t.sin().powi(2) / (2.0 * std::f64::consts::PI * beta * x) * h;
            cdf.push(acc);
        }
        let total = acc;
        cdf.iter_mut().for_each(|c| *c /= total);
        MarchenkoPastur { a, b, cdf }
    }

    /// The `p`-quantile, `p ∈ [0, 1]`.
    fn quantile(&self, p: f64) -> f64 {
        let p = p.clamp(0.0, 1.0);
        let i = self.cdf.partition_point(|&c| c < p).clamp(1, Self::STEPS);
        let (c0, c1) = (self.cdf[i - 1], self.cdf[i]);
        let frac = if c1 > c0 { (p - c0) / (c1 - c0) } else { 0.0 };
        let t = (i as f64 - 1.0 + frac) * std::f64::consts::PI / Self::STEPS as f64;
        (self.a + self.b) / 2.0 - (self.b - self.a) / 2.0 * t.cos()
    }
}

/// Distance to the next larger double (`0` for `0`).
fn ulp(x: f64) -> f64 {
    let x = x.abs();
    if x == 0.0 || !x.is_finite() {
        return 0.0;
    }
    f64::from_bits(x.to_bits() + 1) - x
}

/// A pixel quantity with 3 significant digits, in scientific notation below 0.01.
fn px(v: f64) -> String {
    if v == 0.0 || (v.abs() >= 0.01 && v.abs() < 1e6) {
        format!("{v:.3}")
    } else {
        format!("{v:.2e}")
    }
}

/// The median of the values that are not NaN ([`crate::eval::median`]); `None` when none
/// is left.
fn median(mut v: Vec<f64>) -> Option<f64> {
    v.retain(|x| !x.is_nan());
    (!v.is_empty()).then(|| crate::eval::median(&v))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::table::Id;
    use rand::{RngExt, SeedableRng};
    use rand_distr::{Distribution, Normal};

    #[test]
    fn marchenko_pastur_quantiles() {
        // β = 1: density sqrt((4 − x)x)/(2πx) on [0, 4], median 0.65278 (integrated
        // independently with 2·10⁶ steps).
        let mp = MarchenkoPastur::new(1.0);
        assert!(
            (mp.quantile(0.5) - 0.65278).abs() < 1e-4,
            "{}",
            mp.quantile(0.5)
        );
        assert!((mp.quantile(1.0) - 4.0).abs() < 1e-9);
        let mp = MarchenkoPastur::new(0.25);
        assert!((mp.quantile(0.0) - 0.25).abs() < 1e-9);
        assert!((mp.quantile(1.0) - 2.25).abs() < 1e-9);
        // The mean of the law is 1.
        let mean = (0..1000)
            .map(|i| mp.quantile((i as f64 + 0.5) / 1000.0))
            .sum::<f64>()
            / 1000.0;
        assert!((mean - 1.0).abs() < 1e-3, "{mean}");
    }

    fn table(f: usize, n: usize, pos: impl Fn(usize, usize) -> [f64; 2]) -> TrackTable {
        let mut t = TrackTable::new(
            (0..f).map(Id::from).collect(),
            (0..n).map(Id::from).collect(),
        );
        for fi in 0..f {
            for p in 0..n {
                let [x, y] = pos(fi, p);
                t.set(fi, p, x, y);
            }
        }
        t
    }

    #[test]
    fn noise_level_of_pure_noise_blocks() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(1);
        let nrm = Normal::new(0.0, 0.3).unwrap();
        for (f, n) in [(4usize, 8usize), (10, 40), (30, 200), (100, 60)] {
            let base: Vec<[f64; 2]> = (0..n)
                .map(|_| [rng.random_range(0.0..640.0), rng.random_range(0.0..480.0)])
                .collect();
            let noise: Vec<f64> = (0..2 * f * n).map(|_| nrm.sample(&mut rng)).collect();
            let t = table(f, n, |fi, p| {
                [
                    base[p][0] + noise[2 * (fi * n + p)],
                    base[p][1] + noise[2 * (fi * n + p) + 1],
                ]
            });
            let e = check(&t).unwrap_err().to_string();
            assert!(e.contains("static camera"), "{f}×{n}: {e}");
        }
    }

    #[test]
    fn a_small_rotation_is_not_refused() {
        // 40 points of a unit cube turning by 1° per frame about the vertical axis, 100 px
        // per unit, 0.3 px noise: the nearest track moves a few pixels.
        let mut rng = rand::rngs::StdRng::seed_from_u64(2);
        let nrm = Normal::new(0.0, 0.3).unwrap();
        let pts: Vec<[f64; 3]> = (0..40)
            .map(|_| std::array::from_fn(|_| rng.random_range(-1.0..1.0)))
            .collect();
        let noise: Vec<f64> = (0..2 * 10 * 40).map(|_| nrm.sample(&mut rng)).collect();
        let t = table(10, 40, |f, p| {
            let a = (f as f64).to_radians();
            let [x, y, z] = pts[p];
            [
                320.0 + 100.0 * (a.cos() * x + a.sin() * z) + noise[2 * (f * 40 + p)],
                240.0 + 100.0 * y + noise[2 * (f * 40 + p) + 1],
            ]
        });
        let c = check(&t).unwrap();
        let sigma = c.noise_sigma_px.unwrap();
        assert!((sigma - 0.3).abs() < 0.06, "σ̂ = {sigma}");
    }

    #[test]
    fn precision_and_translation() {
        let t = table(6, 10, |f, p| {
            [1e15 + 0.1 * (f * p) as f64, 1e15 + 0.05 * p as f64]
        });
        let e = check(&t).unwrap_err().to_string();
        assert!(e.contains("too large for double precision"), "{e}");
        // A turning cube 10⁵ px from the origin: its centroid is the origin taken out.
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let pts: Vec<[f64; 3]> = (0..20)
            .map(|_| std::array::from_fn(|_| rng.random_range(-1.0..1.0)))
            .collect();
        let at = |f: usize, p: usize| {
            let a = (5.0 * f as f64).to_radians();
            let [x, y, z] = pts[p];
            [100.0 * (a.cos() * x + a.sin() * z), 100.0 * y]
        };
        let mean = |d: usize| (0..6 * 20).map(|i| at(i / 20, i % 20)[d]).sum::<f64>() / 120.0;
        let t = table(6, 20, |f, p| {
            let [x, y] = at(f, p);
            [1e5 + x, 2e5 + y]
        });
        let c = check(&t).unwrap();
        assert!((c.origin[0] - 1e5 - mean(0)).abs() < 1e-8, "{:?}", c.origin);
        assert!((c.origin[1] - 2e5 - mean(1)).abs() < 1e-8, "{:?}", c.origin);
    }

    #[test]
    fn non_finite_is_named() {
        let mut t = table(5, 10, |f, p| [f as f64, p as f64]);
        t.set(2, 3, f64::INFINITY, 1.0);
        let e = check(&t).unwrap_err().to_string();
        assert!(e.contains("track 3 in frame 2 is not finite"), "{e}");
    }
}

#[cfg(test)]
mod calibration {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// Prints, for pure noise plus a rank-2 signal (the null hypothesis of the rank test),
    /// the two noise estimates (true σ = 1) and σ3 over the noise edge with the smaller:
    /// the figures the module documentation quotes. Slow (200 draws per size up to
    /// 200 × 1000): `cargo test --lib degeneracy::calibration -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn null_distribution() {
        let nrm = Normal::new(0.0, 1.0).unwrap();
        let mut rng = rand::rngs::StdRng::seed_from_u64(9);
        for (rows, cols) in [(8usize, 8usize), (12, 20), (20, 40), (60, 200), (200, 1000)] {
            let mut est_mp = Vec::new();
            let mut est_res = Vec::new();
            let mut ratio = Vec::new();
            for _ in 0..200 {
                let u: Vec<f64> = (0..cols).map(|_| nrm.sample(&mut rng) * 30.0).collect();
                let v: Vec<f64> = (0..cols).map(|_| nrm.sample(&mut rng) * 20.0).collect();
                let mut c = Mat::from_fn(rows, cols, |r, j| {
                    (if r % 2 == 0 { u[j] } else { v[j] }) + nrm.sample(&mut rng)
                });
                for r in 0..rows {
                    let m = (0..cols).map(|j| c[(r, j)]).sum::<f64>() / cols as f64;
                    for j in 0..cols {
                        c[(r, j)] -= m;
                    }
                }
                let s = singular_values(&c).unwrap();
                let (m, n) = block_dims(&c);
                let a = noise_sigma(&s, m, n).unwrap();
                let b = residual_sigma(&s, m, n).unwrap();
                est_mp.push(a);
                est_res.push(b);
                let sig = a.min(b);
                ratio.push(s[2] / (sig * ((m as f64).sqrt() + (n as f64).sqrt())));
            }
            let q = |mut v: Vec<f64>, p: f64| {
                v.sort_by(f64::total_cmp);
                v[((v.len() - 1) as f64 * p) as usize]
            };
            println!(
                "{rows}×{cols}: σ̂ MP median {:.3} [{:.3}, {:.3}], residual {:.3} [{:.3}, {:.3}]; \
                 σ3/edge median {:.3}, 99 % {:.3}, max {:.3}; ≤ 1: {:.3}, ≤ 1.05: {:.3}",
                q(est_mp.clone(), 0.5),
                q(est_mp.clone(), 0.05),
                q(est_mp, 0.95),
                q(est_res.clone(), 0.5),
                q(est_res.clone(), 0.05),
                q(est_res, 0.95),
                q(ratio.clone(), 0.5),
                q(ratio.clone(), 0.99),
                q(ratio.clone(), 1.0),
                ratio.iter().filter(|&&r| r <= 1.0).count() as f64 / ratio.len() as f64,
                ratio.iter().filter(|&&r| r <= 1.05).count() as f64 / ratio.len() as f64,
            );
        }
    }
}
