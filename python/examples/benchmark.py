"""Python against the command line: the overhead of the Python call on a 100 x 2000 table
(conversion in and out), and the dinosaur and hotel results from Python next to the CLI's.

    pip install ./python   (or maturin develop --release in python/)
    python python/examples/benchmark.py [--cli target/release/rank3]

Data sets from $RANK3_DATASETS (default ../shared/datasets).
"""

import argparse
import json
import os
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

import rank3


def synthetic(frames, points, seed=0):
    rng = np.random.default_rng(seed)
    x = rng.uniform(-1, 1, (points, 3))
    out = np.empty((frames, points, 2))
    for f in range(frames):
        a = np.deg2rad(-25 + 50 * f / (frames - 1))
        r = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
        out[f] = 200 * (x @ r.T)[:, :2] + 320
    return out + rng.normal(0, 0.5, out.shape)


def overhead(repeats):
    xy = synthetic(100, 2000)
    rows = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        rec = rank3.reconstruct(xy, camera="orthographic")
        t1 = time.perf_counter()
        arrays = [rec.rotations, rec.translations, rec.scales, rec.points, rec.inlier,
                  rec.flagged, rec.completed, rec.report]
        t2 = time.perf_counter()
        rows.append((t1 - t0, rec.library_seconds, t2 - t1))
        del arrays
    rows.sort()
    call, lib, out = rows[len(rows) // 2]
    print(f"100 x 2000 complete, orthographic, median of {repeats}: call {call:.3f} s, "
          f"library {lib:.3f} s, conversion in {1e3 * (call - lib):.1f} ms "
          f"({100 * (call - lib) / lib:.2f} %), every array and the report out {1e3 * out:.1f} ms; "
          f"total overhead {1e3 * (call - lib + out):.1f} ms ({100 * (call - lib + out) / lib:.2f} %)")


def compare(name, tracks_path, cli, extra=()):
    with tempfile.TemporaryDirectory() as d:
        subprocess.run([cli, "reconstruct", str(tracks_path), "--out", d, *extra], check=True,
                       capture_output=True)
        c = json.loads((Path(d) / "reconstruction.json").read_text())
    t = rank3.read_tracks(tracks_path)
    r = rank3.reconstruct(t)
    same_points = np.array_equal(
        r.points[r.inlier], np.array([p["xyz"] for p in (c.get("perspective") or c)["points"] if p["inlier"]])
    )
    print(f"{name}: CLI {c['camera_model']} RMS {c['rms_px']:.6f} px, {sum(p['inlier'] for p in c['points'])} inliers; "
          f"Python {r.camera_model} RMS {r.rms_px:.6f} px, {int(r.inlier.sum())} inliers; "
          f"identical RMS: {r.rms_px == c['rms_px']}, identical points: {same_points}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--cli", default="target/release/rank3")
    ap.add_argument("--repeats", type=int, default=7)
    a = ap.parse_args()
    overhead(a.repeats)
    data = Path(os.environ.get("RANK3_DATASETS", "../shared/datasets"))
    for name, rel in (("dinosaur", "dino_trimmed/M_dense.txt"),
                      ("model house", "model_house/matrix/M_dense.txt")):
        if (data / rel).exists():
            compare(name, data / rel, a.cli)
    with tempfile.TemporaryDirectory() as d:
        hotel = data / "hotel" / "images"
        if hotel.exists():
            subprocess.run([a.cli, "run", str(hotel), "--out", d, "--no-mesh"], check=True,
                           capture_output=True)
            compare("hotel (tracks of rank3 run)", Path(d) / "tracks.csv", a.cli)


if __name__ == "__main__":
    main()
