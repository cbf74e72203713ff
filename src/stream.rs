//! Streaming factorization of complete tracks: the measurement matrix is never held whole.
//!
//! **Objective** — the dense pipeline's for complete data (docs/math.md §2–§3): with `W`
//! the 2F×N matrix of the complete tracks and `t` its row means,
//! `min ‖W − t1ᵀ − M̂Ŝ‖²_F` over rank-3 products, then the metric upgrade of `M̂` (§3) and
//! each point by least squares given the metric cameras `M` (2F×3):
//! `s_p = argmin ‖w_p − t − M s‖² = (MᵀM)⁻¹ Mᵀ(w_p − t)`.
//!
//! **Method** (docs/math.md §13, *W larger than memory*). The centred Gram matrix
//! `C = (W − t1ᵀ)(W − t1ᵀ)ᵀ` (2F×2F) is summed over the tracks a block at a time:
//! `G = Σ_p (w_p − c)(w_p − c)ᵀ` and `s = Σ_p (w_p − c)` about a shift `c` (the first block's
//! row means, so that `G − s sᵀ/N` does not cancel), `C = G − s sᵀ/N`, `t = c + s/N`. Its
//! eigenvectors are the left singular vectors of `W − t1ᵀ` and its eigenvalues their
//! squared singular values, so the rank-3 truncation's motion is `M̂ = U₃ Σ₃^{1/2}`, as in
//! the dense path (Eckart–Young), found by subspace iteration (`leading_eigen`). One more
//! pass over the entries then
//! sums, per track, `b_p = Mᵀ(w_p − t)`, `â_p = U₃ᵀ(w_p − t)` and `‖w_p − t‖²`: the point
//! `s_p = (MᵀM)⁻¹ b_p`, the affine structure `ŝ_p = Σ₃^{-1/2} â_p`, and the residual
//! `‖w_p − t‖² − b_pᵀ s_p`. These sums are linear in the entries, so that pass reads them in
//! any order. The per-frame residuals come from the Gram alone: the diagonal of
//! `(I − P) C (I − P)`, `P = M (MᵀM)⁻¹ Mᵀ` (the residual of track `p` is `(I − P)(w_p − t)`).
//!
//! **Reading.** A source ([`ObservationSource`]) is scanned in passes; any row order is
//! allowed (a CSV file is typically frame-major, so a track's entries are far apart). The
//! complete tracks are cut into blocks of `B` tracks whose `2F × B` values fit the memory
//! budget; each Gram pass fills one block. When the first (counting) pass's entries and the
//! block built from them fit the budget (40 bytes per observation) the source is read once
//! and the block stays in memory for the rest; otherwise `1 + ⌈N/B⌉` passes, plus one per
//! structure pass and one per downdate of the track test. Partial tracks (not seen in every frame) are set
//! aside and reported: this path is for complete tables (the dense and sparse pipelines
//! take missing data).
//!
//! **Robust test** (the dense robust pass's final track test, docs/math.md §7): a track is
//! an inlier when its residual `r_p ≤ max(σ̂² χ²_ν(p), 2F·r_min²)`, `ν = 2F − 3`, with
//! `σ̂² = median_p r_p / χ²_ν(½)` over the tracks of the fit, `p` = `track_probability`,
//! `r_min` = `min_track_threshold_px`. The tracks that fail are taken out of the Gram (a
//! downdate by their columns, gathered in one pass) and the fit repeated, up to
//! `max_rounds` times; a track that passes again is put back. There is no RANSAC and no
//! gross-entry test: a gross entry makes its whole track fail.
//!
//! **Complexity.** Time `O(F²N)` for the Gram (a symmetric rank-`B` update per block),
//! `O(F²)` per iteration of the leading eigenpairs' subspace iteration (a few for a rigid
//! scene; `O(F³)` in the fallback), `O(n_obs)` per pass of parsing and of the
//! structure sums. Memory: `(2F)²` for the Gram, `2F·B` for the block held, `O(N)` per
//! track (ids, counts, sums): the budget bounds the block, not the file.
//!
//! References: C. Tomasi and T. Kanade, IJCV 9(2), 1992 (factorization); G. H. Golub and
//! C. F. Van Loan, *Matrix Computations*, 4th ed., §8.6 (SVD from the eigenproblem of
//! `AAᵀ`) and §2.4 (its sensitivity: the leading singular vectors are as accurate as the
//! gap `σ3² − σ4²` allows, which for tracks of a rigid scene is large).

use std::path::{Path, PathBuf};
use std::time::Instant;

use faer::linalg::matmul::triangular::BlockStructure;
use faer::{Mat, Par, Side};
use nalgebra::{Matrix3, Vector3};
use serde::Serialize;

use crate::camera::MetricModel;
use crate::metric::{self, MetricConfig, MetricUpgrade};
use crate::observer::{Event, Observer};
use crate::table::csv::{Scanned, ScannedObservation};
use crate::table::{SetAside, SetAsideKind, TrackTable};
use crate::{CameraModel, Error, Id, Result};

/// Settings of [`factorize`]. Every field has a documented default.
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct StreamConfig {
    /// Bytes for the block of `W` held at once (`16·F` bytes per track; a table whose
    /// first-pass list and block, 40 bytes per observation, fit is read once). The Gram
    /// matrix (`32·F²` bytes), the duplicate check (`F/8` bytes per track of the block) and
    /// the per-track sums (about 90 bytes per track) come on top. Default 1 GiB.
    pub memory_budget_bytes: usize,
    /// [`CameraModel::Orthographic`] or [`CameraModel::ScaledOrthographic`] (the default;
    /// [`CameraModel::Auto`] means it). The perspective cameras need the dense or sparse
    /// pipeline.
    pub camera: CameraModel,
    pub metric: MetricConfig,
    /// Run the track test and refit without the tracks that fail it. Default true.
    pub robust: bool,
    /// Probability that a good track passes the test (see the module docs). Default 0.9999,
    /// as the dense robust pass's.
    pub track_probability: f64,
    /// Floor of the test's threshold on a track's RMS, pixels. Default 2, as the pipeline's
    /// [`crate::Config`].
    pub min_track_threshold_px: f64,
    /// Refits at most after tracks were taken out or put back. Default 3.
    pub max_rounds: usize,
}

impl Default for StreamConfig {
    fn default() -> Self {
        Self {
            memory_budget_bytes: 1 << 30,
            camera: CameraModel::ScaledOrthographic,
            metric: MetricConfig::default(),
            robust: true,
            track_probability: 0.9999,
            min_track_threshold_px: 2.0,
            max_rounds: 3,
        }
    }
}

impl StreamConfig {
    fn validate(&self) -> Result<CameraModel> {
        if !(self.track_probability > 0.5 && self.track_probability < 1.0) {
            return Err(Error::InvalidConfig {
                field: "stream.track_probability",
                message: format!("{} is not in (0.5, 1)", self.track_probability),
            });
        }
        if !(self.min_track_threshold_px >= 0.0 && self.min_track_threshold_px.is_finite()) {
            return Err(Error::InvalidConfig {
                field: "stream.min_track_threshold_px",
                message: format!("{} is not a finite value ≥ 0", self.min_track_threshold_px),
            });
        }
        match self.camera {
            CameraModel::Orthographic => Ok(CameraModel::Orthographic),
            CameraModel::ScaledOrthographic | CameraModel::Auto => {
                Ok(CameraModel::ScaledOrthographic)
            }
            other => Err(Error::InvalidConfig {
                field: "camera",
                message: format!(
                    "the streaming factorization fits the affine cameras (orthographic, \
                     scaled orthographic), not {other:?}"
                ),
            }),
        }
    }
}

/// Where the observations come from: scanned once per pass, in the same order every time.
pub trait ObservationSource {
    /// Hands every observation to `visit`, a batch at a time; frame and track are indices
    /// into the returned [`Scanned`] ids, the same on every scan.
    fn scan(
        &mut self,
        visit: &mut dyn FnMut(&[ScannedObservation]) -> Result<()>,
    ) -> Result<Scanned>;
    /// The file, for error messages (None for an in-memory source).
    fn path(&self) -> Option<&Path>;
}

