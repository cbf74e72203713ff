use rerun::{
    Arrows2D, Arrows3D, BarChart, Image, LineStrip3D, LineStrips2D, LineStrips3D, Points3D,
    RecordingStream, Scalars, SerializedComponentBatch, Tensor, TensorBuffer, TensorData,
    TextDocument, TextLog, TextLogLevel, Transform3D,
};

use crate::metric::UpgradeMethod;
use crate::table::SetAsideKind;
use crate::{Error, MetricModel, Reconstruction, TrackTable};

use super::bulk::{
    GREEN, GREY, RED, class_id, class_id_array, f3, heat, observed_count, send_frame_points,
    send_per_frame, show_flagged_labels, subsample, trajectory_batches, vec2_array,
};
use super::layout::{frame_on_camera, frame_view, framing_eye, refresh_layout};
use super::perspective::{log_perspective, log_projective};
use super::{RecordingOptions, RecordingResult, TIMELINE_FRAME, at_stage, paths};

/// Logs everything a finished run explains itself with (see the module table): set-aside
/// tracks, the visibility mask and W, the singular values and σ4/σ3, the affine and metric
/// structure, L's eigenvalues and the upgrade path, the cameras, the residuals and a
/// markdown summary. `table` must be the table the reconstruction was computed from.
///
/// Cost: O(F·N).
pub fn log_reconstruction(
    rec: &RecordingStream,
    table: &TrackTable,
    result: &Reconstruction,
) -> RecordingResult {
    log_reconstruction_with(rec, table, result, &RecordingOptions::default())
}

/// [`log_reconstruction`] with explicit [`RecordingOptions`].
pub fn log_reconstruction_with(
    rec: &RecordingStream,
    table: &TrackTable,
    result: &Reconstruction,
    options: &RecordingOptions,
) -> RecordingResult {
    log_result(rec, table, result, options, true)
}

/// [`log_reconstruction_with`], with the visibility mask and W left out when
/// `with_matrix` is false (already logged while the pipeline ran).
pub(super) fn log_result(
    rec: &RecordingStream,
    table: &TrackTable,
    result: &Reconstruction,
    options: &RecordingOptions,
    with_matrix: bool,
) -> RecordingResult {
    check_consistent(table, result)?;
    // The largest part first, so that the SDK's writer encodes it while the rest is built.
    log_residuals(rec, table, result, options)?;
    log_set_aside(rec, table, result)?;
    if with_matrix {
        log_visibility(rec, table, options)?;
        log_measurement_matrix(
            rec,
            table,
            &result.kept_frames,
            &result.kept_tracks,
            options,
        )?;
    }
    log_projective(rec, table, result, options)?;
    log_perspective(rec, table, result, options)?;
    // The factorization, the structures and the summary (each at its own stage; the 3D
    // views open on the structures just logged).
    log_streamed(rec, result)
}

/// Logs a reconstruction made without a table in memory ([`crate::stream`], `reconstruct
/// --stream`): the singular values and σ4/σ3, the affine and metric structure, the cameras,
/// the upgrade and the summary. The input, W and the per-entry residuals need the table and
/// are not logged. Also the last part of [`log_reconstruction`].
///
/// Cost: O(F + N).
pub fn log_streamed(rec: &RecordingStream, result: &Reconstruction) -> RecordingResult {
    log_factorization(rec, result)?;
    log_metric(rec, result)?;
    at_stage(rec, "result");
    rec.log(
        paths::SUMMARY,
        &TextDocument::from_markdown(summary_markdown(result)),
    )?;
    refresh_layout(rec)
}

pub(super) fn check_consistent(table: &TrackTable, r: &Reconstruction) -> RecordingResult {
    let (fk, nk) = (r.kept_frames.len(), r.kept_tracks.len());
    let bad = r.input_frame_ids.len() != table.n_frames()
        || r.input_track_ids.len() != table.n_tracks()
        || r.model.n_frames() != fk
        || r.model.n_points() != nk
        || r.affine_structure.ncols() != nk
        || r.points.len() != nk + r.outlier_tracks.len()
        || r.points.iter().filter(|p| p.inlier).count() != nk
        || r.outlier_model.n_points() != r.outlier_tracks.len()
        || r.outlier_tracks.iter().any(|&p| p >= table.n_tracks())
        || r.frames.len() != fk
        || r.kept_frames.iter().any(|&f| f >= table.n_frames())
        || r.kept_tracks.iter().any(|&p| p >= table.n_tracks());
    if bad {
        return Err(Error::Dimension {
            context: "recording::log_reconstruction (table vs reconstruction)",
            expected: format!(
                "a reconstruction of a {}×{} table",
                table.n_frames(),
                table.n_tracks()
            ),
            got: format!(
                "one of a {}×{} table with {} kept frames and {} kept tracks",
                r.input_frame_ids.len(),
                r.input_track_ids.len(),
                fk,
                nk
            ),
        }
        .into());
    }
    Ok(())
}

