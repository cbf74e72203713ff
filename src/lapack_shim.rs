//! Pure-Rust (faer) implementations of the eight Fortran-ABI BLAS/LAPACK routines that
//! clarabel's semidefinite cone support links against.
//!
//! clarabel 0.11 with the `sdp` feature calls BLAS/LAPACK through the `blas`/`lapack`
//! crates, which declare `extern "C"` Fortran symbols (`dgemm_`, …) and leave the choice of
//! library to the final binary. rank3 links no system BLAS/LAPACK: this module defines the
//! symbols itself (feature `builtin-lapack`, on by default) on top of faer, so the PSD cone
//! works everywhere without a C/Fortran toolchain. Disable the feature to link a real
//! BLAS/LAPACK (e.g. OpenBLAS through `blas-src`/`lapack-src`) instead.
//!
//! Routines, with the argument conventions of the reference BLAS/LAPACK (all arguments by
//! pointer, column-major storage with leading dimensions, 1-based `info` codes):
//!
//! | symbol    | operation                                              | flags honoured            |
//! |-----------|--------------------------------------------------------|---------------------------|
//! | `dgemm_`  | `C ← α op(A) op(B) + β C`                              | `transa`, `transb` ∈ N/T/C |
//! | `dsyrk_`  | `C ← α A Aᵀ + β C` or `α Aᵀ A + β C` (one triangle)    | `uplo` U/L, `trans` N/T/C |
//! | `dsyr2k_` | `C ← α (A Bᵀ + B Aᵀ) + β C` or transposed (one triangle) | `uplo` U/L, `trans` N/T/C |
//! | `dpotrf_` | Cholesky `A = L Lᵀ` or `A = Uᵀ U` in place             | `uplo` U/L                |
//! | `dpotrs_` | solve `A X = B` from the `dpotrf_` factor              | `uplo` U/L                |
//! | `dsyevr_` | all eigenvalues (ascending) and optionally eigenvectors | `jobz` N/V, `range` A only, `uplo` U/L |
//! | `dgesdd_` | SVD `A = U Σ Vᵀ`                                       | `jobz` N/S/A (not O)      |
//! | `dgesvd_` | SVD `A = U Σ Vᵀ`                                       | `jobu`/`jobvt` N/S/A (not O) |
//!
//! LAPACK routines answer the `lwork = -1` (and `liwork = -1`) workspace query with the
//! reference LAPACK minimum sizes and check `lwork`/`liwork` against them otherwise; the
//! workspace itself is not used (faer allocates its own scratch). Unsupported flags and bad
//! dimensions give `info = -i` for the offending argument `i`, as LAPACK's argument checks
//! do, but nothing is printed (no `xerbla`). The BLAS routines have no `info` argument:
//! with invalid arguments they return without touching any output.
//!
//! Differences from the reference implementation: `dsyevr_` ignores `abstol`, `vl`, `vu`,
//! `il`, `iu` (only `range = 'A'` is supported), sets `isuppz` to full support, and leaves
//! `A` intact instead of destroying it; `dgesdd_`/`dgesvd_` also leave `A` intact. The
//! decompositions are faer's (Householder tridiagonalisation + divide and conquer /
//! implicit QR for the symmetric eigenproblem, bidiagonalisation + divide and conquer /
//! QR for the SVD), so results agree with LAPACK up to rounding and the usual sign
//! ambiguity of eigen/singular vectors. Everything runs single-threaded (`Par::Seq`):
//! clarabel calls these on small dense blocks from inside its own loop.
//!
//! Complexity: `dgemm_` O(mnk); `dsyrk_`/`dsyr2k_` O(n²k); `dpotrf_` O(n³/3);
//! `dpotrs_` O(n² nrhs); `dsyevr_` O(n³); `dgesdd_`/`dgesvd_` O(mn·min(m, n)).
//!
//! References: E. Anderson et al., *LAPACK Users' Guide*, 3rd ed., SIAM 1999 (argument
//! conventions and workspace formulas); J. J. Dongarra et al., "A set of level 3 basic
//! linear algebra subprograms", ACM TOMS 16(1), 1990.
//!
//! # Safety
//!
//! These are `unsafe extern "C"` functions with the reference-BLAS/LAPACK contract: every
//! pointer must be valid for the extent implied by the dimensions and leading dimensions
//! passed alongside it, and output arrays must not alias inputs (except where LAPACK
//! itself works in place).

#![allow(clippy::too_many_arguments)]
#![allow(clippy::missing_safety_doc)]

use std::os::raw::{c_char, c_int};

use faer::diag::Diag;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::matmul::triangular::BlockStructure;
use faer::reborrow::ReborrowMut;
use faer::{Accum, Conj, Mat, MatMut, MatRef, Par};

/// Makes the calling object file reference every symbol of this module, so that static
/// linkers that only pull archive members on demand (GNU ld scanning rank3's rlib before
/// clarabel's) still include the shim. Called by [`crate::sdp::psd_least_squares`]; costs
/// nothing measurable.
#[inline(never)]
pub(crate) fn ensure_linked() {
    let symbols: [*const (); 8] = [
        dgemm_ as *const (),
        dsyrk_ as *const (),
        dsyr2k_ as *const (),
        dpotrf_ as *const (),
        dpotrs_ as *const (),
        dsyevr_ as *const (),
        dgesdd_ as *const (),
        dgesvd_ as *const (),
    ];
    std::hint::black_box(symbols);
}

// ---------------------------------------------------------------------------------------
// helpers
// ---------------------------------------------------------------------------------------

/// Reads a Fortran character flag, upper-cased.
unsafe fn flag(c: *const c_char) -> u8 {
    unsafe { (*c as u8).to_ascii_uppercase() }
}

/// Column-major view of an `nrows × ncols` block with leading dimension `ld`.
/// Callers guarantee `nrows, ncols > 0` and `ld ≥ nrows`.
unsafe fn view<'a>(ptr: *const f64, nrows: usize, ncols: usize, ld: usize) -> MatRef<'a, f64> {
    unsafe { MatRef::from_raw_parts(ptr, nrows, ncols, 1, ld as isize) }
}

/// Mutable column-major view; same contract as [`view`].
unsafe fn view_mut<'a>(ptr: *mut f64, nrows: usize, ncols: usize, ld: usize) -> MatMut<'a, f64> {
    unsafe { MatMut::from_raw_parts_mut(ptr, nrows, ncols, 1, ld as isize) }
}

