"""The out-of-the-box demo: synthetic data -> train -> evaluate against baselines -> report.

``semattnet demo`` generates KITTI-like scenes in the "realistic" style (LiDAR failures on dark
and glossy paint and glass, markings and posters that change colour but not depth, grey cars
before grey walls; half of them with a hard shadow band), trains a width-reduced SemAttNet and the
two-branch ablation (no semantic branch) for the same number of optimiser steps (the paper's
protocol; ``DemoSettings.equal_steps``), once per training seed (two by default), through the
real training engine (backbone stage, then the full model with CSPN++),
scores both on held-out scenes with the KITTI metrics beside the sparse input and a classical
non-learned completion, and writes ``report.md`` and ``report.html`` with the table (each learned
model's mean and every seed), a plain verdict per comparison, per-branch panels, error maps and
training curves, ``viewer.html`` (the interactive viewer of the held-out scenes,
:mod:`semattnet.viz.viewer`) and ``results.json``. No download; about 7.5 minutes on a 2-core CPU.

``results.json`` (schema ``semattnet.demo.results/1``; units: RMSE and MAE in mm, iRMSE and
iMAE in 1/km, as KITTI's leaderboard)::

    {
      "schema": "semattnet.demo.results/1",
      "units": {"rmse": "mm", "mae": "mm", "irmse": "1/km", "imae": "1/km"},
      "seeds": [0, 1],                    # training seeds; the scenes come from settings.seed
      "methods": {                        # sparse, classical, two_branch, semattnet
        "semattnet": {
          "label": "SemAttNet (...)",
          "all": {"rmse": .., "mae": .., "irmse": .., "imae": .., "images": 16},  # mean over seeds
          "shadowed": {...}, "unshadowed": {...},                                  # same keys
          "per_seed": {"0": {"all": {...}, "shadowed": {...}, "unshadowed": {...}}}
        }, ...
      },
      "steps": {"semattnet": {"backbone": N, "full": M}, "two_branch": {...}},  # per seed
      "wall_seconds": {"total": s, "models": {"semattnet": s, "two_branch": s}},  # train + complete, all seeds
      "machine": {"cpu": "model name", "cores": n, "torch": "2.x", "python": "3.x",
                  "platform": "...", "device": "cpu", "torch_threads": n},
      "held_out": {"frames": n, "shadowed": n},
      "settings": {...},                  # DemoSettings as a dict
      "comparisons": {"semattnet_better_than": {"classical": {"rmse": true, ...}, "two_branch": {...}},
                      "verdicts": ["SemAttNet (mean of seeds 0, 1) vs ...: better on ...; not better on ..."]}
    }

The baselines do not depend on the training seed: their ``per_seed`` entries repeat the same
numbers.
"""

from __future__ import annotations

import json
import math
import os
import platform
import shutil
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from semattnet._utils.device import resolve_device
from semattnet.apps.experiment import (
    HeldOut,
    complete_held_out,
    make_synthetic,
    score,
    step_seconds,
    train_variant,
)
from semattnet.baselines.classical import complete_classical
from semattnet.viz.depth import colorize_depth, error_map
from semattnet.viz.panels import branch_panel, save_panel
from semattnet.viz.report import write_report
from semattnet.viz.viewer import ViewerFrame, write_viewer

__all__ = ["DemoResult", "DemoSettings", "run_demo"]


