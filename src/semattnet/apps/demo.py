"""The out-of-the-box demo: synthetic data -> train -> evaluate against baselines -> report.

``semattnet demo`` generates KITTI-like scenes (half of them with a hard shadow band), trains a
width-reduced SemAttNet and the two-branch ablation (no semantic branch) with the same time
budget through the real training engine (backbone stage, then the full model with CSPN++),
scores both on held-out scenes with the KITTI metrics beside the sparse input and a classical
non-learned completion, and writes ``report.md`` and ``report.html`` with the table, per-branch
panels, error maps and training curves. No download; about 8 minutes on a 2-core CPU.
"""

from __future__ import annotations

import json
import math
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

__all__ = ["DemoResult", "DemoSettings", "run_demo"]


@dataclass(frozen=True)
class DemoSettings:
    """What the demo generates and trains.

    ``minutes`` is the training budget of both learned models together (each gets half, split
    ``backbone_share`` : rest between the backbone stage and the full model). The step counts
    are derived from a short timing of each model on this machine, unless ``steps`` gives
    (backbone, full) steps per model explicitly.
    """

    size: tuple[int, int] = (96, 320)
    train_frames: int = 200
    eval_frames: int = 16
    width: float = 0.125
    batch_size: int = 2
    minutes: float = 6.0
    backbone_share: float = 0.4
    lr: float = 2e-3
    steps: tuple[int, int] | None = None
    seed: int = 0
    device: str = "auto"


@dataclass
class DemoResult:
    out_dir: Path
    report_md: Path
    report_html: Path
    #: method -> group ("all", "shadowed", "unshadowed") -> KITTI metrics (leaderboard units)
    metrics: dict[str, dict[str, dict[str, float]]]
    steps: dict[str, dict[str, int]] = field(default_factory=dict)
    seconds: float = 0.0


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
    """Per learned model: its step counts, its run folder and its outputs on the held-out scenes."""

    steps: dict[str, dict[str, int]] = field(default_factory=dict)
    runs: dict[str, Path] = field(default_factory=dict)
    outputs: dict[str, dict[str, dict[str, np.ndarray]]] = field(default_factory=dict)


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
    held = make_synthetic(out / "data", s.train_frames, s.eval_frames, s.size, s.seed)
    log("[2/5] scoring the sparse input and the classical (non-learned) completion ...")
    preds = _baselines(held)
    trained = _train_models(s, device, out, held, log)  # [3/5] and [4/5]
    preds |= {key: {n: o["refined_depth"] for n, o in outputs.items()} for key, outputs in trained.outputs.items()}
    order = ("sparse", "classical", *reversed([k for k, _, _ in _MODELS]))
    metrics = {method: score(preds[method], held) for method in order}
    log("[5/5] writing pictures and the report ...")
    figures = _figures(out / "pictures", held, preds, trained)
    seconds = time.perf_counter() - t_start
    setup = {
        "device": str(device), "torch_threads": torch.get_num_threads(), "seconds": round(seconds, 1),
        "held_out": {"frames": len(held.names), "shadowed": sum(held.shadowed.values())},
        "settings": asdict(s), "steps": trained.steps,
    }  # fmt: skip
    (out / "metrics.json").write_text(json.dumps({"metrics": metrics, "setup": setup}, indent=2) + "\n")
    md, html = write_report(out, metrics, _LABELS, figures, setup)
    _summarise(metrics, order, seconds, html, log)
    return DemoResult(out, md, html, metrics, trained.steps, seconds)


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


def _step_counts(s: DemoSettings, device: torch.device, overrides: dict[str, Any]) -> tuple[int, int]:
    """(backbone, full) steps of one model: as set, or what its share of the time budget allows here."""
    if s.steps is not None:
        n_bb, n_full = s.steps
        return n_bb, n_full
    budget = s.minutes * 60.0 / len(_MODELS)
    kw = {"width": s.width, **overrides}
    t_bb = step_seconds(s.size, s.batch_size, device, "semattnet_backbone", **kw)
    t_full = step_seconds(s.size, s.batch_size, device, "semattnet", **kw)
    return max(5, int(budget * s.backbone_share / t_bb)), max(5, int(budget * (1.0 - s.backbone_share) / t_full))


def _train_models(
    s: DemoSettings, device: torch.device, out: Path, held: HeldOut, log: Callable[[str], None]
) -> _Trained:
    """Train each model of :data:`_MODELS` with the same budget, then complete the held-out scenes with it."""
    trained = _Trained()
    for key, label, overrides in _MODELS:
        n_bb, n_full = _step_counts(s, device, overrides)
        trained.steps[key] = {"backbone": n_bb, "full": n_full}
        log(f"[3/5] training {label}: {n_bb} backbone steps, then {n_full} full-model steps ...")
        trained.runs[key] = out / "runs" / key
        ckpt = train_variant(trained.runs[key], out / "data", n_bb, n_full, size=s.size, width=s.width,
                             batch_size=s.batch_size, lr=s.lr, seed=s.seed, device=device, log=log,
                             **overrides)  # fmt: skip
        log(f"[4/5] completing the held-out scenes with {label} ...")
        trained.outputs[key] = complete_held_out(ckpt, held, device)
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
