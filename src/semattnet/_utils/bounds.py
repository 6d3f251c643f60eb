"""Bounds checked before anything is allocated from a size read in a file or an option: one home per kind.

Image sizes (PNG headers, a calibration's ``S_rect``, a rig's ``image_size``, ``--size``) are bounded
here; frame ranges by the drive's frame count (:func:`semattnet.data.kitti.raw.parse_frames`); point
counts by the file's length (:mod:`semattnet.geometry.pointcloud_io`).
"""

from __future__ import annotations

import math
import os
import stat
from pathlib import Path
from typing import SupportsFloat

from semattnet._errors import DataError, InputError, SemAttNetError

__all__ = [
    "MAX_ADDED_POINTS",
    "MAX_IMAGE_PIXELS",
    "MAX_IMAGE_SIDE",
    "MAX_SKEW_S",
    "check_image_size",
    "check_pinhole",
    "regular_file",
]

#: Largest width or height accepted, checked before decoding or allocating (KITTI: 1242).
MAX_IMAGE_SIDE = 16384
#: Largest width x height accepted (64 Mpx, ~256 MB as RGB): bigger sizes are refused as
#: decompression bombs before any pixel is decoded or any map allocated.
MAX_IMAGE_PIXELS = 64 * 1024 * 1024
#: Most NaN points added to a scan for testing readers (``data bag-from-kitti --nan-points``); a KITTI
#: scan has about 120,000 points.
MAX_ADDED_POINTS = 1_000_000
#: Largest tolerance between an image's stamp and its scan's, in seconds (``--max-skew``).
MAX_SKEW_S = 3600.0


def check_image_size(width: SupportsFloat | str, height: SupportsFloat | str, where: str) -> tuple[int, int]:
    """(width, height) as ints when both are whole numbers in [1, :data:`MAX_IMAGE_SIDE`] and their
    product at most :data:`MAX_IMAGE_PIXELS`.

    Args:
        where: names the file and field (``"calib.txt: S_rect_02"``), the message's start.

    Raises:
        DataError: anything else (zero, negative, fractional, NaN, inf, 401 digits), in one line.
    """
    try:
        w, h = (float(v) for v in (width, height))
    except (TypeError, ValueError, OverflowError):
        w = h = math.nan
    if not all(math.isfinite(v) and v >= 1 and v == int(v) for v in (w, h)):
        raise DataError(f"{where} must be two positive integers (width, height), got {_short(width)} {_short(height)}")
    if w > MAX_IMAGE_SIDE or h > MAX_IMAGE_SIDE or w * h > MAX_IMAGE_PIXELS:
        raise DataError(
            f"{where}: {int(w)}x{int(h)} is above the limit of {MAX_IMAGE_SIDE} a side "
            f"and {MAX_IMAGE_PIXELS} pixels in all (semattnet._utils.bounds)"
        )
    return int(w), int(h)


def _short(value: object) -> str:
    text = str(value)
    return text if len(text) <= 24 else f"{text[:20]}...({len(text)} characters)"


def check_pinhole(fx: float, fy: float, cx: float, cy: float, where: str = "--K") -> None:
    """Refuse intrinsics that mean nothing: NaN / infinite entries or non-positive focal lengths.

    Raises:
        InputError: one line naming ``where`` (the option or file and field) and the values.
    """
    vals = (fx, fy, cx, cy)
    if not all(math.isfinite(v) for v in vals) or not (fx > 0 and fy > 0):
        raise InputError(
            f"{where}: fx, fy must be finite and positive and cx, cy finite; got {', '.join(f'{v:g}' for v in vals)}"
        )


def regular_file(path: str | os.PathLike[str], what: str = "file", error: type[SemAttNetError] = DataError) -> Path:
    """``path`` (a :class:`~pathlib.Path`) when it is a regular file (symlinks followed); otherwise one line
    saying what it is: missing, a folder, or a FIFO / device / socket (a read would block or never end).

    Raises:
        ``error`` (default :class:`DataError`), naming ``path`` and ``what`` was expected.
    """
    path = Path(path)
    try:
        mode = path.stat().st_mode
    except OSError:
        raise error(f"{path}: {what} not found") from None
    if stat.S_ISREG(mode):
        return path
    kind = "a folder" if stat.S_ISDIR(mode) else "a FIFO" if stat.S_ISFIFO(mode) else "a device or socket"
    raise error(f"{path}: is {kind}, not a regular {what}")
