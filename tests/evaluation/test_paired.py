"""The paired statistics of the ablation's claims, against hand-computed values."""

from __future__ import annotations

import numpy as np
import pytest

from semattnet.evaluation.paired import MIN_SEED_UNITS, bootstrap_ci, compare, differences, sign_flip_p, verdict


def test_differences_align_seeds_and_images() -> None:
    worse = {0: {"b": 5.0, "a": 3.0}, 1: {"a": 4.0, "b": 4.0}, 2: {"a": 9.0, "b": 9.0}}
    better = {0: {"a": 1.0, "b": 2.0}, 1: {"a": 4.0, "b": 3.0}}
    d, seeds, images = differences(worse, better)
    assert seeds == [0, 1] and images == ["a", "b"]  # seed 2 has no partner
    np.testing.assert_array_equal(d, [[2.0, 3.0], [0.0, 1.0]])
    with pytest.raises(ValueError, match="different images"):
        differences({0: {"a": 1.0}}, {0: {"c": 1.0}})
    with pytest.raises(ValueError, match="no seed in common"):
        differences({0: {"a": 1.0}}, {1: {"a": 1.0}})


def test_sign_flip_exact_two_sided() -> None:
    # 3 units all positive: only the identity and its mirror reach |mean| = 2 -> p = 2/8 (two-sided).
    assert sign_flip_p(np.array([1.0, 2.0, 3.0])) == pytest.approx(2 / 8)
    # |sum| >= 7 of +-4 +-1 +-1 +-1: (4,1,1,1) and its mirror -> 2/16.
    assert sign_flip_p(np.array([4.0, 1.0, 1.0, 1.0])) == pytest.approx(2 / 16)
    # |sum| >= 5: (4,1,1,1), three with one 1 flipped, and their mirrors -> 8/16.
    assert sign_flip_p(np.array([4.0, -1.0, 1.0, 1.0])) == pytest.approx(8 / 16)
    assert sign_flip_p(np.array([1.0, -1.0])) == 1.0  # mean 0: every flip is as extreme
    assert sign_flip_p(-np.array([1.0, 2.0, 3.0])) == pytest.approx(2 / 8)  # direction does not matter


def test_sign_flip_monte_carlo_is_deterministic() -> None:
    u = np.linspace(1.0, 2.0, 20)  # 20 > exact_max: Monte Carlo
    p = sign_flip_p(u, draws=999)
    assert p == sign_flip_p(u, draws=999)
    assert 1 / 1000 <= p <= 3 / 1000  # (1 + hits) / (1 + draws); a hit has probability 2 / 2**20
    assert sign_flip_p(np.array([1.0, -1.0] * 10), draws=999) == 1.0


def test_bootstrap_ci_deterministic_and_contains_mean() -> None:
    d = np.array([[1.0, 2.0, 3.0, 6.0], [2.0, 3.0, 4.0, 1.0], [0.0, 5.0, 2.0, 3.0]])
    lo, hi = bootstrap_ci(d, seed=3)
    assert (lo, hi) == bootstrap_ci(d, seed=3)
    assert d.min() <= lo < d.mean() < hi <= d.max()
    assert bootstrap_ci(np.full((3, 5), 7.0)) == (7.0, 7.0)
    wide = bootstrap_ci(d, level=0.99, seed=3)
    assert wide[0] <= lo and wide[1] >= hi


def test_verdict_rules() -> None:
    assert verdict((1.0, 2.0), 0.01) == "supported"
    assert verdict((-2.0, -1.0), 0.01) == "contradicted"
    assert verdict((-1.0, 2.0), 0.01) == "not separated"  # CI contains 0
    assert verdict((1.0, 2.0), 0.2) == "not separated"  # not significant
    assert verdict((1.0, 2.0), 0.05) == "not separated"  # p must be below alpha


def test_compare_few_seeds_tests_pairs() -> None:
    d = np.array([[10.0, 20.0, 30.0], [5.0, 15.0, 25.0], [-5.0, 5.0, 0.0]])
    r = compare(d, [0, 1, 2])
    assert r["mean_diff"] == pytest.approx(d.mean())
    assert r["per_seed"] == {"0": 20.0, "1": 15.0, "2": 0.0}
    assert r["seeds_agreeing"] == 2 and r["n_seeds"] == 3 and r["n_pairs"] == 9
    assert r["test_units"] == "seed-image pairs"
    assert r["p"] == sign_flip_p(d.ravel())
    assert r["ci95"][0] < r["mean_diff"] < r["ci95"][1]


def test_compare_many_seeds_tests_seeds() -> None:
    rng = np.random.default_rng(0)
    d = 100.0 + rng.normal(0.0, 10.0, size=(MIN_SEED_UNITS, 4))  # every seed favours the claim
    r = compare(d, list(range(MIN_SEED_UNITS)))
    assert r["test_units"] == "seeds" and r["seeds_agreeing"] == MIN_SEED_UNITS
    assert r["p"] == pytest.approx(2 / 2**MIN_SEED_UNITS) and r["p"] < 0.05
    assert r["verdict"] == "supported"
    assert compare(-d, list(range(MIN_SEED_UNITS)))["verdict"] == "contradicted"
