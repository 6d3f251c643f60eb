"""One frame to complete, whatever it came from, and the protocol every source of frames follows.

A :class:`Frame` is what every completer and every output sink sees: the image, the sparse depth map
(already projected: a source that reads LiDAR scans projects them itself) and what else the source
knows. A :class:`FrameSource` lists its frames by name, loads one by name, and checks every input
before any work (so that a corrupt file fails the run before a model is loaded and before anything is
written). The sources of :mod:`semattnet.data.sources` (a folder of files, a KITTI depth-completion
split, a KITTI raw drive) implement it; a new dataset or recording format (a ROS bag, NYU v2, VOID)
plugs into :func:`semattnet.inference.pipeline.complete_frames` by implementing it too, most simply by
subclassing :class:`IndexedSource` and writing ``names``, ``load`` and ``inputs``.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Protocol, TypeVar, runtime_checkable

import numpy as np

from semattnet._errors import DataError
from semattnet.geometry.calibration import RigCalibration
from semattnet.geometry.cameras import CameraInfoData

__all__ = [
    "Dropped",
    "DuplicateFrameError",
    "Frame",
    "FrameSource",
    "IndexedSource",
    "LiveSource",
    "SensorMeta",
    "SourceInfo",
    "TwoStageSource",
    "View",
    "ViewSource",
    "sensor_frame",
    "unique_names",
]

_T = TypeVar("_T")
_R = TypeVar("_R")


@dataclass(frozen=True)
class SensorMeta:
    """What a recording says about a frame beyond its images, that the robot sinks write back (a bag frame's
    header stamp and frame ids, its CameraInfo); every field is optional (the defaults: the source does not say).

    Attributes:
        stamp_ns: the image's header stamp, integer nanoseconds, or None.
        frame_id: the camera's optical frame id (``""``: unknown).
        lidar_frame_id: the LiDAR's frame id (``""``: unknown).
        scan_stamp_ns: the paired scan's header stamp, integer nanoseconds, or None.
        camera_info: the camera's ``CameraInfo`` (:class:`~semattnet.geometry.cameras.CameraInfoData`), or None.
        dropped_points: scan points left out for a NaN or infinite coordinate.
    """

    stamp_ns: int | None = None
    frame_id: str = ""
    lidar_frame_id: str = ""
    scan_stamp_ns: int | None = None
    camera_info: CameraInfoData | None = None
    dropped_points: int = 0


@dataclass(frozen=True)
class View:
    """Another calibrated image of a frame's scene: a stereo partner, or a neighbouring frame of a recording with
    the camera's motion (what the photometric loss of ``semattnet adapt`` warps into the frame's camera).

    Attributes:
        name: what it is (``image_03``, ``prev``, ...).
        rgb: (h, w, 3) uint8 image (its size may differ from the frame's).
        K: (3, 3) its intrinsics, pixels.
        T_view_cam: (4, 4) the frame's camera -> this view's camera, metres (a rectified stereo pair: the baseline).
    """

    name: str
    rgb: np.ndarray
    K: np.ndarray
    T_view_cam: np.ndarray

    def __post_init__(self) -> None:
        if self.rgb.ndim != 3 or self.rgb.shape[2] != 3:
            raise DataError(f"view {self.name}: the image must be (h, w, 3), got {self.rgb.shape}")
        if np.shape(self.K) != (3, 3) or np.shape(self.T_view_cam) != (4, 4):
            raise DataError(
                f"view {self.name}: K must be 3x3 and T_view_cam 4x4, got {np.shape(self.K)} and "
                f"{np.shape(self.T_view_cam)}"
            )


@dataclass(frozen=True)
class Frame:
    """One frame.

    Attributes:
        name: the frame's name (output files are named after it).
        rgb: (H, W, 3) uint8 image.
        sparse: (H, W) float32 sparse depth, metres, 0 = no measurement.
        semantic: (H, W, 3) uint8 colour-coded semantic map (Cityscapes palette), or None.
        K: (3, 3) intrinsics of the image, pixels, or None when the source does not know them.
        timestamp: seconds (the source's clock), or None.
        points: (N, 3|4) LiDAR points the sparse map was projected from (LiDAR frame, metres), or None.
        calib: the calibration that projected them, or None.
        gt: (H, W) float32 ground-truth depth in metres (0 = none), or None.
        paths: the files it was read from, by role (``rgb``, ``sparse``, ``semantic``, ``gt``, ``scan``, ...).
        meta: what else the recording says (a bag frame's header stamp, frame ids, CameraInfo:
            :class:`SensorMeta`); all defaults for sources that know nothing more.
        views: other calibrated images of the scene (:class:`View`), given by a :class:`ViewSource` on request
            (``semattnet adapt``); empty otherwise.
    """

    name: str
    rgb: np.ndarray
    sparse: np.ndarray
    semantic: np.ndarray | None = None
    K: np.ndarray | None = None
    timestamp: float | None = None
    points: np.ndarray | None = None
    calib: RigCalibration | None = None
    gt: np.ndarray | None = None
    paths: Mapping[str, Path] = field(default_factory=dict)
    meta: SensorMeta = field(default_factory=SensorMeta)
    views: tuple[View, ...] = ()

    def __post_init__(self) -> None:
        where = self.paths.get("rgb", self.name)
        if self.rgb.ndim != 3 or self.rgb.shape[2] != 3:
            raise DataError(f"{where}: the image must be (H, W, 3), got {self.rgb.shape}")
        h, w = self.rgb.shape[:2]
        for role, a in (("sparse", self.sparse), ("gt", self.gt), ("semantic", self.semantic)):
            if a is not None and a.shape[:2] != (h, w):
                raise DataError(
                    f"{self.paths.get(role, self.name)}: {role} is {a.shape[1]}x{a.shape[0]}, the image {w}x{h}"
                )

    @property
    def size(self) -> tuple[int, int]:
        """(H, W)."""
        return self.rgb.shape[0], self.rgb.shape[1]

    def with_semantic(self, semantic: np.ndarray | None) -> Frame:
        """A copy with another semantic map."""
        return replace(self, semantic=semantic)


@dataclass(frozen=True)
class SourceInfo:
    """What a source says about its frames beyond loading them (:attr:`FrameSource.info`).

    Attributes:
        palette: the palette of the semantic maps its frames carry (None: they carry none).
        stamps_ns: every frame's sensor stamp, integer nanoseconds, in the order of ``names`` (None: unknown):
            the sensor period of a run, from every frame and not only those done.
        prediction_names: frame name -> the file name of its prediction where the source names it (KITTI's
            ``val_select``: the ground truth's name); other frames: ``NAME.png`` (:meth:`prediction_name`).
        listed_files: the files the source's lists name (which may lie anywhere): an output must not replace one.
    """

    palette: str | None = None
    stamps_ns: Sequence[int] | None = None
    prediction_names: Mapping[str, str] = field(default_factory=dict)
    listed_files: Sequence[Path] = ()

    def prediction_name(self, name: str) -> str:
        """The file name of frame ``name``'s prediction."""
        return self.prediction_names.get(name, f"{name}.png")


@runtime_checkable
class FrameSource(Protocol):
    """Frames by name: ``names`` (in order), ``len()``, iteration (yields :class:`Frame`), ``load(name)``,
    ``check(names)`` (decode and validate those inputs, raising :class:`DataError` naming the file),
    ``inputs()`` (the files and folders that outputs must never land in or replace) and ``info``
    (:class:`SourceInfo`: what else it says about its frames)."""

    @property
    def names(self) -> Sequence[str]: ...

    @property
    def info(self) -> SourceInfo: ...

    def __len__(self) -> int: ...

    def __iter__(self) -> Iterator[Frame]: ...

    def load(self, name: str) -> Frame: ...

    def check(self, names: Sequence[str] | None = None) -> None: ...

    def inputs(self) -> list[Path]: ...


@runtime_checkable
class TwoStageSource(FrameSource, Protocol[_R]):
    """A source whose ``load`` is two stages that the frame loop times apart: ``read(name)`` (the raw inputs,
    decoded) then ``assemble(raw)`` (the :class:`Frame`, its scan projected into the image), as
    :class:`semattnet.robotics.BagSource` does; ``load(name)`` is ``assemble(read(name))``."""

    def read(self, name: str) -> _R: ...

    def assemble(self, raw: _R) -> Frame: ...


@dataclass(frozen=True)
class Dropped:
    """An item of a :class:`LiveSource` that a newer one replaced before the loop took it: its frame ``name`` and
    why."""

    name: str
    reason: str


class LiveSource(Protocol[_R]):
    """Frames a sensor pushes, as a live node receives them: no names ahead, the newest item waits and a newer one
    replaces it. The frame loop takes what came (:func:`semattnet.inference.feed.live_completions`).

    ``take(timeout)``: the next note that an item was replaced before the loop took it (:class:`Dropped`, in
    order), else the newest item; None when nothing came within ``timeout`` seconds. ``name(raw)``: the item's frame
    name. ``assemble(raw)``: its :class:`Frame` (the scan projected: :func:`sensor_frame`; timed as the loop's
    ``projection``)."""

    def take(self, timeout: float) -> _R | Dropped | None: ...

    def name(self, raw: _R) -> str: ...

    def assemble(self, raw: _R) -> Frame: ...


@runtime_checkable
class ViewSource(Protocol):
    """A source that can also give a frame's other calibrated views (:class:`View`: a stereo partner, neighbouring
    frames), read only when asked: ``views(name)`` (empty when it has none for that frame)."""

    def views(self, name: str) -> tuple[View, ...]: ...


class IndexedSource:
    """Base of sources with random access by name: subclasses set ``names`` and write ``load`` and
    ``inputs``; ``check`` loads every frame (override it when a cheaper full validation exists).
    ``palette``: the palette of the semantic maps its frames carry (None: it gives none); ``info``: that
    palette, and what a subclass adds (:class:`SourceInfo`)."""

    names: Sequence[str] = ()
    palette: str | None = None

    @property
    def info(self) -> SourceInfo:
        return SourceInfo(self.palette)

    def __len__(self) -> int:
        return len(self.names)

    def __iter__(self) -> Iterator[Frame]:
        return (self.load(name) for name in self.names)

    def load(self, name: str) -> Frame:
        raise NotImplementedError

    def check(self, names: Sequence[str] | None = None) -> None:
        """Decode every input of ``names`` (default: all), raising :class:`DataError` naming the file."""
        for name in self.names if names is None else names:
            self.load(name)

    def inputs(self) -> list[Path]:
        raise NotImplementedError


class DuplicateFrameError(DataError):
    """Two inputs whose frames would get the same name (and so the same output files)."""


def unique_names(items: Iterable[tuple[str, _T]], where: object) -> dict[str, _T]:
    """``{name: item}`` of ``(name, item)`` pairs, in order, when no two share a name: a frame never
    silently replaces another (nor its outputs).

    Raises:
        DuplicateFrameError: one line naming ``where``, the name and both items (their input files).
    """
    out: dict[str, _T] = {}
    for name, item in items:
        if name in out:
            raise DuplicateFrameError(
                f"{where}: {out[name]} and {item} both make the frame name {name!r}; "
                "rename one (each frame's outputs are named after it)"
            )
        out[name] = item
    return out


def sensor_frame(
    name: str,
    image: np.ndarray,
    meta: SensorMeta,
    calib: RigCalibration,
    *,
    points: np.ndarray | None = None,
    sparse: np.ndarray | None = None,
    where: str = "",
    semantic: np.ndarray | None = None,
    paths: Mapping[str, Path] | None = None,
) -> Frame:
    """The frame of one camera image and its scan from a sensor stream (a bag, a live node): the scan's ``points``
    (LiDAR frame, metres) projected into the image by ``calib`` (:func:`~semattnet.geometry.project_points`), or a
    ``sparse`` depth image of the image's size as it is; ``where`` names the scan in errors.

    Raises:
        DataError: a sparse depth image of another size than the image, or no point of the scan in front of the
            camera and inside the image (the projection's error, naming ``where``).
    """
    h, w = image.shape[:2]
    if points is not None:
        from semattnet.geometry import project_points

        sparse = project_points(points, calib.K, calib.T_cam_lidar, (w, h), name=where)
    elif sparse is None or sparse.shape != (h, w):
        got = "none" if sparse is None else f"{sparse.shape[1]}x{sparse.shape[0]}"
        raise DataError(f"{where}: the sparse depth is {got}, the image {w}x{h}")
    stamp = None if meta.stamp_ns is None else meta.stamp_ns / 1e9
    K = np.asarray(calib.K, np.float64)
    return Frame(
        name,
        image,
        sparse,
        semantic,
        K=K,
        timestamp=stamp,
        points=points,
        calib=calib,
        paths=dict(paths or {}),
        meta=meta,
    )
