"""Geometry for depth completion: calibration, rigid transforms, LiDAR projection, point clouds, sparsity.

Conventions: ``T_a_b`` is a 4x4 column-vector transform from frame ``b`` to frame ``a``
(``p_cam = T_cam_lidar @ p_lidar``); ``K`` 3x3 intrinsics in pixels; ``P`` 3x4 projection; ``uv`` (N, 2)
pixels with u = column, v = row, pixel centres at integer coordinates; ``xyz`` (N, 3) metres.
Frames: ``lidar``, ``cam0``, ``rect`` (rectified cam0), ``cam2``/``cam3`` (rectified colour cameras).

``geometry`` reads scans and calibration files but writes no depth PNGs and imports nothing from
:mod:`semattnet.data`: ``project_scan_file`` and ``ProjectionSummary`` (which write a KITTI PNG) moved
to :mod:`semattnet.data.scans`; the old names here still work (with a ``DeprecationWarning``).
"""

from __future__ import annotations

import importlib
import warnings

from .calibration import (
    CameraCalibration,
    RigCalibration,
    read_cam_to_cam,
    read_kitti_calibration,
    read_projection,
    read_rig_json,
    read_velo_to_cam,
)
from .motion import VehicleMotion, deskew_scan, read_oxts_motion
from .pointcloud_io import read_points, write_ply
from .projection import PointCloud, depth_to_points, points_to_pixels, project_points, select_pixels
from .scan import load_rig, project_scan
from .sparsify import beam_ids, elevation_deg, keep_beams, keep_random, keep_row_bands
from .transforms import check_rigid, check_rotation, invert_T, make_T, transform_points

__all__ = [
    "CameraCalibration",
    "PointCloud",
    "RigCalibration",
    "VehicleMotion",
    "beam_ids",
    "check_rigid",
    "check_rotation",
    "depth_to_points",
    "deskew_scan",
    "elevation_deg",
    "invert_T",
    "keep_beams",
    "keep_random",
    "keep_row_bands",
    "load_rig",
    "make_T",
    "points_to_pixels",
    "project_points",
    "project_scan",
    "read_cam_to_cam",
    "read_kitti_calibration",
    "read_oxts_motion",
    "read_points",
    "read_projection",
    "read_rig_json",
    "read_velo_to_cam",
    "select_pixels",
    "transform_points",
    "write_ply",
]

#: Names that moved out of geometry (they write files of :mod:`semattnet.data`) -> their new module.
_MOVED = {"ProjectionSummary": "semattnet.data.scans", "project_scan_file": "semattnet.data.scans"}


def __getattr__(name: str) -> object:
    """The moved names, loaded on first use (importing geometry loads nothing from data)."""
    if name not in _MOVED:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    warnings.warn(f"semattnet.geometry.{name} moved to {_MOVED[name]}.{name}", DeprecationWarning, stacklevel=2)
    return getattr(importlib.import_module(_MOVED[name]), name)