pub(super) fn log_set_aside(
    rec: &RecordingStream,
    table: &TrackTable,
    r: &Reconstruction,
) -> RecordingResult {
    at_stage(rec, "set-aside");
    // Neither kept nor an outlier of the robust pass (those are drawn by `log_robust`).
    let mut used = vec![false; table.n_tracks()];
    for &p in r.kept_tracks.iter().chain(&r.outlier_tracks) {
        used[p] = true;
    }
    let aside: Vec<usize> = (0..table.n_tracks()).filter(|&p| !used[p]).collect();
    for s in &r.set_aside {
        let what = match s.kind {
            SetAsideKind::Track => "track",
            SetAsideKind::Frame => "frame",
        };
        rec.log(
            paths::LOG_SET_ASIDE,
            &TextLog::new(format!("set aside {what} {}: {}", s.id, s.reason))
                .with_level(TextLogLevel::INFO),
        )?;
    }
    if aside.is_empty() {
        return Ok(());
    }
    let labels = LineStrips2D::update_fields()
        .with_colors([RED])
        .with_labels(
            aside
                .iter()
                .map(|&p| format!("set aside: track {}", table.track_ids()[p])),
        )
        .with_show_labels(show_flagged_labels(aside.len()));
    let [strips, ids] = trajectory_batches(table, &aside)?;
    rec.log(
        paths::SET_ASIDE_TRAJECTORIES,
        &[&strips as &dyn rerun::AsComponents, &ids, &labels],
    )?;
    send_frame_points(
        rec,
        paths::SET_ASIDE_POINTS,
        "set-aside",
        table,
        &aside,
        Some(RED),
        3.0,
    )
}

/// Logs the visibility mask of the whole input table on `factorization/visibility` (an
/// L8 image, white = observed, subsampled per [`RecordingOptions::max_image_side`]) at stage
/// `factorize`.
///
/// Cost: O(F·N).
pub fn log_visibility(
    rec: &RecordingStream,
    table: &TrackTable,
    options: &RecordingOptions,
) -> RecordingResult {
    at_stage(rec, "factorize");
    let rows = subsample(table.n_frames(), options.max_image_side);
    let cols = subsample(table.n_tracks(), options.max_image_side);
    let mut mask = Vec::with_capacity(rows.len() * cols.len());
    for &f in &rows {
        let row = table.frame_row(f);
        mask.extend(
            cols.iter()
                .map(|&p| if row.contains(p) { 255u8 } else { 0 }),
        );
    }
    rec.log(
        paths::VISIBILITY,
        &Image::from_l8(mask, [cols.len() as u32, rows.len() as u32]),
    )?;
    Ok(())
}

