"""``semattnet predict --kitti-raw``: the bundled KITTI raw frame completed straight from its own files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from plyfile import PlyData

from semattnet.cli import main
from semattnet.data.io import read_depth, read_image
from tests.inference._raw_sample import DRIVE, IMAGE_02, tiny_checkpoint

MAX_DEPTH, TOP_CROP = 60.0, 100


def _predict(out: Path, *args: str) -> str:
    result = CliRunner().invoke(
        main,
        [
            "predict",
            "--kitti-raw",
            str(DRIVE),
            "--frames",
            "5",
            "--camera",
            "2",
            "--ply",
            "--max-depth",
            str(MAX_DEPTH),
            "--top-crop",
            str(TOP_CROP),
            "--device",
            "cpu",
            "--out",
            str(out),
            *args,
        ],
    )
    assert result.exit_code == 0, result.output
    assert "0000000005: 18956 LiDAR pixels" in result.output
    return result.output


def _check_outputs(out: Path, confidence: bool) -> np.ndarray:
    depth = read_depth(out / "0000000005.png")
    assert depth.shape == (375, 1242) and (depth > 0).mean() > 0.5
    assert read_image(out / "0000000005_color.png").shape == (375, 1242, 3)
    v = PlyData.read(str(out / "0000000005.ply"))["vertex"].data
    kept = (depth > 0) & (depth <= MAX_DEPTH)
    kept[:TOP_CROP] = False
    assert len(v) == int(kept.sum()) > 1000
    assert ("confidence" in v.dtype.names) == confidence
    if confidence:
        assert v["confidence"].min() >= 1 / 3 - 1e-4 and v["confidence"].max() <= 1 + 1e-6  # max of 3 softmax weights
    assert 0 < v["z"].min() and v["z"].max() <= MAX_DEPTH
    assert np.abs(v["x"]).max() < 3 * MAX_DEPTH and np.abs(v["y"]).max() < MAX_DEPTH
    rows, cols = np.nonzero(kept)
    image = read_image(IMAGE_02)
    for i in (0, len(rows) // 2, len(rows) - 1):  # row-major order: vertex i is the i-th kept pixel
        assert [v["red"][i], v["green"][i], v["blue"][i]] == image[rows[i], cols[i]].tolist()
        assert v["z"][i] == pytest.approx(depth[rows[i], cols[i]], abs=1e-6)
    return depth


def test_classical_on_the_raw_drive(tmp_path: Path) -> None:
    _predict(tmp_path, "--method", "classical", "--panel")
    _check_outputs(tmp_path, confidence=False)
    assert (tmp_path / "0000000005_panel.png").is_file()
    again = CliRunner().invoke(
        main, ["predict", "--kitti-raw", str(DRIVE), "--method", "classical", "--out", str(tmp_path)]
    )
    assert again.exit_code != 0 and "--overwrite" in again.output


def test_learned_model_on_the_raw_drive(tmp_path: Path) -> None:
    ckpt = tiny_checkpoint(tmp_path / "tiny.safetensors")
    output = _predict(tmp_path / "out", "--checkpoint", str(ckpt))
    _check_outputs(tmp_path / "out", confidence=True)
    assert "Traceback" not in output


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--kitti-raw", str(DRIVE), "--frames", "7"], "no image_02 image and scan for frame(s) 7"),
        (["--kitti-raw", str(DRIVE), "--frames", "x-y"], "expected a range a-b"),
        (["--kitti-raw", str(DRIVE), "--method", "semattnet"], "--checkpoint or --weights is required"),
        (["--kitti-raw", str(DRIVE), "--checkpoint", __file__, "--weights", "x"], "not both"),
        (["--rgb", str(IMAGE_02), "--ply"], "--rgb and --sparse go together: give both"),
    ],
)
def test_bad_raw_options(tmp_path: Path, args: list[str], message: str) -> None:
    extra = ["--method", "classical"] if "--method" not in args and "--checkpoint" not in args else []
    result = CliRunner().invoke(main, ["predict", *extra, *args, "--out", str(tmp_path / "o")])
    assert result.exit_code != 0 and message in result.output, result.output
    assert "Traceback" not in result.output and not (tmp_path / "o" / "0000000005.png").exists()
