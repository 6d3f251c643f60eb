"""Holes stay holes: every PNG the project writes keeps "no prediction" as 0 (which the devkit fills)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

from semattnet.baselines.classical import ClassicalCompleter
from semattnet.data.io import MIN_DEPTH_M, clamp_for_png, read_depth
from semattnet.data.pairing import FramePaths
from semattnet.evaluation.evaluate import EvalOutputs, EvalSplit, evaluate_split, score_folders
from semattnet.evaluation.protocols import eval_source
from semattnet.evaluation.submission import write_submission_files
from semattnet.inference.completer import Completion
from semattnet.inference.folder import complete_folder
from semattnet.synthetic.tree import write_synthetic_kitti


def _holes(shape: tuple[int, ...]) -> np.ndarray:
    """A hole pattern: a block, a column and scattered pixels."""
    h = np.zeros(shape, bool)
    h[..., 2:6, 3:9] = True
    h[..., :, -1] = True
    h[..., ::7, ::5] = True
    return h


def _with_holes(depth: np.ndarray) -> np.ndarray:
    d = depth.astype(np.float32).copy()
    hole = _holes(d.shape)
    d[hole] = 0.0
    d[hole & (np.arange(d.shape[-1]) % 3 == 0)] = np.nan
    d[hole & (np.arange(d.shape[-1]) % 3 == 1)] = -1.0
    return d


def test_clamp_rule() -> None:
    with pytest.warns(UserWarning, match="frame7: 3 hole"):
        out = clamp_for_png(np.array([0.0, np.nan, -2.0, 1e-4, 5.0, 1e4]), "frame7")
    assert out.tolist() == pytest.approx([0.0, 0.0, 0.0, MIN_DEPTH_M, 5.0, 65535 / 256])
    t = clamp_for_png(torch.tensor([0.0, float("inf"), 3.0]))
    assert isinstance(t, torch.Tensor) and t.tolist() == [0.0, 0.0, 3.0]


def test_predict_path_keeps_holes(tmp_path: Path) -> None:
    rgb = np.zeros((20, 30, 3), np.uint8)
    from semattnet.data.io import write_depth, write_image

    write_image(tmp_path / "a.png", rgb)
    write_depth(tmp_path / "s.png", np.full((20, 30), 4.0))
    pred = _with_holes(np.full((20, 30), 7.0))

    class Fixed(ClassicalCompleter):
        def __call__(self, image: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None) -> Completion:
            return Completion(depth=pred)

    completer = Fixed()

    with pytest.warns(UserWarning, match="hole"):
        complete_folder(completer, [FramePaths("a", tmp_path / "a.png", tmp_path / "s.png")], tmp_path / "o", log=str)
    d = read_depth(tmp_path / "o" / "a.png")
    assert np.array_equal(d == 0, _holes(d.shape)) and np.allclose(d[d > 0], 7.0)


def test_submission_keeps_and_reports_holes(tmp_path: Path) -> None:
    expected = {"0000000000.png": (12, 16), "0000000001.png": (12, 16)}
    preds = [("0000000000.png", _with_holes(np.full((12, 16), 3.0))), ("0000000001.png", np.full((12, 16), 3.0))]
    n = int(_holes((12, 16)).sum())
    with pytest.warns(UserWarning, match=rf"{n} hole\(s\) .* in 1 file\(s\): 0000000000.png \({n}\)"):
        write_submission_files(preds, tmp_path / "s", expected)
    d = read_depth(tmp_path / "s" / "0000000000.png")
    assert np.array_equal(d == 0, _holes(d.shape))
    assert (read_depth(tmp_path / "s" / "0000000001.png") > 0).all()


class _Holey(ClassicalCompleter):
    """Predicts 9 m + the mean sparse depth with the hole pattern (NaN, -1 and 0)."""

    def __call__(self, rgb: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None) -> Completion:
        return Completion(depth=_with_holes(np.full(sparse.shape, 9.0) + sparse.mean()))


_holey = _Holey()


def test_evaluate_saved_and_quantized_scores_match_metrics(tmp_path: Path) -> None:
    root = tmp_path / "kitti"
    write_synthetic_kitti(root, 2, (48, 64), seed=3, eval_frames=2, workers=1)
    out = tmp_path / "eval"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        m = evaluate_split(_holey, EvalSplit(root, "val_select"), out, EvalOutputs(save_predictions=True)).metrics
    first = eval_source("kitti-dc", root, "val_select").names[0]
    assert any("hole" in str(w.message) and first in str(w.message) for w in caught)
    saved = sorted((out / "predictions").glob("*.png"))
    assert len(saved) == 2
    for p in saved:
        d = read_depth(p)
        assert np.array_equal(d == 0, _holes(d.shape))
    gt_dir = root / "data_depth_selection/val_selection_cropped/groundtruth_depth"
    ref = score_folders(out / "predictions", gt_dir, progress=False).compute()
    got = m.compute()
    for k in ("rmse_mm", "mae_mm", "irmse_per_km", "imae_per_km"):
        assert got[k] == pytest.approx(ref[k], rel=1e-6), k
    assert got["irmse_per_km"] < 100  # a hole written as 1/256 m would add thousands of 1/km
