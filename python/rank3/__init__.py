"""rank3: 3D structure and camera motion from 2D point tracks, from NumPy.

The same pipeline as the Rust library and the ``rank3`` command line: Tomasi-Kanade
factorization with missing data and a robust pass, the metric upgrade, projective
factorization and a Euclidean (perspective) reconstruction, chosen from the data.

>>> import numpy as np, rank3
>>> tracks = rank3.read_tracks("tracks.csv")          # doctest: +SKIP
>>> rec = rank3.reconstruct(tracks)                    # doctest: +SKIP
>>> rec.points.shape, rec.rms_px                       # doctest: +SKIP

Tables are ``(F, N, 2)`` float arrays (frames x tracks x (x, y) pixels) with NaN for the
entries not observed, or long tables (frame, track, x, y) given as a pandas DataFrame, a
dict of four arrays, or a tuple of four arrays. Errors are ``Rank3Error`` subclasses with the
file, line and field where rank3 knows them; how a solver ended is data in the result.
"""

from __future__ import annotations

import json
import os
from typing import Any, Callable, Iterable, Optional, Sequence, Union

import numpy as np

from . import _rank3
from ._rank3 import ConfigError, DataError, InputError, NumericalError, Rank3Error

__all__ = [
    "Tracks",
    "Reconstruction",
    "reconstruct",
    "reconstruct_stream",
    "track",
    "read_tracks",
    "write_tracks",
    "default_settings",
    "Rank3Error",
    "InputError",
    "ConfigError",
    "DataError",
    "NumericalError",
]

__version__ = _rank3.__version__


def default_settings(kind: str = "reconstruct") -> dict:
    """The library's default settings, as nested dicts: ``"reconstruct"`` (every field of
    ``rank3::Config``: the sections ``svd``, ``metric``, ``robust``, ``completion``,
    ``refine``, ``projective``, ``perspective``, ``sparse`` and the top-level values) or ``"track"``
    (``rank3::tracking::TrackerConfig``: ``detect``, ``klt`` and the re-detection values).
    Any of them can be overridden by keyword argument (see :func:`reconstruct`)."""
    return json.loads(_rank3.default_settings(kind))


class Tracks:
    """A track table: ``xy`` ``(F, N, 2)`` float64 with NaN for missing entries, and the
    frame and track ids (ints or strings, as in the input)."""

    __slots__ = ("xy", "frame_ids", "track_ids")

    def __init__(self, xy: np.ndarray, frame_ids: Sequence = None, track_ids: Sequence = None):
        xy = np.ascontiguousarray(np.asarray(xy, dtype=np.float64))
        if xy.ndim != 3 or xy.shape[2] != 2:
            raise InputError(f"tracks must have shape (F, N, 2), got {xy.shape}")
        self.xy = xy
        self.frame_ids = list(range(xy.shape[0])) if frame_ids is None else list(frame_ids)
        self.track_ids = list(range(xy.shape[1])) if track_ids is None else list(track_ids)
        if len(self.frame_ids) != xy.shape[0] or len(self.track_ids) != xy.shape[1]:
            raise InputError(
                f"{len(self.frame_ids)} frame ids and {len(self.track_ids)} track ids "
                f"for an array of shape {xy.shape}"
            )

    @property
    def shape(self):
        return self.xy.shape

    @property
    def observed(self) -> np.ndarray:
        """``(F, N)`` bool: which entries are observed."""
        return ~np.isnan(self.xy[..., 0])

    def __repr__(self) -> str:
        f, n, _ = self.xy.shape
        return f"Tracks({f} frames x {n} tracks, {int(self.observed.sum())} observations)"


def _plain(v):
    return v.item() if isinstance(v, np.generic) else v


def _as_tracks(tracks, frame_ids=None, track_ids=None) -> Tracks:
    """An (F, N, 2) array, a Tracks, or a long table (frame, track, x, y)."""
    if isinstance(tracks, Tracks):
        return tracks
    columns = None
    if hasattr(tracks, "columns") and hasattr(tracks, "to_numpy"):  # pandas DataFrame
        names = [str(c) for c in tracks.columns]
        missing = [c for c in ("frame", "track", "x", "y") if c not in names]
        if missing:
            raise InputError(
                f"a long table needs the columns frame, track, x, y; missing {missing}"
            )
        columns = [tracks[c].to_numpy() for c in ("frame", "track", "x", "y")]
    elif isinstance(tracks, dict):
        try:
            columns = [np.asarray(tracks[c]) for c in ("frame", "track", "x", "y")]
        except KeyError as e:
            raise InputError(f"a long table needs the keys frame, track, x, y; missing {e}")
    elif isinstance(tracks, (tuple, list)) and len(tracks) == 4:
        columns = [np.asarray(c) for c in tracks]
    if columns is None:
        return Tracks(tracks, frame_ids, track_ids)
    frame, track, x, y = columns
    n = len(frame)
    if not (len(track) == len(x) == len(y) == n):
        raise InputError("the columns frame, track, x, y have different lengths")
    fids, fi = np.unique(frame, return_inverse=True)
    tids, ti = np.unique(track, return_inverse=True)
    xy = np.full((len(fids), len(tids), 2), np.nan)
    key = fi.astype(np.int64) * len(tids) + ti
    if len(np.unique(key)) != n:
        first = np.flatnonzero(np.bincount(key) > 1)[0]
        raise InputError(
            f"track {_plain(tids[first % len(tids)])} is observed twice in frame "
            f"{_plain(fids[first // len(tids)])}"
        )
    xy[fi, ti, 0] = np.asarray(x, dtype=np.float64)
    xy[fi, ti, 1] = np.asarray(y, dtype=np.float64)
    return Tracks(xy, [_plain(v) for v in fids], [_plain(v) for v in tids])


