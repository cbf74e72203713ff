//! Residual models of the metric (Euclidean) perspective camera for the sparse engine in
//! [`crate::projective::bundle`], and the robust-loss wrapper any model can take.

use nalgebra::Matrix3;

use crate::projective::bundle::{BundleModel, Jacobians};

/// How the focal length enters a [`Metric`] model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Focal {
    /// Known; not estimated.
    Fixed(f64),
    /// One unknown focal length shared by every frame (a shared parameter of the engine).
    Shared,
    /// One unknown focal length per frame (zoom): the 7th camera parameter.
    PerFrame,
}

/// The perspective camera with zero skew, optionally with one radial distortion coefficient
/// (COLMAP's `SIMPLE_RADIAL`) and an aspect ratio `a = f_x / f_y` other than 1 (COLMAP's
/// `PINHOLE`; non-square pixels):
///
/// ```text
///   X_c = R X + t,   n = (X_c,1 / X_c,3, X_c,2 / X_c,3),   d = 1 + k₁ ‖n‖²,
///   π(X) = (a f d n₁ + c₁,  f d n₂ + c₂),     r = π(X) − w.
/// ```
///
/// Camera (stored): `R` row-major (9), `t` (3), and `f` when [`Focal::PerFrame`]; tangent:
/// the left rotation increment `R ← exp([ω]ₓ) R` (3), `t` (3), `f`. Point: `X ∈ R³`.
/// Shared parameters, in order: `f` when [`Focal::Shared`], `c` when
/// `principal_point` is `None`, `k₁` when `k1` is `None`, `a` when `aspect` is `None`.
///
/// The gauge is a similarity (7 degrees of freedom): camera 0's pose is pinned, and on
/// camera 1 the scaling about camera 0's centre (`δt₁ = t₁ − R₁ R₀ᵀ t₀`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Metric {
    pub focal: Focal,
    /// Known principal point, or `None` to estimate it (shared by all frames).
    pub principal_point: Option<[f64; 2]>,
    /// Known radial coefficient (0 = none), or `None` to estimate it (shared).
    pub k1: Option<f64>,
    /// Known aspect ratio `f_x / f_y` (1 = square pixels), or `None` to estimate it (shared).
    pub aspect: Option<f64>,
}

impl Metric {
    /// Index of the shared focal, principal point, `k₁` and aspect ratio in the shared
    /// parameters.
    fn layout(&self) -> (Option<usize>, Option<usize>, Option<usize>, Option<usize>) {
        let mut n = 0;
        let mut take = |on: bool, len: usize| {
            on.then(|| {
                n += len;
                n - len
            })
        };
        let f = take(self.focal == Focal::Shared, 1);
        let c = take(self.principal_point.is_none(), 2);
        let k = take(self.k1.is_none(), 1);
        let a = take(self.aspect.is_none(), 1);
        (f, c, k, a)
    }

    /// The shared-parameter vector for the given values (only the free ones are stored).
    pub fn glob(&self, focal: f64, principal_point: [f64; 2], k1: f64, aspect: f64) -> Vec<f64> {
        let mut g = vec![0.0; self.glob_len()];
        let (gf, gc, gk, ga) = self.layout();
        if let Some(i) = gf {
            g[i] = focal;
        }
        if let Some(i) = gc {
            g[i] = principal_point[0];
            g[i + 1] = principal_point[1];
        }
        if let Some(i) = gk {
            g[i] = k1;
        }
        if let Some(i) = ga {
            g[i] = aspect;
        }
        g
    }

    /// The aspect ratio `f_x / f_y` given the shared parameters.
    pub fn aspect(&self, glob: &[f64]) -> f64 {
        match (self.aspect, self.layout().3) {
            (Some(a), _) => a,
            (None, Some(i)) => glob[i],
            (None, None) => 1.0,
        }
    }