/// Parses a BLAS transpose flag: `Some(false)` for N, `Some(true)` for T/C (real data).
fn trans_flag(c: u8) -> Option<bool> {
    match c {
        b'N' => Some(false),
        b'T' | b'C' => Some(true),
        _ => None,
    }
}

/// Parses a triangle flag: `Some(true)` for U, `Some(false)` for L.
fn uplo_flag(c: u8) -> Option<bool> {
    match c {
        b'U' => Some(true),
        b'L' => Some(false),
        _ => None,
    }
}

/// Scales the `upper`/lower triangle (diagonal included) of square `c` by `beta`,
/// writing exact zeros when `beta == 0` (so NaNs in `C` do not propagate, as in BLAS).
fn scale_triangle(mut c: MatMut<'_, f64>, upper: bool, beta: f64) {
    let n = c.nrows();
    for j in 0..n {
        let (lo, hi) = if upper { (0, j + 1) } else { (j, n) };
        for i in lo..hi {
            let v = &mut c[(i, j)];
            *v = if beta == 0.0 { 0.0 } else { beta * *v };
        }
    }
}

/// Scales all of `c` by `beta` (exact zeros for `beta == 0`).
fn scale_all(mut c: MatMut<'_, f64>, beta: f64) {
    for j in 0..c.ncols() {
        for i in 0..c.nrows() {
            let v = &mut c[(i, j)];
            *v = if beta == 0.0 { 0.0 } else { beta * *v };
        }
    }
}

fn dim(x: c_int) -> Option<usize> {
    usize::try_from(x).ok()
}

// ---------------------------------------------------------------------------------------
// BLAS level 3
// ---------------------------------------------------------------------------------------

/// `C ← α op(A) op(B) + β C`, `op(A)` m×k, `op(B)` k×n, `C` m×n (BLAS `DGEMM`).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dgemm_(
    transa: *const c_char,
    transb: *const c_char,
    m: *const c_int,
    n: *const c_int,
    k: *const c_int,
    alpha: *const f64,
    a: *const f64,
    lda: *const c_int,
    b: *const f64,
    ldb: *const c_int,
    beta: *const f64,
    c: *mut f64,
    ldc: *const c_int,
) {
    unsafe {
        let (Some(ta), Some(tb)) = (trans_flag(flag(transa)), trans_flag(flag(transb))) else {
            return;
        };
        let (Some(m), Some(n), Some(k)) = (dim(*m), dim(*n), dim(*k)) else {
            return;
        };
        let (Some(lda), Some(ldb), Some(ldc)) = (dim(*lda), dim(*ldb), dim(*ldc)) else {
            return;
        };
        let (a_rows, a_cols) = if ta { (k, m) } else { (m, k) };
        let (b_rows, b_cols) = if tb { (n, k) } else { (k, n) };
        if lda < a_rows.max(1) || ldb < b_rows.max(1) || ldc < m.max(1) {
            return;
        }
        if m == 0 || n == 0 {
            return;
        }
        let (alpha, beta) = (*alpha, *beta);
        let mut cm = view_mut(c, m, n, ldc);
        if alpha == 0.0 || k == 0 {
            if beta != 1.0 {
                scale_all(cm, beta);
            }
            return;
        }
        let am = view(a, a_rows, a_cols, lda);
        let bm = view(b, b_rows, b_cols, ldb);
        let am = if ta { am.transpose() } else { am };
        let bm = if tb { bm.transpose() } else { bm };
        let accum = if beta == 0.0 {
            Accum::Replace
        } else {
            if beta != 1.0 {
                scale_all(cm.rb_mut(), beta);
            }
            Accum::Add
        };
        faer::linalg::matmul::matmul(cm, accum, am, bm, alpha, Par::Seq);
    }
}

/// Symmetric rank-k update of one triangle: `C ← α A Aᵀ + β C` (`trans = N`, A n×k) or
/// `C ← α Aᵀ A + β C` (`trans = T`, A k×n) (BLAS `DSYRK`).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dsyrk_(
    uplo: *const c_char,
    trans: *const c_char,
    n: *const c_int,
    k: *const c_int,
    alpha: *const f64,
    a: *const f64,
    lda: *const c_int,
    beta: *const f64,
    c: *mut f64,
    ldc: *const c_int,
) {
    unsafe {
        let (Some(upper), Some(t)) = (uplo_flag(flag(uplo)), trans_flag(flag(trans))) else {
            return;
        };
        let (Some(n), Some(k), Some(lda), Some(ldc)) = (dim(*n), dim(*k), dim(*lda), dim(*ldc))
        else {
            return;
        };
        let (a_rows, a_cols) = if t { (k, n) } else { (n, k) };
        if lda < a_rows.max(1) || ldc < n.max(1) || n == 0 {
            return;
        }
        let (alpha, beta) = (*alpha, *beta);
        let mut cm = view_mut(c, n, n, ldc);
        if beta != 1.0 {
            scale_triangle(cm.rb_mut(), upper, beta);
        }
        if alpha == 0.0 || k == 0 {
            return;
        }
        let am = view(a, a_rows, a_cols, lda);
        let op = if t { am.transpose() } else { am };
        let structure = if upper {
            BlockStructure::TriangularUpper
        } else {
            BlockStructure::TriangularLower
        };
        faer::linalg::matmul::triangular::matmul(
            cm,
            structure,
            Accum::Add,
            op,
            BlockStructure::Rectangular,
            op.transpose(),
            BlockStructure::Rectangular,
            alpha,
            Par::Seq,
        );
    }
}

