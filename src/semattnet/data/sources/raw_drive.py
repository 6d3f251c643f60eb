"""A KITTI raw drive as frames: each scan projected into the camera here, in the data layer."""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np

from semattnet._errors import DataError
from semattnet._utils.registry import option
from semattnet.data.frames import Frame, IndexedSource, View
from semattnet.data.io import read_image, read_semantic
from semattnet.data.kitti.raw import RawDrive, RawFrame
from semattnet.data.sources.registry import SourceOptions, register_source

__all__ = ["RawDriveOptions", "RawDriveSource", "project_frame"]


def project_frame(frame: RawFrame) -> np.ndarray:
    """(H, W) float32 sparse depth of a raw frame's scan in its camera (metres, 0 = none), by
    :func:`semattnet.geometry.project_points` (pixel centres at integer coordinates)."""
    from semattnet.geometry import project_points

    size = frame.calib.image_size
    if size is None:  # a raw drive's calibration always has S_rect; say which file lacks it if not
        raise DataError(f"{frame.scan_path}: the drive's calibration gives no image size (S_rect_0X)")
    depth: np.ndarray = project_points(
        frame.points, frame.calib.K, frame.calib.T_cam_lidar, size, name=str(frame.scan_path)
    )
    return depth


@dataclass(frozen=True)
class RawDriveOptions(SourceOptions):
    """``--kitti-raw``: a KITTI raw drive (images, Velodyne scans, calibration, OXTS)."""

    heading: ClassVar[str] = "Inputs: KITTI raw drive"
    usage: ClassVar[str] = "--kitti-raw"
    selects: ClassVar[tuple[str, ...]] = ("kitti_raw",)
    accepts: ClassVar[tuple[str, ...]] = ("semantic", "segment_spec")
    recording: ClassVar[bool] = True

    kitti_raw: Path | None = option(
        "--kitti-raw",
        type="folder",
        help="A KITTI raw drive folder RAW_ROOT/DATE/DATE_drive_NNNN_sync (instead of --rgb/--sparse).",
    )
    frames: str | None = option("--frames", help="Indices, a range a-b or a comma list (default all).")
    camera: str = option(
        "--camera",
        type="choice",
        choices=("2", "3"),
        default="2",
        show_default=True,
        help="The colour camera: image_02 or image_03.",
    )
    deskew: bool = option("--deskew", type="flag", help="Ego-motion compensate the scans with their OXTS data.")

    def source(self, semantic: Path | None, log: Callable[[str], None]) -> RawDriveSource:
        assert self.kitti_raw is not None  # it chose this input
        return RawDriveSource(self.kitti_raw, self.frames, self.camera, semantic, self.deskew)


