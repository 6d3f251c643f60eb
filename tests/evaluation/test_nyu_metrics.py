"""The range protocols' metrics (NYU v2 as NLSPN / CompletionFormer, VOID as KBNet): hand-computed values,
and REL / delta against a second, independent implementation."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from semattnet.evaluation.metrics import RangeMetrics, range_metrics
from semattnet.evaluation.protocols import protocol_metrics


def _t(a: list) -> torch.Tensor:
    return torch.tensor(a, dtype=torch.float64)[None, None]


def test_hand_computed_nyu() -> None:
    gt = _t([[1.0, 2.0], [4.0, 0.0]])  # 0: no ground truth
    pred = _t([[1.5, 2.0], [2.0, 7.0]])
    m = range_metrics(pred, gt, 0.1, 10.0, (0.0, 10.0))
    # errors over the 3 valid pixels: 0.5, 0, -2
    assert float(m["mae"]) == pytest.approx(2.5 / 3)
    assert float(m["rmse"]) == pytest.approx(math.sqrt((0.25 + 4) / 3))
    assert float(m["abs_rel"]) == pytest.approx((0.5 / 1 + 0 + 2 / 4) / 3)
    # ratios 1.5, 1, 2: < 1.25 once (1), < 1.5625 twice (1, 1.5), < 1.953125 twice (2 is not)
    assert [float(m[f"delta{k}"]) for k in (1, 2, 3)] == pytest.approx([1 / 3, 2 / 3, 2 / 3])
    assert float(m["imae"]) == pytest.approx((abs(1 / 1.5 - 1) + 0 + abs(1 / 2 - 1 / 4)) / 3)


def test_range_and_clamp() -> None:
    gt = _t([[0.05, 3.0, 12.0, 4.0]])  # 0.05 and 12 m: outside NYU's 0.1-10 m
    pred = _t([[9.0, 3.0, 1.0, 14.0]])  # 14 m clamps to 10
    m = range_metrics(pred, gt, 0.1, 10.0, (0.0, 10.0))
    assert float(m["valid_pixels"]) == 2 and float(m["mae"]) == pytest.approx(3.0)
    void = range_metrics(_t([[0.1, 2.0]]), _t([[1.0, 2.0]]), 0.2, 5.0, (0.2, 5.0))  # 0.1 clamps to 0.2
    assert float(void["mae"]) == pytest.approx(0.4) and float(void["imae"]) == pytest.approx((5 - 1) / 2)
    empty = range_metrics(_t([[1.0]]), _t([[20.0]]), 0.1, 10.0)
    assert math.isnan(float(empty["rmse"]))


def _reference_rel_delta(pred: np.ndarray, gt: np.ndarray, lo: float, hi: float) -> tuple[float, list[float]]:
    """A second implementation, written from the definitions (per image, then the mean over images)."""
    rels, deltas = [], []
    for p, g in zip(pred, gt, strict=True):
        p = np.clip(p, 0.0, hi)
        keep = (g > 1e-4) & (g >= lo) & (g <= hi)
        p, g = p[keep], g[keep]
        rels.append(np.mean(np.abs(p - g) / g))
        thresh = np.maximum(p / g, g / p)
        deltas.append([np.mean(thresh < 1.25**k) for k in (1, 2, 3)])
    return float(np.mean(rels)), np.mean(deltas, axis=0).tolist()


def test_rel_and_delta_match_an_independent_implementation() -> None:
    rng = np.random.default_rng(3)
    gt = rng.uniform(0.0, 12.0, (4, 1, 20, 30))
    gt[rng.random(gt.shape) < 0.3] = 0.0
    pred = gt * rng.uniform(0.6, 1.5, gt.shape) + rng.normal(0, 0.2, gt.shape).clip(0, None)
    m = protocol_metrics("nyuv2")
    m.update(torch.from_numpy(pred), torch.from_numpy(gt))
    r = m.compute()
    rel, deltas = _reference_rel_delta(pred[:, 0], gt[:, 0], 0.1, 10.0)
    assert r["abs_rel"] == pytest.approx(rel, rel=1e-12)
    assert [r["delta1"], r["delta2"], r["delta3"]] == pytest.approx(deltas, rel=1e-12)
    assert r["images"] == 4 and "REL" in m.table() and "RMSE [m]" in m.table()


def test_void_units_and_table() -> None:
    m = protocol_metrics("void")
    assert isinstance(m, RangeMetrics) and (m.min_depth, m.max_depth, m.clamp) == (0.2, 5.0, (0.0, math.inf))
    m.update(_t([[1.1, 2.0]]), _t([[1.0, 2.0]]))
    r = m.compute()
    assert r["mae_mm"] == pytest.approx(50.0) and r["rmse_mm"] == pytest.approx(1000 * math.sqrt(0.01 / 2))
    assert r["imae_per_km"] == pytest.approx(1000 * (1 - 1 / 1.1) / 2)
    assert m.table().splitlines()[0].split("|")[0].strip() == "MAE [mm]"
