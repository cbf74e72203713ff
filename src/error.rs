//! Typed errors for bad input and impossible requests.
//!
//! How a solver *ended* (converged, hit its iteration cap, stalled) is not an error:
//! it is reported in [`crate::SolverReport`].

use std::path::PathBuf;

/// Result alias used throughout the crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Everything that can go wrong with user input or a request rank3 cannot honour.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A file could not be opened, read or written.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A value in an input file is malformed; `line` is 1-based, `field` names the column
    /// or key (e.g. `x`, `track`, `row 7 column 12`).
    #[error("{}:{line}: field `{field}`: {message}", path.display())]
    Parse {
        path: PathBuf,
        line: usize,
        field: String,
        message: String,
    },
    /// The file extension does not name a known track-table format.
    #[error(
        "{}: unknown track-table format (expected .csv, .txt, .json, .npy, .npz or a COLMAP \
         text model folder holding images.txt)",
        path.display()
    )]
    UnknownFormat { path: PathBuf },
    /// A NumPy `.npy` / `.npz` input is malformed or is not a track layout rank3 reads
    /// (docs/formats.md): the file, the `.npz` member, the field at fault and the kind of
    /// fault ([`crate::table::npy::ArrayError`], boxed to keep `Error` small).
    #[error(transparent)]
    Array(Box<crate::table::npy::ArrayError>),
    /// The table has no usable observations.
    #[error("empty track table{}: {reason}", source_suffix(.path))]
    EmptyTable {
        path: Option<PathBuf>,
        reason: String,
    },
    /// Too few frames, tracks or observations for the requested computation.
    #[error("not enough {what}: need at least {needed}, have {have}")]
    TooFew {
        what: &'static str,
        needed: usize,
        have: usize,
    },
    /// Matrices or vectors whose sizes do not agree.
    #[error("dimension mismatch in {context}: expected {expected}, got {got}")]
    Dimension {
        context: &'static str,
        expected: String,
        got: String,
    },
    /// A configuration value outside its valid range.
    #[error("invalid configuration `{field}`: {message}")]
    InvalidConfig {
        field: &'static str,
        message: String,
    },
    /// The table has missing entries and the selected path needs complete data.
    #[error(
        "the track table has missing entries ({observed} of {total} observations present); \
         {message}"
    )]
    MissingData {
        observed: usize,
        total: usize,
        message: String,
    },
    /// The observation pattern splits into blocks of frames and tracks that share no
    /// observation, so no single reconstruction relates them.
    #[error(
        "the observations split into {components} disconnected blocks (frames and tracks that \
         share no point); the largest has {largest_frames} frames and {largest_tracks} tracks"
    )]
    Disconnected {
        components: usize,
        largest_frames: usize,
        largest_tracks: usize,
    },
    /// The robust pass found no rigid motion shared by a clear majority of the tracks, so
    /// any single reconstruction would be a confident wrong model.
    #[error(
        "no rigid majority ({reason}): the best rigid group holds {:.0} % of the tracks \
         (at least {:.0} % needed), a rival group {:.0} % — several moving objects \
         (`--objects auto` reconstructs each) or a perspective view that an affine camera \
         cannot explain (`--camera auto` or `perspective`) look like this",
        100.0 * inlier_fraction,
        100.0 * min_inlier_fraction,
        100.0 * rival_fraction
    )]
    NoRigidMajority {
        reason: String,
        inlier_fraction: f64,
        rival_fraction: f64,
        min_inlier_fraction: f64,
    },
    /// An image (or a folder of images) cannot be used as a frame sequence: unreadable or
    /// undecodable file, empty folder, frames of different sizes.
    #[error("{}: {message}", path.display())]
    Image { path: PathBuf, message: String },
    /// A video cannot be decoded: FFmpeg is not installed, cannot read the file, or the
    /// stream ended mid-frame.
    #[error("{}: {message}", path.display())]
    Video { path: PathBuf, message: String },
    /// An in-memory model breaks its own rules (duplicate ids, a reference that resolves to
    /// nothing, a track that disagrees with the observations it lists); see
    /// [`crate::colmap::ColmapModel::validate`]. Read from files, the same faults are
    /// [`Error::Parse`] naming the file, line and field.
    #[error("invalid model: {0}")]
    InvalidModel(String),
    /// The data do not determine a solution (e.g. all points collinear).
    #[error("degenerate input: {0}")]
    Degenerate(String),
    /// An output would overwrite one of the run's inputs (or a file inside an input
    /// folder); refused before anything is opened or written.
    #[error(
        "{what} {} would overwrite the input {}; choose another path",
        output.display(),
        input.display()
    )]
    OutputIsInput {
        what: &'static str,
        output: PathBuf,
        input: PathBuf,
    },
    /// An input too large for a dense structure rank3 would have to allocate
    /// ([`crate::budget`]): refused before the allocation, with what to do instead.
    #[error(
        "{what} would need {:.2} GiB, over the budget of {:.2} GiB: {advice}",
        *needed_bytes as f64 / (1u64 << 30) as f64,
        *budget_bytes as f64 / (1u64 << 30) as f64
    )]
    TooLarge {
        what: String,
        needed_bytes: usize,
        budget_bytes: usize,
        advice: String,
    },
    /// A numerical routine failed in a way that is not the user's fault.
    #[error("numerical failure in {stage}: {message}")]
    Numerical {
        stage: &'static str,
        message: String,
    },
}

fn source_suffix(path: &Option<PathBuf>) -> String {
    match path {
        Some(p) => format!(" ({})", p.display()),
        None => String::new(),
    }
}

impl Error {
    /// Shorthand for an [`Error::Io`].
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }

    /// Shorthand for an [`Error::Parse`].
    pub fn parse(
        path: impl Into<PathBuf>,
        line: usize,
        field: impl Into<String>,
        message: impl Into<String>,
    ) -> Self {
        Error::Parse {
            path: path.into(),
            line,
            field: field.into(),
            message: message.into(),
        }
    }
}
