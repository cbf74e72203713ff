//! Metric camera models and the metric reconstruction they parameterize.
//!
//! Orthographic camera (Tomasi & Kanade 1992): `[x, y]ᵀ = R_f[0..2] X_p + t_f`.
//! Scaled orthographic / weak perspective (Poelman & Kanade 1997):
//! `[x, y]ᵀ = s_f R_f[0..2] X_p + t_f`, with `s_f > 0` the per-frame magnification.
//! `R_f` is a rotation whose rows are the camera axes `i_f, j_f, k_f = i_f × j_f` in world
//! coordinates, `t_f` the image translation (pixels).

use faer::Mat;
use nalgebra::{Matrix3, Rotation3, Vector2, Vector3};
use serde::{Deserialize, Serialize};

use crate::Measurements;

/// Which metric camera the upgrade and the refinement use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CameraModel {
    /// Orthographic projection: unit scale in every frame.
    #[default]
    Orthographic,
    /// Scaled orthographic (weak perspective): one positive scale per frame.
    ScaledOrthographic,
    /// Projective camera `w ≃ P_f X_p`, `P_f` a 3×4 matrix, `X_p` homogeneous: the
    /// reconstruction is defined up to a 4×4 homography ([`crate::projective`]). The affine
    /// stages (warm start, metric blocks of the result) run with the scaled orthographic
    /// model.
    Projective,
    /// Pinhole perspective camera with intrinsics `K_f` (focal length, principal point,
    /// optionally one radial coefficient), rotation `R_f` and translation `t_f`:
    /// `w ≃ K_f (R_f X + t_f)`. The projective stages run first, then the Euclidean upgrade
    /// and the metric bundle adjustment ([`crate::perspective`]).
    Perspective,
    /// Chosen from the data: the pipeline fits the scaled orthographic and the perspective
    /// cameras to the same tracks and keeps the perspective one when it explains the data
    /// significantly better ([`crate::reconstruction::ModelSelection`]); the result names
    /// the model it kept.
    Auto,
}

impl CameraModel {
    /// The affine model the affine stages use: the model itself for the affine family,
    /// scaled orthographic (weak perspective, the first-order approximation of a
    /// perspective camera) for the projective and perspective models.
    pub fn affine(self) -> CameraModel {
        match self {
            CameraModel::Orthographic => CameraModel::Orthographic,
            _ => CameraModel::ScaledOrthographic,
        }
    }

    /// Whether the projective stages run (projective and perspective cameras).
    pub fn is_projective(self) -> bool {
        matches!(
            self,
            CameraModel::Projective | CameraModel::Perspective | CameraModel::Auto
        )
    }

    /// Whether the Euclidean perspective stages run (perspective and auto).
    pub fn is_perspective(self) -> bool {
        matches!(self, CameraModel::Perspective | CameraModel::Auto)
    }

    /// Whether the model is affine (orthographic or scaled orthographic).
    pub fn is_affine(self) -> bool {
        matches!(
            self,
            CameraModel::Orthographic | CameraModel::ScaledOrthographic
        )
    }
}

impl std::fmt::Display for CameraModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            CameraModel::Orthographic => "orthographic",
            CameraModel::ScaledOrthographic => "scaled-orthographic",
            CameraModel::Projective => "projective",
            CameraModel::Perspective => "perspective",
            CameraModel::Auto => "auto",
        })
    }
}

/// Per-frame metric cameras and per-track 3D points.
///
/// Projection of point `p` in frame `f`:
/// `[x, y] = diag(aspect, 1) · scales[f] · rotations[f][rows 0..2] · points[p] + translations[f]`.
#[derive(Debug, Clone, PartialEq)]
pub struct MetricModel {
    pub rotations: Vec<Rotation3<f64>>,
    pub translations: Vec<Vector2<f64>>,
    /// All ones for the orthographic model.
    pub scales: Vec<f64>,
    pub points: Vec<Vector3<f64>>,
    /// Aspect ratio `f_x / f_y` of the pixels (1: square): the x row of every camera is
    /// multiplied by it. The solvers work in square pixels (1); a reconstruction of
    /// non-square pixels ([`crate::Config::aspect_ratio`]) carries it.
    pub aspect: f64,
}

impl MetricModel {
    /// Number of frames.
    pub fn n_frames(&self) -> usize {
        self.rotations.len()
    }

    /// Number of points.
    pub fn n_points(&self) -> usize {
        self.points.len()
    }

