"""Depths a KITTI depth PNG cannot hold (beyond 65535/256 m, negative, NaN, infinite) are refused, never clipped:
``write_depth`` names the file and writes nothing, and ``project`` names the scan whose points lie deeper than a
PNG holds."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from semattnet._errors import DataError
from tests.reliability._helpers import cli as _cli
from tests.reliability._helpers import one_line as _one_line
from tests.reliability._helpers import rig as _rig
from tests.reliability._helpers import scan as _scan


@pytest.mark.parametrize("value", [300.0, 1e6, -1.0, np.nan, np.inf])
def test_write_depth_refuses_what_a_kitti_png_cannot_hold(tmp_path: Path, value: float) -> None:
    from semattnet.data.io import write_depth

    depth = np.full((4, 4), 5.0)
    depth[1, 2] = value
    assert "a.png: depth to write" in _one_line(lambda: write_depth(tmp_path / "a.png", depth), DataError)
    assert not (tmp_path / "a.png").exists()
    write_depth(tmp_path / "ok.png", np.full((4, 4), 65535 / 256))  # the top of the range still writes


@pytest.mark.parametrize("depth_m", [256.5, 1000.0, 1e5])
def test_project_refuses_points_deeper_than_a_png_holds(tmp_path: Path, depth_m: float) -> None:
    code, msg = _cli(
        tmp_path,
        "project",
        "--points",
        _scan(tmp_path, [[depth_m, 0, 0], [6.0, 0.5, 0.2]]),
        "--rig",
        _rig(tmp_path),
        "--out",
        tmp_path / "o.png",
    )
    assert code == 1 and "scan.npy" in msg and "deeper than" in msg and not (tmp_path / "o.png").exists(), msg
