"""Frames of a KITTI raw drive (``RAW_ROOT/DATE/DATE_drive_NNNN_sync``), straight from its own files.

A drive folder holds ``image_0X/data/NNNNNNNNNN.png`` (rectified camera X), ``velodyne_points/data/NNNNNNNNNN.bin``
(one Velodyne revolution per frame, LiDAR frame, metres) and ``oxts/data/NNNNNNNNNN.txt``; the calibration
(``calib_cam_to_cam.txt``, ``calib_velo_to_cam.txt``) sits in the date folder, the drive's parent.

    >>> drive = RawDrive("kitti_raw/2011_09_26/2011_09_26_drive_0035_sync", camera=2)   # doctest: +SKIP
    >>> for frame in drive.select("0-10"):                                              # doctest: +SKIP
    ...     frame.name, frame.image.shape, frame.points.shape, frame.calib.K
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from semattnet.data.io import DataError, read_image

if TYPE_CHECKING:  # a run-time import would be a cycle
    from semattnet.geometry.calibration import RigCalibration

__all__ = ["MAX_FRAME_INDEX", "FrameRangeError", "RawDrive", "RawFrame", "parse_frames", "scan_periods"]


@dataclass(frozen=True)
class RawFrame:
    """One synchronised frame: ``image`` (H, W, 3) uint8 from camera ``calib.camera``, ``points`` (N, 4) float32
    (x, y, z metres in the LiDAR frame, reflectance; deskewed when the drive was opened with ``deskew=True``),
    ``calib`` the LiDAR -> camera calibration, ``name`` the file stem ("0000000005") and the source paths."""

    name: str
    index: int
    image: np.ndarray
    points: np.ndarray
    calib: RigCalibration  # imported for the type checker only (a run-time import would be a cycle)
    image_path: Path
    scan_path: Path


#: Largest frame index :func:`parse_frames` accepts without a drive to bound it (KITTI drives: < 5200).
MAX_FRAME_INDEX = 10_000_000


def parse_frames(spec: str | int | Sequence[int] | None, limit: int | None = None) -> list[int] | None:
    """Frame indices from ``"a-b"`` (inclusive), ``"1,3,5"``, ``"5"``, an int or a list; None stays None (all).

    ``limit``: indices must be below it (a drive's largest frame index + 1; default
    :data:`MAX_FRAME_INDEX`), checked on a range's ends before it is expanded.
    """
    if spec is None:
        return None
    if isinstance(spec, int):
        return _bounded([spec], limit, spec)
    if not isinstance(spec, str):
        return _bounded([int(i) for i in spec], limit, spec)
    spans: list[tuple[int, int]] = []
    try:
        for part in (p.strip() for p in spec.split(",") if p.strip()):
            a, b = (int(v) for v in part.split("-", 1)) if "-" in part else (int(part), int(part))
            if b < a:
                raise ValueError  # caught below: reported as the DataError of a bad spec
            spans.append((a, b))
    except ValueError:
        raise DataError(
            f"frames (--frames): expected a range a-b or a comma list, e.g. 0-10 or 1,3,5; got {spec!r}"
        ) from None
    if not spans or min(a for a, _ in spans) < 0:
        raise DataError(f"frames (--frames): no valid (non-negative) index in {spec!r}")
    _bounded([b for _, b in spans], limit, spec)  # before any range is expanded
    return [i for a, b in spans for i in range(a, b + 1)]


class FrameRangeError(DataError):
    """A frame index beyond the bound :func:`parse_frames` was given (``index``: the largest asked for)."""

    def __init__(self, message: str, index: int) -> None:
        super().__init__(message)
        self.index = index


def _bounded(indices: list[int], limit: int | None, spec: object) -> list[int]:
    top = MAX_FRAME_INDEX if limit is None else limit
    if indices and max(indices) >= top:
        what = "the drive's frame count" if limit is not None else "MAX_FRAME_INDEX"
        raise FrameRangeError(
            f"frames: index {max(indices)} in {str(spec)[:40]!r} is beyond {what} ({top})", max(indices)
        )
    return indices


def _seconds(stamp: str) -> float:
    """Seconds of the day of a KITTI timestamp ``YYYY-MM-DD hh:mm:ss.fffffffff``."""
    hh, mm, ss = stamp.split()[1].split(":")
    return int(hh) * 3600 + int(mm) * 60 + float(ss)


def scan_periods(drive_dir: str | os.PathLike[str]) -> list[float] | None:
    """Seconds per revolution of each scan (``timestamps_end - timestamps_start`` in ``velodyne_points/``), or
    None when the drive lacks those files (or they are malformed)."""
    folder = Path(drive_dir) / "velodyne_points"
    try:
        starts = (folder / "timestamps_start.txt").read_text().split("\n")
        ends = (folder / "timestamps_end.txt").read_text().split("\n")
        return [_seconds(e) - _seconds(s) for s, e in zip(starts, ends, strict=False) if s.strip() and e.strip()]
    except (OSError, ValueError, IndexError):
        return None


class RawDrive:
    """A KITTI raw drive read frame by frame for one colour camera.

    Args:
        drive_dir: the ``DATE_drive_NNNN_sync`` folder; its parent holds the calibration files.
        camera: 0..3 (or "02"); KITTI's colour cameras are 2 (left) and 3 (right).
        deskew: compensate each scan for the vehicle's motion with its OXTS packet (see
            :func:`semattnet.geometry.deskew_scan`), as KITTI's official ``velodyne_raw`` maps are; the scan period
            comes from ``velodyne_points/timestamps_{start,end}.txt`` when present, else 0.1 s.

    Raises:
        DataError: the folder, the camera's images, the scans or the calibration are missing.
    """

    def __init__(self, drive_dir: str | os.PathLike[str], camera: str | int = 2, deskew: bool = False) -> None:
        from semattnet.geometry import read_kitti_calibration

        self.drive_dir = Path(drive_dir)
        if not self.drive_dir.is_dir():
            raise DataError(f"{self.drive_dir}: KITTI raw drive folder not found")
        self.camera = f"{int(camera):02d}" if str(camera).isdigit() else str(camera)
        self.image_dir = self.drive_dir / f"image_{self.camera}" / "data"
        self.scan_dir = self.drive_dir / "velodyne_points" / "data"
        self.oxts_dir = self.drive_dir / "oxts" / "data"
        for folder in (self.image_dir, self.scan_dir):
            if not folder.is_dir():
                raise DataError(f"{folder}: not found (is {self.drive_dir} a KITTI raw *_sync drive folder?)")
        self.deskew = deskew
        self.periods = scan_periods(self.drive_dir) if deskew else None
        self.calib = read_kitti_calibration(self.drive_dir.parent, self.camera)
        scans = {p.stem for p in self.scan_dir.glob("*.bin")}
        self.names = sorted(p.stem for p in self.image_dir.glob("*.png") if p.stem in scans)
        if not self.names:
            raise DataError(f"{self.drive_dir}: no frame has both an image in {self.image_dir} and a scan")

    def __len__(self) -> int:
        return len(self.names)

    def __iter__(self) -> Iterator[RawFrame]:
        return (self.frame(name) for name in self.names)

    def names_for(self, frames: str | int | Sequence[int] | None = None) -> list[str]:
        """The frame names for indices (see :func:`parse_frames`; None: every frame with an image and a scan).

        Raises:
            DataError: an index with no image or no scan (the message lists what the drive has).
        """
        if frames is None:
            return list(self.names)
        by_index = self._by_index()
        try:
            indices = parse_frames(frames, max(by_index, default=-1) + 1)
            missing = [i for i in indices if i not in by_index] if indices is not None else []
        except FrameRangeError as exc:
            indices, missing = [], [exc.index]
        if indices is None:
            return list(self.names)
        if missing:
            have = f"{self.names[0]}..{self.names[-1]}" if len(self.names) > 1 else self.names[0]
            missed = ", ".join(map(str, missing[:5]))
            raise DataError(
                f"{self.drive_dir}: no image_{self.camera} image and scan for frame(s) {missed}; "
                f"it has {len(self.names)} frame(s), {have}"
            )
        return [by_index[i] for i in indices]

    def _by_index(self) -> dict[int, str]:
        """Frame number -> name; a name that is not a number, or two names of one number (``1``, ``01``),
        refused naming the files (``--frames`` would pick one of them silently)."""
        from semattnet.data.frames import DuplicateFrameError

        by_index: dict[int, str] = {}
        for name in self.names:
            if not (name.isascii() and name.isdigit()):
                raise DataError(
                    f"{self.image_dir / name}.png: not a frame number (KITTI raw frames are numbered, "
                    "0000000000.png ...); --frames selects by number"
                )
            if int(name) in by_index:
                raise DuplicateFrameError(
                    f"{self.image_dir}: {by_index[int(name)]}.png and {name}.png are both frame {int(name)}; rename one"
                )
            by_index[int(name)] = name
        return by_index

    def select(self, frames: str | int | Sequence[int] | None = None) -> Iterator[RawFrame]:
        """The frames for ``frames`` (validated before the first is read)."""
        names = self.names_for(frames)
        return (self.frame(name) for name in names)

    def frame(self, name: str) -> RawFrame:
        """Read one frame by file stem; checks that the image has the calibration's size."""
        from semattnet.geometry import deskew_scan, read_oxts_motion, read_points
        from semattnet.geometry.scan import DEFAULT_SCAN_PERIOD

        image_path, scan_path = self.image_dir / f"{name}.png", self.scan_dir / f"{name}.bin"
        image, points = read_image(image_path), read_points(scan_path)
        if self.calib.image_size is not None and image.shape[:2] != self.calib.image_size[::-1]:
            w, h = self.calib.image_size
            raise DataError(
                f"{image_path}: image is {image.shape[1]}x{image.shape[0]}, "
                f"the calibration says {w}x{h} for camera {self.camera}"
            )
        if self.deskew:
            motion = read_oxts_motion(self.oxts_dir / f"{name}.txt")
            i, period = int(name), DEFAULT_SCAN_PERIOD
            if self.periods is not None and i < len(self.periods) and 0.05 < self.periods[i] < 0.2:
                period = self.periods[i]
            points = deskew_scan(points, motion.velocity, motion.yaw_rate, period)
        return RawFrame(name, int(name), image, points, self.calib, image_path, scan_path)