    /// `(f, c, k₁)` of camera `cam` given the shared parameters (`f` is `f_y`).
    pub fn intrinsics(&self, cam: &[f64], glob: &[f64]) -> (f64, [f64; 2], f64) {
        let (gf, gc, gk, _) = self.layout();
        let f = match self.focal {
            Focal::Fixed(f) => f,
            Focal::Shared => glob[gf.unwrap_or(0)],
            Focal::PerFrame => cam[12],
        };
        let c = match (self.principal_point, gc) {
            (Some(c), _) => c,
            (None, Some(i)) => [glob[i], glob[i + 1]],
            (None, None) => [0.0, 0.0],
        };
        let k = match (self.k1, gk) {
            (Some(k), _) => k,
            (None, Some(i)) => glob[i],
            (None, None) => 0.0,
        };
        (f, c, k)
    }
}

/// `[e_k]ₓ R` for `k = 0, 1, 2`, divided by √2 so that the basis is orthonormal.
fn rotation_basis(r: &[f64], out: &mut [f64], cd: usize) {
    let s = std::f64::consts::FRAC_1_SQRT_2;
    for k in 0..3 {
        // [e_k]ₓ rows: e_k × (row of R columns) — compute (E R)_{ij} = Σ_l E_il R_lj.
        let e: [[f64; 3]; 3] = match k {
            0 => [[0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]],
            1 => [[0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [-1.0, 0.0, 0.0]],
            _ => [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]],
        };
        for i in 0..3 {
            for j in 0..3 {
                let v: f64 = (0..3).map(|l| e[i][l] * r[3 * l + j]).sum();
                out[(3 * i + j) * cd + k] = s * v;
            }
        }
    }
}

/// The nearest rotation (polar factor) of a row-major 3×3 matrix, in place.
pub fn orthonormalize(r: &mut [f64]) {
    let m = Matrix3::from_row_slice(&r[..9]);
    let svd = m.svd(true, true);
    if let (Some(u), Some(vt)) = (svd.u, svd.v_t) {
        let mut q = u * vt;
        if q.determinant() < 0.0 {
            let mut u2 = u;
            u2.column_mut(2).neg_mut();
            q = u2 * vt;
        }
        for i in 0..3 {
            for j in 0..3 {
                r[3 * i + j] = q[(i, j)];
            }
        }
    }
}

impl BundleModel for Metric {
    fn cam_len(&self) -> usize {
        if self.focal == Focal::PerFrame {
            13
        } else {
            12
        }
    }
    fn cam_dim(&self) -> usize {
        self.cam_len() - 6
    }
    fn pt_len(&self) -> usize {
        3
    }
    fn pt_dim(&self) -> usize {
        3
    }
    fn res_dim(&self) -> usize {
        2
    }
    fn glob_len(&self) -> usize {
        let (f, c, k, a) = self.layout();
        f.map_or(0, |_| 1) + c.map_or(0, |_| 2) + k.map_or(0, |_| 1) + a.map_or(0, |_| 1)
    }

    #[inline]
    fn eval(
        &self,
        cam: &[f64],
        x: &[f64],
        glob: &[f64],
        w: [f64; 2],
        res: &mut [f64],
        jac: Option<Jacobians<'_>>,
    ) {
        let r = &cam[..9];
        let xc: [f64; 3] = std::array::from_fn(|i| {
            r[3 * i] * x[0] + r[3 * i + 1] * x[1] + r[3 * i + 2] * x[2] + cam[9 + i]
        });
        let (f, c, k1) = self.intrinsics(cam, glob);
        let asp = self.aspect(glob);
        let iz = 1.0 / xc[2];
        let (nx, ny) = (xc[0] * iz, xc[1] * iz);
        let r2 = nx * nx + ny * ny;
        let d = 1.0 + k1 * r2;
        res[0] = asp * f * d * nx + c[0] - w[0];
        res[1] = f * d * ny + c[1] - w[1];
        let Some(Jacobians {
            cam: jc,
            pt: jp,
            glob: jg,
        }) = jac
        else {
            return;
        };
        // ∂π/∂n (2×2; the first row times the aspect ratio), then
        // ∂n/∂X_c = [1/z 0 −n_x/z; 0 1/z −n_y/z].
        let a11 = f * (d + 2.0 * k1 * nx * nx);
        let a12 = f * 2.0 * k1 * nx * ny;
        let a22 = f * (d + 2.0 * k1 * ny * ny);
        let (b11, b12) = (asp * a11, asp * a12);
        let a: [[f64; 3]; 2] = [
            [b11 * iz, b12 * iz, -(b11 * nx + b12 * ny) * iz],
            [a12 * iz, a22 * iz, -(a12 * nx + a22 * ny) * iz],
        ];
        // The x row of every intrinsic derivative carries the aspect ratio.
        let sx = [asp, 1.0];
        let cl = self.cam_len();
        for row in 0..2 {
            let jr = &mut jc[row * cl..(row + 1) * cl];
            for i in 0..3 {
                for j in 0..3 {
                    jr[3 * i + j] = a[row][i] * x[j];
                }
                jr[9 + i] = a[row][i];
            }
            if self.focal == Focal::PerFrame {
                jr[12] = sx[row] * d * if row == 0 { nx } else { ny };
            }
            for j in 0..3 {
                jp[row * 3 + j] = (0..3).map(|i| a[row][i] * r[3 * i + j]).sum();
            }
        }
        let gl = self.glob_len();
        if gl > 0 {
            jg.iter_mut().for_each(|v| *v = 0.0);
            let (gf, gc, gk, ga) = self.layout();
            if let Some(i) = gf {
                jg[i] = asp * d * nx;
                jg[gl + i] = d * ny;
            }
            if let Some(i) = gc {
                jg[i] = 1.0;
                jg[gl + i + 1] = 1.0;
            }
            if let Some(i) = gk {
                jg[i] = asp * f * r2 * nx;
                jg[gl + i] = f * r2 * ny;
            }
            if let Some(i) = ga {
                jg[i] = f * d * nx;
            }
        }
    }

