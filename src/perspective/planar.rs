//! A start of the metric adjustment for planar scenes: the focal length and the plane's
//! normal from the consistency of plane-induced homographies, then the frames registered
//! to the plane one at a time.
//!
//! # Why
//!
//! When the tracked points lie on a plane (a facade, a table top, flat ground seen from
//! above) the points span a 3-dimensional subspace of `P³`: the projective factorization is
//! not unique (any homography fixing the plane gives another), the absolute dual quadric is
//! not determined, and the affine model has rank 2, not 3 — none of [`super::fit`]'s other
//! starts is near the metric optimum, and the adjustment from them ends tens of pixels off
//! with a wrong focal length. A plane and a pinhole camera are still determined: each view
//! of the plane is a homography, and the metric camera is recovered from them (Triggs 1998;
//! Zhang 2000 with a known plane; Hartley & Zisserman §8.8, §19.6).
//!
//! # Objective
//!
//! In the principal-point-centred pixels of [`super::Assumed`], let `G_g` be the homography
//! from a reference frame `r` to frame `g` (normalised DLT on the tracks both see), `K =
//! diag(f, f, 1)` and `Ĝ_g = K⁻¹ G_g K`. Frame `r`'s camera frame being the world's, a plane
//! `nᵀX = 1` induces `Ĝ_g ∝ R_g + t_g nᵀ`, so for an orthonormal basis `(a, b)` of the plane
//! (`a, b ⊥ n`) the vectors `u = Ĝ_g a` and `v = Ĝ_g b` are the images of two orthonormal
//! directions by a scaled rotation: orthogonal and of equal length. The focal length and the
//! normal's direction minimise
//!
//! `J(f, n) = Σ_g (uᵀv / (‖u‖ ‖v‖))² + ((‖u‖² − ‖v‖²) / (‖u‖² + ‖v‖²))²`,
//!
//! two conditions per frame on three unknowns (the circular points of the plane imaged in
//! frame `r`, Triggs' formulation with the principal point and unit aspect ratio known).
//! `J` is searched on a grid (log-spaced `f`, normals on a Fibonacci hemisphere), its best
//! cells refined by a pattern search. A known focal length leaves the normal only.
//!
//! Each other frame is then registered to the plane (Zhang's decomposition of the homography
//! from the plane's coordinates to its calibrated image: `H ∝ [R a, R b, R n + t]`, the
//! rotation projected on `SO(3)`, the sign by cheirality), in the order of how many of its
//! tracks are already placed; a track is placed where its ray from the first registered
//! frame that sees it meets the plane.
//!
//! Degenerate cases: a camera that only rotates makes `J` vanish for every normal at the
//! right `f` (the rotating camera's calibration, Hartley 1994), and the start has the
//! plane at an arbitrary distance; a frame sharing fewer than 6 placed tracks with the
//! registered ones leaves no start (`None`).
//!
//! # Complexity
//!
//! `O(n_obs)` for the homographies and the registration (a 9×9 normal matrix per frame),
//! plus `O(G · M · P)` for the grid (`G` focal lengths, `M` normals, `P ≤ 40` frame pairs),
//! independent of the table's size.
//!
//! # References
//!
//! * B. Triggs, "Autocalibration from planar scenes", ECCV 1998.
//! * Z. Zhang, "A flexible new technique for camera calibration", PAMI 22(11), 2000.
//! * R. Hartley, "Self-calibration from multiple views with a rotating camera", ECCV 1994.
//! * R. Hartley and A. Zisserman, *Multiple View Geometry*, 2nd ed., Alg. 4.2 (normalised
//!   DLT), §8.8, §19.6.

use nalgebra::{Matrix3, SMatrix, Vector3};

use super::PerspectiveModel;
use super::models::orthonormalize;
use crate::Measurements;
use crate::projective::Normalization;

/// The nearest rotation (polar factor, determinant +1) of `m`: [`orthonormalize`] on its
/// column-major storage, which is `mᵀ` row by row (the polar factor of `mᵀ` is that of `m`
/// transposed).
fn nearest_rotation(mut m: Matrix3<f64>) -> Matrix3<f64> {
    orthonormalize(m.as_mut_slice());
    m
}