/// Symmetric rank-2k update of one triangle: `C ← α (A Bᵀ + B Aᵀ) + β C` (`trans = N`,
/// A, B n×k) or `C ← α (Aᵀ B + Bᵀ A) + β C` (`trans = T`, A, B k×n) (BLAS `DSYR2K`).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dsyr2k_(
    uplo: *const c_char,
    trans: *const c_char,
    n: *const c_int,
    k: *const c_int,
    alpha: *const f64,
    a: *const f64,
    lda: *const c_int,
    b: *const f64,
    ldb: *const c_int,
    beta: *const f64,
    c: *mut f64,
    ldc: *const c_int,
) {
    unsafe {
        let (Some(upper), Some(t)) = (uplo_flag(flag(uplo)), trans_flag(flag(trans))) else {
            return;
        };
        let (Some(n), Some(k)) = (dim(*n), dim(*k)) else {
            return;
        };
        let (Some(lda), Some(ldb), Some(ldc)) = (dim(*lda), dim(*ldb), dim(*ldc)) else {
            return;
        };
        let (rows, cols) = if t { (k, n) } else { (n, k) };
        if lda < rows.max(1) || ldb < rows.max(1) || ldc < n.max(1) || n == 0 {
            return;
        }
        let (alpha, beta) = (*alpha, *beta);
        let mut cm = view_mut(c, n, n, ldc);
        if beta != 1.0 {
            scale_triangle(cm.rb_mut(), upper, beta);
        }
        if alpha == 0.0 || k == 0 {
            return;
        }
        let am = view(a, rows, cols, lda);
        let bm = view(b, rows, cols, ldb);
        let (opa, opb) = if t {
            (am.transpose(), bm.transpose())
        } else {
            (am, bm)
        };
        let structure = if upper {
            BlockStructure::TriangularUpper
        } else {
            BlockStructure::TriangularLower
        };
        for (x, y) in [(opa, opb), (opb, opa)] {
            faer::linalg::matmul::triangular::matmul(
                cm.rb_mut(),
                structure,
                Accum::Add,
                x,
                BlockStructure::Rectangular,
                y.transpose(),
                BlockStructure::Rectangular,
                alpha,
                Par::Seq,
            );
        }
    }
}

// ---------------------------------------------------------------------------------------
// Cholesky
// ---------------------------------------------------------------------------------------

/// Cholesky factorisation in place (LAPACK `DPOTRF`): `uplo = L` stores `L` with
/// `A = L Lᵀ` in the lower triangle, `uplo = U` stores `U` with `A = Uᵀ U` in the upper
/// triangle; the other triangle is not referenced. `info = i > 0` when the leading minor of
/// order `i` is not positive definite.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dpotrf_(
    uplo: *const c_char,
    n: *const c_int,
    a: *mut f64,
    lda: *const c_int,
    info: *mut c_int,
) {
    unsafe {
        *info = 0;
        let Some(upper) = uplo_flag(flag(uplo)) else {
            *info = -1;
            return;
        };
        let Some(n) = dim(*n) else {
            *info = -2;
            return;
        };
        if dim(*lda).is_none_or(|l| l < n.max(1)) {
            *info = -4;
            return;
        }
        if n == 0 {
            return;
        }
        let mut am = view_mut(a, n, n, *lda as usize);
        // Upper storage: the transpose view holds Uᵀ = L in its lower triangle.
        if upper {
            am = am.transpose_mut();
        }
        // faer uses the strictly upper triangle as scratch, but LAPACK callers (clarabel
        // among them) rely on the unreferenced triangle being left alone: factor a copy of
        // the lower triangle and write back only that triangle.
        let mut work = Mat::<f64>::zeros(n, n);
        for j in 0..n {
            for i in j..n {
                work[(i, j)] = am[(i, j)];
            }
        }
        let par = Par::Seq;
        let params = Default::default();
        let mut buf = MemBuffer::new(
            faer::linalg::cholesky::llt::factor::cholesky_in_place_scratch::<f64>(n, par, params),
        );
        let res = faer::linalg::cholesky::llt::factor::cholesky_in_place(
            work.as_mut(),
            Default::default(),
            par,
            MemStack::new(&mut buf),
            params,
        );
        for j in 0..n {
            for i in j..n {
                am[(i, j)] = work[(i, j)];
            }
        }
        if let Err(faer::linalg::cholesky::llt::factor::LltError::NonPositivePivot { index }) = res
        {
            *info = (index + 1) as c_int;
        }
    }
}

/// Solves `A X = B` in place in `B` (n×nrhs) given the `dpotrf_` factor of `A`
/// (LAPACK `DPOTRS`).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dpotrs_(
    uplo: *const c_char,
    n: *const c_int,
    nrhs: *const c_int,
    a: *const f64,
    lda: *const c_int,
    b: *mut f64,
    ldb: *const c_int,
    info: *mut c_int,
) {
    unsafe {
        *info = 0;
        let Some(upper) = uplo_flag(flag(uplo)) else {
            *info = -1;
            return;
        };
        let Some(n) = dim(*n) else {
            *info = -2;
            return;
        };
        let Some(nrhs) = dim(*nrhs) else {
            *info = -3;
            return;
        };
        if dim(*lda).is_none_or(|l| l < n.max(1)) {
            *info = -5;
            return;
        }
        if dim(*ldb).is_none_or(|l| l < n.max(1)) {
            *info = -7;
            return;
        }
        if n == 0 || nrhs == 0 {
            return;
        }
        let l = view(a, n, n, *lda as usize);
        let l = if upper { l.transpose() } else { l };
        let rhs = view_mut(b, n, nrhs, *ldb as usize);
        faer::linalg::cholesky::llt::solve::solve_in_place_with_conj(
            l,
            Conj::No,
            rhs,
            Par::Seq,
            MemStack::new(&mut MemBuffer::new(faer::dyn_stack::StackReq::EMPTY)),
        );
    }
}

// ---------------------------------------------------------------------------------------
// symmetric eigenproblem
// ---------------------------------------------------------------------------------------