def read_tracks(path: Union[str, os.PathLike]) -> Tracks:
    """Reads a track table: ``.csv`` (frame,track,x,y), ``.txt`` (dense 2F x N matrix, nan =
    missing) or ``.json`` (docs/formats.md). Errors name the file, line and field."""
    xy, f, t = _rank3.read_tracks(os.fspath(path))
    return Tracks(xy, f, t)


def write_tracks(path: Union[str, os.PathLike], tracks) -> None:
    """Writes a track table in the format of the path's extension."""
    t = _as_tracks(tracks)
    _rank3.write_tracks(os.fspath(path), t.xy, t.frame_ids, t.track_ids)


_TRACK_SECTIONS = ("detect", "klt")


def track(
    frames,
    *,
    max_features: Optional[int] = None,
    window: Optional[int] = None,
    levels: Optional[int] = None,
    fb_threshold: Optional[float] = None,
    subpixel: Union[bool, dict, None] = True,
    detect: Optional[dict] = None,
    klt: Optional[dict] = None,
    progress: Optional[Callable[[dict], Any]] = None,
    **settings,
) -> Tracks:
    """Tracks Shi-Tomasi corners with pyramidal Lucas-Kanade through ``frames``: a folder of
    PNG/JPEG images, a video file (through ffmpeg), or an iterable of NumPy frames (2-D gray
    or 3-D RGB, uint8 or float in [0, 1]). Returns the track table.

    Shortcuts: ``max_features`` (detect.max_features, default 500), ``window``
    (klt.window, 21), ``levels`` (klt.max_level, 3), ``fb_threshold`` (klt.fb_threshold,
    1.0 px). ``subpixel``: the sub-pixel (Forstner) refinement of detected corners before
    they are tracked (``True``, the default); ``False`` (or ``None``) starts new tracks at
    the whole-pixel corners, as the CLI's ``--no-subpixel``; a dict overrides fields of the
    refinement (``method``, ``half_window``, ``max_iterations``, ``epsilon``,
    ``max_shift``). ``detect`` and ``klt`` override any field of those sections, other
    keywords the top-level fields (``min_track_len``, ``redetect``, ``redetect_below``,
    ``redetect_radius``, ``redetect_with_points``); ``default_settings("track")`` lists every
    field and its default. ``progress(event)`` is called once per frame with a dict."""
    over: dict = dict(settings)
    d = dict(detect or {})
    k = dict(klt or {})
    if max_features is not None:
        d["max_features"] = max_features
    if window is not None:
        k["window"] = window
    if levels is not None:
        k["max_level"] = levels
    if fb_threshold is not None:
        k["fb_threshold"] = fb_threshold
    if subpixel is False or subpixel is None:
        over["subpixel"] = None
    elif isinstance(subpixel, dict):
        over["subpixel"] = dict(subpixel)
    elif subpixel is not True:
        raise ConfigError(f"subpixel must be True, False or a dict, got {subpixel!r}")
    if d:
        over["detect"] = d
    if k:
        over["klt"] = k
    js = json.dumps(over)
    if isinstance(frames, (str, os.PathLike)):
        xy, f, t = _rank3.track_path(os.fspath(frames), js, progress)
    else:
        xy, f, t = _rank3.track_frames(frames, js, progress)
    return Tracks(xy, f, t)