/// Frames of the reference's homographies that the calibration uses (spread evenly over
/// the frames that share enough tracks with it).
const MAX_PAIRS: usize = 40;
/// Tracks a frame must share with the reference for its homography to be used in the
/// calibration.
const MIN_SHARED: usize = 8;
/// Placed tracks a frame must see to be registered to the plane.
const MIN_PLACED: usize = 6;

/// What the planar calibration found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanarCalibration {
    /// Focal length, pixels.
    pub focal_px: f64,
    /// The plane's unit normal in the reference frame's camera coordinates.
    pub normal: Vector3<f64>,
    /// `J(f, n)` at the minimum, divided by the number of homographies (0 = every
    /// homography exactly consistent).
    pub residual: f64,
    /// Homographies used.
    pub pairs: usize,
    /// The reference frame.
    pub reference: usize,
    /// Median one-sided transfer RMS of the homographies (pixels): how planar the tracks
    /// look (about `√2 σ` for a plane or a rotating camera).
    pub transfer_rms_px: f64,
}

/// The planar start of `meas` (pixels), principal point `c`; `side` scales the focal
/// length search (the image's larger side), `known_focal` holds it. `None` when the
/// homographies or the registration cannot be formed (too few shared tracks). `O(n_obs)`
/// plus the grid's constant.
pub fn start(
    meas: &Measurements,
    c: [f64; 2],
    side: f64,
    known_focal: Option<f64>,
) -> Option<(PerspectiveModel, PlanarCalibration)> {
    let (nf, np) = (meas.n_frames(), meas.n_points());
    if nf < 2 || np < MIN_PLACED {
        return None;
    }
    let pos = |f: usize, p: usize| [meas.w[(2 * f, p)] - c[0], meas.w[(2 * f + 1, p)] - c[1]];
    let mut tracks_of: Vec<Vec<usize>> = vec![Vec::new(); nf];
    let mut frames_of: Vec<Vec<usize>> = vec![Vec::new(); np];
    meas.for_each_observed(|f, p| {
        tracks_of[f].push(p);
        frames_of[p].push(f);
    });
    // The reference: the frame seeing the most tracks.
    let r = (0..nf).max_by_key(|&f| (tracks_of[f].len(), std::cmp::Reverse(f)))?;
    if tracks_of[r].len() < MIN_SHARED {
        return None;
    }
    let mut in_r = vec![false; np];
    for &p in &tracks_of[r] {
        in_r[p] = true;
    }
    let mut homographies = Vec::new();
    let mut transfer = Vec::new();
    for (g, shared) in partners(&tracks_of, r, &in_r) {
        let src: Vec<[f64; 2]> = shared.iter().map(|&p| pos(r, p)).collect();
        let dst: Vec<[f64; 2]> = shared.iter().map(|&p| pos(g, p)).collect();
        let Some(h) = homography(&src, &dst) else {
            continue;
        };
        transfer.push(transfer_rms(&h, &src, &dst));
        homographies.push(h);
    }
    if homographies.len() < 2 {
        return None;
    }
    transfer.sort_by(f64::total_cmp);
    let transfer_rms_px = transfer[transfer.len() / 2];
    // The reference's tracks (their 5–95 % box) must all be in front of the plane.
    let quantile = |mut v: Vec<f64>, q: f64| {
        v.sort_by(f64::total_cmp);
        v[((v.len() - 1) as f64 * q).round() as usize]
    };
    let xs: Vec<f64> = tracks_of[r].iter().map(|&p| pos(r, p)[0]).collect();
    let ys: Vec<f64> = tracks_of[r].iter().map(|&p| pos(r, p)[1]).collect();
    let (x0, x1) = (quantile(xs.clone(), 0.05), quantile(xs, 0.95));
    let (y0, y1) = (quantile(ys.clone(), 0.05), quantile(ys, 0.95));
    let corners = [[x0, y0], [x0, y1], [x1, y0], [x1, y1]];
    let (focal, normal, residual) = calibrate(&homographies, &corners, side, known_focal);
    let calib = PlanarCalibration {
        focal_px: focal,
        normal,
        residual: residual / homographies.len() as f64,
        pairs: homographies.len(),
        reference: r,
        transfer_rms_px,
    };
    let model = register(meas, &tracks_of, &frames_of, r, focal, normal, &pos, c)?;
    Some((model, calib))
}

