//! The track table: what users have.
//!
//! A [`TrackTable`] holds F frames × N tracks of pixel positions `(x, y)`, a visibility mask,
//! and the frame and track ids exactly as they appeared in the input file. Nothing assumes
//! completeness: tracks enter and leave the frame.
//!
//! Formats (chosen by file extension, documented in `docs/formats.md`): `.csv` long format
//! ([`csv`]), `.txt` dense 2F×N measurement matrix ([`dense`]), `.json` ([`json`]).

pub mod csv;
pub mod dense;
pub mod json;

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

/// F frames × N tracks of pixel observations with a visibility mask.
///
/// Storage is frame-major: entry `(f, p)` lives at index `f * N + p`. Unobserved entries
/// hold NaN coordinates and `visible == false`.
#[derive(Debug, Clone)]
pub struct TrackTable {
    frame_ids: Vec<Id>,
    track_ids: Vec<Id>,
    x: Vec<f64>,
    y: Vec<f64>,
    visible: Vec<bool>,
}

impl PartialEq for TrackTable {
    /// Same ids in the same order, same visibility, same coordinates where observed.
    fn eq(&self, other: &Self) -> bool {
        self.frame_ids == other.frame_ids
            && self.track_ids == other.track_ids
            && self.visible == other.visible
            && (0..self.visible.len())
                .filter(|&i| self.visible[i])
                .all(|i| self.x[i] == other.x[i] && self.y[i] == other.y[i])
    }
}

/// Whether a set-aside item is a track or a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SetAsideKind {
    Track,
    Frame,
}

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
            _ => Err(Error::UnknownFormat {
                path: path.to_path_buf(),
            }),
        }
    }
}

/// Reads a track table, choosing the reader by extension, and returns its warnings.
pub fn read_tracks(path: impl AsRef<Path>) -> Result<LoadedTable> {
    let path = path.as_ref();
    let format = Format::from_path(path)?;
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let (table, warnings) = match format {
        Format::Csv => csv::parse(&text, path)?,
        Format::DenseTxt => (dense::parse(&text, path)?, Vec::new()),
        Format::Json => (json::parse(&text, path)?, Vec::new()),
    };
    Ok(LoadedTable {
        table,
        warnings,
        path: path.to_path_buf(),
    })
}

impl TrackTable {
    /// An empty (all missing) table with the given ids.
    pub fn new(frame_ids: Vec<Id>, track_ids: Vec<Id>) -> Self {
        let n = frame_ids.len() * track_ids.len();
        Self {
            frame_ids,
            track_ids,
            x: vec![f64::NAN; n],
            y: vec![f64::NAN; n],
            visible: vec![false; n],
        }
    }

    /// Reads a table by extension (`.csv`, `.txt`, `.json`). Reader warnings are discarded;
    /// use [`read_tracks`] to receive them.
    pub fn read(path: impl AsRef<Path>) -> Result<TrackTable> {
        read_tracks(path).map(|l| l.table)
    }

