//! The track table: what users have.
//!
//! A [`TrackTable`] holds F frames × N tracks of pixel positions `(x, y)`, a visibility mask,
//! and the frame and track ids exactly as they appeared in the input file. Nothing assumes
//! completeness: tracks enter and leave the frame.
//!
//! Formats (chosen by file extension, documented in `docs/formats.md`): `.csv` long format
//! ([`csv`]), `.txt` dense 2F×N measurement matrix ([`dense`]), `.json` ([`json`]), NumPy
//! `.npy` / `.npz` arrays ([`npy`]), and a folder holding a COLMAP text model's `images.txt`
//! ([`crate::colmap::read_tracks`]). A pair of frames × tracks x and y matrices is read by
//! [`read_xy`].

pub mod csv;
pub mod dense;
pub mod json;
pub mod npy;

use std::fmt;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::{Error, Measurements, Result};

/// A frame or track id as given in the input: an integer or a string.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Id {
    Int(i64),
    Str(String),
}

impl Id {
    /// Parses a text field: an integer when it is one, otherwise the trimmed string.
    pub fn parse(s: &str) -> Id {
        let t = s.trim();
        match t.parse::<i64>() {
            Ok(i) => Id::Int(i),
            Err(_) => Id::Str(t.to_string()),
        }
    }
}

impl fmt::Display for Id {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Id::Int(i) => write!(f, "{i}"),
            Id::Str(s) => f.write_str(s),
        }
    }
}

impl From<usize> for Id {
    fn from(i: usize) -> Self {
        Id::Int(i as i64)
    }
}

/// F frames × N tracks of pixel observations, stored sparsely.
///
/// Storage is one row per frame holding that frame's observations sorted by track index
/// (24 bytes per observation plus 24 per frame), so memory is linear in the observations
/// whatever the fill: a 20 000-frame video whose tracks live for tens of frames costs what
/// its observations cost, not F×N. [`TrackTable::get`] is a binary search in the frame's
/// row; loops over observations use [`TrackTable::frame_row`] and
/// [`TrackTable::by_track`].
#[derive(Debug, Clone, PartialEq)]
pub struct TrackTable {
    frame_ids: Vec<Id>,
    track_ids: Vec<Id>,
    rows: Vec<Vec<Entry>>,
}

/// One observation in a frame's row: the track index and its pixel position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Entry {
    pub track: u32,
    pub x: f64,
    pub y: f64,
}

impl Entry {
    /// The entry at `(w + d) ∘ k` (componentwise): [`TrackTable::transform`]'s map.
    fn moved(self, d: [f64; 2], k: [f64; 2]) -> Entry {
        Entry {
            track: self.track,
            x: (self.x + d[0]) * k[0],
            y: (self.y + d[1]) * k[1],
        }
    }
}

/// Two observations of the same (frame, track) pair given to
/// [`TrackTable::from_observations`]: their positions in its input, and its ids back.
#[derive(Debug)]
pub struct DuplicatePair {
    pub first: usize,
    pub second: usize,
    pub frame_ids: Vec<Id>,
    pub track_ids: Vec<Id>,
}

/// At most 40 characters of a bad field, for error messages (a hostile file's multi-megabyte
/// field is not quoted whole).
pub(crate) fn excerpt(s: &str) -> String {
    const MAX: usize = 40;
    if s.chars().count() <= MAX {
        s.to_string()
    } else {
        let head: String = s.chars().take(MAX).collect();
        format!("{head}… ({} bytes)", s.len())
    }
}

/// A frame's observations, sorted by track index.
#[derive(Debug, Clone, Copy)]
pub struct Row<'a>(&'a [Entry]);

impl<'a> Row<'a> {
    /// The observation of track `p`, if this frame has one (binary search).
    #[inline]
    pub fn get(&self, p: usize) -> Option<[f64; 2]> {
        self.0
            .binary_search_by_key(&(p as u32), |e| e.track)
            .ok()
            .map(|i| [self.0[i].x, self.0[i].y])
    }

    /// Whether track `p` is observed in this frame.
    #[inline]
    pub fn contains(&self, p: usize) -> bool {
        self.0
            .binary_search_by_key(&(p as u32), |e| e.track)
            .is_ok()
    }

    /// The observations, sorted by track.
    pub fn entries(&self) -> &'a [Entry] {
        self.0
    }

    /// Number of observations in the frame.
    pub fn len(&self) -> usize {
        self.0.len()
    }

    /// Whether the frame has no observation.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
}

/// Whether a set-aside item is a track or a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SetAsideKind {
    Track,
    Frame,
}

/// The root of `a` in the union–find forest `parent` (path halving).
pub(crate) fn find_root(parent: &mut [usize], mut a: usize) -> usize {
    while parent[a] != a {
        parent[a] = parent[parent[a]];
        a = parent[a];
    }
    a
}

/// Fewer distinct tracks than this joining a block of frames to the main one is a weak join:
/// the block's frames are set aside ([`TrackTable::set_aside`]).
pub const MIN_SHARED_TRACKS: usize = 4;

/// A track or frame that was not used, with the reason. Nothing is dropped silently.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SetAside {
    pub kind: SetAsideKind,
    pub id: Id,
    pub reason: String,
}

/// A table read from a file, with any warnings the reader raised (e.g. ignored columns).
#[derive(Debug, Clone)]
pub struct LoadedTable {
    pub table: TrackTable,
    pub warnings: Vec<String>,
    pub path: PathBuf,
}

/// Track-table file formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// Long format `frame,track,x,y`.
    Csv,
    /// Dense 2F×N measurement matrix, `nan` for missing.
    DenseTxt,
    /// JSON.
    Json,
    /// NumPy `.npy`: `(F, N, 2)` or `(2F, N)` float array, NaN for missing.
    Npy,
    /// NumPy `.npz`: `tracks` (as `.npy`) or `x` and `y`, optional `frame_ids`, `track_ids`.
    Npz,
}