/// The frames sharing at least [`MIN_SHARED`] tracks with frame `r` (`in_r[p]`: `r` sees
/// track `p`), at most [`MAX_PAIRS`] of them spread evenly, each with the tracks it shares.
/// `O(n_obs)`.
fn partners(tracks_of: &[Vec<usize>], r: usize, in_r: &[bool]) -> Vec<(usize, Vec<usize>)> {
    let all: Vec<usize> = (0..tracks_of.len())
        .filter(|&g| g != r && tracks_of[g].iter().filter(|&&p| in_r[p]).count() >= MIN_SHARED)
        .collect();
    let step = all.len().div_ceil(MAX_PAIRS).max(1);
    all.into_iter()
        .step_by(step)
        .map(|g| {
            (
                g,
                tracks_of[g].iter().copied().filter(|&p| in_r[p]).collect(),
            )
        })
        .collect()
}

/// Hartley's normalising similarity of 2D points ([`Normalization::of_points`]: centroid to
/// the origin, mean distance `√2`) as a 3×3 matrix.
fn normaliser(pts: &[[f64; 2]]) -> Matrix3<f64> {
    let Normalization {
        centre: [cx, cy],
        scale: s,
    } = Normalization::of_points(|| pts.iter().copied());
    Matrix3::new(s, 0.0, -s * cx, 0.0, s, -s * cy, 0.0, 0.0, 1.0)
}

/// The homography `x' ≃ H x` of at least 4 point pairs by the normalised DLT (Hartley &
/// Zisserman Alg. 4.2; the null vector of the 9×9 normal matrix). `None` when degenerate.
/// `O(n)`.
pub(crate) fn homography(src: &[[f64; 2]], dst: &[[f64; 2]]) -> Option<Matrix3<f64>> {
    if src.len() < 4 || src.len() != dst.len() {
        return None;
    }
    let (t1, t2) = (normaliser(src), normaliser(dst));
    let mut ata = SMatrix::<f64, 9, 9>::zeros();
    for (s, d) in src.iter().zip(dst) {
        let x = t1 * Vector3::new(s[0], s[1], 1.0);
        let y = t2 * Vector3::new(d[0], d[1], 1.0);
        let r1 = [
            0.0,
            0.0,
            0.0,
            -y[2] * x[0],
            -y[2] * x[1],
            -y[2] * x[2],
            y[1] * x[0],
            y[1] * x[1],
            y[1] * x[2],
        ];
        let r2 = [
            y[2] * x[0],
            y[2] * x[1],
            y[2] * x[2],
            0.0,
            0.0,
            0.0,
            -y[0] * x[0],
            -y[0] * x[1],
            -y[0] * x[2],
        ];
        for row in [r1, r2] {
            for i in 0..9 {
                for j in 0..9 {
                    ata[(i, j)] += row[i] * row[j];
                }
            }
        }
    }
    let eig = ata.symmetric_eigen();
    let (imin, _) = eig
        .eigenvalues
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))?;
    let h = eig.eigenvectors.column(imin);
    let hn = Matrix3::new(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8]);
    let out = t2.try_inverse()? * hn * t1;
    let norm = out.norm();
    (norm.is_finite() && norm > 0.0).then(|| out / norm)
}

/// One-sided transfer RMS of `dst ≈ π(H src)`, pixels.
fn transfer_rms(h: &Matrix3<f64>, src: &[[f64; 2]], dst: &[[f64; 2]]) -> f64 {
    let mut s = 0.0;
    for (a, b) in src.iter().zip(dst) {
        let y = h * Vector3::new(a[0], a[1], 1.0);
        s += (y[0] / y[2] - b[0]).powi(2) + (y[1] / y[2] - b[1]).powi(2);
    }
    (s / src.len().max(1) as f64).sqrt()
}

