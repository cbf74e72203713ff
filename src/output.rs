//! Writing a reconstruction: `reconstruction.json`, `completed.txt`, `points.ply`.

use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::reconstruction::Reconstruction;
use crate::table::dense::write_matrix_to;
use crate::{Error, Id, Result};

/// Paths of the files [`write_all`] wrote.
#[derive(Debug, Clone)]
pub struct Written {
    pub json: PathBuf,
    /// Not written (None) for a sparse-pipeline reconstruction: a dense 2F×N matrix of a
    /// table too large to hold densely is not an output anyone can read.
    pub completed: Option<PathBuf>,
    pub ply: PathBuf,
}

/// The files [`write_all`] writes: `reconstruction.json`, `completed.txt`, `points.ply`.
pub const RECONSTRUCTION_FILES: [&str; 3] = ["reconstruction.json", "completed.txt", "points.ply"];

/// The files [`write_objects`] writes besides its `object_<k>/` folders: `objects.csv`,
/// `segmentation.json`.
pub const OBJECTS_FILES: [&str; 2] = ["objects.csv", "segmentation.json"];

/// How `points.ply` is written.
#[derive(Debug, Clone, Copy, Default)]
pub struct PlyOptions<'a> {
    /// Per-track colours by track id (sampled from the frames, [`crate::mesh`]); with them the
    /// PLY has `red`, `green`, `blue` (tracks without a colour are grey).
    pub colors: Option<&'a HashMap<Id, [u8; 3]>>,
    /// Leave the outlier tracks' points out.
    pub inliers_only: bool,
}

/// Writes the three outputs into `dir` (created if needed).
pub fn write_all(rec: &Reconstruction, dir: &Path) -> Result<Written> {
    write_all_with(rec, dir, PlyOptions::default())
}

/// [`write_all`] with the PLY's colours and filter.
pub fn write_all_with(
    rec: &Reconstruction,
    dir: &Path,
    ply_opts: PlyOptions<'_>,
) -> Result<Written> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let [json, completed, ply] = RECONSTRUCTION_FILES.map(|name| dir.join(name));
    // One set: a failure while writing any of them replaces none.
    let mut set = crate::atomic::FileSet::new();
    set.add(&json, rec.to_json())?;
    let completed = if rec.sparse.is_none() {
        set.add_with(&completed, |w| write_completed_to(rec, w))?;
        Some(completed)
    } else {
        None
    };
    set.add(&ply, ply_bytes(rec, ply_opts))?;
    set.commit()?;
    Ok(Written {
        json,
        completed,
        ply,
    })
}

/// The affine prediction of every track in every frame, dense 2F×N in the input's frame and
/// track order (set-aside frames/tracks are `nan`), with comment lines naming the ids.
/// Streamed: the text is formatted a batch of rows at a time and never held whole, nor is
/// the 2F×N matrix ([`Reconstruction::completed_value`]).
pub fn write_completed(rec: &Reconstruction, path: &Path) -> Result<()> {
    crate::atomic::write_with(path, |w| write_completed_to(rec, w))
}

/// The text of [`write_completed`], written to `w`.
fn write_completed_to(rec: &Reconstruction, w: &mut impl std::io::Write) -> std::io::Result<()> {
    let (rows, cols) = (2 * rec.input_frame_ids.len(), rec.input_track_ids.len());
    let ids = |v: &[crate::Id]| {
        v.iter()
            .map(|i| i.to_string())
            .collect::<Vec<_>>()
            .join(" ")
    };
    write!(
        w,
        "# rank3 completed measurement matrix (affine fit, before the metric upgrade): {rows} \
         rows (x, y per frame) x {cols} tracks; nan = set aside\n# frames: {}\n# tracks: {}\n",
        ids(&rec.input_frame_ids),
        ids(&rec.input_track_ids)
    )?;
    write_matrix_to(w, rows, cols, rec.completed_value())
}

/// Binary little-endian PLY with `float x, y, z` per point (and `uchar inlier`).
/// With a perspective result, its Euclidean points; otherwise the metric (affine-family)
/// ones.
pub fn write_ply(rec: &Reconstruction, path: &Path) -> Result<()> {
    write_ply_with(rec, path, PlyOptions::default())
}

/// [`write_ply`] with `uchar red, green, blue` after `z` when colours are given, and only
/// the inlier points when asked.
pub fn write_ply_with(rec: &Reconstruction, path: &Path, opts: PlyOptions<'_>) -> Result<()> {
    crate::atomic::write(path, ply_bytes(rec, opts))
}

