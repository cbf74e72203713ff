//! Self-calibration: the Euclidean upgrade of a projective reconstruction by the absolute
//! dual quadric.
//!
//! # Objective
//!
//! A projective reconstruction `(P_f, X_p)` is the Euclidean one up to a 4×4 homography
//! `H`: `P_f = K_f [R_f | t_f] H⁻¹`. The absolute dual quadric `Q*∞ = H diag(1,1,1,0) Hᵀ`
//! (symmetric 4×4, rank 3, positive semidefinite) projects to the dual image of the
//! absolute conic of every camera (Triggs 1997):
//!
//! ```text
//!   ω*_f = P_f Q*∞ P_fᵀ ∝ K_f K_fᵀ.
//! ```
//!
//! In image coordinates normalised by the principal point `c` and a scale `s`
//! (`x̂ = (x − c)/s`, so that the focal length is `f̂ = f/s ≈ 1`), zero skew, unit aspect
//! ratio and the known principal point make `ω*_f = diag(f̂², f̂², 1)` up to scale: linear
//! equations in the 10 entries of `Q*∞`. Following Pollefeys, Verbiest & Van Gool
//! (ECCV 2002) and Pollefeys et al. (IJCV 2004, §4.2) each is weighted by its expected
//! uncertainty, with a weak prior `f̂ ≈ 1`:
//!
//! ```text
//!   (ω₁₁ − ω₃₃)/9ν = 0,  (ω₂₂ − ω₃₃)/9ν = 0,  (ω₁₁ − ω₂₂)/0.2ν = 0,
//!   ω₁₃/0.1ν = 0,        ω₂₃/0.1ν = 0,        ω₁₂/0.01ν = 0,
//! ```
//!
//! `ν = ω₃₃` of the previous estimate (three reweighted passes). With a known focal length
//! the scale is `s = f` and the prior becomes a hard equation (weight 1/0.01).
//!
//! # Method
//!
//! 1. **Linear estimate**: the unit vector minimising the weighted residual (smallest right
//!    singular vector), signed so that `Σ_f ω₃₃ > 0`.
//! 2. **PSD and rank 3**: when the linear `Q` is not positive semidefinite (noise, weak
//!    perspective), the same least squares is solved over the PSD cone with Clarabel
//!    ([`crate::sdp::psd_least_squares_sym`]), normalised by `Σ_f ω₃₃/ν_f = F`; the
//!    smallest eigenvalue is then set to zero (the nearest rank-3 matrix).
//! 3. **Rectifying homography**: `Q = V Λ Vᵀ` gives `H = [v₁√λ₁ v₂√λ₂ v₃√λ₃ v₄]`; each
//!    `P̂_f H = λ K_f [R_f | t_f]` is split by an RQ decomposition; `X = H⁻¹ X_p`. A
//!    reflection `(X, t) → (−X, −t)` is applied if most points would lie behind their
//!    cameras (cheirality).
//! 4. The nonlinear refinement is the metric bundle adjustment that follows
//!    ([`upgrade`]): the maximum-likelihood estimate of the focal length(s), poses and
//!    points under the camera model.
//!
//! # Complexity
//!
//! `O(F)` to form the `6F × 10` system and `O(F)` for its SVD (10 columns); the PSD solve
//! is a fixed 10-unknown conic program; `O(N)` to transform the points.
//!
//! # References
//!
//! * B. Triggs, "Autocalibration and the absolute quadric", CVPR 1997.
//! * M. Pollefeys, R. Koch and L. Van Gool, "Self-calibration and metric reconstruction in
//!   spite of varying and unknown internal camera parameters", IJCV 32(1), 1999.
//! * M. Pollefeys, F. Verbiest and L. Van Gool, "Surviving dominant planes in uncalibrated
//!   structure and motion recovery", ECCV 2002 (the weighted linear equations).
//! * R. Hartley and A. Zisserman, *Multiple View Geometry*, 2nd ed., ch. 19.