/// An orthonormal basis `(a, b)` of the plane orthogonal to the unit `n`, with
/// `a × b = n`.
fn plane_basis(n: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let e = if n.x.abs() < 0.6 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let a = n.cross(&e).normalize();
    let b = n.cross(&a);
    (a, b)
}

/// `J(f, n)` of the module doc over the homographies `hs` (centred pixels); infinite when
/// the plane does not lie ahead of the reference camera across the `corners` of its
/// tracks' box (centred pixels): the plane seen edge-on, a degenerate family along which
/// `J` nearly vanishes for small `f`.
fn objective(hs: &[Matrix3<f64>], corners: &[[f64; 2]], f: f64, n: &Vector3<f64>) -> f64 {
    let ahead = |x: &[f64; 2]| n.x * x[0] + n.y * x[1] + n.z * f > 0.0;
    let first = corners.first().is_some_and(ahead);
    if corners.iter().any(|x| ahead(x) != first) {
        return f64::INFINITY;
    }
    let (a, b) = plane_basis(n);
    let k = Matrix3::new(f, 0.0, 0.0, 0.0, f, 0.0, 0.0, 0.0, 1.0);
    let kinv = Matrix3::new(1.0 / f, 0.0, 0.0, 0.0, 1.0 / f, 0.0, 0.0, 0.0, 1.0);
    let (ka, kb) = (k * a, k * b);
    hs.iter()
        .map(|h| {
            let u = kinv * (h * ka);
            let v = kinv * (h * kb);
            let (uu, vv) = (u.norm_squared(), v.norm_squared());
            if !(uu > 0.0 && vv > 0.0) {
                return 2.0;
            }
            u.dot(&v).powi(2) / (uu * vv) + ((uu - vv) / (uu + vv)).powi(2)
        })
        .sum()
}

/// The unit vector at polar angle `theta` and azimuth `phi`.
fn direction(theta: f64, phi: f64) -> Vector3<f64> {
    Vector3::new(
        theta.sin() * phi.cos(),
        theta.sin() * phi.sin(),
        theta.cos(),
    )
}

/// Minimises [`objective`]: a grid of focal lengths (`side · 0.2 … side · 20`, 41 values
/// log-spaced; the known one alone when given) × 800 normals on a Fibonacci hemisphere,
/// then a pattern search on `(ln f, θ, φ)` from the three best cells. Returns `(f, n, J)`.
fn calibrate(
    hs: &[Matrix3<f64>],
    corners: &[[f64; 2]],
    side: f64,
    known_focal: Option<f64>,
) -> (f64, Vector3<f64>, f64) {
    const NORMALS: usize = 800;
    let focals: Vec<f64> = match known_focal {
        Some(f) => vec![f],
        None => (0..=40)
            .map(|i| side * 0.2 * 100f64.powf(i as f64 / 40.0))
            .collect(),
    };
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let normals: Vec<(f64, f64)> = (0..NORMALS)
        .map(|i| {
            let z = (i as f64 + 0.5) / NORMALS as f64;
            (z.acos(), (i as f64 * golden) % std::f64::consts::TAU)
        })
        .collect();
    let mut cells: Vec<(f64, f64, f64, f64)> = Vec::with_capacity(focals.len() * NORMALS);
    for &f in &focals {
        for &(th, ph) in &normals {
            cells.push((
                objective(hs, corners, f, &direction(th, ph)),
                f.ln(),
                th,
                ph,
            ));
        }
    }
    cells.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut best = (f64::INFINITY, 0.0, 0.0, 0.0);
    for &(j0, lf0, th0, ph0) in cells.iter().take(3).filter(|c| c.0.is_finite()) {
        let mut cur = [lf0, th0, ph0];
        let mut j = j0;
        let mut steps = [if known_focal.is_some() { 0.0 } else { 0.06 }, 0.05, 0.05];
        let eval = |x: &[f64; 3]| objective(hs, corners, x[0].exp(), &direction(x[1], x[2]));
        for _ in 0..400 {
            let mut moved = false;
            for d in 0..3 {
                if steps[d] == 0.0 {
                    continue;
                }
                for s in [1.0, -1.0] {
                    let mut x = cur;
                    x[d] += s * steps[d];
                    let jx = eval(&x);
                    if jx < j {
                        (cur, j, moved) = (x, jx, true);
                        break;
                    }
                }
            }
            if !moved {
                for s in &mut steps {
                    *s *= 0.5;
                }
                if steps[1] < 1e-7 {
                    break;
                }
            }
        }
        if j < best.0 {
            best = (j, cur[0], cur[1], cur[2]);
        }
    }
    (best.1.exp(), direction(best.2, best.3), best.0)
}

