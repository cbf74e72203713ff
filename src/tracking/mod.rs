//! From frames to tracks: Shi–Tomasi corners tracked by pyramidal Lucas–Kanade (KLT).
//!
//! ```text
//! FrameSource (folder of PNG/JPEG, or video via ffmpeg) ─→ GrayImage per frame
//!   ─→ Pyramid (smoothing + ×½ subsampling, Scharr gradients per level)
//!   ─→ frame 0: detect_corners + sub-pixel refinement (or the caller's initial points)
//!   ─→ frame t→t+1: track_points (Bouguet's pyramidal LK + validity checks)
//!   ─→ re-detection in empty regions when too few tracks are alive
//!   ─→ TrackTable (frames × tracks, partial)
//! ```
//!
//! A track that fails a check in frame `t+1` ends at frame `t`: it is missing afterwards and
//! never restarted under the same id. New tracks (re-detection) start at the frame where they
//! are detected, so the table is partial in general.
//!
//! Ids: frame ids are the image file stems (folder input, parsed with
//! [`Id::parse`](crate::Id::parse)) or the 0-based frame indices (video). Track ids are
//! integers: detection order (0, 1, …), or, with initial points, the 0-based line number of
//! each point in the points file.
//!
//! The module depends on nothing in the crate but [`crate::Error`] and the
//! [`TrackTable`] it produces.
//!
//! Complexity per frame: O(W·H) for the pyramid (and detection when it runs), plus
//! O(D·r²·I) to refine D new corners to sub-pixel positions ([`subpixel`]), plus
//! O(P·L·w²·K) for tracking P points over L levels with a w×w window and K iterations
//! (×2 with the forward–backward check), parallel over points.

// Negated comparisons are deliberate: they also reject NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod detect;
pub mod frames;
pub mod klt;
pub mod pyramid;
pub mod scene3d;
pub mod subpixel;
pub mod synthetic;

use std::collections::BTreeMap;
use std::path::Path;

pub use detect::{Corner, DetectConfig, detect_corners, detect_corners_filtered};
pub use frames::{FrameSource, GrayImage};
pub use klt::{Failure, KltConfig, track_points};
pub use pyramid::Pyramid;
pub use subpixel::{SubpixelConfig, SubpixelMethod, refine_corners};

use crate::table::{Id, TrackTable};
use crate::{Error, Result};

/// Tracker settings; every field has a documented default.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TrackerConfig {
    /// Corner detection (also caps the number of live tracks: `detect.max_features`).
    pub detect: DetectConfig,
    /// Lucas–Kanade tracking and validity checks.
    pub klt: KltConfig,
    /// Sub-pixel refinement of detected corners before they are tracked (Förstner's operator,
    /// as OpenCV's `cornerSubPix`; [`subpixel`]); `None` starts tracks at whole pixels.
    /// Initial points given by the caller are never moved. Default `Some` of
    /// [`SubpixelConfig::default`].
    #[serde(default = "default_subpixel")]
    pub subpixel: Option<SubpixelConfig>,
    /// Detect new corners when tracks die (tracker started by detection). Default `true`.
    pub redetect: bool,
    /// Detect new corners when tracks die in a tracker started from initial points
    /// ([`Tracker::with_points`]); new ids continue after the last point's. Default `false`.
    pub redetect_with_points: bool,
    /// Re-detect when fewer than `redetect_below · max_features` tracks are alive.
    /// Default 0.9.
    pub redetect_below: f32,
    /// New corners must be at least this far from every live track, pixels; `None` (default)
    /// uses `detect.min_distance`.
    pub redetect_radius: Option<f32>,
    /// Tracks observed in fewer frames are dropped from the output table (detected tracks
    /// only; initial-point tracks are always kept so ids match lines). Default 2.
    pub min_track_len: usize,
}

impl Default for TrackerConfig {
    fn default() -> Self {
        Self {
            detect: DetectConfig::default(),
            klt: KltConfig::default(),
            subpixel: default_subpixel(),
            redetect: true,
            redetect_with_points: false,
            redetect_below: 0.9,
            redetect_radius: None,
            min_track_len: 2,
        }
    }
}

impl TrackerConfig {
    /// Checks every field's range.
    pub fn validate(&self) -> Result<()> {
        self.detect.validate()?;
        self.klt.validate()?;
        if let Some(s) = &self.subpixel {
            s.validate()?;
        }
        if !(0.0..=1.0).contains(&self.redetect_below) {
            return Err(Error::InvalidConfig {
                field: "redetect_below",
                message: format!("must be in [0, 1], got {}", self.redetect_below),
            });
        }
        Ok(())
    }
}

fn default_subpixel() -> Option<SubpixelConfig> {
    Some(SubpixelConfig::default())
}

