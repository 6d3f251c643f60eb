"""The figure at the top of the README and the docs home (``docs/sparsity-sweep.png``), remade by one command.

``make figures`` (``python scripts/docs-figures.py --out docs``) writes it from the trained weights that ship
with the package (``semattnet-demo-ref-seed0`` / ``-seed1``, :mod:`semattnet.weights.packed`) and the classical
completion, on the demo's 16 held-out scenes (synthetic, 96x320, "realistic" style, data seed 0; the
reference checkpoints were trained on other scenes, data seed 1000):

* left: RMSE against input density, the LiDAR thinned to fewer beams and to fewer random points
  (:func:`semattnet.evaluation.sparsity.run_sparsity_sweep`);
* right: the sparsification curves (RMSE) of each method's per-pixel uncertainty at full density, with the
  oracle's (:class:`semattnet.evaluation.sparsification.Sparsification`; AUSE and AURG in the legend).

The numbers behind it go to ``sparsity-sweep.json`` beside the picture, so the docs quote what was drawn.
"""

from __future__ import annotations

import json
import textwrap
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, TypedDict

import numpy as np

from semattnet._errors import InputError
from semattnet._utils.atomic import atomic_path
from semattnet.apps.demo.recipe import DemoSettings
from semattnet.apps.experiment import make_synthetic
from semattnet.evaluation.sparsification import Sparsification
from semattnet.evaluation.sparsity import SweepRow, run_sparsity_sweep
from semattnet.evaluation.split import eval_dataset
from semattnet.inference.backends import needs_semantic
from semattnet.inference.contract import Completer

__all__ = ["FIGURE_COMMAND", "FIGURE_WEIGHTS", "SETTINGS", "make_front_figure", "plot_front", "uncertainty_curves"]

#: The documented command that remakes the figure.
FIGURE_COMMAND = "make figures"
#: The thinning settings of the left panel (``keep=1`` is ``beams=64``: the full scan).
SETTINGS = ("beams=64", "beams=32", "beams=16", "beams=8", "keep=0.5", "keep=0.1")
#: The shipped trained weights drawn, by label.
FIGURE_WEIGHTS = {
    "SemAttNet reference, seed 0": "semattnet-demo-ref-seed0",
    "SemAttNet reference, seed 1": "semattnet-demo-ref-seed1",
}


class FrontNumbers(TypedDict):
    """What ``sparsity-sweep.json`` holds (and :func:`make_front_figure` returns)."""

    command: str
    scenes: int
    size: list[int]
    weights: dict[str, str]
    sweep: list[SweepRow]  # rows of :func:`~semattnet.evaluation.sparsity.run_sparsity_sweep`
    uncertainty: dict[str, dict[str, float]]  # method -> AUSE / AURG
    curves: dict[str, dict[str, list[float]]]  # method -> RMSE sparsification curves


def _completers(device: str) -> dict[str, Completer]:
    from semattnet.baselines.classical import ClassicalCompleter
    from semattnet.inference.backends import EngineSpec
    from semattnet.inference.completer import DepthCompleter
    from semattnet.weights import from_pretrained

    found: dict[str, Completer] = {
        label: DepthCompleter(from_pretrained(name), EngineSpec(device=device))
        for label, name in FIGURE_WEIGHTS.items()
    }
    return found | {"classical completion": ClassicalCompleter()}


def uncertainty_curves(
    data_root: Path, completers: dict[str, Completer], split: str = "val_select", max_frames: int | None = None
) -> dict[str, Sparsification]:
    """Each completer's :class:`Sparsification` of its ``Completion.uncertainty`` over the frames of ``split``."""
    ds = eval_dataset(data_root, split)
    found = {name: Sparsification() for name in completers}
    for i in range(min(len(ds), max_frames or len(ds))):
        s = ds.load(i)
        if s.gt is None:
            continue
        for name, completer in completers.items():
            c = completer(s.rgb, s.sparse, s.semantic if needs_semantic(completer) else None)
            if c.uncertainty is None:
                raise InputError(f"{name}: gives no uncertainty to draw sparsification curves of")
            found[name].add(np.asarray(c.depth, np.float32), s.gt, c.uncertainty)
    return found