/// The camera `(R, t)` of a frame from the homography `h` of plane coordinates `(α, β, 1)`
/// (the point `n + α a + β b`) to calibrated image coordinates, the sign chosen so that
/// most of `placed` (world points with their calibrated image) are in front.
fn pose_from_plane_homography(
    h: &Matrix3<f64>,
    n: &Vector3<f64>,
    a: &Vector3<f64>,
    b: &Vector3<f64>,
    placed: &[(Vector3<f64>, [f64; 2])],
) -> Option<(Matrix3<f64>, Vector3<f64>)> {
    let (h1, h2, h3) = (h.column(0), h.column(1), h.column(2));
    let lambda = (h1.norm() * h2.norm()).sqrt();
    if !(lambda.is_finite() && lambda > 0.0) {
        return None;
    }
    let basis = Matrix3::from_columns(&[*a, *b, *n]);
    let mut best: Option<(usize, Matrix3<f64>, Vector3<f64>)> = None;
    for sign in [1.0, -1.0] {
        let l = sign * lambda;
        let r1: Vector3<f64> = h1 / l;
        let r2: Vector3<f64> = h2 / l;
        let q = nearest_rotation(Matrix3::from_columns(&[r1, r2, r1.cross(&r2)]));
        let rot = q * basis.transpose();
        let t = h3 / l - rot * n;
        let front = placed.iter().filter(|(x, _)| (rot * x + t).z > 0.0).count();
        if best.as_ref().is_none_or(|b| front > b.0) {
            best = Some((front, rot, t));
        }
    }
    best.map(|(_, r, t)| (r, t))
}

/// Where the ray of calibrated image point `x` of camera `(R, t)` meets the plane
/// `nᵀX = 1`, in front of the camera; `None` when it does not.
fn on_plane(
    rot: &Matrix3<f64>,
    t: &Vector3<f64>,
    n: &Vector3<f64>,
    x: [f64; 2],
) -> Option<Vector3<f64>> {
    let centre = -rot.transpose() * t;
    let dir = rot.transpose() * Vector3::new(x[0], x[1], 1.0);
    let den = n.dot(&dir);
    if den.abs() < 1e-12 {
        return None;
    }
    let s = (1.0 - n.dot(&centre)) / den;
    (s > 0.0 && s.is_finite()).then(|| centre + dir * s)
}

