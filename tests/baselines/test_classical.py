"""The classical (non-learned) baseline."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner

from semattnet.baselines.classical import complete_classical
from semattnet.cli import main
from semattnet.data.io import read_depth
from semattnet.evaluation.metrics import KittiMetrics
from semattnet.synthetic.scenes import make_frame
from tests._helpers import SAMPLE


def test_beats_the_sparse_input_on_synthetic_scenes() -> None:
    ours, raw = KittiMetrics(), KittiMetrics()
    for seed in range(2):
        fr = make_frame(128, 416, seed=50 + seed)
        sparse, gt = torch.from_numpy(fr.sparse)[None, None], torch.from_numpy(fr.gt)[None, None]
        dense = complete_classical(sparse)
        assert dense.shape == sparse.shape and torch.isfinite(dense).all()
        ours.update(dense, gt)
        raw.update(sparse, gt)
    assert ours.compute()["rmse_mm"] < 0.5 * raw.compute()["rmse_mm"]
    assert ours.compute()["mae_mm"] < 0.5 * raw.compute()["mae_mm"]


def test_constant_scene_and_empty_input() -> None:
    sparse = torch.zeros(1, 1, 40, 60)
    sparse[..., 20::4, ::3] = 12.0
    dense = complete_classical(sparse)
    assert torch.allclose(dense[..., 5:, 5:-5], torch.full_like(dense[..., 5:, 5:-5], 12.0), atol=1e-3)
    assert complete_classical(torch.zeros(1, 1, 8, 8)).eq(0).all()
    with pytest.raises(ValueError, match="B, 1, H, W"):
        complete_classical(torch.zeros(8, 8))


def test_predict_method_classical_on_the_real_frame(tmp_path: Path) -> None:
    rgb = SAMPLE / "kitti_raw/2011_09_26/2011_09_26_drive_0035_sync/image_02/data/0000000005.png"
    sparse = SAMPLE / (
        "data_depth_velodyne/train/2011_09_26_drive_0035_sync/proj_depth/velodyne_raw/image_02/0000000005.png"
    )
    result = CliRunner().invoke(
        main, ["predict", "--method", "classical", "--rgb", str(rgb), "--sparse", str(sparse), "--out", str(tmp_path)]
    )
    assert result.exit_code == 0, result.output
    d = read_depth(tmp_path / "0000000005.png")
    assert d.shape == (375, 1242) and (d > 0).all()
    gt = read_depth(
        SAMPLE
        / ("data_depth_annotated/train/2011_09_26_drive_0035_sync/proj_depth/groundtruth/image_02/0000000005.png")
    )
    valid = gt > 0
    assert np.sqrt(np.mean((d[valid] - gt[valid]) ** 2)) < 3.0  # metres, on real KITTI
