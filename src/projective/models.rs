//! The residual models of the projective stages, for the sparse engine in [`super::bundle`].

use super::bundle::{BundleModel, Jacobians, normalize, sphere_basis};

/// Projective reprojection error: `r = π(P X) − w`, `π(a, b, c) = (a/c, b/c)`, with
/// `P ∈ R¹²` (row-major 3×4) and `X ∈ R⁴` both on their unit spheres (their scales are
/// gauge freedoms): 11 + 3 tangent parameters.
#[derive(Debug, Clone, Copy, Default)]
pub struct Projective;

impl BundleModel for Projective {
    fn cam_len(&self) -> usize {
        12
    }
    fn cam_dim(&self) -> usize {
        11
    }
    fn pt_len(&self) -> usize {
        4
    }
    fn pt_dim(&self) -> usize {
        3
    }
    fn res_dim(&self) -> usize {
        2
    }

    #[inline]
    fn eval(
        &self,
        p: &[f64],
        x: &[f64],
        _glob: &[f64],
        w: [f64; 2],
        r: &mut [f64],
        jac: Option<Jacobians<'_>>,
    ) {
        let a = p[0] * x[0] + p[1] * x[1] + p[2] * x[2] + p[3] * x[3];
        let b = p[4] * x[0] + p[5] * x[1] + p[6] * x[2] + p[7] * x[3];
        let c = p[8] * x[0] + p[9] * x[1] + p[10] * x[2] + p[11] * x[3];
        let ic = 1.0 / c;
        let (u, v) = (a * ic, b * ic);
        r[0] = u - w[0];
        r[1] = v - w[1];
        if let Some(Jacobians {
            cam: jc, pt: jp, ..
        }) = jac
        {
            for k in 0..4 {
                // ∂u/∂P1 = X/c, ∂u/∂P3 = −u X/c; ∂v/∂P2 = X/c, ∂v/∂P3 = −v X/c.
                jc[k] = x[k] * ic;
                jc[4 + k] = 0.0;
                jc[8 + k] = -u * x[k] * ic;
                jc[12 + k] = 0.0;
                jc[16 + k] = x[k] * ic;
                jc[20 + k] = -v * x[k] * ic;
                // ∂u/∂X = (P1 − u P3)/c, ∂v/∂X = (P2 − v P3)/c.
                jp[k] = (p[k] - u * p[8 + k]) * ic;
                jp[4 + k] = (p[4 + k] - v * p[8 + k]) * ic;
            }
        }
    }

    fn cam_basis(&self, cam: &[f64], out: &mut [f64]) -> bool {
        sphere_basis(cam, out);
        true
    }
    fn pt_basis(&self, pt: &[f64], out: &mut [f64]) -> bool {
        sphere_basis(pt, out);
        true
    }
    fn normalize_cam(&self, cam: &mut [f64]) {
        normalize(cam)
    }
    fn normalize_pt(&self, pt: &mut [f64]) {
        normalize(pt)
    }

    /// The 15-dimensional projective gauge `P_f → P_f (I + E)`: every direction of camera
    /// 0 (its orbit `P_0 E` spans all of its tangent space), and for camera 1 the
    /// transformations that leave camera 0 fixed, `E = c₀ vᵀ` with `c₀` camera 0's centre
    /// (`P_0 c₀ = 0`): the directions `(P_1 c₀) e_kᵀ`, `k = 1..4`.
    fn gauge_pins(&self, cams: &[f64], n_cams: usize) -> Vec<(usize, Vec<Vec<f64>>)> {
        if n_cams < 2 {
            return Vec::new();
        }
        let all: Vec<Vec<f64>> = (0..12)
            .map(|i| (0..12).map(|j| if i == j { 1.0 } else { 0.0 }).collect())
            .collect();
        let c0 = centre(&cams[..12]);
        let p1 = &cams[12..24];
        let e: [f64; 3] = std::array::from_fn(|r| (0..4).map(|k| p1[4 * r + k] * c0[k]).sum());
        let dirs = (0..4)
            .map(|k| {
                let mut v = vec![0.0; 12];
                for r in 0..3 {
                    v[4 * r + k] = e[r];
                }
                v
            })
            .collect();
        vec![(0, all), (1, dirs)]
    }
}

/// The centre of a camera `P` (3×4 row-major): the null vector, by the generalised cross
/// product of its rows (signed 3×3 minors).
fn centre(p: &[f64]) -> [f64; 4] {
    let m = |a: usize, b: usize, c: usize| {
        let col = |k: usize| [p[k], p[4 + k], p[8 + k]];
        let (x, y, z) = (col(a), col(b), col(c));
        x[0] * (y[1] * z[2] - y[2] * z[1]) - x[1] * (y[0] * z[2] - y[2] * z[0])
            + x[2] * (y[0] * z[1] - y[1] * z[0])
    };
    [m(1, 2, 3), -m(0, 2, 3), m(0, 1, 3), -m(0, 1, 2)]
}

/// The pseudo object space error (pOSE) of Hong & Zach (CVPR 2018): for `X = (x̃, 1)`,
///
/// ```text
///   ℓ = (1 − η) ‖P₁₂ X − (P₃ X) w‖² + η ‖P₁₂ X − w‖²,
/// ```
///
/// a convex combination of the object space error (bilinear, projectively invariant, but
/// minimised by collapsing the depths) and the affine reprojection error (which rules the
/// collapse out). It is bilinear in `(P, x̃)`, so variable projection reaches its minimum
/// from arbitrary starts as reliably as for affine factorization, and its minimiser is close
/// to the projective one for small `η`. Four residuals per observation, `P ∈ R¹²` and
/// `x̃ ∈ R³` Euclidean (the affine term fixes the scale of `P`).
#[derive(Debug, Clone, Copy)]
pub struct Pose {
    /// Weight of the affine term, in (0, 1].
    pub eta: f64,
}

