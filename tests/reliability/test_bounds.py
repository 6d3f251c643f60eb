"""Bounds before allocation: sizes and counts read from files or options are checked first, each a one-line
DataError naming the file and the field (image sizes, frame ranges, point counts)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from semattnet._errors import SemAttNetError
from semattnet._utils.bounds import MAX_IMAGE_SIDE, check_image_size
from semattnet.cli import main
from semattnet.data import io
from semattnet.data.kitti.raw import MAX_FRAME_INDEX, parse_frames
from semattnet.geometry import read_points
from semattnet.geometry.calibration import read_cam_to_cam, read_rig_json

RIG = {
    "K": [[50, 0, 16], [0, 50, 12], [0, 0, 1]],
    "T_cam_lidar": [[0, -1, 0, 0], [0, 0, -1, 0], [1, 0, 0, 0], [0, 0, 0, 1]],
    "image_size": [32, 24],
}
BAD_SIZES = [
    (0, 10),
    (-5, 10),
    (10.5, 10),
    (float("nan"), 10),
    (float("inf"), 10),
    (MAX_IMAGE_SIDE + 1, 10),
    (16384, 16384),
    (10**400, 10),
    ("ten", 10),
    (None, 10),
]


def test_one_home_for_the_image_bound() -> None:
    assert io.MAX_IMAGE_SIDE is MAX_IMAGE_SIDE  # the old public name still works
    assert check_image_size(1242, 375, "x") == (1242, 375) and check_image_size(1.0, 2.0, "x") == (1, 2)


@pytest.mark.parametrize(("w", "h"), BAD_SIZES)
def test_bad_image_sizes_are_one_line(w: object, h: object) -> None:
    with pytest.raises(SemAttNetError, match="^where[ :]") as err:
        check_image_size(w, h, "where")
    assert "\n" not in str(err.value) and len(str(err.value)) < 300


@pytest.mark.parametrize("size", [[1_000_000, 1_000_000], [0, 24], [32.5, 24], [10**400, 24], [-1, 24]])
def test_rig_image_size_is_bounded(tmp_path: Path, size: list) -> None:
    path = tmp_path / "rig.json"
    path.write_text(json.dumps({**RIG, "image_size": size}))
    with pytest.raises(SemAttNetError, match=r"rig\.json: '?image_size") as err:
        read_rig_json(path)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("key", ["K", "T_cam_lidar"])
def test_a_401_digit_integer_in_a_rig_is_one_line(tmp_path: Path, key: str) -> None:
    doc = json.loads(json.dumps(RIG))
    doc[key][0][0] = 10**400
    path = tmp_path / "rig.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(SemAttNetError, match="rig.json"):
        read_rig_json(path)


CAM_TO_CAM = """P_rect_02: 7.2e+02 0 6.0e+02 4.4e+01 0 7.2e+02 1.7e+02 2.1e-01 0 0 1 2.7e-03
R_rect_02: 1 0 0 0 1 0 0 0 1
S_rect_02: {size}
"""


@pytest.mark.parametrize("size", ["1000000 1000000", "0 375", "1242.5 375", "nan 375", "1242 -1", "9" * 401 + " 3"])
def test_calibration_s_rect_is_bounded(tmp_path: Path, size: str) -> None:
    path = tmp_path / "calib_cam_to_cam.txt"
    path.write_text(CAM_TO_CAM.format(size=size))
    with pytest.raises(SemAttNetError, match="calib_cam_to_cam.txt") as err:
        read_cam_to_cam(path)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("size", ["1000000x1000000", "0x24", "32x0"])
def test_project_size_option_is_bounded(tmp_path: Path, size: str) -> None:
    np.save(tmp_path / "s.npy", np.array([[5.0, 0, 0]], np.float32))
    res = CliRunner().invoke(
        main,
        [
            "project",
            "--points",
            str(tmp_path / "s.npy"),
            "--K",
            "50,50,16,12",
            "--T",
            "0,-1,0,0,0,0,-1,0,1,0,0,0,0,0,0,1",
            "--size",
            size,
            "--out",
            str(tmp_path / "o.png"),
        ],
    )
    assert res.exit_code in (1, 2) and "Traceback" not in res.output and not (tmp_path / "o.png").exists(), res.output


@pytest.mark.parametrize("spec", ["0-3000000000", "5,3000000000", [0, 10**12], 10**9, f"0-{MAX_FRAME_INDEX}"])
def test_frame_ranges_are_bounded_before_expansion(spec: object) -> None:
    with pytest.raises(SemAttNetError, match="beyond"):
        parse_frames(spec)  # type: ignore[arg-type]
    with pytest.raises(SemAttNetError, match="frame count"):
        parse_frames(spec, limit=100)  # type: ignore[arg-type]


def test_frame_ranges_still_parse() -> None:
    assert parse_frames("0-3,7") == [0, 1, 2, 3, 7] and parse_frames(4, limit=5) == [4]
    with pytest.raises(SemAttNetError, match="expected a range"):
        parse_frames("3-1")


def _pcd(tmp_path: Path, points: str, count: str = "1 1 1", data: bytes = b"1 2 3\n") -> Path:
    path = tmp_path / "c.pcd"
    head = f"VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT {count}\nPOINTS {points}\nDATA ascii\n"
    path.write_bytes(head.encode() + data)
    return path


BAD_PCD = [
    ("-2", "1 1 1"),
    ("1", "0 1 1"),
    ("1", "1 -1 1"),
    ("99999999999999", "1 1 1"),
    ("x", "1 1 1"),
    ("1", "a 1 1"),
]


@pytest.mark.parametrize(("points", "count"), BAD_PCD)
def test_pcd_counts_are_bounded(tmp_path: Path, points: str, count: str) -> None:
    with pytest.raises(SemAttNetError, match=r"c\.pcd") as err:
        read_points(_pcd(tmp_path, points, count))
    assert "\n" not in str(err.value)


def test_pcd_valid_still_reads(tmp_path: Path) -> None:
    assert read_points(_pcd(tmp_path, "1")).tolist() == [[1, 2, 3, 0]]


@pytest.mark.parametrize(
    "array",
    [
        np.zeros(3, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4")]),
        np.array([["a", "b", "c"]]),
        np.array([[1 + 2j, 0, 0]]),
        np.ones((2, 3), bool),
        np.zeros((0, 3)),
    ],
)
def test_npy_that_is_not_a_plain_numeric_array(tmp_path: Path, array: np.ndarray) -> None:
    np.save(tmp_path / "p.npy", array)
    with pytest.raises(SemAttNetError, match=r"p\.npy"):
        read_points(tmp_path / "p.npy")


def test_npy_header_claiming_a_huge_shape_is_refused_without_allocating(tmp_path: Path) -> None:
    from numpy.lib import format as npformat

    path = tmp_path / "p.npy"
    with open(path, "wb") as f:  # 4e9 x 3 float64 claimed (96 GB), 24 bytes present
        npformat.write_array_header_1_0(f, {"descr": "<f8", "fortran_order": False, "shape": (4_000_000_000, 3)})
        f.write(b"\0" * 24)
    with pytest.raises(SemAttNetError, match=r"p\.npy"):
        read_points(path)
    np.savez(tmp_path / "z.npz", a=np.zeros((2, 3)))  # an .npz under an .npy name
    with pytest.raises(SemAttNetError, match=r"z\.npy"):
        read_points((tmp_path / "z.npz").rename(tmp_path / "z.npy"))