def plot_front(rows: Sequence[Mapping[str, Any]], curves: dict[str, Sparsification], path: Path, caption: str) -> Path:
    """Two panels: RMSE against density (beams solid, random points dashed); sparsification curves (RMSE)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 3.8), dpi=90)
    for i, method in enumerate(curves):
        for kind, style in (("beams", "o-"), ("keep", "s--")):
            mine = [r for r in rows if r["method"] == method]
            pts = sorted(
                (r["density"], r["rmse_mm"] / 1000)
                for r in mine
                if r["setting"].startswith(kind) or r["setting"] == "beams=64"
            )
            label = f"{method} ({'fewer beams' if kind == 'beams' else 'random points'})"
            left.plot(*zip(*pts, strict=True), style, color=f"C{i}", label=label, ms=4)
        c, summary = curves[method].curves(), curves[method].compute()
        x = np.arange(len(c["rmse_curve"])) / len(c["rmse_curve"])
        right.plot(
            x,
            c["rmse_curve"],
            "-",
            color=f"C{i}",
            label=f"{method}: AUSE {summary['ause_rmse']:.3f}, AURG {summary['aurg_rmse']:.3f}",
        )
        right.plot(x, c["rmse_oracle"], ":", color=f"C{i}", lw=1)
    left.set(xscale="log", xlabel="input density (valid pixels)", ylabel="RMSE [m]", title="Sparser LiDAR")
    left.xaxis.set_major_locator(matplotlib.ticker.LogLocator(subs=(1.0, 2.0, 5.0)))
    left.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{100 * v:g} %"))
    left.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    right.set(
        xlabel="fraction of pixels removed, most uncertain first",
        ylabel="RMSE / RMSE of all pixels",
        title="Per-pixel uncertainty (dotted: oracle)",
        ylim=(0, None),
    )
    for ax in (left, right):
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=6.5)
    fig.text(0.5, 0.01, textwrap.fill(caption, 150), ha="center", fontsize=7)
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return path


def _rmse_curves(s: Sparsification) -> dict[str, list[float]]:
    return {k: [round(float(v), 5) for v in a] for k, a in s.curves().items() if k.startswith("rmse")}


def make_front_figure(
    out: Path,
    work: Path,
    settings: tuple[str, ...] = SETTINGS,
    device: str = "cpu",
    demo: DemoSettings | None = None,
    log: Callable[[str], object] = print,
) -> FrontNumbers:
    """Write ``out/sparsity-sweep.png`` and ``out/sparsity-sweep.json`` from the demo's held-out scenes (made in
    ``work``); returns the numbers."""
    s = demo or DemoSettings()
    log(f"scenes: {s.eval_frames} held-out synthetic scenes at {s.size[0]}x{s.size[1]} (seed {s.seed}) ...")
    make_synthetic(work / "data", s.train_frames, s.eval_frames, s.size, s.seed, style=s.style)
    completers = _completers(device)
    log(f"sweep: {', '.join(settings)} ...")
    rows = run_sparsity_sweep(work / "data", "val_select", settings, completers, work / "sweep")
    log("uncertainty: sparsification curves at full density ...")
    curves = uncertainty_curves(work / "data", completers)
    caption = (
        f"The shipped reference checkpoints (SemAttNet, width 1/8, trained on synthetic scenes) and the "
        f"classical completion on the demo's {s.eval_frames} held-out synthetic scenes; remade by "
        f"`{FIGURE_COMMAND}`."
    )
    out.mkdir(parents=True, exist_ok=True)
    plot_front(rows, curves, out / "sparsity-sweep.png", caption)
    numbers = FrontNumbers(
        command=FIGURE_COMMAND,
        scenes=s.eval_frames,
        size=list(s.size),
        weights=FIGURE_WEIGHTS,
        sweep=rows,
        uncertainty={name: c.compute() for name, c in curves.items()},
        curves={name: _rmse_curves(c) for name, c in curves.items()},
    )
    with atomic_path(out / "sparsity-sweep.json") as tmp:
        tmp.write_text(json.dumps(numbers, indent=1) + "\n")
    return numbers
