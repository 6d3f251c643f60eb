"""Calibration frames of the int8 engine: what NNCF's post-training quantisation measures ranges on.

A calibration is given to ``optimize_for_inference(..., precision="int8", calibration=...)`` as

* ``None`` (the default): :data:`DEFAULT_CALIBRATION_FRAMES` synthetic scenes
  (:func:`semattnet.synthetic.make_frame`, seeds 0, 1, ...) at the engine's size;
* a :class:`~semattnet.data.frames.FrameSource` (``semattnet.data.sources``: a folder, a KITTI split,
  a raw drive), or any sequence of :class:`~semattnet.data.frames.Frame`;
* a folder path: ``rgb/`` + ``sparse/`` (+ ``semantic/``) subfolders paired by name
  (:class:`~semattnet.data.sources.FolderSource`), else a KITTI (or ``semattnet synth``) root whose
  ``val_select`` split is used (:class:`~semattnet.data.sources.KittiSplitSource`).

Frames are cropped to the engine's size as KITTI's evaluation crop does (bottom rows, centred
columns; zero-padded at the top when smaller); a frame without a semantic map gets the
``unknown`` fallback map (:func:`semattnet.palette.unknown_map`). The cache key of a
calibration is its description for synthetic scenes (they are a function of the seed and the
library version, which the engine key holds) and the sha256 of the frames' arrays otherwise.

Calibration frames that cannot be used (not a folder, no frames, a corrupt file, a frame without a
LiDAR point) are a :class:`CalibrationError`: the run's fault, never taken for a fault of the frames
being completed (``predict --calibration`` checks them before any work).
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Protocol, TypeAlias, TypeGuard

import numpy as np

from semattnet._errors import DataError, InputError, MissingDependencyError

if TYPE_CHECKING:
    from semattnet.data.frames import FrameSource

__all__ = [
    "DEFAULT_CALIBRATION_FRAMES",
    "Calibration",
    "CalibrationError",
    "CalibrationFrames",
    "calibration_frames",
    "fit_to_size",
    "resolve_calibration",
]


class CalibrationError(InputError):
    """The calibration frames cannot be used (not a folder, no frames, a corrupt file, no LiDAR point): the
    run's fault, never one frame's (:func:`semattnet.inference.feed.is_frame_fault`)."""


class CalibrationFrame(Protocol):
    """What a calibration frame gives (a :class:`~semattnet.data.frames.Frame` does)."""

    @property
    def rgb(self) -> np.ndarray: ...

    @property
    def semantic(self) -> np.ndarray | None: ...

    @property
    def sparse(self) -> np.ndarray: ...


#: What int8 calibrates on: a folder (``rgb/`` + ``sparse/``, or a KITTI root), a FrameSource, Frames, or None
#: (synthetic scenes).
CalibrationFrames: TypeAlias = "str | os.PathLike[str] | FrameSource | Sequence[CalibrationFrame] | None"


def _is_frame(f: object) -> TypeGuard[CalibrationFrame]:
    return hasattr(f, "rgb") and hasattr(f, "sparse")


#: Synthetic scenes calibrated on when the user gives no frames (and the most frames used from a source).
DEFAULT_CALIBRATION_FRAMES = 8


def fit_to_size(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """(H, W, ...) -> (h, w, ...) of ``size``: the bottom rows and centred columns, zeros above when smaller."""
    h, w = size
    rows, cols = image.shape[:2]
    left = max(0, (cols - w) // 2)
    crop = image[max(0, rows - h) :, left : left + w]
    out = np.zeros((h, w, *image.shape[2:]), dtype=image.dtype)
    out[h - crop.shape[0] :, : crop.shape[1]] = crop
    return out


def _feed(
    rgb: np.ndarray, semantic: np.ndarray | None, sparse: np.ndarray, size: tuple[int, int]
) -> dict[str, np.ndarray]:
    """One frame as the graph's named (1, C, H, W) float32 inputs (colours 0..255, sparse metres)."""
    from semattnet.palette import unknown_map

    semantic = unknown_map(*rgb.shape[:2]) if semantic is None else semantic

    def chw(a: np.ndarray) -> np.ndarray:
        a = fit_to_size(np.asarray(a), size).astype(np.float32)
        return np.ascontiguousarray((a[..., None] if a.ndim == 2 else a).transpose(2, 0, 1)[None])

    return {"rgb": chw(rgb), "semantic": chw(semantic), "sparse": chw(sparse)}


@dataclass
class Calibration:
    """The calibration frames of one engine: a cache ``key`` and the named inputs, made when needed."""

    key: str
    description: str
    _make: Callable[[], list[dict[str, np.ndarray]]] = field(repr=False)
    _feeds: list[dict[str, np.ndarray]] | None = field(default=None, repr=False)

    def feeds(self) -> list[dict[str, np.ndarray]]:
        """Every calibration frame as the graph's named float32 inputs."""
        if self._feeds is None:
            self._feeds = self._make()
        return self._feeds


