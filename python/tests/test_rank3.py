"""The Python package against the library and the command line.

Run by `cargo test` (tests/python.rs builds the extension into the test venv first), or by
hand after `pip install ./python`: `python -m pytest python/tests`. `RANK3_BIN` names the
`rank3` binary for the comparisons with the command line (skipped without it),
`RANK3_DATASETS` the data sets, `RERUN_BIN` the Rerun CLI.
"""

import json
import os
import re
import signal
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import rank3

ROOT = Path(__file__).resolve().parents[2]
TOY = ROOT / "datasets" / "toy-house" / "tracks.csv"


def scene(frames=12, points=80, missing=0.0, noise=0.3, distance=None, seed=0):
    """Orthographic (or, with `distance`, perspective) views of a random point cloud turning
    about the vertical axis: (F, N, 2) with NaN for the missing entries."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(-1, 1, (points, 3))
    out = np.empty((frames, points, 2))
    for f in range(frames):
        a = np.deg2rad(-20 + 40 * f / (frames - 1))
        r = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
        c = x @ r.T
        if distance is None:
            out[f] = 200 * c[:, :2] + 320
        else:
            z = c[:, 2] + distance
            out[f] = 500 * c[:, :2] / z[:, None] + 320
    out += rng.normal(0, noise, out.shape)
    if missing:
        hide = rng.random((frames, points)) < missing
        hide[:3] = False  # every track seen in the first frames: one connected table
        out[hide] = np.nan
    return out


def test_shapes_and_dtypes_in_and_out():
    xy = scene().astype(np.float32)
    rec = rank3.reconstruct(xy, camera="orthographic")
    f, n = xy.shape[:2]
    assert rec.camera_model == "orthographic"
    assert rec.rotations.shape == (f, 3, 3) and rec.rotations.dtype == np.float64
    assert rec.translations.shape == (f, 2)
    assert rec.scales.shape == (f,)
    assert rec.points.shape == (n, 3)
    assert rec.inlier.shape == (n,) and rec.inlier.dtype == np.bool_
    assert rec.flagged.shape == (f, n)
    assert rec.completed.shape == (f, n, 2)
    assert rec.focal_px is None and rec.K is None and rec.projective_cameras is None
    r0 = rec.rotations[0]
    assert np.allclose(r0 @ r0.T, np.eye(3), atol=1e-9)
    assert rec.rms_px < 0.5
    assert isinstance(rec.report["singular_values"], list)
    assert rec.singular_values == rec.report["singular_values"]
    assert isinstance(rec.timings, list) and isinstance(rec.warnings, list)
    assert json.loads(rec.to_json())["rms_px"] == rec.rms_px


def test_long_tables_keep_their_ids():
    xy = scene(frames=6, points=20)
    f, p = np.nonzero(~np.isnan(xy[..., 0]))
    names = np.array([f"t{k}" for k in range(20)])
    long = {"frame": f + 100, "track": names[p], "x": xy[f, p, 0], "y": xy[f, p, 1]}
    for tracks in (long, (long["frame"], long["track"], long["x"], long["y"])):
        rec = rank3.reconstruct(tracks, camera="orthographic")
        assert rec.frame_ids == list(range(100, 106))
        assert sorted(rec.track_ids) == sorted(names.tolist())
    pd = pytest.importorskip("pandas")
    rec = rank3.reconstruct(pd.DataFrame(long), camera="orthographic")
    assert rec.points.shape == (20, 3)
    dup = {k: np.concatenate([v, v[:1]]) for k, v in long.items()}
    with pytest.raises(rank3.InputError, match="observed twice"):
        rank3.reconstruct(dup)


def test_streaming_factorization_of_a_csv(tmp_path):
    xy = scene(frames=10, points=60, seed=3)
    path = tmp_path / "t.csv"
    rank3.write_tracks(path, xy)
    whole = rank3.reconstruct(xy, camera="scaled-orthographic", refine=False, robust=False)
    # 2K: 2048 / (2F · 8 bytes) = 12 tracks per block, so 5 blocks: the counting pass,
    # five Gram passes and one structure pass.
    streamed = rank3.reconstruct_stream(path, memory="2K", robust=False)
    assert streamed.report["stream"]["blocks"] == 5
    assert streamed.report["stream"]["passes"] == 7
    assert streamed.camera_model == "scaled-orthographic"
    assert streamed.points.shape == (60, 3)
    np.testing.assert_allclose(streamed.completed, whole.completed, atol=1e-8)
    assert abs(streamed.rms_px - whole.rms_px) < 1e-9
    with pytest.raises(rank3.ConfigError):
        rank3.reconstruct_stream(path, camera="perspective")


def test_nan_entries_are_missing_data():
    xy = scene(frames=10, points=60, missing=0.3)
    rec = rank3.reconstruct(xy, camera="orthographic")
    assert rec.report["completion"] is not None
    hidden = np.isnan(xy[..., 0])
    assert np.isfinite(rec.completed[hidden]).all()
    assert rec.rms_px < 0.6
    half = xy.copy()
    half[0, 0, 1] = np.nan
    with pytest.raises(rank3.InputError, match=r"tracks\[0, 0\]"):
        rank3.reconstruct(half)


def test_every_file_format_round_trips(tmp_path):
    xy = scene(frames=5, points=15, missing=0.2)
    t = rank3.Tracks(xy, [f"f{k}" for k in range(5)], list(range(15)))
    for ext in ("csv", "txt", "json"):
        path = tmp_path / f"t.{ext}"
        rank3.write_tracks(path, t)
        back = rank3.read_tracks(path)
        assert back.shape == t.shape
        np.testing.assert_allclose(back.xy, t.xy, rtol=0, atol=1e-9, equal_nan=True)
        if ext != "txt":
            assert back.frame_ids == t.frame_ids
    toy = rank3.read_tracks(TOY)
    assert toy.shape == (30, 200, 2)


def test_errors_carry_file_line_and_field(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("frame,track,x,y\n0,1,2.0,3.0\n1,1,2.5,oops\n")
    with pytest.raises(rank3.InputError) as e:
        rank3.read_tracks(bad)
    assert (e.value.kind, e.value.line, e.value.field) == ("parse", 3, "y")
    assert e.value.path == str(bad)
    with pytest.raises(rank3.InputError) as e:
        rank3.read_tracks(tmp_path / "missing.csv")
    assert e.value.kind == "io"
    with pytest.raises(rank3.ConfigError, match="completion.rnus"):
        rank3.reconstruct(scene(), completion={"rnus": 2})
    with pytest.raises(rank3.ConfigError):
        rank3.reconstruct(scene(), completion={"runs": "many"})
    with pytest.raises(rank3.DataError):
        rank3.reconstruct(scene(frames=2, points=3))
    assert issubclass(rank3.DataError, rank3.Rank3Error)


def test_settings_reach_every_config_field():
    d = rank3.default_settings()
    for section in ("svd", "metric", "robust", "completion", "refine", "projective", "perspective", "sparse"):
        assert isinstance(d[section], dict)
    rec = rank3.reconstruct(
        scene(missing=0.2), camera="orthographic", robust=False, refine=False,
        completion={"solver": "als", "max_iterations": 500},
    )
    assert rec.report["robust"] is None and rec.report["refinement"] is None
    assert rec.report["completion"]["solver"] == "als"
    assert "klt" in rank3.default_settings("track")
    # The sparse pipeline, asked for: its report is in the result.
    rec = rank3.reconstruct(scene(missing=0.2), camera="scaled-orthographic", sparse={"pipeline": "sparse"})
    assert rec.report["sparse"]["status"] == "converged"
    assert rec.report["factorization"]["method"] == "sparse-varpro"


def test_results_equal_the_command_line(tmp_path):
    binary = os.environ.get("RANK3_BIN")
    if not binary:
        pytest.skip("RANK3_BIN not set (the rank3 binary)")
    out = tmp_path / "cli"
    subprocess.run([binary, "reconstruct", str(TOY), "--out", str(out)], check=True,
                   capture_output=True)
    cli = json.loads((out / "reconstruction.json").read_text())
    rec = rank3.reconstruct(rank3.read_tracks(TOY))
    assert rec.camera_model == cli["camera_model"]
    assert rec.rms_px == cli["rms_px"]
    pts = np.array([p["xyz"] for p in cli["points"]])
    np.testing.assert_array_equal(rec.points, pts)
    rec.save(tmp_path / "py")
    for name in ("reconstruction.json", "completed.txt", "points.ply"):
        assert (tmp_path / "py" / name).exists()
    assert (tmp_path / "py" / "points.ply").read_bytes() == (out / "points.ply").read_bytes()


def test_progress_and_interruption():
    events = []
    rank3.reconstruct(scene(missing=0.3), camera="projective", progress=events.append)
    kinds = {e["kind"] for e in events}
    assert {"stage-started", "stage-finished", "iteration"} <= kinds

    def stop(e):
        if e["kind"] == "iteration":
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        rank3.reconstruct(scene(missing=0.3), camera="projective", progress=stop)

    class Boom(Exception):
        pass

    def boom(e):
        raise Boom()

    with pytest.raises(Boom):
        rank3.reconstruct(scene(), progress=boom)


def test_ctrl_c_interrupts_a_long_run():
    xy = scene(frames=60, points=600, missing=0.5, distance=3.0, seed=3)
    timer = threading.Timer(0.5, lambda: signal.raise_signal(signal.SIGINT))
    t0 = time.perf_counter()
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            rank3.reconstruct(xy, camera="perspective")
    finally:
        timer.cancel()
    assert time.perf_counter() - t0 < 30


def test_the_gil_is_released_while_computing():
    xy = scene(frames=30, points=300, missing=0.4, seed=2)
    done = threading.Event()
    ticks = [0]

    def count():
        while not done.is_set():
            ticks[0] += 1
            time.sleep(0.001)

    th = threading.Thread(target=count)
    th.start()
    t0 = time.perf_counter()
    rank3.reconstruct(xy, camera="orthographic")
    elapsed = time.perf_counter() - t0
    done.set()
    th.join()
    # With the GIL held for the whole run the counter would not move.
    assert ticks[0] > 0.3 * elapsed / 0.0011, (ticks[0], elapsed)


def test_recording(tmp_path):
    path = tmp_path / "run.rrd"
    rank3.reconstruct(scene(), camera="orthographic", rrd=path)
    assert path.stat().st_size > 10_000
    rerun = os.environ.get("RERUN_BIN")
    if rerun:
        subprocess.run([rerun, "rrd", "verify", str(path)], check=True, capture_output=True)


def test_tracking_numpy_frames_and_folders(tmp_path):
    rng = np.random.default_rng(1)
    base = rng.random((40, 40))
    tex = np.kron(base, np.ones((6, 6)))  # 240 x 240 blocky texture: corners everywhere
    frames = [np.roll(np.roll(tex, 2 * k, axis=1), k, axis=0)[20:200, 20:220] for k in range(6)]
    events = []
    t = rank3.track((f * 255).astype(np.uint8) for f in frames)
    t2 = rank3.track(frames, max_features=100, progress=events.append)
    assert t.shape[0] == 6 and t.shape[1] > 20
    assert t2.shape[1] <= 100 and len(events) == 6
    # A track's motion is the frames' shift, (2, 1) px per frame.
    full = np.flatnonzero(t.observed.all(axis=0))
    d = np.nanmedian(t.xy[5, full] - t.xy[0, full], axis=0)
    np.testing.assert_allclose(d, [10.0, 5.0], atol=0.2)
    rgb = [np.stack([f] * 3, axis=-1) for f in frames]
    assert rank3.track(rgb).shape == t.shape
    pil = pytest.importorskip("PIL.Image")
    folder = tmp_path / "frames"
    folder.mkdir()
    for k, f in enumerate(frames):
        pil.fromarray((f * 255).astype(np.uint8)).save(folder / f"{k:03}.png")
    tp = rank3.track(folder)
    assert tp.frame_ids == list(range(6)) and tp.shape == t.shape
    with pytest.raises(rank3.InputError):
        rank3.track(tmp_path / "nothing-here")


def test_tracking_subpixel_option():
    rng = np.random.default_rng(1)
    tex = np.kron(rng.random((40, 40)), np.ones((6, 6)))  # corners between pixels
    frames = [np.roll(tex, k, axis=1)[20:200, 20:220] for k in range(3)]
    on = rank3.track(frames, max_features=100)
    off = rank3.track(frames, max_features=100, subpixel=False)
    first_on = on.xy[0][on.observed[0]]
    first_off = off.xy[0][off.observed[0]]
    assert len(first_on) > 20 and len(first_off) > 20
    # Without the refinement new tracks start at whole pixels; with it (the default) most
    # corners move off them.
    np.testing.assert_array_equal(first_off, np.round(first_off))
    assert np.mean(first_on != np.round(first_on)) > 0.5
    # None is False; a dict overrides the refinement's fields (and is checked).
    none = rank3.track(frames, max_features=100, subpixel=None)
    np.testing.assert_array_equal(none.xy, off.xy)
    with pytest.raises(rank3.ConfigError):
        rank3.track(frames, subpixel={"half_window": 0})
    with pytest.raises(rank3.ConfigError):
        rank3.track(frames, subpixel="off")


def test_pycolmap_interop(tmp_path):
    pycolmap = pytest.importorskip("pycolmap")
    xy = scene(frames=10, points=60, distance=3.0, seed=5)
    rec = rank3.reconstruct(xy, camera="perspective", image_size=(640, 640))
    model = rank3.to_pycolmap(rec, tmp_path)
    assert isinstance(model, pycolmap.Reconstruction)
    assert model.num_reg_images() == 10 if callable(getattr(model, "num_reg_images", None)) else True
    assert rec.focal_px.shape == (10,) and rec.K.shape == (3, 3)
    assert rec.translations.shape == (10, 3)


def test_the_readme_example_runs_as_written(tmp_path, monkeypatch):
    text = (ROOT / "README.md").read_text()
    m = re.search(r"<!-- python-example -->\s*```python\n(.*?)```", text, re.S)
    assert m, "README has no marked Python example"
    monkeypatch.chdir(ROOT)
    exec(compile(m.group(1), "README.md", "exec"), {})
