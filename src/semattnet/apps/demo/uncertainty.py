"""The demo's uncertainty scores: sparsification curves, AUSE and AURG of each method's per-pixel uncertainty.

Every learned model's completions carry :func:`semattnet.models.uncertainty.depth_uncertainty` (through
:meth:`~semattnet.inference.DepthCompleter.run`), the classical completion its own proxy
(:func:`semattnet.baselines.classical.classical_uncertainty`). Each is scored on the held-out scenes by
:class:`semattnet.evaluation.sparsification.Sparsification` (per-scene curves averaged, 100 fractions,
normalised by the metric of all the pixels), once per training seed; the headline is the mean over seeds.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch

from semattnet.apps.demo.recipe import LABELS
from semattnet.apps.experiment import HeldOut
from semattnet.baselines.classical import classical_uncertainty
from semattnet.evaluation.sparsification import Sparsification, summary

__all__ = ["UNCERTAINTY_FIGURE", "classical_uncertainties", "score_uncertainty", "uncertainty_report"]

#: The sparsification curves' picture, under the report's folder.
UNCERTAINTY_FIGURE = "pictures/sparsification.png"

#: method -> seed -> scene -> (H, W) array
BySeed = dict[str, dict[int, dict[str, np.ndarray]]]


def classical_uncertainties(held: HeldOut, depths: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """scene -> the classical completion's uncertainty (metres), from its ``depths`` (scene -> completion)."""
    return {
        n: classical_uncertainty(smp["sparse"][None], torch.from_numpy(depths[n])[None, None])[0, 0].numpy()
        for n, smp in zip(held.names, held.samples, strict=True)
    }


def score_uncertainty(preds: BySeed, uncertainty: BySeed, held: HeldOut) -> dict[str, dict[str, Any]]:
    """method -> ``{"label", "ause_rmse", "aurg_rmse", "ause_mae", "aurg_mae"`` (mean over seeds),
    ``"per_seed": {seed: the same four}``, ``"curves"``: the mean curves (lists, for the figure)}; the label is the
    method's key where :data:`LABELS` has none."""
    out: dict[str, dict[str, Any]] = {}
    for method, seeds in uncertainty.items():
        per_seed: dict[str, dict[str, float]] = {}
        curves: list[dict[str, np.ndarray]] = []
        for seed, uncs in seeds.items():
            acc = Sparsification()
            for n in held.names:
                acc.add(preds[method][seed][n], held.gts[n], uncs[n])
            per_seed[str(seed)] = acc.compute()
            curves.append(acc.curves())
        mean_curves = {k: np.mean([c[k] for c in curves], axis=0) for k in curves[0]}
        # the areas are linear in the curve: the AUSE / AURG of the mean curves are the means over seeds
        out[method] = {
            "label": LABELS.get(method, method),
            **summary(mean_curves),
            "per_seed": per_seed,
            "curves": {k: [round(float(x), 6) for x in v] for k, v in mean_curves.items()},
        }
    return out


def uncertainty_report(scores: dict[str, dict[str, Any]], pictures: Path) -> tuple[tuple[str, str], list[str]]:
    """The report's figure (caption, path) of the mean curves and one sentence per method with its AUSE / AURG."""
    from semattnet.evaluation.sparsification import figure_data
    from semattnet.viz.curves import plot_sparsification

    short = {m: LABELS[m].split(" (")[0] for m in scores}
    curves = {short[m]: figure_data({k: np.asarray(v) for k, v in s["curves"].items()}) for m, s in scores.items()}
    plot_sparsification(
        curves,
        pictures / Path(UNCERTAINTY_FIGURE).name,
        title="Sparsification on the held-out scenes (mean over seeds)",
    )
    caption = (
        "Sparsification curves of each method's per-pixel uncertainty on the held-out scenes: the metric "
        "of the pixels left after removing the most uncertain ones (solid), the oracle that removes the "
        "largest errors first (dashed), a random removal (dotted); normalised by the metric of all pixels, "
        "mean over seeds (docs/guides/uncertainty.md)"
    )
    lines = []
    for m, s in scores.items():
        runs = list(s["per_seed"].values())
        seeds = "; ".join(f"seed {k}: {v['ause_rmse']:.3f} / {v['aurg_rmse']:.3f}" for k, v in s["per_seed"].items())
        how = f"mean over seeds ({seeds})" if any(r != runs[0] for r in runs) else "the same for every seed"
        lines.append(
            f"Uncertainty of {short[m]}, AUSE / AURG of RMSE: {s['ause_rmse']:.3f} / {s['aurg_rmse']:.3f}, "
            f"{how}; lower AUSE and higher AURG rank the errors better."
        )
    return (caption, UNCERTAINTY_FIGURE), lines
