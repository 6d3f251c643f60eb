"""Training curves from a run's ``log.csv``."""

from __future__ import annotations

from pathlib import Path

__all__ = ["plot_training_curves"]


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