@dataclass(frozen=True)
class DemoSettings:
    """What the demo generates and trains.

    ``steps`` gives the (backbone, full) optimiser steps of each model and seed; the default
    (160, 96) is about 6 minutes of training for both models and both seeds on a 2-core CPU, and
    the same steps on every machine give the same numbers. With ``steps=None`` they come from
    ``minutes`` instead, the training budget of both models and all seeds together, split
    ``backbone_share`` : rest between the backbone stage and the full model, from a short timing
    of each model on this machine (noisy on shared machines). With ``equal_steps`` (the default,
    as the paper compares configurations at equal epochs) both models get the same step counts,
    so the slower three-branch model uses more of the time; ``equal_steps=False`` gives each
    model half the time.
    """

    size: tuple[int, int] = (96, 320)
    train_frames: int = 200
    eval_frames: int = 16
    width: float = 0.125
    batch_size: int = 2
    minutes: float = 6.0
    backbone_share: float = 0.4
    lr: float = 2e-3
    steps: tuple[int, int] | None = (160, 96)
    seed: int = 0
    device: str = "auto"
    #: training seeds (each model is trained once per seed; the headline is the mean); None: (seed,)
    seeds: tuple[int, ...] | None = (0, 1)
    #: held-out scenes in viewer.html (all by default: about 0.2 MB each at 96x320)
    viewer_frames: int = 16
    #: the same optimiser steps for both models (the paper's protocol), else the same time
    equal_steps: bool = True
    #: synthetic scene style (:data:`semattnet.data.synthetic.SCENE_STYLES`): "realistic" has the
    #: sensor failures and misleading colour edges where semantics carry information
    style: str = "realistic"

    def training_seeds(self) -> tuple[int, ...]:
        return tuple(self.seeds) if self.seeds else (self.seed,)


@dataclass
class DemoResult:
    out_dir: Path
    report_md: Path
    report_html: Path
    #: method -> group ("all", "shadowed", "unshadowed") -> KITTI metrics (leaderboard units), mean over seeds
    metrics: dict[str, dict[str, dict[str, float]]]
    steps: dict[str, dict[str, int]] = field(default_factory=dict)
    seconds: float = 0.0
    viewer_html: Path | None = None
    results_json: Path | None = None


#: (key, label, model overrides) of the learned models the demo trains.
_MODELS: tuple[tuple[str, str, dict[str, Any]], ...] = (
    ("semattnet", "SemAttNet (CG + SG + DG, SAMMAFB, CSPN++)", {"branches": 3}),
    ("two_branch", "Two-branch ablation (CG + DG, SAMMAFB, CSPN++)", {"branches": 2}),
)


#: method -> display name, for the baselines and the learned models.
_LABELS: dict[str, str] = {
    "sparse": "Sparse input",
    "classical": "Classical completion",
    **{key: label for key, label, _ in _MODELS},
}


@dataclass
class _Trained:
    """Per learned model: its step counts, its run folder and its outputs on the held-out scenes
    (of the first seed), its refined depths per seed, and its training wall time (all seeds)."""

    steps: dict[str, dict[str, int]] = field(default_factory=dict)
    runs: dict[str, Path] = field(default_factory=dict)
    outputs: dict[str, dict[str, dict[str, np.ndarray]]] = field(default_factory=dict)
    per_seed: dict[int, dict[str, dict[str, np.ndarray]]] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)


def run_demo(
    out_dir: str | Path = "semattnet-demo",
    settings: DemoSettings | None = None,
    overwrite: bool = False,
    log: Callable[[str], None] = print,
) -> DemoResult:
    """Run the demo into ``out_dir`` (refused if it holds files, unless ``overwrite``)."""
    s = settings or DemoSettings()
    t_start = time.perf_counter()
    out = Path(out_dir)
    _make_empty(out, overwrite)
    device = resolve_device(s.device)
    torch.manual_seed(s.seed)
    h, w = s.size
    log(f"[1/5] generating {s.train_frames} training and {s.eval_frames} held-out scenes at {h}x{w} ...")
    held = make_synthetic(out / "data", s.train_frames, s.eval_frames, s.size, s.seed, style=s.style)
    log("[2/5] scoring the sparse input and the classical (non-learned) completion ...")
    base = _baselines(held)
    trained = _train_models(s, device, out, held, log)  # [3/5] and [4/5]
    order = ("sparse", "classical", *reversed([k for k, _, _ in _MODELS]))
    per_seed = {seed: {m: score((base | preds)[m], held) for m in order} for seed, preds in trained.per_seed.items()}
    metrics = _mean_over_seeds(per_seed)
    log("[5/5] writing pictures, the report and the viewer ...")
    preds = base | trained.per_seed[s.training_seeds()[0]]
    figures = _figures(out / "pictures", held, preds, trained)
    viewer = _viewer(out, held, preds, trained, s.viewer_frames)
    seconds = time.perf_counter() - t_start
    setup = {
        "device": str(device), "torch_threads": torch.get_num_threads(), "seconds": round(seconds, 1),
        "held_out": {"frames": len(held.names), "shadowed": sum(held.shadowed.values())},
        "settings": asdict(s), "steps": trained.steps, "seeds": list(s.training_seeds()),
    }  # fmt: skip
    setup["comparisons"] = comparisons(metrics)
    setup["verdicts"] = _verdict_sentences(setup["comparisons"], setup["seeds"])
    (out / "metrics.json").write_text(json.dumps({"metrics": metrics, "setup": setup}, indent=2) + "\n")
    results = _write_results(out / "results.json", per_seed, metrics, trained, setup)
    links = [("Interactive viewer of the held-out scenes (hover for depths, layers, 3D point cloud)", "viewer.html"),
             ("All numbers as JSON", "results.json")]  # fmt: skip
    table, labels = _with_seed_rows(metrics, per_seed)
    md, html = write_report(out, table, labels, figures, setup, links=links)
    _summarise(metrics, order, seconds, html, log)
    return DemoResult(out, md, html, metrics, trained.steps, seconds, viewer, results)


