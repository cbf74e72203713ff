#!/usr/bin/env python3
"""rank3's KLT tracker next to OpenCV's goodFeaturesToTrack + calcOpticalFlowPyrLK.

Same window, pyramid levels, iteration criteria and feature count on the CMU hotel
sequence (51 frames, 512x480):

1. Speed (detection mode): frames per second of the tracking loop (pyramids, detection,
   tracking; frames already decoded), with the same re-detection policy for both (re-detect
   in empty regions when fewer than 90 % of the features are alive).
2. Accuracy: both trackers follow the 491 reference tracks from their frame-0 positions;
   median / p95 distance to the reference over all tracked observations, and how many tracks
   reach the last frame.
3. With --synthetic DIR (written by `cargo run --release --example klt_synthetic -- 640 480
   20 DIR`): both trackers follow the same frame-0 corners through rendered sequences with
   known motion; median / p95 endpoint error against the truth and the fraction of wrong
   tracks (> 2 px somewhere) kept.

rank3 runs as a subprocess (`rank3 track`, release build); its tracking time is the one it
prints (decoding excluded, like OpenCV's loop here, whose frames are preloaded).

    cargo build --release && pip install opencv-python-headless
    python3 examples/klt_vs_opencv.py [--features 500] [--window 21] [--levels 3]
"""

import argparse
import csv
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np


def natural_key(name):
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", name)]


def image_names(folder):
    return sorted(
        (n for n in os.listdir(folder) if n.lower().endswith((".png", ".jpg", ".jpeg"))),
        key=natural_key,
    )


def load_frames(folder):
    return [cv2.imread(str(Path(folder) / n), cv2.IMREAD_GRAYSCALE) for n in image_names(folder)]


def read_reference(root):
    xs = np.loadtxt(root / "tracked_points_Xs.txt", comments="#")
    ys = np.loadtxt(root / "tracked_points_Ys.txt", comments="#")
    return xs, ys  # frames x tracks


def lk(prev, nxt, pts, a, fb):
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 0.01)
    win = (a.window, a.window)
    p1, st, _ = cv2.calcOpticalFlowPyrLK(
        prev, nxt, pts, None, winSize=win, maxLevel=a.levels, criteria=crit
    )
    ok = st.reshape(-1) == 1
    if fb:
        p0b, st_b, _ = cv2.calcOpticalFlowPyrLK(
            nxt, prev, p1, None, winSize=win, maxLevel=a.levels, criteria=crit
        )
        err = np.linalg.norm((p0b - pts).reshape(-1, 2), axis=1)
        ok &= (st_b.reshape(-1) == 1) & (err < 1.0)
    return p1, ok


def opencv_detect_run(frames, a, fb):
    """Detection + tracking + re-detection; returns (seconds, tracks started, alive at end,
    CPU seconds including PNG decoding)."""
    c0 = time.process_time()
    for name in a.names:
        cv2.imread(str(a.images / name), cv2.IMREAD_GRAYSCALE)
    c_decode = time.process_time() - c0
    h, w = frames[0].shape
    c0 = time.process_time()
    t0 = time.perf_counter()
    pts = cv2.goodFeaturesToTrack(
        frames[0], a.features, qualityLevel=0.01, minDistance=8, blockSize=3
    )
    started = len(pts)
    for k in range(1, len(frames)):
        p1, ok = lk(frames[k - 1], frames[k], pts, a, fb)
        pts = p1[ok].reshape(-1, 1, 2)
        if len(pts) < 0.9 * a.features:
            mask = np.full((h, w), 255, np.uint8)
            for x, y in pts.reshape(-1, 2):
                cv2.circle(mask, (int(round(x)), int(round(y))), 8, 0, -1)
            new = cv2.goodFeaturesToTrack(
                frames[k],
                a.features - len(pts),
                qualityLevel=0.01,
                minDistance=8,
                blockSize=3,
                mask=mask,
            )
            if new is not None:
                started += len(new)
                pts = np.concatenate([pts, new.astype(np.float32)])
    return time.perf_counter() - t0, started, len(pts), time.process_time() - c0 + c_decode


