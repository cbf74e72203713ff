use rerun::{LineStrips2D, Points2D, Radius, RecordingStream, Scalars, TextLog, TextLogLevel};

use crate::{Error, TrackTable};

use super::bulk::{GREEN, ORANGE, RED, class_id, f2, show_flagged_labels, trajectory_batches};
use super::{RecordingResult, TIMELINE_FRAME, TIMELINE_ITERATION, at_stage, paths};

/// Logs the robust (RANSAC) pass at stage `robust`: a colour per input trajectory on
/// `image/trajectories` (green inlier, red outlier; the strips logged by [`log_input`](super::log_input) keep
/// their positions), the outlier tracks' trajectories in red (labelled) on
/// `image/robust/outliers`,
/// flagged entries as orange points per frame on `image/robust/flagged`, and the inlier count
/// per RANSAC iteration on `solver/ransac/inliers` (`iteration` timeline).
///
/// `inlier_tracks[p]` refers to track `p` of `table`; `flagged_entries` are `(frame, track)`
/// indices into `table`.
///
/// Cost: O(F·N + #flagged + #iterations).
pub fn log_robust(
    rec: &RecordingStream,
    table: &TrackTable,
    inlier_tracks: &[bool],
    flagged_entries: &[(usize, usize)],
    inliers_per_iteration: &[usize],
) -> RecordingResult {
    if inlier_tracks.len() != table.n_tracks() {
        return Err(Error::Dimension {
            context: "recording::log_robust inlier_tracks",
            expected: format!("{} entries (one per track)", table.n_tracks()),
            got: inlier_tracks.len().to_string(),
        }
        .into());
    }
    if let Some(&(f, p)) = flagged_entries
        .iter()
        .find(|&&(f, p)| f >= table.n_frames() || p >= table.n_tracks())
    {
        return Err(Error::Dimension {
            context: "recording::log_robust flagged_entries",
            expected: format!(
                "(frame, track) indices below ({}, {})",
                table.n_frames(),
                table.n_tracks()
            ),
            got: format!("({f}, {p})"),
        }
        .into());
    }
    at_stage(rec, "robust");
    let (inl, outl): (Vec<usize>, Vec<usize>) =
        (0..table.n_tracks()).partition(|&p| inlier_tracks[p]);
    // The input trajectories turn green (inlier) or red (outlier) from this stage on: a
    // colour column, not a second copy of every trajectory.
    rec.log(
        paths::TRAJECTORIES,
        &LineStrips2D::update_fields().with_colors(
            inlier_tracks
                .iter()
                .map(|&inlier| if inlier { GREEN } else { RED }),
        ),
    )?;
    let labels = LineStrips2D::update_fields()
        .with_colors([RED])
        .with_labels(
            outl.iter()
                .map(|&p| format!("outlier track {}", table.track_ids()[p])),
        )
        .with_show_labels(show_flagged_labels(outl.len()));
    let [strips, ids] = trajectory_batches(table, &outl)?;
    rec.log(
        paths::ROBUST_OUTLIERS,
        &[&strips as &dyn rerun::AsComponents, &ids, &labels],
    )?;
    rec.log(
        paths::LOG_STAGES,
        &TextLog::new(format!(
            "robust: {} inlier track(s), {} outlier track(s), {} flagged entr(y/ies)",
            inl.len(),
            outl.len(),
            flagged_entries.len()
        ))
        .with_level(TextLogLevel::INFO),
    )?;
    let mut by_frame: Vec<Vec<usize>> = vec![Vec::new(); table.n_frames()];
    for &(f, p) in flagged_entries {
        by_frame[f].push(p);
    }
    for (f, tracks) in by_frame.iter().enumerate() {
        if tracks.is_empty() {
            continue;
        }
        rec.set_time_sequence(TIMELINE_FRAME, f as i64);
        let (pos, ids): (Vec<[f32; 2]>, Vec<u16>) = tracks
            .iter()
            .filter_map(|&p| table.get(f, p).map(|xy| (f2(xy), class_id(p))))
            .unzip();
        rec.log(
            paths::ROBUST_FLAGGED,
            &Points2D::new(pos)
                .with_class_ids(ids)
                .with_colors([ORANGE])
                .with_radii([Radius::new_ui_points(5.0)])
                .with_show_labels(false),
        )?;
    }
    rec.disable_timeline(TIMELINE_FRAME);
    for (it, &count) in inliers_per_iteration.iter().enumerate() {
        rec.set_time_sequence(TIMELINE_ITERATION, it as i64);
        rec.log(paths::ROBUST_INLIER_COUNT, &Scalars::single(count as f64))?;
    }
    rec.disable_timeline(TIMELINE_ITERATION);
    Ok(())
}
