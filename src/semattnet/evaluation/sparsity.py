"""Robustness to sparser LiDARs: score completers on inputs thinned to fewer beams or fewer points.

Settings are strings: ``beams=N`` keeps every ``64 // N``-th line of the projected map
(:func:`~semattnet.geometry.sparsify.keep_row_bands`, as the scan itself is not in the splits) and
``keep=R`` keeps a random fraction ``R`` of the valid pixels (:func:`~semattnet.geometry.sparsify.keep_random`,
seeded per frame). Every method sees the same thinned inputs (:class:`ThinnedSource`). Each (setting, method)
is one run of the one frame loop (:func:`~semattnet.inference.pipeline.complete_frames`) scored by its metrics
sink (:class:`~semattnet.evaluation.sink.MetricsSink`: the protocol's metrics, KITTI's the devkit's rule, of
the prediction as its 16-bit PNG stores it, like ``evaluate``).
"""

from __future__ import annotations

import csv
import json
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TypedDict

import numpy as np
import torch

from semattnet._errors import SemAttNetError
from semattnet._utils.outputs import stage_folder
from semattnet.data.frames import Frame, FrameSource, IndexedSource
from semattnet.evaluation.protocols import eval_source, protocol_metrics
from semattnet.evaluation.sink import MetricsSink
from semattnet.evaluation.split import prepare_out, refuse_listed_inputs
from semattnet.geometry.sparsify import keep_random, keep_row_bands
from semattnet.inference.pipeline import Completer, OutputSpec, RunOptions, RunPlan, check_frames
from semattnet.inference.semantic import SemanticMaps
from semattnet.inference.sinks import Prediction, Sink