    fn cam_basis(&self, cam: &[f64], out: &mut [f64]) -> bool {
        let (cl, cd) = (self.cam_len(), self.cam_dim());
        out[..cl * cd].iter_mut().for_each(|v| *v = 0.0);
        rotation_basis(&cam[..9], out, cd);
        for i in 0..3 {
            out[(9 + i) * cd + 3 + i] = 1.0;
        }
        if self.focal == Focal::PerFrame {
            out[12 * cd + 6] = 1.0;
        }
        true
    }

    fn normalize_cam(&self, cam: &mut [f64]) {
        orthonormalize(&mut cam[..9]);
    }

    /// Camera 0's pose (6 directions) and the scaling about its centre on camera 1.
    fn gauge_pins(&self, cams: &[f64], n_cams: usize) -> Vec<(usize, Vec<Vec<f64>>)> {
        if n_cams < 2 {
            return Vec::new();
        }
        let (cl, cd) = (self.cam_len(), self.cam_dim());
        let mut basis = vec![0.0; cl * cd];
        self.cam_basis(&cams[..cl], &mut basis);
        let pose0: Vec<Vec<f64>> = (0..6)
            .map(|c| (0..cl).map(|r| basis[r * cd + c]).collect())
            .collect();
        let (c0, c1) = (&cams[..cl], &cams[cl..2 * cl]);
        // t₁ − R₁ R₀ᵀ t₀.
        let r0t0: [f64; 3] =
            std::array::from_fn(|j| (0..3).map(|i| c0[3 * i + j] * c0[9 + i]).sum());
        let mut v = vec![0.0; cl];
        for i in 0..3 {
            v[9 + i] = c1[9 + i] - (0..3).map(|j| c1[3 * i + j] * r0t0[j]).sum::<f64>();
        }
        vec![(0, pose0), (1, vec![v])]
    }
}

/// A robust loss `ρ(s)` of the squared residual norm `s = ‖r‖²`, with scale `δ` (in the
/// residual's units).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case", tag = "kind", content = "scale")]
pub enum Loss {
    /// `ρ(s) = s`.
    Squared,
    /// `ρ(s) = s` for `s ≤ δ²`, `2δ√s − δ²` beyond (Huber 1964).
    Huber(f64),
    /// `ρ(s) = δ² ln(1 + s/δ²)` (Cauchy / Lorentzian).
    Cauchy(f64),
}

impl Loss {
    /// `(ρ(s), ρ'(s))`.
    pub fn rho(&self, s: f64) -> (f64, f64) {
        match *self {
            Loss::Squared => (s, 1.0),
            Loss::Huber(d) => {
                if s <= d * d {
                    (s, 1.0)
                } else {
                    let rs = s.sqrt();
                    (2.0 * d * rs - d * d, d / rs)
                }
            }
            Loss::Cauchy(d) => {
                let d2 = d * d;
                (d2 * (s / d2).ln_1p(), 1.0 / (1.0 + s / d2))
            }
        }
    }