/// Logs the measurement matrix W of the given input `frames` and `tracks` (indices into
/// `table`) on `factorization/W` at stage `factorize`: a 2F'×N' f32 tensor with rows x₀, y₀,
/// x₁, y₁, … and NaN where unobserved, subsampled per [`RecordingOptions::max_image_side`].
///
/// Cost: O(F'·N').
pub fn log_measurement_matrix(
    rec: &RecordingStream,
    table: &TrackTable,
    frames: &[usize],
    tracks: &[usize],
    options: &RecordingOptions,
) -> RecordingResult {
    if let Some(&bad) = frames
        .iter()
        .find(|&&f| f >= table.n_frames())
        .or_else(|| tracks.iter().find(|&&p| p >= table.n_tracks()))
    {
        return Err(Error::Dimension {
            context: "recording::log_measurement_matrix (frames, tracks)",
            expected: format!(
                "frame indices below {} and track indices below {}",
                table.n_frames(),
                table.n_tracks()
            ),
            got: bad.to_string(),
        }
        .into());
    }
    at_stage(rec, "factorize");
    let rows = subsample(frames.len(), options.max_image_side / 2);
    let cols = subsample(tracks.len(), options.max_image_side);
    let mut w = vec![f32::NAN; 2 * rows.len() * cols.len()];
    let cols: Vec<usize> = cols.iter().map(|&kp| tracks[kp]).collect();
    for (r, &kf) in rows.iter().enumerate() {
        let (wx, wy) = w[2 * r * cols.len()..(2 * r + 2) * cols.len()].split_at_mut(cols.len());
        let row = table.frame_row(frames[kf]);
        for ((&p, u), v) in cols.iter().zip(wx).zip(wy) {
            if let Some([x, y]) = row.get(p) {
                (*u, *v) = (x as f32, y as f32);
            }
        }
    }
    let w = TensorData::new(
        vec![2 * rows.len() as u64, cols.len() as u64],
        TensorBuffer::F32(w.into()),
    )
    .with_dim_names(["row (2·frame + x|y)", "track"]);
    rec.log(paths::W, &Tensor::new(w))?;
    Ok(())
}

/// The factorization's results: singular values, σ4/σ3 and the affine structure.
pub(super) fn log_factorization(rec: &RecordingStream, r: &Reconstruction) -> RecordingResult {
    at_stage(rec, "factorize");
    rec.log(
        paths::SINGULAR_VALUES,
        &BarChart::new(r.singular_values.clone()),
    )?;
    if r.rank_ratio.is_finite() {
        rec.log(paths::RANK_RATIO, &Scalars::single(r.rank_ratio))?;
    }
    let s = &r.affine_structure;
    rec.log(
        paths::AFFINE_POINTS,
        &Points3D::new(
            (0..s.ncols()).map(|p| [s[(0, p)] as f32, s[(1, p)] as f32, s[(2, p)] as f32]),
        )
        .with_class_ids(r.kept_tracks.iter().map(|&p| class_id(p)))
        .with_show_labels(false),
    )?;
    // The affine frame has no camera: seen along its third axis, its second one down.
    let points = (0..s.ncols()).map(|p| [s[(0, p)] as f32, s[(1, p)] as f32, s[(2, p)] as f32]);
    if let Some(eye) = framing_eye(points, [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]) {
        frame_view(rec, "/affine", eye);
    }
    Ok(())
}

/// Camera centre placed back along the viewing direction `k` (scaled orthographic: by
/// `1/s`, since magnification is inversely proportional to depth).
pub(super) fn camera_centre(model: &MetricModel, f: usize, d: f64) -> nalgebra::Vector3<f64> {
    let k = model.rotations[f].matrix().row(2).transpose();
    let s = model.scales[f];
    let s = if s.is_finite() && s > 0.0 { s } else { 1.0 };
    -k * (d / s)
}

/// A viewing distance: twice the largest distance of a point from the centroid (≥ 1e-9).
pub(super) fn scene_distance(model: &MetricModel) -> f64 {
    let n = model.points.len().max(1) as f64;
    let c = model
        .points
        .iter()
        .fold(nalgebra::Vector3::zeros(), |a, p| a + p)
        / n;
    let r = model
        .points
        .iter()
        .map(|p| (p - c).norm())
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max);
    if r > 0.0 { 2.0 * r } else { 1.0 }
}

