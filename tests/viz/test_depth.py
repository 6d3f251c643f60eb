"""Depth pictures: the fixed colour scale and the pictures written for saved predictions."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from semattnet.data.io import read_image, write_depth
from semattnet.viz.depth import DEPTH_MAX_M, colorize_depth, write_depth_pictures


def test_colorize_fixed_scale_and_black_holes() -> None:
    d = np.array([[0.0, 10.0, DEPTH_MAX_M, 500.0]], np.float32)
    rgb = colorize_depth(d)
    assert rgb.shape == (1, 4, 3) and rgb.dtype == np.uint8
    assert rgb[0, 0].tolist() == [0, 0, 0]  # no depth: black
    assert rgb[0, 2].tolist() == rgb[0, 3].tolist()  # beyond the scale: the top colour
    assert rgb[0, 1].tolist() != rgb[0, 2].tolist()


def test_write_depth_pictures(tmp_path: Path) -> None:
    pred, gt = tmp_path / "pred", tmp_path / "gt"
    write_depth(pred / "f.png", np.full((4, 6), 12.0))
    write_depth(gt / "f.png", np.full((4, 6), 10.0))
    assert write_depth_pictures(pred, tmp_path / "out", gt) == 1
    colour, error = read_image(tmp_path / "out/f_color.png"), read_image(tmp_path / "out/f_error.png")
    assert colour.shape == error.shape == (4, 6, 3)
    assert (colour == colorize_depth(np.full((4, 6), 12.0))).all()