__all__ = [
    "FIELDS",
    "InputDensity",
    "SparsityError",
    "SweepRow",
    "ThinnedSource",
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


class ThinnedSource(IndexedSource):
    """``source``'s frames with their sparse maps thinned as ``setting`` says (:func:`thin`; one ``beams=N`` or
    ``keep=R``): the frame at position ``i`` of ``source.names`` with the seed ``seed + i``, so every method and
    every run sees the same points. The LiDAR points a frame carried are dropped (the thinned map no longer
    holds them all); everything else, inputs and checks included, is ``source``'s."""

    def __init__(self, source: FrameSource, setting: str, seed: int = 0) -> None:
        parsed = parse_settings([setting])
        if len(parsed) != 1:
            raise SparsityError(f"ThinnedSource takes one setting (beams=N or keep=R), got {setting!r}")
        self.setting = parsed[0]
        self.source, self.seed, self.names = source, seed, list(source.names)
        self.palette: str | None = source.info.palette
        self.position = {name: i for i, name in enumerate(self.names)}

    def load(self, name: str) -> Frame:
        frame = self.source.load(name)
        sparse = thin(frame.sparse, self.setting, seed=self.seed + self.position[name])
        return replace(frame, sparse=np.asarray(sparse, np.float32), points=None)

    def check(self, names: Sequence[str] | None = None) -> None:
        self.source.check(names)

    def inputs(self) -> list[Path]:
        return self.source.inputs()


@dataclass
class InputDensity(Sink):
    """Writes no file: the fraction of valid pixels of each completed frame's sparse input, in order."""

    values: list[float] = field(default_factory=list)

    def path(self, name: str) -> str | None:
        return None

    def write(self, stage: Path, pred: Prediction) -> None:
        self.values.append(float((pred.frame.sparse > 0).mean()))


def _quiet(line: str) -> None:
    """The loop's per-frame lines are not printed: the sweep reports its table."""


def _score_setting(
    source: FrameSource,
    setting: str,
    completers: dict[str, Completer],
    stage: Path,
    seed: int = 0,
    dataset: str = "kitti-dc",
    palette_mismatch: str = "refuse",
) -> list[SweepRow]:
    """One row per method for one setting, each method through the one frame loop
    (:func:`~semattnet.inference.pipeline.complete_frames`, into a run folder of ``stage``) on the same thinned
    frames (:class:`ThinnedSource`): the mean density of the thinned input and the four metrics of what the
    PNG stores (:class:`~.sink.MetricsSink`, under ``dataset``'s protocol: KITTI's devkit, NYU's or VOID's range)."""
    thinned = ThinnedSource(source, setting, seed)
    rows = []
    for k, (name, completer) in enumerate(completers.items()):
        scores = MetricsSink(metrics=protocol_metrics(dataset, keep_per_image=False))
        density = InputDensity()
        plan = RunPlan.trusted(thinned, [scores, density], stage / f"run{k}", RunOptions(on_error="stop"))
        plan.run(completer, semantic=SemanticMaps(mismatch=palette_mismatch), log=_quiet)
        r = scores.metrics.compute()
        rows.append(
            SweepRow(
                method=name,
                setting=setting,
                density=float(np.mean(density.values)),
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
                pts = sorted(
                    (r["density"], r["rmse_mm" if key == "rmse_mm" else "mae_mm"])
                    for r in rows
                    if r["method"] == method and r["setting"].startswith(kind)
                )
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
    dataset: str = "kitti-dc",
) -> list[SweepRow]:
    """Score every completer (``name -> completer(rgb, sparse, semantic) -> Completion``) on every
    setting of ``settings`` (strings, see :func:`parse_settings`) over the frames of ``split`` (``dataset``'s
    registry entry: the frames its protocol scores, :func:`~.protocols.eval_source`; ``max_frames``: the first).

    Each (setting, method) is one run of the frame loop on :class:`ThinnedSource` frames (seeded per frame
    from ``seed``), scored as the 16-bit PNG stores the prediction (1/256 m steps, like ``evaluate``). Writes
    ``sparsity.csv``, ``sparsity.json`` (rows with :data:`FIELDS`) and ``sparsity.png`` into ``out_dir``, and
    nothing else (the runs' folders are a stage inside it, removed); returns the rows.
    """
    return _sweep(data_root, split, settings, lambda: completers, out_dir, seed, max_frames, overwrite, dataset)


def _sweep(
    data_root: str | Path,
    split: str,
    settings: Iterable[str],
    make: Callable[[], dict[str, Completer]],
    out_dir: str | Path,
    seed: int,
    max_frames: int | None,
    overwrite: bool,
    dataset: str,
    palette_mismatch: str = "refuse",
) -> list[SweepRow]:
    """The sweep: settings, split and ``out_dir`` checked, every input decoded, then ``make()`` (the completers:
    a model is loaded after every check), every (setting, method) run, the tables and the plot written."""
    settings = parse_settings(settings)
    source = eval_source(dataset, data_root, split, max_frames=max_frames)
    out = prepare_out(Path(out_dir), overwrite, [data_root])  # never inside the data
    refuse_listed_inputs(out, source)
    with stage_folder(out) as stage:  # the runs' folders (their journals): removed, whatever happens
        check_frames(source, [], stage, OutputSpec(overwrite=True, inputs=[data_root]), RunOptions(on_error="stop"))
        completers = make()
        rows = [
            row
            for setting in settings
            for row in _score_setting(source, setting, completers, stage, seed, dataset, palette_mismatch)
        ]
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
    palette_mismatch: str = "refuse",
) -> list[SweepRow]:
    """:func:`run_sparsity_sweep` of ``model`` (as ``semattnet``; skipped when None; a function that loads
    it is called after the split and ``out_dir`` are checked and every input decoded) beside the classical
    baseline (as ``classical``). ``palette_mismatch``: the model with maps of another palette
    (:class:`~semattnet.inference.semantic.SemanticMaps`)."""

    def make() -> dict[str, Completer]:
        from semattnet.baselines.classical import ClassicalCompleter
        from semattnet.inference.backends import EngineSpec
        from semattnet.inference.completer import DepthCompleter

        completers: dict[str, Completer] = {}
        if model is not None:
            net = model if isinstance(model, torch.nn.Module) else model()
            completers["semattnet"] = DepthCompleter(net, EngineSpec(device=device))
        return completers | {"classical": ClassicalCompleter()}

    return _sweep(data_root, split, settings, make, out_dir, 0, max_frames, overwrite, dataset, palette_mismatch)


def format_sweep(rows: list[SweepRow]) -> str:
    """The sweep's rows as a text table (method, setting, density, the four metrics in KITTI units)."""
    lines = [f"{'method':>10} {'setting':>10} {'density':>8} {'RMSE':>8} {'MAE':>8} {'iRMSE':>7} {'iMAE':>6}"]
    for r in rows:
        lines.append(
            f"{r['method']:>10} {r['setting']:>10} {r['density']:8.4f} {r['rmse_mm']:8.1f} "
            f"{r['mae_mm']:8.1f} {r['irmse_per_km']:7.2f} {r['imae_per_km']:6.2f}"
        )
    return "\n".join(lines)
