//! What a reconstruction prints: the summary on stderr (more of it with `-v`), then its
//! one-line result on stdout.

use rank3::output::spelled;
use std::path::Path;

use rank3::Reconstruction;

use super::verbosity::{self, detail, info, say, warning};

/// Set-aside tracks and frames listed one per line by default; `-v` lists them all.
const SET_ASIDE_LINES: usize = 10;

/// The summary of `rec` (stderr), then its result line (stdout) naming `out`.
pub fn print_summary(rec: &Reconstruction, out: &Path) {
    print_report(rec);
    print_timings(rec);
    let fitted = rec.points.iter().filter(|p| p.inlier).count();
    let outliers = rec.points.len() - fitted;
    say!(
        "{} camera, {} frames, {fitted} points fitted{}, RMS {:.6} px{} → {}",
        rec.camera_model,
        rec.frames.len(),
        if outliers > 0 {
            format!(" ({outliers} outlier tracks left out)")
        } else {
            String::new()
        },
        rec.rms_px,
        rec.perspective.as_ref().map_or(String::new(), |p| format!(
            ", focal {:.1} px",
            p.intrinsics.focal_px
        )),
        out.display()
    );
}

/// With `-v`: the wall-clock time of every stage.
pub fn print_timings(rec: &Reconstruction) {
    if !verbosity::verbose() || rec.timings.is_empty() {
        return;
    }
    let total: f64 = rec.timings.iter().map(|t| t.seconds).sum();
    let stages: Vec<String> = rec
        .timings
        .iter()
        .map(|t| format!("{} {:.3}", t.stage, t.seconds))
        .collect();
    detail!(
        "time per stage (s): {}; total {total:.3} s",
        stages.join(", ")
    );
}

