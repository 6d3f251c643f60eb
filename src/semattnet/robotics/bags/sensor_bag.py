"""Writing a small bag from camera images and LiDAR scans, e.g. from a KITTI raw drive.

Per frame: the image as ``sensor_msgs/Image`` rgb8 (and optionally ``CompressedImage``), the scan as
``sensor_msgs/PointCloud2`` (x, y, z, intensity float32; optionally some NaN points, so ``is_dense`` is
false), the camera's ``CameraInfo`` (rectified: ``K = P[:, :3]``, no distortion, ``P`` = KITTI's
``P_rect_0X``); once, ``/tf_static`` through an intermediate frame: ``base_link -> velodyne`` and
``base_link -> camera_color_left``, composed so that ``T_cam_base @ T_base_lidar = T_cam_lidar``; per frame with a
pose, ``/tf`` ``odom -> base_link`` (the vehicle's motion, what poses neighbouring frames). KITTI's ``base_link`` is
its IMU (``calib_imu_to_velo.txt``), its ``odom`` the IMU's pose at the first frame written, the poses those of the
OXTS packets (:func:`semattnet.geometry.motion.read_oxts_pose`). Stamps come from the drive's ``timestamps.txt``
files, else frame index x 0.1 s after the drive's date.
"""

from __future__ import annotations

import calendar
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from semattnet._errors import DataError, InputError
from semattnet._utils.bounds import MAX_ADDED_POINTS
from semattnet.geometry import RigCalibration, invert_T, make_T, read_velo_to_cam

from .decode import CameraInfoData
from .encode import camera_info_message, compressed_image_message, image_message, pointcloud2_message, tf_message
from .tf_buffer import TF_TOPIC
from .writer import MessageWriter, bag_format, staged_bag

__all__ = ["BagTopics", "SensorRecord", "WrittenBag", "kitti_stamps_ns", "write_kitti_bag", "write_sensor_bag"]

#: ``base_link -> velodyne`` when a drive has no ``calib_imu_to_velo.txt``: KITTI's mounting height, metres.
DEFAULT_LIDAR_HEIGHT = 1.73


@dataclass(frozen=True)
class BagTopics:
    """Topic and frame names of a written sensor bag (kitti2bag's topic names by default)."""

    image: str = "/kitti/camera_color_left/image_raw"
    camera_info: str = "/kitti/camera_color_left/camera_info"
    points: str = "/kitti/velo/pointcloud"
    tf_static: str = "/tf_static"
    tf: str = TF_TOPIC
    camera_frame: str = "camera_color_left"
    lidar_frame: str = "velodyne"
    base_frame: str = "base_link"
    odom_frame: str = "odom"

    @property
    def compressed(self) -> str:
        """The CompressedImage topic: ``IMAGE/compressed``."""
        return f"{self.image}/compressed"

    @classmethod
    def for_camera(cls, camera: str) -> BagTopics:
        """Names for KITTI camera "02" (left colour) or "03" (right colour); others get ``camera_XX``."""
        side = {"02": "camera_color_left", "03": "camera_color_right"}.get(camera, f"camera_{camera}")
        return cls(f"/kitti/{side}/image_raw", f"/kitti/{side}/camera_info", camera_frame=side)


@dataclass(frozen=True)
class SensorRecord:
    """One frame to write: ``image`` (H, W, 3) uint8, ``points`` (N, 3|4) float32 LiDAR frame (+ intensity),
    the image's and the scan's stamps (ns); ``pose``: (4, 4) ``T_odom_base``, the base's pose at ``pose_stamp_ns``
    (None: the image's stamp), written to ``/tf`` (None: none)."""

    image: np.ndarray
    points: np.ndarray
    image_stamp_ns: int
    scan_stamp_ns: int
    pose: np.ndarray | None = None
    pose_stamp_ns: int | None = None


@dataclass(frozen=True)
class WrittenBag:
    """What was written: the bag ``path``, its ``fmt``, the ``topics`` and message ``counts`` per topic."""

    path: Path
    fmt: str
    topics: BagTopics
    counts: dict[str, int] = field(default_factory=dict)

    def describe(self) -> str:
        counts = ", ".join(f"{t} {n}" for t, n in self.counts.items())
        return f"wrote {self.path} ({self.fmt}): {counts}"


def _camera_info(calib: RigCalibration, frame_id: str) -> CameraInfoData:
    if calib.image_size is None:
        raise DataError(f"{calib.source or 'calibration'}: no image size for the CameraInfo")
    P = calib.P_rect if calib.P_rect is not None else np.hstack([calib.K, np.zeros((3, 1))])
    w, h = calib.image_size
    return CameraInfoData(
        w, h, np.asarray(P)[:, :3].copy(), np.zeros(5), np.eye(3), np.asarray(P, np.float64), "plumb_bob", frame_id
    )


