"""Robustness to sparser LiDARs: score completers on inputs thinned to fewer beams or fewer points.

Settings are strings: ``beams=N`` keeps every ``64 // N``-th line of the projected map
(:func:`~semattnet.geometry.sparsify.keep_row_bands`, as the scan itself is not in the splits) and
``keep=R`` keeps a random fraction ``R`` of the valid pixels (:func:`~semattnet.geometry.sparsify.keep_random`,
seeded per frame). Every method sees the same thinned inputs; every score goes through
:class:`~semattnet.evaluation.metrics.KittiMetrics` (the devkit's rule).
"""

from __future__ import annotations

import csv
import json
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import TYPE_CHECKING, TypedDict

import numpy as np
import torch

from semattnet._errors import SemAttNetError
from semattnet.evaluation.protocols import protocol_metrics
from semattnet.evaluation.split import eval_dataset, prepare_out, refuse_listed_inputs
from semattnet.geometry.sparsify import keep_random, keep_row_bands
from semattnet.inference.backends import needs_semantic
from semattnet.inference.pipeline import Completer

if TYPE_CHECKING:
    from semattnet.data.datasets import SplitDataset

__all__ = [
    "FIELDS",
    "SparsityError",
    "SweepRow",
    "format_sweep",
    "parse_settings",
    "plot_sweep",
    "run_sparsity_sweep",
    "sweep_model",
    "thin",
]

FIELDS = ("method", "setting", "density", "rmse_mm", "mae_mm", "irmse_per_km", "imae_per_km")
NUM_BEAMS = 64


class SweepRow(TypedDict):
    """One row of the sweep (:data:`FIELDS`): a method under a setting, the input's mean density, four metrics."""

    method: str
    setting: str
    density: float
    rmse_mm: float
    mae_mm: float
    irmse_per_km: float
    imae_per_km: float


class SparsityError(SemAttNetError):
    """A sparsity setting that cannot be parsed."""


def parse_settings(texts: Iterable[str]) -> list[str]:
    """``["beams=64,32", "keep=1,0.5"]`` -> ``["beams=64", "beams=32", "keep=1", "keep=0.5"]`` (checked)."""
    out = []
    for text in texts:
        kind, sep, values = text.partition("=")
        if not sep or kind not in ("beams", "keep") or not values:
            raise SparsityError(f"bad sparsity setting {text!r}: expected beams=64,32,... or keep=1,0.5,...")
        for v in values.split(","):
            try:
                num = int(v) if kind == "beams" else float(v)
            except ValueError:
                raise SparsityError(f"bad value {v!r} in {text!r}: beams take integers, keep takes ratios") from None
            if kind == "beams" and (num <= 0 or NUM_BEAMS % num):
                raise SparsityError(f"beams={v}: must divide {NUM_BEAMS} (64, 32, 16, 8, 4, 2, 1)")
            if kind == "keep" and not 0.0 < num <= 1.0:
                raise SparsityError(f"keep={v}: must be in (0, 1]")
            out.append(f"{kind}={v}")
    if not out:
        raise SparsityError("no sparsity setting given")
    return out


def thin(sparse: np.ndarray, setting: str, seed: int = 0) -> np.ndarray:
    """The (H, W) sparse map in metres thinned as ``setting`` (one ``beams=N`` or ``keep=R``) says."""
    kind, _, value = setting.partition("=")
    if kind == "beams":
        return keep_row_bands(sparse, int(value), num_beams=NUM_BEAMS)
    if kind == "keep":
        return keep_random(np.asarray(sparse, np.float32), float(value), seed=seed, kind="map")
    raise SparsityError(f"bad sparsity setting {setting!r}")


def _score_setting(ds: SplitDataset, setting: str, completers: dict[str, Completer], seed: int,
                   max_frames: int | None, dataset: str = "kitti-dc") -> list[SweepRow]:  # fmt: skip
    """One row per method for one setting: mean density of the thinned input and the four metrics
    (under ``dataset``'s protocol: KITTI's devkit, NYU's or VOID's range)."""
    metrics = {name: protocol_metrics(dataset, keep_per_image=False) for name in completers}
    densities = []
    for i in range(min(len(ds), max_frames or len(ds))):
        s = ds.load(i)
        sparse = thin(s.sparse, setting, seed=seed + i)
        densities.append(float((sparse > 0).mean()))
        gt = torch.from_numpy(s.gt)[None, None]
        for name, completer in completers.items():
            sem = s.semantic if needs_semantic(completer) else None
            depth = completer(s.rgb, sparse, sem).depth
            metrics[name].update(torch.from_numpy(np.asarray(depth, np.float32))[None, None], gt)
    rows = []
    for name, m in metrics.items():
        r = m.compute()
        rows.append(
            SweepRow(
                method=name,
                setting=setting,
                density=float(np.mean(densities)),
                rmse_mm=r["rmse_mm"],
                mae_mm=r["mae_mm"],
                irmse_per_km=r["irmse_per_km"],
                imae_per_km=r["imae_per_km"],
            )
        )
    return rows