/// Counts of what happened in one frame.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FrameStats {
    /// 0-based frame index.
    pub frame: usize,
    /// Tracks continued into this frame.
    pub tracked: usize,
    /// Tracks lost per reason.
    pub lost_out_of_image: usize,
    pub lost_low_texture: usize,
    pub lost_residual: usize,
    pub lost_forward_backward: usize,
    /// New tracks started in this frame.
    pub new: usize,
    /// Live tracks after this frame.
    pub alive: usize,
}

/// Summary of a whole run.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TrackSummary {
    pub frames: usize,
    /// Tracks started (before dropping short ones).
    pub started: usize,
    /// Tracks in the output table.
    pub kept: usize,
    /// Tracks alive in the last frame.
    pub alive_at_end: usize,
    /// Lost tracks per reason over the whole run.
    pub lost: BTreeMap<String, usize>,
    /// Wall-clock seconds spent in [`Tracker::push`] (pyramids, detection, tracking; not
    /// decoding).
    pub seconds: f64,
}

struct TrackState {
    id: i64,
    /// (frame index, x, y) in order.
    obs: Vec<(u32, f32, f32)>,
    alive: bool,
}

/// Incremental tracker: feed frames with [`Tracker::push`], then [`Tracker::finish`].
pub struct Tracker {
    cfg: TrackerConfig,
    frame_ids: Vec<Id>,
    prev: Option<Pyramid>,
    /// The pyramid of two frames ago, rebuilt in place for the next frame.
    spare: Option<Pyramid>,
    tracks: Vec<TrackState>,
    init_points: Option<Vec<[f32; 2]>>,
    /// Number of initial points (tracks with smaller ids are always kept).
    initial_count: i64,
    next_id: i64,
    size: Option<(usize, usize)>,
    lost: BTreeMap<String, usize>,
    seconds: f64,
}

impl Tracker {
    /// A tracker that detects its own corners (and re-detects when `cfg.redetect`).
    pub fn new(cfg: TrackerConfig) -> Result<Tracker> {
        cfg.validate()?;
        Ok(Tracker {
            cfg,
            frame_ids: Vec::new(),
            prev: None,
            spare: None,
            tracks: Vec::new(),
            init_points: None,
            initial_count: 0,
            next_id: 0,
            size: None,
            lost: BTreeMap::new(),
            seconds: 0.0,
        })
    }

    /// A tracker that follows the given first-frame points (track id = index in `points`).
    /// Re-detection follows `cfg.redetect_with_points` (default off).
    pub fn with_points(cfg: TrackerConfig, points: Vec<[f64; 2]>) -> Result<Tracker> {
        let mut t = Tracker::new(cfg)?;
        t.next_id = points.len() as i64;
        t.initial_count = points.len() as i64;
        t.init_points = Some(points.iter().map(|p| [p[0] as f32, p[1] as f32]).collect());
        Ok(t)
    }

    /// The configuration.
    pub fn config(&self) -> &TrackerConfig {
        &self.cfg
    }

    fn pyramid_levels(&self) -> usize {
        self.cfg.klt.max_level
    }

    fn border(&self) -> usize {
        self.cfg
            .detect
            .border
            .unwrap_or((self.cfg.klt.margin().ceil() as usize).max(self.cfg.klt.half()) + 1)
    }