def _mean_over_seeds(
    per_seed: dict[int, dict[str, dict[str, dict[str, float]]]],
) -> dict[str, dict[str, dict[str, float]]]:
    """method -> group -> metric: the mean over seeds of each number."""
    first = next(iter(per_seed.values()))
    return {
        method: {
            group: {k: float(np.mean([run[method][group][k] for run in per_seed.values()])) for k in values}
            for group, values in groups.items()
        }
        for method, groups in first.items()
    }


def _with_seed_rows(
    metrics: dict[str, dict[str, dict[str, float]]], per_seed: dict[int, dict[str, dict[str, dict[str, float]]]]
) -> tuple[dict[str, dict[str, dict[str, float]]], dict[str, str]]:
    """The report's table: every method (learned ones: mean over seeds), then each learned model's seeds."""
    if len(per_seed) < 2:
        return metrics, dict(_LABELS)
    table, labels = {}, {}
    for method, groups in metrics.items():
        learned = method in {k for k, _, _ in _MODELS}
        table[method] = groups
        labels[method] = _LABELS[method] + (f", mean of {len(per_seed)} seeds" if learned else "")
        for seed, run in per_seed.items() if learned else ():
            table[f"{method}@seed{seed}"] = run[method]
            labels[f"{method}@seed{seed}"] = f"  {_LABELS[method].split(' (')[0]}, seed {seed}"
    return table, labels


#: The demo's comparisons: SemAttNet against each of these, on these metrics (issue 16's bar).
COMPARED: dict[str, tuple[str, ...]] = {"classical": ("rmse", "mae", "irmse", "imae"), "two_branch": ("rmse", "mae")}
_METRICS = ("rmse", "mae", "irmse", "imae")


def comparisons(metrics: dict[str, dict[str, dict[str, float]]]) -> dict[str, dict[str, bool]]:
    """other method -> metric -> whether SemAttNet's held-out mean (over seeds) is lower (better)."""
    ours = _record(metrics["semattnet"])["all"]
    return {other: {k: ours[k] < _record(metrics[other])["all"][k] for k in _METRICS} for other in COMPARED}


def _verdict_sentences(comparison: dict[str, dict[str, bool]], seeds: list[int]) -> list[str]:
    """One plain sentence per compared method: where SemAttNet is better and where it is not."""
    names = {"rmse": "RMSE", "mae": "MAE", "irmse": "iRMSE", "imae": "iMAE"}
    out, which = [], f"seed{'s' if len(seeds) > 1 else ''} {', '.join(map(str, seeds))}"
    for other, wins in comparison.items():
        better = [names[k] for k in _METRICS if wins[k]]
        worse = [names[k] for k in _METRICS if not wins[k]]
        text = f"SemAttNet (mean of {which}) vs {_LABELS[other]}: "
        text += f"better on {', '.join(better)}" if better else "better on no metric"
        out.append(text + (f"; not better on {', '.join(worse)}." if worse else "."))
    return out


