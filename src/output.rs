//! Writing a reconstruction: `reconstruction.json`, `completed.txt`, `points.ply`.

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::reconstruction::Reconstruction;
use crate::tracks::dense::write_matrix;
use crate::{Error, Result};

/// Paths of the files [`write_all`] wrote.
#[derive(Debug, Clone)]
pub struct Written {
    pub json: PathBuf,
    pub completed: PathBuf,
    pub ply: PathBuf,
}

/// Writes the three outputs into `dir` (created if needed).
pub fn write_all(rec: &Reconstruction, dir: &Path) -> Result<Written> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let json = dir.join("reconstruction.json");
    std::fs::write(&json, rec.to_json()).map_err(|e| Error::io(&json, e))?;
    let completed = dir.join("completed.txt");
    write_completed(rec, &completed)?;
    let ply = dir.join("points.ply");
    write_ply(rec, &ply)?;
    Ok(Written {
        json,
        completed,
        ply,
    })
}

/// The affine prediction of every track in every frame, dense 2F×N in the input's frame and
/// track order (set-aside frames/tracks are `nan`), with comment lines naming the ids.
pub fn write_completed(rec: &Reconstruction, path: &Path) -> Result<()> {
    let m = rec.completed_matrix();
    let ids = |v: &[crate::Id]| {
        v.iter()
            .map(|i| i.to_string())
            .collect::<Vec<_>>()
            .join(" ")
    };
    let mut s = format!(
        "# rank3 completed measurement matrix (affine fit, before the metric upgrade): {} rows \
         (x, y per frame) x {} tracks; nan = set aside\n# frames: {}\n# tracks: {}\n",
        m.nrows(),
        m.ncols(),
        ids(&rec.input_frame_ids),
        ids(&rec.input_track_ids)
    );
    write_matrix(&mut s, m.nrows(), m.ncols(), |r, c| m[(r, c)]);
    std::fs::write(path, s).map_err(|e| Error::io(path, e))
}

/// Binary little-endian PLY with `float x, y, z` per point (and `uchar inlier`).
pub fn write_ply(rec: &Reconstruction, path: &Path) -> Result<()> {
    let mut buf = Vec::with_capacity(64 + rec.points.len() * 13);
    let _ = write!(
        buf,
        "ply\nformat binary_little_endian 1.0\ncomment rank3 metric structure\nelement vertex \
         {}\nproperty float x\nproperty float y\nproperty float z\nproperty uchar inlier\n\
         end_header\n",
        rec.points.len()
    );
    for p in &rec.points {
        for v in p.xyz {
            buf.extend_from_slice(&(v as f32).to_le_bytes());
        }
        buf.push(u8::from(p.inlier));
    }
    std::fs::write(path, buf).map_err(|e| Error::io(path, e))
}
