"""Depth pictures: the fixed colour scale and the pictures written for saved predictions."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from semattnet.data.io import read_image, write_depth
from semattnet.viz.depth import DEPTH_MAX_M, colorize_depth, write_depth_pictures


def test_colorize_fixed_scale_and_black_holes() -> None:
    d = np.array([[0.0, 10.0, DEPTH_MAX_M, 500.0]], np.float32)
    rgb = colorize_depth(d)
    assert rgb.shape == (1, 4, 3) and rgb.dtype == np.uint8
    assert rgb[0, 0].tolist() == [0, 0, 0]  # no depth: black
    assert rgb[0, 2].tolist() == rgb[0, 3].tolist()  # beyond the scale: the top colour
    assert rgb[0, 1].tolist() != rgb[0, 2].tolist()


@pytest.mark.parametrize(("vmax", "cmap"), [(DEPTH_MAX_M, "turbo"), (7.5, "viridis")])
def test_colorize_is_matplotlibs_colormap_to_the_bit(vmax: float, cmap: str) -> None:
    """The table lookup gives the picture of matplotlib's colormap call, at every bin edge and odd value."""
    from matplotlib import colormaps

    edges = (np.arange(257) / 256 * vmax).astype(np.float32)
    odd = np.array([np.nan, np.inf, -np.inf, 0.0, -0.0, -3.0, 1e-9, 1e30, vmax], np.float32)
    noise = np.random.default_rng(0).uniform(-1, 2 * vmax, 500).astype(np.float32)
    d = np.concatenate([edges, np.nextafter(edges, np.float32(0)), np.nextafter(edges, np.float32(1e9)), odd, noise])
    for depth in (d[None], d.astype(np.float64)[None]):
        f = np.asarray(depth, np.float32)
        want = colormaps[cmap](np.clip(f / vmax, 0.0, 1.0))[..., :3]
        want[~(f > 0)] = 0.0
        np.testing.assert_array_equal(colorize_depth(depth, vmax, cmap), (want * 255.0 + 0.5).astype(np.uint8))


def test_write_depth_pictures(tmp_path: Path) -> None:
    pred, gt = tmp_path / "pred", tmp_path / "gt"
    write_depth(pred / "f.png", np.full((4, 6), 12.0))
    write_depth(gt / "f.png", np.full((4, 6), 10.0))
    assert write_depth_pictures(pred, tmp_path / "out", gt) == 1
    colour, error = read_image(tmp_path / "out/f_color.png"), read_image(tmp_path / "out/f_error.png")
    assert colour.shape == error.shape == (4, 6, 3)
    assert (colour == colorize_depth(np.full((4, 6), 12.0))).all()
