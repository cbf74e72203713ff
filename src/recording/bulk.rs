use std::sync::Arc;

use rerun::external::arrow::array::{
    ArrayRef, FixedSizeListArray, Float32Array, ListArray, UInt16Array,
};
use rerun::external::arrow::buffer::OffsetBuffer;
use rerun::external::arrow::datatypes::{DataType, Field};
use rerun::{
    LineStrips2D, Points2D, Radius, RecordingStream, SerializedComponentBatch,
    SerializedComponentColumn, TimeColumn,
};

use crate::TrackTable;

use super::{RecordingResult, STAGES, TIMELINE_FRAME, TIMELINE_STAGE, stage_index};

pub(super) fn f2(p: [f64; 2]) -> [f32; 2] {
    [p[0] as f32, p[1] as f32]
}

pub(super) fn f3(x: &nalgebra::Vector3<f64>) -> [f32; 3] {
    [x[0] as f32, x[1] as f32, x[2] as f32]
}

pub(super) fn class_id(p: usize) -> u16 {
    (p % 65536) as u16
}

pub(super) const RED: [u8; 3] = [230, 40, 40];
pub(super) const GREEN: [u8; 3] = [40, 190, 60];
pub(super) const ORANGE: [u8; 3] = [255, 150, 0];
pub(super) const GREY: [u8; 3] = [150, 150, 150];

/// Flagged tracks (set aside, outliers) are labelled on the views when there are at most
/// this many of them; more labels would overlap, and hovering still names every track.
pub(super) const MAX_FLAGGED_LABELS: usize = 24;

/// Whether `count` flagged tracks get their labels drawn ([`MAX_FLAGGED_LABELS`]).
pub(super) fn show_flagged_labels(count: usize) -> bool {
    count <= MAX_FLAGGED_LABELS
}

/// Green (0) → yellow (0.5) → red (1).
pub(super) fn heat(t: f64) -> [u8; 3] {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        1.0
    };
    if t < 0.5 {
        [(510.0 * t) as u8, 200, 40]
    } else {
        [255, (200.0 * (2.0 - 2.0 * t)) as u8, 40]
    }
}

/// The Arrow field of Rerun's `Vec2D` datatype (2D positions and vectors are
/// `FixedSizeList<2, f32>` of this field).
pub(super) fn vec2_field() -> Arc<Field> {
    Arc::new(Field::new("item", DataType::Float32, false))
}

/// `[x0, y0, x1, y1, …]` as a `Vec2D` Arrow array, built in one move instead of element by
/// element (the SDK's generic serializer costs several times more on 10⁵ points).
pub(super) fn vec2_array(flat: Vec<f32>) -> RecordingResult<ArrayRef> {
    Ok(Arc::new(FixedSizeListArray::try_new(
        vec2_field(),
        2,
        Arc::new(Float32Array::from(flat)),
        None,
    )?))
}

/// `LineStrip2D` components (lists of `Vec2D`) from the strips' concatenated points and
/// their lengths.
pub(super) fn strips_array(flat: Vec<f32>, lengths: &[usize]) -> RecordingResult<ArrayRef> {
    let item = Arc::new(Field::new(
        "item",
        DataType::FixedSizeList(vec2_field(), 2),
        false,
    ));
    Ok(Arc::new(ListArray::try_new(
        item,
        OffsetBuffer::from_lengths(lengths.iter().copied()),
        vec2_array(flat)?,
        None,
    )?))
}

/// Class ids (`u16`) as an Arrow array.
pub(super) fn class_id_array(ids: Vec<u16>) -> ArrayRef {
    Arc::new(UInt16Array::from(ids))
}