impl Format {
    /// The format named by a path's extension.
    pub fn from_path(path: &Path) -> Result<Format> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase());
        match ext.as_deref() {
            Some("csv") => Ok(Format::Csv),
            Some("txt") => Ok(Format::DenseTxt),
            Some("json") => Ok(Format::Json),
            Some("npy") => Ok(Format::Npy),
            Some("npz") => Ok(Format::Npz),
            _ => Err(Error::UnknownFormat {
                path: path.to_path_buf(),
            }),
        }
    }
}

/// Reads a track table, choosing the reader by extension (a folder is read as a COLMAP
/// text model: [`crate::colmap::read_tracks`]), and returns its warnings.
pub fn read_tracks(path: impl AsRef<Path>) -> Result<LoadedTable> {
    let path = path.as_ref();
    if path.is_dir() {
        let (table, warnings) = crate::colmap::read_tracks(path)?;
        return Ok(LoadedTable {
            table,
            warnings,
            path: path.to_path_buf(),
        });
    }
    let format = Format::from_path(path)?;
    let (table, warnings) = match format {
        Format::Npy => (npy::read_npy(path)?, Vec::new()),
        Format::Npz => npy::read_npz(path)?,
        // Streamed: the file is never held whole in memory.
        Format::Csv => {
            let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
            csv::parse_reader(file, path)?
        }
        Format::DenseTxt | Format::Json => {
            let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
            if format == Format::Json {
                (json::parse(&text, path)?, Vec::new())
            } else {
                (dense::parse(&text, path)?, Vec::new())
            }
        }
    };
    Ok(LoadedTable {
        table,
        warnings,
        path: path.to_path_buf(),
    })
}

/// Reads a pair of frames × tracks matrices of x and y coordinates (NaN for missing): two
/// text files ([`dense::read_xy`], the layout of the CMU hotel reference tracks
/// `tracked_points_Xs.txt` / `tracked_points_Ys.txt`) or two 2-D `.npy` files
/// ([`npy::read_xy_npy`]). `path` of the result is the x file's.
pub fn read_xy(x_path: impl AsRef<Path>, y_path: impl AsRef<Path>) -> Result<LoadedTable> {
    let (x_path, y_path) = (x_path.as_ref(), y_path.as_ref());
    let is_npy = |p: &Path| {
        p.extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| e.eq_ignore_ascii_case("npy"))
    };
    let table = match (is_npy(x_path), is_npy(y_path)) {
        (true, true) => npy::read_xy_npy(x_path, y_path)?,
        (false, false) => {
            let t = dense::read_xy(x_path, y_path)?;
            if t.n_observed() == 0 {
                return Err(Error::EmptyTable {
                    path: Some(x_path.to_path_buf()),
                    reason: "every entry is nan".into(),
                });
            }
            t
        }
        _ => {
            return Err(Error::InvalidConfig {
                field: "x/y matrices",
                message: format!(
                    "{} and {} must both be .npy arrays or both text matrices",
                    x_path.display(),
                    y_path.display()
                ),
            });
        }
    };
    Ok(LoadedTable {
        table,
        warnings: Vec::new(),
        path: x_path.to_path_buf(),
    })
}

impl TrackTable {
    /// An empty (all missing) table with the given ids.
    pub fn new(frame_ids: Vec<Id>, track_ids: Vec<Id>) -> Self {
        let rows = vec![Vec::new(); frame_ids.len()];
        Self {
            frame_ids,
            track_ids,
            rows,
        }
    }

    /// A table from observations `(frame, track, x, y)` (indices into the id lists), in
    /// any order. Sorts them by frame and track: `O(n log n)` time (`O(n)`, on all cores,
    /// when they are already in that order), memory of the observations. A pair given
    /// twice is returned as a [`DuplicatePair`] (with the ids handed back for the message).
    ///
    /// # Panics
    /// If an index is out of range of its id list (a programming error).
    pub fn from_observations(
        frame_ids: Vec<Id>,
        track_ids: Vec<Id>,
        obs: &[(u32, u32, f64, f64)],
    ) -> std::result::Result<Self, Box<DuplicatePair>> {
        assert!(
            obs.iter()
                .all(|o| (o.0 as usize) < frame_ids.len() && (o.1 as usize) < track_ids.len()),
            "observation index out of range"
        );
        let mut counts = vec![0usize; frame_ids.len()];
        obs.iter().for_each(|o| counts[o.0 as usize] += 1);
        // Already in (frame, track) order, each pair once (a frame-major file, as rank3
        // writes them): the rows are runs of `obs`, copied on all cores.
        if obs.windows(2).all(|w| (w[0].0, w[0].1) < (w[1].0, w[1].1)) {
            use rayon::prelude::*;
            let mut starts = Vec::with_capacity(counts.len() + 1);
            starts.push(0);
            for &c in &counts {
                starts.push(starts.last().copied().unwrap_or(0) + c);
            }
            let rows = (0..frame_ids.len())
                .into_par_iter()
                .with_min_len(16)
                .map(|f| {
                    obs[starts[f]..starts[f + 1]]
                        .iter()
                        .map(|o| Entry {
                            track: o.1,
                            x: o.2,
                            y: o.3,
                        })
                        .collect()
                })
                .collect();
            return Ok(Self {
                frame_ids,
                track_ids,
                rows,
            });
        }
        let mut order: Vec<u32> = (0..obs.len() as u32).collect();
        rayon::slice::ParallelSliceMut::par_sort_unstable_by_key(order.as_mut_slice(), |&i| {
            let o = &obs[i as usize];
            (o.0, o.1, i)
        });
        for w in order.windows(2) {
            let (a, b) = (&obs[w[0] as usize], &obs[w[1] as usize]);
            if a.0 == b.0 && a.1 == b.1 {
                return Err(Box::new(DuplicatePair {
                    first: w[0] as usize,
                    second: w[1] as usize,
                    frame_ids,
                    track_ids,
                }));
            }
        }
        let mut rows: Vec<Vec<Entry>> = counts.iter().map(|&c| Vec::with_capacity(c)).collect();
        for &i in &order {
            let o = &obs[i as usize];
            rows[o.0 as usize].push(Entry {
                track: o.1,
                x: o.2,
                y: o.3,
            });
        }
        Ok(Self {
            frame_ids,
            track_ids,
            rows,
        })
    }

