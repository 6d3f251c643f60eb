"""Training curves from a run's ``log.csv``; sparsification curves of a per-pixel uncertainty."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

__all__ = ["plot_sparsification", "plot_training_curves"]


def plot_training_curves(csv_path: str | Path, out_path: str | Path) -> Path | None:
    """Training loss and validation RMSE against steps, from a run's ``log.csv``."""
    import csv

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = list(csv.DictReader(open(csv_path))) if Path(csv_path).exists() else []
    if not rows:
        return None
    train = [(int(r["step"]), float(r["loss"])) for r in rows if r["split"] == "train" and r["loss"]]
    val = [(int(r["step"]), float(r["rmse_mm"])) for r in rows if r["split"] != "train" and r["rmse_mm"]]
    fig, ax = plt.subplots(figsize=(7, 3.5))
    if train:
        ax.plot(*zip(*train, strict=True), label="training loss (m²)", color="tab:blue")
        ax.set_yscale("log")
    ax.set_xlabel("step")
    ax.set_ylabel("loss")
    if val:
        ax2 = ax.twinx()
        ax2.plot(*zip(*val, strict=True), "o-", label="validation RMSE (mm)", color="tab:red")
        ax2.set_ylabel("RMSE (mm)")
        ax2.legend(loc="upper center")
    ax.legend(loc="upper right")
    fig.tight_layout()
    out_path = Path(out_path)
    fig.savefig(out_path, dpi=100)
    plt.close(fig)
    return out_path


def plot_sparsification(
    curves: Mapping[str, Mapping[str, np.ndarray | float]],
    out_path: str | Path,
    metrics: tuple[str, ...] = ("rmse", "mae"),
    title: str = "",
) -> Path:
    """One panel per metric: each method's normalised sparsification curve (solid) and its oracle (dashed),
    a random ordering's (the constant 1, dotted), AUSE and AURG in the legend.

    ``curves``: method label -> :func:`semattnet.evaluation.sparsification.figure_data` (``fractions``,
    ``{metric}_curve``, ``{metric}_oracle``, ``ause_{metric}``, ``aurg_{metric}``): the figure draws, the
    evaluation computes.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(metrics), figsize=(5.5 * len(metrics), 4), squeeze=False)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, metric in zip(axes[0], metrics, strict=True):
        for k, (label, c) in enumerate(curves.items()):
            if f"{metric}_curve" not in c:
                continue
            curve, oracle, colour = c[f"{metric}_curve"], c[f"{metric}_oracle"], colours[k % len(colours)]
            r, areas = c["fractions"], f"AUSE {float(c[f'ause_{metric}']):.3f}, AURG {float(c[f'aurg_{metric}']):.3f}"
            ax.plot(r, curve, "-", color=colour, label=f"{label} ({areas})")
            ax.plot(r, oracle, "--", color=colour, alpha=0.7)
        ax.axhline(1.0, color="grey", linestyle=":", label="random (expected)")
        ax.set_xlabel("fraction of pixels removed (most uncertain first)")
        ax.set_ylabel(f"{metric.upper()} of the rest / {metric.upper()} of all")
        ax.set_title(f"{metric.upper()}: solid = uncertainty, dashed = oracle")
        ax.legend(fontsize=7, loc="lower left")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    out_path = Path(out_path)
    fig.savefig(out_path, dpi=100)
    plt.close(fig)
    return out_path