/// The observed positions of `tracks` in frame order (gaps bridged), concatenated, with
/// each track's number of points. Two passes over the table's frame rows (count, then
/// fill), so that the table is read in memory order.
pub(super) fn trajectories(table: &TrackTable, tracks: &[usize]) -> (Vec<f32>, Vec<usize>) {
    let mut lengths = vec![0usize; tracks.len()];
    for f in 0..table.n_frames() {
        let row = table.frame_row(f);
        for (len, &p) in lengths.iter_mut().zip(tracks) {
            *len += usize::from(row.contains(p));
        }
    }
    let mut next: Vec<usize> = lengths
        .iter()
        .scan(0, |start, &len| {
            let s = *start;
            *start += len;
            Some(2 * s)
        })
        .collect();
    let mut flat = vec![0f32; 2 * lengths.iter().sum::<usize>()];
    for f in 0..table.n_frames() {
        let row = table.frame_row(f);
        for (at, &p) in next.iter_mut().zip(tracks) {
            if let Some([x, y]) = row.get(p) {
                flat[*at] = x as f32;
                flat[*at + 1] = y as f32;
                *at += 2;
            }
        }
    }
    (flat, lengths)
}

/// `LineStrips2D` of the trajectories of `tracks`, with their class ids.
pub(super) fn trajectory_batches(
    table: &TrackTable,
    tracks: &[usize],
) -> RecordingResult<[SerializedComponentBatch; 2]> {
    let (flat, lengths) = trajectories(table, tracks);
    Ok([
        SerializedComponentBatch::new(
            strips_array(flat, &lengths)?,
            LineStrips2D::descriptor_strips(),
        ),
        SerializedComponentBatch::new(
            class_id_array(tracks.iter().map(|&p| class_id(p)).collect()),
            LineStrips2D::descriptor_class_ids(),
        ),
    ])
}

/// Number of observed entries of `tracks` in `frames`: the size of the per-entry buffers,
/// allocated up front.
pub(super) fn observed_count(
    table: &TrackTable,
    frames: impl IntoIterator<Item = usize>,
    tracks: &[usize],
) -> usize {
    frames
        .into_iter()
        .map(|f| {
            let row = table.frame_row(f);
            tracks.iter().filter(|&&p| row.contains(p)).count()
        })
        .sum()
}

/// Per-frame observed points of `tracks` for the given `frames`: concatenated positions,
/// class ids and the number of points per frame.
pub(super) fn frame_points(
    table: &TrackTable,
    frames: &[usize],
    tracks: &[usize],
) -> (Vec<f32>, Vec<u16>, Vec<usize>) {
    let ids_of: Vec<u16> = tracks.iter().map(|&p| class_id(p)).collect();
    let n = observed_count(table, frames.iter().copied(), tracks);
    let mut flat = Vec::with_capacity(2 * n);
    let mut ids = Vec::with_capacity(n);
    let mut lengths = Vec::with_capacity(frames.len());
    for &f in frames {
        let before = ids.len();
        let row = table.frame_row(f);
        for (&p, &id) in tracks.iter().zip(&ids_of) {
            if let Some([x, y]) = row.get(p) {
                flat.push(x as f32);
                flat.push(y as f32);
                ids.push(id);
            }
        }
        lengths.push(ids.len() - before);
    }
    (flat, ids, lengths)
}

/// Sends one row per frame of an entity as a single chunk (`send_columns`): row `k` on the
/// `frame` timeline at `frames[k]` and on the `stage` timeline at `stage`. One chunk instead
/// of a log call per frame spares the SDK's batcher from re-assembling 10⁵ points.
pub(super) fn send_per_frame(
    rec: &RecordingStream,
    path: &str,
    stage: &str,
    frames: &[usize],
    columns: Vec<SerializedComponentColumn>,
) -> RecordingResult {
    let stage = stage_index(stage).unwrap_or(STAGES.len() as i64);
    rec.send_columns(
        path,
        [
            TimeColumn::new_sequence(TIMELINE_FRAME, frames.iter().map(|&f| f as i64)),
            TimeColumn::new_sequence(TIMELINE_STAGE, std::iter::repeat_n(stage, frames.len())),
        ],
        columns,
    )?;
    Ok(())
}