def _with_nans(points: np.ndarray, n: int) -> np.ndarray:
    """``points`` with ``n`` NaN rows spread evenly through them (intensity 0)."""
    if n <= 0:
        return points
    at = np.linspace(0, len(points), n, dtype=np.int64)
    nan = np.zeros((n, points.shape[1]), points.dtype)
    nan[:, :3] = np.nan
    return np.insert(points, at, nan, axis=0)


def write_sensor_bag(
    path: str | os.PathLike[str],
    records: Iterable[SensorRecord],
    calib: RigCalibration,
    *,
    T_base_lidar: np.ndarray | None = None,
    topics: BagTopics | None = None,
    fmt: str | None = None,
    compressed: str | None = None,
    nan_points: int = 0,
    overwrite: bool = False,
) -> WrittenBag:
    """Write ``records`` with ``calib`` (K, T_cam_lidar, image size; ``P_rect`` for the CameraInfo when set) as
    a bag (module doc). ``fmt``: ros1, sqlite3 or mcap (default from the suffix, see ``bag_format``);
    ``compressed``: also a CompressedImage ("png" or "jpeg"); ``nan_points``: NaN points added per scan.

    Raises:
        FileExistsError: ``path`` exists and not ``overwrite``. InputError: a bad record. Nothing is left on error.
    """
    if isinstance(nan_points, bool) or not isinstance(nan_points, int) or not 0 <= nan_points <= MAX_ADDED_POINTS:
        raise InputError(f"nan_points: must be a whole number in 0..{MAX_ADDED_POINTS}, got {nan_points!r}")
    topics = topics or BagTopics()
    fmt = bag_format(path, fmt)
    T_base_lidar = make_T(np.eye(3), np.array([0, 0, DEFAULT_LIDAR_HEIGHT])) if T_base_lidar is None else T_base_lidar
    T_base_cam = np.asarray(T_base_lidar, np.float64) @ invert_T(np.asarray(calib.T_cam_lidar, np.float64))
    info = _camera_info(calib, topics.camera_frame)
    with staged_bag(path, overwrite) as tmp, MessageWriter(tmp, fmt) as out:
        ts = out.ts
        for n, rec in enumerate(records):
            img, pts = np.asarray(rec.image), np.asarray(rec.points, dtype=np.float32)
            if img.shape != (info.height, info.width, 3) or img.dtype != np.uint8:
                raise InputError(
                    f"record {n}: image must be ({info.height}, {info.width}, 3) uint8, got {img.shape} {img.dtype}"
                )
            if pts.ndim != 2 or pts.shape[1] not in (3, 4):
                raise InputError(f"record {n}: points must be (N, 3) or (N, 4), got {pts.shape}")
            if n == 0:
                edges = [
                    (topics.base_frame, topics.lidar_frame, T_base_lidar),
                    (topics.base_frame, topics.camera_frame, T_base_cam),
                ]
                out.write(topics.tf_static, rec.image_stamp_ns, tf_message(ts, edges, rec.image_stamp_ns))
            t_img, t_scan, cam = rec.image_stamp_ns, rec.scan_stamp_ns, topics.camera_frame
            out.write(topics.image, t_img, image_message(ts, img, t_img, cam))
            if compressed:
                out.write(topics.compressed, t_img, compressed_image_message(ts, img, t_img, cam, compressed))
            out.write(topics.camera_info, t_img, camera_info_message(ts, info, t_img, cam))
            if rec.pose is not None:
                t_pose = t_img if rec.pose_stamp_ns is None else rec.pose_stamp_ns
                out.write(topics.tf, t_pose, tf_message(ts, [(topics.odom_frame, topics.base_frame, rec.pose)], t_pose))
            pts = _with_nans(pts, nan_points)
            cols = {"x": pts[:, 0], "y": pts[:, 1], "z": pts[:, 2]}
            if pts.shape[1] == 4:
                cols["intensity"] = pts[:, 3]
            out.write(topics.points, t_scan, pointcloud2_message(ts, cols, t_scan, topics.lidar_frame))
        if not out.counts:
            raise InputError(f"{path}: no record to write")
        counts = dict(out.counts)
    return WrittenBag(Path(path), fmt, topics, counts)