    /// The weight `ρ'(s)` an entry with squared residual `s` has at a solution (1 = full).
    pub fn weight(&self, s: f64) -> f64 {
        self.rho(s).1
    }
}

/// Any [`BundleModel`] under a robust loss: the residual is rescaled to
/// `r̃ = φ(s) r`, `φ = sqrt(ρ(s)/s)`, so that `‖r̃‖² = ρ(‖r‖²)` — the engine's
/// least-squares cost becomes `Σ ρ` exactly — with the exact Jacobian
/// `J̃ = φ J + 2 φ'(s) r rᵀ J` (Triggs et al. 2000, §4.3, the "robustified residual").
#[derive(Debug, Clone, Copy)]
pub struct Robust<M> {
    pub inner: M,
    pub loss: Loss,
}

impl<M: BundleModel> BundleModel for Robust<M> {
    fn cam_len(&self) -> usize {
        self.inner.cam_len()
    }
    fn cam_dim(&self) -> usize {
        self.inner.cam_dim()
    }
    fn pt_len(&self) -> usize {
        self.inner.pt_len()
    }
    fn pt_dim(&self) -> usize {
        self.inner.pt_dim()
    }
    fn res_dim(&self) -> usize {
        self.inner.res_dim()
    }
    fn glob_len(&self) -> usize {
        self.inner.glob_len()
    }

    fn eval(
        &self,
        cam: &[f64],
        pt: &[f64],
        glob: &[f64],
        w: [f64; 2],
        r: &mut [f64],
        jac: Option<Jacobians<'_>>,
    ) {
        let m = self.res_dim();
        let Some(j) = jac else {
            self.inner.eval(cam, pt, glob, w, r, None);
            let s: f64 = r[..m].iter().map(|v| v * v).sum();
            let phi = phi(&self.loss, s).0;
            r[..m].iter_mut().for_each(|v| *v *= phi);
            return;
        };
        let Jacobians {
            cam: jc,
            pt: jp,
            glob: jg,
        } = j;
        self.inner.eval(
            cam,
            pt,
            glob,
            w,
            r,
            Some(Jacobians {
                cam: &mut *jc,
                pt: &mut *jp,
                glob: &mut *jg,
            }),
        );
        let s: f64 = r[..m].iter().map(|v| v * v).sum();
        let (phi, dphi) = phi(&self.loss, s);
        for jm in [&mut *jc, &mut *jp, &mut *jg] {
            let n = jm.len() / m.max(1);
            for col in 0..n {
                let rj: f64 = (0..m).map(|i| r[i] * jm[i * n + col]).sum();
                for i in 0..m {
                    jm[i * n + col] = phi * jm[i * n + col] + 2.0 * dphi * r[i] * rj;
                }
            }
        }
        r[..m].iter_mut().for_each(|v| *v *= phi);
    }

    fn cam_basis(&self, cam: &[f64], out: &mut [f64]) -> bool {
        self.inner.cam_basis(cam, out)
    }
    fn pt_basis(&self, pt: &[f64], out: &mut [f64]) -> bool {
        self.inner.pt_basis(pt, out)
    }
    fn normalize_cam(&self, cam: &mut [f64]) {
        self.inner.normalize_cam(cam)
    }
    fn normalize_pt(&self, pt: &mut [f64]) {
        self.inner.normalize_pt(pt)
    }
    fn gauge_pins(&self, cams: &[f64], n_cams: usize) -> Vec<(usize, Vec<Vec<f64>>)> {
        self.inner.gauge_pins(cams, n_cams)
    }
}