/// Everything `rec` reports, on stderr: warnings always; the stages' results by default;
/// details of each stage with `-v`.
pub fn print_report(rec: &Reconstruction) {
    let n = rec.set_aside.len();
    let listed = if verbosity::verbose() {
        n
    } else {
        n.min(SET_ASIDE_LINES)
    };
    for s in &rec.set_aside[..listed] {
        info!("set aside {} {}: {}", spelled(&s.kind), s.id, s.reason);
    }
    if listed < n {
        info!(
            "… and {} more set aside (all in reconstruction.json's set_aside; -v lists them \
             here)",
            n - listed
        );
    }
    for w in &rec.warnings {
        warning!("{w}");
    }
    let i = &rec.input;
    detail!(
        "input: {} frames × {} tracks, {} observations ({:.1} % filled); used {} frames × {} \
         tracks",
        i.frames,
        i.tracks,
        i.observations,
        100.0 * i.fill,
        i.frames_used,
        i.tracks_used
    );
    if let Some(s) = &rec.sparse {
        detail!(
            "sparse pipeline: {}; {} observations, {} round(s), {} window(s) skipped, \
             affine RMS {:.6} px, {} after {} iterations ({} extended), {} Schur non-zeros, \
             {:.2} s",
            s.reason,
            s.observations,
            s.rounds,
            s.skipped_windows,
            s.rms_px,
            spelled(&s.status),
            s.iterations,
            s.extensions,
            s.schur_nonzeros,
            s.seconds
        );
    }
    let shown = if verbosity::verbose() { 12 } else { 6 };
    let sv: Vec<String> = rec
        .singular_values
        .iter()
        .take(shown)
        .map(|v| format!("{v:.4}"))
        .collect();
    if rec.completion.is_none() {
        info!(
            "singular values: {} (σ4/σ3 = {:.4})",
            sv.join(" "),
            rec.rank_ratio
        );
    } else {
        // With missing data the spectrum is that of the rank-3 completion: σ4/σ3 comes from
        // the largest complete block.
        info!(
            "singular values of the completed matrix: {} (σ4/σ3 = {:.4} on {})",
            sv.join(" "),
            rec.rank_ratio,
            rec.rank_ratio_source
        );
    }
    let f = &rec.factorization;
    detail!(
        "factorization: {} ({} SVD{}), {} singular values computed",
        f.method,
        f.svd_method,
        f.svd_fallback_reason
            .as_ref()
            .map_or(String::new(), |r| format!(", fallback: {r}")),
        rec.singular_values.len()
    );
    if let Some(r) = &rec.robust {
        info!(
            "robust pass: {} inlier / {} outlier tracks, {} gross entries flagged (σ ≈ {:.3} px, \
             RANSAC τ {:.3} px on trimmed RMS, entry threshold {:.3} px, {:.2} s)",
            r.n_inlier_tracks,
            r.n_outlier_tracks,
            r.n_flagged_entries,
            r.noise_sigma_px,
            r.threshold_px,
            r.entry_threshold_px,
            r.seconds
        );
        detail!(
            "robust pass: {} RANSAC iterations, {} rigid group(s) seen, {} track(s) of another \
             object rejected{}",
            r.iterations,
            r.rigid_groups_seen,
            r.other_object_tracks,
            list(
                "outlier tracks",
                r.outlier_tracks.iter().map(ToString::to_string)
            )
        );
    }
    if let Some(c) = &rec.completion {
        info!(
            "completion: {} ({} model) affine RMS {:.6} px, {} after {} iterations{}, {:.2} s",
            c.solver.name(),
            spelled(&c.model),
            c.rms_px,
            spelled(&c.status),
            c.iterations,
            if c.als_sweeps_first > 0 {
                format!(
                    " (after {} ALS sweeps first: its iterations would be costly, \
                     completion.als_first_flops)",
                    c.als_sweeps_first
                )
            } else {
                String::new()
            },
            c.seconds
        );
        detail!("completion: {} run(s), the best kept", c.runs);
    }
    info!(
        "affine fit RMS {:.6} px; metric upgrade by {} (least-squares L min eigenvalue {:.3e})",
        rec.factorization.rms_px,
        spelled(&rec.metric_upgrade.method),
        rec.metric_upgrade.min_eigenvalue_ls
    );
    let m = &rec.metric_upgrade;
    detail!(
        "metric upgrade: least-squares L eigenvalues {:.3e} {:.3e} {:.3e}, used L eigenvalues \
         {:.3e} {:.3e} {:.3e}, constraint RMS {:.3e}{}{}",
        m.eigenvalues_ls[0],
        m.eigenvalues_ls[1],
        m.eigenvalues_ls[2],
        m.eigenvalues[0],
        m.eigenvalues[1],
        m.eigenvalues[2],
        m.constraint_rms,
        m.sdp_status
            .as_ref()
            .map_or(String::new(), |s| format!(", SDP {s}")),
        m.sdp_iterations
            .map_or(String::new(), |k| format!(" after {k} iterations")),
    );
    detail!(
        "depth reversal: the solution was {}mirrored; metric model RMS {:.6} px",
        if rec.mirrored { "" } else { "not " },
        rec.metric_rms_px
    );
    if let Some(r) = &rec.refinement
        && let Some(why) = &r.skipped
    {
        info!("refinement: skipped: {why}");
    } else if let Some(r) = &rec.refinement {
        info!(
            "refinement: RMS {:.6} → {:.6} px ({}, {} iterations, {:.3} s)",
            r.rms_before_px,
            r.rms_after_px,
            spelled(&r.status),
            r.iterations,
            r.seconds
        );
    }
    if let Some(j) = rec.robust.as_ref().and_then(|r| r.projective.as_ref()) {
        info!(
            "projective verdict: {} track(s) readmitted, {} rejected, flagged entries {} → {} \
             (σ ≈ {:.3} px, entry threshold {:.3} px), {} refit(s){}",
            j.readmitted_tracks,
            j.rejected_tracks,
            j.flagged_before,
            j.flagged_after,
            j.noise_sigma_px,
            j.entry_threshold_px,
            j.refits,
            if j.objects_held_out > 0 {
                format!(
                    "; {} other object(s) kept out (their own motion explains them better)",
                    j.objects_held_out
                )
            } else {
                String::new()
            }
        );
        if j.readmissions_not_refitted > 0 {
            info!(
                "projective verdict: {} flagged entr{} it would readmit stay flagged (within                  the fit's noise; not refitted)",
                j.readmissions_not_refitted,
                if j.readmissions_not_refitted == 1 {
                    "y"
                } else {
                    "ies"
                }
            );
        }
    }
    if let Some(p) = &rec.projective {
        let solver = if p.schur_nnz == 0 {
            "reduced camera system solved by conjugate gradients, not formed".to_string()
        } else {
            format!("{} non-zeros in the reduced camera system", p.schur_nnz)
        };
        detail!(
            "projective: started from {}, {solver}, RMS {:.6} px",
            spelled(&p.start),
            p.rms_px
        );
        for s in &p.stages {
            if s.rms_after_px.is_nan() {
                // The windows of a long sequence: no RMS of their own.
                info!(
                    "projective {}: {} windows fitted and chained, {:.3} s",
                    s.stage, s.iterations, s.seconds
                );
                continue;
            }
            info!(
                "projective {}: RMS {:.6} → {:.6} px ({}, {} iterations{}, {:.3} s)",
                s.stage,
                s.rms_before_px,
                s.rms_after_px,
                spelled(&s.status),
                s.iterations,
                if s.cg_iterations > 0 {
                    format!(", {} conjugate-gradient products", s.cg_iterations)
                } else {
                    String::new()
                },
                s.seconds
            );
        }
        let name = |b: &rank3::projective::Bridge| match b {
            rank3::projective::Bridge::Direct => "direct".to_string(),
            rank3::projective::Bridge::Pose { eta } => format!("pOSE η = {eta}"),
        };
        if !p.bridges.is_empty() {
            info!(
                "projective bridges from the affine start: {} (the adjustment started from the \
                 lower; the stages above are its)",
                p.bridges
                    .iter()
                    .map(|b| format!(
                        "{} → RMS {:.6} px ({} iterations, {:.3} s){}",
                        name(&b.bridge),
                        b.start_rms_px,
                        b.iterations,
                        b.seconds,
                        if b.kept { " ←" } else { "" }
                    ))
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        }
        for e in &p.escapes {
            info!(
                "projective escape by {} from RMS {:.6} px: bridge → {:.6} px, adjustment → \
                 {:.6} px ({} iterations, {:.3} s){}",
                name(&e.bridge),
                e.from_rms_px,
                e.bridge_rms_px,
                e.rms_px,
                e.iterations,
                e.seconds,
                if e.kept { ", kept" } else { ", not lower" }
            );
        }
    }
    if let Some(p) = &rec.perspective
        && let Some(sc) = &p.self_calibration
    {
        info!(
            "self-calibration: {} (linear Q eigenvalues {:.3} {:.3} {:.3} {:.3}{}), {:.1} % of \
             observations in front",
            if sc.sdp { "PSD-constrained" } else { "linear" },
            sc.linear_eigenvalues[0],
            sc.linear_eigenvalues[1],
            sc.linear_eigenvalues[2],
            sc.linear_eigenvalues[3],
            sc.sdp_status
                .as_ref()
                .map_or(String::new(), |s| format!(", SDP {s}")),
            100.0 * p.in_front
        );
    }
    if let Some(p) = &rec.perspective {
        let starts: Vec<String> = p
            .starts
            .iter()
            .map(|s| {
                format!(
                    "{}{} f={:.0}: {:.3}{}",
                    s.kind,
                    if s.mirrored { " (mirrored)" } else { "" },
                    s.focal_px,
                    s.rms_px,
                    if s.chosen { " ←" } else { "" }
                )
            })
            .collect();
        let on = p.starts.first().map_or(String::new(), |s| {
            format!(
                " on {} frames × {} tracks",
                s.screen_frames, s.screen_tracks
            )
        });
        info!(
            "perspective starts (RMS px after screening{on}): {}",
            starts.join(", ")
        );
        for s in &p.stages {
            info!(
                "perspective {}: RMS {:.6} → {:.6} px ({}, {} iterations, {:.3} s)",
                s.stage,
                s.rms_before_px,
                s.rms_after_px,
                spelled(&s.status),
                s.iterations,
                s.seconds
            );
        }
        let k = &p.intrinsics;
        info!(
            "intrinsics: focal {:.2} px ({}), principal point ({:.2}, {:.2}) ({}), k1 {:.4}",
            k.focal_px,
            k.focal,
            k.principal_point[0],
            k.principal_point[1],
            k.principal_point_source,
            k.k1
        );
        detail!(
            "perspective: RMS {:.6} px, {:.1} % of observations in front, {} observation(s) \
             down-weighted by the robust loss",
            p.rms_px,
            100.0 * p.in_front,
            p.downweighted.len()
        );
    }
    if let Some(sel) = &rec.model_selection {
        info!("camera model chosen: {}", sel.reason);
    }
    if let Some(m) = &rec.mesh {
        detail!(
            "mesh: surface {:.2} s, texture {:.2} s",
            m.seconds_surface,
            m.seconds_texture
        );
    }
}

/// `; NAME: a, b, c` (at most 20 items), or nothing for an empty list.
fn list(name: &str, items: impl ExactSizeIterator<Item = String>) -> String {
    let n = items.len();
    if n == 0 {
        return String::new();
    }
    let shown: Vec<String> = items.take(20).collect();
    format!(
        "; {name}: {}{}",
        shown.join(", "),
        if n > 20 {
            format!(" … ({} more in reconstruction.json)", n - 20)
        } else {
            String::new()
        }
    )
}