#: results.json metric name -> key of :meth:`KittiMetrics.compute`.
_RESULT_KEYS = {"rmse": "rmse_mm", "mae": "mae_mm", "irmse": "irmse_per_km", "imae": "imae_per_km", "images": "images"}


def _record(groups: dict[str, dict[str, float]]) -> dict[str, dict[str, float]]:
    return {g: {k: v[src] for k, src in _RESULT_KEYS.items() if src in v} for g, v in groups.items()}


def _machine() -> dict[str, Any]:
    """CPU model (from /proc/cpuinfo where there is one), core count, torch and Python versions."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith(("model name", "hardware")):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"cpu": cpu, "cores": os.cpu_count(), "torch": torch.__version__, "python": platform.python_version(),
            "platform": platform.platform()}  # fmt: skip


def _write_results(
    path: Path,
    per_seed: dict[int, dict[str, dict[str, dict[str, float]]]],
    metrics: dict[str, dict[str, dict[str, float]]],
    trained: _Trained,
    setup: dict[str, Any],
) -> Path:
    """Write ``results.json`` (schema in the module docstring)."""
    methods = {
        m: {"label": _LABELS[m], **_record(metrics[m]),
            "per_seed": {str(seed): _record(run[m]) for seed, run in per_seed.items()}}
        for m in metrics
    }  # fmt: skip
    doc = {
        "schema": "semattnet.demo.results/1",
        "units": {"rmse": "mm", "mae": "mm", "irmse": "1/km", "imae": "1/km"},
        "seeds": setup["seeds"], "methods": methods, "steps": trained.steps,
        "wall_seconds": {"total": setup["seconds"], "models": {k: round(v, 1) for k, v in trained.seconds.items()}},
        "machine": {**_machine(), "device": setup["device"], "torch_threads": setup["torch_threads"]},
        "held_out": setup["held_out"], "settings": setup["settings"],
        "comparisons": {"semattnet_better_than": setup["comparisons"], "verdicts": setup["verdicts"]},
    }  # fmt: skip
    path.write_text(json.dumps(doc, indent=2) + "\n")
    return path


def _intrinsics(sample: dict[str, Any]) -> np.ndarray | None:
    """The scene's (3, 3) intrinsics, None when the sample has none (NaN-filled)."""
    K = sample.get("K")
    K = None if K is None else np.asarray(K, dtype=np.float64).reshape(3, 3)
    return K if K is not None and np.isfinite(K).all() else None


def _viewer(out: Path, held: HeldOut, preds: dict[str, dict[str, np.ndarray]], trained: _Trained, count: int) -> Path:
    """``viewer.html`` for the first ``count`` held-out scenes: every method, SemAttNet's intermediates."""
    frames = []
    for n in held.names[:count]:
        smp = held.samples[held.names.index(n)]
        frames.append(ViewerFrame(
            name=n, rgb=smp["rgb"].permute(1, 2, 0).numpy().astype(np.uint8), sparse=smp["sparse"][0].numpy(),
            depths={m: preds[m][n] for m in ("classical", "two_branch", "semattnet")},
            semantic=smp["semantic"].permute(1, 2, 0).numpy().astype(np.uint8), gt=held.gts[n],
            outputs=trained.outputs["semattnet"][n], outputs_of="semattnet", K=_intrinsics(smp),
            cloud_of="semattnet", note="shadowed" if held.shadowed[n] else "unshadowed",
        ))  # fmt: skip
    return write_viewer(out, frames, _LABELS, title="SemAttNet demo: held-out scenes", back=("report", "report.html"))


def _make_empty(out: Path, overwrite: bool) -> None:
    """Create ``out``; if it holds files, empty it when ``overwrite``, else refuse."""
    if out.exists() and any(out.iterdir()):
        if not overwrite:
            raise FileExistsError(f"{out} is not empty; pass --overwrite to replace it")
        shutil.rmtree(out)
    out.mkdir(parents=True, exist_ok=True)


