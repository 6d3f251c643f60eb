"""Paths to the bundled KITTI frame (see tests/data/README.md for its licence)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests._helpers import SAMPLE

RAW_DATE = SAMPLE / "kitti_raw" / "2011_09_26"
DRIVE = RAW_DATE / "2011_09_26_drive_0035_sync"
SCAN = DRIVE / "velodyne_points" / "data" / "0000000005.bin"
OXTS = DRIVE / "oxts" / "data" / "0000000005.txt"
#: timestamps_end - timestamps_start of this frame's scan (14:01:23.149746259 - 14:01:23.046412081), seconds.
SCAN_PERIOD = 0.103334178


def official_velodyne_raw(camera: str) -> Path:
    return (
        SAMPLE
        / "data_depth_velodyne"
        / "train"
        / "2011_09_26_drive_0035_sync"
        / "proj_depth"
        / "velodyne_raw"
        / f"image_{camera}"
        / "0000000005.png"
    )


@pytest.fixture(scope="session")
def scan() -> np.ndarray:
    from semattnet.geometry import read_points

    return read_points(SCAN)