/// `(φ(s), φ'(s))` for `φ = sqrt(ρ(s)/s)`; the limits at `s → 0` are `(1, ρ''(0)/2)`.
fn phi(loss: &Loss, s: f64) -> (f64, f64) {
    match *loss {
        Loss::Squared => (1.0, 0.0),
        Loss::Huber(d) if s <= d * d => (1.0, 0.0),
        Loss::Cauchy(d) if s < 1e-8 * d * d => {
            // ρ/s ≈ 1 − s/(2δ²) + s²/(3δ⁴): φ ≈ 1 − s/(4δ²).
            let d2 = d * d;
            (1.0 - s / (4.0 * d2), -1.0 / (4.0 * d2))
        }
        _ => {
            let (rho, drho) = loss.rho(s);
            let ph = (rho / s).sqrt();
            // φ' = (ρ' s − ρ) / (2 s² φ).
            (ph, (drho * s - rho) / (2.0 * s * s * ph))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check<M: BundleModel>(m: &M, cam: &[f64], pt: &[f64], glob: &[f64], w: [f64; 2]) {
        let (cl, pl, gl, k) = (m.cam_len(), m.pt_len(), m.glob_len(), m.res_dim());
        let mut r = vec![0.0; k];
        let (mut jc, mut jp, mut jg) = (vec![0.0; k * cl], vec![0.0; k * pl], vec![0.0; k * gl]);
        m.eval(
            cam,
            pt,
            glob,
            w,
            &mut r,
            Some(Jacobians {
                cam: &mut jc,
                pt: &mut jp,
                glob: &mut jg,
            }),
        );
        let h = 1e-6;
        for (which, len) in [(0, cl), (1, pl), (2, gl)] {
            for j in 0..len {
                let mut args = [cam.to_vec(), pt.to_vec(), glob.to_vec()];
                let mut args2 = args.clone();
                args[which][j] += h;
                args2[which][j] -= h;
                let (mut r1, mut r2) = (vec![0.0; k], vec![0.0; k]);
                m.eval(&args[0], &args[1], &args[2], w, &mut r1, None);
                m.eval(&args2[0], &args2[1], &args2[2], w, &mut r2, None);
                for i in 0..k {
                    let fd = (r1[i] - r2[i]) / (2.0 * h);
                    let an = [&jc, &jp, &jg][which][i * len + j];
                    assert!(
                        (fd - an).abs() < 1e-5 * (1.0 + an.abs()),
                        "block {which} r{i} p{j}: {fd} vs {an}"
                    );
                }
            }
        }
    }

    #[test]
    fn metric_jacobians_match_finite_differences() {
        let mut cam = vec![
            0.9, 0.1, -0.2, 0.05, 1.1, 0.2, 0.01, -0.02, 0.9, 0.3, -0.4, 4.0, 1.3,
        ];
        orthonormalize(&mut cam[..9]);
        let pt = [0.3, -0.2, 0.5];
        let w = [0.2, -0.1];
        for (focal, pp, k1, aspect) in [
            (Focal::Fixed(1.2), Some([0.01, -0.02]), Some(0.0), Some(1.0)),
            (Focal::Shared, None, None, None),
            (Focal::PerFrame, Some([0.0, 0.0]), None, Some(0.9)),
            (Focal::PerFrame, None, Some(0.1), None),
        ] {
            let m = Metric {
                focal,
                principal_point: pp,
                k1,
                aspect,
            };
            let cl = m.cam_len();
            let glob = m.glob(1.1, [0.02, 0.01], -0.05, 0.8);
            check(&m, &cam[..cl], &pt, &glob, w);
            for loss in [Loss::Huber(0.05), Loss::Cauchy(0.05), Loss::Cauchy(10.0)] {
                check(&Robust { inner: m, loss }, &cam[..cl], &pt, &glob, w);
            }
        }
    }

    #[test]
    fn robust_residual_norm_is_the_loss() {
        let m = Robust {
            inner: Metric {
                focal: Focal::Fixed(1.0),
                principal_point: Some([0.0, 0.0]),
                k1: Some(0.0),
                aspect: Some(1.0),
            },
            loss: Loss::Cauchy(0.1),
        };
        let cam = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 2.0];
        let mut r = [0.0; 2];
        m.eval(&cam, &[0.4, 0.2, 0.0], &[], [0.0, 0.0], &mut r, None);
        let s = 0.2f64.powi(2) + 0.1f64.powi(2);
        let rho = 0.01 * (1.0 + s / 0.01).ln();
        assert!((r[0] * r[0] + r[1] * r[1] - rho).abs() < 1e-14);
    }
}
