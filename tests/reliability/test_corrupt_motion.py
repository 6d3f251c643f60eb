"""Motion that means nothing is blamed on where it came from: a corrupt OXTS packet (a NaN, infinite or absurd
velocity or yaw rate) is one line naming the OXTS file, never the scan it would deskew, both for ``project
--deskew-oxts`` and in a raw drive; ``deskew_scan`` itself refuses such motion, or a scan period that is not
positive, in one line naming itself. Nothing is written."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from semattnet._errors import DataError, InputError
from tests._helpers import SAMPLE
from tests.reliability._helpers import cli as _cli
from tests.reliability._helpers import one_line as _one_line
from tests.reliability._helpers import rig as _rig
from tests.reliability._helpers import scan as _scan

DRIVE = ("2011_09_26", "2011_09_26_drive_0035_sync")


def _oxts(path: Path, index: int, value: str) -> Path:
    vals = ["0.1"] * 30
    vals[index] = value
    path.write_text(" ".join(vals) + "\n")
    return path


BAD_OXTS = [(8, "nan"), (9, "inf"), (10, "-inf"), (8, "1e300"), (22, "nan"), (22, "1e6")]


@pytest.mark.parametrize(("index", "value"), BAD_OXTS)
def test_a_corrupt_oxts_packet_is_blamed_on_the_oxts_file(tmp_path: Path, index: int, value: str) -> None:
    from semattnet.geometry import read_oxts_motion

    path = _oxts(tmp_path / "oxts.txt", index, value)
    assert "oxts.txt: OXTS velocity" in _one_line(lambda: read_oxts_motion(path), DataError)
    code, msg = _cli(
        tmp_path,
        "project",
        "--points",
        _scan(tmp_path),
        "--rig",
        _rig(tmp_path),
        "--deskew-oxts",
        path,
        "--out",
        tmp_path / "o.png",
    )
    assert code == 1 and "oxts.txt" in msg and "scan.npy" not in msg, msg
    assert not (tmp_path / "o.png").exists()


def test_a_raw_drive_with_a_corrupt_oxts_packet_names_it(tmp_path: Path) -> None:
    shutil.copytree(SAMPLE / "kitti_raw", tmp_path / "raw")
    drive = tmp_path / "raw" / DRIVE[0] / DRIVE[1]
    packet = drive / "oxts" / "data" / "0000000005.txt"
    vals = packet.read_text().split()
    vals[8] = "nan"
    packet.write_text(" ".join(vals) + "\n")
    code, msg = _cli(
        tmp_path, "predict", "--method", "classical", "--kitti-raw", drive, "--deskew", "--out", tmp_path / "o"
    )
    assert code == 1 and "0000000005.txt" in msg and "OXTS" in msg, msg


@pytest.mark.parametrize(
    ("velocity", "yaw", "period"),
    [
        ([np.nan, 0, 0], 0.0, 0.1),
        ([0, 0], 0.0, 0.1),
        ([0, 0, 0], np.inf, 0.1),
        ([0, 0, 0], 0.0, 0.0),
        ([0, 0, 0], 0.0, np.nan),
    ],
)
def test_deskew_refuses_meaningless_motion(velocity: list[float], yaw: float, period: float) -> None:
    from semattnet.geometry import deskew_scan

    assert "deskew_scan" in _one_line(lambda: deskew_scan(np.ones((3, 4)), np.array(velocity), yaw, period), InputError)
