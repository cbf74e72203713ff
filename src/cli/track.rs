//! `rank3 track`, and the tracking that `rank3 run` shares with it.

use std::path::{Path, PathBuf};

use super::output::{Recording, refuse_overwriting_inputs};
use super::verbosity::{self, detail, info, say};

/// Tracking options shared by `rank3 track` and `rank3 run`.
#[derive(clap::Args)]
pub struct TrackOpts {
    /// Follow these first-frame points (`x y` per line, `#` comments) instead of detecting;
    /// track ids are the 0-based indices of the point lines.
    #[arg(long)]
    pub init_points: Option<PathBuf>,
    /// With --init-points: also detect new corners as tracks die (without --init-points
    /// new corners are always detected).
    #[arg(long, requires = "init_points")]
    pub redetect: bool,
    /// Maximum number of live tracks (corners detected, strongest first).
    #[arg(long, default_value_t = 500)]
    pub max_features: usize,
    /// Corner quality relative to the strongest corner's minimum eigenvalue.
    #[arg(long, default_value_t = 0.01)]
    pub quality: f32,
    /// Minimum distance between corners, pixels.
    #[arg(long, default_value_t = 8.0)]
    pub min_distance: f32,
    /// Lucas–Kanade window side (odd).
    #[arg(long, default_value_t = 21)]
    pub window: usize,
    /// Coarsest pyramid level (0 = no pyramid).
    #[arg(long, default_value_t = 3)]
    pub levels: usize,
    /// Newton iterations per level at most.
    #[arg(long, default_value_t = 30)]
    pub iterations: usize,
    /// Forward–backward round-trip tolerance, pixels.
    #[arg(long, default_value_t = 1.0)]
    pub fb_threshold: f32,
    /// Skip the forward–backward check (about twice as fast, less reliable; not with
    /// --fb-threshold).
    #[arg(long, conflicts_with = "fb_threshold")]
    pub no_fb: bool,
    /// Largest mean absolute intensity error over the window (intensities in [0, 1]).
    #[arg(long, default_value_t = 0.06)]
    pub max_residual: f32,
    /// Low-texture threshold: minimum eigenvalue of the gradient matrix / window area.
    #[arg(long, default_value_t = 1e-4)]
    pub min_eigenvalue: f32,
    /// Lose points closer than this to the border, pixels (default 0: a point is lost when
    /// it leaves the image; its window may cross the border).
    #[arg(long)]
    pub border_margin: Option<f32>,
    /// Start new tracks at the whole-pixel corners, without the sub-pixel (Förstner)
    /// refinement.
    #[arg(long)]
    pub no_subpixel: bool,
}

impl TrackOpts {
    pub fn config(&self) -> rank3::tracking::TrackerConfig {
        let mut c = rank3::tracking::TrackerConfig::default();
        c.detect.max_features = self.max_features;
        c.detect.quality_level = self.quality;
        c.detect.min_distance = self.min_distance;
        c.klt.window = self.window;
        c.klt.max_level = self.levels;
        c.klt.max_iterations = self.iterations;
        c.klt.fb_threshold = (!self.no_fb).then_some(self.fb_threshold);
        c.klt.max_residual = self.max_residual;
        c.klt.min_eigenvalue = self.min_eigenvalue;
        c.klt.border_margin = self.border_margin;
        c.redetect_with_points = self.redetect;
        if self.no_subpixel {
            c.subpixel = None;
        }
        c
    }
}

#[derive(clap::Args)]
pub struct TrackArgs {
    /// A folder of PNG/JPEG frames (natural name order) or a video file (needs ffmpeg).
    pub input: PathBuf,
    /// Output track table: .csv, .txt, .json, .npy or .npz.
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub opts: TrackOpts,
    #[cfg(feature = "rerun")]
    #[command(flatten)]
    pub record: rank3::recording::RecordingArgs,
}

/// What tracking produced: the table and the per-frame counts.
pub struct Tracked {
    pub table: rank3::TrackTable,
    /// Width and height of the frames, pixels.
    pub image_size: Option<[u32; 2]>,
    /// The pixels' aspect ratio the input's files state, if any.
    pub pixel_aspect: Option<rank3::pixel_aspect::PixelAspect>,
    /// Per-frame counts (recorded with `--rrd`).
    #[cfg_attr(not(feature = "rerun"), allow(dead_code))]
    pub stats: Vec<rank3::tracking::FrameStats>,
}