    /// Adds the next frame: tracks live points into it, then re-detects if needed.
    /// Frames must all have the size of the first ([`Error::Dimension`] otherwise).
    pub fn push(&mut self, id: Id, image: &GrayImage) -> Result<FrameStats> {
        let t0 = std::time::Instant::now();
        if image.data.len() != image.width * image.height || image.width == 0 || image.height == 0 {
            return Err(Error::Dimension {
                context: "tracker frame data",
                expected: format!(
                    "{} values ({}×{})",
                    image.width * image.height,
                    image.width,
                    image.height
                ),
                got: format!("{}", image.data.len()),
            });
        }
        match self.size {
            None => self.size = Some((image.width, image.height)),
            Some((w, h)) if (w, h) != (image.width, image.height) => {
                return Err(Error::Dimension {
                    context: "tracker frame size",
                    expected: format!("{w}×{h}"),
                    got: format!("{}×{}", image.width, image.height),
                });
            }
            Some(_) => {}
        }
        let f = self.frame_ids.len();
        self.frame_ids.push(id);
        let min_side = self.cfg.klt.window.max(8);
        let pyr = match self.spare.take() {
            Some(mut p) => {
                p.rebuild(image, self.pyramid_levels(), min_side);
                p
            }
            None => Pyramid::with_padding(
                image,
                self.pyramid_levels(),
                min_side,
                klt::padding_for_window(self.cfg.klt.window),
            ),
        };
        let mut stats = FrameStats {
            frame: f,
            ..FrameStats::default()
        };
        if let Some(prev) = &self.prev {
            let live: Vec<usize> = (0..self.tracks.len())
                .filter(|&i| self.tracks[i].alive)
                .collect();
            let pts: Vec<[f32; 2]> = live
                .iter()
                .map(|&i| {
                    let &(_, x, y) = self.tracks[i].obs.last().expect("live track observed");
                    [x, y]
                })
                .collect();
            let res = track_points(prev, &pyr, &pts, None, &self.cfg.klt);
            for (&i, r) in live.iter().zip(res) {
                let tr = &mut self.tracks[i];
                match r {
                    Ok([x, y]) => {
                        tr.obs.push((f as u32, x, y));
                        stats.tracked += 1;
                    }
                    Err(e) => {
                        tr.alive = false;
                        match e {
                            Failure::OutOfImage => stats.lost_out_of_image += 1,
                            Failure::LowTexture => stats.lost_low_texture += 1,
                            Failure::Residual => stats.lost_residual += 1,
                            Failure::ForwardBackward => stats.lost_forward_backward += 1,
                        }
                        *self.lost.entry(format!("{e:?}")).or_insert(0) += 1;
                    }
                }
            }
        } else if let Some(points) = self.init_points.take() {
            for (k, p) in points.iter().enumerate() {
                self.tracks.push(TrackState {
                    id: k as i64,
                    obs: vec![(0, p[0], p[1])],
                    alive: true,
                });
            }
            stats.new = points.len();
        }
        let alive = self.tracks.iter().filter(|t| t.alive).count();
        let cap = self.cfg.detect.max_features;
        let redetect = if self.initial_count > 0 {
            self.cfg.redetect_with_points
        } else {
            self.cfg.redetect
        };
        let detect = if f == 0 {
            self.initial_count == 0 || redetect
        } else {
            redetect && (alive as f32) < self.cfg.redetect_below * cap as f32
        };
        if detect {
            stats.new += self.detect_new(&pyr, f, alive);
        }
        stats.alive = self.tracks.iter().filter(|t| t.alive).count();
        self.spare = self.prev.replace(pyr);
        self.seconds += t0.elapsed().as_secs_f64();
        Ok(stats)
    }

    /// Detects corners away from live tracks and starts tracks for them (up to the cap).
    fn detect_new(&mut self, pyr: &Pyramid, f: usize, alive: usize) -> usize {
        let cap = self.cfg.detect.max_features;
        if alive >= cap {
            return 0;
        }
        let l0 = &pyr.levels[0];
        let (w, h) = (l0.w, l0.h);
        let mask = if alive > 0 {
            let rad = self
                .cfg
                .redetect_radius
                .unwrap_or(self.cfg.detect.min_distance)
                .max(0.0);
            let mut m = vec![true; w * h];
            let ri = rad.ceil() as isize;
            let r2 = rad * rad;
            for t in self.tracks.iter().filter(|t| t.alive) {
                let &(_, x, y) = t.obs.last().expect("live track observed");
                let (cx, cy) = (x.round() as isize, y.round() as isize);
                for yy in (cy - ri).max(0)..=(cy + ri).min(h as isize - 1) {
                    for xx in (cx - ri).max(0)..=(cx + ri).min(w as isize - 1) {
                        let (dx, dy) = (xx as f32 - x, yy as f32 - y);
                        if dx * dx + dy * dy < r2 {
                            m[yy as usize * w + xx as usize] = false;
                        }
                    }
                }
            }
            Some(m)
        } else {
            None
        };
        let mut dcfg = self.cfg.detect.clone();
        dcfg.max_features = cap - alive;
        // Only corners the tracker's own low-texture test accepts (else they die at once).
        let (win, thr) = (self.cfg.klt.window, self.cfg.klt.min_eigenvalue);
        let mut corners =
            detect_corners_filtered(l0, &dcfg, self.border(), mask.as_deref(), |x, y| {
                klt::window_min_eigenvalue(l0, x, y, win) >= thr
            });
        if let Some(sp) = &self.cfg.subpixel {
            let margin = self.cfg.klt.margin();
            refine_corners(l0, &mut corners, sp, self.cfg.detect.block_size, margin);
        }
        for c in &corners {
            self.tracks.push(TrackState {
                id: self.next_id,
                obs: vec![(f as u32, c.x, c.y)],
                alive: true,
            });
            self.next_id += 1;
        }
        corners.len()
    }