class Reconstruction:
    """The result of :func:`reconstruct`. Arrays are indexed like the input table (frame f,
    track p), with NaN for frames and tracks set aside; ``report`` holds everything
    ``reconstruction.json`` holds (diagnostics, solver reports, warnings, timings) as Python
    values."""

    def __init__(self, inner):
        self._inner = inner
        self._report = None

    @property
    def report(self) -> dict:
        """The full report, as ``reconstruction.json`` (docs/formats.md)."""
        if self._report is None:
            self._report = json.loads(self._inner.to_json())
        return self._report

    def to_json(self) -> str:
        """``reconstruction.json``'s text."""
        return self._inner.to_json()

    def save(self, directory: Union[str, os.PathLike]) -> None:
        """Writes the CLI's files into ``directory``: reconstruction.json, completed.txt,
        points.ply, and colmap/ with a perspective result."""
        self._inner.save(os.fspath(directory))

    camera_model = property(lambda self: self._inner.camera_model, doc="The camera model used (chosen with 'auto').")
    rms_px = property(lambda self: self._inner.rms_px, doc="RMS reprojection error over observed scalars, pixels.")
    library_seconds = property(lambda self: self._inner.library_seconds, doc="Seconds spent inside the Rust library.")
    frame_ids = property(lambda self: self._inner.frame_ids)
    track_ids = property(lambda self: self._inner.track_ids)
    rotations = property(lambda self: self._inner.rotations, doc="(F, 3, 3) world-to-camera rotations.")
    translations = property(lambda self: self._inner.translations, doc="(F, 3) perspective or (F, 2) affine translations.")
    scales = property(lambda self: self._inner.scales, doc="(F,) scales of the affine-family model.")
    focal_px = property(lambda self: self._inner.focal_px, doc="(F,) focal lengths (perspective), else None.")
    K = property(lambda self: self._inner.k, doc="(3, 3) intrinsics of the first perspective camera, else None.")
    points = property(lambda self: self._inner.points, doc="(N, 3) points.")
    inlier = property(lambda self: self._inner.inlier, doc="(N,) tracks the fit kept.")
    flagged = property(lambda self: self._inner.flagged, doc="(F, N) entries flagged as gross errors.")
    completed = property(lambda self: self._inner.completed, doc="(F, N, 2) every track predicted in every frame.")
    projective_cameras = property(lambda self: self._inner.projective_cameras, doc="(F, 3, 4) P_f, else None.")
    projective_points = property(lambda self: self._inner.projective_points, doc="(N, 4) X_p, else None.")

    @property
    def singular_values(self) -> list:
        return self.report["singular_values"]

    @property
    def warnings(self) -> list:
        return self.report["warnings"]

    @property
    def timings(self) -> list:
        return self.report["timings"]

    def __repr__(self) -> str:
        f = len(self.frame_ids)
        n = int(self.inlier.sum())
        return f"Reconstruction({self.camera_model}, {f} frames, {n} inlier points, RMS {self.rms_px:.4f} px)"


_SECTIONS = ("svd", "metric", "completion", "projective", "perspective", "sparse")


