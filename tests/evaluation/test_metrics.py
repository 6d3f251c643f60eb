"""KITTI metrics against hand-computed values."""

from __future__ import annotations

import math

import pytest
import torch

from semattnet.evaluation.metrics import KittiMetrics, fill_holes_kitti, image_metrics


def t(rows) -> torch.Tensor:  # type: ignore[no-untyped-def]
    return torch.tensor(rows, dtype=torch.float32)[None, None]


def test_hole_filling_rows_then_columns() -> None:
    pred = t([[0, 0, 0, 0], [0, 4, 0, 2], [0, 0, 0, 0], [3, 0, 0, 5]])
    expected = t(
        [
            [4, 4, 2, 2],  # top row copies the first valid row below (column-wise)
            [4, 4, 2, 2],  # row 1: left end copies 4, the gap takes min(4, 2), right end 2
            [-1, -1, -1, -1],  # an empty row between filled rows stays empty (-1)
            [3, 3, 3, 5],
        ]
    )
    assert torch.equal(fill_holes_kitti(pred), expected)


def test_all_holes_prediction() -> None:
    pred = torch.zeros(1, 1, 3, 3)
    assert torch.equal(fill_holes_kitti(pred), torch.full_like(pred, -1.0))
    gt = t([[0, 2, 0], [0, 0, 4], [0, 0, 0]])
    m = image_metrics(pred, gt)
    # every scored pixel predicts -1 m: errors 3 and 5
    assert m["mae"].item() == pytest.approx(4.0)
    assert m["rmse"].item() == pytest.approx(math.sqrt((9 + 25) / 2))
    # inverse: |-1 - 1/2| = 1.5 and |-1 - 1/4| = 1.25
    assert m["imae"].item() == pytest.approx(1.375)
    assert m["irmse"].item() == pytest.approx(math.sqrt((1.5**2 + 1.25**2) / 2))


def test_hand_values_and_units() -> None:
    gt = t([[10, 0], [20, 40]])
    pred = t([[11, 7], [18, 40]])
    m = image_metrics(pred, gt)
    assert m["mae"].item() == pytest.approx((1 + 2 + 0) / 3)
    assert m["rmse"].item() == pytest.approx(math.sqrt((1 + 4) / 3))
    inv = [abs(1 / 11 - 1 / 10), abs(1 / 18 - 1 / 20), 0.0]
    assert m["imae"].item() == pytest.approx(sum(inv) / 3)
    assert m["delta1"].item() == 1.0 and m["abs_rel"].item() == pytest.approx((0.1 + 0.1 + 0) / 3)
    acc = KittiMetrics()
    acc.update(pred, gt)
    r = acc.compute()
    assert r["rmse_mm"] == pytest.approx(1000 * math.sqrt(5 / 3))
    assert r["imae_per_km"] == pytest.approx(1000 * sum(inv) / 3)


def test_mean_over_images_not_pixels() -> None:
    gt = torch.stack([t([[10, 10], [10, 10]])[0], t([[10, 0], [0, 0]])[0]])
    pred = torch.stack([t([[10, 10], [10, 10]])[0], t([[14, 0], [0, 0]])[0]])
    acc = KittiMetrics()
    acc.update(pred, gt, names=["a", "b"])
    assert acc.compute()["mae"] == pytest.approx((0 + 4) / 2)  # pooled over pixels would be 4 / 5
    assert [r["name"] for r in acc.per_image] == ["a", "b"]


def test_image_without_ground_truth_is_skipped() -> None:
    gt = torch.stack([t([[0, 0], [0, 0]])[0], t([[5, 0], [0, 0]])[0]])
    pred = torch.full_like(gt, 6.0)
    acc = KittiMetrics()
    values = acc.update(pred, gt)
    assert math.isnan(values["rmse"][0].item())
    r = acc.compute()
    assert r["images"] == 1 and r["mae"] == pytest.approx(1.0)
    with pytest.raises(ValueError, match="no image"):
        KittiMetrics().compute()


def test_prediction_row_without_valid_pixel() -> None:
    gt = t([[5, 5], [5, 5], [5, 5]])
    pred = t([[4, 4], [0, 0], [6, 6]])  # middle row empty, between valid rows -> -1 m
    m = image_metrics(pred, gt)
    assert m["mae"].item() == pytest.approx((1 + 1 + 6 + 6 + 1 + 1) / 6)


def test_authors_variant_ignores_near_gt() -> None:
    gt = t([[0.05, 10]])
    pred = t([[3.0, 11]])
    assert image_metrics(pred, gt)["mae"].item() == pytest.approx((2.95 + 1) / 2)
    assert image_metrics(pred, gt, min_gt=0.1)["mae"].item() == pytest.approx(1.0)
    assert image_metrics(t([[0.0, 11]]), gt, fill_holes=False, min_gt=0.1)["mae"].item() == pytest.approx(1.0)


def test_shape_mismatch() -> None:
    with pytest.raises(ValueError, match="differ in shape"):
        image_metrics(torch.zeros(1, 1, 2, 2), torch.zeros(1, 1, 2, 3))