/// Tracks `input` with a progress bar; prints a summary to stderr. `on_frame` sees every
/// decoded frame with its index.
pub fn track_input(
    input: &Path,
    opts: &TrackOpts,
    on_frame: &mut dyn FnMut(usize, &rank3::tracking::GrayImage),
) -> Result<Tracked, rank3::Error> {
    let cfg = opts.config();
    print_settings(&cfg, opts);
    let init = opts
        .init_points
        .as_deref()
        .map(rank3::tracking::read_init_points)
        .transpose()?;
    let mut src = rank3::tracking::FrameSource::open(input)?;
    let pixel_aspect = src.pixel_aspect();
    let bar = verbosity::progress(
        src.len_hint().map(|n| n as u64),
        "tracking {bar:30} {pos}/{len} frames ({per_sec}, eta {eta}) {msg}",
        "tracking {spinner} {pos} frames ({per_sec}) {msg}",
    );
    let t0 = std::time::Instant::now();
    let cpu0 = process_cpu_seconds();
    let mut stats = Vec::new();
    let mut image_size = None;
    let result = rank3::tracking::track_source(&mut src, &cfg, init, &mut |s, image| {
        image_size.get_or_insert([image.width as u32, image.height as u32]);
        bar.inc(1);
        bar.set_message(format!("{} alive", s.alive));
        stats.push(*s);
        on_frame(s.frame, image);
    });
    bar.finish_and_clear();
    let (table, summary) = result?;
    let wall = t0.elapsed().as_secs_f64();
    let cpu = process_cpu_seconds().zip(cpu0).map(|(a, b)| a - b);
    let lost: Vec<String> = summary
        .lost
        .iter()
        .map(|(k, v)| format!("{k} {v}"))
        .collect();
    if verbosity::verbose() {
        print_frame_stats(&stats);
    }
    info!(
        "tracked {} frames: {} tracks started, {} kept, {} alive at the end; lost: {}",
        summary.frames,
        summary.started,
        summary.kept,
        summary.alive_at_end,
        if lost.is_empty() {
            "none".to_string()
        } else {
            lost.join(", ")
        }
    );
    info!(
        "tracking time {:.3} s ({:.1} frames/s), total with decoding {:.3} s ({:.1} frames/s){}",
        summary.seconds,
        summary.frames as f64 / summary.seconds.max(1e-9),
        wall,
        summary.frames as f64 / wall.max(1e-9),
        cpu.map_or(String::new(), |c| format!(", CPU {c:.3} s with decoding"))
    );
    Ok(Tracked {
        table,
        stats,
        image_size,
        pixel_aspect,
    })
}

/// Records what tracking produced besides the frames (logged as they are tracked): the
/// tracker's per-frame counts, and the track table (points per frame and trajectories)
/// when `log_table`.
#[cfg(feature = "rerun")]
fn record_tracking(
    rec: &rerun::RecordingStream,
    tracked: &Tracked,
    log_table: bool,
) -> Result<(), rank3::Error> {
    rank3::recording::log_tracking(rec, &tracked.stats)?;
    if log_table {
        rank3::recording::log_input(rec, &tracked.table)?;
    }
    Ok(())
}

/// CPU seconds (user + system, all threads) of this process so far; Linux only.
fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    let fields: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    let ticks = |i: usize| fields.get(i)?.parse::<f64>().ok();
    // utime and stime (fields 14 and 15 of proc(5)), in clock ticks of 1/100 s.
    Some((ticks(11)? + ticks(12)?) / 100.0)
}