    /// Image position of point `p` in frame `f`.
    #[inline]
    pub fn project(&self, f: usize, p: usize) -> Vector2<f64> {
        let r = self.rotations[f].matrix();
        let x = &self.points[p];
        let s = self.scales[f];
        Vector2::new(
            self.aspect * s * (r[(0, 0)] * x[0] + r[(0, 1)] * x[1] + r[(0, 2)] * x[2]),
            s * (r[(1, 0)] * x[0] + r[(1, 1)] * x[1] + r[(1, 2)] * x[2]),
        ) + self.translations[f]
    }

    /// Predicted 2F×N matrix for every frame and point.
    pub fn predict(&self) -> Mat<f64> {
        Mat::from_fn(2 * self.n_frames(), self.n_points(), |r, p| {
            self.project(r / 2, p)[r % 2]
        })
    }

    /// RMS reprojection error over observed scalars (x, y counted separately).
    pub fn rms(&self, meas: &Measurements) -> f64 {
        meas.rms_of(|f, p| {
            let q = self.project(f, p);
            [q[0], q[1]]
        })
    }

    /// Per-point linear least-squares triangulation given the cameras:
    /// `X_p = argmin Σ_f ‖s_f R_f[0..2] X − (w_fp − t_f)‖²` over the frames observing `p`.
    ///
    /// Each point solves a 3×3 normal system, so the cost is O(observations), the points
    /// on all cores (each point's sums in increasing frame order, whatever the thread
    /// count). Points whose normal matrix is singular (seen from a single viewing
    /// direction) keep their previous value and are returned in the list of indices.
    pub fn triangulate(&mut self, meas: &Measurements) -> Vec<usize> {
        use rayon::prelude::*;
        let (nf, n) = (meas.n_frames(), meas.n_points());
        let this = &*self;
        let solved: Vec<Option<Vector3<f64>>> = (0..n)
            .into_par_iter()
            .with_min_len(crate::measurements::TILE_TRACKS)
            .map(|p| {
                let (mut ata, mut atb) = (Matrix3::<f64>::zeros(), Vector3::<f64>::zeros());
                for f in 0..nf {
                    if meas.visible[f * n + p] {
                        let w = [meas.w[(2 * f, p)], meas.w[(2 * f + 1, p)]];
                        this.accumulate(f, w, &mut ata, &mut atb);
                    }
                }
                solve_point(&ata, &atb)
            })
            .collect();
        let mut failed = Vec::new();
        for (p, x) in solved.into_iter().enumerate() {
            match x {
                Some(x) => self.points[p] = x,
                None => failed.push(p),
            }
        }
        failed
    }

    /// Row `row` (0: x, 1: y) of frame `f`'s affine camera matrix: `s R[row]`, times
    /// `aspect` on the x row.
    #[inline]
    pub fn camera_row(&self, f: usize, row: usize) -> Vector3<f64> {
        let r = self.rotations[f].matrix();
        let s = self.scales[f];
        let sr = if row == 0 { s * self.aspect } else { s };
        Vector3::new(r[(row, 0)], r[(row, 1)], r[(row, 2)]) * sr
    }

    /// Adds frame `f`'s observation `w` of a point to its triangulation normal equations
    /// `Σ aaᵀ x = Σ a b` (`a = s R[row]`, times `aspect` on the x row, `b = w[row] − t[row]`).
    #[inline]
    pub fn accumulate(
        &self,
        f: usize,
        w: [f64; 2],
        ata: &mut Matrix3<f64>,
        atb: &mut Vector3<f64>,
    ) {
        for row in 0..2 {
            let a = self.camera_row(f, row);
            *ata += a * a.transpose();
            *atb += a * (w[row] - self.translations[f][row]);
        }
    }
}

/// The point of triangulation normal equations `ata x = atb`, or `None` when `ata` is
/// near-singular relative to its own scale (smallest eigenvalue ≤ 1e-10 × the largest: the
/// point is seen from a single viewing direction).
pub fn solve_point(ata: &Matrix3<f64>, atb: &Vector3<f64>) -> Option<Vector3<f64>> {
    let eig = ata.symmetric_eigenvalues();
    let (lo, hi) = (eig.min(), eig.max());
    if hi <= 0.0 || lo <= 1e-10 * hi {
        return None;
    }
    ata.cholesky().map(|ch| ch.solve(atb))
}