/// Per-frame `Points2D` rows (positions, class ids, one colour and radius per row) of the
/// observed entries of `tracks`, sent with [`send_per_frame`].
pub(super) fn send_frame_points(
    rec: &RecordingStream,
    path: &str,
    stage: &str,
    table: &TrackTable,
    tracks: &[usize],
    color: Option<[u8; 3]>,
    radius: f32,
) -> RecordingResult {
    let frames: Vec<usize> = (0..table.n_frames()).collect();
    let (flat, ids, lengths) = frame_points(table, &frames, tracks);
    let mut columns = vec![
        SerializedComponentBatch::new(vec2_array(flat)?, Points2D::descriptor_positions())
            .partitioned(lengths.iter().copied())?,
        SerializedComponentBatch::new(class_id_array(ids), Points2D::descriptor_class_ids())
            .partitioned(lengths.iter().copied())?,
    ];
    // Track labels on hover only (the annotation context names each class id): drawn on
    // every point they would cover the image.
    let mut rows = Points2D::update_fields()
        .with_radii(vec![Radius::new_ui_points(radius); frames.len()])
        .with_many_show_labels(vec![false; frames.len()]);
    if let Some(c) = color {
        rows = rows.with_colors(vec![c; frames.len()]);
    }
    columns.extend(rows.columns_of_unit_batches()?);
    send_per_frame(rec, path, stage, &frames, columns)
}

/// Every-k-th index so that at most `max` remain.
pub(super) fn subsample(len: usize, max: usize) -> Vec<usize> {
    let max = max.max(1);
    let step = len.div_ceil(max).max(1);
    (0..len).step_by(step).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rerun::Loggable;

    /// The hand-built Arrow arrays must have exactly the types the SDK's serializers produce
    /// (a Rerun upgrade that changes them fails here, not in the viewer).
    #[test]
    fn bulk_arrays_match_the_sdk_types() {
        let pts = vec2_array(vec![1.0, 2.0, 3.0, 4.0]).unwrap();
        assert_eq!(pts.data_type(), &rerun::datatypes::Vec2D::arrow_datatype());
        assert_eq!(
            pts.data_type(),
            &rerun::components::Position2D::arrow_datatype()
        );
        assert_eq!(
            pts.data_type(),
            &rerun::components::Vector2D::arrow_datatype()
        );
        assert_eq!(pts.len(), 2);
        let strips = strips_array(vec![0.0; 10], &[2, 0, 3]).unwrap();
        assert_eq!(
            strips.data_type(),
            &rerun::components::LineStrip2D::arrow_datatype()
        );
        assert_eq!(strips.len(), 3);
        assert!(
            strips_array(vec![0.0; 10], &[2, 4]).is_err(),
            "lengths beyond the data"
        );
        let ids = class_id_array(vec![1, 2]);
        assert_eq!(
            ids.data_type(),
            &rerun::components::ClassId::arrow_datatype()
        );
    }

    /// Trajectories are built in memory order by two passes; they must equal the
    /// per-track walk through the frames, gaps bridged.
    #[test]
    fn trajectories_match_a_walk_along_each_track() {
        let mut t = TrackTable::new(
            (0..4).map(crate::table::Id::Int).collect(),
            (0..3).map(crate::table::Id::Int).collect(),
        );
        for (f, p, x, y) in [
            (0, 0, 1.0, 2.0),
            (2, 0, 3.0, 4.0),
            (1, 2, 5.0, 6.0),
            (3, 2, 7.0, 8.0),
            (0, 2, 9.0, 10.0),
        ] {
            t.set(f, p, x, y);
        }
        let (flat, lengths) = trajectories(&t, &[2, 1, 0]);
        assert_eq!(lengths, vec![3, 0, 2]);
        assert_eq!(
            flat,
            vec![9.0, 10.0, 5.0, 6.0, 7.0, 8.0, 1.0, 2.0, 3.0, 4.0]
        );
    }
}