@register_source("kitti-raw", option="--kitti-raw", options=RawDriveOptions)
class RawDriveSource(IndexedSource):
    """The frames ``frames`` (see :func:`semattnet.data.kitti.raw.parse_frames`) of a KITTI raw drive
    (:class:`~semattnet.data.kitti.raw.RawDrive`: ``camera``, ``deskew``), with the points and calibration
    each sparse map was projected from. ``semantic``: a folder of colour-coded maps named like the images.

    Raises:
        DataError: missing drive files, frames or semantic folder (naming them).
    """

    def __init__(
        self,
        drive_dir: str | os.PathLike[str],
        frames: str | int | Sequence[int] | None = None,
        camera: str | int = 2,
        semantic: str | os.PathLike[str] | None = None,
        deskew: bool = False,
    ) -> None:
        self.drive = RawDrive(drive_dir, camera, deskew=deskew)
        self.names = self.drive.names_for(frames)
        self.semantic_dir = Path(semantic) if semantic is not None else None
        if self.semantic_dir is not None and not self.semantic_dir.is_dir():
            raise DataError(f"{self.semantic_dir}: semantic folder not found")

    def load(self, name: str) -> Frame:
        raw = self.drive.frame(name)
        sem_path = self.semantic_dir / f"{name}.png" if self.semantic_dir is not None else None
        sem = read_semantic(sem_path) if sem_path is not None else None
        paths = {"rgb": raw.image_path, "scan": raw.scan_path} | ({"semantic": sem_path} if sem_path else {})
        return Frame(
            name, raw.image, project_frame(raw), sem, K=raw.calib.K, points=raw.points, calib=raw.calib, paths=paths
        )

    def views(self, name: str) -> tuple[View, ...]:
        """Frame ``name``'s other views: its stereo partner (camera 03 for 02 and back; ``T_view_cam`` the rectified
        baseline from the calibration's ``P_rect_02`` / ``P_rect_03``) and the same camera's previous and next frames
        (``T_view_cam`` from the OXTS poses, :func:`semattnet.geometry.motion.read_oxts_pose`, and
        ``calib_imu_to_velo.txt``), each where the drive has its files.

        Raises:
            DataError: an image unreadable or not of its calibrated size, a malformed OXTS packet (naming the file).
        """
        partner = {"02": "03", "03": "02"}.get(self.drive.camera)
        stereo = self._partner(name, partner) if partner is not None else None
        return tuple(v for v in (stereo, *(self._neighbour(name, step) for step in (-1, 1))) if v is not None)

    def _image(self, path: Path, size: tuple[int, int] | None, camera: str) -> np.ndarray:
        image = read_image(path)
        if size is not None and image.shape[:2] != size[::-1]:
            raise DataError(
                f"{path}: image is {image.shape[1]}x{image.shape[0]}, the calibration says "
                f"{size[0]}x{size[1]} for camera {camera}"
            )
        return image

    def _partner(self, name: str, partner: str) -> View | None:
        from semattnet.geometry import invert_T, read_kitti_calibration

        path = self.drive.drive_dir / f"image_{partner}" / "data" / f"{name}.png"
        if not path.is_file():
            return None
        calib = read_kitti_calibration(self.drive.drive_dir.parent, partner)
        T_view_cam = calib.T_cam_lidar @ invert_T(self.drive.calib.T_cam_lidar)
        return View(f"image_{partner}", self._image(path, calib.image_size, partner), calib.K, T_view_cam)

    def _neighbour(self, name: str, step: int) -> View | None:
        """The same camera's frame ``step`` away, with the camera's motion from the OXTS poses, when all exist."""
        from semattnet.geometry import invert_T, read_velo_to_cam
        from semattnet.geometry.motion import read_oxts_latitude, read_oxts_pose

        drive = self.drive
        other = f"{int(name) + step:0{len(name)}d}" if name.isdigit() and int(name) + step >= 0 else None
        imu = drive.drive_dir.parent / "calib_imu_to_velo.txt"
        if other is None:
            return None
        needed = (
            drive.image_dir / f"{other}.png",
            imu,
            drive.oxts_dir / f"{name}.txt",
            drive.oxts_dir / f"{other}.txt",
        )
        if not all(p.is_file() for p in needed):
            return None
        here = read_oxts_pose(drive.oxts_dir / f"{name}.txt")
        there = read_oxts_pose(drive.oxts_dir / f"{other}.txt", lat0_deg=read_oxts_latitude(needed[2]))
        T_cam_imu = drive.calib.T_cam_lidar @ read_velo_to_cam(imu)
        T_view_cam = T_cam_imu @ invert_T(there) @ here @ invert_T(T_cam_imu)
        image = self._image(drive.image_dir / f"{other}.png", drive.calib.image_size, drive.camera)
        return View(other, image, drive.calib.K, T_view_cam)

    def inputs(self) -> list[Path]:
        date = self.drive.drive_dir.parent
        calib = [p for p in (date / "calib_cam_to_cam.txt", date / "calib_velo_to_cam.txt") if p.is_file()]
        return [self.drive.drive_dir, *calib, *([self.semantic_dir] if self.semantic_dir is not None else [])]