def _baselines(held: HeldOut) -> dict[str, dict[str, np.ndarray]]:
    """Predictions of the non-learned baselines, method -> scene -> depth: the sparse input itself, classical."""
    preds: dict[str, dict[str, np.ndarray]] = {"sparse": {}, "classical": {}}
    for n, smp in zip(held.names, held.samples, strict=True):
        preds["sparse"][n] = smp["sparse"][0].numpy()  # the devkit fills its holes when scoring
        preds["classical"][n] = complete_classical(smp["sparse"][None])[0, 0].numpy()
    return preds


#: A training step in a real run (data loading, logging, validation, checkpoints, completing the
#: held-out scenes) costs this much more than the bare step :func:`step_seconds` times: measured
#: 490 s of training for a 360 s plan on a 2-core CPU (1.36x; the ablation's runs: about 1.3x).
_OVERHEAD = 1.35


def _step_plan(s: DemoSettings, device: torch.device) -> dict[str, tuple[int, int]]:
    """(backbone, full) steps per model: as set, or what the time budget allows here, at equal
    steps for both models (``equal_steps``) or an equal share of the time each."""
    if s.steps is not None:
        return {key: (s.steps[0], s.steps[1]) for key, _, _ in _MODELS}
    budget = s.minutes * 60.0 / len(s.training_seeds())
    times = {key: tuple(_OVERHEAD * t for t in _step_times(s, device, overrides)) for key, _, overrides in _MODELS}
    if s.equal_steps:  # one step of every model per "round": as many rounds as the budget holds
        t_bb, t_full = (sum(t[i] for t in times.values()) for i in (0, 1))
        n = (max(5, int(budget * s.backbone_share / t_bb)), max(5, int(budget * (1.0 - s.backbone_share) / t_full)))
        return dict.fromkeys(times, n)
    share = budget / len(_MODELS)
    return {key: (max(5, int(share * s.backbone_share / t_bb)), max(5, int(share * (1.0 - s.backbone_share) / t_full)))
            for key, (t_bb, t_full) in times.items()}  # fmt: skip


def _step_times(s: DemoSettings, device: torch.device, overrides: dict[str, Any]) -> tuple[float, float]:
    """Seconds per backbone-stage step and per full-model step of one model, timed here."""
    kw = {"width": s.width, **overrides}
    t_bb = step_seconds(s.size, s.batch_size, device, "semattnet_backbone", **kw)
    return t_bb, step_seconds(s.size, s.batch_size, device, "semattnet", **kw)


def _train_models(
    s: DemoSettings, device: torch.device, out: Path, held: HeldOut, log: Callable[[str], None]
) -> _Trained:
    """Train each model of :data:`_MODELS` with the same budget per seed, then complete the held-out scenes."""
    trained = _Trained()
    seeds = s.training_seeds()
    plan = _step_plan(s, device)
    for key, label, overrides in _MODELS:
        n_bb, n_full = plan[key]
        trained.steps[key] = {"backbone": n_bb, "full": n_full}
        trained.runs[key] = out / "runs" / key
        start = time.perf_counter()
        for seed in seeds:
            run = trained.runs[key] if seed == seeds[0] else out / "runs" / f"{key}_seed{seed}"
            log(f"[3/5] training {label} (seed {seed}): {n_bb} backbone steps, then {n_full} full-model steps ...")
            ckpt = train_variant(run, out / "data", n_bb, n_full, size=s.size, width=s.width,
                                 batch_size=s.batch_size, lr=s.lr, seed=seed, device=device, log=log,
                                 **overrides)  # fmt: skip
            log(f"[4/5] completing the held-out scenes with {label} (seed {seed}) ...")
            outputs = complete_held_out(ckpt, held, device)
            trained.per_seed.setdefault(seed, {})[key] = {n: o["refined_depth"] for n, o in outputs.items()}
            if seed == seeds[0]:
                trained.outputs[key] = outputs
        trained.seconds[key] = time.perf_counter() - start
    return trained


