//! Links a binary against rank3 as an ordinary dependency (rlib, as the CLI and users do)
//! with no system BLAS/LAPACK, and runs clarabel with PSD cones through rank3's built-in
//! shim: a 5×5 cone (clarabel's dense BLAS/LAPACK paths, used only above 3×3) and the
//! 3×3 metric-upgrade problem.
#![cfg(feature = "builtin-lapack")]

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettings, DefaultSolver, IPSolver, PSDTriangleConeT, SolverStatus, ZeroConeT,
};

/// min ⟨C, X⟩ s.t. tr X = 1, X ⪰ 0 has value λ_min(C).
#[test]
fn clarabel_psd_cone_5x5_min_eigenvalue() {
    let n = 5;
    let nvec = n * (n + 1) / 2;
    // C = tridiag(-1, 2, -1): λ_min = 2 − 2 cos(π / (n + 1)).
    let c_at = |i: usize, j: usize| -> f64 {
        if i == j {
            2.0
        } else if i.abs_diff(j) == 1 {
            -1.0
        } else {
            0.0
        }
    };
    // svec order: upper triangle column by column, off-diagonals × √2.
    let mut q = Vec::with_capacity(nvec);
    let mut trace_row = Vec::with_capacity(nvec);
    for j in 0..n {
        for i in 0..=j {
            let off = i != j;
            q.push(if off {
                std::f64::consts::SQRT_2 * c_at(i, j)
            } else {
                c_at(i, j)
            });
            trace_row.push(if off { 0.0 } else { 1.0 });
        }
    }
    let p = CscMatrix::<f64>::zeros((nvec, nvec));
    let (mut ii, mut jj, mut vv) = (Vec::new(), Vec::new(), Vec::new());
    for (k, &t) in trace_row.iter().enumerate() {
        ii.push(k);
        jj.push(k);
        vv.push(-1.0);
        if t != 0.0 {
            ii.push(nvec);
            jj.push(k);
            vv.push(1.0);
        }
    }
    let a = CscMatrix::new_from_triplets(nvec + 1, nvec, ii, jj, vv);
    let mut b = vec![0.0; nvec];
    b.push(1.0);
    let cones = [PSDTriangleConeT(n), ZeroConeT(1)];
    let settings = DefaultSettings {
        verbose: false,
        ..DefaultSettings::default()
    };
    let mut solver = DefaultSolver::new(&p, &q, &a, &b, &cones, settings).unwrap();
    solver.solve();
    assert_eq!(solver.solution.status, SolverStatus::Solved);
    let want = 2.0 - 2.0 * (std::f64::consts::PI / (n as f64 + 1.0)).cos();
    assert!(
        (solver.solution.obj_val - want).abs() < 1e-7,
        "{}",
        solver.solution.obj_val
    );
}

#[test]
fn rank3_psd_least_squares_links() {
    // Fit L = I from the three constraints per "frame" with axis-aligned rows.
    let e = [
        nalgebra::Vector3::new(1.0, 0.0, 0.0),
        nalgebra::Vector3::new(0.0, 1.0, 0.0),
        nalgebra::Vector3::new(0.0, 0.0, 1.0),
    ];
    let mut a = Vec::new();
    let mut b = Vec::new();
    for x in 0..3 {
        for y in x..3 {
            a.push(rank3::sdp::bilinear_row(&e[x], &e[y]));
            b.push(if x == y { 1.0 } else { 0.0 });
        }
    }
    let sol = rank3::sdp::psd_least_squares(&a, &b, None, &Default::default()).unwrap();
    assert!((sol.l - nalgebra::Matrix3::identity()).norm() < 1e-8);
}
