"""The textbook Tomasi-Kanade factorization in NumPy: the peer that rank3's complete-data
path is measured against (docs/results.md, "Long videos and big tables").

    /usr/bin/python3 examples/numpy_tk.py TRACKS.csv

TRACKS.csv is a complete `frame,track,x,y` table with a header (as `rank3 synth` writes).
Steps, as in Tomasi & Kanade (IJCV 1992): read the file (np.loadtxt, NumPy's C reader),
scatter it into the 2F x N measurement matrix W, subtract each row's mean, thin SVD, keep
rank 3 (M = U3 S3^(1/2), S = S3^(1/2) V3^T), and the metric upgrade: the symmetric L = Q Q^T
from the orthographic constraints m_i^T L m_i = m_j^T L m_j = 1, m_i^T L m_j = 0 by linear
least squares, Q by Cholesky (eigenvalue clipping when L is not positive definite).

Prints the time of each step, the peak resident memory (ru_maxrss) and the RMS reprojection
error over the observed scalars. Nothing else: no missing data, no outliers, no refinement.
"""

import resource
import sys
import time

import numpy as np


def main():
    path = sys.argv[1]
    t0 = time.perf_counter()
    a = np.loadtxt(path, delimiter=",", skiprows=1)
    t1 = time.perf_counter()
    f = a[:, 0].astype(np.int64)
    p = a[:, 1].astype(np.int64)
    nf, n_p = f.max() + 1, p.max() + 1
    w = np.full((2 * nf, n_p), np.nan)
    w[2 * f, p] = a[:, 2]
    w[2 * f + 1, p] = a[:, 3]
    del a, f, p
    if np.isnan(w).any():
        sys.exit("the table is not complete: the textbook factorization needs every entry")
    t_mean = w.mean(axis=1, keepdims=True)
    w -= t_mean
    t2 = time.perf_counter()
    u, s, vt = np.linalg.svd(w, full_matrices=False)
    t3 = time.perf_counter()
    r = np.sqrt(s[:3])
    m = u[:, :3] * r
    x = r[:, None] * vt[:3]
    # Metric upgrade: rows i = 2f, j = 2f + 1; unknowns the 6 entries of symmetric L.
    def g(a, b):
        return np.stack([a[:, 0] * b[:, 0],
                         a[:, 0] * b[:, 1] + a[:, 1] * b[:, 0],
                         a[:, 0] * b[:, 2] + a[:, 2] * b[:, 0],
                         a[:, 1] * b[:, 1],
                         a[:, 1] * b[:, 2] + a[:, 2] * b[:, 1],
                         a[:, 2] * b[:, 2]], axis=1)
    mi, mj = m[0::2], m[1::2]
    lhs = np.vstack([g(mi, mi), g(mj, mj), g(mi, mj)])
    rhs = np.concatenate([np.ones(nf), np.ones(nf), np.zeros(nf)])
    l6 = np.linalg.lstsq(lhs, rhs, rcond=None)[0]
    big_l = np.array([[l6[0], l6[1], l6[2]], [l6[1], l6[3], l6[4]], [l6[2], l6[4], l6[5]]])
    ev, evec = np.linalg.eigh(big_l)
    q = evec * np.sqrt(np.clip(ev, 1e-12, None))
    motion = m @ q
    shape = np.linalg.solve(q, x)
    t4 = time.perf_counter()
    resid = w - motion @ shape
    rms = np.sqrt(np.mean(resid ** 2))
    t5 = time.perf_counter()
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"numpy {np.__version__}: {nf} frames x {n_p} tracks | read {t1 - t0:.2f} s | "
          f"W {t2 - t1:.2f} s | SVD {t3 - t2:.2f} s | upgrade {t4 - t3:.2f} s | "
          f"residual {t5 - t4:.2f} s | total {t5 - t0:.2f} s | peak {peak_mb:.0f} MB | "
          f"RMS {rms:.6f} px")


if __name__ == "__main__":
    main()
