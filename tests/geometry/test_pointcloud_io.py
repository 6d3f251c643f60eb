from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from plyfile import PlyData

from semattnet.data.io import DataError
from semattnet.geometry import PointCloud, read_points, write_ply

from .conftest import SCAN

PTS = np.array([[1.0, 2.0, 3.0, 0.5], [-4.0, 5.5, -6.0, 0.25]], dtype=np.float32)


def test_kitti_bin(scan: np.ndarray) -> None:
    assert scan.shape == (SCAN.stat().st_size // 16, 4) == (118434, 4) and scan.dtype == np.float32
    assert 0 <= scan[:, 3].min() and scan[:, 3].max() <= 1  # KITTI reflectance in [0, 1]
    assert np.abs(scan[:, :3]).max() < 130  # HDL-64E range


def test_bin_errors(tmp_path: Path) -> None:
    (tmp_path / "short.bin").write_bytes(PTS.tobytes()[:-4])
    with pytest.raises(DataError, match=r"short.bin: 28 bytes is not a multiple of 16"):
        read_points(tmp_path / "short.bin")
    (tmp_path / "empty.bin").write_bytes(b"")
    with pytest.raises(DataError, match="empty.bin: empty scan"):
        read_points(tmp_path / "empty.bin")
    bad = PTS.copy()
    bad[1, 0] = np.nan
    (tmp_path / "nan.bin").write_bytes(bad.tobytes())
    with pytest.raises(DataError, match="nan.bin: 1 of 2 points have NaN"):
        read_points(tmp_path / "nan.bin")
    with pytest.raises(DataError, match="not found"):
        read_points(tmp_path / "missing.bin")
    (tmp_path / "x.las").write_bytes(b"x")
    with pytest.raises(DataError, match="unknown point cloud format '.las'"):
        read_points(tmp_path / "x.las")


def test_npy_txt_csv(tmp_path: Path) -> None:
    np.save(tmp_path / "a.npy", PTS[:, :3])
    out = read_points(tmp_path / "a.npy")
    assert out.shape == (2, 4) and np.array_equal(out[:, :3], PTS[:, :3]) and not out[:, 3].any()
    (tmp_path / "a.txt").write_text("1 2 3 0.5\n-4 5.5 -6 0.25\n")
    assert np.array_equal(read_points(tmp_path / "a.txt"), PTS)
    (tmp_path / "a.csv").write_text("x,y,z,intensity\n1,2,3,0.5\n-4,5.5,-6,0.25\n")
    assert np.array_equal(read_points(tmp_path / "a.csv"), PTS)
    (tmp_path / "b.csv").write_text("1,2\n3,4\n")
    with pytest.raises(DataError, match=r"b.csv: expected N x 3 or N x 4"):
        read_points(tmp_path / "b.csv")
    (tmp_path / "c.txt").write_text("1 2 3\n4 five 6\n")
    with pytest.raises(DataError, match="c.txt: malformed numbers"):
        read_points(tmp_path / "c.txt")


def _pcd_header(n: int, data: str, fields: str = "x y z intensity") -> bytes:
    k = len(fields.split())
    return (
        f"# .PCD v0.7\nVERSION 0.7\nFIELDS {fields}\nSIZE {'4 ' * k}\nTYPE {'F ' * k}\nCOUNT {'1 ' * k}\n"
        f"WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n"
    ).encode()


def test_pcd_ascii_and_binary(tmp_path: Path) -> None:
    (tmp_path / "a.pcd").write_bytes(_pcd_header(2, "ascii") + b"1 2 3 0.5\n-4 5.5 -6 0.25\n")
    assert np.array_equal(read_points(tmp_path / "a.pcd"), PTS)
    (tmp_path / "b.pcd").write_bytes(_pcd_header(2, "binary") + PTS.astype("<f4").tobytes())
    assert np.array_equal(read_points(tmp_path / "b.pcd"), PTS)
    # A mixed-type record (x y z float32, ring uint16) without intensity.
    rec = np.array(
        [(1.0, 2.0, 3.0, 7), (4.0, 5.0, 6.0, 9)], dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("ring", "<u2")]
    )
    head = _pcd_header(2, "binary", "x y z ring").replace(b"SIZE 4 4 4 4", b"SIZE 4 4 4 2")
    (tmp_path / "c.pcd").write_bytes(head.replace(b"TYPE F F F F", b"TYPE F F F U") + rec.tobytes())
    assert np.array_equal(read_points(tmp_path / "c.pcd"), [[1, 2, 3, 0], [4, 5, 6, 0]])
    (tmp_path / "d.pcd").write_bytes(_pcd_header(2, "binary") + PTS.tobytes()[:20])
    with pytest.raises(DataError, match="d.pcd: PCD data is truncated"):
        read_points(tmp_path / "d.pcd")
    (tmp_path / "e.pcd").write_bytes(_pcd_header(2, "binary_compressed") + b"\0" * 8)
    with pytest.raises(DataError, match="'DATA binary_compressed' is not supported"):
        read_points(tmp_path / "e.pcd")


def test_write_ply_reads_back(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    xyz = rng.uniform(-10, 10, size=(500, 3)).astype(np.float32)
    rgb = rng.integers(0, 256, size=(500, 3)).astype(np.uint8)
    conf = rng.uniform(0, 1, size=500).astype(np.float32)
    path = write_ply(tmp_path / "out" / "cloud.ply", PointCloud(xyz, rgb, None, conf, frame="lidar"))
    ply = PlyData.read(str(path))
    assert not ply.text and ply.byte_order == "<"
    v = ply["vertex"].data
    assert len(v) == 500
    expected = [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", "|u1"), ("green", "|u1"), ("blue", "|u1")]
    assert [(n, v.dtype[n].str) for n in v.dtype.names] == [*expected, ("confidence", "<f4")]
    assert np.array_equal(np.stack([v["x"], v["y"], v["z"]], 1), xyz)
    assert np.array_equal(np.stack([v["red"], v["green"], v["blue"]], 1), rgb)
    assert np.array_equal(v["confidence"], conf) and 0 <= v["confidence"].min() and v["confidence"].max() <= 1
    assert np.array_equal(read_points(path)[:, :3], xyz)
    assert [p.name for p in path.parent.iterdir()] == ["cloud.ply"]  # no temporary file left
    with pytest.raises(FileExistsError, match="refusing to overwrite"):
        write_ply(path, PointCloud(xyz[:3]))
    assert len(PlyData.read(str(path))["vertex"].data) == 500  # untouched
    write_ply(path, PointCloud(xyz[:3]), overwrite=True)
    v = PlyData.read(str(path))["vertex"].data
    assert len(v) == 3 and v.dtype.names == ("x", "y", "z")
    with pytest.raises(DataError, match="empty point cloud"):
        write_ply(tmp_path / "empty.ply", PointCloud(np.zeros((0, 3), np.float32)))