def _parse_stamp(line: str) -> int:
    """ns since the epoch (UTC) of a KITTI ``YYYY-MM-DD hh:mm:ss.fffffffff`` line."""
    day, clock = line.split()
    hh, mm, ss = clock.split(":")
    whole, _, frac = ss.partition(".")
    secs = calendar.timegm((*map(int, day.split("-")), int(hh), int(mm), int(whole), 0, 0, 0))
    return secs * 1_000_000_000 + int((frac + "000000000")[:9])


def kitti_stamps_ns(drive_dir: str | os.PathLike[str], folder: str, names: Sequence[str]) -> list[int]:
    """Stamps (ns) of frames ``names`` from ``DRIVE/FOLDER/timestamps.txt``; without the file (or for frames it
    lacks), the drive's date (from ``YYYY_MM_DD_drive_...``, else the epoch) + frame index x 0.1 s."""
    drive_dir = Path(drive_dir)
    try:
        lines = [ln for ln in (drive_dir / folder / "timestamps.txt").read_text().splitlines() if ln.strip()]
        stamps = [_parse_stamp(ln) for ln in lines]
    except (OSError, ValueError):
        stamps = []
    try:
        y, m, d = (int(v) for v in drive_dir.name.split("_")[:3])
        t0 = calendar.timegm((y, m, d, 0, 0, 0, 0, 0, 0)) * 1_000_000_000
    except ValueError:
        t0 = 0
    return [stamps[int(n)] if int(n) < len(stamps) else t0 + int(n) * 100_000_000 for n in names]


def write_kitti_bag(
    drive_dir: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    camera: str | int = 2,
    frames: str | Sequence[int] | None = None,
    fmt: str | None = None,
    compressed: str | None = None,
    nan_points: int = 0,
    overwrite: bool = False,
) -> WrittenBag:
    """A bag of a KITTI raw drive (:class:`semattnet.data.kitti.raw.RawDrive`): frames ``frames`` (e.g. "0-10";
    None: all) of colour camera ``camera`` with the Velodyne scans, CameraInfo, ``/tf_static`` and, where the drive
    has ``calib_imu_to_velo.txt`` and the frame its OXTS packet, ``/tf`` (``odom -> base_link``, module doc).

    Raises:
        DataError: a missing drive, camera, frame or calibration file (naming it). FileExistsError: ``out`` exists.
        OutputError: ``out`` is, holds or lies inside the drive or its calibration, or is not a bag we wrote.
    """
    from semattnet._utils.outputs import Output, check_outputs
    from semattnet.data.kitti.raw import RawDrive

    calib = sorted(Path(drive_dir).parent.glob("calib_*.txt"))  # the drive's calibration, beside it
    check_outputs(
        [("--drive", drive_dir), *(("calibration", c) for c in calib)], [Output("--out", out, "bag")], overwrite
    )
    drive = RawDrive(drive_dir, camera)
    names = drive.names_for(frames)
    imu = drive.drive_dir.parent / "calib_imu_to_velo.txt"
    T_base_lidar = invert_T(read_velo_to_cam(imu)) if imu.is_file() else None
    img_ns = kitti_stamps_ns(drive.drive_dir, f"image_{drive.camera}", names)
    scan_ns = kitti_stamps_ns(drive.drive_dir, "velodyne_points", names)
    poses = _odom_poses(drive.oxts_dir, names) if imu.is_file() else [None] * len(names)
    pose_ns = kitti_stamps_ns(drive.drive_dir, "oxts", names)
    records = (
        SensorRecord(f.image, f.points, ti, ts, T, tp)
        for f, ti, ts, T, tp in zip((drive.frame(n) for n in names), img_ns, scan_ns, poses, pose_ns, strict=True)
    )
    return write_sensor_bag(
        out,
        records,
        drive.calib,
        T_base_lidar=T_base_lidar,
        topics=BagTopics.for_camera(drive.camera),
        fmt=fmt,
        compressed=compressed,
        nan_points=nan_points,
        overwrite=overwrite,
    )


def _odom_poses(oxts_dir: Path, names: Sequence[str]) -> list[np.ndarray | None]:
    """Each frame's ``T_odom_imu`` from its OXTS packet (None without one): ``odom`` is the IMU at the first frame
    with a packet, whose latitude fixes the Mercator scale of every pose."""
    from semattnet.geometry.motion import read_oxts_latitude, read_oxts_pose

    paths = [oxts_dir / f"{name}.txt" for name in names]
    first = next((p for p in paths if p.is_file()), None)
    if first is None:
        return [None] * len(paths)
    lat0 = read_oxts_latitude(first)
    T_odom_world = invert_T(read_oxts_pose(first, lat0_deg=lat0))
    return [T_odom_world @ read_oxts_pose(p, lat0_deg=lat0) if p.is_file() else None for p in paths]