/// A long-format CSV file (`frame,track,x,y`), read again on every pass
/// ([`crate::table::csv::scan_reader`]).
#[derive(Debug, Clone)]
pub struct CsvFile {
    pub path: PathBuf,
}

impl ObservationSource for CsvFile {
    fn scan(
        &mut self,
        visit: &mut dyn FnMut(&[ScannedObservation]) -> Result<()>,
    ) -> Result<Scanned> {
        let file = std::fs::File::open(&self.path).map_err(|e| Error::io(&self.path, e))?;
        crate::table::csv::scan_reader(file, &self.path, visit)
    }

    fn path(&self) -> Option<&Path> {
        Some(&self.path)
    }
}

/// A table in memory as a source (frame by frame, tracks in the table's order; its ids are
/// already in rank3's order). For tests and for comparing with the dense path.
#[derive(Debug, Clone, Copy)]
pub struct TableSource<'a>(pub &'a TrackTable);

impl ObservationSource for TableSource<'_> {
    fn scan(
        &mut self,
        visit: &mut dyn FnMut(&[ScannedObservation]) -> Result<()>,
    ) -> Result<Scanned> {
        let t = self.0;
        let mut buf = Vec::with_capacity(t.n_tracks());
        for f in 0..t.n_frames() {
            buf.clear();
            for p in 0..t.n_tracks() {
                if let Some([x, y]) = t.get(f, p) {
                    buf.push(ScannedObservation {
                        frame: f as u32,
                        track: p as u32,
                        x,
                        y,
                        line: 0,
                    });
                }
            }
            visit(&buf)?;
        }
        Ok(Scanned {
            frame_ids: t.frame_ids().to_vec(),
            track_ids: t.track_ids().to_vec(),
            frame_order: (0..t.n_frames() as u32).collect(),
            track_order: (0..t.n_tracks() as u32).collect(),
            observations: t.n_observed(),
            warnings: Vec::new(),
        })
    }

    fn path(&self) -> Option<&Path> {
        None
    }
}

/// One round of the fit: the tracks in it and what it reached.
#[derive(Debug, Clone, Serialize)]
pub struct StreamRound {
    /// Tracks in the Gram matrix.
    pub tracks: usize,
    /// RMS of the rank-3 affine fit over their scalars, pixels.
    pub affine_rms_px: f64,
    /// RMS of the metric model over the same scalars, pixels.
    pub metric_rms_px: f64,
    /// Noise level of the track test, pixels (`σ̂`; NaN without the test).
    pub sigma_px: f64,
    /// Tracks failing the test after this round, and how many of them were in the fit.
    pub failing: usize,
    pub taken_out: usize,
    /// Tracks that passed again after being taken out in an earlier round.
    pub put_back: usize,
}

/// How the streaming factorization ran (`stream` in reconstruction.json).
#[derive(Debug, Clone, Serialize)]
pub struct StreamReport {
    /// Passes over the source, the counting pass included.
    pub passes: usize,
    /// Tracks per block of `W`, and blocks (Gram passes).
    pub block_tracks: usize,
    pub blocks: usize,
    pub memory_budget_bytes: usize,
    /// Bytes of the Gram matrix (2F×2F).
    pub gram_bytes: usize,
    pub rounds: Vec<StreamRound>,
    /// `"converged"` (the test's verdict stopped changing), `"max rounds"`, or `"no test"`.
    pub status: String,
    /// Seconds reading the source, in the Gram products, and in all.
    pub read_seconds: f64,
    pub gram_seconds: f64,
    pub seconds: f64,
}

/// The result of [`factorize`]. Frames and tracks are indexed in rank3's order of the
/// source's ids (ascending when all are integers, else first appearance).
#[derive(Debug, Clone)]
pub struct StreamResult {
    /// The camera fitted ([`CameraModel::Orthographic`] or
    /// [`CameraModel::ScaledOrthographic`]).
    pub camera: CameraModel,
    pub frame_ids: Vec<Id>,
    pub track_ids: Vec<Id>,
    pub observations: usize,
    /// The metric model: every frame's camera and the points of `tracks`.
    pub model: MetricModel,
    pub upgrade: MetricUpgrade,
    /// Whether the depth-reversal convention mirrored the solution.
    pub mirrored: bool,
    /// `M̂` (2F×3), `Ŝ` (3×|tracks|), `t` (2F) of the affine fit.
    pub m_hat: Mat<f64>,
    pub s_hat: Mat<f64>,
    pub t: Vec<f64>,
    /// The outlier tracks' affine structure (3×|outliers|) and metric points.
    pub outlier_s_hat: Mat<f64>,
    pub outlier_points: Vec<Vector3<f64>>,
    /// Every singular value of the centred `W` of the final fit, descending.
    pub singular_values: Vec<f64>,
    /// Track indices of the fit (ascending) and of the tracks that failed the test.
    pub tracks: Vec<usize>,
    pub outliers: Vec<usize>,
    /// Per track (all of them): the metric model's sum of squared residuals, NaN for a
    /// partial track.
    pub track_residuals: Vec<f64>,
    /// Per frame: the metric model's sum of squared residuals over the fit's tracks.
    pub frame_residuals: Vec<f64>,
    /// Partial tracks, set aside with the reason.
    pub set_aside: Vec<SetAside>,
    /// Per track: observations in the source.
    pub track_counts: Vec<u32>,
    pub affine_rms_px: f64,
    pub metric_rms_px: f64,
    pub report: StreamReport,
    /// The source's warnings (ignored columns, …).
    pub warnings: Vec<String>,
}

/// The running sums of the centred Gram matrix (see the module docs), over blocks of
/// shifted tracks.
struct Gram {
    shift: Vec<f64>,
    /// Lower triangle of `Σ (w − c)(w − c)ᵀ`.
    g: Mat<f64>,
    s: Vec<f64>,
    n: f64,
}

impl Gram {
    /// A Gram matrix about the row means of `first` (b×2F, one track per row).
    fn new(first: faer::MatRef<'_, f64>) -> Self {
        let rows = first.ncols();
        let shift = (0..rows)
            .map(|r| first.col(r).iter().sum::<f64>() / first.nrows().max(1) as f64)
            .collect();
        Self {
            shift,
            g: Mat::zeros(rows, rows),
            s: vec![0.0; rows],
            n: 0.0,
        }
    }

    /// Subtracts the shift from a block of raw tracks (b×2F), in place.
    fn shift(&self, x: &mut Mat<f64>) {
        for (r, &c) in self.shift.iter().enumerate() {
            x.col_mut(r).iter_mut().for_each(|v| *v -= c);
        }
    }

    /// Adds (`sign` 1) or removes (−1) the shifted tracks `x` (b×2F, one per row).
    fn add(&mut self, x: faer::MatRef<'_, f64>, sign: f64) {
        if x.nrows() == 0 {
            return;
        }
        for (r, s) in self.s.iter_mut().enumerate() {
            *s += sign * x.col(r).iter().sum::<f64>();
        }
        self.n += sign * x.nrows() as f64;
        faer::linalg::matmul::triangular::matmul(
            self.g.as_mut(),
            BlockStructure::TriangularLower,
            faer::Accum::Add,
            x.transpose(),
            BlockStructure::Rectangular,
            x,
            BlockStructure::Rectangular,
            sign,
            Par::rayon(0),
        );
    }

    /// The centred Gram matrix (full, symmetric) and the row means.
    fn centred(&self) -> (Mat<f64>, Vec<f64>) {
        let rows = self.g.nrows();
        let n = self.n;
        let c = Mat::from_fn(rows, rows, |i, j| {
            let (a, b) = if i >= j { (i, j) } else { (j, i) };
            self.g[(a, b)] - self.s[a] * self.s[b] / n
        });
        let t = (0..rows).map(|r| self.shift[r] + self.s[r] / n).collect();
        (c, t)
    }
}