def _figures(
    pictures: Path, held: HeldOut, preds: dict[str, dict[str, np.ndarray]], trained: _Trained
) -> list[tuple[str, str]]:
    """The report's (caption, path) figures: panels of a shadowed and an unshadowed scene, training curves."""
    names, shadowed = held.names, held.shadowed
    shown = [next(n for n in names if shadowed[n]), next(n for n in names if not shadowed[n])]
    figures: list[tuple[str, str]] = []
    for n in shown:
        figures += _scene_figures(pictures, held, n, preds, trained.outputs["semattnet"][n])
    return figures + _curve_figures(pictures, trained.runs)


def _scene_figures(
    pictures: Path,
    held: HeldOut,
    n: str,
    preds: dict[str, dict[str, np.ndarray]],
    semattnet_outputs: dict[str, np.ndarray],
) -> list[tuple[str, str]]:
    """Scene ``n``'s panels: SemAttNet's intermediate depths, and depth and error map per method."""
    smp, gt = held.samples[held.names.index(n)], held.gts[n]
    rgb = smp["rgb"].permute(1, 2, 0).numpy().astype(np.uint8)
    sem = smp["semantic"].permute(1, 2, 0).numpy().astype(np.uint8)
    kind = "shadowed" if held.shadowed[n] else "unshadowed"
    branch_panel(pictures / f"branches_{kind}.png", rgb, sem, smp["sparse"][0].numpy(), semattnet_outputs, gt,
                 columns=4)  # fmt: skip
    tiles = [("RGB", rgb), ("ground truth", colorize_depth(gt))]
    for method in ("classical", "two_branch", "semattnet"):
        rmse = score({n: preds[method][n]}, held)["all"]["rmse_mm"]
        short = _LABELS[method].split(" (")[0]
        tiles.append((f"{short}: depth, RMSE {rmse / 1000:.2f} m", colorize_depth(preds[method][n])))
        tiles.append((f"{short}: error", error_map(preds[method][n], gt)))
    save_panel(tiles, pictures / f"compare_{kind}.png", columns=2)
    return [(f"Comparison on a held-out {kind} scene: depth and KITTI error map per method "
             "(error colours: blue = small, red = large)", f"pictures/compare_{kind}.png"),
            (f"SemAttNet's intermediate depths on the {kind} scene: colour-, semantic- and depth-guided "
             "branches, their fusion, the CSPN++ refinement and the branch confidences",
             f"pictures/branches_{kind}.png")]  # fmt: skip


def _curve_figures(pictures: Path, runs: dict[str, Path]) -> list[tuple[str, str]]:
    """Copy each model's training curves (per stage, where written) beside the pictures."""
    figures = []
    for key, label, _ in _MODELS:
        for stage in ("backbone", "full"):
            curve = runs[key] / stage / "curves.png"
            if curve.is_file():
                target = pictures / f"curves_{key}_{stage}.png"
                shutil.copyfile(curve, target)
                figures.append((f"Training curves: {label}, {stage} stage", f"pictures/{target.name}"))
    return figures


def _summarise(
    metrics: dict[str, dict[str, dict[str, float]]],
    order: tuple[str, ...],
    seconds: float,
    html: Path,
    log: Callable[[str], None],
) -> None:
    """Log the held-out RMSE of every method and where the report is; fail if SemAttNet's RMSE is not finite."""
    best_base = min(metrics["sparse"]["all"]["rmse_mm"], metrics["classical"]["all"]["rmse_mm"])
    ours = metrics["semattnet"]["all"]["rmse_mm"]
    summary = ", ".join(
        f"{_LABELS[k].split(' (')[0]} {metrics[k]['all']['rmse_mm'] / 1000:.2f} m" for k in reversed(order)
    )
    log(f"held-out RMSE: {summary} (SemAttNet {'beats' if ours < best_base else 'does not beat'} both baselines)")
    log(f"done in {seconds / 60:.1f} min. Report: {html.resolve()}")
    if not math.isfinite(ours):
        raise RuntimeError("the trained model produced no finite RMSE")