def opencv_init_run(frames, init, a, fb):
    """Follows init points; returns positions (frames x tracks x 2, NaN once lost)."""
    n = len(init)
    out = np.full((len(frames), n, 2), np.nan)
    out[0] = init
    alive = np.arange(n)
    pts = init.astype(np.float32).reshape(-1, 1, 2)
    for k in range(1, len(frames)):
        if len(alive) == 0:
            break
        p1, ok = lk(frames[k - 1], frames[k], pts, a, fb)
        alive = alive[ok]
        pts = p1[ok].reshape(-1, 1, 2)
        out[k, alive] = pts.reshape(-1, 2)
    return out


def rank3_run(a, out_csv, extra):
    cmd = [
        a.bin, "track", str(a.images), "--out", str(out_csv),
        "--max-features", str(a.features), "--window", str(a.window),
        "--levels", str(a.levels), "--iterations", "30",
    ] + extra
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"rank3 failed: {r.stderr}")
    m = re.search(r"tracking time ([0-9.]+) s", r.stderr)
    started = re.search(r"(\d+) tracks started", r.stderr)
    alive = re.search(r"(\d+) alive at the end", r.stderr)
    cpu = re.search(r"CPU ([0-9.]+) s", r.stderr)
    return (float(m.group(1)), int(started.group(1)), int(alive.group(1)),
            float(cpu.group(1)) if cpu else float("nan"))


def read_rank3_csv(path, n_frames, n_tracks):
    out = np.full((n_frames, n_tracks, 2), np.nan)
    frame_index = {}
    with open(path) as f:
        for row in csv.DictReader(f):
            k = frame_index.setdefault(row["frame"], len(frame_index))
            out[k, int(row["track"])] = (float(row["x"]), float(row["y"]))
    return out


def accuracy(pos, xs, ys):
    ref = np.stack([xs, ys], axis=-1)
    d = np.linalg.norm(pos[1:] - ref[1:], axis=-1)
    d = d[~np.isnan(d)]
    last = int((~np.isnan(pos[-1, :, 0])).sum())
    return np.median(d), np.percentile(d, 95), last


def synthetic(a, dirs, tmp):
    print("\nSynthetic sequences with known motion (same frame-0 corners for both; FB check on)\n")
    print("| motion | tracker | median EPE (px) | p95 EPE (px) | wrong tracks kept (> 2 px) | tracks to last frame |")
    print("|---|---|---|---|---|---|")
    for d in dirs:
        frames = load_frames(d / "frames")
        init = np.loadtxt(d / "init.txt").reshape(-1, 2)
        n, nf = len(init), len(frames)
        truth = np.full((nf, n, 2), np.nan)
        with open(d / "truth.csv") as f:
            for row in csv.DictReader(f):
                truth[int(row["frame"]), int(row["track"])] = (float(row["x"]), float(row["y"]))
        out_csv = Path(tmp) / "s.csv"
        a2 = argparse.Namespace(**vars(a))
        a2.images = d / "frames"
        rank3_run(a2, out_csv, ["--init-points", str(d / "init.txt")])
        runs = [("OpenCV", opencv_init_run(frames, init, a, True)),
                ("rank3", read_rank3_csv(out_csv, nf, n))]
        for name, pos in runs:
            e = np.linalg.norm(pos[1:] - truth[1:], axis=-1)
            tracked = ~np.isnan(e)
            has = tracked.any(axis=0)
            wrong = (np.nan_to_num(e, nan=0.0) > 2.0).any(axis=0) & has
            ev = e[tracked]
            last = int((~np.isnan(pos[-1, :, 0])).sum())
            print(f"| {d.name} | {name} | {np.median(ev):.3f} | {np.percentile(ev, 95):.3f} "
                  f"| {100 * wrong.sum() / max(has.sum(), 1):.2f} % ({wrong.sum()}) | {last} / {n} |")