/// One observation kept from the first pass (24 bytes).
#[derive(Clone, Copy)]
struct Entry {
    frame: u32,
    track: u32,
    x: f64,
    y: f64,
}

/// Bytes per observation of the first pass's list plus the block built from it: the list
/// is kept (and the source read once more only for a repeated pair) while this many bytes
/// per observation fit the budget.
const LIST_BYTES: usize = 24 + 16;

/// The passes over a source, counted and timed, and what the first one learnt.
struct Reader<'a, S: ObservationSource + ?Sized> {
    source: &'a mut S,
    passes: usize,
    read_seconds: f64,
    /// The first pass's entries, when they fit the budget.
    list: Option<Vec<Entry>>,
    /// Per first-appearance index: rank3's frame index, the track's position among the
    /// complete tracks (`u32::MAX`: partial).
    frame_of: Vec<u32>,
    position: Vec<u32>,
    frames: usize,
    /// Observations the first pass read (a later pass that reads another count means the
    /// file changed).
    observations: usize,
    /// The sum of the first pass's [`fingerprint`]s (a later pass with another sum read
    /// other values).
    checksum: u64,
    /// The first pass's ids, for messages.
    frame_ids: Vec<Id>,
    track_ids: Vec<Id>,
}

impl<S: ObservationSource + ?Sized> Reader<'_, S> {
    fn scan(
        &mut self,
        visit: &mut dyn FnMut(&[ScannedObservation]) -> Result<()>,
    ) -> Result<Scanned> {
        let t0 = Instant::now();
        let r = self.source.scan(visit);
        self.passes += 1;
        self.read_seconds += t0.elapsed().as_secs_f64();
        r
    }

    /// The tracks at positions with a slot in `slots` (`u32::MAX`: not wanted), as rows
    /// of a `cols × 2F` block of raw values, from the first pass's list or one pass over
    /// the source. A (frame, track) pair given twice is an error naming both lines.
    fn fill(&mut self, slots: &[u32], cols: usize) -> Result<Mat<f64>> {
        let nf = self.frames;
        let mut x = Mat::<f64>::zeros(cols, 2 * nf);
        let mut seen = vec![0u64; (cols * nf).div_ceil(64)];
        let mut dup: Option<(u32, u32, u32)> = None;
        let (frame_of, position) = (&self.frame_of, &self.position);
        let mut alien = false;
        let mut put = |frame: u32, track: u32, vx: f64, vy: f64, line: u32| {
            let (Some(&k), Some(&f)) = (position.get(track as usize), frame_of.get(frame as usize))
            else {
                // An id the first pass did not see: the file changed since.
                alien = true;
                return;
            };
            if k == u32::MAX || slots[k as usize] == u32::MAX {
                return;
            }
            let (f, c) = (f as usize, slots[k as usize] as usize);
            let bit = f * cols + c;
            if seen[bit / 64] & (1 << (bit % 64)) != 0 {
                dup.get_or_insert((frame, track, line));
                return;
            }
            seen[bit / 64] |= 1 << (bit % 64);
            x[(c, 2 * f)] = vx;
            x[(c, 2 * f + 1)] = vy;
        };
        match &self.list {
            Some(list) => list.iter().for_each(|e| put(e.frame, e.track, e.x, e.y, 0)),
            None => {
                let t0 = Instant::now();
                let mut sum = 0u64;
                let r = self.source.scan(&mut |obs| {
                    for o in obs {
                        sum = sum.wrapping_add(fingerprint(o));
                        put(o.frame, o.track, o.x, o.y, o.line);
                    }
                    Ok(())
                });
                self.passes += 1;
                self.read_seconds += t0.elapsed().as_secs_f64();
                self.same_as_first(alien, r?.observations, sum)?;
            }
        }
        match dup {
            Some((frame, track, line)) => Err(self.duplicate(frame, track, line)),
            None => Ok(x),
        }
    }

    /// Whether a later pass read what the first one did: no id the first pass did not see
    /// (`alien`), as many observations (`n`) and the same sum of [`fingerprint`]s (`sum`);
    /// otherwise the error of a source that changed between passes, naming the file.
    fn same_as_first(&self, alien: bool, n: usize, sum: u64) -> Result<()> {
        if !alien && n == self.observations && sum == self.checksum {
            return Ok(());
        }
        let message = format!(
            "the file changed while it was read: {} observations on the first pass, {n} on \
             pass {} (or other ids or values)",
            self.observations, self.passes
        );
        Err(match self.source.path() {
            Some(path) => Error::io(path, std::io::Error::other(message)),
            None => Error::InvalidModel(message),
        })
    }

    /// The error for a (frame, track) pair given twice: one more pass finds both lines
    /// (the list does not keep them).
    fn duplicate(&mut self, frame: u32, track: u32, mut second: u32) -> Error {
        let mut lines = Vec::new();
        let _ = self.source.scan(&mut |obs| {
            for o in obs {
                if o.frame == frame && o.track == track && lines.len() < 2 {
                    lines.push(o.line);
                }
            }
            Ok(())
        });
        let first = lines.first().copied().unwrap_or(0);
        if let Some(&l) = lines.get(1) {
            second = l;
        }
        let message = format!(
            "frame {} track {} is given twice (first on line {first})",
            self.frame_ids[frame as usize], self.track_ids[track as usize]
        );
        match self.source.path() {
            Some(path) => Error::parse(path, second as usize, "track", message),
            None => Error::InvalidModel(message),
        }
    }
}