/// Cameras of `model` under `base` (`world` or `truth`): a Transform3D per frame on
/// `<base>/camera` (frame timeline value `frame_index[f]`), static camera-local axes on
/// `<base>/camera/axes`, all viewing directions and the centre trajectory under
/// `<base>/cameras/`.
pub(super) fn log_cameras(
    rec: &RecordingStream,
    base: &str,
    model: &MetricModel,
    frame_index: &[usize],
) -> RecordingResult {
    let d = scene_distance(model);
    let centres: Vec<nalgebra::Vector3<f64>> = (0..model.n_frames())
        .map(|f| camera_centre(model, f, d))
        .collect();
    let axis = (0.25 * d) as f32;
    rec.log_static(
        format!("{base}/camera/axes"),
        &Arrows3D::from_vectors([[axis, 0.0, 0.0], [0.0, axis, 0.0], [0.0, 0.0, 2.0 * axis]])
            .with_colors([RED, GREEN, [60, 90, 255]])
            .with_labels(["i", "j", "k (view)"]),
    )?;
    rec.log(
        format!("{base}/cameras/view_directions"),
        &Arrows3D::from_vectors((0..model.n_frames()).map(|f| {
            let k = model.rotations[f].matrix().row(2).transpose();
            f3(&(k * (0.5 * d)))
        }))
        .with_origins(centres.iter().map(f3))
        .with_colors([[60, 90, 255]]),
    )?;
    rec.log(
        format!("{base}/cameras/trajectory"),
        &LineStrips3D::new([LineStrip3D::from_iter(centres.iter().map(f3))]).with_colors([GREY]),
    )?;
    for f in 0..model.n_frames() {
        rec.set_time_sequence(TIMELINE_FRAME, frame_index[f] as i64);
        let r = model.rotations[f].matrix();
        // Columns of the camera-to-world rotation are the camera axes i, j, k (rows of R).
        let cols: [[f32; 3]; 3] =
            std::array::from_fn(|a| std::array::from_fn(|b| r[(a, b)] as f32));
        rec.log(
            format!("{base}/camera"),
            &Transform3D::from_translation_mat3x3(f3(&centres[f]), cols),
        )?;
    }
    rec.disable_timeline(TIMELINE_FRAME);
    Ok(())
}

pub(super) fn upgrade_text(r: &Reconstruction) -> String {
    let u = &r.metric_upgrade;
    let mut s = format!(
        "## Metric upgrade\n\nSolved `L = QQᵀ` by **{}**.\n\n\
         * eigenvalues of the least-squares L: {:.4e}, {:.4e}, {:.4e}\n\
         * eigenvalues of the L used: {:.4e}, {:.4e}, {:.4e}\n\
         * constraint RMS at the L used: {:.3e}\n",
        match u.method {
            UpgradeMethod::LeastSquares => "linear least squares (L positive definite)",
            UpgradeMethod::Sdp => "the PSD-constrained SDP",
        },
        u.eigenvalues_ls[0],
        u.eigenvalues_ls[1],
        u.eigenvalues_ls[2],
        u.eigenvalues[0],
        u.eigenvalues[1],
        u.eigenvalues[2],
        u.constraint_rms
    );
    if u.method == UpgradeMethod::Sdp {
        s.push_str(&format!(
            "* why: the least-squares L's smallest eigenvalue is {:.3e} (not positive definite, \
             or forced)\n* SDP status: {}, {} iterations\n",
            u.min_eigenvalue_ls,
            u.sdp_status.as_deref().unwrap_or("?"),
            u.sdp_iterations.map_or("?".into(), |i| i.to_string())
        ));
    }
    s
}

/// The points of the kept tracks, in `kept_tracks` order: `r.points` holds every kept and
/// outlier track in input order, and the kept ones are the inliers (both ascending).
pub(super) fn kept_points(
    r: &Reconstruction,
) -> impl Iterator<Item = &crate::reconstruction::PointResult> {
    r.points.iter().filter(|p| p.inlier)
}

pub(super) fn log_metric(rec: &RecordingStream, r: &Reconstruction) -> RecordingResult {
    // The world has the first camera's axes: x right, y down, z forward (as the images).
    rec.log_static("world", &rerun::ViewCoordinates::RDF())?;
    at_stage(rec, "metric-upgrade");
    let u = &r.metric_upgrade;
    rec.log(
        paths::EIGENVALUES_LS,
        &BarChart::new(u.eigenvalues_ls.to_vec()),
    )?;
    rec.log(paths::EIGENVALUES, &BarChart::new(u.eigenvalues.to_vec()))?;
    rec.log(
        paths::METRIC_METHOD,
        &TextDocument::from_markdown(upgrade_text(r)),
    )?;
    let max_rms = kept_points(r)
        .map(|p| p.rms_px)
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max);
    rec.log(
        paths::POINTS,
        &Points3D::new(r.model.points.iter().map(f3))
            .with_colors(kept_points(r).map(|p| {
                heat(if max_rms > 0.0 {
                    p.rms_px / max_rms
                } else {
                    0.0
                })
            }))
            .with_class_ids(r.kept_tracks.iter().map(|&p| class_id(p)))
            .with_show_labels(false),
    )?;
    if !r.outlier_tracks.is_empty() {
        rec.log(
            paths::OUTLIER_POINTS,
            &Points3D::new(r.outlier_model.points.iter().map(f3))
                .with_colors([RED])
                .with_class_ids(r.outlier_tracks.iter().map(|&p| class_id(p)))
                // Named on hover: in 3D the labels of nearby points overlap; the image
                // plane labels the outlier tracks' trajectories.
                .with_show_labels(false),
        )?;
    }
    // The view opens on the points, seen from the first camera's side (its rows i, j, k
    // are the world's axes up to the refinement).
    if let Some(r0) = r.model.rotations.first() {
        frame_on_camera(rec, "/world", r.model.points.iter().map(f3), r0.matrix());
    }
    log_cameras(rec, "world", &r.model, &r.kept_frames)
}

