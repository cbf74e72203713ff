//! # rank3
//!
//! Structure and motion from 2D point tracks by Tomasi–Kanade factorization,
//! made to work on real, partial, messy track tables.
//!
//! Pipeline: [`table::TrackTable`] → set-aside of under-observed tracks and frames →
//! observation matrix `W` (2F×N) → rank-3 factorization (centering + truncated SVD for
//! complete data, low-rank completion for missing data) → metric upgrade
//! ([`metric`]) → Levenberg–Marquardt refinement ([`refine`]) → [`reconstruction::Reconstruction`].
//! Tables whose dense W does not fit run the [`sparse`] pipeline (memory linear in the
//! observations).
//!
//! References: C. Tomasi and T. Kanade, "Shape and motion from image streams under
//! orthography: a factorization method", IJCV 9(2), 1992; C. J. Poelman and T. Kanade,
//! "A paraperspective factorization method for shape and motion recovery", PAMI 19(3), 1997.

// Numeric code: index loops mirror the math, and `!(a > b)` is the NaN-safe comparison.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

#[cfg(feature = "builtin-lapack")]
mod lapack_shim;

pub mod atomic;
pub mod budget;
pub mod camera;
pub mod colmap;
pub mod compare;
pub mod completion;
pub mod datasets;
pub mod degeneracy;
pub mod error;
pub mod eval;
pub mod measurements;
pub mod mesh;
pub mod metric;
pub mod objects;
pub mod observer;
pub mod output;
pub mod perspective;
pub mod pixel_aspect;
pub mod projective;
pub mod reconstruction;
pub mod reconstruction_file;
#[cfg(feature = "rerun")]
pub mod recording;
pub mod refine;
pub mod robust;
pub mod sdp;
pub mod segment;
pub mod settings;
pub mod solver;
pub mod sparse;
pub mod stream;
pub mod svd;
pub mod synth;
pub mod table;
pub mod tracking;

pub use camera::{CameraModel, MetricModel};
pub use error::{Error, Result};
pub use measurements::Measurements;
pub use observer::{Both, Event, NoopObserver, Observer};
pub use reconstruction::{Config, Reconstruction};
pub use solver::{SolverReport, SolverStatus};
pub use table::{Id, TrackTable};

/// The README's code examples, compiled and run by `cargo test` (doctests).
#[doc = include_str!("../README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctests;
