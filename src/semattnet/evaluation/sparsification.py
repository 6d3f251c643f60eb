"""How well a per-pixel uncertainty ranks the errors: sparsification curves, AUSE and AURG.

The protocol of pNCNN (Eldesokey et al., "Uncertainty-Aware CNNs for Depth Completion: Uncertainty
from Beginning to End", CVPR 2020), after Ilg et al. (ECCV 2018):

* **sparsification curve**: remove the pixels in order of decreasing predicted uncertainty, a fraction
  ``r`` in ``0, 1/S, ..., (S-1)/S`` (``S = steps``, 100 by default: 0 ... 0.99), and score the pixels
  left (RMSE or MAE). Removing ``r`` of ``n`` pixels removes ``floor(r n)`` of them (exact integers).
  Pixels of equal uncertainty are removed in random order: the curve takes its expected value (a tied
  group cut in part contributes its mean error per pixel kept), so no raster order biases it;
* **normalised**: every curve is divided by its value at ``r = 0``, the metric of all the pixels, the
  same for every ordering (pNCNN's convention; a perfect prediction gives a curve of zeros);
* **oracle**: the same with the pixels removed in order of decreasing true error, the best any
  uncertainty can do;
* **AUSE**: the area between the curve and the oracle's, ``int (curve - oracle) dr`` by the trapezoid
  rule over the fractions (0 ... 0.99); 0 is perfect, smaller is better;
* **AURG**: the area between a random ordering and the curve, ``int (curve(0) - curve) dr``: a random
  removal keeps, in expectation, the metric of all the pixels (exactly for MAE and for RMSE's mean
  square), a constant ``curve(0)``; positive means better than random.

Over a data set (:class:`Sparsification`), the curves are computed per frame and averaged with equal
weight per frame, as the KITTI metrics are (and as pNCNN's ``sparsification_plot.py`` does over images;
its ``eval_ause`` instead pools the pixels of all images into one curve: :func:`sparsification_curve`
on the concatenated pixels gives that). As both areas are linear in the curve, the AUSE of the mean
curves is the mean of the per-frame AUSE.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import torch

from semattnet._errors import InputError

__all__ = [
    "CURVE_METRICS",
    "Sparsification",
    "aurg",
    "ause",
    "figure_data",
    "fractions",
    "oracle_curve",
    "sparsification_curve",
    "summary",
]

#: The metrics a curve can score: name -> per-pixel value from the error e (the mean of it, then ``root``).
CURVE_METRICS = ("rmse", "mae")


def fractions(steps: int = 100) -> np.ndarray:
    """The removed fractions ``0, 1/steps, ..., (steps - 1)/steps`` (0 ... 0.99 for 100 steps)."""
    if steps < 2:
        raise InputError(f"steps must be at least 2, got {steps}")
    return np.arange(steps, dtype=np.float64) / steps


def _per_pixel(error: torch.Tensor, metric: str) -> torch.Tensor:
    if metric == "rmse":
        return error.double() ** 2
    if metric == "mae":
        return error.double().abs()
    raise InputError(f"unknown metric {metric!r}; one of {CURVE_METRICS}")


def sparsification_curve(
    error: torch.Tensor | np.ndarray,
    uncertainty: torch.Tensor | np.ndarray,
    metric: str = "rmse",
    steps: int = 100,
    normalize: bool = True,
) -> np.ndarray:
    """The metric of the pixels left after removing the most uncertain ``r`` of them, for each of
    :func:`fractions` (``steps`` values), normalised by the value at ``r = 0`` unless ``normalize=False``.

    Args:
        error: per-pixel error ``pred - gt`` (any shape; only the pixels to score).
        uncertainty: per-pixel uncertainty, same shape; ties are removed in random order (expected value).
        metric: ``rmse`` or ``mae``.
    """
    e = torch.as_tensor(np.asarray(error) if isinstance(error, np.ndarray) else error).flatten()
    u = torch.as_tensor(np.asarray(uncertainty) if isinstance(uncertainty, np.ndarray) else uncertainty).flatten()
    if e.shape != u.shape:
        raise InputError(f"error and uncertainty must have the same size, got {e.numel()} and {u.numel()}")
    n = e.numel()
    if n == 0:
        raise InputError("no pixels to score")
    value = _per_pixel(e, metric).cpu()
    u = u.double().cpu()
    order = torch.argsort(u, stable=True)  # the least uncertain first: the pixels kept longest
    u_sorted, v_sorted = u[order], value[order]
    cum = torch.cat((torch.zeros(1, dtype=torch.float64), v_sorted.cumsum(0)))
    # tied groups: [start, end) in the sorted order
    _, counts = torch.unique_consecutive(u_sorted, return_counts=True)
    ends = counts.cumsum(0)
    starts = ends - counts
    kept = n - (torch.arange(steps, dtype=torch.int64) * n) // steps  # n - floor(r n)
    group = torch.searchsorted(ends, kept, right=False)  # the group holding the last kept pixel
    s, e_ = starts[group], ends[group]
    group_mean = (cum[e_] - cum[s]) / (e_ - s).double()
    total = cum[s] + (kept - s).double() * group_mean
    mean = total / kept.double()
    curve = mean.sqrt() if metric == "rmse" else mean
    out = curve.numpy()
    if normalize:
        out = out / out[0] if out[0] > 0 else np.zeros_like(out)
    return out


def oracle_curve(
    error: torch.Tensor | np.ndarray, metric: str = "rmse", steps: int = 100, normalize: bool = True
) -> np.ndarray:
    """:func:`sparsification_curve` with the pixels removed in order of decreasing true error (the best ordering)."""
    e = torch.as_tensor(np.asarray(error) if isinstance(error, np.ndarray) else error)
    return sparsification_curve(e, e.double().abs(), metric, steps, normalize)


def _trapezoid(y: np.ndarray) -> float:
    """The trapezoid rule over :func:`fractions` (``len(y)`` of them)."""
    return float(((y[1:] + y[:-1]) / 2).sum() / len(y))


def ause(curve: np.ndarray, oracle: np.ndarray) -> float:
    """Area Under the Sparsification Error: ``int (curve - oracle) dr`` over the fractions (trapezoid rule)."""
    c, o = np.asarray(curve, dtype=np.float64), np.asarray(oracle, dtype=np.float64)
    return _trapezoid(c - o)


def aurg(curve: np.ndarray) -> float:
    """Area Under the Random Gain: ``int (curve(0) - curve) dr``, a random ordering's expected curve being the
    constant ``curve(0)``; positive when the ordering beats random."""
    c = np.asarray(curve, dtype=np.float64)
    return _trapezoid(c[0] - c)


@dataclass
class Sparsification:
    """Sparsification curves over frames: :meth:`add` each frame's prediction, ground truth and uncertainty;
    :meth:`compute` the per-frame curves averaged (equal weight per frame), the oracle's, AUSE and AURG.

    Pixels count where ``gt > 0`` (and the uncertainty is finite); frames without any are skipped.
    """

    steps: int = 100
    metrics: tuple[str, ...] = CURVE_METRICS
    frames: int = 0
    _sums: dict[str, np.ndarray] = field(default_factory=dict, repr=False)

    def add(
        self, pred: torch.Tensor | np.ndarray, gt: torch.Tensor | np.ndarray, uncertainty: torch.Tensor | np.ndarray
    ) -> None:
        """One frame: ``pred``, ``gt`` and ``uncertainty`` of the same shape (metres; gt 0 = none)."""
        p, g, u = (torch.as_tensor(np.asarray(a)) if isinstance(a, np.ndarray) else a for a in (pred, gt, uncertainty))
        if not (p.shape == g.shape == u.shape):
            raise InputError(f"pred, gt and uncertainty must have one shape, got {p.shape}, {g.shape}, {u.shape}")
        valid = (g > 0) & torch.isfinite(u)
        if not bool(valid.any()):
            return
        err = (p.double() - g.double())[valid]
        unc = u[valid]
        for m in self.metrics:
            for kind, curve in (
                ("curve", sparsification_curve(err, unc, m, self.steps)),
                ("oracle", oracle_curve(err, m, self.steps)),
            ):
                key = f"{m}_{kind}"
                self._sums[key] = self._sums.get(key, 0.0) + curve
        self.frames += 1

    def reduce(self) -> None:
        """Sum the curves and frame counts over DDP ranks (call on every rank, all with the same metrics)."""
        if not (torch.distributed.is_available() and torch.distributed.is_initialized()):
            return
        keys = [f"{m}_{kind}" for m in self.metrics for kind in ("curve", "oracle")]
        flat = [self._sums.get(k, np.zeros(self.steps)) for k in keys]
        t = torch.from_numpy(np.concatenate([*flat, [float(self.frames)]]))
        if torch.distributed.get_backend() == "nccl":
            t = t.cuda()
        torch.distributed.all_reduce(t)
        values = t.cpu().numpy()
        self.frames = int(values[-1] + 0.5)
        self._sums = {k: values[i * self.steps : (i + 1) * self.steps].copy() for i, k in enumerate(keys)}

    def curves(self) -> dict[str, np.ndarray]:
        """``{metric}_curve`` and ``{metric}_oracle``: the mean normalised curves (empty before any frame)."""
        return {k: v / self.frames for k, v in self._sums.items()} if self.frames else {}

    def compute(self) -> dict[str, float]:
        """``ause_{metric}`` and ``aurg_{metric}`` for each metric (empty before any frame)."""
        return summary(self.curves(), self.metrics)


def summary(curves: Mapping[str, np.ndarray], metrics: tuple[str, ...] = CURVE_METRICS) -> dict[str, float]:
    """``ause_{m}`` and ``aurg_{m}`` from mean curves ``{m}_curve`` / ``{m}_oracle``
    (as :meth:`Sparsification.curves` returns them)."""
    out: dict[str, float] = {}
    for m in metrics:
        if f"{m}_curve" in curves:
            out[f"ause_{m}"] = ause(curves[f"{m}_curve"], curves[f"{m}_oracle"])
            out[f"aurg_{m}"] = aurg(curves[f"{m}_curve"])
    return out


def figure_data(
    curves: Mapping[str, np.ndarray], metrics: tuple[str, ...] = CURVE_METRICS
) -> dict[str, np.ndarray | float]:
    """What :func:`semattnet.viz.curves.plot_sparsification` draws for one method: the mean curves, their
    ``fractions`` (the x axis) and :func:`summary`'s AUSE / AURG."""
    steps = len(next(iter(curves.values())))
    return {**curves, "fractions": fractions(steps), **summary(curves, metrics)}