/// The bytes of [`write_ply_with`].
fn ply_bytes(rec: &Reconstruction, opts: PlyOptions<'_>) -> Vec<u8> {
    let points: Vec<_> = rec
        .perspective
        .as_ref()
        .map_or(&rec.points, |p| &p.points)
        .iter()
        .filter(|p| p.inlier || !opts.inliers_only)
        .collect();
    let mut buf = Vec::with_capacity(128 + points.len() * 16);
    let _ = write!(
        buf,
        "ply\nformat binary_little_endian 1.0\ncomment rank3 metric structure\nelement vertex \
         {}\nproperty float x\nproperty float y\nproperty float z\n{}property uchar inlier\n\
         end_header\n",
        points.len(),
        if opts.colors.is_some() {
            "property uchar red\nproperty uchar green\nproperty uchar blue\n"
        } else {
            ""
        }
    );
    for p in points {
        for v in p.xyz {
            buf.extend_from_slice(&(v as f32).to_le_bytes());
        }
        if let Some(colors) = opts.colors {
            buf.extend_from_slice(&colors.get(&p.track).copied().unwrap_or([128, 128, 128]));
        }
        buf.push(u8::from(p.inlier));
    }
    buf
}

/// The perspective reconstruction of `rec` as a COLMAP sparse model ([`crate::colmap`]):
/// one `SIMPLE_PINHOLE` camera (`SIMPLE_RADIAL` when `k₁ ≠ 0`) shared by every image, or
/// one per image with per-frame focal lengths; one image per fitted frame, named by its
/// frame id (white space replaced by `_`; [`colmap_model_with`] names them by their image
/// files, so that COLMAP and OpenMVS find the pictures), with every observation of `table` in that frame
/// as a keypoint; one 3D point per fitted track, its track the keypoints the fit used
/// (entries the robust pass flagged stay keypoints without a 3D point), its error the
/// track's reprojection RMS. Pixel coordinates are shifted by
/// [`crate::colmap::PIXEL_CENTRE_OFFSET`] (rank3 puts the centre of the top-left pixel at
/// (0, 0), COLMAP at (0.5, 0.5)). The image size is the given one, else the smallest that
/// holds every observation. `None` without a perspective result. `O(observations)`.
pub fn colmap_model(
    rec: &Reconstruction,
    table: &crate::TrackTable,
) -> Option<crate::colmap::ColmapModel> {
    colmap_model_with(rec, table, &ColmapExtras::default())
}

/// What the frames add to a COLMAP model ([`colmap_model_with`]).
#[derive(Debug, Clone, Copy, Default)]
pub struct ColmapExtras<'a> {
    /// One per frame of the table: the frame's image file, relative to the folder COLMAP is
    /// given as `--image_path`, so that COLMAP's `image_undistorter` and OpenMVS's
    /// `InterfaceCOLMAP` find the pictures. A frame without one (`None`, or no list) is named
    /// by its frame id.
    pub image_names: Option<&'a [Option<String>]>,
    /// The tracks' colours (the same as `points.ply`'s); a track without one is grey (128).
    pub colors: Option<&'a std::collections::HashMap<crate::Id, [u8; 3]>>,
}