pub(super) fn log_residuals(
    rec: &RecordingStream,
    table: &TrackTable,
    r: &Reconstruction,
    options: &RecordingOptions,
) -> RecordingResult {
    at_stage(rec, "refine");
    rec.log(
        paths::POINT_RMS,
        &BarChart::new(kept_points(r).map(|p| p.rms_px).collect::<Vec<f64>>()),
    )?;
    send_residual_arrows(
        rec,
        table,
        r,
        options,
        paths::RESIDUAL_ARROWS,
        "refine",
        |kf, kp| {
            let q = r.model.project(kf, kp);
            [q[0], q[1]]
        },
    )?;
    let rms = Scalars::update_fields()
        .with_scalars(r.frames.iter().map(|f| f.rms_px))
        .columns_of_unit_batches()?;
    send_per_frame(
        rec,
        paths::FRAME_RMS,
        "refine",
        &r.kept_frames,
        rms.collect(),
    )
}

/// Residual arrows (observed → `predict(kept frame, kept track)`) of the kept tracks on
/// `path` per frame at `stage`, sent in blocks of frames
/// ([`RecordingOptions::residual_arrows_per_chunk`]).
#[allow(clippy::too_many_arguments)]
pub(super) fn send_residual_arrows(
    rec: &RecordingStream,
    table: &TrackTable,
    r: &Reconstruction,
    options: &RecordingOptions,
    path: &str,
    stage: &str,
    predict: impl Fn(usize, usize) -> [f64; 2],
) -> RecordingResult {
    let tracks = subsample(r.kept_tracks.len(), options.max_residual_arrows_per_frame);
    let inputs: Vec<usize> = tracks.iter().map(|&kp| r.kept_tracks[kp]).collect();
    // Sent in blocks of frames (RecordingOptions::residual_arrows_per_chunk), so that the
    // SDK's writer encodes a block while the next one is built.
    let block = (options.residual_arrows_per_chunk / tracks.len().max(1)).max(1);
    let frames: Vec<(usize, usize)> = r.kept_frames.iter().copied().enumerate().collect();
    for part in frames.chunks(block) {
        let n = observed_count(table, part.iter().map(|&(_, fi)| fi), &inputs);
        let mut origins = Vec::with_capacity(2 * n);
        let mut vectors = Vec::with_capacity(2 * n);
        let mut ids = Vec::with_capacity(n);
        let mut lengths = Vec::with_capacity(part.len());
        for &(kf, fi) in part {
            let before = ids.len();
            let row = table.frame_row(fi);
            for (&kp, &pi) in tracks.iter().zip(&inputs) {
                if let Some([x, y]) = row.get(pi) {
                    let q = predict(kf, kp);
                    origins.push(x as f32);
                    origins.push(y as f32);
                    vectors.push((q[0] - x) as f32);
                    vectors.push((q[1] - y) as f32);
                    ids.push(class_id(pi));
                }
            }
            lengths.push(ids.len() - before);
        }
        let columns = vec![
            SerializedComponentBatch::new(vec2_array(vectors)?, Arrows2D::descriptor_vectors())
                .partitioned(lengths.iter().copied())?,
            SerializedComponentBatch::new(vec2_array(origins)?, Arrows2D::descriptor_origins())
                .partitioned(lengths.iter().copied())?,
            SerializedComponentBatch::new(class_id_array(ids), Arrows2D::descriptor_class_ids())
                .partitioned(lengths.iter().copied())?,
        ];
        // Track labels on hover only: hundreds of them would cover the image.
        let mut columns = columns;
        columns.extend(
            Arrows2D::update_fields()
                .with_many_show_labels(vec![false; part.len()])
                .columns_of_unit_batches()?,
        );
        let frame_values: Vec<usize> = part.iter().map(|&(_, fi)| fi).collect();
        send_per_frame(rec, path, stage, &frame_values, columns)?;
    }
    Ok(())
}

