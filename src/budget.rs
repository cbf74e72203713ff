//! Memory budgets for the allocations whose size user input decides, so that an input too
//! large for an algorithm is a fallback or a typed error, never an abort.
//!
//! * Dense matrices that grow with the square of the frames (the damped Wiberg solver's
//!   `(2F·q)²` Hessian, the metric refinement's `(5F)²`–`(6F)²` reduced camera matrix) are
//!   allowed up to [`DENSE_MATRIX_BYTES`]; above it the completion runs ALS (memory linear in
//!   the observations) and the refinement is skipped, each with a warning.
//! * The track table is dense (F×N entries) until the sparse table lands: a table whose dense
//!   form would exceed both [`DENSE_TABLE_BYTES`] and [`DENSE_TABLE_FACTOR`] times the size of
//!   its observations is refused with [`crate::Error::TooLarge`] before it is allocated.
//! * Frames: an image or video frame above [`FRAME_PIXELS`] pixels is refused before it is
//!   decoded.

/// Largest dense matrix (bytes) a solver may allocate: 1 GiB.
pub const DENSE_MATRIX_BYTES: usize = 1 << 30;

/// A dense track table may always take this many bytes: 1 GiB.
pub const DENSE_TABLE_BYTES: usize = 1 << 30;

/// Above [`DENSE_TABLE_BYTES`], the dense table may still be this many times the
/// observations' own size (tables that are mostly filled).
pub const DENSE_TABLE_FACTOR: usize = 8;

/// Bytes per entry of the dense track table (x, y as f64 and a visibility flag), and per
/// observation as read (frame, track indices and x, y).
pub const TABLE_ENTRY_BYTES: usize = 17;
pub const OBSERVATION_BYTES: usize = 32;

/// Largest frame, pixels: 100 megapixels (e.g. 12 000 × 8 000).
pub const FRAME_PIXELS: u64 = 100_000_000;

/// Bytes of a dense `rows × cols` f64 matrix (saturating).
pub fn matrix_bytes(rows: usize, cols: usize) -> usize {
    rows.saturating_mul(cols).saturating_mul(8)
}

/// Checks the dense F×N table of `observations` observations against the budget.
pub fn check_table(
    path: Option<&std::path::Path>,
    frames: usize,
    tracks: usize,
    observations: usize,
) -> crate::Result<()> {
    let dense = frames
        .saturating_mul(tracks)
        .saturating_mul(TABLE_ENTRY_BYTES);
    let own = observations
        .saturating_mul(OBSERVATION_BYTES)
        .saturating_mul(DENSE_TABLE_FACTOR);
    if dense > DENSE_TABLE_BYTES && dense > own {
        return Err(crate::Error::TooLarge {
            what: format!(
                "the track table{} ({frames} frames × {tracks} tracks, {observations} \
                 observations, {:.3} % filled)",
                path.map_or(String::new(), |p| format!(" of {}", p.display())),
                100.0 * observations as f64 / (frames as f64 * tracks as f64).max(1.0)
            ),
            needed_bytes: dense,
            budget_bytes: DENSE_TABLE_BYTES.max(own),
            advice: "rank3 stores tables densely (F×N) for now; split the sequence into \
                     overlapping windows of frames, or drop tracks seen in few frames"
                .into(),
        });
    }
    Ok(())
}

/// Checks a frame's size before it is decoded.
pub fn check_frame(path: &std::path::Path, width: u64, height: u64) -> crate::Result<()> {
    let pixels = width.saturating_mul(height);
    if pixels > FRAME_PIXELS {
        return Err(crate::Error::TooLarge {
            what: format!("the frame {} ({width} × {height} pixels)", path.display()),
            needed_bytes: (pixels as usize).saturating_mul(4),
            budget_bytes: (FRAME_PIXELS as usize) * 4,
            advice: format!(
                "frames are limited to {} megapixels; downscale the images or the video",
                FRAME_PIXELS / 1_000_000
            ),
        });
    }
    Ok(())
}
