use std::path::PathBuf;

use rerun::{
    AnnotationContext, ClassDescription, LineStrips2D, Points3D, RecordingStream, Scalars, TextLog,
    TextLogLevel,
};

use crate::synth::SynthScene;
use crate::{Error, TrackTable};

use super::bulk::{GREY, RED, class_id, f3, send_frame_points, send_per_frame, trajectory_batches};
use super::layout::{frame_on_camera, refresh_layout};
use super::reconstruction::log_cameras;
use super::{RecordingOptions, RecordingResult, TIMELINE_FRAME, TIMELINE_STAGE, at_stage, paths};

/// Logs the input table: per-frame observed points on `image/tracks` (class id = track
/// index, with an annotation context mapping it to the track id), and one trajectory per
/// track on `image/trajectories`, at stage `input` (and frame 0). Track labels are shown on
/// hover, not drawn.
///
/// Cost: O(F·N).
pub fn log_input(rec: &RecordingStream, table: &TrackTable) -> RecordingResult {
    log_input_with(rec, table, &RecordingOptions::default())
}

/// [`log_input`] with explicit [`RecordingOptions`].
pub fn log_input_with(
    rec: &RecordingStream,
    table: &TrackTable,
    options: &RecordingOptions,
) -> RecordingResult {
    at_stage(rec, "input");
    let n = table.n_tracks();
    if let Some(ctx) = track_labels(table, options) {
        rec.log_static("image", &ctx)?;
        rec.log_static("world", &ctx)?;
        rec.log_static("affine", &ctx)?;
        rec.log_static(paths::TRUTH_ROOT, &ctx)?;
    }
    let all: Vec<usize> = (0..n).collect();
    // Also at frame 0 of the `frame` timeline, on which `rank3 track`'s recording opens
    // (data without a `frame` time are not shown there). Labels on hover only.
    rec.set_time_sequence(TIMELINE_FRAME, 0);
    rec.log(
        paths::TRAJECTORIES,
        &[
            &trajectory_batches(table, &all)? as &dyn rerun::AsComponents,
            &LineStrips2D::update_fields().with_show_labels(false),
        ],
    )?;
    rec.disable_timeline(TIMELINE_FRAME);
    send_frame_points(rec, paths::TRACKS, "input", table, &all, None, 2.0)
}

/// The annotation context that names each class id `track <id>` (hover labels), when the
/// table has at most `options.max_annotated_tracks` tracks.
pub(super) fn track_labels(
    table: &TrackTable,
    options: &RecordingOptions,
) -> Option<AnnotationContext> {
    (table.n_tracks() <= options.max_annotated_tracks.min(65535)).then(|| {
        AnnotationContext::new(
            table.track_ids().iter().enumerate().map(|(p, id)| {
                ClassDescription::from((class_id(p), format!("track {id}").as_str()))
            }),
        )
    })
}

/// Logs a frame the tracker saw on `image/frame` as a JPEG (`quality` 1–100) at `frame`
/// timeline value `index`, stage `input`, beneath the tracks of [`log_input`]. The image
/// is encoded here (about 5 ms for 640×480), so a recording holds tens of kilobytes per
/// frame instead of the raw pixels.
///
/// Cost: O(width·height).
pub fn log_frame(
    rec: &RecordingStream,
    index: usize,
    image: &crate::tracking::GrayImage,
    quality: u8,
) -> RecordingResult {
    let (w, h) = (image.width, image.height);
    let pixels: Vec<u8> = image
        .data
        .iter()
        .map(|&v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect();
    let mut jpeg = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, quality.clamp(1, 100))
        .encode(&pixels, w as u32, h as u32, image::ExtendedColorType::L8)
        .map_err(|e| Error::Image {
            path: PathBuf::from(format!("frame {index}")),
            message: format!("cannot encode the frame as JPEG for the recording: {e}"),
        })?;
    rec.set_time_sequence(TIMELINE_STAGE, 0);
    rec.set_time_sequence(TIMELINE_FRAME, index as i64);
    rec.log(
        paths::FRAME_IMAGE,
        &rerun::EncodedImage::from_file_contents(jpeg).with_draw_order(-10.0),
    )?;
    rec.disable_timeline(TIMELINE_FRAME);
    Ok(())
}

/// Logs the tracker's per-frame counts as Scalars on the `frame` timeline (stage `input`):
/// `tracking/tracked`, `tracking/new`, `tracking/alive` and `tracking/lost/<reason>` for
/// the reasons out_of_image, low_texture, residual and forward_backward.
///
/// Cost: O(F).
pub fn log_tracking(
    rec: &RecordingStream,
    stats: &[crate::tracking::FrameStats],
) -> RecordingResult {
    let frames: Vec<usize> = stats.iter().map(|s| s.frame).collect();
    type Count = fn(&crate::tracking::FrameStats) -> usize;
    let series: [(&str, Count); 7] = [
        ("tracked", |s| s.tracked),
        ("new", |s| s.new),
        ("alive", |s| s.alive),
        ("lost/out_of_image", |s| s.lost_out_of_image),
        ("lost/low_texture", |s| s.lost_low_texture),
        ("lost/residual", |s| s.lost_residual),
        ("lost/forward_backward", |s| s.lost_forward_backward),
    ];
    for (name, count) in series {
        let column = Scalars::update_fields()
            .with_scalars(stats.iter().map(|s| count(s) as f64))
            .columns_of_unit_batches()?;
        send_per_frame(
            rec,
            &format!("{}/{name}", paths::TRACKING),
            "input",
            &frames,
            column.collect(),
        )?;
    }
    Ok(())
}

/// Logs a synthetic scene's ground truth under `truth/`: the true points (outlier tracks
/// red, the rest grey) on `truth/points` and the true cameras laid out like `world/`
/// (`log_cameras` layout) on `truth/camera…`, at stage `input`. Pair with [`log_input`].
///
/// Cost: O(F + N).
pub fn log_synth_truth(rec: &RecordingStream, scene: &SynthScene) -> RecordingResult {
    at_stage(rec, "input");
    let m = &scene.truth;
    rec.log(
        paths::TRUTH_POINTS,
        &Points3D::new(m.points.iter().map(f3))
            .with_colors((0..m.n_points()).map(|p| {
                if scene.outlier_tracks.get(p).is_some_and(|o| o.is_some()) {
                    RED
                } else {
                    GREY
                }
            }))
            .with_class_ids((0..m.n_points()).map(class_id))
            .with_show_labels(false),
    )?;
    if let Some(r0) = m.rotations.first() {
        frame_on_camera(rec, "/truth", m.points.iter().map(f3), r0.matrix());
    }
    let frames: Vec<usize> = (0..m.n_frames()).collect();
    log_cameras(rec, paths::TRUTH_ROOT, m, &frames)?;
    rec.log(
        paths::LOG_STAGES,
        &TextLog::new(format!(
            "synthetic scene: {} frames × {} tracks, {} outlier track(s), {} gross entr(y/ies)",
            m.n_frames(),
            m.n_points(),
            scene.outlier_tracks.iter().filter(|o| o.is_some()).count(),
            scene.gross_entries.len()
        ))
        .with_level(TextLogLevel::INFO),
    )?;
    // The truth view opens on the true points.
    refresh_layout(rec)
}
