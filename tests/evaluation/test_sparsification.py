"""Sparsification curves, AUSE and AURG (semattnet.evaluation.sparsification), by hand on tiny examples."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from semattnet._errors import InputError
from semattnet.evaluation.sparsification import (
    Sparsification,
    aurg,
    ause,
    fractions,
    oracle_curve,
    sparsification_curve,
)

# Four pixels, |error| 1, 2, 3, 4, uncertainty 0.1, 0.4, 0.3, 0.2. With 4 steps the fractions removed are
# 0, 1/4, 1/2, 3/4, i.e. 4, 3, 2, 1 pixels kept. The least uncertain kept longest: errors in the order
# 1 (0.1), 4 (0.2), 3 (0.3), 2 (0.4).
ERROR = np.array([1.0, -2.0, 3.0, -4.0])
UNC = np.array([0.1, 0.4, 0.3, 0.2])


def test_fractions() -> None:
    np.testing.assert_allclose(fractions(4), [0, 0.25, 0.5, 0.75])
    assert len(fractions()) == 100 and fractions()[-1] == pytest.approx(0.99)
    with pytest.raises(InputError):
        fractions(1)


def test_mae_curve_oracle_ause_aurg_by_hand() -> None:
    # kept errors 1,4,3,2 -> MAE 10/4 = 2.5; 1,4,3 -> 8/3; 1,4 -> 2.5; 1 -> 1; normalised by 2.5
    curve = sparsification_curve(ERROR, UNC, "mae", steps=4)
    np.testing.assert_allclose(curve, [1, 16 / 15, 1, 0.4])
    np.testing.assert_allclose(sparsification_curve(ERROR, UNC, "mae", 4, normalize=False), [2.5, 8 / 3, 2.5, 1])
    # oracle keeps the smallest errors: 2.5, (1+2+3)/3 = 2, 1.5, 1 -> normalised 1, 0.8, 0.6, 0.4
    oracle = oracle_curve(ERROR, "mae", steps=4)
    np.testing.assert_allclose(oracle, [1, 0.8, 0.6, 0.4])
    # AUSE: trapezoids of width 1/4 over differences 0, 4/15, 0.4, 0:
    # 1/8 * (4/15 + (4/15 + 0.4) + 0.4) = 1/8 * 20/15 = 1/6
    assert ause(curve, oracle) == pytest.approx(1 / 6)
    # AURG: 1 - curve = 0, -1/15, 0, 0.6 -> 1/8 * (-1/15 - 1/15 + 0.6) = 7/120
    assert aurg(curve) == pytest.approx(7 / 120)


def test_rmse_curve_by_hand() -> None:
    # squared errors kept: 1,16,9,4 -> 30/4; 1,16,9 -> 26/3; 1,16 -> 17/2; 1 -> 1; RMSE = the roots
    full = math.sqrt(7.5)
    expected = np.array([full, math.sqrt(26 / 3), math.sqrt(8.5), 1.0]) / full
    np.testing.assert_allclose(sparsification_curve(ERROR, UNC, "rmse", steps=4), expected)
    # the oracle: 30/4, (1+4+9)/3, (1+4)/2, 1
    oracle = np.array([full, math.sqrt(14 / 3), math.sqrt(2.5), 1.0]) / full
    np.testing.assert_allclose(oracle_curve(ERROR, "rmse", steps=4), oracle)


def test_ties_take_their_expected_value() -> None:
    # uncertainty 0, 0, 1, 1 with |errors| 1, 3, 2, 4: the tied pair {2, 4} is cut at 3 pixels kept, so
    # its kept pixel counts as its mean 3: (1 + 3 + 3) / 3 = 7/3; at 1 kept, the pair {1, 3} gives 2
    curve = sparsification_curve(np.array([1.0, 3, 2, 4]), np.array([0.0, 0, 1, 1]), "mae", 4, normalize=False)
    np.testing.assert_allclose(curve, [2.5, 7 / 3, 2, 2])
    # every pixel tied: the curve of a random ordering, flat
    flat = sparsification_curve(np.array([1.0, 3, 2, 4]), np.zeros(4), "mae", 4)
    np.testing.assert_allclose(flat, 1.0)
    assert aurg(flat) == pytest.approx(0.0)


def test_perfect_uncertainty_has_zero_ause_and_random_gain() -> None:
    g = torch.Generator().manual_seed(0)
    err = torch.randn(1000, generator=g)
    for metric in ("rmse", "mae"):
        curve = sparsification_curve(err, err.abs() * 3 + 1, metric)
        assert ause(curve, oracle_curve(err, metric)) == pytest.approx(0.0, abs=1e-12)
        assert aurg(curve) > 0.3
        worst = sparsification_curve(err, -err.abs(), metric)  # the most wrong first kept: worse than random
        assert aurg(worst) < 0


def test_removal_uses_exact_integer_counts() -> None:
    # 3 pixels, 2 steps: fractions 0 and 0.5 -> floor(1.5) = 1 removed, 2 kept
    curve = sparsification_curve(np.array([1.0, 2.0, 6.0]), np.array([0.0, 1.0, 2.0]), "mae", 2, normalize=False)
    np.testing.assert_allclose(curve, [3.0, 1.5])


def test_accumulator_averages_frames() -> None:
    acc = Sparsification(steps=4)
    gt = np.array([[10.0, 10.0], [10.0, 10.0]])
    acc.add(gt + ERROR.reshape(2, 2), gt, UNC.reshape(2, 2))
    # a second frame: a hole in gt (0) is not scored; its three pixels ranked perfectly
    acc.add(
        np.array([[11.0, 12.0], [13.0, 5.0]]), np.array([[10.0, 10.0], [10.0, 0.0]]), np.array([[1.0, 2.0], [3.0, 0.0]])
    )
    acc.add(np.ones((2, 2)), np.zeros((2, 2)), np.ones((2, 2)))  # no ground truth: skipped
    assert acc.frames == 2
    first = sparsification_curve(ERROR, UNC, "mae", 4)
    second = sparsification_curve(np.array([1.0, 2.0, 3.0]), np.array([1.0, 2.0, 3.0]), "mae", 4)
    curves = acc.curves()
    np.testing.assert_allclose(curves["mae_curve"], (first + second) / 2)
    res = acc.compute()
    assert set(res) == {"ause_rmse", "aurg_rmse", "ause_mae", "aurg_mae"}
    per_frame = [ause(first, oracle_curve(ERROR, "mae", 4)), 0.0]
    assert res["ause_mae"] == pytest.approx(sum(per_frame) / 2)  # linear: the mean of the per-frame AUSE
    assert Sparsification().compute() == {}


def test_bad_input() -> None:
    with pytest.raises(InputError):
        sparsification_curve(np.ones(3), np.ones(4))
    with pytest.raises(InputError):
        sparsification_curve(np.ones(3), np.ones(3), metric="irmse")
    with pytest.raises(InputError):
        sparsification_curve(np.ones(0), np.ones(0))