/// All eigenvalues (ascending, in `w`) and, for `jobz = V`, orthonormal eigenvectors
/// (columns of `z`) of the symmetric matrix whose `uplo` triangle is stored in `a`
/// (LAPACK `DSYEVR`, `range = 'A'` only). Workspace query: `lwork = -1` or `liwork = -1`
/// returns `work[0] = max(1, 26n)`, `iwork[0] = max(1, 10n)`. `info > 0`: no convergence.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dsyevr_(
    jobz: *const c_char,
    range: *const c_char,
    uplo: *const c_char,
    n: *const c_int,
    a: *mut f64,
    lda: *const c_int,
    _vl: *const f64,
    _vu: *const f64,
    _il: *const c_int,
    _iu: *const c_int,
    _abstol: *const f64,
    m: *mut c_int,
    w: *mut f64,
    z: *mut f64,
    ldz: *const c_int,
    isuppz: *mut c_int,
    work: *mut f64,
    lwork: *const c_int,
    iwork: *mut c_int,
    liwork: *const c_int,
    info: *mut c_int,
) {
    unsafe {
        *info = 0;
        let vectors = match flag(jobz) {
            b'N' => false,
            b'V' => true,
            _ => {
                *info = -1;
                return;
            }
        };
        if flag(range) != b'A' {
            *info = -2;
            return;
        }
        let Some(upper) = uplo_flag(flag(uplo)) else {
            *info = -3;
            return;
        };
        let Some(n) = dim(*n) else {
            *info = -4;
            return;
        };
        if dim(*lda).is_none_or(|l| l < n.max(1)) {
            *info = -6;
            return;
        }
        if vectors && dim(*ldz).is_none_or(|l| l < n.max(1)) || *ldz < 1 {
            *info = -15;
            return;
        }
        let min_lwork = (26 * n).max(1);
        let min_liwork = (10 * n).max(1);
        if *lwork == -1 || *liwork == -1 {
            *work = min_lwork as f64;
            *iwork = min_liwork as c_int;
            return;
        }
        if dim(*lwork).is_none_or(|l| l < min_lwork) {
            *info = -18;
            return;
        }
        if dim(*liwork).is_none_or(|l| l < min_liwork) {
            *info = -20;
            return;
        }
        *m = 0;
        if n == 0 {
            return;
        }
        let am = view(a, n, n, *lda as usize);
        // faer reads the lower triangle; the transpose of an upper-stored matrix is lower-stored.
        let am = if upper { am.transpose() } else { am };
        let par = Par::Seq;
        let params = Default::default();
        let compute = if vectors {
            faer::linalg::evd::ComputeEigenvectors::Yes
        } else {
            faer::linalg::evd::ComputeEigenvectors::No
        };
        let mut s = Diag::<f64>::zeros(n);
        let mut u = if vectors {
            Mat::<f64>::zeros(n, n)
        } else {
            Mat::<f64>::zeros(0, 0)
        };
        let mut buf = MemBuffer::new(faer::linalg::evd::self_adjoint_evd_scratch::<f64>(
            n, compute, par, params,
        ));
        let res = faer::linalg::evd::self_adjoint_evd(
            am,
            s.as_mut(),
            if vectors { Some(u.as_mut()) } else { None },
            par,
            MemStack::new(&mut buf),
            params,
        );
        if res.is_err() {
            *info = 1;
            return;
        }
        // faer returns eigenvalues in nondecreasing order, as LAPACK does.
        let wv = std::slice::from_raw_parts_mut(w, n);
        for (i, wi) in wv.iter_mut().enumerate() {
            *wi = s[i];
        }
        if vectors {
            view_mut(z, n, n, *ldz as usize).copy_from(&u);
            let supp = std::slice::from_raw_parts_mut(isuppz, 2 * n);
            for pair in supp.chunks_exact_mut(2) {
                pair[0] = 1;
                pair[1] = n as c_int;
            }
        }
        *m = n as c_int;
    }
}

// ---------------------------------------------------------------------------------------
// SVD
// ---------------------------------------------------------------------------------------

/// Which singular vectors to produce.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Job {
    None,
    Thin,
    Full,
}

fn job_flag(c: u8) -> Option<Job> {
    match c {
        b'N' => Some(Job::None),
        b'S' => Some(Job::Thin),
        b'A' => Some(Job::Full),
        _ => None,
    }
}

/// Shared SVD driver: computes the SVD of the m×n matrix at `a` and writes `s`, `U` (m×ucols)
/// and `Vᵀ` (vtrows×n) as requested. Returns the LAPACK `info` (0 or 1 on no convergence).
unsafe fn svd_into(
    a: *const f64,
    m: usize,
    n: usize,
    lda: usize,
    s: *mut f64,
    (ujob, u, ldu): (Job, *mut f64, usize),
    (vjob, vt, ldvt): (Job, *mut f64, usize),
) -> c_int {
    unsafe {
        let mn = m.min(n);
        if mn == 0 {
            return 0;
        }
        let am = view(a, m, n, lda);
        let ucols = match ujob {
            Job::None => 0,
            Job::Thin => mn,
            Job::Full => m,
        };
        let vcols = match vjob {
            Job::None => 0,
            Job::Thin => mn,
            Job::Full => n,
        };
        let compute = |j: Job| match j {
            Job::None => faer::linalg::svd::ComputeSvdVectors::No,
            Job::Thin => faer::linalg::svd::ComputeSvdVectors::Thin,
            Job::Full => faer::linalg::svd::ComputeSvdVectors::Full,
        };
        let par = Par::Seq;
        let params = Default::default();
        let mut buf = MemBuffer::new(faer::linalg::svd::svd_scratch::<f64>(
            m,
            n,
            compute(ujob),
            compute(vjob),
            par,
            params,
        ));
        let mut sd = Diag::<f64>::zeros(mn);
        let mut um = Mat::<f64>::zeros(m, ucols);
        let mut vm = Mat::<f64>::zeros(n, vcols);
        let res = faer::linalg::svd::svd(
            am,
            sd.as_mut(),
            (ujob != Job::None).then(|| um.as_mut()),
            (vjob != Job::None).then(|| vm.as_mut()),
            par,
            MemStack::new(&mut buf),
            params,
        );
        if res.is_err() {
            return 1;
        }
        let sv = std::slice::from_raw_parts_mut(s, mn);
        for (i, si) in sv.iter_mut().enumerate() {
            *si = sd[i];
        }
        if ujob != Job::None {
            view_mut(u, m, ucols, ldu).copy_from(&um);
        }
        if vjob != Job::None {
            view_mut(vt, vcols, n, ldvt).copy_from(vm.transpose());
        }
        0
    }
}

/// Minimum `lwork` of reference `DGESDD`.
fn gesdd_min_lwork(job: Job, m: usize, n: usize) -> usize {
    let (mn, mx) = (m.min(n), m.max(n));
    let w = match job {
        Job::None => 3 * mn + mx.max(7 * mn),
        _ => 3 * mn * mn + mx.max(4 * mn * mn + 4 * mn),
    };
    w.max(1)
}

/// Minimum `lwork` of reference `DGESVD`.
fn gesvd_min_lwork(m: usize, n: usize) -> usize {
    let (mn, mx) = (m.min(n), m.max(n));
    (3 * mn + mx).max(5 * mn).max(1)
}

/// Validates `ldu`/`ldvt` for a job; returns `true` when acceptable.
fn ld_ok(job: Job, ld: c_int, rows: usize) -> bool {
    match job {
        Job::None => ld >= 1,
        _ => dim(ld).is_some_and(|l| l >= rows.max(1)),
    }
}

