"""Ego-motion compensation ("deskewing") of a spinning-LiDAR scan.

A Velodyne sweep takes one revolution (~0.1 s), while the car moves; KITTI triggers the cameras when the
sensor faces forward (azimuth 0). KITTI's official ``velodyne_raw`` depth maps are compensated for this
motion: on the bundled frame, deskewing with the OXTS velocity puts 93 % of their points on exactly our
pixel with the same depth to 1 cm, against 13 % without it.

Model (fitted on that frame: the sensor spins clockwise seen from above, i.e. towards negative azimuth):
a point at azimuth ``phi = atan2(y, x)`` (radians, counter-clockwise from forward) was measured at
``dt = -phi / (2 pi) * scan_period`` seconds relative to the forward-facing instant. With the vehicle's
velocity ``v`` (m/s, LiDAR axes: x forward, y left, z up) and yaw rate ``w`` (rad/s) taken constant, the
point in the LiDAR frame at the forward-facing instant is ``p0 = Rz(w dt) p + v dt``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from semattnet._errors import DataError, InputError
from semattnet._utils.bounds import regular_file

#: Largest speed component (m/s) and yaw rate (rad/s) an OXTS packet may give: far beyond any car
#: (KITTI: < 30 m/s, < 1 rad/s); bigger or non-finite values are a corrupt packet, not motion.
MAX_SPEED_MPS = 100.0
MAX_YAW_RATE = 10.0

#: The Earth's radius (metres) of KITTI's Mercator projection of the OXTS positions.
EARTH_RADIUS_M = 6378137.0

__all__ = [
    "MAX_SPEED_MPS",
    "MAX_YAW_RATE",
    "VehicleMotion",
    "deskew_scan",
    "read_oxts_latitude",
    "read_oxts_motion",
    "read_oxts_pose",
]


@dataclass(frozen=True)
class VehicleMotion:
    """Velocity (3,) m/s as (forward, left, up) and yaw rate rad/s (counter-clockwise seen from above)."""

    velocity: np.ndarray
    yaw_rate: float


def read_oxts_motion(path: str | os.PathLike[str]) -> VehicleMotion:
    """Velocity and yaw rate from one KITTI raw OXTS packet (``oxts/data/NNNNNNNNNN.txt``, 30 numbers).

    Uses ``vf, vl, vu`` (fields 9-11) and ``wu`` (field 23, rate around the upward axis). The IMU and the
    Velodyne axes are nearly aligned in KITTI (both x forward, y left, z up), so these serve in the LiDAR frame.

    Raises:
        DataError: missing file, fewer than 23 numbers, malformed numbers, or a velocity / yaw rate that is
            NaN, infinite or beyond :data:`MAX_SPEED_MPS` / :data:`MAX_YAW_RATE` (the message names the file).
    """
    path = regular_file(path, "OXTS file")
    try:
        vals = [float(v) for v in path.read_text().split()]
    except (ValueError, UnicodeDecodeError) as exc:
        raise DataError(f"{path}: malformed numbers: {exc}") from None
    if len(vals) < 23:
        raise DataError(f"{path}: expected 30 OXTS fields, found {len(vals)}")
    velocity, yaw_rate = np.array(vals[8:11], dtype=np.float64), float(vals[22])
    if not (np.all(np.abs(velocity) <= MAX_SPEED_MPS) and abs(yaw_rate) <= MAX_YAW_RATE):  # False for NaN too
        raise DataError(
            f"{path}: OXTS velocity (vf, vl, vu) = {', '.join(f'{v:g}' for v in velocity)} m/s and "
            f"yaw rate wu = {yaw_rate:g} rad/s must be finite, at most {MAX_SPEED_MPS:g} m/s and "
            f"{MAX_YAW_RATE:g} rad/s"
        )
    return VehicleMotion(velocity, yaw_rate)


def deskew_scan(
    points: np.ndarray, velocity: np.ndarray, yaw_rate: float = 0.0, scan_period: float = 0.1
) -> np.ndarray:
    """Move every point to where it was at the forward-facing instant (see the module doc for the model).

    Args:
        points: (N, 3|4) LiDAR-frame points, metres (extra columns are kept unchanged).
        velocity: (3,) vehicle velocity (forward, left, up), m/s. yaw_rate: rad/s.
        scan_period: seconds per revolution (KITTI: ``timestamps_end - timestamps_start`` of the frame, ~0.103 s).

    Returns:
        (N, 3|4) compensated points, same dtype as ``points``.
    """
    vel = np.asarray(velocity, dtype=np.float64).reshape(-1)
    if vel.shape != (3,) or not np.all(np.isfinite(vel)) or not np.isfinite(yaw_rate):
        raise InputError(
            f"deskew_scan: velocity must be 3 finite numbers and yaw_rate finite, got {vel} and {yaw_rate}"
        )
    if not (np.isfinite(scan_period) and scan_period > 0):
        raise InputError(f"deskew_scan: scan_period must be a positive number of seconds, got {scan_period}")
    pts = np.asarray(points)
    xyz = pts[:, :3].astype(np.float64)
    dt = -np.arctan2(xyz[:, 1], xyz[:, 0]) / (2 * np.pi) * float(scan_period)
    a = float(yaw_rate) * dt
    c, s = np.cos(a), np.sin(a)
    out: np.ndarray = pts.copy()
    out[:, 0] = c * xyz[:, 0] - s * xyz[:, 1]
    out[:, 1] = s * xyz[:, 0] + c * xyz[:, 1]
    out[:, 2] = xyz[:, 2]
    out[:, :3] += vel.reshape(1, 3) * dt[:, None]
    return out


def _oxts_numbers(path: str | os.PathLike[str], count: int) -> list[float]:
    """The first numbers of an OXTS packet, at least ``count`` of them, all finite (a DataError naming the file)."""
    path = regular_file(path, "OXTS file")
    try:
        vals = [float(v) for v in path.read_text().split()]
    except (ValueError, UnicodeDecodeError) as exc:
        raise DataError(f"{path}: malformed numbers: {exc}") from None
    if len(vals) < count or not np.all(np.isfinite(vals[:count])):
        raise DataError(f"{path}: expected 30 finite OXTS fields, found {len(vals)}")
    return vals


def read_oxts_latitude(path: str | os.PathLike[str]) -> float:
    """The latitude (degrees) of a KITTI raw OXTS packet (its first number): the ``lat0_deg`` of
    :func:`read_oxts_pose` that fixes the Mercator scale of a drive's poses.

    Raises:
        DataError: missing file, fewer than 6 numbers or one not finite (naming the file).
    """
    return _oxts_numbers(path, 6)[0]


def read_oxts_pose(path: str | os.PathLike[str], lat0_deg: float | None = None) -> np.ndarray:
    """(4, 4) ``T_world_imu`` of one KITTI raw OXTS packet, as the devkit's ``convertOxtsToPose``: the position
    (``lat, lon, alt``, fields 1-3) in a Mercator projection scaled by ``cos(lat0)`` (``lat0_deg``: the latitude
    that fixes the scale, the same for every pose compared; None: this packet's), the orientation
    ``Rz(yaw) Ry(pitch) Rx(roll)`` (fields 4-6, radians). Relative poses of nearby packets are metres.

    Raises:
        DataError: missing file, fewer than 6 numbers, or a latitude beyond +-85 degrees (naming the file).
    """
    lat, lon, alt, roll, pitch, yaw = _oxts_numbers(path, 6)[:6]
    if abs(lat) > 85 or abs(lon) > 180:
        raise DataError(f"{path}: OXTS latitude {lat:g} / longitude {lon:g} out of range")
    scale = np.cos(np.deg2rad(lat if lat0_deg is None else lat0_deg))
    t = [
        scale * EARTH_RADIUS_M * np.deg2rad(lon),
        scale * EARTH_RADIUS_M * np.log(np.tan(np.pi * (90 + lat) / 360)),
        alt,
    ]

    def rot(axis: int, a: float) -> np.ndarray:
        c, s, (i, j) = np.cos(a), np.sin(a), [(1, 2), (2, 0), (0, 1)][axis]
        R = np.eye(3)
        R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
        return R

    T = np.eye(4)
    T[:3, :3] = rot(2, yaw) @ rot(1, pitch) @ rot(0, roll)
    T[:3, 3] = t
    return T
