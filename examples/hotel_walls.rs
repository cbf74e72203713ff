//! The angle between the two dominant planes of a metric reconstruction — on the CMU hotel
//! sequence, the two main building walls, perpendicular in the real model.
//!
//! Reads the `reconstruction.json` written by `rank3 run` (inlier points only) and finds the
//! two dominant planes by sequential RANSAC: a plane through three random points, its
//! inliers the points closer than `τ = frac · s`, where the scene size `s` is the median
//! distance of the points to their coordinate-wise median; the plane with the most inliers
//! is refitted by least squares (normal = eigenvector of the smallest eigenvalue of the
//! inliers' scatter matrix; inliers recomputed, twice), its inliers removed, and the search
//! repeated for the second plane. Prints both planes (normal, inlier count, RMS distance)
//! and the angle between their normals.
//!
//! Reference: M. A. Fischler and R. C. Bolles, "Random sample consensus", CACM 1981.
//! Complexity: O(T·N) for T RANSAC trials over N points (T = 2000 per plane).
//!
//! ```text
//! cargo run --release --no-default-features --features builtin-lapack -- \
//!     run ../shared/datasets/hotel/images --out out/hotel
//! cargo run --release --no-default-features --features builtin-lapack --example hotel_walls \
//!     -- out/hotel/reconstruction.json [FRAC=0.03] [SEED=1]
//! ```

use nalgebra::{Matrix3, Vector3};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

/// A plane `n·x = c` with unit normal `n`.
#[derive(Debug, Clone, Copy)]
struct Plane {
    n: Vector3<f64>,
    c: f64,
}

impl Plane {
    fn dist(&self, p: &Vector3<f64>) -> f64 {
        (self.n.dot(p) - self.c).abs()
    }
}

/// Least-squares plane through `pts` (at least 3).
fn fit(pts: &[Vector3<f64>]) -> Plane {
    let m = pts.iter().sum::<Vector3<f64>>() / pts.len() as f64;
    let s = pts
        .iter()
        .map(|p| (p - m) * (p - m).transpose())
        .sum::<Matrix3<f64>>();
    let e = s.symmetric_eigen();
    let n = e.eigenvectors.column(e.eigenvalues.imin()).into_owned();
    Plane { n, c: n.dot(&m) }
}

/// The dominant plane of `pts` and its inlier indices.
fn ransac(pts: &[Vector3<f64>], tau: f64, rng: &mut StdRng) -> Option<(Plane, Vec<usize>)> {
    if pts.len() < 3 {
        return None;
    }
    let inliers =
        |pl: &Plane| -> Vec<usize> { (0..pts.len()).filter(|&i| pl.dist(&pts[i]) < tau).collect() };
    let mut best: Option<(Plane, usize)> = None;
    for _ in 0..2000 {
        let (a, b, c) = (
            rng.random_range(0..pts.len()),
            rng.random_range(0..pts.len()),
            rng.random_range(0..pts.len()),
        );
        let n = (pts[b] - pts[a]).cross(&(pts[c] - pts[a]));
        if n.norm() < 1e-12 {
            continue;
        }
        let n = n.normalize();
        let pl = Plane {
            n,
            c: n.dot(&pts[a]),
        };
        let k = pts.iter().filter(|p| pl.dist(p) < tau).count();
        if best.as_ref().is_none_or(|b| k > b.1) {
            best = Some((pl, k));
        }
    }
    let (mut pl, _) = best?;
    let mut idx = inliers(&pl);
    for _ in 0..2 {
        if idx.len() < 3 {
            break;
        }
        let sel: Vec<Vector3<f64>> = idx.iter().map(|&i| pts[i]).collect();
        pl = fit(&sel);
        idx = inliers(&pl);
    }
    Some((pl, idx))
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = args
        .first()
        .cloned()
        .unwrap_or_else(|| "out/hotel/reconstruction.json".into());
    let frac: f64 = args.get(1).map_or(Ok(0.03), |s| s.parse())?;
    let seed: u64 = args.get(2).map_or(Ok(1), |s| s.parse())?;
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path)?)?;
    let mut pts = Vec::new();
    // The Euclidean points of a perspective reconstruction when present, else the metric
    // (affine-family) ones.
    let points = if json["perspective"].is_object() {
        println!("using the perspective reconstruction's points");
        &json["perspective"]["points"]
    } else {
        &json["points"]
    };
    for p in points.as_array().ok_or("no `points` array")? {
        if p["inlier"].as_bool() != Some(true) {
            continue;
        }
        let v: Vec<f64> = p["xyz"]
            .as_array()
            .ok_or("point without xyz")?
            .iter()
            .filter_map(|x| x.as_f64())
            .collect();
        if v.len() == 3 {
            pts.push(Vector3::new(v[0], v[1], v[2]));
        }
    }
    if pts.len() < 6 {
        return Err(format!("{path}: only {} inlier points", pts.len()).into());
    }
    let med = Vector3::from_fn(|k, _| median(pts.iter().map(|p| p[k]).collect()));
    let size = median(pts.iter().map(|p| (p - med).norm()).collect());
    let tau = frac * size;
    println!(
        "{path}: {} inlier points, metric RMS {:.3} px, scene size s = {size:.4}, τ = {frac}·s = {tau:.4}",
        pts.len(),
        json["rms_px"].as_f64().unwrap_or(f64::NAN)
    );
    // Spread of the structure along its principal axes (depth conditioning).
    let m = pts.iter().sum::<Vector3<f64>>() / pts.len() as f64;
    let scatter = pts
        .iter()
        .map(|p| (p - m) * (p - m).transpose())
        .sum::<Matrix3<f64>>()
        / pts.len() as f64;
    let mut sd: Vec<f64> = scatter
        .symmetric_eigen()
        .eigenvalues
        .iter()
        .map(|v| v.max(0.0).sqrt())
        .collect();
    sd.sort_by(|a, b| b.total_cmp(a));
    println!(
        "principal standard deviations of the structure: {:.4} {:.4} {:.4}",
        sd[0], sd[1], sd[2]
    );
    let mut rng = StdRng::seed_from_u64(seed);
    let mut rest: Vec<usize> = (0..pts.len()).collect();
    let mut planes = Vec::new();
    for k in 0..2 {
        let sub: Vec<Vector3<f64>> = rest.iter().map(|&i| pts[i]).collect();
        let Some((pl, idx)) = ransac(&sub, tau, &mut rng) else {
            println!("plane {}: not found", k + 1);
            break;
        };
        let rms = (idx.iter().map(|&i| pl.dist(&sub[i]).powi(2)).sum::<f64>()
            / idx.len().max(1) as f64)
            .sqrt();
        println!(
            "plane {}: normal ({:+.3}, {:+.3}, {:+.3}), {} inliers, RMS distance {:.4} ({:.2} τ)",
            k + 1,
            pl.n[0],
            pl.n[1],
            pl.n[2],
            idx.len(),
            rms,
            rms / tau
        );
        let taken: std::collections::HashSet<usize> = idx.iter().map(|&i| rest[i]).collect();
        rest.retain(|i| !taken.contains(i));
        planes.push(pl);
    }
    if let [a, b] = planes[..] {
        let angle = a.n.dot(&b.n).abs().min(1.0).acos().to_degrees();
        println!("angle between the two planes: {angle:.1}° (90° in the real model)");
    }
    Ok(())
}
