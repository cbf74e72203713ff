//! Memory budgets for the allocations whose size user input decides, so that an input too
//! large for an algorithm is a fallback or a typed error, never an abort.
//!
//! * Dense matrices that grow with the square of the frames (the damped Wiberg solver's
//!   `(2F·q)²` Hessian, the metric refinement's `(5F)²`–`(6F)²` reduced camera matrix) are
//!   allowed up to [`DENSE_MATRIX_BYTES`]; above it the completion runs ALS (memory linear in
//!   the observations) and the refinement is skipped, each with a warning.
//! * The track table is sparse (memory of its observations); the dense pipeline's `2F×N`
//!   matrix is built only when it fits [`DENSE_TABLE_BYTES`] or [`DENSE_TABLE_FACTOR`] times
//!   the size of the observations; larger tables run the sparse pipeline
//!   ([`crate::sparse`]), or are refused with [`crate::Error::TooLarge`] when the dense one
//!   is forced.
//! * Frames: an image or video frame above [`FRAME_PIXELS`] pixels is refused before it is
//!   decoded.

/// Largest dense matrix (bytes) a solver may allocate: 1 GiB.
pub const DENSE_MATRIX_BYTES: usize = 1 << 30;

/// A dense track table may always take this many bytes: 1 GiB.
pub const DENSE_TABLE_BYTES: usize = 1 << 30;

/// Above [`DENSE_TABLE_BYTES`], the dense table may still be this many times the
/// observations' own size (tables that are mostly filled).
pub const DENSE_TABLE_FACTOR: usize = 8;

/// Bytes per entry of the dense `2F×N` matrix and mask (x, y as f64 and a visibility flag),
/// and per observation of the sparse table (frame, track indices and x, y).
pub const TABLE_ENTRY_BYTES: usize = 17;
pub const OBSERVATION_BYTES: usize = 32;

/// Largest frame, pixels: 100 megapixels (e.g. 12 000 × 8 000).
pub const FRAME_PIXELS: u64 = 100_000_000;

/// Bytes of a dense `rows × cols` f64 matrix (saturating).
pub fn matrix_bytes(rows: usize, cols: usize) -> usize {
    rows.saturating_mul(cols).saturating_mul(8)
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
