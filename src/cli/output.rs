//! Output writing shared by `reconstruct` and `run`: the refusal to overwrite inputs, the
//! files of a single-object reconstruction (with the mesh and the COLMAP model), and the
//! recording's layout.

use std::path::{Path, PathBuf};

use rank3::Reconstruction;

use super::reconstruct::ReconstructOpts;
use super::summary::print_summary;
use super::verbosity::{detail, info, say, warning};

/// The recording a command writes to (none without the `rerun` feature).
#[cfg(feature = "rerun")]
pub type Recording = Option<rerun::RecordingStream>;
#[cfg(not(feature = "rerun"))]
pub type Recording = ();

/// Refuses, before anything is opened, an output (the .rrd, the output file or folder, the
/// files written in the folder) that would overwrite an input.
pub fn refuse_overwriting_inputs(
    inputs: &[&Path],
    out_dir: Option<&Path>,
    out_file: Option<&Path>,
    #[cfg(feature = "rerun")] record: &rank3::recording::RecordingArgs,
) -> Result<(), rank3::Error> {
    let mut outputs: Vec<(&'static str, PathBuf)> = Vec::new();
    #[cfg(feature = "rerun")]
    if let Some(r) = &record.rrd {
        outputs.push(("--rrd", r.clone()));
    }
    if let Some(f) = out_file {
        outputs.push(("--out", f.to_path_buf()));
    }
    if let Some(d) = out_dir {
        outputs.push(("--out", d.to_path_buf()));
        let written = rank3::output::RECONSTRUCTION_FILES
            .iter()
            .chain(&rank3::output::OBJECTS_FILES)
            .chain(&rank3::mesh::export::MESH_FILES)
            .chain(&["tracks.csv"]);
        outputs.extend(written.map(|n| ("output file", d.join(n))));
    }
    let refs: Vec<(&'static str, &Path)> = outputs.iter().map(|(w, p)| (*w, p.as_path())).collect();
    rank3::output::check_outputs(&refs, inputs)
}

/// Builds the textured mesh when the frames are known (a failure is reported after the
/// reconstruction's files are written, so nothing computed is lost), then writes every
/// output of a single-object run and prints the summary.
pub fn write_outputs(
    mut rec: Reconstruction,
    table: &rank3::TrackTable,
    frames: Option<(&Path, Option<[u32; 2]>)>,
    opts: &ReconstructOpts,
    out: &Path,
    #[cfg(feature = "rerun")] recording: Option<&rerun::RecordingStream>,
) -> Result<(), rank3::Error> {
    let mut mesh_error = None;
    let mesh = match frames {
        Some((path, size)) if !opts.no_mesh => {
            match rank3::mesh::from_frames(&rec, table, path, size, &Default::default()) {
                Ok(m) => Some(m),
                Err(e) => {
                    mesh_error = Some(e);
                    None
                }
            }
        }
        _ => None,
    };
    if let Some(m) = &mesh {
        rec.mesh = Some(m.report.clone());
    }
    let colors: Option<std::collections::HashMap<rank3::Id, [u8; 3]>> = mesh.as_ref().map(|m| {
        table
            .track_ids()
            .iter()
            .zip(&m.track_colors)
            .filter_map(|(id, c)| Some((id.clone(), (*c)?)))
            .collect()
    });
    let mut keep = rank3::output::RECONSTRUCTION_FILES.to_vec();
    if rec.sparse.is_some() {
        // No completed.txt (see output::Written); an earlier run's is removed.
        keep.retain(|&f| f != "completed.txt");
    }
    if rec.perspective.is_some() {
        keep.push("colmap");
    }
    if mesh.is_some() {
        keep.extend(rank3::mesh::export::MESH_FILES);
    }
    rank3::output::remove_stale(out, &keep)?;
    let write_start = std::time::Instant::now();
    let written = rank3::output::write_all_with(
        &rec,
        out,
        rank3::output::PlyOptions {
            colors: colors.as_ref(),
            inliers_only: opts.ply_inliers_only,
        },
    )?;
    if let Some(m) = &mesh {
        rank3::mesh::export::write_all(m, out)?;
        #[cfg(feature = "rerun")]
        if let Some(r) = recording {
            rank3::recording::log_mesh(r, &rec, m)?;
        }
    }
    write_colmap(&rec, table, frames.map(|(p, _)| p), colors.as_ref(), out)?;
    let write_seconds = write_start.elapsed().as_secs_f64();
    print_summary(&rec, out);
    let mut files: Vec<&Path> = vec![&written.json];
    files.extend(written.completed.as_deref());
    files.push(&written.ply);
    detail!(
        "wrote {}{} in {:.2} s",
        files
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", "),
        if mesh.is_some() {
            format!(" and {}", rank3::mesh::export::MESH_FILES.join(", "))
        } else {
            String::new()
        },
        write_seconds
    );
    if let Some(m) = &mesh {
        if let Some(t) = &m.report.texture
            && t.charts_unfilled > 0
        {
            warning!(
                "{} of {} texture charts come from frames that were not given (left \
                 black): {} of the {} frames read matched the table's {} frames by {}",
                t.charts_unfilled,
                t.charts,
                t.frames_matched,
                t.frames_read,
                table.n_frames(),
                t.frames_matched_by
            );
        }
        let s = &m.report.surface;
        let tex = m.report.texture.as_ref().map_or(String::new(), |t| {
            format!(
                ", texture {}×{} px from {} frames",
                t.atlas_px[0], t.atlas_px[1], t.views_used
            )
        });
        say!(
            "mesh: {} triangles on {} tracks{tex} ({:.2} s) → {}",
            s.triangles,
            s.vertices,
            m.report.seconds_surface + m.report.seconds_texture,
            out.join("mesh.glb").display()
        );
    }
    match mesh_error {
        Some(e) => {
            // Part of the error: printed at every level.
            eprintln!("the reconstruction was written; the mesh was not:");
            Err(e)
        }
        None => Ok(()),
    }
}

/// With `--camera auto` the layout sent when the recording opened has no perspective views
/// (the camera was not chosen yet); when the perspective camera was chosen, the layout is
/// sent again with its structure beside the affine model's.
#[cfg(feature = "rerun")]
pub fn show_perspective_layout(
    recording: Option<&rerun::RecordingStream>,
    rec: &Reconstruction,
    camera: super::args::CameraArg,
    parts: rank3::recording::LayoutParts,
) -> Result<(), rank3::Error> {
    if let Some(r) = recording
        && matches!(camera, super::args::CameraArg::Auto)
        && rec.perspective.is_some()
    {
        rank3::recording::send_layout(
            r,
            rank3::recording::LayoutParts {
                perspective: true,
                ..parts
            },
        )?;
    }
    Ok(())
}

/// With a perspective result, the COLMAP text model in `OUT/colmap/`. When the tracks came
/// from a folder of images (`frames`), each image is named by its file, so that COLMAP
/// (`--image_path` = that folder) and OpenMVS find the pictures; a video's frames keep their
/// ids. Its points have the colours of `points.ply` when the frames gave them.
fn write_colmap(
    rec: &Reconstruction,
    table: &rank3::TrackTable,
    frames: Option<&Path>,
    colors: Option<&std::collections::HashMap<rank3::Id, [u8; 3]>>,
    out: &Path,
) -> Result<(), rank3::Error> {
    if rec.perspective.is_none() {
        return Ok(());
    }
    let names: Option<Vec<Option<String>>> = match frames {
        Some(p) if p.is_dir() => {
            rank3::tracking::FrameSource::images(p)?
                .image_files()
                .map(|files| {
                    let by_id: std::collections::HashMap<rank3::Id, String> =
                        files.into_iter().collect();
                    table
                        .frame_ids()
                        .iter()
                        .map(|id| by_id.get(id).cloned())
                        .collect()
                })
        }
        _ => None,
    };
    let dir = out.join("colmap");
    let extras = rank3::output::ColmapExtras {
        image_names: names.as_deref(),
        colors,
    };
    if rank3::output::write_colmap_with(rec, table, &extras, &dir)? {
        match frames {
            Some(p) if names.is_some() => info!(
                "wrote COLMAP model {} (images named by their files in {})",
                dir.display(),
                p.display()
            ),
            _ => info!("wrote COLMAP model {}", dir.display()),
        }
    }
    Ok(())
}
