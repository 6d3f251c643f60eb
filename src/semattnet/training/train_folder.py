"""A training run's folder: the files a run writes (:data:`RUN_FILES`), the refusal of a folder that holds a run
(or, with ``--overwrite``, the replacement of it at the new run's first state: :mod:`semattnet._utils.run_folder`),
and the log rows a killed run wrote after its last state."""

from __future__ import annotations

import csv
import os
import time
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

from semattnet._utils.atomic import atomic_path

if TYPE_CHECKING:
    from torch.utils.tensorboard import SummaryWriter

__all__ = ["LOG_FIELDS", "RUN_FILES", "prepare_run_folder", "run_files", "truncate_log", "write_log_row"]

#: What a run writes into its folder (``--overwrite`` removes exactly these, nothing else).
RUN_FILES = ("config.json", "log.csv", "curves.png", "checkpoints/last.pt", "checkpoints/best.pt")


def truncate_log(path: Path, step: int) -> None:
    """Drop the ``log.csv`` rows written after ``step`` (by a run killed after its last checkpoint):
    a resumed run writes them again, so the log never holds a step twice."""
    if not path.is_file():
        return
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    if len(rows) < 2 or "step" not in rows[0]:
        return
    col = rows[0].index("step")
    kept = [rows[0]] + [r for r in rows[1:] if len(r) > col and r[col].isdigit() and int(r[col]) <= step]
    if len(kept) == len(rows):
        return
    with atomic_path(path, suffix=".csv") as tmp, open(tmp, "w", newline="") as f:
        csv.writer(f).writerows(kept)


def run_files(folder: Path) -> list[str]:
    """The files of a run in ``folder`` (:data:`RUN_FILES`, ``checkpoints/step-*.pt``, ``tensorboard/``), relative."""
    steps = [f"checkpoints/{p.name}" for p in sorted((folder / "checkpoints").glob("step-*.pt"))]
    return [f for f in (*RUN_FILES, *steps, "tensorboard") if (folder / f).exists() or (folder / f).is_symlink()]


def prepare_run_folder(out: str | os.PathLike[str], overwrite: bool = False) -> bool:
    """A new run (not ``resume``) refuses a folder that already holds a run. With ``overwrite`` it removes nothing:
    returns whether there is one, which the new run replaces at its first state (:meth:`Trainer.save`); the earlier
    run's files (:func:`run_files`) stay until then, and only they go."""
    existing = run_files(Path(out))
    if any(f != "tensorboard" for f in existing) and not overwrite:
        raise FileExistsError(
            f"{out} already holds a run ({Path(out) / existing[0]} exists); pass --resume to continue "
            "it or --overwrite to start over"
        )
    return overwrite and bool(existing)


#: The columns of ``log.csv``.
LOG_FIELDS = ("time", "epoch", "step", "split", "loss", "lr", "rmse_mm", "mae_mm", "irmse_per_km", "imae_per_km")


def write_log_row(path: Path, row: Mapping[str, float | str], tb: SummaryWriter | None = None) -> None:
    """Append ``row`` (stamped with the time) to the run's ``log.csv`` at ``path`` (the header first, in a new file),
    and its numbers to TensorBoard (``tb``) under ``SPLIT/KEY``."""
    new = not path.exists()
    with open(path, "a", newline="") as f:
        w = csv.DictWriter(f, fieldnames=LOG_FIELDS, extrasaction="ignore")
        if new:
            w.writeheader()
        w.writerow({"time": f"{time.time():.1f}", **row})
    if tb is not None:
        for key in LOG_FIELDS[4:]:
            if row.get(key) not in (None, ""):
                tb.add_scalar(f"{row['split']}/{key}", float(row[key]), int(row["step"]))
