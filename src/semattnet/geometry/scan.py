"""One LiDAR scan -> one sparse depth map (``semattnet project`` writes it with
:func:`semattnet.data.scans.project_scan_file`).

The calibration comes from one of three sources (exactly one must be given):

* a KITTI raw date folder (``calib_cam_to_cam.txt`` + ``calib_velo_to_cam.txt``) and a camera id;
* a rig file (JSON/YAML with ``K``, ``T_cam_lidar``, ``image_size``, see :func:`read_rig_json`);
* numbers: ``K`` as (fx, fy, cx, cy) pixels, ``T_cam_lidar`` as 16 numbers row-major, ``image_size`` (w, h).

Optionally the scan is first ego-motion compensated with one KITTI OXTS packet (:func:`deskew_scan`), which
is how KITTI's official ``velodyne_raw`` maps were made.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np

from semattnet._errors import DataError
from semattnet._utils.bounds import check_image_size, check_pinhole

from .calibration import RigCalibration, read_kitti_calibration, read_rig_json
from .motion import deskew_scan, read_oxts_motion
from .projection import project_points
from .transforms import check_rigid

__all__ = ["DEFAULT_SCAN_PERIOD", "load_rig", "project_scan"]

#: Seconds per Velodyne revolution when the drive's timestamps are not at hand (KITTI: ~0.103 s).
DEFAULT_SCAN_PERIOD = 0.1


def _rig_from_numbers(K: Sequence[float], T: Sequence[float], image_size: Sequence[int] | None) -> RigCalibration:
    if len(K) != 4:
        raise DataError(f"--K: K needs 4 numbers fx,fy,cx,cy; got {len(K)}")
    if len(T) != 16:
        raise DataError(f"--T: T_cam_lidar needs 16 numbers (4x4 row-major); got {len(T)}")
    if image_size is None or len(image_size) != 2:
        raise DataError(f"the image size (width, height) is required with K and T; got {image_size}")
    size = check_image_size(image_size[0], image_size[1], "--size")
    fx, fy, cx, cy = (float(v) for v in K)
    check_pinhole(fx, fy, cx, cy, "--K")
    T_cam_lidar = np.asarray(T, dtype=np.float64).reshape(4, 4)
    if not np.all(np.isfinite(T_cam_lidar)):
        raise DataError("--T: T_cam_lidar has NaN or infinite entries")
    why = check_rigid(T_cam_lidar)
    if why:
        raise DataError(f"--T: T_cam_lidar is not a rigid transform: {why}")
    K3 = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]], dtype=np.float64)
    return RigCalibration(K3, T_cam_lidar, size, source="command line")


def load_rig(
    calib_dir: str | os.PathLike[str] | None = None,
    camera: str | int = "02",
    rig: str | os.PathLike[str] | None = None,
    K: Sequence[float] | None = None,
    T: Sequence[float] | None = None,
    image_size: Sequence[int] | None = None,
) -> RigCalibration:
    """The calibration from exactly one source (module doc): ``calib_dir`` + ``camera``, ``rig``, or ``K`` + ``T``
    + ``image_size``.

    Raises:
        DataError: none or several sources, or what the readers raise (naming the file).
    """
    given = [
        name
        for name, v in (("calib_dir", calib_dir), ("rig", rig), ("K/T", K if K is not None else T))
        if v is not None
    ]
    if len(given) != 1:
        raise DataError(f"give exactly one calibration source (KITTI calib dir, rig file, or K and T); got {given}")
    if calib_dir is not None:
        return read_kitti_calibration(calib_dir, camera)
    if rig is not None:
        return read_rig_json(rig)
    if K is None or T is None:
        raise DataError("K and T must be given together")
    return _rig_from_numbers(K, T, image_size)


def project_scan(
    points: np.ndarray,
    calib: RigCalibration,
    oxts: str | os.PathLike[str] | None = None,
    scan_period: float = DEFAULT_SCAN_PERIOD,
    name: str = "points",
) -> np.ndarray:
    """(H, W) float32 sparse depth (metres, 0 = none) of LiDAR-frame ``points`` in ``calib``'s camera,
    optionally deskewed with the OXTS packet ``oxts`` first (see :func:`deskew_scan`).

    Raises:
        DataError: no point lands inside the image (a wrong calibration or scan: the map would be empty).
    """
    if calib.image_size is None:
        raise DataError(f"{calib.source or name}: the calibration does not give the image size")
    if oxts is not None:
        motion = read_oxts_motion(oxts)
        points = deskew_scan(points, motion.velocity, motion.yaw_rate, scan_period)
    depth = project_points(points, calib.K, calib.T_cam_lidar, calib.image_size, name=name)
    if not depth.any():
        w, h = calib.image_size
        raise DataError(
            f"{name}: none of its {len(points)} points projects in front of the camera inside the "
            f"{w}x{h} image; check the calibration ({calib.source or 'T_cam_lidar, K'})"
        )
    return depth