def _synthetic(size: tuple[int, int], count: int) -> Calibration:
    def make() -> list[dict[str, np.ndarray]]:
        from semattnet.synthetic import make_frame

        frames = (make_frame(size[0], size[1], seed=s) for s in range(count))
        return [_feed(f.rgb, f.semantic, f.sparse, size) for f in frames]

    what = f"synthetic scenes, seeds 0..{count - 1}, {size[0]}x{size[1]}"
    return Calibration(hashlib.sha256(what.encode()).hexdigest()[:16], what, make)


def _from_frames(frames: Sequence[CalibrationFrame], size: tuple[int, int], what: str) -> Calibration:
    feeds = [_feed(f.rgb, f.semantic, f.sparse, size) for f in frames]
    digest = hashlib.sha256()
    for feed in feeds:
        for name in sorted(feed):
            digest.update(name.encode() + feed[name].tobytes())
    return Calibration(digest.hexdigest()[:16], f"{len(feeds)} frames of {what}", lambda: feeds, feeds)


def _source_of_folder(path: Path) -> FrameSource:
    from semattnet.data.datasets.frames import MissingSplitError
    from semattnet.data.sources import FolderSource, KittiSplitSource

    if not path.is_dir():
        raise CalibrationError(
            f"calibration: {path} is not a folder (expected rgb/ + sparse/ subfolders or a KITTI root)"
        )
    if (path / "rgb").is_dir() and (path / "sparse").is_dir():
        semantic = path / "semantic" if (path / "semantic").is_dir() else None
        return FolderSource.pair(path / "rgb", path / "sparse", semantic)
    try:
        return KittiSplitSource(path, "val_select")
    except MissingSplitError:
        raise CalibrationError(
            f"calibration: {path}: neither rgb/ + sparse/ subfolders nor a KITTI root with val_select frames"
        ) from None


def _checked(frames: Sequence[CalibrationFrame], what: str) -> list[CalibrationFrame]:
    """``frames``, refused when there are none or one has no LiDAR point (it would calibrate nothing)."""
    if not frames:
        raise CalibrationError(f"calibration: {what} holds no frames; give at least one (or None for synthetic scenes)")
    for i, f in enumerate(frames):
        if not np.any(np.asarray(f.sparse) > 0):
            name = getattr(f, "name", f"frame {i}")
            raise CalibrationError(
                f"calibration: {what}: {name} has no LiDAR point (an empty sparse map calibrates nothing)"
            )
    return list(frames)


def calibration_frames(
    calibration: CalibrationFrames, count: int = DEFAULT_CALIBRATION_FRAMES
) -> tuple[list[CalibrationFrame], str]:
    """The first ``count`` frames of ``calibration`` (not ``None``: a folder, a FrameSource or Frames) and what
    they are, read and checked: any problem is a :class:`CalibrationError` naming the folder or file."""
    if isinstance(calibration, Sequence) and not isinstance(calibration, str):
        if not all(_is_frame(f) for f in calibration):
            raise CalibrationError("calibration: expected Frames (with .rgb and .sparse) in the sequence")
        return _checked(list(calibration)[:count], "the given frames"), "the given frames"
    if calibration is None or (not isinstance(calibration, str | os.PathLike) and not hasattr(calibration, "load")):
        raise CalibrationError(
            "calibration: expected None, a FrameSource, a sequence of Frames or a folder path, "
            f"got {type(calibration).__name__}"
        )
    try:
        if isinstance(calibration, str | os.PathLike):
            calibration, what = _source_of_folder(Path(calibration)), str(calibration)
        else:
            what = type(calibration).__name__
        frames = [calibration.load(n) for n in list(calibration.names)[:count]]
    except (DataError, InputError) as exc:  # a missing split, a corrupt PNG: the calibration's, not a frame's
        if isinstance(exc, CalibrationError | MissingDependencyError):
            raise
        raise CalibrationError(f"calibration: {' '.join(str(exc).split())}") from None
    return _checked(frames, what), what


def anchored(calibration: Calibration) -> Calibration:
    """``calibration`` as a generalist's network reads it (:func:`semattnet.models.generalist.prepare_inputs`:
    standardised colours, the sparse points and the anchor as two normalised channels)."""

    def make() -> list[dict[str, np.ndarray]]:
        import torch

        from semattnet.models.generalist import prepare_inputs

        out = []
        for feed in calibration.feeds():
            prepared = prepare_inputs(torch.from_numpy(feed["rgb"]), torch.from_numpy(feed["sparse"]))
            out.append(feed | {"rgb": prepared.rgb.numpy(), "sparse": prepared.depth.numpy()})
        return out

    return Calibration(f"{calibration.key}-anchored", f"{calibration.description}, anchored", make)


def resolve_calibration(
    calibration: CalibrationFrames, size: tuple[int, int], count: int = DEFAULT_CALIBRATION_FRAMES
) -> Calibration:
    """The :class:`Calibration` of what the user gave (module docstring); at most ``count`` frames."""
    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        raise InputError(f"calibration_frames: expected a whole number >= 1, got {count!r}")
    if calibration is None:
        return _synthetic(size, count)
    frames, what = calibration_frames(calibration, count)
    return _from_frames(frames, size, what)