/// Singular value decomposition `A = U Σ Vᵀ` (LAPACK `DGESDD`), `jobz` ∈ {N, S, A}:
/// `s` gets the min(m, n) singular values in descending order, `u` the first min(m, n)
/// (S) or all m (A) left singular vectors, `vt` the corresponding rows of `Vᵀ`.
/// `lwork = -1` returns the reference minimum workspace size in `work[0]`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dgesdd_(
    jobz: *const c_char,
    m: *const c_int,
    n: *const c_int,
    a: *mut f64,
    lda: *const c_int,
    s: *mut f64,
    u: *mut f64,
    ldu: *const c_int,
    vt: *mut f64,
    ldvt: *const c_int,
    work: *mut f64,
    lwork: *const c_int,
    _iwork: *mut c_int,
    info: *mut c_int,
) {
    unsafe {
        *info = 0;
        let Some(job) = job_flag(flag(jobz)) else {
            *info = -1;
            return;
        };
        let Some(m) = dim(*m) else {
            *info = -2;
            return;
        };
        let Some(n) = dim(*n) else {
            *info = -3;
            return;
        };
        if dim(*lda).is_none_or(|l| l < m.max(1)) {
            *info = -5;
            return;
        }
        let mn = m.min(n);
        if !ld_ok(job, *ldu, m) {
            *info = -8;
            return;
        }
        let vt_rows = if job == Job::Full { n } else { mn };
        if !ld_ok(job, *ldvt, vt_rows) {
            *info = -10;
            return;
        }
        let min_lwork = gesdd_min_lwork(job, m, n);
        if *lwork == -1 {
            *work = min_lwork as f64;
            return;
        }
        if dim(*lwork).is_none_or(|l| l < min_lwork) {
            *info = -12;
            return;
        }
        *info = svd_into(
            a,
            m,
            n,
            *lda as usize,
            s,
            (job, u, (*ldu).max(1) as usize),
            (job, vt, (*ldvt).max(1) as usize),
        );
    }
}

/// Singular value decomposition `A = U Σ Vᵀ` (LAPACK `DGESVD`), `jobu`, `jobvt` ∈
/// {N, S, A} independently. `lwork = -1` returns the reference minimum workspace size.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn dgesvd_(
    jobu: *const c_char,
    jobvt: *const c_char,
    m: *const c_int,
    n: *const c_int,
    a: *mut f64,
    lda: *const c_int,
    s: *mut f64,
    u: *mut f64,
    ldu: *const c_int,
    vt: *mut f64,
    ldvt: *const c_int,
    work: *mut f64,
    lwork: *const c_int,
    info: *mut c_int,
) {
    unsafe {
        *info = 0;
        let Some(ujob) = job_flag(flag(jobu)) else {
            *info = -1;
            return;
        };
        let Some(vjob) = job_flag(flag(jobvt)) else {
            *info = -2;
            return;
        };
        let Some(m) = dim(*m) else {
            *info = -3;
            return;
        };
        let Some(n) = dim(*n) else {
            *info = -4;
            return;
        };
        if dim(*lda).is_none_or(|l| l < m.max(1)) {
            *info = -6;
            return;
        }
        let mn = m.min(n);
        if !ld_ok(ujob, *ldu, m) {
            *info = -9;
            return;
        }
        let vt_rows = if vjob == Job::Full { n } else { mn };
        if !ld_ok(vjob, *ldvt, vt_rows) {
            *info = -11;
            return;
        }
        let min_lwork = gesvd_min_lwork(m, n);
        if *lwork == -1 {
            *work = min_lwork as f64;
            return;
        }
        if dim(*lwork).is_none_or(|l| l < min_lwork) {
            *info = -13;
            return;
        }
        *info = svd_into(
            a,
            m,
            n,
            *lda as usize,
            s,
            (ujob, u, (*ldu).max(1) as usize),
            (vjob, vt, (*ldvt).max(1) as usize),
        );
    }
}

#[cfg(test)]
mod tests {
    //! Each routine against a direct reference computation on random matrices stored with
    //! leading dimensions larger than the row count (padding must stay untouched).
    #![allow(clippy::needless_range_loop)]

    use super::*;
    use rand::rngs::StdRng;
    use rand::{RngExt, SeedableRng};

    const PAD: f64 = 12345.0;

    /// Column-major rows×cols matrix with leading dimension `ld`; padding filled with `PAD`.
    struct Cm {
        rows: usize,
        cols: usize,
        ld: usize,
        data: Vec<f64>,
    }

    impl Cm {
        fn random(rng: &mut StdRng, rows: usize, cols: usize, ld: usize) -> Self {
            let mut data = vec![PAD; ld * cols.max(1)];
            for j in 0..cols {
                for i in 0..rows {
                    data[i + j * ld] = rng.random_range(-1.0..1.0);
                }
            }
            Cm {
                rows,
                cols,
                ld,
                data,
            }
        }
        fn filled(rows: usize, cols: usize, ld: usize, v: f64) -> Self {
            let mut m = Cm {
                rows,
                cols,
                ld,
                data: vec![PAD; ld * cols.max(1)],
            };
            for j in 0..cols {
                for i in 0..rows {
                    m.data[i + j * ld] = v;
                }
            }
            m
        }
        fn get(&self, i: usize, j: usize) -> f64 {
            self.data[i + j * self.ld]
        }
        fn set(&mut self, i: usize, j: usize, v: f64) {
            self.data[i + j * self.ld] = v;
        }
        /// Element of op(self).
        fn op(&self, t: bool, i: usize, j: usize) -> f64 {
            if t { self.get(j, i) } else { self.get(i, j) }
        }
        fn padding_intact(&self) -> bool {
            (0..self.cols).all(|j| (self.rows..self.ld).all(|i| self.get(i, j) == PAD))
        }
        fn ld_i(&self) -> c_int {
            self.ld as c_int
        }
    }

    fn ch(c: u8) -> c_char {
        c as c_char
    }

    /// Random symmetric positive definite n×n matrix (full storage) B Bᵀ + n I.
    fn spd(rng: &mut StdRng, n: usize, ld: usize) -> Cm {
        let b = Cm::random(rng, n, n, n);
        let mut a = Cm::filled(n, n, ld, 0.0);
        for i in 0..n {
            for j in 0..n {
                let v: f64 = (0..n).map(|k| b.get(i, k) * b.get(j, k)).sum();
                a.set(i, j, v + if i == j { n as f64 } else { 0.0 });
            }
        }
        a
    }