def main():
    root = Path(os.environ.get("RANK3_DATASETS", Path(__file__).resolve().parents[2] / "shared" / "datasets"))
    p = argparse.ArgumentParser()
    p.add_argument("--hotel", type=Path, default=root / "hotel")
    p.add_argument("--bin", default=str(Path(__file__).resolve().parents[1] / "target" / "release" / "rank3"))
    p.add_argument("--features", type=int, default=500)
    p.add_argument("--window", type=int, default=21)
    p.add_argument("--levels", type=int, default=3)
    p.add_argument("--repeat", type=int, default=3, help="timing runs; the best is reported")
    p.add_argument("--synthetic", type=Path, help="folder written by the klt_synthetic example")
    a = p.parse_args()
    a.images = a.hotel / "images"
    a.names = image_names(a.images)
    frames = load_frames(a.images)
    nf = len(frames)
    threads = cv2.getNumThreads()
    print(f"hotel: {nf} frames {frames[0].shape[1]}x{frames[0].shape[0]}, {a.features} features, "
          f"window {a.window}, levels {a.levels}, 30 iterations / eps 0.01; "
          f"OpenCV {cv2.__version__} ({threads} threads), {os.cpu_count()} CPUs\n")

    print("| tracker | FB check | tracks started | alive at end | tracking wall time (s) | frames/s (wall) | CPU s incl. PNG decoding | frames/s (CPU) |")
    print("|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        out_csv = Path(tmp) / "t.csv"
        for fb in (True, False):
            best = min(opencv_detect_run(frames, a, fb) for _ in range(a.repeat))
            runs = [opencv_detect_run(frames, a, fb) for _ in range(a.repeat)]
            best, cpu = min(runs), min(r[3] for r in runs)
            print(f"| OpenCV goodFeaturesToTrack + calcOpticalFlowPyrLK | {'on' if fb else 'off'} "
                  f"| {best[1]} | {best[2]} | {best[0]:.3f} | {nf / best[0]:.1f} | {cpu:.3f} | {nf / cpu:.1f} |")
            extra = [] if fb else ["--no-fb"]
            runs = [rank3_run(a, out_csv, extra) for _ in range(a.repeat)]
            best, cpu = min(runs), min(r[3] for r in runs)
            print(f"| rank3 track | {'on' if fb else 'off'} | {best[1]} | {best[2]} "
                  f"| {best[0]:.3f} | {nf / best[0]:.1f} | {cpu:.3f} | {nf / cpu:.1f} |")

        xs, ys = read_reference(a.hotel)
        init = np.stack([xs[0], ys[0]], axis=-1)
        pts_file = Path(tmp) / "init.txt"
        np.savetxt(pts_file, init, fmt="%.17g")
        print(f"\nAccuracy against the {init.shape[0]} hotel reference tracks (started from their frame-0 positions)\n")
        print("| tracker | FB check | median dist (px) | p95 dist (px) | tracks to last frame |")
        print("|---|---|---|---|---|")
        for fb in (True, False):
            med, p95, last = accuracy(opencv_init_run(frames, init, a, fb), xs, ys)
            print(f"| OpenCV calcOpticalFlowPyrLK | {'on' if fb else 'off'} | {med:.3f} | {p95:.3f} | {last} / {init.shape[0]} |")
            extra = ["--init-points", str(pts_file)] + ([] if fb else ["--no-fb"])
            rank3_run(a, out_csv, extra)
            pos = read_rank3_csv(out_csv, nf, init.shape[0])
            med, p95, last = accuracy(pos, xs, ys)
            print(f"| rank3 track | {'on' if fb else 'off'} | {med:.3f} | {p95:.3f} | {last} / {init.shape[0]} |")

        if a.synthetic:
            synthetic(a, sorted(p for p in a.synthetic.iterdir() if (p / "truth.csv").exists()), tmp)


if __name__ == "__main__":
    main()
