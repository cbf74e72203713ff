//! How an iterative solver ended: data, not an error.

use serde::{Deserialize, Serialize};

/// Why an iterative solver stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SolverStatus {
    /// A convergence test was met (relative cost decrease, step or gradient tolerance).
    Converged,
    /// The iteration cap was reached before convergence.
    MaxIterations,
    /// No further progress was possible (e.g. damping grew past its bound) before the
    /// convergence tests were met.
    Stalled,
}

/// Summary of one solver run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SolverReport {
    pub status: SolverStatus,
    pub iterations: usize,
    /// Cost at the start (sum of squared residuals unless documented otherwise).
    pub initial_cost: f64,
    /// Cost at the end.
    pub final_cost: f64,
    /// Wall-clock seconds.
    pub seconds: f64,
}