    #[test]
    fn dgemm_matches_triple_loop_all_transposes() {
        let mut rng = StdRng::seed_from_u64(1);
        for &(m, n, k) in &[(5usize, 7usize, 4usize), (33, 17, 29), (1, 3, 1)] {
            for ta in [false, true] {
                for tb in [false, true] {
                    for (alpha, beta) in [(1.3, -0.7), (0.8, 0.0), (0.0, 2.0)] {
                        let (ar, ac) = if ta { (k, m) } else { (m, k) };
                        let (br, bc) = if tb { (n, k) } else { (k, n) };
                        let a = Cm::random(&mut rng, ar, ac, ar + 3);
                        let b = Cm::random(&mut rng, br, bc, br + 2);
                        let mut c = Cm::random(&mut rng, m, n, m + 4);
                        if beta == 0.0 {
                            c.set(0, 0, f64::NAN); // must not propagate when β = 0
                        }
                        let c0 = Cm {
                            data: c.data.clone(),
                            ..c
                        };
                        unsafe {
                            dgemm_(
                                &ch(if ta { b'T' } else { b'N' }),
                                &ch(if tb { b't' } else { b'n' }),
                                &(m as c_int),
                                &(n as c_int),
                                &(k as c_int),
                                &alpha,
                                a.data.as_ptr(),
                                &a.ld_i(),
                                b.data.as_ptr(),
                                &b.ld_i(),
                                &beta,
                                c.data.as_mut_ptr(),
                                &c.ld_i(),
                            );
                        }
                        let tol = 1e-14 * (k as f64 + 2.0) * 4.0;
                        for i in 0..m {
                            for j in 0..n {
                                let ab: f64 = (0..k).map(|l| a.op(ta, i, l) * b.op(tb, l, j)).sum();
                                let prev = if beta == 0.0 {
                                    0.0
                                } else {
                                    beta * c0.get(i, j)
                                };
                                let want = alpha * ab + prev;
                                assert!(
                                    (c.get(i, j) - want).abs() <= tol,
                                    "dgemm ta={ta} tb={tb} ({i},{j}): {} vs {want}",
                                    c.get(i, j)
                                );
                            }
                        }
                        assert!(c.padding_intact());
                    }
                }
            }
        }
    }

    #[test]
    fn dsyrk_and_dsyr2k_touch_one_triangle_only() {
        let mut rng = StdRng::seed_from_u64(2);
        for &(n, k) in &[(6usize, 4usize), (23, 31), (1, 1)] {
            for upper in [true, false] {
                for t in [false, true] {
                    let (r, c) = if t { (k, n) } else { (n, k) };
                    let a = Cm::random(&mut rng, r, c, r + 2);
                    let b = Cm::random(&mut rng, r, c, r + 5);
                    let (alpha, beta) = (0.9, -1.1);
                    let mut c1 = Cm::random(&mut rng, n, n, n + 3);
                    let mut c2 = Cm {
                        data: c1.data.clone(),
                        ..c1
                    };
                    let c0 = c1.data.clone();
                    let uplo = ch(if upper { b'U' } else { b'l' });
                    let trans = ch(if t { b'T' } else { b'N' });
                    unsafe {
                        dsyrk_(
                            &uplo,
                            &trans,
                            &(n as c_int),
                            &(k as c_int),
                            &alpha,
                            a.data.as_ptr(),
                            &a.ld_i(),
                            &beta,
                            c1.data.as_mut_ptr(),
                            &c1.ld_i(),
                        );
                        dsyr2k_(
                            &uplo,
                            &trans,
                            &(n as c_int),
                            &(k as c_int),
                            &alpha,
                            a.data.as_ptr(),
                            &a.ld_i(),
                            b.data.as_ptr(),
                            &b.ld_i(),
                            &beta,
                            c2.data.as_mut_ptr(),
                            &c2.ld_i(),
                        );
                    }
                    // op(X)[i, l] with op = identity for N (X n×k) and transpose for T.
                    let opx = |x: &Cm, i: usize, l: usize| x.op(t, i, l);
                    let tol = 1e-14 * (k as f64 + 2.0) * 8.0;
                    for i in 0..n {
                        for j in 0..n {
                            let old = c0[i + j * c1.ld];
                            let in_tri = if upper { i <= j } else { i >= j };
                            if !in_tri {
                                assert_eq!(c1.get(i, j), old);
                                assert_eq!(c2.get(i, j), old);
                                continue;
                            }
                            let aa: f64 = (0..k).map(|l| opx(&a, i, l) * opx(&a, j, l)).sum();
                            let ab: f64 = (0..k)
                                .map(|l| {
                                    opx(&a, i, l) * opx(&b, j, l) + opx(&b, i, l) * opx(&a, j, l)
                                })
                                .sum();
                            assert!((c1.get(i, j) - (alpha * aa + beta * old)).abs() <= tol);
                            assert!((c2.get(i, j) - (alpha * ab + beta * old)).abs() <= tol);
                        }
                    }
                    assert!(c1.padding_intact() && c2.padding_intact());
                }
            }
        }
    }

    #[test]
    fn dpotrf_dpotrs_factor_and_solve() {
        let mut rng = StdRng::seed_from_u64(3);
        for &n in &[1usize, 4, 9, 40] {
            for upper in [false, true] {
                let a = spd(&mut rng, n, n + 3);
                let mut f = Cm {
                    data: a.data.clone(),
                    ..a
                };
                // Sentinel in the unreferenced triangle: it must be neither read (the factor
                // would be wrong) nor written (checked exactly below).
                const SENTINEL: f64 = 777.0;
                for j in 0..n {
                    for i in 0..n {
                        if (upper && i > j) || (!upper && i < j) {
                            f.set(i, j, SENTINEL);
                        }
                    }
                }
                let uplo = ch(if upper { b'U' } else { b'L' });
                let mut info = -99;
                unsafe {
                    dpotrf_(
                        &uplo,
                        &(n as c_int),
                        f.data.as_mut_ptr(),
                        &f.ld_i(),
                        &mut info,
                    )
                };
                assert_eq!(info, 0);
                // factor entry: T[i][j] of the triangular factor with A = T Tᵀ (T lower).
                let tf = |i: usize, j: usize| -> f64 {
                    if j > i {
                        0.0
                    } else if upper {
                        f.get(j, i)
                    } else {
                        f.get(i, j)
                    }
                };
                let scale = n as f64 * 2.0;
                for i in 0..n {
                    for j in 0..n {
                        let v: f64 = (0..n).map(|l| tf(i, l) * tf(j, l)).sum();
                        assert!((v - a.get(i, j)).abs() <= 1e-13 * scale * scale);
                        if (upper && i > j) || (!upper && i < j) {
                            assert_eq!(f.get(i, j), SENTINEL);
                        }
                    }
                }
                assert!(f.padding_intact());
                // Solve with 3 right-hand sides.
                let nrhs = 3;
                let x = Cm::random(&mut rng, n, nrhs, n);
                let mut b = Cm::filled(n, nrhs, n + 2, 0.0);
                for i in 0..n {
                    for j in 0..nrhs {
                        b.set(i, j, (0..n).map(|l| a.get(i, l) * x.get(l, j)).sum());
                    }
                }
                unsafe {
                    dpotrs_(
                        &uplo,
                        &(n as c_int),
                        &(nrhs as c_int),
                        f.data.as_ptr(),
                        &f.ld_i(),
                        b.data.as_mut_ptr(),
                        &b.ld_i(),
                        &mut info,
                    )
                };
                assert_eq!(info, 0);
                for i in 0..n {
                    for j in 0..nrhs {
                        assert!((b.get(i, j) - x.get(i, j)).abs() <= 1e-12 * scale);
                    }
                }
                assert!(b.padding_intact());
            }
        }
    }