    /// Writes the table in the format named by the extension.
    pub fn write(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        let text = match Format::from_path(path)? {
            Format::Csv => csv::to_string(self),
            Format::DenseTxt => dense::to_string(self),
            Format::Json => json::to_string(self),
        };
        crate::atomic::write(path, text)
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

    #[inline]
    fn idx(&self, f: usize, p: usize) -> usize {
        f * self.track_ids.len() + p
    }

    /// Frame `f`'s row: x, y and visibility of every track (x and y are meaningless where
    /// not visible). For loops over whole frames without a bounds check per entry.
    #[cfg_attr(not(feature = "rerun"), allow(dead_code))]
    pub(crate) fn frame_row(&self, f: usize) -> (&[f64], &[f64], &[bool]) {
        let r = f * self.track_ids.len()..(f + 1) * self.track_ids.len();
        (&self.x[r.clone()], &self.y[r.clone()], &self.visible[r])
    }

    /// The observation of track `p` in frame `f`, if any.
    pub fn get(&self, f: usize, p: usize) -> Option<[f64; 2]> {
        let i = self.idx(f, p);
        self.visible[i].then(|| [self.x[i], self.y[i]])
    }

    /// Sets an observation (coordinates must be finite; the readers check this).
    pub fn set(&mut self, f: usize, p: usize, x: f64, y: f64) {
        let i = self.idx(f, p);
        self.x[i] = x;
        self.y[i] = y;
        self.visible[i] = true;
    }

    /// Removes an observation.
    pub fn unset(&mut self, f: usize, p: usize) {
        let i = self.idx(f, p);
        self.x[i] = f64::NAN;
        self.y[i] = f64::NAN;
        self.visible[i] = false;
    }

    /// Whether track `p` is observed in frame `f`.
    pub fn is_visible(&self, f: usize, p: usize) -> bool {
        self.visible[self.idx(f, p)]
    }

    /// Number of observed (frame, track) pairs.
    pub fn n_observed(&self) -> usize {
        self.visible.iter().filter(|&&v| v).count()
    }

    /// Fraction of (frame, track) pairs observed.
    pub fn fill(&self) -> f64 {
        if self.visible.is_empty() {
            0.0
        } else {
            self.n_observed() as f64 / self.visible.len() as f64
        }
    }

    /// True when every track is seen in every frame.
    pub fn is_complete(&self) -> bool {
        self.visible.iter().all(|&v| v)
    }

    /// Number of frames in which track `p` is seen.
    pub fn track_len(&self, p: usize) -> usize {
        (0..self.n_frames())
            .filter(|&f| self.is_visible(f, p))
            .count()
    }

    /// Number of tracks seen in frame `f`.
    pub fn frame_len(&self, f: usize) -> usize {
        (0..self.n_tracks())
            .filter(|&p| self.is_visible(f, p))
            .count()
    }

    /// The numeric 2F×N observation matrix and mask the solvers use.
    pub fn measurements(&self) -> Measurements {
        let (f, n) = (self.n_frames(), self.n_tracks());
        let w = faer::Mat::from_fn(2 * f, n, |r, p| {
            let i = self.idx(r / 2, p);
            if !self.visible[i] {
                0.0
            } else if r % 2 == 0 {
                self.x[i]
            } else {
                self.y[i]
            }
        });
        Measurements::new(w, self.visible.clone())
    }

    /// The sub-table of the given frames and tracks (indices into this table, in order).
    pub fn select(&self, frames: &[usize], tracks: &[usize]) -> TrackTable {
        let mut t = TrackTable::new(
            frames.iter().map(|&f| self.frame_ids[f].clone()).collect(),
            tracks.iter().map(|&p| self.track_ids[p].clone()).collect(),
        );
        for (nf, &f) in frames.iter().enumerate() {
            for (np, &p) in tracks.iter().enumerate() {
                if let Some([x, y]) = self.get(f, p) {
                    t.set(nf, np, x, y);
                }
            }
        }
        t
    }

    /// Sets aside, repeatedly until stable, tracks seen in fewer than `min_frames_per_track`
    /// frames and frames with fewer than `min_points_per_frame` tracks (removing one can
    /// starve the other), then — when the remaining observations split into blocks of
    /// frames and tracks that share no observation — every block but the largest.
    ///
    /// Returns the kept table and the list of what was set aside, with reasons, and the
    /// indices (into `self`) of the kept frames and tracks. O(F·N) per round.
    pub fn set_aside(
        &self,
        min_frames_per_track: usize,
        min_points_per_frame: usize,
    ) -> (TrackTable, Vec<SetAside>, Vec<usize>, Vec<usize>) {
        let (nf, nt) = (self.n_frames(), self.n_tracks());
        let mut keep_f = vec![true; nf];
        let mut keep_t = vec![true; nt];
        let mut out = Vec::new();
        loop {
            let mut changed = false;
            for p in 0..nt {
                if !keep_t[p] {
                    continue;
                }
                let c = (0..nf)
                    .filter(|&f| keep_f[f] && self.is_visible(f, p))
                    .count();
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
            for f in 0..nf {
                if !keep_f[f] {
                    continue;
                }
                let c = (0..nt)
                    .filter(|&p| keep_t[p] && self.is_visible(f, p))
                    .count();
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
            if !changed {
                break;
            }
        }
        // Connected components of the bipartite frame–track graph.
        let frames: Vec<usize> = (0..nf).filter(|&f| keep_f[f]).collect();
        let tracks: Vec<usize> = (0..nt).filter(|&p| keep_t[p]).collect();
        let comps = self.components(&frames, &tracks);
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
        (self.select(&frames, &tracks), out, frames, tracks)
    }

    /// Connected components (frames, tracks) of the bipartite graph restricted to the given
    /// frames and tracks; isolated frames/tracks form their own components.
    fn components(&self, frames: &[usize], tracks: &[usize]) -> Vec<(Vec<usize>, Vec<usize>)> {
        let (nf, nt) = (self.n_frames(), self.n_tracks());
        let mut in_f = vec![false; nf];
        let mut in_t = vec![false; nt];
        frames.iter().for_each(|&f| in_f[f] = true);
        tracks.iter().for_each(|&p| in_t[p] = true);
        let mut seen_f = vec![false; nf];
        let mut seen_t = vec![false; nt];
        let mut comps = Vec::new();
        for &start in frames {
            if seen_f[start] {
                continue;
            }
            let (mut cf, mut ct) = (Vec::new(), Vec::new());
            let mut stack_f = vec![start];
            seen_f[start] = true;
            while let Some(f) = stack_f.pop() {
                cf.push(f);
                for p in 0..nt {
                    if in_t[p] && !seen_t[p] && self.is_visible(f, p) {
                        seen_t[p] = true;
                        ct.push(p);
                        for g in 0..nf {
                            if in_f[g] && !seen_f[g] && self.is_visible(g, p) {
                                seen_f[g] = true;
                                stack_f.push(g);
                            }
                        }
                    }
                }
            }
            cf.sort_unstable();
            ct.sort_unstable();
            comps.push((cf, ct));
        }
        for &p in tracks {
            if !seen_t[p] {
                comps.push((Vec::new(), vec![p]));
            }
        }
        comps
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
