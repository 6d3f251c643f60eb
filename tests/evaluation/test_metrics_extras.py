"""The authors' extra metrics against values computed by hand (conventions in metrics.py)."""

from __future__ import annotations

import math

import pytest
import torch

from semattnet.evaluation.metrics import image_metrics


def test_extras_hand_values() -> None:
    # Two valid pixels: gt 10 m with pred 12 m (e = 2), gt 20 m with pred 15 m (e = -5).
    gt = torch.tensor([[[[10.0, 20.0, 0.0]]]], dtype=torch.float64)
    pred = torch.tensor([[[[12.0, 15.0, 7.0]]]], dtype=torch.float64)
    m = {k: float(v[0]) for k, v in image_metrics(pred, gt).items()}
    assert m["abs_rel"] == pytest.approx((2 / 10 + 5 / 20) / 2)
    # sq_rel in the authors' convention: (e / gt)^2, not Eigen's e^2 / gt (which would be 1.45)
    assert m["sq_rel"] == pytest.approx(((2 / 10) ** 2 + (5 / 20) ** 2) / 2)  # 0.05125
    assert m["sq_rel"] != pytest.approx((4 / 10 + 25 / 20) / 2)
    assert m["delta1"] == pytest.approx(0.5)  # ratios 1.2 (< 1.25) and 1.333 (not)
    assert m["delta2"] == pytest.approx(1.0)
    assert m["log10"] == pytest.approx((abs(math.log10(1.2)) + abs(math.log10(0.75))) / 2)
    d = [math.log(1.2), math.log(0.75)]
    silog = math.sqrt(sum(x * x for x in d) / 2 - (sum(d) / 2) ** 2) * 100
    assert m["silog"] == pytest.approx(silog)
    assert m["rmse"] == pytest.approx(math.sqrt((4 + 25) / 2))
    assert m["mae"] == pytest.approx(3.5)