use nalgebra::{DMatrix, Matrix3, Matrix3x4, Matrix4, Vector3, Vector4};

use crate::error::{Error, Result};
use crate::sdp::{SdpSettings, SdpStatus, bilinear_row_n, psd_least_squares_sym, sym_index};

/// What the self-calibration found, for the report.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SelfCalibration {
    /// `Q*∞` in normalised image coordinates (row-major 4×4), rank 3.
    pub quadric: [f64; 16],
    /// Eigenvalues of the linear estimate (descending), relative to the largest: a clear
    /// rank 3 has the 4th near zero and none negative.
    pub linear_eigenvalues: [f64; 4],
    /// Whether the PSD-constrained solve was needed (the linear estimate was indefinite).
    pub sdp: bool,
    /// Clarabel's status when it ran.
    pub sdp_status: Option<String>,
    /// Per frame, the focal length the upgrade implies (pixels).
    pub focal_px: Vec<f64>,
    /// Fraction of observations in front of their camera after the upgrade.
    pub in_front: f64,
}

/// Intrinsics assumed by the upgrade: the principal point and the image scale (pixels).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    pub principal_point: [f64; 2],
    /// Normalising scale `s`: the known focal length, or the image size when unknown.
    pub scale: f64,
    /// The focal length is known (`= scale`).
    pub known_focal: bool,
}

/// A Euclidean reconstruction in normalised image units (`x̂ = (x − c)/s`): per frame
/// `(f̂, R, t)`, per point `X`.
#[derive(Debug, Clone)]
pub struct Upgraded {
    pub focal: Vec<f64>,
    pub rotations: Vec<Matrix3<f64>>,
    pub translations: Vec<Vector3<f64>>,
    pub points: Vec<Vector3<f64>>,
    pub report: SelfCalibration,
}