impl BundleModel for Pose {
    fn cam_len(&self) -> usize {
        12
    }
    fn cam_dim(&self) -> usize {
        12
    }
    fn pt_len(&self) -> usize {
        3
    }
    fn pt_dim(&self) -> usize {
        3
    }
    fn res_dim(&self) -> usize {
        4
    }

    #[inline]
    fn eval(
        &self,
        p: &[f64],
        x: &[f64],
        _glob: &[f64],
        w: [f64; 2],
        r: &mut [f64],
        jac: Option<Jacobians<'_>>,
    ) {
        let (so, sa) = ((1.0 - self.eta).sqrt(), self.eta.sqrt());
        let a = p[0] * x[0] + p[1] * x[1] + p[2] * x[2] + p[3];
        let b = p[4] * x[0] + p[5] * x[1] + p[6] * x[2] + p[7];
        let c = p[8] * x[0] + p[9] * x[1] + p[10] * x[2] + p[11];
        r[0] = so * (a - w[0] * c);
        r[1] = so * (b - w[1] * c);
        r[2] = sa * (a - w[0]);
        r[3] = sa * (b - w[1]);
        if let Some(Jacobians {
            cam: jc, pt: jp, ..
        }) = jac
        {
            jc.iter_mut().for_each(|v| *v = 0.0);
            for k in 0..4 {
                let xk = if k < 3 { x[k] } else { 1.0 };
                jc[k] = so * xk;
                jc[8 + k] = -so * w[0] * xk;
                jc[12 + 4 + k] = so * xk;
                jc[12 + 8 + k] = -so * w[1] * xk;
                jc[24 + k] = sa * xk;
                jc[36 + 4 + k] = sa * xk;
            }
            for k in 0..3 {
                jp[k] = so * (p[k] - w[0] * p[8 + k]);
                jp[3 + k] = so * (p[4 + k] - w[1] * p[8 + k]);
                jp[6 + k] = sa * p[k];
                jp[9 + k] = sa * p[4 + k];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Central differences of the residual against the analytic Jacobians.
    fn check<M: BundleModel>(m: &M, cam: &[f64], pt: &[f64], w: [f64; 2]) {
        let (cl, pl, k) = (m.cam_len(), m.pt_len(), m.res_dim());
        let mut r = vec![0.0; k];
        let mut jc = vec![0.0; k * cl];
        let mut jp = vec![0.0; k * pl];
        m.eval(
            cam,
            pt,
            &[],
            w,
            &mut r,
            Some(Jacobians {
                cam: &mut jc,
                pt: &mut jp,
                glob: &mut [],
            }),
        );
        let h = 1e-6;
        for (len, is_cam) in [(cl, true), (pl, false)] {
            for j in 0..len {
                let (mut c1, mut p1) = (cam.to_vec(), pt.to_vec());
                let (mut c2, mut p2) = (cam.to_vec(), pt.to_vec());
                if is_cam {
                    c1[j] += h;
                    c2[j] -= h;
                } else {
                    p1[j] += h;
                    p2[j] -= h;
                }
                let (mut r1, mut r2) = (vec![0.0; k], vec![0.0; k]);
                m.eval(&c1, &p1, &[], w, &mut r1, None);
                m.eval(&c2, &p2, &[], w, &mut r2, None);
                for i in 0..k {
                    let fd = (r1[i] - r2[i]) / (2.0 * h);
                    let an = if is_cam {
                        jc[i * cl + j]
                    } else {
                        jp[i * pl + j]
                    };
                    assert!(
                        (fd - an).abs() < 1e-6 * (1.0 + an.abs()),
                        "{i} {j}: {fd} vs {an}"
                    );
                }
            }
        }
    }

    #[test]
    fn jacobians_match_finite_differences() {
        let cam = [
            0.9, 0.1, -0.2, 0.3, 0.05, 1.1, 0.2, -0.4, 0.01, -0.02, 0.1, 2.0,
        ];
        check(&Projective, &cam, &[0.3, -0.2, 0.5, 1.0], [0.2, -0.1]);
        check(&Pose { eta: 0.1 }, &cam, &[0.3, -0.2, 0.5], [0.2, -0.1]);
    }

    #[test]
    fn centre_is_the_null_vector() {
        let p = [
            0.9, 0.1, -0.2, 0.3, 0.05, 1.1, 0.2, -0.4, 0.01, -0.02, 0.1, 2.0,
        ];
        let c = centre(&p);
        for r in 0..3 {
            let v: f64 = (0..4).map(|k| p[4 * r + k] * c[k]).sum();
            assert!(v.abs() < 1e-14, "row {r}: {v}");
        }
        assert!(c.iter().map(|x| x * x).sum::<f64>() > 1e-6);
    }

    #[test]
    fn sphere_basis_is_orthonormal_and_tangent() {
        let mut v = vec![0.3, -0.8, 0.1, 0.5];
        normalize(&mut v);
        let mut b = vec![0.0; 12];
        sphere_basis(&v, &mut b);
        for c in 0..3 {
            let dot: f64 = (0..4).map(|k| b[k * 3 + c] * v[k]).sum();
            assert!(dot.abs() < 1e-14);
            for c2 in 0..3 {
                let d: f64 = (0..4).map(|k| b[k * 3 + c] * b[k * 3 + c2]).sum();
                let want = if c == c2 { 1.0 } else { 0.0 };
                assert!((d - want).abs() < 1e-14);
            }
        }
    }
}
