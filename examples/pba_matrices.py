"""Converts the measurement matrices of ECCV 2016's projective benchmark to rank3's text
matrix, for `examples/projective_benchmark.rs` (`MATRICES=...`).

The data sets (Hong, Zach, Fitzgibbon & Cipolla, "Projective bundle adjustment from arbitrary
initialization using the variable projection method", ECCV 2016, Table 7) are MATLAB files
in github.com/jhh37/pba-datasets: `M` (2F x N image coordinates) and `W` (the 0/1 mask of
observed entries). Each is written as OUT/<name>/M_dense.txt: 2F rows of N numbers, `nan`
where W = 0. The data stay outside the repository (public research data; clone it yourself).

    git clone https://github.com/jhh37/pba-datasets
    python examples/pba_matrices.py pba-datasets /tmp/pba
    # prints the MATRICES=... line for the benchmark

Needs numpy and scipy.
"""

import os
import sys

import numpy as np
import scipy.io

# name: (file in pba-datasets, best known projective RMS from ECCV 2016 Table 7)
SETS = {
    "blue_bear": ("Blue_bear/Blue_bear.mat", 0.489283),
    "corridor": ("Corridor/corridor.mat", 0.272462),
    "dinosaur_trimmed": ("Dinosaur_trimmed/dinosaur_trimmed.mat", 1.114493),
    "dinosaur": ("Dinosaur/dinosaur.mat", 1.166165),
    # Table 7 gives 0.838414, but this file is not the matrix behind it: its affine optimum,
    # reached from 86 of 100 random starts, is 8.643080, below Table 7's best affine 9.380473
    # (every other matrix here matches Table 7's affine and projective optima to the printed
    # digits). 0.846283 is this file's optimum: rank3 reaches it from the noise-free truth
    # (`M_true`) and from 96 of 100 random starts (docs/results.md).
    "dinosaur_closer": ("Dinosaur_closer/dinosaur_closer.mat", 0.846283),
    "house": ("House/house.mat", 0.441660),
    "library": ("Library/library.mat", 0.172830),
    "merton1": ("Merton_1/merton_1.mat", 0.118450),
    "merton2": ("Merton_2/merton_2.mat", 0.158851),
    "sthlm": ("Sthlm_trimmed/Sthlm_trimmed.mat", 5.619975),
    "wadham": ("Wadham/wadham.mat", 0.135711),
    "wilshire": ("Wilshire/Wilshire.mat", 0.423892),
    # No published optimum (Table 7 has no row for it): the value all of 100 random starts
    # of rank3 reached (docs/results.md, 2026-12-01). 9 of its 575 tracks are seen in fewer
    # than two frames; the benchmark sets them aside, as the pipeline does.
    "merton3": ("Merton_3/merton_3.mat", 0.136852),
}
# The synthetic spheres of ECCV 2016's Table 6 (319 points on a sphere of radius 10, 36
# cameras on a ring of radius d, 77 % missing; "_lc" = loop closed), best projective RMS.
for d, tag, best, best_lc in [
    (3000, "Sphere", 0.842539, 0.861392),
    (2000, "Sphere", 0.842511, 0.862520),
    (1300, "sphere", 0.844125, 0.863871),
    (1200, "Sphere", 0.844817, 0.863867),
    (1100, "Sphere", 0.845271, 0.863274),
    (1050, "Sphere", 0.844771, 0.862545),
    # Two more rings in the repository, not in Table 6 (no published optimum): the values
    # every one of 30 random starts of rank3 reached (docs/results.md, 2026-12-01).
    (1500, "Sphere", 0.843218, 0.863496),
    (5000, "Sphere", 0.842942, 0.860515),
]:
    for lc, b in [("", best), ("_loop_closed", best_lc)]:
        base = f"sphere_d{d}_miss77{lc}"
        SETS[base] = (f"{tag}_d{d}_miss77{lc}/{base}.mat", b)


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    src, out = sys.argv[1], sys.argv[2]
    specs = []
    for name, (rel, best) in SETS.items():
        path = os.path.join(src, rel)
        if not os.path.exists(path):
            print(f"{name}: {path} not found, skipped", file=sys.stderr)
            continue
        m = scipy.io.loadmat(path)
        w = m["M"].astype(float)
        w[m["W"] == 0] = np.nan
        os.makedirs(os.path.join(out, name), exist_ok=True)
        dst = os.path.join(out, name, "M_dense.txt")
        with open(dst, "w") as f:
            f.write(f"# {name}: {rel} of github.com/jhh37/pba-datasets (nan = unobserved)\n")
            for row in w:
                f.write(" ".join("nan" if np.isnan(v) else repr(float(v)) for v in row) + "\n")
        filled = 100.0 * np.mean(m["W"] != 0)
        print(f"{name}: {w.shape[0] // 2} frames x {w.shape[1]} tracks, {filled:.1f} % filled -> {dst}",
              file=sys.stderr)
        specs.append(f"{name}:{dst}:{best}")
    print("MATRICES=" + ",".join(specs))


if __name__ == "__main__":
    main()
