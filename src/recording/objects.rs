use rerun::{LineStrips2D, Points3D, RecordingStream, TextDocument};

use crate::TrackTable;

use super::bulk::{RED, class_id, f3, send_frame_points, trajectory_batches};
use super::input::track_labels;
use super::reconstruction::{log_cameras, scene_distance};
use super::{RecordingOptions, RecordingResult, at_stage};

/// Distinct colours for objects (cycled).
pub(super) const OBJECT_COLOURS: [[u8; 3]; 8] = [
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [148, 103, 189],
    [23, 190, 207],
    [188, 189, 34],
    [227, 119, 194],
    [140, 86, 75],
];

/// Colour of object `k` (cycled).
pub(super) fn object_colour(k: usize) -> [u8; 3] {
    OBJECT_COLOURS[k % OBJECT_COLOURS.len()]
}

/// Logs a multi-object result ([`crate::objects`]): each object's trajectories in its
/// colour on `image/objects/<k>/trajectories` (stage `input`) and, per frame, its points on
/// `image/objects/<k>`; the outlier tracks likewise in red under `image/objects/outliers`; each reconstructed object's points and cameras (in its own
/// frame, which a translation on `objects/<k>` places beside the previous object's, so
/// that they do not overlap) under `objects/<k>/`; a
/// markdown summary on `objects/summary`. At stage `result`.
///
/// Cost: O(F·N) plus each object's points and cameras.
pub fn log_objects(
    rec: &RecordingStream,
    table: &TrackTable,
    mb: &crate::objects::MultiBody,
) -> RecordingResult {
    // The input's hover labels, then trajectories and per-frame points coloured by object
    // (not the input's per-track colours).
    at_stage(rec, "input");
    if let Some(ctx) = track_labels(table, &RecordingOptions::default()) {
        rec.log_static("image", &ctx)?;
    }
    let outliers: Vec<usize> = (0..table.n_tracks())
        .filter(|&p| mb.segmentation.labels[p].code() < 0)
        .collect();
    let groups = mb
        .objects
        .iter()
        .map(|o| {
            let path = format!("image/objects/{}", o.index);
            (path, &o.tracks, object_colour(o.index))
        })
        .chain(
            (!outliers.is_empty()).then(|| ("image/objects/outliers".to_string(), &outliers, RED)),
        )
        .collect::<Vec<_>>();
    for (path, tracks, colour) in &groups {
        rec.log(
            format!("{path}/trajectories"),
            &[
                &trajectory_batches(table, tracks)? as &dyn rerun::AsComponents,
                &LineStrips2D::update_fields()
                    .with_colors([*colour])
                    .with_show_labels(false),
            ],
        )?;
    }
    at_stage(rec, "result");
    for (path, tracks, colour) in &groups {
        send_frame_points(rec, path, "result", table, tracks, Some(*colour), 3.0)?;
    }
    let mut offset = 0.0;
    let mut md = String::from(
        "| object | tracks | subspace RMS (px) | camera | RMS (px) |\n|---|---|---|---|---|\n",
    );
    for o in &mb.objects {
        let colour = object_colour(o.index);
        match &o.reconstruction {
            Ok(r) => {
                let pts = &r.model.points;
                let radius = pts
                    .iter()
                    .map(|x| x.norm())
                    .fold(0.0, f64::max)
                    .max(scene_distance(&r.model) * 0.1);
                let shift = (offset + radius) as f32;
                offset += 2.5 * radius;
                let base = format!("objects/{}", o.index);
                rec.log(
                    format!("{base}/points"),
                    &Points3D::new(pts.iter().map(f3))
                        .with_colors([colour])
                        .with_class_ids(r.kept_tracks.iter().map(|&p| class_id(o.tracks[p])))
                        .with_show_labels(false),
                )?;
                rec.log(
                    base.clone(),
                    &rerun::Transform3D::from_translation([shift, 0.0, 0.0]),
                )?;
                log_cameras(rec, &format!("{base}/cameras"), &r.model, &r.kept_frames)?;
                md.push_str(&format!(
                    "| {} | {} | {:.3} | {} | {:.3} |\n",
                    o.index,
                    o.tracks.len(),
                    o.subspace_rms_px,
                    crate::output::spelled(&r.camera_model),
                    r.rms_px
                ));
            }
            Err(e) => md.push_str(&format!(
                "| {} | {} | {:.3} | failed: {} | |\n",
                o.index,
                o.tracks.len(),
                o.subspace_rms_px,
                e.replace('|', "/")
            )),
        }
    }
    md.push_str(&format!(
        "\n{} outlier and {} unscored tracks; σ {:.3} px; {} rounds.\n",
        mb.segmentation.n_outliers(),
        mb.segmentation.n_unscored(),
        mb.segmentation.sigma,
        mb.segmentation.rounds
    ));
    rec.log_static("objects/summary", &TextDocument::from_markdown(md))?;
    Ok(())
}
