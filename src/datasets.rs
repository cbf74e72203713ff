//! Locating the public benchmark data sets (never shipped with rank3).
//!
//! The directory is taken from the `RANK3_DATASETS` environment variable, or defaults to
//! `../shared/datasets` next to this crate's manifest.

use std::path::PathBuf;

/// Directory that holds `dino_trimmed/`, `model_house/`, `hotel/`.
pub fn dir() -> PathBuf {
    match std::env::var_os("RANK3_DATASETS") {
        Some(p) => PathBuf::from(p),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/datasets"),
    }
}

/// Path of a file inside the data-set directory if it exists; `None` (with the reason
/// printed to stderr) when it is absent, so tests and examples can say so and skip.
pub fn find(relative: &str) -> Option<PathBuf> {
    let p = dir().join(relative);
    if p.exists() {
        Some(p)
    } else {
        eprintln!(
            "data set file {} not found (set RANK3_DATASETS to the data-set directory); skipping",
            p.display()
        );
        None
    }
}