/// The model of the module doc's registration: frame `r` the world, the plane `nᵀX = 1`
/// (its sign flipped so that `r`'s tracks are in front), the other frames registered in the
/// order of their placed tracks. `None` when a frame cannot be registered or a track not
/// placed. `O(n_obs)` plus `O(F)` per registered frame to pick the next.
#[allow(clippy::too_many_arguments)]
fn register(
    meas: &Measurements,
    tracks_of: &[Vec<usize>],
    frames_of: &[Vec<usize>],
    r: usize,
    focal: f64,
    normal: Vector3<f64>,
    pos: &dyn Fn(usize, usize) -> [f64; 2],
    c: [f64; 2],
) -> Option<PerspectiveModel> {
    let (nf, np) = (meas.n_frames(), meas.n_points());
    let cal = |f: usize, p: usize| {
        let x = pos(f, p);
        [x[0] / focal, x[1] / focal]
    };
    // The plane in front of the reference camera.
    let ahead = tracks_of[r]
        .iter()
        .map(|&p| {
            let x = cal(r, p);
            normal.dot(&Vector3::new(x[0], x[1], 1.0))
        })
        .filter(|d| *d > 0.0)
        .count();
    let n = if 2 * ahead >= tracks_of[r].len() {
        normal
    } else {
        -normal
    };
    let (a, b) = plane_basis(&n);
    let mut rotations = vec![None; nf];
    let mut translations = vec![Vector3::zeros(); nf];
    let mut points: Vec<Option<Vector3<f64>>> = vec![None; np];
    let mut placed_in = vec![0usize; nf];
    let place = |p: usize,
                 x: Vector3<f64>,
                 points: &mut Vec<Option<Vector3<f64>>>,
                 placed_in: &mut Vec<usize>| {
        points[p] = Some(x);
        for &f in &frames_of[p] {
            placed_in[f] += 1;
        }
    };
    rotations[r] = Some(Matrix3::identity());
    for &p in &tracks_of[r] {
        if let Some(x) = on_plane(&Matrix3::identity(), &Vector3::zeros(), &n, cal(r, p)) {
            place(p, x, &mut points, &mut placed_in);
        }
    }
    for _ in 1..nf {
        let g = (0..nf)
            .filter(|&f| rotations[f].is_none())
            .max_by_key(|&f| (placed_in[f], std::cmp::Reverse(f)))?;
        if placed_in[g] < MIN_PLACED {
            return None;
        }
        let placed: Vec<(Vector3<f64>, [f64; 2])> = tracks_of[g]
            .iter()
            .filter_map(|&p| points[p].map(|x| (x, cal(g, p))))
            .collect();
        let src: Vec<[f64; 2]> = placed.iter().map(|(x, _)| [a.dot(x), b.dot(x)]).collect();
        let dst: Vec<[f64; 2]> = placed.iter().map(|(_, y)| *y).collect();
        let h = homography(&src, &dst)?;
        let (rot, t) = pose_from_plane_homography(&h, &n, &a, &b, &placed)?;
        rotations[g] = Some(rot);
        translations[g] = t;
        for &p in &tracks_of[g] {
            if points[p].is_none()
                && let Some(x) = on_plane(&rot, &t, &n, cal(g, p))
            {
                place(p, x, &mut points, &mut placed_in);
            }
        }
    }
    Some(PerspectiveModel {
        focal_px: vec![focal; nf],
        principal_point: c,
        k1: 0.0,
        aspect: 1.0,
        rotations: rotations.into_iter().collect::<Option<Vec<_>>>()?,
        translations,
        points: points.into_iter().collect::<Option<Vec<_>>>()?,
    })
}