/// An order-independent fingerprint of one observation (its sum over a pass tells whether a
/// later pass read the same observations): splitmix64 of its ids and values.
fn fingerprint(o: &ScannedObservation) -> u64 {
    let mut z = (u64::from(o.frame) << 32 | u64::from(o.track))
        ^ o.x.to_bits().rotate_left(17)
        ^ o.y.to_bits().rotate_left(41);
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Fits the complete tracks of `source` without holding its measurement matrix: see the
/// module docs for the objective, the method and the cost. Bad input (a repeated
/// frame–track pair, too few complete tracks or frames, a rank below 3) is an `Err`; the
/// partial tracks are set aside and reported.
pub fn factorize<S: ObservationSource + ?Sized>(
    source: &mut S,
    cfg: &StreamConfig,
    observer: &mut dyn Observer,
) -> Result<StreamResult> {
    let camera = cfg.validate()?;
    let start = Instant::now();
    // Pass 1: ids and counts, and the entries while they fit the budget.
    observer.on_event(&Event::StageStarted {
        stage: "stream-count",
    });
    let mut counts: Vec<u32> = Vec::new();
    let mut list = Some(Vec::new());
    let max_list = cfg.memory_budget_bytes / LIST_BYTES;
    let t0 = Instant::now();
    let mut checksum = 0u64;
    let scanned = source.scan(&mut |obs| {
        for o in obs {
            checksum = checksum.wrapping_add(fingerprint(o));
            let p = o.track as usize;
            if p >= counts.len() {
                counts.resize(p + 1, 0);
            }
            counts[p] += 1;
        }
        if list
            .as_ref()
            .is_some_and(|l| l.len() + obs.len() > max_list)
        {
            list = None;
        }
        if let Some(l) = &mut list {
            l.extend(obs.iter().map(|o| Entry {
                frame: o.frame,
                track: o.track,
                x: o.x,
                y: o.y,
            }));
        }
        Ok(())
    })?;
    let first_pass = t0.elapsed().as_secs_f64();
    observer.on_event(&Event::StageFinished {
        stage: "stream-count",
        seconds: first_pass,
    });
    let nf = scanned.frame_ids.len();
    let nt = scanned.track_ids.len();
    counts.resize(nt, 0);
    // rank3's order: `order[i]` is the position of first-appearance index `i`.
    let mut frame_ids = vec![Id::Int(0); nf];
    for (i, id) in scanned.frame_ids.iter().enumerate() {
        frame_ids[scanned.frame_order[i] as usize] = id.clone();
    }
    let mut track_ids = vec![Id::Int(0); nt];
    let mut track_counts = vec![0u32; nt];
    for (i, id) in scanned.track_ids.iter().enumerate() {
        let k = scanned.track_order[i] as usize;
        track_ids[k] = id.clone();
        track_counts[k] = counts[i];
    }
    drop(counts);
    if nf < 2 {
        return Err(Error::TooFew {
            what: "frames for the streaming factorization",
            needed: 2,
            have: nf,
        });
    }
    let rows = 2 * nf;
    // Complete tracks (seen at least F times: a repeated pair is caught when scattered),
    // in rank3's order.
    let complete: Vec<usize> = (0..nt)
        .filter(|&p| track_counts[p] as usize >= nf)
        .collect();
    let set_aside: Vec<SetAside> = (0..nt)
        .filter(|&p| (track_counts[p] as usize) < nf)
        .map(|p| SetAside {
            kind: SetAsideKind::Track,
            id: track_ids[p].clone(),
            reason: format!(
                "seen in {} of the {nf} frames: the streaming factorization takes complete \
                 tracks (the dense and sparse pipelines take partial ones)",
                track_counts[p]
            ),
        })
        .collect();
    if complete.len() < 4 {
        return Err(Error::TooFew {
            what: "complete tracks (seen in every frame) for the streaming factorization",
            needed: 4,
            have: complete.len(),
        });
    }
    let n_complete = complete.len();
    let gram_bytes = rows * rows * 8;
    let block_tracks = (cfg.memory_budget_bytes / (rows * 8)).clamp(1, n_complete);
    let blocks = n_complete.div_ceil(block_tracks);
    let mut by_rank = vec![u32::MAX; nt];
    for (k, &p) in complete.iter().enumerate() {
        by_rank[p] = k as u32;
    }
    let mut reader = Reader {
        source,
        passes: 1,
        read_seconds: first_pass,
        list,
        position: scanned
            .track_order
            .iter()
            .map(|&k| by_rank[k as usize])
            .collect(),
        frame_of: scanned.frame_order.clone(),
        frames: nf,
        observations: scanned.observations,
        checksum,
        frame_ids: scanned.frame_ids.clone(),
        track_ids: scanned.track_ids.clone(),
    };
    drop(by_rank);

    // The Gram passes, one block of tracks each.
    observer.on_event(&Event::StageStarted {
        stage: "stream-gram",
    });
    let t_gram = Instant::now();
    let mut gram_seconds = 0.0;
    let mut gram: Option<Gram> = None;
    let mut kept_block = None;
    for b in 0..blocks {
        let range = b * block_tracks..((b + 1) * block_tracks).min(n_complete);
        let slots: Vec<u32> = (0..n_complete)
            .map(|k| {
                if range.contains(&k) {
                    (k - range.start) as u32
                } else {
                    u32::MAX
                }
            })
            .collect();
        let mut x = reader.fill(&slots, range.len())?;
        let t0 = Instant::now();
        let g = gram.get_or_insert_with(|| Gram::new(x.as_ref()));
        g.shift(&mut x);
        g.add(x.as_ref(), 1.0);
        gram_seconds += t0.elapsed().as_secs_f64();
        if blocks == 1 {
            kept_block = Some(x);
        }
    }
    reader.list = None;
    let mut gram = gram.expect("at least one block");
    observer.on_event(&Event::StageFinished {
        stage: "stream-gram",
        seconds: t_gram.elapsed().as_secs_f64(),
    });

    // Rounds: factor, upgrade, structure, test.
    let mut out = vec![false; n_complete];
    let mut rounds = Vec::new();
    let mut status = if cfg.robust { "max rounds" } else { "no test" }.to_string();
    let mut round = 0;
    loop {
        let fit = fit_round(&gram, camera, &cfg.metric)?;
        let sums = structure_sums(
            &mut reader,
            &fit,
            kept_block.as_ref(),
            &gram.shift,
            n_complete,
        )?;
        let residual: Vec<f64> = sums.iter().map(|s| s.residual(&fit)).collect();
        let in_fit: Vec<usize> = (0..n_complete).filter(|&k| !out[k]).collect();
        let affine_rms = (fit.affine_ss / (rows as f64 * gram.n)).sqrt();
        let metric_rms = (fit.frame_ss.iter().sum::<f64>() / (rows as f64 * gram.n)).sqrt();
        let (sigma, failing) = if cfg.robust {
            let nu = (rows - 3) as f64;
            let mut r: Vec<f64> = in_fit.iter().map(|&k| residual[k]).collect();
            let mid = r.len() / 2;
            let median = *r.select_nth_unstable_by(mid, f64::total_cmp).1;
            let sigma2 = median / crate::robust::chi2_quantile(nu, 0.5);
            let threshold = (sigma2 * crate::robust::chi2_quantile(nu, cfg.track_probability))
                .max(rows as f64 * cfg.min_track_threshold_px.powi(2));
            let failing: Vec<bool> = residual.iter().map(|&r| !(r <= threshold)).collect();
            (sigma2.sqrt(), failing)
        } else {
            (f64::NAN, vec![false; n_complete])
        };
        let taken_out: Vec<usize> = (0..n_complete).filter(|&k| failing[k] && !out[k]).collect();
        let put_back: Vec<usize> = (0..n_complete).filter(|&k| !failing[k] && out[k]).collect();
        rounds.push(StreamRound {
            tracks: in_fit.len(),
            affine_rms_px: affine_rms,
            metric_rms_px: metric_rms,
            sigma_px: sigma,
            failing: failing.iter().filter(|&&f| f).count(),
            taken_out: taken_out.len(),
            put_back: put_back.len(),
        });
        observer.on_event(&Event::Iteration {
            solver: "stream",
            run: 0,
            iteration: round,
            cost: fit.frame_ss.iter().sum(),
            rms: metric_rms,
            lambda: f64::NAN,
        });
        let changed = !taken_out.is_empty() || !put_back.is_empty();
        if cfg.robust && !changed {
            status = "converged".into();
        }
        // Done when the verdict holds, or (still changing after `max_rounds` refits) with
        // the last fit, its outliers those outside it.
        if !cfg.robust || !changed || round == cfg.max_rounds {
            let report = StreamReport {
                passes: reader.passes,
                block_tracks,
                blocks,
                memory_budget_bytes: cfg.memory_budget_bytes,
                gram_bytes,
                rounds,
                status,
                read_seconds: reader.read_seconds,
                gram_seconds,
                seconds: start.elapsed().as_secs_f64(),
            };
            return Ok(finish(Finish {
                camera,
                fit,
                sums,
                residual,
                out,
                complete,
                frame_ids,
                track_ids,
                track_counts,
                set_aside,
                observations: scanned.observations,
                warnings: scanned.warnings,
                n: gram.n,
                report,
            }));
        }
        let remaining = in_fit.len() - taken_out.len() + put_back.len();
        if remaining < 4 {
            return Err(Error::TooFew {
                what: "complete tracks passing the track test",
                needed: 4,
                have: remaining,
            });
        }
        // Downdate / update the Gram by the changed tracks (taken out, then put back), one
        // shifted row each: from the block in memory, or gathered by one pass.
        let changed: Vec<usize> = taken_out.iter().chain(&put_back).copied().collect();
        let x = match &kept_block {
            Some(x) => Mat::from_fn(changed.len(), rows, |c, r| x[(changed[c], r)]),
            None => {
                let mut slots = vec![u32::MAX; n_complete];
                for (c, &k) in changed.iter().enumerate() {
                    slots[k] = c as u32;
                }
                let mut x = reader.fill(&slots, changed.len())?;
                gram.shift(&mut x);
                x
            }
        };
        let t0 = Instant::now();
        let split = taken_out.len();
        gram.add(x.as_ref().subrows(0, split), -1.0);
        gram.add(x.as_ref().subrows(split, put_back.len()), 1.0);
        gram_seconds += t0.elapsed().as_secs_f64();
        for &k in &taken_out {
            out[k] = true;
        }
        for &k in &put_back {
            out[k] = false;
        }
        round += 1;
    }
}

/// One fit of the Gram's tracks: the factor, the upgrade, the metric cameras.
struct RoundFit {
    t: Vec<f64>,
    /// `U₃` (2F×3) and `Σ₃^{1/2}`.
    u3: Mat<f64>,
    sqrt_s: [f64; 3],
    singular_values: Vec<f64>,
    upgrade: MetricUpgrade,
    model: MetricModel,
    mirrored: bool,
    /// The metric cameras as rows (2F×3) and `(MᵀM)⁻¹`.
    m: Mat<f64>,
    ainv: Matrix3<f64>,
    /// Sum of squares of the affine residuals (the eigenvalues past the third).
    affine_ss: f64,
    /// Per frame: the metric model's sum of squared residuals.
    frame_ss: Vec<f64>,
}

fn fit_round(gram: &Gram, camera: CameraModel, metric_cfg: &MetricConfig) -> Result<RoundFit> {
    let (c, t) = gram.centred();
    let rows = c.nrows();
    let nf = rows / 2;
    let (lambda, u3) = leading_eigen(&c)?;
    let singular_values: Vec<f64> = lambda.iter().map(|l| l.sqrt()).collect();
    if !(singular_values[2] > 1e-10 * singular_values[0]) {
        return Err(Error::Degenerate(format!(
            "the centered observation matrix has rank < 3 (singular values {:?}): the points \
             or the motion do not span 3D",
            singular_values.iter().take(4).collect::<Vec<_>>()
        )));
    }
    let sqrt_s = [0, 1, 2].map(|k| singular_values[k].sqrt());
    let m_hat = Mat::from_fn(rows, 3, |r, k| u3[(r, k)] * sqrt_s[k]);
    // The affine residual: every eigenvalue past the third, `tr C − λ₁ − λ₂ − λ₃`.
    let trace: f64 = (0..rows).map(|r| c[(r, r)]).sum();
    let affine_ss = (trace - lambda[..3].iter().sum::<f64>()).max(0.0);
    let upgrade = metric::upgrade(m_hat.as_ref(), camera, metric_cfg)?;
    let mut model = metric::cameras(m_hat.as_ref(), &upgrade.q, &t, camera)?;
    // The gauge of the dense path (first camera's rotation the identity, its scale 1) and
    // the depth-reversal convention; the points' centroid is 0 by construction (`t` is
    // the mean of the fit's tracks).
    crate::refine::fix_gauge(&mut model, camera);
    let mirrored = metric::apply_necker_convention(&mut model);
    let m = Mat::from_fn(rows, 3, |r, k| {
        let f = r / 2;
        model.scales[f] * model.rotations[f].matrix()[(r % 2, k)]
    });
    let mut a = Matrix3::zeros();
    for r in 0..rows {
        for i in 0..3 {
            for j in 0..3 {
                a[(i, j)] += m[(r, i)] * m[(r, j)];
            }
        }
    }
    let ainv = a.try_inverse().ok_or_else(|| Error::Numerical {
        stage: "streaming factorization",
        message: "the metric cameras do not span 3D (MᵀM is singular)".into(),
    })?;
    // Per-frame residuals: diag((I − P) C (I − P)), P = M A⁻¹ Mᵀ.
    let k = &c * &m; // 2F×3: C M
    let mut mtcm = Matrix3::zeros();
    for r in 0..rows {
        for i in 0..3 {
            for j in 0..3 {
                mtcm[(i, j)] += m[(r, i)] * k[(r, j)];
            }
        }
    }
    let inner = ainv * mtcm * ainv;
    let mut frame_ss = vec![0.0; nf];
    for r in 0..rows {
        let mr = Vector3::new(m[(r, 0)], m[(r, 1)], m[(r, 2)]);
        let kr = Vector3::new(k[(r, 0)], k[(r, 1)], k[(r, 2)]);
        let v = c[(r, r)] - 2.0 * mr.dot(&(ainv * kr)) + mr.dot(&(inner * mr));
        frame_ss[r / 2] += v.max(0.0);
    }
    Ok(RoundFit {
        t,
        u3,
        sqrt_s,
        singular_values,
        upgrade,
        model,
        mirrored,
        m,
        ainv,
        affine_ss,
        frame_ss,
    })
}

/// Eigenpairs of the Gram matrix kept: the leading ones (`λ₁…λ₃` to working accuracy,
/// the rest Ritz values, `λ₄` for σ4/σ3).
const RITZ: usize = 12;

/// The [`RITZ`] leading eigenvalues of the symmetric positive semidefinite `c` (descending)
/// and the eigenvectors of the 3 leading ones (`n×3`).
///
/// Block subspace iteration with Rayleigh–Ritz (Golub & Van Loan, *Matrix Computations*,
/// 4th ed., §8.2.4; Saad, *Numerical Methods for Large Eigenvalue Problems*, ch. 5):
/// `Q ← orth(C Q)`, `k = RITZ` columns, until the residuals `‖C v_i − θ_i v_i‖` of the three
/// leading Ritz pairs are below `10⁻¹³ θ₁` and the fourth Ritz value moves by less than
/// `10⁻³` of itself (it is a lower bound of `λ₄`, for the σ4/σ3 diagnostic). The leading three converge at the rate
/// `(λ_{k+1}/λ₃)` per iteration — a few iterations for a rigid scene, whose `λ₃` stands far
/// above the noise's eigenvalues. `O(n² k)` per iteration instead of the full
/// eigendecomposition's `O(n³)` (1.3 s at n = 2000 on this machine); the full one is the
/// fallback for small `n` or when 300 iterations do not converge.
fn leading_eigen(c: &Mat<f64>) -> Result<(Vec<f64>, Mat<f64>)> {
    let n = c.nrows();
    let full = |c: &Mat<f64>| -> Result<(Vec<f64>, Mat<f64>)> {
        let evd = c
            .self_adjoint_eigen(Side::Lower)
            .map_err(|e| Error::Numerical {
                stage: "streaming factorization",
                message: format!("eigendecomposition of the Gram matrix: {e:?}"),
            })?;
        let (ev, u) = (evd.S().column_vector(), evd.U());
        let lambda = (0..n.min(RITZ)).map(|i| ev[n - 1 - i].max(0.0)).collect();
        Ok((lambda, Mat::from_fn(n, 3, |r, k| u[(r, n - 1 - k)])))
    };
    let k = RITZ;
    if n <= 4 * k {
        return full(c);
    }
    // A fixed start (a linear congruential sequence): the result does not depend on a seed.
    let mut state: u64 = 0x9e37_79b9_7f4a_7c15;
    let mut q = Mat::from_fn(n, k, |_, _| {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    });
    let (mut prev4, mut converged) = (f64::INFINITY, None);
    for _ in 0..300 {
        let y = c * &q;
        q = y.qr().compute_thin_Q();
        let cq = c * &q;
        let b = q.transpose() * &cq;
        let evd = b
            .self_adjoint_eigen(Side::Lower)
            .map_err(|e| Error::Numerical {
                stage: "streaming factorization",
                message: format!("Rayleigh–Ritz eigendecomposition: {e:?}"),
            })?;
        let (theta, z) = (evd.S().column_vector(), evd.U());
        // Ritz vectors, largest first: V = Q Z (reversed), and C V = (C Q) Z.
        let order: Vec<usize> = (0..k).rev().collect();
        let zr = Mat::from_fn(k, k, |i, j| z[(i, order[j])]);
        let v = &q * &zr;
        let cv = &cq * &zr;
        let top = theta[order[0]].max(0.0);
        let done = (0..3).all(|j| {
            let th = theta[order[j]];
            let res: f64 = (0..n)
                .map(|r| (cv[(r, j)] - th * v[(r, j)]).powi(2))
                .sum::<f64>()
                .sqrt();
            res <= 1e-13 * top
        });
        q = v;
        // λ₄ (σ4/σ3 only) settles more slowly, at `λ_{k+1}/λ₄` per iteration: it is taken
        // once it moves by less than 10⁻³ of itself.
        let l4 = theta[order[3]].max(0.0);
        let settled = (l4 - prev4).abs() <= 1e-3 * l4;
        prev4 = l4;
        if done {
            let lambda: Vec<f64> = order.iter().map(|&i| theta[i].max(0.0)).collect();
            let result = (lambda, Mat::from_fn(n, 3, |r, j| q[(r, j)]));
            if settled {
                return Ok(result);
            }
            converged = Some(result);
        }
    }
    match converged {
        Some(r) => Ok(r),
        None => full(c),
    }
}

/// Per track: `b = Mᵀ(w − t)`, `â = U₃ᵀ(w − t)`, `‖w − t‖²`.
#[derive(Debug, Clone, Copy, Default)]
struct TrackSums {
    b: [f64; 3],
    a: [f64; 3],
    ss: f64,
}

impl TrackSums {
    /// Adds the centred entry `d` of a row whose rows of `M` and `U₃` are `m` and `u`.
    #[inline]
    fn add_row(&mut self, m: &[f64; 3], u: &[f64; 3], d: f64) {
        for i in 0..3 {
            self.b[i] += m[i] * d;
            self.a[i] += u[i] * d;
        }
        self.ss += d * d;
    }

    /// Adds the centred entry `d = w_r − t_r`.
    fn add(&mut self, fit: &RoundFit, r: usize, d: f64) {
        let (m, u) = (fit.m.row(r), fit.u3.row(r));
        self.add_row(&[m[0], m[1], m[2]], &[u[0], u[1], u[2]], d);
    }

    fn point(&self, fit: &RoundFit) -> Vector3<f64> {
        fit.ainv * Vector3::from(self.b)
    }

    fn residual(&self, fit: &RoundFit) -> f64 {
        (self.ss - Vector3::from(self.b).dot(&self.point(fit))).max(0.0)
    }

    fn affine(&self, fit: &RoundFit) -> [f64; 3] {
        [0, 1, 2].map(|k| self.a[k] / fit.sqrt_s[k])
    }
}

/// The structure sums of every complete track (by position), from the block in memory
/// (shifted by `shift`) or one pass over the source (the sums are linear in the entries:
/// any order).
fn structure_sums<S: ObservationSource + ?Sized>(
    reader: &mut Reader<'_, S>,
    fit: &RoundFit,
    block: Option<&Mat<f64>>,
    shift: &[f64],
    n_complete: usize,
) -> Result<Vec<TrackSums>> {
    let mut sums = vec![TrackSums::default(); n_complete];
    match block {
        Some(x) => {
            use rayon::prelude::*;
            // Per row, the offset of the shifted values from the centred ones.
            let off: Vec<f64> = (0..fit.t.len()).map(|r| fit.t[r] - shift[r]).collect();
            const CHUNK: usize = 512;
            sums.par_chunks_mut(CHUNK)
                .enumerate()
                .for_each(|(i, part)| {
                    let c0 = i * CHUNK;
                    for (r, &o) in off.iter().enumerate() {
                        let col = x.col(r);
                        let (m, u) = (fit.m.row(r), fit.u3.row(r));
                        let (m, u) = ([m[0], m[1], m[2]], [u[0], u[1], u[2]]);
                        for (k, s) in part.iter_mut().enumerate() {
                            s.add_row(&m, &u, col[c0 + k] - o);
                        }
                    }
                });
        }
        None => {
            // (A repeated pair was refused by the Gram pass.)
            let (frame_of, position) = (reader.frame_of.clone(), reader.position.clone());
            let (mut alien, mut sum) = (false, 0u64);
            let n = reader
                .scan(&mut |obs| {
                    for o in obs {
                        sum = sum.wrapping_add(fingerprint(o));
                        let (Some(&k), Some(&f)) = (
                            position.get(o.track as usize),
                            frame_of.get(o.frame as usize),
                        ) else {
                            alien = true;
                            continue;
                        };
                        if k == u32::MAX {
                            continue;
                        }
                        let (s, f) = (&mut sums[k as usize], f as usize);
                        s.add(fit, 2 * f, o.x - fit.t[2 * f]);
                        s.add(fit, 2 * f + 1, o.y - fit.t[2 * f + 1]);
                    }
                    Ok(())
                })?
                .observations;
            reader.same_as_first(alien, n, sum)?;
        }
    }
    Ok(sums)
}

struct Finish {
    camera: CameraModel,
    fit: RoundFit,
    sums: Vec<TrackSums>,
    residual: Vec<f64>,
    out: Vec<bool>,
    complete: Vec<usize>,
    frame_ids: Vec<Id>,
    track_ids: Vec<Id>,
    track_counts: Vec<u32>,
    set_aside: Vec<SetAside>,
    observations: usize,
    warnings: Vec<String>,
    n: f64,
    report: StreamReport,
}

fn finish(f: Finish) -> StreamResult {
    let Finish {
        camera,
        fit,
        sums,
        residual,
        out,
        complete,
        frame_ids,
        track_ids,
        track_counts,
        set_aside,
        observations,
        warnings,
        n,
        report,
    } = f;
    let rows = fit.t.len();
    let mut track_residuals = vec![f64::NAN; track_ids.len()];
    for (k, &p) in complete.iter().enumerate() {
        track_residuals[p] = residual[k];
    }
    let (inl, outl): (Vec<usize>, Vec<usize>) = (0..complete.len()).partition(|&k| !out[k]);
    let s_hat = Mat::from_fn(3, inl.len(), |i, c| sums[inl[c]].affine(&fit)[i]);
    let outlier_s_hat = Mat::from_fn(3, outl.len(), |i, c| sums[outl[c]].affine(&fit)[i]);
    let outlier_points = outl.iter().map(|&k| sums[k].point(&fit)).collect();
    let points = inl.iter().map(|&k| sums[k].point(&fit)).collect();
    let mut model = fit.model;
    model.points = points;
    let metric_rms_px = (fit.frame_ss.iter().sum::<f64>() / (rows as f64 * n)).sqrt();
    let affine_rms_px = (fit.affine_ss / (rows as f64 * n)).sqrt();
    let m_hat = Mat::from_fn(rows, 3, |r, k| fit.u3[(r, k)] * fit.sqrt_s[k]);
    StreamResult {
        camera,
        frame_ids,
        observations,
        model,
        upgrade: fit.upgrade,
        mirrored: fit.mirrored,
        m_hat,
        s_hat,
        t: fit.t,
        outlier_s_hat,
        outlier_points,
        singular_values: fit.singular_values,
        tracks: inl.iter().map(|&k| complete[k]).collect(),
        outliers: outl.iter().map(|&k| complete[k]).collect(),
        track_residuals,
        frame_residuals: fit.frame_ss,
        set_aside,
        track_counts,
        affine_rms_px,
        metric_rms_px,
        report,
        warnings,
        track_ids,
    }
}

impl StreamResult {
    /// The [`Reconstruction`](crate::Reconstruction) of this fit, for the outputs
    /// (`reconstruction.json` with a `stream` report, `completed.txt` = the affine prediction
    /// `M̂Ŝ + t1ᵀ`, `points.ply`). Its `timings` are the report's.
    pub fn into_reconstruction(self) -> crate::Reconstruction {
        use crate::reconstruction::{
            AffinePrediction, FactorizationReport, FrameResult, InputSummary, PointResult,
            StageTime,
        };
        let nf = self.frame_ids.len();
        let rows = 2 * nf;
        let n_in = self.tracks.len();
        let frames = (0..nf)
            .map(|f| {
                let r = self.model.rotations[f].matrix();
                FrameResult {
                    frame: self.frame_ids[f].clone(),
                    rotation: std::array::from_fn(|a| std::array::from_fn(|b| r[(a, b)])),
                    translation: [self.model.translations[f][0], self.model.translations[f][1]],
                    scale: self.model.scales[f],
                    rms_px: (self.frame_residuals[f] / (2 * n_in) as f64).sqrt(),
                    n_observations: n_in,
                }
            })
            .collect();
        let mut points: Vec<(usize, PointResult)> = Vec::with_capacity(n_in + self.outliers.len());
        let point = |p: usize, x: &Vector3<f64>, inlier: bool| PointResult {
            track: self.track_ids[p].clone(),
            xyz: [x[0], x[1], x[2]],
            inlier,
            rms_px: (self.track_residuals[p] / rows as f64).sqrt(),
            n_observations: nf,
        };
        for (k, &p) in self.tracks.iter().enumerate() {
            points.push((p, point(p, &self.model.points[k], true)));
        }
        for (k, &p) in self.outliers.iter().enumerate() {
            points.push((p, point(p, &self.outlier_points[k], false)));
        }
        points.sort_by_key(|(p, _)| *p);
        let points = points.into_iter().map(|(_, r)| r).collect();
        let outlier_prediction = Mat::from_fn(rows, self.outliers.len(), |r, c| {
            self.t[r]
                + (0..3)
                    .map(|k| self.m_hat[(r, k)] * self.outlier_s_hat[(k, c)])
                    .sum::<f64>()
        });
        let outlier_model = MetricModel {
            points: self.outlier_points.clone(),
            ..self.model.clone()
        };
        let rank_ratio = self
            .singular_values
            .get(3)
            .map_or(f64::NAN, |s4| s4 / self.singular_values[2]);
        let mut warnings = self.warnings.clone();
        if !self.set_aside.is_empty() {
            warnings.push(format!(
                "{} of {} tracks set aside as partial: the streaming factorization takes \
                 tracks seen in every frame (without --stream the dense or sparse pipeline \
                 uses the partial ones too)",
                self.set_aside.len(),
                self.track_ids.len()
            ));
        }
        if self.report.status == "max rounds" {
            warnings.push(format!(
                "the track test still changed its verdict after {} refits; the last fit is \
                 reported",
                self.report.rounds.len() - 1
            ));
        }
        crate::Reconstruction {
            camera_model: self.camera,
            model_selection: None,
            frames,
            points,
            rms_px: self.metric_rms_px,
            metric_rms_px: self.metric_rms_px,
            metric_upgrade: self.upgrade.clone(),
            singular_values: self.singular_values.clone(),
            rank_ratio,
            rank_ratio_source: format!(
                "all {n_in} tracks of the fit (streamed: σ4 a Ritz value of the Gram matrix)"
            ),
            factorization: FactorizationReport {
                method: "svd".into(),
                svd_method: "streamed-gram".into(),
                svd_fallback_reason: None,
                rms_px: self.affine_rms_px,
            },
            completion: None,
            robust: None,
            refinement: None,
            projective: None,
            perspective: None,
            input: InputSummary {
                frames: nf,
                tracks: self.track_ids.len(),
                observations: self.observations,
                fill: self.observations as f64 / (nf * self.track_ids.len()) as f64,
                frames_used: nf,
                tracks_used: n_in,
            },
            set_aside: self.set_aside.clone(),
            mirrored: self.mirrored,
            warnings,
            timings: vec![
                StageTime {
                    stage: "stream-read".into(),
                    seconds: self.report.read_seconds,
                },
                StageTime {
                    stage: "stream-gram".into(),
                    seconds: self.report.gram_seconds,
                },
                StageTime {
                    stage: "stream-fit".into(),
                    seconds: (self.report.seconds
                        - self.report.read_seconds
                        - self.report.gram_seconds)
                        .max(0.0),
                },
            ],
            sparse: None,
            stream: Some(self.report.clone()),
            mesh: None,
            aspect_ratio: 1.0,
            aspect_ratio_source: crate::reconstruction::SQUARE_PIXELS.into(),
            affine_structure: self.s_hat.clone(),
            affine_prediction: AffinePrediction {
                m: self.m_hat,
                s: self.s_hat,
                t: self.t,
                aspect: 1.0,
                origin: [0.0, 0.0],
            },
            outlier_prediction,
            outlier_model,
            model: self.model,
            kept_frames: (0..nf).collect(),
            kept_tracks: self.tracks,
            outlier_tracks: self.outliers,
            input_frame_ids: self.frame_ids,
            input_track_ids: self.track_ids,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::observer::NoopObserver;
    use crate::synth::{SynthConfig, generate};

    fn scene(outliers: f64, seed: u64) -> crate::synth::SynthScene {
        generate(&SynthConfig {
            camera: CameraModel::ScaledOrthographic,
            frames: 12,
            points: 90,
            noise: 0.5,
            outliers,
            seed,
            ..Default::default()
        })
        .unwrap()
    }

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("rank3-stream-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn run(source: &mut dyn ObservationSource, budget: usize, robust: bool) -> StreamResult {
        let cfg = StreamConfig {
            memory_budget_bytes: budget,
            robust,
            ..Default::default()
        };
        factorize(source, &cfg, &mut NoopObserver).unwrap()
    }

    /// The affine prediction `M̂ŝ_p + t` of a result, every track of the fit.
    fn prediction(r: &StreamResult) -> Mat<f64> {
        Mat::from_fn(r.t.len(), r.tracks.len(), |row, c| {
            r.t[row]
                + (0..3)
                    .map(|k| r.m_hat[(row, k)] * r.s_hat[(k, c)])
                    .sum::<f64>()
        })
    }

    fn max_abs_diff(a: &Mat<f64>, b: &Mat<f64>) -> f64 {
        assert_eq!((a.nrows(), a.ncols()), (b.nrows(), b.ncols()));
        let mut d: f64 = 0.0;
        for j in 0..a.ncols() {
            for i in 0..a.nrows() {
                d = d.max((a[(i, j)] - b[(i, j)]).abs());
            }
        }
        d
    }

    #[test]
    fn streamed_factor_matches_the_in_memory_one() {
        let s = scene(0.0, 3);
        let t = &s.table;
        let one = run(&mut TableSource(t), 1 << 30, false);
        // One block, built from the first pass's list: the source is read once.
        assert_eq!((one.report.blocks, one.report.passes), (1, 1));
        // Dense: the centred W's truncated SVD and the pipeline without refinement.
        let meas = t.measurements();
        let (rows, n) = (meas.w.nrows(), meas.w.ncols());
        let mean: Vec<f64> = (0..rows)
            .map(|r| (0..n).map(|p| meas.w[(r, p)]).sum::<f64>() / n as f64)
            .collect();
        let centred = Mat::from_fn(rows, n, |r, p| meas.w[(r, p)] - mean[r]);
        let svd = centred.thin_svd().unwrap();
        let sv = svd.S().column_vector();
        for k in 0..6 {
            let rel = (one.singular_values[k] - sv[k]).abs() / sv[0];
            assert!(
                rel < 1e-12,
                "σ{} {} vs {}",
                k + 1,
                one.singular_values[k],
                sv[k]
            );
        }
        let u = svd.U();
        let dense_pred = Mat::from_fn(rows, n, |r, p| {
            mean[r]
                + (0..3)
                    .map(|k| u[(r, k)] * sv[k] * svd.V()[(p, k)])
                    .sum::<f64>()
        });
        // The prediction is gauge-free: equal to rounding (pixel values ~10², errors
        // bounded by the eigenvector accuracy ε·σ1²/(σ3² − σ4²)).
        assert!(max_abs_diff(&prediction(&one), &dense_pred) < 1e-8);
        let config = crate::Config {
            camera: CameraModel::ScaledOrthographic,
            refine: None,
            robust: None,
            ..Default::default()
        };
        let dense = crate::Reconstruction::from_tracks(t, &config).unwrap();
        assert!(
            (dense.metric_rms_px - one.metric_rms_px).abs() < 1e-9 * dense.metric_rms_px,
            "{} vs {}",
            dense.metric_rms_px,
            one.metric_rms_px
        );
        assert!((dense.factorization.rms_px - one.affine_rms_px).abs() < 1e-9);
        // Same gauge and convention: the points agree too.
        for (a, b) in dense.model.points.iter().zip(&one.model.points) {
            assert!((a - b).norm() < 1e-8 * (1.0 + a.norm()), "{a} vs {b}");
        }
        for f in 0..t.n_frames() {
            let (a, b) = (&dense.frames[f], &one.model);
            assert!((a.scale - b.scales[f]).abs() < 1e-9);
            assert!((a.rms_px - (one.frame_residuals[f] / (2 * n) as f64).sqrt()).abs() < 1e-9);
        }
        // Many blocks (several passes over the source) give the same result.
        let bytes_per_track = 2 * t.n_frames() * 8;
        let many = run(&mut TableSource(t), 7 * bytes_per_track, false);
        assert_eq!(many.report.blocks, 90usize.div_ceil(7));
        assert_eq!(many.report.passes, 1 + many.report.blocks + 1);
        assert!(max_abs_diff(&prediction(&one), &prediction(&many)) < 1e-9);
        assert!(
            (one.metric_rms_px - many.metric_rms_px).abs() < 1e-10,
            "{} vs {}",
            one.metric_rms_px,
            many.metric_rms_px
        );
    }

    /// The subspace iteration against the full eigendecomposition, on the Gram matrix of
    /// 40 frames (n = 80, past the full-decomposition cut-off).
    #[test]
    fn leading_eigenpairs_match_the_full_decomposition() {
        let s = generate(&SynthConfig {
            camera: CameraModel::ScaledOrthographic,
            frames: 40,
            points: 300,
            noise: 0.5,
            seed: 2,
            ..Default::default()
        })
        .unwrap();
        let meas = s.table.measurements();
        let (rows, n) = (meas.w.nrows(), meas.w.ncols());
        let mean: Vec<f64> = (0..rows)
            .map(|r| (0..n).map(|p| meas.w[(r, p)]).sum::<f64>() / n as f64)
            .collect();
        let x = Mat::from_fn(rows, n, |r, p| meas.w[(r, p)] - mean[r]);
        let c = &x * x.transpose();
        let (lambda, u3) = leading_eigen(&c).unwrap();
        let evd = c.self_adjoint_eigen(Side::Lower).unwrap();
        let (ev, u) = (evd.S().column_vector(), evd.U());
        for k in 0..3 {
            let truth = ev[rows - 1 - k];
            assert!((lambda[k] - truth).abs() < 1e-12 * ev[rows - 1], "λ{k}");
            // The same eigenvector up to sign.
            let dot: f64 = (0..rows).map(|r| u3[(r, k)] * u[(r, rows - 1 - k)]).sum();
            assert!((dot.abs() - 1.0).abs() < 1e-10, "v{k}: {dot}");
        }
        // λ₄ (for σ4/σ3) is a Ritz value in the noise's bulk: below the true one, close.
        let l4 = ev[rows - 4];
        assert!(
            lambda[3] <= l4 * (1.0 + 1e-12) && lambda[3] > 0.8 * l4,
            "{} vs {l4}",
            lambda[3]
        );
    }

    #[test]
    fn a_csv_file_is_read_in_passes_in_any_order() {
        let s = scene(0.0, 5);
        let dir = scratch("order");
        let path = dir.join("t.csv");
        // Track-major rows, tracks in reverse: neither the file's order nor the ids' order.
        let mut text = String::from("track,frame,x,y\n");
        for p in (0..s.table.n_tracks()).rev() {
            for f in 0..s.table.n_frames() {
                let [x, y] = s.table.get(f, p).unwrap();
                text.push_str(&format!("{p},{f},{x},{y}\n"));
            }
        }
        std::fs::write(&path, text).unwrap();
        let per_track = 2 * 12 * 8;
        let file = run(&mut CsvFile { path: path.clone() }, 20 * per_track, true);
        let table = run(&mut TableSource(&s.table), 1 << 30, true);
        assert_eq!(file.report.blocks, 5);
        assert_eq!(file.track_ids, s.table.track_ids());
        assert_eq!(file.tracks, table.tracks);
        assert!(max_abs_diff(&prediction(&file), &prediction(&table)) < 1e-9);
        for (a, b) in file.model.points.iter().zip(&table.model.points) {
            assert!((a - b).norm() < 1e-9 * (1.0 + a.norm()));
        }
    }

    #[test]
    fn outlier_tracks_are_taken_out_and_partial_tracks_set_aside() {
        let s = scene(0.2, 7);
        let mut t = s.table.clone();
        // Two partial tracks.
        t.unset(0, 3);
        t.unset(5, 4);
        let r = run(&mut TableSource(&t), 1 << 30, true);
        let truth: Vec<usize> = (0..t.n_tracks())
            .filter(|&p| s.outlier_tracks[p].is_some() && p != 3 && p != 4)
            .collect();
        // Every track taken out is an outlier, and (of these 18 outliers of mixed kinds,
        // some close to rigid) at least 90 % are taken out.
        assert!(
            r.outliers.iter().all(|p| truth.contains(p)),
            "{:?}",
            r.outliers
        );
        assert!(r.outliers.len() * 10 >= truth.len() * 9, "{:?}", r.report);
        assert_eq!(r.set_aside.len(), 2);
        assert!(
            r.set_aside[0]
                .reason
                .contains("seen in 11 of the 12 frames")
        );
        assert_eq!(r.report.status, "converged");
        // The fit without them is at the noise level (0.5 px).
        assert!(r.metric_rms_px < 0.6, "{}", r.metric_rms_px);
        let r_outliers = r.outliers.len();
        let rec = r.into_reconstruction();
        assert_eq!(rec.points.len(), t.n_tracks() - 2);
        assert_eq!(rec.points.iter().filter(|p| !p.inlier).count(), r_outliers);
    }

    /// A source whose later passes read another table (a file rewritten during the run).
    struct Changing<'a> {
        first: &'a TrackTable,
        later: &'a TrackTable,
        scans: usize,
    }

    impl ObservationSource for Changing<'_> {
        fn scan(
            &mut self,
            visit: &mut dyn FnMut(&[ScannedObservation]) -> Result<()>,
        ) -> Result<Scanned> {
            self.scans += 1;
            let t = if self.scans == 1 {
                self.first
            } else {
                self.later
            };
            TableSource(t).scan(visit)
        }

        fn path(&self) -> Option<&Path> {
            None
        }
    }

    #[test]
    fn a_source_that_changes_between_passes_is_an_error_not_a_panic() {
        let (a, b) = (scene(0.0, 1), scene(0.0, 2));
        let mut more = generate(&SynthConfig {
            frames: 12,
            points: 120,
            seed: 3,
            ..Default::default()
        })
        .unwrap()
        .table;
        for later in [&b.table, &mut more] {
            let mut source = Changing {
                first: &a.table,
                later,
                scans: 0,
            };
            let cfg = StreamConfig {
                memory_budget_bytes: 10 * 2 * 12 * 8,
                ..Default::default()
            };
            let err = factorize(&mut source, &cfg, &mut NoopObserver).unwrap_err();
            assert!(
                err.to_string().contains("changed while it was read"),
                "{err}"
            );
        }
    }

    #[test]
    fn a_repeated_pair_names_its_lines() {
        let dir = scratch("dup");
        let path = dir.join("d.csv");
        let s = scene(0.0, 1);
        let mut text = crate::table::csv::to_string(&s.table);
        let [x, y] = s.table.get(2, 7).unwrap();
        text.push_str(&format!("2,7,{x},{y}\n"));
        std::fs::write(&path, text).unwrap();
        let err = factorize(
            &mut CsvFile { path },
            &StreamConfig::default(),
            &mut NoopObserver,
        )
        .unwrap_err();
        let msg = err.to_string();
        let line = 2 + 2 * 90 + 7;
        assert!(msg.contains("frame 2 track 7 is given twice"), "{msg}");
        assert!(msg.contains(&format!("first on line {line}")), "{msg}");
        assert!(msg.contains(&format!("{}", 2 + 12 * 90)), "{msg}");
    }
}
