"""Completing folders of a user's frames: pairing by name, outputs, no silent overwrite."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from semattnet.baselines import ClassicalCompleter
from semattnet.data.io import DataError, read_depth, write_depth, write_image
from semattnet.data.pairing import pair_frames
from semattnet.inference import complete_folder


def _frames(root: Path, names: list[str]) -> tuple[Path, Path]:
    rgb, sparse = root / "rgb", root / "sparse"
    for i, name in enumerate(names):
        write_image(rgb / name, np.full((20, 30, 3), 40 * i, np.uint8))
        d = np.zeros((20, 30), np.float32)
        d[::4, ::5] = 10.0 + i
        write_depth(sparse / name.replace("_image_", "_velodyne_raw_"), d)
    return rgb, sparse


def test_pairing_by_name_and_kitti_swap(tmp_path: Path) -> None:
    rgb, sparse = _frames(tmp_path, ["a.png", "x_image_02.png"])
    frames = pair_frames(rgb, sparse)
    assert [(f.name, f.sparse.name) for f in frames] == [("a", "a.png"), ("x_image_02", "x_velodyne_raw_02.png")]
    (rgb / "lonely.png").write_bytes((rgb / "a.png").read_bytes())
    with pytest.raises(DataError, match="no matching sparse/semantic file for 1 image"):
        pair_frames(rgb, sparse)


def test_complete_folder_writes_and_refuses_overwrite(tmp_path: Path) -> None:
    rgb, sparse = _frames(tmp_path, ["a.png", "b.png"])
    out, lines = tmp_path / "out", []
    written = complete_folder(ClassicalCompleter(), pair_frames(rgb, sparse), out, npy=True, log=lines.append)
    assert [p.name for p in written] == ["a.png", "b.png"] and len(lines) == 2
    depth = read_depth(out / "b.png")
    assert depth.shape == (20, 30) and depth[0, 0] == pytest.approx(11.0)  # a measured pixel is kept
    assert np.load(out / "a.npy").dtype == np.float32 and (out / "a_color.png").is_file()
    before = (out / "a.png").read_bytes()
    with pytest.raises(FileExistsError, match="--overwrite"):
        complete_folder(ClassicalCompleter(), pair_frames(rgb, sparse), out)
    assert (out / "a.png").read_bytes() == before