def _write_tables(out: Path, rows: list[SweepRow]) -> None:
    (out / "sparsity.json").write_text(json.dumps(rows, indent=2) + "\n")
    with open(out / "sparsity.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(FIELDS))
        writer.writeheader()
        writer.writerows(rows)


def plot_sweep(rows: list[SweepRow], path: Path) -> Path:
    """RMSE and MAE against input density (log x), one line per method and kind of setting."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.4), dpi=90)
    methods = list(dict.fromkeys(r["method"] for r in rows))
    for ax, key, label in zip(axes, ("rmse_mm", "mae_mm"), ("RMSE [mm]", "MAE [mm]"), strict=True):
        for i, method in enumerate(methods):
            for kind, style in (("beams", "o-"), ("keep", "s--")):
                pts = sorted((r["density"], r["rmse_mm" if key == "rmse_mm" else "mae_mm"]) for r in rows
                             if r["method"] == method
                             and r["setting"].startswith(kind))  # fmt: skip
                if pts:
                    ax.plot(*zip(*pts, strict=True), style, color=f"C{i}", label=f"{method} ({kind})")
        ax.set_xscale("log")
        ax.xaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
        ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{100 * v:g} %"))
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel("input density (valid pixels)")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def run_sparsity_sweep(
    data_root: str | Path,
    split: str,
    settings: Iterable[str],
    completers: dict[str, Completer],
    out_dir: str | Path,
    seed: int = 0,
    max_frames: int | None = None,
    overwrite: bool = False,
) -> list[SweepRow]:
    """Score every completer (``name -> completer(rgb, sparse, semantic) -> Completion``) on every
    setting of ``settings`` (strings, see :func:`parse_settings`) over the frames of ``split``.

    Writes ``sparsity.csv``, ``sparsity.json`` (rows with :data:`FIELDS`) and ``sparsity.png`` into
    ``out_dir``; returns the rows.
    """
    settings = parse_settings(settings)
    ds = eval_dataset(data_root, split)
    out = prepare_out(Path(out_dir), overwrite, [data_root])  # never inside the data
    refuse_listed_inputs(out, ds)
    return _sweep(ds, out, settings, completers, seed, max_frames)


def _sweep(ds: SplitDataset, out: Path, settings: list[str], completers: dict[str, Completer], seed: int,
           max_frames: int | None, dataset: str = "kitti-dc") -> list[SweepRow]:  # fmt: skip
    rows = [row for setting in settings for row in _score_setting(ds, setting, completers, seed, max_frames, dataset)]
    _write_tables(out, rows)
    plot_sweep(rows, out / "sparsity.png")
    return rows


def sweep_model(
    data_root: str | Path,
    split: str,
    settings: Iterable[str],
    model: torch.nn.Module | Callable[[], torch.nn.Module] | None,
    out_dir: str | Path,
    device: str = "auto",
    max_frames: int | None = None,
    overwrite: bool = False,
    dataset: str = "kitti-dc",
) -> list[SweepRow]:
    """:func:`run_sparsity_sweep` of ``model`` (as ``semattnet``; skipped when None; a function that loads
    it is called after the split and ``out_dir`` are checked) beside the classical baseline (as ``classical``)."""
    from semattnet.baselines.classical import ClassicalCompleter
    from semattnet.inference.completer import DepthCompleter

    settings = parse_settings(settings)
    ds = eval_dataset(data_root, split, dataset=dataset)
    out = prepare_out(Path(out_dir), overwrite, [data_root])  # never inside the data
    refuse_listed_inputs(out, ds)
    completers: dict[str, Completer] = {}
    if model is not None:
        net = model if isinstance(model, torch.nn.Module) else model()
        completers["semattnet"] = DepthCompleter(net, device=device)
    completers["classical"] = ClassicalCompleter()
    return _sweep(ds, out, settings, completers, 0, max_frames, dataset)


def format_sweep(rows: list[SweepRow]) -> str:
    """The sweep's rows as a text table (method, setting, density, the four metrics in KITTI units)."""
    lines = [f"{'method':>10} {'setting':>10} {'density':>8} {'RMSE':>8} {'MAE':>8} {'iRMSE':>7} {'iMAE':>6}"]
    for r in rows:
        lines.append(f"{r['method']:>10} {r['setting']:>10} {r['density']:8.4f} {r['rmse_mm']:8.1f} "
                     f"{r['mae_mm']:8.1f} {r['irmse_per_km']:7.2f} {r['imae_per_km']:6.2f}")  # fmt: skip
    return "\n".join(lines)
