"""PNG I/O: encodings, bad files (truncated, wrong bit depth, wrong channels), no silent overwrite."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from semattnet.data.io import DataError, encode_depth, read_depth, read_image, read_intrinsics, write_depth, write_image
from tests._helpers import SAMPLE

VELO = SAMPLE / "data_depth_velodyne/train/2011_09_26_drive_0035_sync/proj_depth/velodyne_raw/image_02/0000000005.png"


def test_depth_round_trip(tmp_path: Path) -> None:
    d = np.array([[0.0, 1.0 / 256, 12.3456], [80.0, 255.99, 0.5]], dtype=np.float32)
    write_depth(tmp_path / "d.png", d)
    back = read_depth(tmp_path / "d.png")
    assert back.dtype == np.float32
    np.testing.assert_allclose(back, np.round(d * 256) / 256)
    assert Image.open(tmp_path / "d.png").mode.startswith("I;16")


def test_encode_depth_clamps_and_rejects_nan() -> None:
    assert encode_depth(np.array([300.0, -1.0, 1.0])).tolist() == [65535, 0, 256]
    with pytest.raises(DataError, match="NaN"):
        encode_depth(np.array([np.nan]))


def test_no_silent_overwrite_and_nothing_written_on_error(tmp_path: Path) -> None:
    write_depth(tmp_path / "d.png", np.ones((2, 2)))
    with pytest.raises(FileExistsError, match="refusing to overwrite"):
        write_depth(tmp_path / "d.png", np.zeros((2, 2)))
    assert read_depth(tmp_path / "d.png").max() == 1.0
    with pytest.raises(DataError):
        write_depth(tmp_path / "nan.png", np.full((2, 2), np.nan))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.png"]  # no partial or temp files
    write_depth(tmp_path / "d.png", np.zeros((2, 2)), overwrite=True)
    assert read_depth(tmp_path / "d.png").max() == 0.0


def test_real_kitti_depth_is_metres() -> None:
    d = read_depth(VELO)
    assert d.shape == (375, 1242)
    assert 0.03 < (d > 0).mean() < 0.05 and 1.0 < d[d > 0].min() and d.max() < 100
    assert np.all(np.round(d * 256) == d * 256)


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda p: p.write_bytes(VELO.read_bytes()[:3000]), "truncated or corrupt"),
        (lambda p: Image.fromarray(np.zeros((4, 4), np.uint8)).save(p), "16-bit single-channel"),
        (lambda p: Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(p), "16-bit single-channel"),
        (lambda p: p.write_bytes(b""), "truncated or corrupt"),
        (lambda p: None, "file not found"),
    ],
)
def test_bad_depth_files(tmp_path: Path, make, message: str) -> None:
    path = tmp_path / "bad.png"
    make(path)
    with pytest.raises(DataError, match=message) as info:
        read_depth(path)
    assert str(path) in str(info.value)


def test_bad_colour_files(tmp_path: Path) -> None:
    Image.fromarray(np.zeros((4, 4), np.uint16)).save(tmp_path / "d16.png")
    with pytest.raises(DataError, match="8-bit colour"):
        read_image(tmp_path / "d16.png")
    Image.fromarray(np.zeros((4, 4, 4), np.uint8)).save(tmp_path / "rgba.png")
    assert read_image(tmp_path / "rgba.png").shape == (4, 4, 3)
    with pytest.raises(DataError, match="must be \\(H, W, 3\\) uint8"):
        write_image(tmp_path / "x.png", np.zeros((4, 4), np.uint8))


def test_random_bytes_never_crash(tmp_path: Path) -> None:
    """Fuzz: garbage and mutated PNGs raise DataError (never another exception)."""
    rng = np.random.default_rng(0)
    good = VELO.read_bytes()
    refused: list[int] = []
    for i in range(40):
        path = tmp_path / f"f{i}.png"
        if i % 2:
            data = bytearray(good[: int(rng.integers(8, len(good)))])
            for _ in range(5):
                data[int(rng.integers(0, len(data)))] = int(rng.integers(0, 256))
            path.write_bytes(bytes(data))
        else:
            path.write_bytes(rng.bytes(int(rng.integers(0, 500))))
        for reader in (read_depth, read_image):
            try:
                out = reader(path)
            except DataError as exc:
                assert str(path) in str(exc)  # the message names the file
                refused.append(i)
            else:  # a mutation that kept the PNG valid must still decode to the documented type
                assert isinstance(out, np.ndarray) and out.dtype in (np.float32, np.uint8) and out.ndim in (2, 3)
    # pure garbage (even i) is always refused, by both readers
    assert set(range(0, 40, 2)) <= set(refused) and refused.count(0) == 2


def test_intrinsics(tmp_path: Path) -> None:
    K = read_intrinsics(SAMPLE / "kitti_raw/2011_09_26/calib_cam_to_cam.txt", "02")
    assert K[0, 0] == pytest.approx(721.5377) and K[2, 2] == 1.0
    (tmp_path / "k.txt").write_text("1 0 2 0 3 4 0 0 1")
    assert read_intrinsics(tmp_path / "k.txt")[1, 2] == 4
    (tmp_path / "bad.txt").write_text("1 2 3")
    with pytest.raises(DataError, match="9 numbers"):
        read_intrinsics(tmp_path / "bad.txt")


def test_read_intrinsics_is_the_calibration_readers_P_rect(tmp_path) -> None:
    """One reader of KITTI calibration files: K from read_intrinsics is P_rect's left 3x3 as geometry reads it,
    and a file with only P_rect rows (no R_rect / S_rect, as the synthetic trees write) still works."""
    from semattnet.geometry import read_projection

    calib = SAMPLE / "kitti_raw/2011_09_26/calib_cam_to_cam.txt"
    P = read_projection(calib, "02")
    assert P.shape == (3, 4) and P[0, 3] != 0  # the baseline column is kept there
    np.testing.assert_array_equal(read_intrinsics(calib, "02"), P[:, :3])
    (tmp_path / "c.txt").write_text("P_rect_02: 700 0 600 45 0 700 180 0 0 0 1 0\n")
    assert read_intrinsics(tmp_path / "c.txt", "02")[0, 2] == 600
    with pytest.raises(DataError, match="P_rect_03"):
        read_intrinsics(tmp_path / "c.txt", "03")