/// Upgrades the projective reconstruction `(cameras, points)` (cameras in pixels, 3×4
/// row-major; points homogeneous) to a Euclidean one. `observations` are the `(frame,
/// point)` pairs used to check cheirality.
pub fn upgrade(
    cameras: &[[f64; 12]],
    points: &[[f64; 4]],
    observations: &[(usize, usize)],
    frame: &Frame,
    sdp: &SdpSettings,
) -> Result<Upgraded> {
    let nf = cameras.len();
    if nf < 3 && !frame.known_focal {
        return Err(Error::TooFew {
            what: "frames for self-calibration",
            needed: 3,
            have: nf,
        });
    }
    if !(frame.scale.is_finite() && frame.scale > 0.0) {
        return Err(Error::InvalidConfig {
            field: "focal",
            message: format!("the image scale must be positive, got {}", frame.scale),
        });
    }
    // Normalised cameras T P, unit Frobenius norm.
    let (c, s) = (frame.principal_point, frame.scale);
    let t = Matrix3::new(
        1.0 / s,
        0.0,
        -c[0] / s,
        0.0,
        1.0 / s,
        -c[1] / s,
        0.0,
        0.0,
        1.0,
    );
    let cams: Vec<Matrix3x4<f64>> = cameras
        .iter()
        .map(|p| {
            let m = t * Matrix3x4::from_row_slice(p);
            let n = m.norm();
            if n > 0.0 { m / n } else { m }
        })
        .collect();
    let rows_of = |p: &Matrix3x4<f64>| -> [Vec<f64>; 3] {
        std::array::from_fn(|i| p.row(i).iter().copied().collect())
    };
    let prior = if frame.known_focal { 0.01 } else { 9.0 };
    let weights = [prior, prior, 0.2, 0.1, 0.1, 0.01];
    let equations = |nu: &[f64]| -> Vec<Vec<f64>> {
        let mut a = Vec::with_capacity(6 * nf);
        for (p, &nu) in cams.iter().zip(nu) {
            let r = rows_of(p);
            let w = |i: usize, j: usize| bilinear_row_n(&r[i], &r[j]);
            let diff = |x: Vec<f64>, y: Vec<f64>| -> Vec<f64> {
                x.iter().zip(&y).map(|(a, b)| a - b).collect()
            };
            let eqs = [
                diff(w(0, 0), w(2, 2)),
                diff(w(1, 1), w(2, 2)),
                diff(w(0, 0), w(1, 1)),
                w(0, 2),
                w(1, 2),
                w(0, 1),
            ];
            for (e, wt) in eqs.into_iter().zip(weights) {
                a.push(e.iter().map(|v| v / (wt * nu)).collect());
            }
        }
        a
    };
    let ij = sym_index(4);
    let to_q = |q: &[f64]| -> Matrix4<f64> {
        let mut m = Matrix4::zeros();
        for (k, &(i, j)) in ij.iter().enumerate() {
            m[(i, j)] = q[k];
            m[(j, i)] = q[k];
        }
        m
    };
    let w33 = |p: &Matrix3x4<f64>, q: &Matrix4<f64>| -> f64 {
        let r: Vector4<f64> = p.row(2).transpose();
        (r.transpose() * q * r)[0]
    };

    let mut nu = vec![1.0; nf];
    let mut q = Matrix4::zeros();
    for _pass in 0..3 {
        let a = equations(&nu);
        let am = DMatrix::from_fn(a.len(), 10, |i, j| a[i][j]);
        let svd = am.svd(false, true);
        let vt = svd.v_t.ok_or_else(|| Error::Numerical {
            stage: "self-calibration",
            message: "SVD of the linear system failed".into(),
        })?;
        let k = (0..svd.singular_values.len())
            .min_by(|&x, &y| svd.singular_values[x].total_cmp(&svd.singular_values[y]))
            .unwrap_or(9);
        let v: Vec<f64> = vt.row(k).iter().copied().collect();
        q = to_q(&v);
        let total: f64 = cams.iter().map(|p| w33(p, &q)).sum();
        if total < 0.0 {
            q = -q;
        }
        let new_nu: Vec<f64> = cams.iter().map(|p| w33(p, &q)).collect();
        if new_nu.iter().all(|&x| x > 0.0 && x.is_finite()) {
            let mean = new_nu.iter().sum::<f64>() / nf as f64;
            nu = new_nu.iter().map(|x| x / mean).collect();
        } else {
            break;
        }
    }
    let eig = q.symmetric_eigen();
    let mut ev: Vec<f64> = eig.eigenvalues.iter().copied().collect();
    ev.sort_by(|a, b| b.total_cmp(a));
    let emax = ev[0].abs().max(f64::MIN_POSITIVE);
    let linear_eigenvalues = [ev[0] / emax, ev[1] / emax, ev[2] / emax, ev[3] / emax];
    // PSD: the three largest must be positive and the 4th not clearly negative.
    let psd = ev[2] > 0.0 && ev[3] > -1e-9 * emax;
    let mut sdp_status = None;
    if !psd {
        let a = equations(&nu);
        let b = vec![0.0; a.len()];
        let mut c = vec![0.0; 10];
        for (p, &n) in cams.iter().zip(&nu) {
            let r = rows_of(p);
            for (ck, v) in c.iter_mut().zip(bilinear_row_n(&r[2], &r[2])) {
                *ck += v / n;
            }
        }
        let sol = psd_least_squares_sym(4, &a, &b, Some((&c, nf as f64)), sdp)?;
        sdp_status = Some(match &sol.status {
            SdpStatus::Other(s) => s.clone(),
            other => format!("{other:?}"),
        });
        q = Matrix4::from_fn(|i, j| sol.l[(i, j)]);
    }
    // Rank 3, and the rectifying homography.
    let eig = q.symmetric_eigen();
    let mut order: Vec<usize> = (0..4).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let lam: Vec<f64> = order.iter().map(|&i| eig.eigenvalues[i].max(0.0)).collect();
    if !(lam[2] > 1e-12 * lam[0]) {
        return Err(Error::Degenerate(format!(
            "self-calibration: the absolute dual quadric has rank < 3 (eigenvalues {:.3e}, \
             {:.3e}, {:.3e}): the frames do not constrain the Euclidean upgrade (too little \
             rotation, or an affine-looking sequence)",
            lam[0], lam[1], lam[2]
        )));
    }
    let mut h = Matrix4::zeros();
    for (c, &i) in order.iter().enumerate() {
        let v = eig.eigenvectors.column(i);
        let scale = if c < 3 { lam[c].sqrt() } else { 1.0 };
        h.set_column(c, &(v * scale));
    }
    let q3 = h * Matrix4::from_diagonal(&Vector4::new(1.0, 1.0, 1.0, 0.0)) * h.transpose();
    let hinv = h.try_inverse().ok_or_else(|| Error::Numerical {
        stage: "self-calibration",
        message: "the rectifying homography is singular".into(),
    })?;

    // Cameras: P̂ H = [M | m] = λ K [R | t].
    let mut focal = Vec::with_capacity(nf);
    let mut rotations = Vec::with_capacity(nf);
    let mut translations = Vec::with_capacity(nf);
    for p in &cams {
        let ph = p * h;
        let mut m = ph.fixed_view::<3, 3>(0, 0).into_owned();
        let mut col = ph.column(3).into_owned();
        if m.determinant() < 0.0 {
            m = -m;
            col = -col;
        }
        let (k, r) = rq(&m);
        let kinv = k.try_inverse().unwrap_or_else(Matrix3::identity);
        let tr = kinv * col;
        let f = 0.5 * (k[(0, 0)] + k[(1, 1)]) / k[(2, 2)];
        focal.push(f);
        rotations.push(r);
        translations.push(tr);
    }
    let mut pts: Vec<Vector3<f64>> = points
        .iter()
        .map(|x| {
            let y = hinv * Vector4::from_row_slice(x);
            let w = if y[3].abs() > 1e-300 { y[3] } else { 1e-300 };
            Vector3::new(y[0] / w, y[1] / w, y[2] / w)
        })
        .collect();
    let depth = |f: usize, p: usize, pts: &[Vector3<f64>], ts: &[Vector3<f64>]| {
        (rotations[f] * pts[p] + ts[f])[2]
    };
    let front = observations
        .iter()
        .filter(|&&(f, p)| depth(f, p, &pts, &translations) > 0.0)
        .count();
    let mut in_front = front as f64 / observations.len().max(1) as f64;
    if in_front < 0.5 {
        for x in pts.iter_mut() {
            *x = -*x;
        }
        for t in translations.iter_mut() {
            *t = -*t;
        }
        in_front = 1.0 - in_front;
    }
    let known = frame.known_focal;
    let report = SelfCalibration {
        quadric: std::array::from_fn(|k| q3[(k / 4, k % 4)]),
        linear_eigenvalues,
        sdp: !psd,
        sdp_status,
        focal_px: focal
            .iter()
            .map(|f| if known { s } else { f * s })
            .collect(),
        in_front,
    };
    Ok(Upgraded {
        focal,
        rotations,
        translations,
        points: pts,
        report,
    })
}