    /// Reads a table by extension (`.csv`, `.txt`, `.json`, `.npy`, `.npz`) or a COLMAP
    /// model folder. Reader warnings are discarded; use [`read_tracks`] to receive them.
    pub fn read(path: impl AsRef<Path>) -> Result<TrackTable> {
        read_tracks(path).map(|l| l.table)
    }

    /// Writes the table in the format named by the extension.
    pub fn write(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        let format = Format::from_path(path)?;
        if matches!(format, Format::Npy | Format::Npz) {
            // A NumPy array is dense: F × N × 2 float64, whatever the fill.
            use crate::budget::{DENSE_TABLE_BYTES, DENSE_TABLE_FACTOR};
            let needed = self
                .n_frames()
                .saturating_mul(self.n_tracks())
                .saturating_mul(16);
            let budget = DENSE_TABLE_BYTES
                .max(DENSE_TABLE_FACTOR.saturating_mul(self.n_observed().saturating_mul(16)));
            if needed > budget {
                return Err(Error::TooLarge {
                    what: format!(
                        "a dense {} × {} × 2 array for {}",
                        self.n_frames(),
                        self.n_tracks(),
                        path.display()
                    ),
                    needed_bytes: needed,
                    budget_bytes: budget,
                    advice: "write the sparse .csv format instead".into(),
                });
            }
        }
        let bytes = match format {
            Format::Csv => csv::to_string(self).into_bytes(),
            Format::DenseTxt => dense::to_string(self).into_bytes(),
            Format::Json => json::to_string(self).into_bytes(),
            Format::Npy => npy::to_npy(self),
            Format::Npz => npy::to_npz(self, path)?,
        };
        crate::atomic::write(path, bytes)
    }

    /// A table from measurements (frame ids `0..F`, track ids `0..N`).
    pub fn from_measurements(meas: &Measurements) -> Self {
        let (f, n) = (meas.n_frames(), meas.n_points());
        let mut t = Self::new(
            (0..f).map(Id::from).collect(),
            (0..n).map(Id::from).collect(),
        );
        for (fi, p) in meas.observed_pairs() {
            t.set(fi, p, meas.w[(2 * fi, p)], meas.w[(2 * fi + 1, p)]);
        }
        t
    }

    /// Number of frames F.
    pub fn n_frames(&self) -> usize {
        self.frame_ids.len()
    }

    /// Number of tracks N.
    pub fn n_tracks(&self) -> usize {
        self.track_ids.len()
    }

    /// Frame ids in table order.
    pub fn frame_ids(&self) -> &[Id] {
        &self.frame_ids
    }

    /// Track ids in table order.
    pub fn track_ids(&self) -> &[Id] {
        &self.track_ids
    }

