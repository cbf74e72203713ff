"""Type stubs of the rank3 package (see rank3/__init__.py for the documentation)."""

import os
from typing import Any, Callable, Iterable, Mapping, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

PathLike = Union[str, os.PathLike]
Event = Mapping[str, Any]
Progress = Callable[[dict], Any]
Frame = npt.ArrayLike
TrackInput = Union[
    "Tracks",
    npt.ArrayLike,
    Mapping[str, npt.ArrayLike],
    Tuple[npt.ArrayLike, npt.ArrayLike, npt.ArrayLike, npt.ArrayLike],
    Any,  # pandas.DataFrame with columns frame, track, x, y
]

class Rank3Error(Exception):
    kind: str
    path: Optional[str]
    line: Optional[int]
    field: Optional[str]
    detail: Optional[str]
    input: Optional[str]
    reason: Optional[str]

class InputError(Rank3Error): ...
class ConfigError(Rank3Error): ...
class DataError(Rank3Error): ...
class NumericalError(Rank3Error): ...

class Tracks:
    xy: np.ndarray
    frame_ids: list
    track_ids: list
    def __init__(
        self, xy: npt.ArrayLike, frame_ids: Optional[Sequence] = ..., track_ids: Optional[Sequence] = ...
    ) -> None: ...
    @property
    def shape(self) -> Tuple[int, int, int]: ...
    @property
    def observed(self) -> np.ndarray: ...

class Reconstruction:
    @property
    def report(self) -> dict: ...
    def to_json(self) -> str: ...
    def save(self, directory: PathLike) -> None: ...
    @property
    def camera_model(self) -> str: ...
    @property
    def rms_px(self) -> float: ...
    @property
    def library_seconds(self) -> float: ...
    @property
    def frame_ids(self) -> list: ...
    @property
    def track_ids(self) -> list: ...
    @property
    def rotations(self) -> np.ndarray: ...
    @property
    def translations(self) -> np.ndarray: ...
    @property
    def scales(self) -> np.ndarray: ...
    @property
    def focal_px(self) -> Optional[np.ndarray]: ...
    @property
    def K(self) -> Optional[np.ndarray]: ...
    @property
    def points(self) -> np.ndarray: ...
    @property
    def inlier(self) -> np.ndarray: ...
    @property
    def flagged(self) -> np.ndarray: ...
    @property
    def completed(self) -> np.ndarray: ...
    @property
    def projective_cameras(self) -> Optional[np.ndarray]: ...
    @property
    def projective_points(self) -> Optional[np.ndarray]: ...
    @property
    def singular_values(self) -> list: ...
    @property
    def warnings(self) -> list: ...
    @property
    def timings(self) -> list: ...

def default_settings(kind: str = ...) -> dict: ...
def read_tracks(path: PathLike) -> Tracks: ...
def write_tracks(path: PathLike, tracks: TrackInput) -> None: ...
def track(
    frames: Union[PathLike, Iterable[Frame]],
    *,
    max_features: Optional[int] = ...,
    window: Optional[int] = ...,
    levels: Optional[int] = ...,
    fb_threshold: Optional[float] = ...,
    subpixel: Union[bool, dict, None] = ...,
    detect: Optional[dict] = ...,
    klt: Optional[dict] = ...,
    progress: Optional[Progress] = ...,
    min_track_len: int = ...,
    redetect: bool = ...,
    redetect_below: float = ...,
    redetect_radius: Optional[float] = ...,
    redetect_with_points: bool = ...,
) -> Tracks: ...
def reconstruct(
    tracks: TrackInput,
    *,
    camera: str = "auto",
    robust: Union[bool, dict] = True,
    refine: Union[bool, dict] = True,
    seed: int = 0,
    min_frames_per_track: int = 2,
    min_points_per_frame: int = 3,
    rank3_warning_ratio: float = 0.1,
    rank2_warning_ratio: float = 0.05,
    svd: Optional[dict] = ...,
    metric: Optional[dict] = ...,
    completion: Optional[dict] = ...,
    projective: Optional[dict] = ...,
    perspective: Optional[dict] = ...,
    sparse: Optional[dict] = ...,
    focal: Optional[float] = ...,
    principal_point: Optional[Sequence[float]] = ...,
    image_size: Optional[Sequence[int]] = ...,
    frame_ids: Optional[Sequence] = ...,
    track_ids: Optional[Sequence] = ...,
    rrd: Optional[PathLike] = ...,
    progress: Optional[Progress] = ...,
) -> Reconstruction: ...
def reconstruct_stream(
    path: PathLike,
    *,
    memory: Union[int, str] = "1G",
    camera: str = "auto",
    robust: bool = True,
    progress: Optional[Progress] = ...,
    **settings: Any,
) -> Reconstruction: ...
def to_pycolmap(rec: Reconstruction, directory: PathLike) -> Any: ...