/// [`colmap_model`] with the images named by their files and the points coloured
/// ([`ColmapExtras`]).
pub fn colmap_model_with(
    rec: &Reconstruction,
    table: &crate::TrackTable,
    extras: &ColmapExtras<'_>,
) -> Option<crate::colmap::ColmapModel> {
    use crate::colmap::{
        ColmapCamera, ColmapCameraModel, ColmapImage, ColmapModel, ColmapPoint,
        PIXEL_CENTRE_OFFSET as OFF,
    };
    let per = rec.perspective.as_ref()?;
    let m = &per.model;
    let (w, h) = match per.intrinsics.image_size {
        Some([w, h]) => (w, h),
        None => {
            let (mut mx, mut my) = (1.0f64, 1.0f64);
            for f in 0..table.n_frames() {
                for e in table.frame_row(f).entries() {
                    mx = mx.max(e.x + 1.0);
                    my = my.max(e.y + 1.0);
                }
            }
            (mx.ceil() as u32, my.ceil() as u32)
        }
    };
    let (cx, cy) = (m.principal_point[0] + OFF, m.principal_point[1] + OFF);
    let camera = |id: u32, f: f64| ColmapCamera {
        id,
        // Non-square pixels: focal lengths `aspect · f` along x and `f` along y.
        model: if m.aspect != 1.0 && m.k1 != 0.0 {
            ColmapCameraModel::Opencv {
                fx: m.aspect * f,
                fy: f,
                cx,
                cy,
                k1: m.k1,
                k2: 0.0,
                p1: 0.0,
                p2: 0.0,
            }
        } else if m.aspect != 1.0 {
            ColmapCameraModel::Pinhole {
                fx: m.aspect * f,
                fy: f,
                cx,
                cy,
            }
        } else if m.k1 != 0.0 {
            ColmapCameraModel::SimpleRadial { f, cx, cy, k: m.k1 }
        } else {
            ColmapCameraModel::SimplePinhole { f, cx, cy }
        },
        width: w,
        height: h,
    };
    let shared = per.intrinsics.focal != "per-frame";
    let nf = rec.kept_frames.len();
    let cameras: Vec<ColmapCamera> = if shared {
        vec![camera(1, m.focal_px[0])]
    } else {
        (0..nf)
            .map(|k| camera(k as u32 + 1, m.focal_px[k]))
            .collect()
    };
    // Input track index → 3D point id (fitted tracks), and the flagged entries.
    let mut point_of = vec![None; table.n_tracks()];
    for (k, &p) in rec.kept_tracks.iter().enumerate() {
        point_of[p] = Some(k as u64 + 1);
    }
    let flagged: std::collections::HashSet<(usize, usize)> = rec
        .robust
        .as_ref()
        .map(|r| r.flagged_indices.iter().copied().collect())
        .unwrap_or_default();
    let rms_of: std::collections::HashMap<String, f64> = per
        .points
        .iter()
        .map(|r| (r.track.to_string(), r.rms_px))
        .collect();
    let mut points: Vec<ColmapPoint> = rec
        .kept_tracks
        .iter()
        .enumerate()
        .map(|(k, &p)| {
            let x = m.points[k];
            let err = rms_of
                .get(&table.track_ids()[p].to_string())
                .copied()
                .unwrap_or(-1.0);
            ColmapPoint {
                id: k as u64 + 1,
                xyz: [x[0], x[1], x[2]],
                rgb: extras
                    .colors
                    .and_then(|c| c.get(&table.track_ids()[p]).copied())
                    .unwrap_or([128, 128, 128]),
                error: if err.is_finite() { err } else { -1.0 },
                track: Vec::new(),
            }
        })
        .collect();
    let mut images = Vec::with_capacity(nf);
    for (k, &f) in rec.kept_frames.iter().enumerate() {
        let id = k as u32 + 1;
        let row = table.frame_row(f).entries();
        let mut points2d = Vec::with_capacity(row.len());
        for e in row {
            let p = e.track as usize;
            let pid = point_of[p].filter(|_| !flagged.contains(&(f, p)));
            if let Some(pid) = pid {
                points[pid as usize - 1].track.push((id, points2d.len()));
            }
            points2d.push(([e.x + OFF, e.y + OFF], pid));
        }
        let name: String = extras
            .image_names
            .and_then(|n| n.get(f).cloned().flatten())
            .unwrap_or_else(|| table.frame_ids()[f].to_string())
            .chars()
            .map(|c| if c.is_whitespace() { '_' } else { c })
            .collect();
        images.push(ColmapImage {
            id,
            camera_id: if shared { 1 } else { id },
            name,
            rotation: m.rotations[k],
            translation: m.translations[k],
            points2d,
        });
    }
    // A point whose entries were all flagged has no track: COLMAP needs at least one.
    points.retain(|p| !p.track.is_empty());
    let keep: std::collections::HashSet<u64> = points.iter().map(|p| p.id).collect();
    for im in &mut images {
        for kp in &mut im.points2d {
            if kp.1.is_some_and(|id| !keep.contains(&id)) {
                kp.1 = None;
            }
        }
    }
    Some(ColmapModel {
        cameras,
        images,
        points,
    })
}

/// Writes [`colmap_model`] into `dir` (cameras.txt, images.txt, points3D.txt); returns
/// whether there was a perspective result to write.
pub fn write_colmap(rec: &Reconstruction, table: &crate::TrackTable, dir: &Path) -> Result<bool> {
    write_colmap_with(rec, table, &ColmapExtras::default(), dir)
}

/// [`write_colmap`] with what the frames add ([`ColmapExtras`]).
pub fn write_colmap_with(
    rec: &Reconstruction,
    table: &crate::TrackTable,
    extras: &ColmapExtras<'_>,
    dir: &Path,
) -> Result<bool> {
    match colmap_model_with(rec, table, extras) {
        Some(model) => model.write_text(dir).map(|_| true),
        None => Ok(false),
    }
}