    /// The track table and a summary. Frame ids are those given to [`Tracker::push`].
    pub fn finish(self) -> (TrackTable, TrackSummary) {
        let started = self.tracks.len();
        let alive_at_end = self.tracks.iter().filter(|t| t.alive).count();
        let keep: Vec<&TrackState> = self
            .tracks
            .iter()
            .filter(|t| t.obs.len() >= self.cfg.min_track_len || t.id < self.initial_count)
            .collect();
        let mut table = TrackTable::new(
            self.frame_ids.clone(),
            keep.iter().map(|t| Id::Int(t.id)).collect(),
        );
        for (p, t) in keep.iter().enumerate() {
            for &(f, x, y) in &t.obs {
                table.set(f as usize, p, x as f64, y as f64);
            }
        }
        let summary = TrackSummary {
            frames: self.frame_ids.len(),
            started,
            kept: keep.len(),
            alive_at_end,
            lost: self.lost.clone(),
            seconds: self.seconds,
        };
        (table, summary)
    }
}

/// Reads initial points: one `x y` pair per line (whitespace or comma separated); blank
/// lines and lines starting with `#` are skipped and do not count, so a point's track id is
/// its 0-based index among the point lines (its 0-based line number in a file without
/// comments). Errors: [`Error::Parse`] with the 1-based line, [`Error::EmptyTable`] when no
/// point is given.
pub fn read_init_points(path: &Path) -> Result<Vec<[f64; 2]>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    parse_init_points(&text, path)
}

/// [`read_init_points`] on text already read; `path` names it in errors.
pub fn parse_init_points(text: &str, path: &Path) -> Result<Vec<[f64; 2]>> {
    let mut pts = Vec::new();
    for (ln, line) in text.lines().enumerate() {
        let t = line.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        let mut it = t
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|s| !s.is_empty());
        let mut num = |field: &str| -> Result<f64> {
            let s = it
                .next()
                .ok_or_else(|| Error::parse(path, ln + 1, field, "missing value"))?;
            let v: f64 = s
                .parse()
                .map_err(|_| Error::parse(path, ln + 1, field, format!("`{s}` is not a number")))?;
            if !v.is_finite() {
                return Err(Error::parse(path, ln + 1, field, "not finite"));
            }
            Ok(v)
        };
        let x = num("x")?;
        let y = num("y")?;
        if let Some(extra) = it.next() {
            return Err(Error::parse(
                path,
                ln + 1,
                "line",
                format!("expected two numbers `x y`, found extra `{extra}`"),
            ));
        }
        pts.push([x, y]);
    }
    if pts.is_empty() {
        return Err(Error::EmptyTable {
            path: Some(path.to_path_buf()),
            reason: "no initial points".into(),
        });
    }
    Ok(pts)
}

/// Tracks a whole frame source. `init_points` switch to following those points (no
/// re-detection unless `cfg.redetect_with_points`). `progress` is called after every frame
/// with its counts and the decoded image (so a caller can record the frames without
/// decoding them again).
/// Frames are decoded one ahead on a scoped reader thread (at most two waiting), so decoding
/// overlaps tracking.
pub fn track_source(
    source: &mut FrameSource,
    cfg: &TrackerConfig,
    init_points: Option<Vec<[f64; 2]>>,
    progress: &mut dyn FnMut(&FrameStats, &GrayImage),
) -> Result<(TrackTable, TrackSummary)> {
    let mut tracker = match init_points {
        Some(p) => Tracker::with_points(cfg.clone(), p)?,
        None => Tracker::new(cfg.clone())?,
    };
    let path = source.path().to_path_buf();
    // Decode ahead: the next frame is read on another thread while this one is tracked.
    std::thread::scope(|scope| -> Result<()> {
        let (tx, rx) = std::sync::mpsc::sync_channel(2);
        let reader = scope.spawn(move || {
            loop {
                let item = source.next_frame();
                let stop = !matches!(item, Ok(Some(_)));
                if tx.send(item).is_err() || stop {
                    break;
                }
            }
        });
        let mut out = Ok(());
        for item in rx.iter() {
            match item {
                Ok(Some((id, img))) => match tracker.push(id, &img) {
                    Ok(s) => progress(&s, &img),
                    Err(e) => {
                        out = Err(e);
                        break;
                    }
                },
                Ok(None) => break,
                Err(e) => {
                    out = Err(e);
                    break;
                }
            }
        }
        // Dropping the receiver stops the reader at its next send.
        drop(rx);
        if let Err(panic) = reader.join() {
            std::panic::resume_unwind(panic);
        }
        out
    })?;
    if tracker.frame_ids.is_empty() {
        return Err(Error::Image {
            path,
            message: "no frames".into(),
        });
    }
    Ok(tracker.finish())
}

/// [`track_source`] on a path (folder of images or video), without progress reports.
pub fn track_path(
    path: impl AsRef<Path>,
    cfg: &TrackerConfig,
    init_points: Option<Vec<[f64; 2]>>,
) -> Result<(TrackTable, TrackSummary)> {
    let mut src = FrameSource::open(path)?;
    track_source(&mut src, cfg, init_points, &mut |_, _| {})
}