/// The markdown run summary logged on `summary`: inputs, choices, results, timings,
/// warnings.
pub fn summary_markdown(r: &Reconstruction) -> String {
    let i = &r.input;
    let mut s = String::from("# rank3 reconstruction\n\n## Input\n\n");
    s.push_str(&format!(
        "* {} frames × {} tracks, {} observations ({:.1} % filled)\n\
         * used: {} frames × {} tracks; set aside: {} track(s), {} frame(s)\n",
        i.frames,
        i.tracks,
        i.observations,
        100.0 * i.fill,
        i.frames_used,
        i.tracks_used,
        r.set_aside
            .iter()
            .filter(|a| a.kind == SetAsideKind::Track)
            .count(),
        r.set_aside
            .iter()
            .filter(|a| a.kind == SetAsideKind::Frame)
            .count(),
    ));
    s.push_str("\n## Choices\n\n");
    s.push_str(&format!(
        "* camera model: {}\n* factorization: {} (SVD: {}{})\n* metric upgrade: {}\n\
         * refinement: {}\n* depth-reversal convention mirrored the solution: {}\n",
        r.camera_model,
        r.factorization.method,
        r.factorization.svd_method,
        r.factorization
            .svd_fallback_reason
            .as_deref()
            .map_or(String::new(), |why| format!(", fallback: {why}")),
        crate::output::spelled(&r.metric_upgrade.method),
        match &r.refinement {
            Some(f) if f.skipped.is_some() => {
                format!("skipped ({})", f.skipped.as_deref().unwrap_or(""))
            }
            Some(f) => format!(
                "RMS {:.6} → {:.6} px ({}, {} iterations)",
                f.rms_before_px,
                f.rms_after_px,
                crate::output::spelled(&f.status),
                f.iterations
            ),
            None => "off".into(),
        },
        r.mirrored
    ));
    let sv: Vec<String> = r
        .singular_values
        .iter()
        .take(6)
        .map(|v| format!("{v:.4}"))
        .collect();
    s.push_str(&format!(
        "\n## Results\n\n* singular values: {}\n* σ4/σ3 = {:.4}\n* affine fit RMS: {:.6} px\n\
         * final RMS: {:.6} px\n",
        sv.join(", "),
        r.rank_ratio,
        r.factorization.rms_px,
        r.rms_px
    ));
    if let Some(p) = &r.projective {
        s.push_str(&format!(
            "* camera model: projective (start {}); metric (scaled-orthographic) model RMS \
             {:.6} px\n",
            crate::output::spelled(&p.start),
            r.metric_rms_px
        ));
        for st in &p.stages {
            s.push_str(&format!(
                "* projective {}: RMS {:.6} → {:.6} px ({}, {} iterations)\n",
                st.stage,
                st.rms_before_px,
                st.rms_after_px,
                crate::output::spelled(&st.status),
                st.iterations
            ));
        }
    }
    s.push_str("\n## Timings\n\n| stage | seconds |\n|---|---|\n");
    for t in &r.timings {
        s.push_str(&format!("| {} | {:.4} |\n", t.stage, t.seconds));
    }
    s.push_str("\n## Warnings\n\n");
    if r.warnings.is_empty() {
        s.push_str("none\n");
    }
    for w in &r.warnings {
        s.push_str(&format!("* {w}\n"));
    }
    s.push('\n');
    s.push_str(&upgrade_text(r));
    s
}

/// Logs a failed run's error on `log/errors` (level ERROR) at stage `result`.
pub fn log_error(rec: &RecordingStream, error: &Error) -> RecordingResult {
    at_stage(rec, "result");
    rec.log(
        paths::LOG_ERRORS,
        &TextLog::new(error.to_string()).with_level(TextLogLevel::ERROR),
    )?;
    Ok(())
}