/// Files of a multi-object run in `dir`: `objects.csv` (`track,object` for every input
/// track, −1 = outlier or unscored), `segmentation.json` ([`crate::objects::MultiBodyReport`])
/// and, per object reconstructed, `object_<k>/` with [`write_all`]'s files. Returns the
/// object folders written.
pub fn write_objects(
    mb: &crate::objects::MultiBody,
    given: bool,
    dir: &Path,
) -> Result<Vec<std::path::PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let [csv, json] = OBJECTS_FILES.map(|name| dir.join(name));
    crate::atomic::write(&csv, mb.objects_csv())?;
    let text = serde_json::to_string_pretty(&mb.report(given)).expect("serializable report");
    crate::atomic::write(&json, text)?;
    let mut dirs = Vec::new();
    for o in &mb.objects {
        if let Ok(rec) = &o.reconstruction {
            let d = dir.join(crate::objects::object_dir(o.index));
            write_all(rec, &d)?;
            dirs.push(d);
        }
    }
    Ok(dirs)
}

/// Refuses outputs that would overwrite an input, before anything is opened or written:
/// an output path that is one of `inputs` (the same file, through any links), or an existing
/// file inside an input folder (a frame of an image sequence). `outputs` pairs each path
/// with what it is (`"--rrd"`, `"--out"`, …); paths that do not exist yet cannot be inputs
/// and pass.
///
/// Errors: [`Error::OutputIsInput`] naming both paths.
pub fn check_outputs(outputs: &[(&'static str, &Path)], inputs: &[&Path]) -> Result<()> {
    let inputs: Vec<(std::path::PathBuf, &Path)> = inputs
        .iter()
        .filter_map(|p| std::fs::canonicalize(p).ok().map(|c| (c, *p)))
        .collect();
    for &(what, out) in outputs {
        let Ok(co) = std::fs::canonicalize(out) else {
            continue;
        };
        for (ci, input) in &inputs {
            if co == *ci || (ci.is_dir() && co.is_file() && co.starts_with(ci)) {
                return Err(Error::OutputIsInput {
                    what,
                    output: out.to_path_buf(),
                    input: input.to_path_buf(),
                });
            }
        }
    }
    Ok(())
}

/// Removes from `dir` the outputs of an earlier run that this run will not write, so that
/// every rank3 output in the folder belongs to this run: the files of
/// `reconstruction.json`, `completed.txt`, `points.ply`, `objects.csv`,
/// `segmentation.json`, `mesh.obj`, `mesh.mtl`, `mesh_texture.png`, `mesh.glb` not in `keep`, and the folders `colmap/` and `object_<k>/` not in
/// `keep` (their rank3 files, then the folder if that left it empty). Nothing else is
/// touched (not `tracks.csv`, not files of the user's). A missing `dir` is fine.
pub fn remove_stale(dir: &Path, keep: &[&str]) -> Result<()> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Ok(());
    };
    let remove_file = |p: &Path| match std::fs::remove_file(p) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(Error::io(p, e)),
        _ => Ok(()),
    };
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if keep.contains(&name.as_str()) {
            continue;
        }
        let path = entry.path();
        let is_dir = entry.file_type().is_ok_and(|t| t.is_dir());
        let object_dir = name
            .strip_prefix("object_")
            .is_some_and(|k| !k.is_empty() && k.bytes().all(|b| b.is_ascii_digit()));
        let rank3_file = RECONSTRUCTION_FILES
            .iter()
            .chain(&OBJECTS_FILES)
            .chain(&crate::mesh::export::MESH_FILES)
            .any(|f| *f == name);
        if !is_dir && rank3_file {
            remove_file(&path)?;
        } else if is_dir && (object_dir || name == "colmap") {
            let inner: &[&str] = if name == "colmap" {
                &[
                    crate::colmap::CAMERAS_TXT,
                    crate::colmap::IMAGES_TXT,
                    crate::colmap::POINTS3D_TXT,
                ]
            } else {
                &RECONSTRUCTION_FILES
            };
            for f in inner {
                remove_file(&path.join(f))?;
            }
            let _ = std::fs::remove_dir(&path); // only when empty
        }
    }
    Ok(())
}

/// An enum value as the JSON outputs spell it (`least-squares`, `converged`, …), so that the
/// log and reconstruction.json use one spelling.
pub fn spelled<T: serde::Serialize>(v: &T) -> String {
    match serde_json::to_value(v) {
        Ok(serde_json::Value::String(s)) => s,
        Ok(other) => other.to_string(),
        Err(_) => "?".into(),
    }
}