def reconstruct(
    tracks,
    *,
    camera: str = "auto",
    robust: Union[bool, dict] = True,
    refine: Union[bool, dict] = True,
    seed: int = 0,
    min_frames_per_track: int = 2,
    min_points_per_frame: int = 3,
    rank3_warning_ratio: float = 0.1,
    rank2_warning_ratio: float = 0.05,
    svd: Optional[dict] = None,
    metric: Optional[dict] = None,
    completion: Optional[dict] = None,
    projective: Optional[dict] = None,
    perspective: Optional[dict] = None,
    sparse: Optional[dict] = None,
    focal: Optional[float] = None,
    principal_point: Optional[Sequence[float]] = None,
    image_size: Optional[Sequence[int]] = None,
    frame_ids: Optional[Sequence] = None,
    track_ids: Optional[Sequence] = None,
    rrd: Union[str, os.PathLike, None] = None,
    progress: Optional[Callable[[dict], Any]] = None,
) -> Reconstruction:
    """Recovers cameras and 3D points from ``tracks``.

    ``tracks``: an ``(F, N, 2)`` array (NaN = missing), a :class:`Tracks`, or a long table
    (frame, track, x, y) as a pandas DataFrame, a dict or a tuple of four arrays.

    Settings mirror the library's ``rank3::Config`` field by field, with its defaults
    (``default_settings()`` prints them all), except ``camera``, ``"auto"`` as for the
    command line (the library's default is ``"orthographic"``):

    * ``camera``: ``"auto"`` (scaled orthographic or perspective, chosen by a BIC test),
      ``"orthographic"``, ``"scaled-orthographic"``, ``"projective"``, ``"perspective"``.
    * ``robust``: ``True`` (the default robust pass), ``False`` (none) or a dict overriding
      fields of ``robust`` (e.g. ``{"min_track_threshold_px": 3.0}``); ``refine`` likewise.
    * ``seed``, ``min_frames_per_track``, ``min_points_per_frame``, ``rank3_warning_ratio``,
      ``rank2_warning_ratio``: the top-level values.
    * ``svd``, ``metric``, ``completion``, ``projective``, ``perspective``, ``sparse``: dicts
      overriding fields of those sections, e.g. ``completion={"solver": "als", "runs": 4}``
      or ``sparse={"pipeline": "sparse"}`` (the sparse pipeline for long videos:
      ``"auto"``, ``"dense"`` or ``"sparse"``; docs/math.md §13).
    * ``focal``, ``principal_point``, ``image_size``: known intrinsics of the perspective
      camera (shortcuts for ``perspective={"intrinsics": {...}}``).

    ``rrd``: a path to save a Rerun recording of every stage. ``progress(event)``: called
    with a dict per stage and at most every 50 ms during solver iterations (``kind``,
    ``solver``, ``iteration``, ``cost``, ``rms``, ...). Raising from it, or Ctrl-C, stops the
    run. The GIL is released while rank3 computes.
    """
    t = _as_tracks(tracks, frame_ids, track_ids)
    over: dict = {
        "camera": camera,
        "seed": seed,
        "min_frames_per_track": min_frames_per_track,
        "min_points_per_frame": min_points_per_frame,
        "rank3_warning_ratio": rank3_warning_ratio,
        "rank2_warning_ratio": rank2_warning_ratio,
    }
    for name, value in (("robust", robust), ("refine", refine)):
        if value is False or value is None:
            over[name] = None
        elif isinstance(value, dict):
            over[name] = value
        elif value is not True:
            raise ConfigError(f"{name} must be True, False or a dict, got {value!r}")
    for name, value in zip(_SECTIONS, (svd, metric, completion, projective, perspective, sparse)):
        if value is not None:
            over[name] = dict(value)
    intr = {}
    if focal is not None:
        intr["focal_px"] = float(focal)
    if principal_point is not None:
        intr["principal_point"] = [float(v) for v in principal_point]
    if image_size is not None:
        intr["image_size"] = [int(v) for v in image_size]
    if intr:
        p = over.setdefault("perspective", {})
        p["intrinsics"] = {**p.get("intrinsics", {}), **intr}
    inner = _rank3.reconstruct(
        t.xy,
        t.frame_ids,
        t.track_ids,
        json.dumps(over),
        None if rrd is None else os.fspath(rrd),
        progress,
    )
    return Reconstruction(inner)


def reconstruct_stream(
    path: Union[str, os.PathLike],
    *,
    memory: Union[int, str] = "1G",
    camera: str = "auto",
    robust: bool = True,
    progress: Optional[Callable[[dict], Any]] = None,
    **settings,
) -> Reconstruction:
    """Fits the complete tracks of a CSV file (``frame,track,x,y``) without holding them:
    the streaming factorization of ``rank3 reconstruct --stream`` (docs/math.md §13).

    The file is read in passes, each filling a block of tracks that fits ``memory`` (bytes,
    or a string with a K, M, G or T suffix); the tracks' 2F×2F Gram matrix gives the same
    factorization as the in-memory SVD. Affine cameras only (``"auto"`` means
    ``"scaled-orthographic"``; ``"orthographic"``), a per-track outlier test instead of
    RANSAC (``robust=False`` turns it off), no refinement; tracks not seen in every frame
    are set aside (``report["set_aside"]``). Other keyword arguments override fields of
    ``rank3::stream::StreamConfig`` (e.g. ``max_rounds=5``, ``track_probability=0.999``).
    The result's ``report["stream"]`` says how many passes it took.
    """
    if isinstance(memory, str):
        text = memory.strip()
        scale = {"K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}
        unit = text[-1:].upper()
        try:
            memory = int(float(text[:-1]) * scale[unit]) if unit in scale else int(text)
        except ValueError:
            raise ConfigError(f"memory {text!r} is not a byte count (e.g. 512M, 2G)") from None
    if camera == "auto":
        camera = "scaled-orthographic"
    over = {"memory_budget_bytes": int(memory), "camera": camera, "robust": bool(robust)}
    over.update(settings)
    inner = _rank3.reconstruct_stream(os.fspath(path), json.dumps(over), progress)
    return Reconstruction(inner)


def to_pycolmap(rec: Reconstruction, directory: Union[str, os.PathLike]):
    """The perspective reconstruction as a ``pycolmap.Reconstruction`` (needs pycolmap):
    written as a COLMAP text model into ``directory`` (by :meth:`Reconstruction.save`),
    then read by pycolmap."""
    import pycolmap  # noqa: PLC0415 - optional dependency

    if rec.report.get("perspective") is None:
        raise DataError("a COLMAP model needs a perspective reconstruction (camera='perspective' or 'auto' choosing it)")
    rec.save(directory)
    return pycolmap.Reconstruction(os.path.join(os.fspath(directory), "colmap"))


__all__.append("to_pycolmap")