/// How far the tracks are from what a camera turning about its centre would see: over pairs
/// of frames sharing at least 8 tracks (each of up to 8 reference frames spread over the
/// sequence with up to 40 partners), the rotation that best maps one frame's rays onto the
/// other's (Kabsch's SVD solution of Wahba's problem on the calibrated, undistorted rays of
/// `model`'s intrinsics) and the median distance, in pixels, between the tracks' positions
/// and their rays so rotated; the largest of these medians. A camera that only rotates (a
/// tripod pan, a panorama) leaves the noise: about `1.7 σ` for noise `σ` per coordinate.
/// Then the rotations and the focal length are determined but the depths and the camera
/// centres are not. `None` without such a pair. `O(n_obs)` per reference.
///
/// Reference: W. Kabsch, "A solution for the best rotation to relate two sets of vectors",
/// Acta Cryst. A32, 1976.
pub fn rotation_parallax_px(meas: &Measurements, model: &PerspectiveModel) -> Option<f64> {
    const REFERENCES: usize = 8;
    let (nf, np) = (meas.n_frames(), meas.n_points());
    if model.focal_px.len() != nf || nf < 2 {
        return None;
    }
    let c = model.principal_point;
    let ray = |f: usize, p: usize| {
        let fo = model.focal_px[f];
        let (dx, dy) = (
            (meas.w[(2 * f, p)] - c[0]) / (model.aspect * fo),
            (meas.w[(2 * f + 1, p)] - c[1]) / fo,
        );
        // First-order undistortion of `n_d = n (1 + k₁‖n‖²)`.
        let u = 1.0 - model.k1 * (dx * dx + dy * dy);
        Vector3::new(dx * u, dy * u, 1.0).normalize()
    };
    let mut tracks_of: Vec<Vec<usize>> = vec![Vec::new(); nf];
    meas.for_each_observed(|f, p| tracks_of[f].push(p));
    let mut worst: Option<f64> = None;
    let mut seen = vec![false; np];
    for r in (0..REFERENCES.min(nf)).map(|k| k * nf / REFERENCES.min(nf)) {
        for &p in &tracks_of[r] {
            seen[p] = true;
        }
        for (g, shared) in partners(&tracks_of, r, &seen) {
            let mut h = Matrix3::zeros();
            for &p in &shared {
                h += ray(g, p) * ray(r, p).transpose();
            }
            // Kabsch: the nearest rotation of `Σ d_g d_rᵀ`.
            let rot = nearest_rotation(h);
            let mut dist: Vec<f64> = shared
                .iter()
                .filter_map(|&p| {
                    let y = rot * ray(r, p);
                    if y.z <= 0.0 {
                        return None;
                    }
                    let (nx, ny) = (y.x / y.z, y.y / y.z);
                    let k = 1.0 + model.k1 * (nx * nx + ny * ny);
                    let fo = model.focal_px[g];
                    let px = model.aspect * fo * k * nx + c[0];
                    let py = fo * k * ny + c[1];
                    Some((px - meas.w[(2 * g, p)]).hypot(py - meas.w[(2 * g + 1, p)]))
                })
                .collect();
            if dist.len() < MIN_SHARED {
                continue;
            }
            dist.sort_by(f64::total_cmp);
            let m = dist[dist.len() / 2];
            worst = Some(worst.map_or(m, |w: f64| w.max(m)));
        }
        for &p in &tracks_of[r] {
            seen[p] = false;
        }
    }
    worst
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::Mat;
    use nalgebra::Rotation3;

    /// Noise-free views of points on a tilted plane by a 500 px camera turning around it:
    /// the calibration finds the focal length and the start reprojects exactly.
    #[test]
    fn a_plane_is_calibrated_and_registered() {
        let (nf, np, focal) = (8, 40, 500.0);
        let n_true = Vector3::new(0.3, -0.2, 1.0).normalize();
        let (a, b) = plane_basis(&n_true);
        let mut rng = 12345u64;
        let mut uniform = || {
            rng = rng
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((rng >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        let pts: Vec<Vector3<f64>> = (0..np).map(|_| a * uniform() + b * uniform()).collect();
        let mut w = Mat::<f64>::zeros(2 * nf, np);
        for f in 0..nf {
            let ang = -0.5 + f as f64 / (nf - 1) as f64;
            let rot = Rotation3::from_euler_angles(0.15 * ang, ang, 0.05).into_inner();
            let t = Vector3::new(0.1, 0.0, 4.0);
            for (p, x) in pts.iter().enumerate() {
                let y = rot * x + t;
                w[(2 * f, p)] = focal * y.x / y.z + 320.0;
                w[(2 * f + 1, p)] = focal * y.y / y.z + 240.0;
            }
        }
        let meas = Measurements::complete(w);
        let (model, calib) = start(&meas, [320.0, 240.0], 640.0, None).expect("a start");
        assert!(
            (calib.focal_px - focal).abs() < 1e-3 * focal,
            "focal {}",
            calib.focal_px
        );
        assert!(calib.transfer_rms_px < 1e-6);
        let rms = meas.rms_of(|f, p| model.project(f, p));
        assert!(rms < 1e-5, "rms {rms}");
    }
}