    #[test]
    fn dpotrf_reports_first_non_positive_minor() {
        // Leading 2×2 minor is PD (det 16), the 3×3 one is not (det −16), so info = 3.
        let mut a = [4.0, 2.0, 2.0, 2.0, 5.0, 3.0, 2.0, 3.0, 1.0];
        let mut info = 0;
        for uplo in [b'L', b'U'] {
            let mut m = a;
            unsafe { dpotrf_(&ch(uplo), &3, m.as_mut_ptr(), &3, &mut info) };
            assert_eq!(info, 3, "uplo {}", uplo as char);
        }
        a[0] = -1.0;
        unsafe { dpotrf_(&ch(b'L'), &3, a.as_mut_ptr(), &3, &mut info) };
        assert_eq!(info, 1);
        unsafe { dpotrf_(&ch(b'X'), &3, a.as_mut_ptr(), &3, &mut info) };
        assert_eq!(info, -1);
    }

    /// Calls `dsyevr_` with a workspace query first, as clarabel does.
    fn syevr(a: &mut Cm, jobz: u8, uplo: u8, w: &mut [f64], z: &mut Cm) -> c_int {
        let n = a.rows as c_int;
        let (mut m, mut info) = (0, 0);
        let mut isuppz = vec![0; 2 * a.rows.max(1)];
        let mut work = vec![0.0; 1];
        let mut iwork = vec![0; 1];
        let (mut lwork, mut liwork) = (-1, -1);
        for pass in 0..2 {
            unsafe {
                dsyevr_(
                    &ch(jobz),
                    &ch(b'A'),
                    &ch(uplo),
                    &n,
                    a.data.as_mut_ptr(),
                    &a.ld_i(),
                    &0.0,
                    &0.0,
                    &0,
                    &0,
                    &-1.0,
                    &mut m,
                    w.as_mut_ptr(),
                    z.data.as_mut_ptr(),
                    &z.ld_i(),
                    isuppz.as_mut_ptr(),
                    work.as_mut_ptr(),
                    &lwork,
                    iwork.as_mut_ptr(),
                    &liwork,
                    &mut info,
                );
            }
            if info != 0 {
                return info;
            }
            if pass == 0 {
                lwork = work[0] as c_int;
                liwork = iwork[0];
                assert_eq!(lwork as usize, (26 * a.rows).max(1));
                assert_eq!(liwork as usize, (10 * a.rows).max(1));
                work.resize(lwork as usize, 0.0);
                iwork.resize(liwork as usize, 0);
            }
        }
        assert_eq!(m, n);
        info
    }

    #[test]
    fn dsyevr_eigenpairs_from_either_triangle() {
        let mut rng = StdRng::seed_from_u64(4);
        for &n in &[1usize, 3, 7, 30] {
            let full = {
                let r = Cm::random(&mut rng, n, n, n);
                let mut s = Cm::filled(n, n, n + 2, 0.0);
                for i in 0..n {
                    for j in 0..n {
                        s.set(i, j, r.get(i, j) + r.get(j, i));
                    }
                }
                s
            };
            let fro: f64 = full
                .data
                .iter()
                .filter(|v| **v != PAD)
                .map(|v| v * v)
                .sum::<f64>();
            let tol = 1e-13 * (n as f64 + 1.0) * fro.sqrt().max(1.0);
            for uplo in [b'U', b'L'] {
                let mut a = Cm {
                    data: full.data.clone(),
                    ..full
                };
                for j in 0..n {
                    for i in 0..n {
                        if (uplo == b'U' && i > j) || (uplo == b'L' && i < j) {
                            a.set(i, j, f64::NAN); // unreferenced triangle
                        }
                    }
                }
                let mut w = vec![0.0; n];
                let mut z = Cm::filled(n, n, n + 1, 0.0);
                assert_eq!(syevr(&mut a, b'V', uplo, &mut w, &mut z), 0);
                assert!(w.windows(2).all(|p| p[0] <= p[1]), "ascending");
                for p in 0..n {
                    for i in 0..n {
                        let av: f64 = (0..n).map(|l| full.get(i, l) * z.get(l, p)).sum();
                        assert!((av - w[p] * z.get(i, p)).abs() <= tol);
                    }
                    for q in 0..n {
                        let d: f64 = (0..n).map(|l| z.get(l, p) * z.get(l, q)).sum();
                        let want = if p == q { 1.0 } else { 0.0 };
                        assert!((d - want).abs() <= 1e-13 * (n as f64 + 1.0));
                    }
                }
                assert!(z.padding_intact());
                // Values only; `z` is a 1-element placeholder as in clarabel.
                let mut w2 = vec![0.0; n];
                let mut dummy = Cm::filled(1, 1, 1, 0.0);
                dummy.ld = n.max(1);
                dummy.data.resize(1, 0.0);
                let mut a2 = Cm {
                    data: a.data.clone(),
                    ..a
                };
                assert_eq!(syevr(&mut a2, b'N', uplo, &mut w2, &mut dummy), 0);
                assert_eq!(dummy.data, vec![0.0]);
                for (x, y) in w.iter().zip(&w2) {
                    assert!((x - y).abs() <= tol);
                }
            }
        }
    }