    /// Frame `f`'s observations, sorted by track.
    #[inline]
    pub fn frame_row(&self, f: usize) -> Row<'_> {
        Row(&self.rows[f])
    }

    /// Per track, its observations as `(frame, x, y)` in frame order (CSR: `ptr` has N + 1
    /// entries, track `p`'s are `obs[ptr[p]..ptr[p + 1]]`). `O(n_obs)`.
    pub fn by_track(&self) -> (Vec<usize>, Vec<(u32, f64, f64)>) {
        let n = self.n_tracks();
        let mut ptr = vec![0usize; n + 1];
        for row in &self.rows {
            for e in row {
                ptr[e.track as usize + 1] += 1;
            }
        }
        for p in 0..n {
            ptr[p + 1] += ptr[p];
        }
        let mut fill = ptr.clone();
        let mut obs = vec![(0u32, 0.0, 0.0); ptr[n]];
        for (f, row) in self.rows.iter().enumerate() {
            for e in row {
                let at = &mut fill[e.track as usize];
                obs[*at] = (f as u32, e.x, e.y);
                *at += 1;
            }
        }
        (ptr, obs)
    }

    /// The observation of track `p` in frame `f`, if any.
    pub fn get(&self, f: usize, p: usize) -> Option<[f64; 2]> {
        self.frame_row(f).get(p)
    }

    /// Sets an observation (coordinates must be finite; the readers check this). Appending
    /// in increasing track order is `O(1)`; otherwise the frame's row is shifted.
    pub fn set(&mut self, f: usize, p: usize, x: f64, y: f64) {
        assert!(p < self.track_ids.len(), "track index out of range");
        let row = &mut self.rows[f];
        let e = Entry {
            track: p as u32,
            x,
            y,
        };
        match row.last() {
            Some(last) if last.track < p as u32 => row.push(e),
            None => row.push(e),
            _ => match row.binary_search_by_key(&(p as u32), |e| e.track) {
                Ok(i) => row[i] = e,
                Err(i) => row.insert(i, e),
            },
        }
    }

    /// Removes an observation.
    pub fn unset(&mut self, f: usize, p: usize) {
        let row = &mut self.rows[f];
        if let Ok(i) = row.binary_search_by_key(&(p as u32), |e| e.track) {
            row.remove(i);
        }
    }

    /// Whether track `p` is observed in frame `f`.
    pub fn is_visible(&self, f: usize, p: usize) -> bool {
        self.frame_row(f).contains(p)
    }

    /// Number of observed (frame, track) pairs.
    pub fn n_observed(&self) -> usize {
        self.rows.iter().map(Vec::len).sum()
    }

    /// Fraction of (frame, track) pairs observed.
    pub fn fill(&self) -> f64 {
        let cells = self.n_frames() as f64 * self.n_tracks() as f64;
        if cells == 0.0 {
            0.0
        } else {
            self.n_observed() as f64 / cells
        }
    }

    /// True when every track is seen in every frame.
    pub fn is_complete(&self) -> bool {
        self.rows.iter().all(|r| r.len() == self.n_tracks())
    }

    /// Number of frames in which track `p` is seen.
    pub fn track_len(&self, p: usize) -> usize {
        (0..self.n_frames())
            .filter(|&f| self.is_visible(f, p))
            .count()
    }

    /// Number of tracks seen in frame `f`.
    pub fn frame_len(&self, f: usize) -> usize {
        self.rows[f].len()
    }

    /// Bytes of the dense 2F×N matrix and mask that [`TrackTable::measurements`] builds.
    pub fn dense_bytes(&self) -> usize {
        self.n_frames()
            .saturating_mul(self.n_tracks())
            .saturating_mul(crate::budget::TABLE_ENTRY_BYTES)
    }

    /// The numeric 2F×N observation matrix and mask the dense solvers use (`O(F·N)`
    /// memory; the pipeline checks [`TrackTable::dense_bytes`] against the budget first).
    pub fn measurements(&self) -> Measurements {
        use rayon::prelude::*;
        let (f, n) = (self.n_frames(), self.n_tracks());
        let mut w = faer::Mat::zeros(2 * f, n);
        let mut visible = vec![false; f * n];
        if n == 0 {
            return Measurements::new(w, visible);
        }
        // Written in tiles of FRAMES frames × TRACKS tracks (a cursor per row, whose entries
        // are in track order), so that consecutive writes to the column-major W land in the
        // same columns instead of 16·F bytes apart. (An entry out of track order is written
        // in a later tile: any order is written whole.) The blocks of FRAMES frames (rows
        // of W, and of the mask) are filled on all cores.
        const FRAMES: usize = 32;
        const TRACKS: usize = 256;
        let mut blocks = Vec::with_capacity(f.div_ceil(FRAMES));
        let mut rest = w.as_mut();
        for f0 in (0..f).step_by(FRAMES) {
            let (top, bottom) = rest.split_at_row_mut(2 * FRAMES.min(f - f0));
            blocks.push((f0, top));
            rest = bottom;
        }
        blocks
            .into_par_iter()
            .zip(visible.par_chunks_mut(FRAMES * n))
            .for_each(|((f0, mut wb), vis)| {
                let rows = &self.rows[f0..(f0 + FRAMES).min(f)];
                let mut cursor = vec![0usize; rows.len()];
                for t0 in (0..n).step_by(TRACKS) {
                    let end = if t0 + TRACKS >= n {
                        usize::MAX
                    } else {
                        t0 + TRACKS
                    };
                    for (k, row) in rows.iter().enumerate() {
                        while let Some(e) = row.get(cursor[k]).filter(|e| (e.track as usize) < end)
                        {
                            let p = e.track as usize;
                            wb[(2 * k, p)] = e.x;
                            wb[(2 * k + 1, p)] = e.y;
                            vis[k * n + p] = true;
                            cursor[k] += 1;
                        }
                    }
                }
            });
        Measurements::new(w, visible)
    }

    /// The sub-table of the given frames and tracks (indices into this table, in order).
    /// `O(n_obs of the frames + N)`.
    pub fn select(&self, frames: &[usize], tracks: &[usize]) -> TrackTable {
        let identity =
            |v: &[usize], n: usize| v.len() == n && v.iter().enumerate().all(|(i, &k)| i == k);
        if identity(frames, self.n_frames()) && identity(tracks, self.n_tracks()) {
            return self.clone();
        }
        let mut new_index = vec![u32::MAX; self.n_tracks()];
        for (k, &p) in tracks.iter().enumerate() {
            new_index[p] = k as u32;
        }
        let rows = frames
            .iter()
            .map(|&f| {
                let mut row: Vec<Entry> = self.rows[f]
                    .iter()
                    .filter(|e| new_index[e.track as usize] != u32::MAX)
                    .map(|e| Entry {
                        track: new_index[e.track as usize],
                        ..*e
                    })
                    .collect();
                row.sort_unstable_by_key(|e| e.track);
                row
            })
            .collect();
        TrackTable {
            frame_ids: frames.iter().map(|&f| self.frame_ids[f].clone()).collect(),
            track_ids: tracks.iter().map(|&p| self.track_ids[p].clone()).collect(),
            rows,
        }
    }

    /// Sets aside, repeatedly until stable, tracks seen in fewer than `min_frames_per_track`
    /// frames and frames with fewer than `min_points_per_frame` tracks (removing one can
    /// starve the other), and the frames of blocks joined to the main block by fewer than
    /// [`MIN_SHARED_TRACKS`] tracks; then — when the remaining observations split into blocks
    /// of frames and tracks that share no observation — every block but the largest.
    ///
    /// Returns the kept table and the list of what was set aside, with reasons, and the
    /// indices (into `self`) of the kept frames and tracks. O(F·N) per round.
    pub fn set_aside(
        &self,
        min_frames_per_track: usize,
        min_points_per_frame: usize,
    ) -> (TrackTable, Vec<SetAside>, Vec<usize>, Vec<usize>) {
        let (kept, out, frames, tracks) =
            self.set_aside_cow(min_frames_per_track, min_points_per_frame);
        (kept.into_owned(), out, frames, tracks)
    }

    /// [`Self::set_aside`] without the copy when nothing is set aside (the table itself,
    /// borrowed).
    pub fn set_aside_cow(
        &self,
        min_frames_per_track: usize,
        min_points_per_frame: usize,
    ) -> (
        std::borrow::Cow<'_, TrackTable>,
        Vec<SetAside>,
        Vec<usize>,
        Vec<usize>,
    ) {
        use std::borrow::Cow;
        let (out, frames, tracks) = self.set_aside_plan(min_frames_per_track, min_points_per_frame);
        let kept = if frames.len() == self.n_frames() && tracks.len() == self.n_tracks() {
            Cow::Borrowed(self)
        } else {
            Cow::Owned(self.select(&frames, &tracks))
        };
        (kept, out, frames, tracks)
    }

    /// [`Self::set_aside`] of a table that is no longer needed: when nothing is set aside it
    /// is returned as it is, without the copy.
    pub fn into_set_aside(
        self,
        min_frames_per_track: usize,
        min_points_per_frame: usize,
    ) -> (TrackTable, Vec<SetAside>, Vec<usize>, Vec<usize>) {
        let (out, frames, tracks) = self.set_aside_plan(min_frames_per_track, min_points_per_frame);
        let kept = if frames.len() == self.n_frames() && tracks.len() == self.n_tracks() {
            self
        } else {
            self.select(&frames, &tracks)
        };
        (kept, out, frames, tracks)
    }

    /// What [`Self::set_aside`] sets aside and the indices of the frames and tracks it keeps.
    fn set_aside_plan(
        &self,
        min_frames_per_track: usize,
        min_points_per_frame: usize,
    ) -> (Vec<SetAside>, Vec<usize>, Vec<usize>) {
        let (nf, nt) = (self.n_frames(), self.n_tracks());
        let mut keep_f = vec![true; nf];
        let mut keep_t = vec![true; nt];
        let mut out = Vec::new();
        // Whether every kept frame sees every kept track (after the last pass).
        let mut complete;
        loop {
            let mut changed = false;
            let mut track_count = vec![0usize; nt];
            for (f, row) in self.rows.iter().enumerate() {
                if keep_f[f] {
                    row.iter().for_each(|e| track_count[e.track as usize] += 1);
                }
            }
            for p in 0..nt {
                if !keep_t[p] {
                    continue;
                }
                let c = track_count[p];
                if c < min_frames_per_track {
                    keep_t[p] = false;
                    changed = true;
                    out.push(SetAside {
                        kind: SetAsideKind::Track,
                        id: self.track_ids[p].clone(),
                        reason: format!(
                            "seen in {c} usable frame(s); at least {min_frames_per_track} needed"
                        ),
                    });
                }
            }
            let n_kept_t = keep_t.iter().filter(|&&k| k).count();
            complete = n_kept_t > 0;
            for f in 0..nf {
                if !keep_f[f] {
                    continue;
                }
                let c = self.rows[f]
                    .iter()
                    .filter(|e| keep_t[e.track as usize])
                    .count();
                complete &= c == n_kept_t;
                if c < min_points_per_frame {
                    keep_f[f] = false;
                    changed = true;
                    out.push(SetAside {
                        kind: SetAsideKind::Frame,
                        id: self.frame_ids[f].clone(),
                        reason: format!(
                            "has {c} usable track(s); at least {min_points_per_frame} needed"
                        ),
                    });
                }
            }
            // Blocks of frames placed by fewer than MIN_SHARED_TRACKS tracks (none when every
            // frame sees every track: then all frames are one block).
            if !changed && !complete {
                changed = self.set_aside_weak_blocks(&mut keep_f, &keep_t, &mut out);
            }
            if !changed {
                break;
            }
        }
        // Connected components of the bipartite frame–track graph.
        let frames: Vec<usize> = (0..nf).filter(|&f| keep_f[f]).collect();
        let tracks: Vec<usize> = (0..nt).filter(|&p| keep_t[p]).collect();
        // (A table where every frame sees every track is one component.)
        let comps = if complete {
            Vec::new()
        } else {
            self.components(&frames, &tracks)
        };
        if comps.len() > 1 {
            let best = comps
                .iter()
                .enumerate()
                .max_by_key(|(i, (cf, ct))| (cf.len() * ct.len(), usize::MAX - i))
                .map(|(i, _)| i)
                .unwrap_or(0);
            let (bf, bt) = (&comps[best].0, &comps[best].1);
            for (i, (cf, ct)) in comps.iter().enumerate() {
                if i == best {
                    continue;
                }
                let reason = format!(
                    "in a block of {} frame(s) and {} track(s) that shares no observation with \
                     the main block ({} frames, {} tracks)",
                    cf.len(),
                    ct.len(),
                    bf.len(),
                    bt.len()
                );
                for &f in cf {
                    keep_f[f] = false;
                    out.push(SetAside {
                        kind: SetAsideKind::Frame,
                        id: self.frame_ids[f].clone(),
                        reason: reason.clone(),
                    });
                }
                for &p in ct {
                    keep_t[p] = false;
                    out.push(SetAside {
                        kind: SetAsideKind::Track,
                        id: self.track_ids[p].clone(),
                        reason: reason.clone(),
                    });
                }
            }
        }
        let frames: Vec<usize> = (0..nf).filter(|&f| keep_f[f]).collect();
        let tracks: Vec<usize> = (0..nt).filter(|&p| keep_t[p]).collect();
        (out, frames, tracks)
    }

    /// Sets aside the frames of every *weakly joined* block: frames that the kept tracks join
    /// to the main block (the one with the most observations) through fewer than
    /// [`MIN_SHARED_TRACKS`] distinct tracks (and fewer than the block's own tracks: a block
    /// of 3 tracks shared whole is joined), but through at least one (blocks sharing none
    /// are the disconnected ones of [`Self::set_aside`]). Two such blocks have their own 3D
    /// frames, related by an affine map of 12 degrees of freedom that 3 points or fewer do
    /// not fix: completing the missing entries across them is a guess (two blocks joined by
    /// one observation gave an RMS of 0.26 px with completed entries ~100 px off). Blocks:
    /// frames are first joined when ≥ `MIN_SHARED_TRACKS` tracks (or all of either frame's)
    /// see both of two frames consecutive along a track, then blocks are merged while as
    /// many distinct tracks see both. Returns whether anything was set aside.
    ///
    /// Cost: `O(n_obs)` per merging round (a hash map of frame and block pairs); a track
    /// touching more than 16 blocks adds its first 16 only.
    fn set_aside_weak_blocks(
        &self,
        keep_f: &mut [bool],
        keep_t: &[bool],
        out: &mut Vec<SetAside>,
    ) -> bool {
        let (nf, nt) = (self.n_frames(), self.n_tracks());
        let mut parent: Vec<usize> = (0..nf).collect();
        fn union(parent: &mut [usize], a: usize, b: usize) -> bool {
            let (a, b) = (find_root(parent, a), find_root(parent, b));
            if a == b {
                return false;
            }
            parent[a.max(b)] = a.min(b);
            true
        }
        // Frames of each kept track, in order.
        let mut frames_of: Vec<Vec<u32>> = vec![Vec::new(); nt];
        for (f, row) in self.rows.iter().enumerate() {
            if keep_f[f] {
                for e in row.iter().filter(|e| keep_t[e.track as usize]) {
                    frames_of[e.track as usize].push(f as u32);
                }
            }
        }
        let mut pairs: std::collections::HashMap<(usize, usize), usize> =
            std::collections::HashMap::new();
        for fr in &frames_of {
            for w in fr.windows(2) {
                *pairs.entry((w[0] as usize, w[1] as usize)).or_insert(0) += 1;
            }
        }
        // A frame with fewer tracks than MIN_SHARED_TRACKS joins with all it has.
        let per_frame: Vec<usize> = self
            .rows
            .iter()
            .map(|row| row.iter().filter(|e| keep_t[e.track as usize]).count())
            .collect();
        for (&(a, b), &c) in &pairs {
            if c >= MIN_SHARED_TRACKS.min(per_frame[a]).min(per_frame[b]) {
                union(&mut parent, a, b);
            }
        }
        // Merge blocks while enough distinct tracks see both.
        let block_pairs = |parent: &mut [usize]| {
            let mut counts: std::collections::HashMap<(usize, usize), usize> =
                std::collections::HashMap::new();
            // Distinct tracks per block, under its root.
            let mut tracks_in = vec![0usize; nf];
            let mut roots: Vec<usize> = Vec::new();
            for fr in &frames_of {
                roots.clear();
                for &f in fr {
                    let r = find_root(parent, f as usize);
                    if !roots.contains(&r) {
                        roots.push(r);
                        if roots.len() == 16 {
                            break;
                        }
                    }
                }
                roots.iter().for_each(|&r| tracks_in[r] += 1);
                for i in 0..roots.len() {
                    for j in i + 1..roots.len() {
                        let k = (roots[i].min(roots[j]), roots[i].max(roots[j]));
                        *counts.entry(k).or_insert(0) += 1;
                    }
                }
            }
            (counts, tracks_in)
        };
        // Enough shared tracks: MIN_SHARED_TRACKS, or every track of the smaller block.
        let enough = |c: usize, a: usize, b: usize, tracks_in: &[usize]| {
            c >= MIN_SHARED_TRACKS.min(tracks_in[a]).min(tracks_in[b])
        };
        // The pair counts of the final blocks (the round that merged nothing).
        let counts = loop {
            let (counts, tracks_in) = block_pairs(&mut parent);
            let mut merged = false;
            for (&(a, b), &c) in &counts {
                if enough(c, a, b, &tracks_in) {
                    merged |= union(&mut parent, a, b);
                }
            }
            if !merged {
                break counts;
            }
        };
        // The main block: the most observations.
        let mut obs = vec![0usize; nf];
        for fr in &frames_of {
            for &f in fr {
                let r = find_root(&mut parent, f as usize);
                obs[r] += 1;
            }
        }
        let Some(main) = (0..nf).filter(|&f| keep_f[f]).max_by_key(|&f| obs[f]) else {
            return false;
        };
        let main = find_root(&mut parent, main);
        let mut changed = false;
        let mut block_frames: std::collections::BTreeMap<usize, Vec<usize>> =
            std::collections::BTreeMap::new();
        for f in (0..nf).filter(|&f| keep_f[f]) {
            let r = find_root(&mut parent, f);
            if r != main {
                block_frames.entry(r).or_default().push(f);
            }
        }
        for (r, fs) in block_frames {
            let shared = counts
                .get(&(r.min(main), r.max(main)))
                .copied()
                .unwrap_or(0);
            if shared == 0 {
                continue;
            }
            let reason = format!(
                "in a block of {} frame(s) joined to the main block by only {shared} track(s): \
                 at least {MIN_SHARED_TRACKS} are needed to place one block's 3D frame in the \
                 other's (an affine map has 12 degrees of freedom)",
                fs.len()
            );
            for f in fs {
                keep_f[f] = false;
                changed = true;
                out.push(SetAside {
                    kind: SetAsideKind::Frame,
                    id: self.frame_ids[f].clone(),
                    reason: reason.clone(),
                });
            }
        }
        changed
    }

    /// Connected components (frames, tracks) of the bipartite graph restricted to the given
    /// frames and tracks, ordered by their first frame; tracks no given frame sees form
    /// their own components, last. Union–find over the observations: `O(n_obs α)`.
    fn components(&self, frames: &[usize], tracks: &[usize]) -> Vec<(Vec<usize>, Vec<usize>)> {
        let (nf, nt) = (self.n_frames(), self.n_tracks());
        let mut in_t = vec![false; nt];
        tracks.iter().for_each(|&p| in_t[p] = true);
        // Nodes: frames 0..nf, tracks nf..nf+nt.
        let mut parent: Vec<usize> = (0..nf + nt).collect();
        let mut seen_t = vec![false; nt];
        for &f in frames {
            for e in &self.rows[f] {
                let p = e.track as usize;
                if in_t[p] {
                    seen_t[p] = true;
                    let (a, b) = (find_root(&mut parent, f), find_root(&mut parent, nf + p));
                    if a != b {
                        // The smaller root (a frame when one is present) represents.
                        let (lo, hi) = if a < b { (a, b) } else { (b, a) };
                        parent[hi] = lo;
                    }
                }
            }
        }
        let mut comp_of_root = vec![usize::MAX; nf + nt];
        let mut comps: Vec<(Vec<usize>, Vec<usize>)> = Vec::new();
        for &f in frames {
            let r = find_root(&mut parent, f);
            if comp_of_root[r] == usize::MAX {
                comp_of_root[r] = comps.len();
                comps.push((Vec::new(), Vec::new()));
            }
            comps[comp_of_root[r]].0.push(f);
        }
        for &p in tracks {
            if seen_t[p] {
                let r = find_root(&mut parent, nf + p);
                comps[comp_of_root[r]].1.push(p);
            }
        }
        for c in &mut comps {
            c.0.sort_unstable();
            c.1.sort_unstable();
        }
        for &p in tracks {
            if !seen_t[p] {
                comps.push((Vec::new(), vec![p]));
            }
        }
        comps
    }

    /// Adds `d` to every observation's coordinates. `O(observations)`, on all cores.
    pub fn translate(&mut self, d: [f64; 2]) {
        self.transform(d, [1.0, 1.0]);
    }

    /// Multiplies every observation's x by `k[0]` and y by `k[1]`. `O(observations)`, on
    /// all cores.
    pub fn scale(&mut self, k: [f64; 2]) {
        self.transform([0.0, 0.0], k);
    }

    /// Every observation `w` replaced by `(w + d) ∘ k` (componentwise), as
    /// [`Self::translate`] then [`Self::scale`] in one pass. `O(observations)`, on all
    /// cores.
    pub fn transform(&mut self, d: [f64; 2], k: [f64; 2]) {
        use rayon::prelude::*;
        self.rows.par_iter_mut().with_min_len(16).for_each(|row| {
            for e in row {
                *e = e.moved(d, k);
            }
        });
    }

    /// A copy with every observation `w` replaced by `(w + d) ∘ k`: [`Self::transform`] of
    /// a clone, in one pass. `O(observations)`, on all cores.
    pub fn transformed(&self, d: [f64; 2], k: [f64; 2]) -> TrackTable {
        use rayon::prelude::*;
        let rows = self
            .rows
            .par_iter()
            .with_min_len(16)
            .map(|row| row.iter().map(|e| e.moved(d, k)).collect())
            .collect();
        TrackTable {
            frame_ids: self.frame_ids.clone(),
            track_ids: self.track_ids.clone(),
            rows,
        }
    }

    /// A copy with frames and tracks reordered (`frames[k]` is the old index of new frame k).
    pub fn permuted(&self, frames: &[usize], tracks: &[usize]) -> TrackTable {
        self.select(frames, tracks)
    }
}

