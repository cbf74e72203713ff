//! Truncated SVD (k = 4) vs faer's thin SVD on synthetic centred rank-3-plus-noise
//! observation matrices `W` (2F×N, σ = 0.5 px noise).
//!
//! Run: `cargo bench --bench svd`. Set `RANK3_BENCH_SKIP_THIN_LARGEST=1` to skip timing the
//! thin SVD at 2000×10000 (its accuracy reference is still computed once).
//! The accuracy lines (largest principal angle between the rank-3 left subspaces, relative
//! error of σ1..σ4 against the thin SVD) are printed outside the timed closures.

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use faer::Mat;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use rank3::svd::{SvdMethod, TruncatedSvdConfig, truncated_svd};

const SIZES: [(usize, usize); 5] = [
    (100, 500),
    (500, 2000),
    (1000, 5000),
    (2000, 5000),
    (2000, 10000),
];

/// Centred W = M S + noise: F orthographic cameras (random rotations, first two rows),
/// N points uniform in a ±100 px cube, Gaussian noise `noise` px, row means removed.
fn synthetic_w(rows: usize, cols: usize, noise: f64, seed: u64) -> Mat<f64> {
    let mut rng = StdRng::seed_from_u64(seed);
    let frames = rows / 2;
    let mut m = Mat::<f64>::zeros(rows, 3);
    for f in 0..frames {
        // Random rotation from a normalised Gaussian quaternion.
        let q: [f64; 4] = std::array::from_fn(|_| rng.sample(StandardNormal));
        let nq = q.iter().map(|x| x * x).sum::<f64>().sqrt();
        let [w, x, y, z] = q.map(|c| c / nq);
        let r0 = [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ];
        let r1 = [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ];
        for c in 0..3 {
            m[(2 * f, c)] = r0[c];
            m[(2 * f + 1, c)] = r1[c];
        }
    }
    let s = Mat::<f64>::from_fn(3, cols, |_, _| 200.0 * rng.random::<f64>() - 100.0);
    let mut w = &m * &s;
    for j in 0..cols {
        for i in 0..rows {
            w[(i, j)] += noise * rng.sample::<f64, _>(StandardNormal) + 50.0;
        }
    }
    for i in 0..rows {
        let mean = (0..cols).map(|j| w[(i, j)]).sum::<f64>() / cols as f64;
        for j in 0..cols {
            w[(i, j)] -= mean;
        }
    }
    w
}

/// Largest principal angle (radians) between the column spaces of two orthonormal bases,
/// from `sin θ_max = ‖(I − AAᵀ) B‖₂` (accurate for small angles, unlike `acos`).
fn max_principal_angle(a: faer::MatRef<'_, f64>, b: faer::MatRef<'_, f64>) -> f64 {
    let resid = b - a * (a.transpose() * b);
    let sv = resid.singular_values().expect("svd of an m×3 matrix");
    sv.first().copied().unwrap_or(0.0).min(1.0).asin()
}

fn bench_svd(cr: &mut Criterion) {
    let skip_largest_thin = std::env::var_os("RANK3_BENCH_SKIP_THIN_LARGEST").is_some();
    let configs = [
        ("truncated_k4", TruncatedSvdConfig::default()),
        (
            "truncated_k4_ct1e-2",
            TruncatedSvdConfig {
                cluster_tolerance: 1e-2,
                ..Default::default()
            },
        ),
    ];
    let mut group = cr.benchmark_group("svd");
    let mut table = Vec::new();
    for (idx, &(rows, cols)) in SIZES.iter().enumerate() {
        let w = synthetic_w(rows, cols, 0.5, 7 + idx as u64);
        let big = rows * cols >= 1000 * 5000;
        if big {
            group.sample_size(10);
            group.measurement_time(Duration::from_secs(5));
            group.warm_up_time(Duration::from_millis(500));
        } else {
            group.sample_size(20);
            group.measurement_time(Duration::from_secs(3));
            group.warm_up_time(Duration::from_secs(1));
        }
        let id = format!("{rows}x{cols}");

        // Accuracy, once, outside the timed closures.
        let t0 = Instant::now();
        let reference = w.thin_svd().expect("thin svd");
        let thin_once = t0.elapsed().as_secs_f64();
        let sref = reference.S().column_vector();
        for (name, cfg) in &configs {
            let t0 = Instant::now();
            let tr = truncated_svd(w.as_ref(), 4, cfg).expect("truncated svd");
            let trunc_once = t0.elapsed().as_secs_f64();
            let angle_u = max_principal_angle(reference.U().subcols(0, 3), tr.u.subcols(0, 3));
            let angle_v = max_principal_angle(reference.V().subcols(0, 3), tr.v.subcols(0, 3));
            let rel: Vec<f64> = (0..4)
                .map(|i| (tr.s[i] - sref[i]).abs() / sref[i])
                .collect();
            eprintln!(
                "svd {id} {name}: method {:?} fallback {:?} residual {:.2e} | angle U3 {:.2e} \
                 V3 {:.2e} | rel err σ1..σ4 {:.1e} {:.1e} {:.1e} {:.1e} | σ4/σ3 {:.4e} (ref \
                 {:.4e}) | one-shot thin {:.3} s truncated {:.4} s",
                tr.method,
                tr.fallback_reason,
                tr.residual,
                angle_u,
                angle_v,
                rel[0],
                rel[1],
                rel[2],
                rel[3],
                tr.s[3] / tr.s[2],
                sref[3] / sref[2],
                thin_once,
                trunc_once
            );
            let iters = match tr.method {
                SvdMethod::Randomized { iterations, .. } => iterations.to_string(),
                SvdMethod::Thin => "thin (fallback)".to_string(),
                SvdMethod::Gram => "gram".to_string(),
            };
            table.push((id.clone(), name.to_string(), iters, angle_u, angle_v, rel));
            group.bench_with_input(BenchmarkId::new(*name, &id), &w, |b, w| {
                b.iter(|| truncated_svd(black_box(w.as_ref()), 4, cfg).expect("truncated svd"))
            });
        }
        let largest = idx + 1 == SIZES.len();
        if !(largest && skip_largest_thin) {
            group.bench_with_input(BenchmarkId::new("thin", &id), &w, |b, w| {
                b.iter(|| black_box(w.as_ref()).thin_svd().expect("thin svd"))
            });
        }
    }
    group.finish();
    eprintln!();
    eprintln!(
        "| W size | variant | iterations | max angle U₃ (rad) | max angle V₃ (rad) | rel err σ1 | σ2 | σ3 | σ4 |"
    );
    eprintln!("|---|---|---|---|---|---|---|---|---|");
    for (id, name, iters, au, av, rel) in table {
        eprintln!(
            "| {id} | {name} | {iters} | {au:.1e} | {av:.1e} | {:.1e} | {:.1e} | {:.1e} | {:.1e} |",
            rel[0], rel[1], rel[2], rel[3]
        );
    }
}

criterion_group!(benches, bench_svd);
criterion_main!(benches);