/// RQ decomposition `M = K R` with `K` upper triangular with a positive diagonal and `R`
/// a rotation (`det M > 0`).
pub fn rq(m: &Matrix3<f64>) -> (Matrix3<f64>, Matrix3<f64>) {
    // With the row-reversal permutation P: P M = (P Mᵀ ... ) — via QR of (P M)ᵀ.
    let p = Matrix3::new(0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0);
    let a = (p * m).transpose();
    let qr = a.qr();
    let (q, r) = (qr.q(), qr.r());
    let mut k = p * r.transpose() * p;
    let mut rot = p * q.transpose();
    // Make K's diagonal positive: K D, D R with D = diag(±1).
    for i in 0..3 {
        if k[(i, i)] < 0.0 {
            for r in 0..3 {
                k[(r, i)] = -k[(r, i)];
            }
            for c in 0..3 {
                rot[(i, c)] = -rot[(i, c)];
            }
        }
    }
    (k, rot)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    #[test]
    fn rq_recovers_k_and_r() {
        let k = Matrix3::new(800.0, 1.0, 320.0, 0.0, 790.0, 240.0, 0.0, 0.0, 1.0);
        let r = Rotation3::from_euler_angles(0.3, -0.2, 1.1).into_inner();
        let (k2, r2) = rq(&(k * r));
        assert!((k2 - k).norm() < 1e-9 * k.norm(), "{k2}");
        assert!((r2 - r).norm() < 1e-12);
    }

    /// Noise-free: the linear upgrade recovers the focal lengths and the structure up to a
    /// similarity, from cameras and points garbled by a homography, to within the bias of
    /// the weak focal prior (here `f̂ = 700/640`; exactness comes from the adjustment that
    /// follows, tested in `tests/perspective.rs`).
    #[test]
    fn noise_free_upgrade_recovers_focal_and_angles() {
        let f_px = 700.0;
        let c = [320.0, 240.0];
        let k = Matrix3::new(f_px, 0.0, c[0], 0.0, f_px, c[1], 0.0, 0.0, 1.0);
        let pts: Vec<Vector3<f64>> = (0..30)
            .map(|i| {
                let a = i as f64;
                Vector3::new((a * 0.7).sin(), (a * 1.3).cos(), 0.5 * (a * 0.4).sin())
            })
            .collect();
        let mut cams = Vec::new();
        for fi in 0..6 {
            let ang = 0.15 * fi as f64;
            let r = Rotation3::from_euler_angles(0.05 * fi as f64, ang, 0.02).into_inner();
            let centre = Vector3::new(4.0 * ang.sin(), 0.3, -4.0 * ang.cos());
            let t = -r * centre;
            let mut p = Matrix3x4::zeros();
            p.fixed_view_mut::<3, 3>(0, 0).copy_from(&(k * r));
            p.set_column(3, &(k * t));
            cams.push(p);
        }
        let g = Matrix4::new(
            1.0, 0.2, -0.1, 0.3, 0.1, 0.9, 0.2, -0.2, 0.05, -0.1, 1.1, 0.4, 0.1, 0.05, -0.2, 1.0,
        );
        let ginv = g.try_inverse().unwrap();
        let pcams: Vec<[f64; 12]> = cams
            .iter()
            .map(|p| {
                let q = p * g;
                std::array::from_fn(|k| q[(k / 4, k % 4)])
            })
            .collect();
        let ppts: Vec<[f64; 4]> = pts
            .iter()
            .map(|x| {
                let y = ginv * Vector4::new(x[0], x[1], x[2], 1.0);
                [y[0], y[1], y[2], y[3]]
            })
            .collect();
        let obs: Vec<(usize, usize)> = (0..6).flat_map(|f| (0..30).map(move |p| (f, p))).collect();
        let frame = Frame {
            principal_point: c,
            scale: 640.0,
            known_focal: false,
        };
        let up = upgrade(&pcams, &ppts, &obs, &frame, &SdpSettings::default()).unwrap();
        for f in &up.report.focal_px {
            assert!((f - f_px).abs() < 3e-3 * f_px, "focal {f}");
        }
        assert_eq!(up.report.in_front, 1.0);
        // Angles between point triples are preserved by a similarity.
        let angle = |a: Vector3<f64>, b: Vector3<f64>, c: Vector3<f64>| (b - a).angle(&(c - a));
        for (i, j, l) in [(0, 5, 9), (3, 17, 22), (11, 2, 29)] {
            let a0 = angle(pts[i], pts[j], pts[l]);
            let a1 = angle(up.points[i], up.points[j], up.points[l]);
            assert!((a0 - a1).abs() < 3e-3, "{a0} vs {a1}");
        }
    }
}
