//! Speed of the Levenberg–Marquardt metric refinement ([`rank3::refine::refine`]) on a
//! synthetic complete problem: F = 100 frames × N = 2000 points, scaled orthography,
//! σ = 0.5 px noise, start perturbed from the truth (rotations ~5°, points ~3 px).
//!
//! Run with `cargo run --release --example refine_speed [frames] [points] [percent_visible]`
//! (defaults 100, 2000, 100); prints the time of every LM iteration and the total. Below
//! ~70 % visibility the reduced camera matrix is accumulated sparsely instead of by GEMM.

use std::time::Instant;

use nalgebra::{Rotation3, Vector2, Vector3};
use rand::prelude::*;
use rand_distr::{Distribution, Normal};
use rank3::refine::{RefineConfig, refine};
use rank3::{CameraModel, Event, Measurements, MetricModel, Observer};

struct Timer {
    last: Instant,
    rows: Vec<(usize, f64, f64, f64)>,
}

impl Observer for Timer {
    fn on_event(&mut self, e: &Event<'_>) {
        if let Event::Iteration {
            iteration,
            rms,
            lambda,
            ..
        } = e
        {
            let now = Instant::now();
            self.rows
                .push((*iteration, (now - self.last).as_secs_f64(), *rms, *lambda));
            self.last = now;
        }
    }
}

fn main() {
    let args: Vec<f64> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let nf = args.first().map_or(100, |&v| v as usize);
    let n = args.get(1).map_or(2000, |&v| v as usize);
    let visible = args.get(2).map_or(1.0, |&v| v / 100.0);
    let cam = CameraModel::ScaledOrthographic;
    let mut rng = StdRng::seed_from_u64(42);
    let g = Normal::new(0.0, 1.0).unwrap();

    let truth = MetricModel {
        rotations: (0..nf)
            .map(|_| {
                Rotation3::new(Vector3::new(
                    rng.random_range(-1.5..1.5),
                    rng.random_range(-1.5..1.5),
                    rng.random_range(-1.5..1.5),
                ))
            })
            .collect(),
        translations: (0..nf)
            .map(|_| {
                Vector2::new(
                    320.0 + rng.random_range(-50.0..50.0),
                    240.0 + rng.random_range(-50.0..50.0),
                )
            })
            .collect(),
        scales: (0..nf).map(|_| rng.random_range(0.8..1.2)).collect(),
        points: (0..n)
            .map(|_| {
                Vector3::new(
                    rng.random_range(-100.0..100.0),
                    rng.random_range(-100.0..100.0),
                    rng.random_range(-100.0..100.0),
                )
            })
            .collect(),
        aspect: 1.0,
    };
    let mut w = truth.predict();
    for r in 0..2 * nf {
        for p in 0..n {
            w[(r, p)] += 0.5 * g.sample(&mut rng);
        }
    }
    let mask = (0..nf * n).map(|_| rng.random::<f64>() < visible).collect();
    let meas = Measurements::new(w, mask);

    let mut model = truth.clone();
    for r in &mut model.rotations {
        let axis = Vector3::new(g.sample(&mut rng), g.sample(&mut rng), g.sample(&mut rng));
        *r = Rotation3::new(axis.normalize() * 5f64.to_radians()) * *r;
    }
    for x in &mut model.points {
        *x += Vector3::new(g.sample(&mut rng), g.sample(&mut rng), g.sample(&mut rng)) * 3.0;
    }
    for s in &mut model.scales {
        *s *= 1.0 + 0.02 * g.sample(&mut rng);
    }

    let mut timer = Timer {
        last: Instant::now(),
        rows: Vec::new(),
    };
    let t0 = Instant::now();
    let res = refine(&meas, &mut model, cam, &RefineConfig::default(), &mut timer)
        .expect("valid synthetic problem");
    let total = t0.elapsed().as_secs_f64();

    println!(
        "refine_speed: F = {nf}, N = {n}, {:.0} % visible, {cam}, {} observations",
        100.0 * visible,
        meas.n_observed()
    );
    println!("iter  seconds     rms(px)       lambda");
    for (it, s, rms, lambda) in &timer.rows {
        println!("{it:>4}  {s:>8.4}  {rms:>10.6}  {lambda:>10.3e}");
    }
    let iters = res.report.iterations.max(1);
    println!(
        "status {:?}, {} iterations, total {:.3} s ({:.3} s/iteration incl. setup), rms {:.4} -> {:.4} px",
        res.report.status,
        res.report.iterations,
        total,
        total / iters as f64,
        res.rms_before,
        res.rms_after
    );
}
