use rerun::{
    LineStrip3D, LineStrips3D, Points3D, RecordingStream, Scalars, TextDocument, Transform3D,
};

use crate::{Reconstruction, TrackTable};

use super::bulk::{GREY, RED, f3, heat, send_per_frame};
use super::layout::frame_on_camera;
use super::reconstruction::send_residual_arrows;
use super::{RecordingOptions, RecordingResult, TIMELINE_FRAME, at_stage, paths};

/// The projective stages (camera `projective`): residual arrows to `π(P_f X_p)`, per-frame
/// RMS, and a table of each stage's RMS before/after at stage `projective`. Nothing for
/// the affine cameras.
pub(super) fn log_projective(
    rec: &RecordingStream,
    table: &TrackTable,
    r: &Reconstruction,
    options: &RecordingOptions,
) -> RecordingResult {
    let Some(p) = &r.projective else {
        return Ok(());
    };
    send_residual_arrows(
        rec,
        table,
        r,
        options,
        paths::PROJECTIVE_RESIDUALS,
        "projective",
        |kf, kp| p.model.project(kf, kp),
    )?;
    let rms = Scalars::update_fields()
        .with_scalars(p.cameras.iter().map(|c| c.rms_px))
        .columns_of_unit_batches()?;
    send_per_frame(
        rec,
        paths::PROJECTIVE_FRAME_RMS,
        "projective",
        &r.kept_frames,
        rms.collect(),
    )?;
    at_stage(rec, "projective");
    rec.log(
        paths::PROJECTIVE_STAGES,
        &TextDocument::from_markdown(projective_markdown(p)),
    )?;
    Ok(())
}

/// The perspective reconstruction: residual arrows, Euclidean points, the camera path with
/// pinhole frustums of the estimated intrinsics, and a report.
pub(super) fn log_perspective(
    rec: &RecordingStream,
    table: &TrackTable,
    r: &Reconstruction,
    options: &RecordingOptions,
) -> RecordingResult {
    let Some(p) = &r.perspective else {
        return Ok(());
    };
    let m = &p.model;
    send_residual_arrows(
        rec,
        table,
        r,
        options,
        paths::PERSPECTIVE_RESIDUALS,
        "perspective",
        |kf, kp| m.project(kf, kp),
    )?;
    at_stage(rec, "perspective");
    rec.log_static("perspective/world", &rerun::ViewCoordinates::RDF())?;
    let fitted: Vec<&crate::reconstruction::PointResult> =
        p.points.iter().filter(|q| q.inlier).collect();
    let max_rms = fitted
        .iter()
        .map(|q| q.rms_px)
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max)
        .max(1e-12);
    // The unit is the points' RMS spread about their centroid: sizes relative to it.
    rec.log(
        paths::PERSPECTIVE_POINTS,
        &Points3D::new(m.points.iter().map(f3))
            .with_colors(fitted.iter().map(|q| heat(q.rms_px / max_rms)))
            .with_radii([0.01f32]),
    )?;
    if let Some(r0) = m.rotations.first() {
        frame_on_camera(rec, "/perspective/world", m.points.iter().map(f3), r0);
    }
    rec.log(
        paths::PERSPECTIVE_OUTLIERS,
        &Points3D::new(
            p.outlier_points
                .iter()
                .filter(|x| x.iter().all(|v| v.is_finite()))
                .map(f3),
        )
        .with_colors([RED])
        .with_radii([0.012f32]),
    )?;
    let nf = m.rotations.len();
    let centres: Vec<nalgebra::Vector3<f64>> = (0..nf).map(|f| m.centre(f)).collect();
    rec.log(
        paths::PERSPECTIVE_TRAJECTORY,
        &LineStrips3D::new([LineStrip3D::from_iter(centres.iter().map(f3))]).with_colors([GREY]),
    )?;
    let size = p
        .intrinsics
        .image_size
        .map(|[w, h]| [w as f32, h as f32])
        .unwrap_or([
            (2.0 * m.principal_point[0] + 1.0) as f32,
            (2.0 * m.principal_point[1] + 1.0) as f32,
        ]);
    let pinhole = |f: usize| {
        rerun::Pinhole::from_focal_length_and_resolution(
            [(m.aspect * m.focal_px[f]) as f32, m.focal_px[f] as f32],
            size,
        )
        .with_principal_point([m.principal_point[0] as f32, m.principal_point[1] as f32])
        .with_image_plane_distance(0.15f32)
    };
    // Camera-to-world: translation = centre, rotation = Rᵀ (its columns are the camera's
    // x (right), y (down), z (forward) axes, Rerun's default RDF pinhole frame).
    let pose = |f: usize| {
        let rt = m.rotations[f].transpose();
        let cols: [[f32; 3]; 3] =
            std::array::from_fn(|c| std::array::from_fn(|row| rt[(row, c)] as f32));
        Transform3D::from_translation_mat3x3(f3(&centres[f]), cols)
    };
    let step = nf.div_ceil(24).max(1);
    for f in (0..nf).step_by(step) {
        let path = format!("{}/{f}", paths::PERSPECTIVE_FRUSTUMS);
        rec.log_static(path.clone(), &pose(f))?;
        rec.log_static(path, &pinhole(f))?;
    }
    for f in 0..nf {
        rec.set_time_sequence(TIMELINE_FRAME, r.kept_frames[f] as i64);
        rec.log(paths::PERSPECTIVE_CAMERA, &pose(f))?;
        rec.log(paths::PERSPECTIVE_CAMERA, &pinhole(f))?;
    }
    rec.disable_timeline(TIMELINE_FRAME);
    rec.log(
        paths::PERSPECTIVE_REPORT,
        &TextDocument::from_markdown(perspective_markdown(p)),
    )?;
    Ok(())
}