/// Opens the requested recording, tracks `input` and records the tracking (the table too
/// when `log_table`).
pub fn track_recorded(
    input: &Path,
    opts: &TrackOpts,
    #[cfg(feature = "rerun")] record: &rank3::recording::RecordingArgs,
    #[cfg_attr(not(feature = "rerun"), allow(unused_variables))] log_table: bool,
    #[cfg_attr(not(feature = "rerun"), allow(unused_variables))] perspective: bool,
) -> Result<(Tracked, Recording), rank3::Error> {
    // The input must open (folder with images, decodable video) before the recording is
    // opened: opening it replaces an existing .rrd, which a run that fails at once on bad
    // input must not destroy.
    drop(rank3::tracking::FrameSource::open(input)?);
    if let Some(p) = &opts.init_points {
        rank3::tracking::read_init_points(p)?;
    }
    // `rank3 track` logs the table itself; `rank3 run` reconstructs from it.
    #[cfg(feature = "rerun")]
    let recording = record.open(
        "rank3",
        rank3::recording::LayoutParts {
            tracking: true,
            reconstruction: !log_table,
            truth: false,
            perspective: !log_table && perspective,
            objects: false,
        },
    )?;
    #[cfg(not(feature = "rerun"))]
    let recording = ();
    // Frames are recorded (JPEG) as they are tracked; the first logging failure is kept.
    #[cfg(feature = "rerun")]
    let mut log_error: Option<rank3::recording::RecordingError> = None;
    #[cfg_attr(not(feature = "rerun"), allow(unused_variables))]
    let tracked = track_input(input, opts, &mut |index, image| {
        #[cfg(feature = "rerun")]
        if let Some(rec) = &recording
            && log_error.is_none()
            && let Err(e) = rank3::recording::log_frame(rec, index, image, 85)
        {
            log_error = Some(e);
        }
    })?;
    #[cfg(feature = "rerun")]
    if let Some(e) = log_error {
        return Err(e.into());
    }
    #[cfg(feature = "rerun")]
    if let Some(rec) = &recording {
        record_tracking(rec, &tracked, log_table)?;
    }
    if tracked.table.n_tracks() == 0 || tracked.table.n_observed() == 0 {
        return Err(rank3::Error::EmptyTable {
            path: Some(input.to_path_buf()),
            reason: format!(
                "no point could be tracked in its {} frame(s): no corner passed the detector \
                 (blank or textureless frames?) — try a lower --quality (now {}) or \
                 --min-distance (now {} px), or give --init-points",
                tracked.table.n_frames(),
                opts.quality,
                opts.min_distance
            ),
        });
    }
    Ok((tracked, recording))
}

pub fn track(a: &TrackArgs) -> Result<(), rank3::Error> {
    let mut inputs: Vec<&Path> = vec![&a.input];
    inputs.extend(a.opts.init_points.as_deref());
    refuse_overwriting_inputs(
        &inputs,
        None,
        Some(&a.out),
        #[cfg(feature = "rerun")]
        &a.record,
    )?;
    // Fail on a bad output extension before the (long) tracking.
    rank3::table::Format::from_path(&a.out)?;
    let (tracked, _recording) = track_recorded(
        &a.input,
        &a.opts,
        #[cfg(feature = "rerun")]
        &a.record,
        true,
        false,
    )?;
    let table = tracked.table;
    table.write(&a.out)?;
    say!(
        "wrote {} ({} frames × {} tracks, {} observations, {:.1} % filled)",
        a.out.display(),
        table.n_frames(),
        table.n_tracks(),
        table.n_observed(),
        100.0 * table.fill()
    );
    // The table does not carry the frames' pixel shape: say what `reconstruct` needs.
    if let Some(pa) = rank3::pixel_aspect::of_frames(tracked.pixel_aspect, tracked.image_size) {
        info!(
            "pixel aspect ratio fx/fy = {}: {}; reconstruct these tracks with --aspect-ratio {} \
             (or --images {})",
            pa.ratio,
            pa.source,
            pa.ratio,
            a.input.display()
        );
    }
    Ok(())
}

/// With `-v`: the tracker's settings, one line.
fn print_settings(cfg: &rank3::tracking::TrackerConfig, opts: &TrackOpts) {
    let d = &cfg.detect;
    let k = &cfg.klt;
    detail!(
        "tracker: {}; at most {} tracks, corner quality {}, min distance {} px, sub-pixel \
         refinement {}; window {} px, {} pyramid level(s), {} iterations, forward–backward {}, \
         max residual {}, min eigenvalue {:e}, border margin {} px",
        match &opts.init_points {
            Some(p) if opts.redetect => format!("from {} with re-detection", p.display()),
            Some(p) => format!("from {} (no detection)", p.display()),
            None => "detected corners, re-detected as tracks die".to_string(),
        },
        d.max_features,
        d.quality_level,
        d.min_distance,
        if cfg.subpixel.is_some() { "on" } else { "off" },
        k.window,
        k.max_level,
        k.max_iterations,
        k.fb_threshold
            .map_or("off".to_string(), |t| format!("{t} px")),
        k.max_residual,
        k.min_eigenvalue,
        k.border_margin.unwrap_or(0.0)
    );
}

/// With `-v`: one line per frame of the tracker's counts.
fn print_frame_stats(stats: &[rank3::tracking::FrameStats]) {
    for s in stats {
        detail!(
            "frame {}: {} tracked, lost {} out of image, {} low texture, {} residual, {} \
             forward–backward; {} new, {} alive",
            s.frame,
            s.tracked,
            s.lost_out_of_image,
            s.lost_low_texture,
            s.lost_residual,
            s.lost_forward_backward,
            s.new,
            s.alive
        );
    }
}
