"""One LiDAR scan file -> one KITTI-encoded 16-bit sparse depth PNG: what ``semattnet project`` runs.

The projection is :mod:`semattnet.geometry`'s (:func:`~semattnet.geometry.load_rig`,
:func:`~semattnet.geometry.project_scan`); this module adds the files: reading the scan and writing the
PNG with :func:`~semattnet.data.io.write_depth` (so ``geometry`` needs nothing from ``data``).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from semattnet._errors import DataError
from semattnet._utils.outputs import Output, check_no_input_overlap, check_outputs
from semattnet.data.io import MAX_DEPTH_M, write_depth
from semattnet.geometry import load_rig, project_scan, read_points
from semattnet.geometry.scan import DEFAULT_SCAN_PERIOD

__all__ = ["ProjectionSummary", "project_scan_file"]


@dataclass(frozen=True)
class ProjectionSummary:
    """What :func:`project_scan_file` did: ``points`` read, ``projected`` pixels with depth (the nearest
    point wins a pixel), their ``density`` (fraction of the image's pixels), the written ``path`` and the
    ``depth`` map (H, W) metres."""

    path: Path
    points: int
    projected: int
    density: float
    depth: np.ndarray

    def describe(self) -> str:
        h, w = self.depth.shape
        density = f"{100 * self.density:.2f} % of {w}x{h}"
        return f"{self.path}: {self.points} points read, {self.projected} projected into pixels (density {density})"


def project_scan_file(
    scan: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    calib_dir: str | os.PathLike[str] | None = None,
    camera: str | int = "02",
    rig: str | os.PathLike[str] | None = None,
    K: Sequence[float] | None = None,
    T: Sequence[float] | None = None,
    image_size: Sequence[int] | None = None,
    deskew_oxts: str | os.PathLike[str] | None = None,
    scan_period: float = DEFAULT_SCAN_PERIOD,
    overwrite: bool = False,
) -> ProjectionSummary:
    """Read ``scan`` (any :func:`read_points` format), project it with the calibration from :func:`load_rig`
    and write ``out`` as a KITTI 16-bit depth PNG (depth * 256, 0 = none).

    Raises:
        OutputError: ``out`` is one of the input files or inside an input folder (even with ``overwrite``), or
            exists and is not a PNG image.
        FileExistsError: ``out`` exists and ``overwrite`` is False (checked before reading anything).
        DataError: bad scan, calibration or OXTS file; the message names the file.
    """
    out = Path(out)
    given = [("--points", scan), ("--rig", rig), ("--deskew-oxts", deskew_oxts), ("--calib-dir", calib_dir)]
    check_outputs(given, [Output("--out", out, "png")], overwrite)
    check_no_input_overlap([scan, rig, deskew_oxts, calib_dir], out_files=[out])
    calib = load_rig(calib_dir, camera, rig, K, T, image_size)
    points = read_points(scan)
    depth = project_scan(points, calib, deskew_oxts, scan_period, name=str(scan))
    if (deep := int((depth > MAX_DEPTH_M).sum())) > 0:
        raise DataError(
            f"{scan}: {deep} point(s) project deeper than {MAX_DEPTH_M:.2f} m (up to {depth.max():g} m), "
            "more than a KITTI 16-bit PNG holds; crop the scan or check its units (metres)"
        )
    out.parent.mkdir(parents=True, exist_ok=True)
    write_depth(out, depth, overwrite=overwrite)
    projected = int(np.count_nonzero(depth))
    return ProjectionSummary(out, int(points.shape[0]), projected, projected / depth.size, depth)
