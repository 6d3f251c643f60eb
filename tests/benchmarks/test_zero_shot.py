"""benchmarks/zero_shot.py and evaluation.zero_shot: the scores against hand-computed values, the real frame's
inputs, the tables and the docs markers, and one quick run of the whole command."""

from __future__ import annotations

import json
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from semattnet.evaluation.zero_shot import mean_scores, real_frames, score
from tests.benchmarks._scripts import load_script

SAMPLE = Path(__file__).resolve().parents[1] / "data" / "kitti_sample"


@pytest.fixture(scope="module")
def zero_shot() -> ModuleType:
    return load_script("zero_shot")


def test_scores_match_hand_computed_values() -> None:
    gt = np.array([[2.0, 4.0], [0.0, 8.0]], np.float32)
    pred = np.array([[3.0, 4.0], [9.0, 4.0]], np.float32)
    sigma = np.array([[0.6, 0.1], [1.0, 1.0]], np.float32)
    s = score(pred, gt, sigma)
    # errors over the 3 pixels with truth: 1, 0, -4 m
    assert s["rmse_mm"] == pytest.approx(1000 * np.sqrt(17 / 3))
    assert s["mae_mm"] == pytest.approx(1000 * 5 / 3)
    inv = np.array([1 / 3 - 1 / 2, 0.0, 1 / 4 - 1 / 8])
    assert s["irmse_per_km"] == pytest.approx(1000 * np.sqrt(np.mean(inv**2)))
    assert s["rel"] == pytest.approx((0.5 + 0 + 0.5) / 3)
    # |error| <= 2 sigma: 1 <= 1.2 yes, 0 <= 0.2 yes, 4 <= 2 no
    assert s["coverage_2sigma_pct"] == pytest.approx(200 / 3)
    # the 10 % gate keeps sigma <= 0.1 * depth: 0.1 <= 0.4 only (the pixel with no error)
    assert s["gate_kept_pct"] == pytest.approx(100 / 3) and s["gate_rmse_mm"] == 0.0
    # a pixel with truth and no depth is filled for the depth metrics (as the devkit fills it: from its
    # neighbour, 9 m) but has no uncertainty to judge
    holed = score(np.array([[3.0, 4.0], [9.0, 0.0]], np.float32), gt, sigma)
    assert holed["rmse_mm"] == pytest.approx(1000 * np.sqrt((1 + 0 + 1) / 3))
    assert holed["coverage_2sigma_pct"] == pytest.approx(100.0) and holed["gate_kept_pct"] == pytest.approx(50.0)
    assert mean_scores([{"a": 1.0, "b": 2.0}, {"a": 3.0}]) == {"a": 2.0}


def test_the_real_frame_is_both_cameras_with_their_own_scan() -> None:
    frames = real_frames(SAMPLE)
    assert [f.name for f in frames] == ["kitti-0035-5-cam02", "kitti-0035-5-cam03"]
    for f in frames:
        assert f.rgb.shape == (375, 1242, 3) and f.sparse.shape == f.gt.shape == (375, 1242)
        assert 0.035 < (f.sparse > 0).mean() < 0.045 and 0.1 < (f.gt > 0).mean() < 0.2


def test_tables_mark_the_best_and_the_docs_markers_are_filled(zero_shot: ModuleType, tmp_path: Path) -> None:
    results = {
        "classical": {"indoor/points500": {"rmse_mm": 300.0, "rel": 0.05}},
        "x": {"indoor/points500": {"rmse_mm": 200.0, "rel": 0.04}},
    }
    text = zero_shot.table(results, ["indoor/points500"])
    assert "| `x` | **200** |" in text and "| `classical` | 300 |" in text
    assert "**0.040**" in zero_shot.table(results, ["indoor/points500"], "rel")
    page = tmp_path / "p.md"
    page.write_text("a\n<!-- zero-shot:begin -->\nold\n<!-- zero-shot:end -->\nb\n")
    zero_shot._docs(page, "new\n")
    assert page.read_text() == "a\n<!-- zero-shot:begin -->\nnew\n<!-- zero-shot:end -->\nb\n"


def test_a_quick_run_writes_results_table_and_plot(zero_shot: ModuleType, tmp_path: Path) -> None:
    out = tmp_path / "run"
    assert zero_shot.main(["--out", str(out), "--quick", "--methods", "classical,anchor", "--sample", str(SAMPLE)]) == 0
    results = json.loads((out / "results.json").read_text())["results"]
    assert set(results) == {"classical", "anchor"}
    assert set(results["classical"]) == {"real/cam02", "real/cam03"} | {c[0] for c in zero_shot.CELLS}
    # the classical completion on the real frame: the figure the docs and the issue quote (1311 mm, camera 02)
    assert results["classical"]["real/cam02"]["rmse_mm"] == pytest.approx(1310.6, abs=1.0)
    assert (out / "zero-shot.png").stat().st_size > 10_000 and "Real KITTI frame" in (out / "table.md").read_text()
