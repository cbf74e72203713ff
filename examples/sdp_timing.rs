//! Times one `rank3::sdp::psd_least_squares` call on an orthographic metric-upgrade
//! instance with F frames (default 100; pass another F as the first argument).
//!
//! `cargo run --release --example sdp_timing [F]`

use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use rank3::sdp::{SdpSettings, bilinear_row, psd_least_squares};

fn main() {
    let frames: usize = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(100);
    let mut rng = StdRng::seed_from_u64(7);
    let q = Matrix3::from_fn(|_, _| rng.sample::<f64, _>(StandardNormal)) * 5.0;
    let q_inv_t = q.try_inverse().expect("invertible").transpose();
    let truth = q * q.transpose();
    let mut a = Vec::with_capacity(3 * frames);
    let mut b = Vec::with_capacity(3 * frames);
    for _ in 0..frames {
        let r = UnitQuaternion::from_quaternion(Quaternion::new(
            rng.sample::<f64, _>(StandardNormal),
            rng.sample(StandardNormal),
            rng.sample(StandardNormal),
            rng.sample(StandardNormal),
        ))
        .to_rotation_matrix();
        // Noisy affine rows (1% noise) so the problem is not trivially exact.
        let noise =
            |rng: &mut StdRng| Vector3::from_fn(|_, _| 0.01 * rng.sample::<f64, _>(StandardNormal));
        let i = q_inv_t * (r.matrix().row(0).transpose() + noise(&mut rng));
        let j = q_inv_t * (r.matrix().row(1).transpose() + noise(&mut rng));
        a.extend([
            bilinear_row(&i, &i),
            bilinear_row(&j, &j),
            bilinear_row(&i, &j),
        ]);
        b.extend([1.0, 1.0, 0.0]);
    }
    let settings = SdpSettings::default();
    // Warm-up (first call pays one-time allocation / page-fault costs).
    let _ = psd_least_squares(&a, &b, None, &settings).expect("valid input");
    let runs = 50;
    let start = std::time::Instant::now();
    let mut last = None;
    for _ in 0..runs {
        last = Some(psd_least_squares(&a, &b, None, &settings).expect("valid input"));
    }
    let per_call = start.elapsed().as_secs_f64() / runs as f64;
    let sol = last.expect("ran at least once");
    println!(
        "F = {frames}: {:.1} µs per call (mean of {runs}), status {:?}, {} iterations, \
         objective {:.3e}, rel. error vs truth {:.2e}",
        per_call * 1e6,
        sol.status,
        sol.iterations,
        sol.objective,
        (sol.l - truth).norm() / truth.norm()
    );
}
