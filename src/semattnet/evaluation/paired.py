"""Paired comparison of two models trained with the same seeds and scored on the same images.

The data are the differences ``d[s, i] = metric(worse, seed s, image i) - metric(better, seed s,
image i)`` for every training seed ``s`` (both models trained with that seed: same data order,
augmentation and initialisation seed) and every held-out image ``i`` (the same images for every
seed). A positive mean difference ``mean(d)`` is the claim's direction: the "better" model has the
lower error.

Procedure (:func:`compare`):

* **Estimate**: ``mean(d)`` over all (seed, image) pairs, which equals the mean of the per-seed
  means ``m_s = mean_i d[s, i]`` (every seed has the same images); the per-seed means and how many
  of them are positive are reported too.
* **95 % confidence interval**: a crossed two-way bootstrap (:func:`bootstrap_ci`). Seeds and
  images are crossed random factors (every seed's models are scored on the same scenes), so a
  replicate draws ``S`` seeds *and* ``n`` images with replacement and takes the mean of
  ``d[seeds][:, images]``; resampling pairs independently would treat the images of one seed,
  which share a model, as independent and make the interval too narrow.
* **p-value**: a two-sided sign-flip permutation test (:func:`sign_flip_p`) of H0 "each unit's
  difference is symmetric about 0". The natural units are whole seeds (their means ``m_s``): a
  seed's models are the independent replicate of the training procedure. But with ``S`` seeds the
  smallest two-sided p is ``2 / 2**S``, which is below 0.05 only from ``S = 6``
  (:data:`MIN_SEED_UNITS`) on; with fewer seeds the units are the (seed, image) pairs, a test
  conditional on the trained models (it ignores the seed-to-seed spread). That is why a verdict
  needs the bootstrap interval, which does resample seeds, to exclude 0 as well.
* **Verdict** (:func:`verdict`): ``supported`` if p < alpha and the interval lies above 0,
  ``contradicted`` if p < alpha and it lies below 0, else ``not separated``.

Everything is deterministic: the random draws use ``numpy.random.default_rng(seed)``.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence

import numpy as np

from semattnet._errors import InputError

__all__ = ["ALPHA", "MIN_SEED_UNITS", "bootstrap_ci", "compare", "differences", "sign_flip_p", "verdict"]

#: Significance level of the verdicts.
ALPHA = 0.05
#: Fewest seeds for seeds to be the test's units: 2 / 2**6 = 0.031 < 0.05 (2 / 2**5 = 0.0625 is not).
MIN_SEED_UNITS = 6


def differences(
    worse: Mapping[int, Mapping[str, float]], better: Mapping[int, Mapping[str, float]]
) -> tuple[np.ndarray, list[int], list[str]]:
    """``d[s, i] = worse[s][i] - better[s][i]`` over the seeds both have, images sorted by name.

    Args:
        worse, better: seed -> image name -> metric value.

    Returns:
        ``(d, seeds, images)`` with ``d`` of shape (seeds, images).

    Raises:
        InputError: no common seed, or a seed whose two image sets differ (not paired).
    """
    seeds = sorted(set(worse) & set(better))
    if not seeds:
        raise InputError("the two models have no seed in common")
    images = sorted(worse[seeds[0]])
    for s in seeds:
        if sorted(worse[s]) != images or sorted(better[s]) != images:
            raise InputError(f"seed {s}: the two models were scored on different images")
    d = np.array([[worse[s][i] - better[s][i] for i in images] for s in seeds], dtype=np.float64)
    return d, seeds, images


def sign_flip_p(units: np.ndarray, *, exact_max: int = 16, draws: int = 20_000, seed: int = 0) -> float:
    """Two-sided sign-flip permutation p-value of the mean of ``units``.

    With ``T(e) = |mean(e * u)|`` for sign vectors ``e`` in {-1, +1}^n:

    * exact (``n <= exact_max``): ``p = #{e : T(e) >= T(1)} / 2**n`` over all ``2**n`` vectors
      (the identity and its mirror are among them, so ``p >= 2 / 2**n``);
    * otherwise Monte Carlo: ``p = (1 + #{draws with T(e) >= T(1)}) / (1 + draws)``.

    A small relative tolerance counts ties as extreme (conservative).
    """
    u = np.asarray(units, dtype=np.float64).ravel()
    n = u.size
    if n == 0:
        raise InputError("no units to test")
    observed = abs(u.mean())
    tol = 1e-12 * max(1.0, float(np.abs(u).max()))
    if n <= exact_max:
        signs = np.array(list(itertools.product((1.0, -1.0), repeat=n)))
        return float(np.mean(np.abs(signs @ u) / n >= observed - tol))
    rng = np.random.default_rng(seed)
    hits = 0
    for start in range(0, draws, 2000):
        signs = rng.choice((-1.0, 1.0), size=(min(2000, draws - start), n))
        hits += int(np.sum(np.abs(signs @ u) / n >= observed - tol))
    return (1 + hits) / (1 + draws)


def bootstrap_ci(d: np.ndarray, *, level: float = 0.95, draws: int = 4000, seed: int = 0) -> tuple[float, float]:
    """Percentile interval of ``mean(d)`` from the crossed two-way bootstrap.

    Each replicate ``b`` draws seed indices ``S_b`` (``S`` of them) and image indices ``I_b``
    (``n`` of them) with replacement, the same images for every drawn seed, and computes
    ``mean(d[S_b][:, I_b])``; the interval is the ``(1 - level) / 2`` and ``(1 + level) / 2``
    quantiles of the replicates.
    """
    d = np.asarray(d, dtype=np.float64)
    if d.ndim != 2 or d.size == 0:
        raise InputError(f"expected a non-empty (seeds, images) array, got shape {d.shape}")
    rng = np.random.default_rng(seed)
    n_seeds, n_images = d.shape
    reps = np.empty(draws)
    for start in range(0, draws, 500):
        k = min(500, draws - start)
        si = rng.integers(0, n_seeds, size=(k, n_seeds))
        ii = rng.integers(0, n_images, size=(k, n_images))
        reps[start : start + k] = d[si[:, :, None], ii[:, None, :]].mean(axis=(1, 2))
    lo, hi = np.quantile(reps, [(1 - level) / 2, (1 + level) / 2])
    return float(lo), float(hi)


def verdict(ci: Sequence[float], p: float, alpha: float = ALPHA) -> str:
    """``supported`` (p < alpha, interval above 0), ``contradicted`` (p < alpha, below 0), or ``not separated``."""
    if p < alpha and ci[0] > 0:
        return "supported"
    if p < alpha and ci[1] < 0:
        return "contradicted"
    return "not separated"


def compare(d: np.ndarray, seeds: Sequence[int], *, alpha: float = ALPHA, seed: int = 0) -> dict[str, object]:
    """The whole paired procedure (module docstring) on ``d`` of shape (seeds, images).

    Returns ``mean_diff``, ``ci95``, ``p``, ``test_units`` (``"seeds"`` or ``"seed-image pairs"``),
    ``per_seed`` (seed -> mean difference), ``seeds_agreeing`` (seeds with a positive mean
    difference), ``n_seeds``, ``n_pairs`` and ``verdict``.
    """
    d = np.asarray(d, dtype=np.float64)
    if d.ndim != 2 or d.shape[0] != len(seeds):
        raise InputError(f"expected shape ({len(seeds)}, images), got {d.shape}")
    per_seed = d.mean(axis=1)
    by_seed = len(seeds) >= MIN_SEED_UNITS
    p = sign_flip_p(per_seed if by_seed else d.ravel(), seed=seed)
    ci = bootstrap_ci(d, seed=seed)
    return {
        "mean_diff": float(d.mean()),
        "ci95": [ci[0], ci[1]],
        "p": p,
        "test_units": "seeds" if by_seed else "seed-image pairs",
        "per_seed": {str(s): float(m) for s, m in zip(seeds, per_seed, strict=True)},
        "seeds_agreeing": int(np.sum(per_seed > 0)),
        "n_seeds": len(seeds),
        "n_pairs": int(d.size),
        "verdict": verdict(ci, p, alpha),
    }
