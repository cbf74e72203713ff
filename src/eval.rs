//! Comparing a reconstruction with ground truth (tests, examples, benchmarks).
//!
//! Orthographic structure from motion recovers the scene up to a rotation, a translation,
//! (for scaled orthography, or any unknown image scale) a global scale, and the
//! depth-reversal (Necker) reflection. These helpers remove exactly those.

use nalgebra::{Matrix3, Rotation3, Vector3};

/// A similarity (optionally improper) that maps estimated points onto true ones:
/// `truth ≈ scale · rotation · est + translation`.
#[derive(Debug, Clone)]
pub struct Alignment {
    pub scale: f64,
    /// Orthogonal; determinant −1 when the reflection was allowed and better.
    pub rotation: Matrix3<f64>,
    pub translation: Vector3<f64>,
    /// RMS distance after alignment.
    pub rms: f64,
    /// RMS distance after alignment divided by the RMS spread of the truth about its
    /// centroid (scale-free structure error).
    pub relative_rms: f64,
}

/// Least-squares similarity alignment (Umeyama, PAMI 13(4), 1991): minimizes
/// `Σ ‖t_i − (s R e_i + c)‖²` over scale `s`, orthogonal `R` (proper unless
/// `allow_reflection`), and `c`. O(n).
///
/// Returns `None` for fewer than 3 points or a degenerate (zero-spread) estimate.
pub fn align_similarity(
    est: &[Vector3<f64>],
    truth: &[Vector3<f64>],
    allow_reflection: bool,
) -> Option<Alignment> {
    let n = est.len();
    if n < 3 || truth.len() != n {
        return None;
    }
    let me = est.iter().fold(Vector3::zeros(), |a, p| a + p) / n as f64;
    let mt = truth.iter().fold(Vector3::zeros(), |a, p| a + p) / n as f64;
    let mut cov = Matrix3::zeros();
    let mut var_e = 0.0;
    let mut var_t = 0.0;
    for (e, t) in est.iter().zip(truth) {
        let (de, dt) = (e - me, t - mt);
        cov += dt * de.transpose();
        var_e += de.norm_squared();
        var_t += dt.norm_squared();
    }
    if var_e <= 0.0 || var_t <= 0.0 {
        return None;
    }
    let svd = cov.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let mut d = Matrix3::identity();
    if !allow_reflection && (u * vt).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let rotation = u * d * vt;
    let trace: f64 = (0..3).map(|i| svd.singular_values[i] * d[(i, i)]).sum();
    let scale = trace / var_e;
    let translation = mt - rotation * me * scale;
    let ss: f64 = est
        .iter()
        .zip(truth)
        .map(|(e, t)| (t - (rotation * e * scale + translation)).norm_squared())
        .sum();
    let rms = (ss / n as f64).sqrt();
    Some(Alignment {
        scale,
        rotation,
        translation,
        rms,
        relative_rms: rms / (var_t / n as f64).sqrt(),
    })
}

/// Relative structure error up to a similarity and the depth reversal: the smaller
/// `relative_rms` of the proper and the reflected alignment. `f64::INFINITY` if degenerate.
pub fn structure_error(est: &[Vector3<f64>], truth: &[Vector3<f64>]) -> f64 {
    align_similarity(est, truth, true).map_or(f64::INFINITY, |a| a.relative_rms)
}

/// Per-frame rotation errors in degrees between estimated and true cameras, after both are
/// expressed relative to frame 0 (`R_f R_0ᵀ`) and allowing the global depth reversal
/// (`D R D`, `D = diag(1, 1, −1)`): the branch with the smaller median is returned.
pub fn rotation_errors_deg(est: &[Rotation3<f64>], truth: &[Rotation3<f64>]) -> Vec<f64> {
    rotation_errors_deg_with(est, truth, true)
}

/// [`rotation_errors_deg`], with the depth-reversal branch only when `allow_mirror` (two
/// Euclidean perspective reconstructions have no such ambiguity).
pub fn rotation_errors_deg_with(
    est: &[Rotation3<f64>],
    truth: &[Rotation3<f64>],
    allow_mirror: bool,
) -> Vec<f64> {
    if est.is_empty() || est.len() != truth.len() {
        return Vec::new();
    }
    let d = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0));
    let branch = |mirror: bool| -> Vec<f64> {
        est.iter()
            .zip(truth)
            .map(|(e, t)| {
                let re = e.matrix() * est[0].matrix().transpose();
                let mut rt = t.matrix() * truth[0].matrix().transpose();
                if mirror {
                    rt = d * rt * d;
                }
                rotation_angle(&(re * rt.transpose())).to_degrees()
            })
            .collect()
    };
    let a = branch(false);
    if !allow_mirror {
        return a;
    }
    let b = branch(true);
    if median(&a) <= median(&b) { a } else { b }
}

/// Rotation angle of a (nearly) orthogonal matrix, accurate near 0 and π:
/// `atan2(‖vee(R − Rᵀ)‖ / 2, (tr R − 1) / 2)`.
pub fn rotation_angle(r: &Matrix3<f64>) -> f64 {
    let s = Vector3::new(
        r[(2, 1)] - r[(1, 2)],
        r[(0, 2)] - r[(2, 0)],
        r[(1, 0)] - r[(0, 1)],
    )
    .norm()
        / 2.0;
    let c = (r.trace() - 1.0) / 2.0;
    s.atan2(c)
}

/// Median of a slice (NaN for an empty one).
pub fn median(v: &[f64]) -> f64 {
    percentile(v, 50.0)
}

/// Percentile (linear interpolation between order statistics), `q` in [0, 100].
pub fn percentile(v: &[f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    let pos = (q / 100.0).clamp(0.0, 1.0) * (s.len() - 1) as f64;
    let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
    s[lo] + (s[hi] - s[lo]) * (pos - lo as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_similarity_and_reflection() {
        let pts: Vec<Vector3<f64>> = (0..20)
            .map(|i| {
                let x = i as f64;
                Vector3::new(x.sin() * 3.0, (x * 0.7).cos(), x * 0.1)
            })
            .collect();
        let r = Rotation3::from_euler_angles(0.3, -0.2, 1.0);
        let moved: Vec<_> = pts
            .iter()
            .map(|p| r * p * 2.5 + Vector3::new(1.0, 2.0, 3.0))
            .collect();
        let a = align_similarity(&moved, &pts, false).unwrap();
        assert!(a.rms < 1e-12 && (a.scale - 0.4).abs() < 1e-12);
        let mirrored: Vec<_> = moved
            .iter()
            .map(|p| Vector3::new(p[0], p[1], -p[2]))
            .collect();
        assert!(
            align_similarity(&mirrored, &pts, false)
                .unwrap()
                .relative_rms
                > 0.1
        );
        assert!(structure_error(&mirrored, &pts) < 1e-12);
        assert_eq!(percentile(&[1.0, 2.0, 3.0, 4.0], 50.0), 2.5);
    }
}