    #[test]
    fn dsyevr_rejects_unsupported_range() {
        let mut a = [1.0];
        let (mut m, mut info) = (0, 0);
        let (mut w, mut z, mut is, mut work, mut iwork) =
            ([0.0], [0.0], [0; 2], [0.0; 26], [0; 10]);
        unsafe {
            dsyevr_(
                &ch(b'V'),
                &ch(b'I'),
                &ch(b'U'),
                &1,
                a.as_mut_ptr(),
                &1,
                &0.0,
                &0.0,
                &1,
                &1,
                &0.0,
                &mut m,
                w.as_mut_ptr(),
                z.as_mut_ptr(),
                &1,
                is.as_mut_ptr(),
                work.as_mut_ptr(),
                &26,
                iwork.as_mut_ptr(),
                &10,
                &mut info,
            )
        };
        assert_eq!(info, -2);
    }

    /// Runs `dgesdd_` (`gesvd = false`) or `dgesvd_` with a workspace query, returns
    /// (s, U, Vᵀ) checked for shape; `ujob`/`vjob` are the job characters.
    fn run_svd(a: &Cm, gesvd: bool, ujob: u8, vjob: u8) -> (Vec<f64>, Cm, Cm) {
        let (m, n) = (a.rows, a.cols);
        let mn = m.min(n);
        let ucols = match ujob {
            b'A' => m,
            b'S' => mn,
            _ => 1,
        };
        let vtrows = match vjob {
            b'A' => n,
            b'S' => mn,
            _ => 1,
        };
        let mut u = Cm::filled(m, ucols, m + 2, 0.0);
        let mut vt = Cm::filled(vtrows, n, vtrows + 3, 0.0);
        let mut s = vec![0.0; mn];
        let mut a2 = Cm {
            data: a.data.clone(),
            ..*a
        };
        let mut work = vec![0.0; 1];
        let mut iwork = vec![0; 8 * mn];
        let mut lwork: c_int = -1;
        let mut info = 0;
        for pass in 0..2 {
            unsafe {
                if gesvd {
                    dgesvd_(
                        &ch(ujob),
                        &ch(vjob),
                        &(m as c_int),
                        &(n as c_int),
                        a2.data.as_mut_ptr(),
                        &a2.ld_i(),
                        s.as_mut_ptr(),
                        u.data.as_mut_ptr(),
                        &u.ld_i(),
                        vt.data.as_mut_ptr(),
                        &vt.ld_i(),
                        work.as_mut_ptr(),
                        &lwork,
                        &mut info,
                    );
                } else {
                    dgesdd_(
                        &ch(ujob),
                        &(m as c_int),
                        &(n as c_int),
                        a2.data.as_mut_ptr(),
                        &a2.ld_i(),
                        s.as_mut_ptr(),
                        u.data.as_mut_ptr(),
                        &u.ld_i(),
                        vt.data.as_mut_ptr(),
                        &vt.ld_i(),
                        work.as_mut_ptr(),
                        &lwork,
                        iwork.as_mut_ptr(),
                        &mut info,
                    );
                }
            }
            assert_eq!(info, 0);
            if pass == 0 {
                lwork = work[0] as c_int;
                assert!(lwork >= 1);
                work.resize(lwork as usize, 0.0);
            }
        }
        assert!(u.padding_intact() && vt.padding_intact());
        (s, u, vt)
    }

    fn check_orthonormal_cols(q: &Cm, tol: f64) {
        for p in 0..q.cols {
            for r in 0..q.cols {
                let d: f64 = (0..q.rows).map(|l| q.get(l, p) * q.get(l, r)).sum();
                assert!((d - if p == r { 1.0 } else { 0.0 }).abs() <= tol);
            }
        }
    }

    #[test]
    fn dgesdd_dgesvd_reconstruct() {
        let mut rng = StdRng::seed_from_u64(5);
        for &(m, n) in &[(7usize, 4usize), (4, 7), (25, 25), (1, 5)] {
            let a = Cm::random(&mut rng, m, n, m + 3);
            let mn = m.min(n);
            let tol = 1e-13 * (m.max(n) as f64 + 1.0) * 4.0;
            for gesvd in [false, true] {
                for job in [b'S', b'A'] {
                    let (s, u, vt) = run_svd(&a, gesvd, job, job);
                    assert!(s.windows(2).all(|p| p[0] >= p[1]) && s[mn - 1] >= 0.0);
                    check_orthonormal_cols(&u, tol);
                    let vtt = {
                        let mut v = Cm::filled(n, vt.rows, n, 0.0);
                        for i in 0..vt.rows {
                            for j in 0..n {
                                v.set(j, i, vt.get(i, j));
                            }
                        }
                        v
                    };
                    check_orthonormal_cols(&vtt, tol);
                    for i in 0..m {
                        for j in 0..n {
                            let v: f64 = (0..mn).map(|l| u.get(i, l) * s[l] * vt.get(l, j)).sum();
                            assert!((v - a.get(i, j)).abs() <= tol, "gesvd={gesvd} job={job}");
                        }
                    }
                }
                let (s0, _, _) = run_svd(&a, gesvd, b'N', b'N');
                let (s1, _, _) = run_svd(&a, gesvd, b'S', b'S');
                for (x, y) in s0.iter().zip(&s1) {
                    assert!((x - y).abs() <= tol);
                }
            }
            // dgesvd with mixed jobs: U thin, no Vᵀ.
            let (s, u, _) = run_svd(&a, true, b'S', b'N');
            // Uᵀ A = Σ Vᵀ, so the row norms of Uᵀ A are the singular values.
            for (l, sl) in s.iter().enumerate() {
                let norm2: f64 = (0..n)
                    .map(|j| {
                        (0..m)
                            .map(|i| u.get(i, l) * a.get(i, j))
                            .sum::<f64>()
                            .powi(2)
                    })
                    .sum();
                assert!((norm2.sqrt() - sl).abs() <= tol);
            }
        }
    }

    #[test]
    fn svd_rejects_overwrite_job() {
        let mut a = [1.0, 2.0];
        let (mut s, mut u, mut vt, mut work, mut iwork) =
            ([0.0], [0.0; 2], [0.0], [0.0; 64], [0; 8]);
        let mut info = 0;
        unsafe {
            dgesdd_(
                &ch(b'O'),
                &2,
                &1,
                a.as_mut_ptr(),
                &2,
                s.as_mut_ptr(),
                u.as_mut_ptr(),
                &2,
                vt.as_mut_ptr(),
                &1,
                work.as_mut_ptr(),
                &64,
                iwork.as_mut_ptr(),
                &mut info,
            )
        };
        assert_eq!(info, -1);
    }
}