/// Sorts ids the way rank3 orders frames and tracks read from long formats: ascending when
/// every id is an integer, otherwise in order of first appearance (already the input order).
pub(crate) fn order_ids(ids: &mut [Id]) {
    if ids.iter().all(|i| matches!(i, Id::Int(_))) {
        ids.sort();
    }
}

/// Test helper: the line, field and message of an [`Error::Parse`] (panics on any other).
#[cfg(test)]
pub(crate) fn parse_error_parts(e: Error) -> (usize, String, String) {
    match e {
        Error::Parse {
            line,
            field,
            message,
            ..
        } => (line, field, message),
        e => panic!("unexpected {e}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(vis: &[&[u8]]) -> TrackTable {
        let f = vis.len();
        let n = vis[0].len();
        let mut t = TrackTable::new(
            (0..f).map(Id::from).collect(),
            (0..n).map(Id::from).collect(),
        );
        for (fi, row) in vis.iter().enumerate() {
            for (p, &v) in row.iter().enumerate() {
                if v == 1 {
                    t.set(fi, p, (fi * 10 + p) as f64, p as f64);
                }
            }
        }
        t
    }

    /// The tiled writer of `measurements` puts every observation where the plain
    /// frame-by-frame writer did, on shapes that are not multiples of its tiles, and
    /// `Measurements::select` of it equals the table's own selection.
    #[test]
    fn measurements_are_written_tile_by_tile_exactly() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        for &(f, n) in &[(1usize, 1usize), (33, 257), (70, 600), (5, 1000)] {
            let mut t = TrackTable::new(
                (0..f).map(Id::from).collect(),
                (0..n).map(Id::from).collect(),
            );
            for fi in 0..f {
                for p in 0..n {
                    if rng.random_range(0.0..1.0) < 0.7 {
                        t.set(
                            fi,
                            p,
                            rng.random_range(-9.0..9.0),
                            rng.random_range(-9.0..9.0),
                        );
                    }
                }
            }
            let m = t.measurements();
            for fi in 0..f {
                let row = t.frame_row(fi);
                let mut seen = vec![false; n];
                for e in row.entries() {
                    let p = e.track as usize;
                    seen[p] = true;
                    assert_eq!((m.w[(2 * fi, p)], m.w[(2 * fi + 1, p)]), (e.x, e.y));
                }
                for p in 0..n {
                    assert_eq!(m.is_visible(fi, p), seen[p]);
                    if !seen[p] {
                        assert_eq!((m.w[(2 * fi, p)], m.w[(2 * fi + 1, p)]), (0.0, 0.0));
                    }
                }
            }
            let frames: Vec<usize> = (0..f).filter(|k| k % 3 != 1).collect();
            let tracks: Vec<usize> = (0..n).filter(|k| k % 4 != 2).collect();
            let a = m.select(&frames, &tracks);
            let b = t.select(&frames, &tracks).measurements();
            assert_eq!(a.visible, b.visible);
            assert_eq!(a.w, b.w);
        }
    }

    #[test]
    fn set_aside_short_tracks_and_sparse_frames_cascades() {
        // Track 4 is seen once; frame 3 has only tracks 0,1 (< 3) after that.
        let t = table(&[
            &[1, 1, 1, 1, 0],
            &[1, 1, 1, 1, 0],
            &[1, 1, 1, 1, 0],
            &[1, 1, 0, 0, 1],
        ]);
        let (kept, out, frames, tracks) = t.set_aside(2, 3);
        assert_eq!(frames, vec![0, 1, 2]);
        assert_eq!(tracks, vec![0, 1, 2, 3]);
        assert!(kept.is_complete());
        assert_eq!(out.len(), 2);
        assert_eq!(out[0].kind, SetAsideKind::Track);
        assert_eq!(out[0].id, Id::Int(4));
        assert_eq!(out[1].kind, SetAsideKind::Frame);
        assert_eq!(out[1].id, Id::Int(3));
    }

    /// A table whose kept part is complete keeps everything, including after a first pass
    /// that set a track aside (the completeness shortcut skips the block tests only then);
    /// `into_set_aside` returns such a table without a copy and agrees with `set_aside`.
    #[test]
    fn set_aside_complete_and_into_set_aside() {
        let t = table(&[&[1, 1, 1, 1], &[1, 1, 1, 1], &[1, 1, 1, 1]]);
        let (kept, out, frames, tracks) = t.set_aside(2, 3);
        assert!(out.is_empty());
        assert_eq!((frames, tracks), (vec![0, 1, 2], vec![0, 1, 2, 3]));
        assert_eq!(kept, t);
        let (owned, out2, _, _) = t.clone().into_set_aside(2, 3);
        assert!(out2.is_empty());
        assert_eq!(owned, t);
        // Complete once track 4 (seen once) is set aside.
        let t = table(&[&[1, 1, 1, 1, 0], &[1, 1, 1, 1, 0], &[1, 1, 1, 1, 1]]);
        let a = t.set_aside(2, 3);
        let b = t.clone().into_set_aside(2, 3);
        assert_eq!(a.2, vec![0, 1, 2]);
        assert_eq!(a.3, vec![0, 1, 2, 3]);
        assert_eq!((a.0.clone(), a.2.clone(), a.3.clone()), (b.0, b.2, b.3));
        assert_eq!(a.1.len(), 1);
        assert!(a.0.is_complete());
    }

    #[test]
    fn set_aside_disconnected_blocks() {
        let t = table(&[
            &[1, 1, 1, 0, 0, 0],
            &[1, 1, 1, 0, 0, 0],
            &[1, 1, 1, 0, 0, 0],
            &[0, 0, 0, 1, 1, 1],
            &[0, 0, 0, 1, 1, 1],
        ]);
        let (kept, out, frames, tracks) = t.set_aside(2, 3);
        assert_eq!(frames, vec![0, 1, 2]);
        assert_eq!(tracks, vec![0, 1, 2]);
        assert_eq!(kept.n_observed(), 9);
        assert_eq!(out.len(), 5);
        assert!(
            out.iter()
                .all(|s| s.reason.contains("shares no observation"))
        );
    }

    /// Two blocks of frames joined by k tracks: below `MIN_SHARED_TRACKS` the smaller
    /// block's frames are set aside as weakly joined; at it, both are kept.
    #[test]
    fn set_aside_weakly_joined_blocks() {
        let blocks = |k: usize| {
            // Frames 0..4 see tracks 0..8, frames 4..7 see tracks 8..14; tracks 0..k are
            // also seen in frame 4.
            let mut m = vec![vec![0u8; 14]; 7];
            for (f, row) in m.iter_mut().enumerate() {
                let tracks = if f < 4 { 0..8 } else { 8..14 };
                tracks.for_each(|p| row[p] = 1);
            }
            (0..k).for_each(|p| m[4][p] = 1);
            let rows: Vec<&[u8]> = m.iter().map(|r| r.as_slice()).collect();
            table(&rows).set_aside(2, 3)
        };
        let (_, out, frames, _) = blocks(1);
        assert_eq!(frames, vec![0, 1, 2, 3]);
        assert!(
            out.iter()
                .filter(|s| s.kind == SetAsideKind::Frame)
                .all(|s| s
                    .reason
                    .contains("joined to the main block by only 1 track")),
            "{out:?}"
        );
        let (_, out, frames, _) = blocks(MIN_SHARED_TRACKS);
        assert_eq!(frames, (0..7).collect::<Vec<_>>(), "{out:?}");
    }

    #[test]
    fn sparse_rows_by_track_select_and_duplicates() {
        let obs = [(1u32, 2u32, 5.0, 6.0), (0, 2, 1.0, 2.0), (1, 0, 3.0, 4.0)];
        let ids = |n: usize| (0..n).map(Id::from).collect::<Vec<_>>();
        let t = TrackTable::from_observations(ids(2), ids(3), &obs).unwrap();
        assert_eq!(t.n_observed(), 3);
        assert_eq!(t.get(1, 2), Some([5.0, 6.0]));
        assert_eq!(t.get(0, 0), None);
        assert_eq!(t.frame_row(1).len(), 2);
        let (ptr, by) = t.by_track();
        assert_eq!(ptr, vec![0, 1, 1, 3]);
        assert_eq!(by[1..], [(0, 1.0, 2.0), (1, 5.0, 6.0)]);
        // Select reorders tracks; rows stay sorted.
        let s = t.select(&[1], &[2, 0]);
        assert_eq!(s.get(0, 0), Some([5.0, 6.0]));
        assert_eq!(s.get(0, 1), Some([3.0, 4.0]));
        let d =
            TrackTable::from_observations(ids(2), ids(3), &[(0, 1, 0.0, 0.0), (0, 1, 1.0, 1.0)])
                .unwrap_err();
        assert_eq!((d.first.min(d.second), d.first.max(d.second)), (0, 1));
        // Out-of-order sets and unsets keep the rows sorted.
        let mut u = TrackTable::new(ids(1), ids(4));
        for p in [3, 1, 2, 0] {
            u.set(0, p, p as f64, 0.0);
        }
        u.unset(0, 2);
        let tracks: Vec<u32> = u.frame_row(0).entries().iter().map(|e| e.track).collect();
        assert_eq!(tracks, vec![0, 1, 3]);
    }

    #[test]
    fn measurements_layout() {
        let t = table(&[&[1, 0], &[1, 1]]);
        let m = t.measurements();
        assert_eq!(m.w.nrows(), 4);
        assert_eq!(m.w[(2, 1)], 11.0);
        assert_eq!(m.w[(3, 1)], 1.0);
        assert!(!m.is_visible(0, 1));
        assert_eq!(TrackTable::from_measurements(&m), t);
    }
}