/// Markdown report of the perspective stages.
pub(super) fn perspective_markdown(p: &crate::reconstruction::PerspectiveResult) -> String {
    let k = &p.intrinsics;
    let mut s = format!(
        "# Perspective reconstruction\n\nRMS {:.6} px; {:.1} % of the observations in front of \
         their camera.\n\n## Intrinsics\n\n* focal length {:.2} px ({})\n* principal point \
         ({:.2}, {:.2}) ({})\n* k₁ {:.5}\n",
        p.rms_px,
        100.0 * p.in_front,
        k.focal_px,
        k.focal,
        k.principal_point[0],
        k.principal_point[1],
        k.principal_point_source,
        k.k1
    );
    if let Some(sc) = &p.self_calibration {
        s.push_str(&format!(
            "\n## Self-calibration\n\n* linear absolute dual quadric eigenvalues: {:.4} {:.4} \
             {:.4} {:.4}\n* PSD-constrained solve: {}\n",
            sc.linear_eigenvalues[0],
            sc.linear_eigenvalues[1],
            sc.linear_eigenvalues[2],
            sc.linear_eigenvalues[3],
            sc.sdp_status.as_deref().unwrap_or("not needed")
        ));
    }
    if let Some(st) = p.starts.first() {
        s.push_str(&format!(
            "\n## Starts (screened on {} frames × {} tracks)\n\n",
            st.screen_frames, st.screen_tracks
        ));
    }
    s.push_str(
        "| start | focal (px) | mirrored | RMS (px) | kept |\n\
         |---|---|---|---|---|\n",
    );
    for st in &p.starts {
        s.push_str(&format!(
            "| {} | {:.1} | {} | {:.4} | {} |\n",
            st.kind,
            st.focal_px,
            st.mirrored,
            st.rms_px,
            if st.chosen { "✓" } else { "" }
        ));
    }
    s.push_str("\n## Adjustment\n\n");
    s.push_str(&stages_table(&p.stages));
    s
}

/// Markdown table of the projective stages.
pub(super) fn projective_markdown(p: &crate::reconstruction::ProjectiveResult) -> String {
    format!(
        "# Projective reconstruction\n\nstart: {}; final RMS {:.6} px; reduced camera system \
         {} non-zeros (0: solved by conjugate gradients, not formed)\n\n{}",
        crate::output::spelled(&p.start),
        p.rms_px,
        p.schur_nnz,
        stages_table(&p.stages)
    )
}

/// Markdown table of solver stages: status, iterations, RMS before and after, seconds.
pub(super) fn stages_table(stages: &[crate::projective::StageReport]) -> String {
    let mut s = String::from(
        "| stage | status | iterations | RMS before (px) | RMS after (px) | s | reduced system |\n\
         |---|---|---|---|---|---|---|\n",
    );
    for st in stages {
        s.push_str(&format!(
            "| {} | {} | {} | {:.6} | {:.6} | {:.3} | {} |\n",
            st.stage,
            crate::output::spelled(&st.status),
            st.iterations,
            st.rms_before_px,
            st.rms_after_px,
            st.seconds,
            match st.linear_solver {
                Some(crate::projective::bundle::LinearSolver::Iterative) => {
                    format!("conjugate gradients, {} products", st.cg_iterations)
                }
                Some(_) => "sparse Cholesky".to_string(),
                None => "–".to_string(),
            }
        ));
    }
    s
}
