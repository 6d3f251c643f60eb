"""Deprecated since 0.2, removed in 0.3: KITTI raw drives are read by :mod:`semattnet.data.kitti.raw`.

``from semattnet.data.kitti_raw import RawDrive`` still works until then, with a ``DeprecationWarning``.
"""

import warnings

from semattnet.data.kitti.raw import MAX_FRAME_INDEX, FrameRangeError, RawDrive, RawFrame, parse_frames, scan_periods

__all__ = ["MAX_FRAME_INDEX", "FrameRangeError", "RawDrive", "RawFrame", "parse_frames", "scan_periods"]

warnings.warn(
    "semattnet.data.kitti_raw is deprecated since 0.2 and goes in 0.3: use semattnet.data.kitti.raw",
    DeprecationWarning,
    stacklevel=2,
)
