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

from ._device import resolve_device
from .classical import complete_classical
from .experiment import complete_held_out, make_synthetic, score, step_seconds, train_variant
from .report import write_report
from .visualize import branch_panel, colorize_depth, error_map, save_panel

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
    if out.exists() and any(out.iterdir()):
        if not overwrite:
            raise FileExistsError(f"{out} is not empty; pass --overwrite to replace it")
        shutil.rmtree(out)
    out.mkdir(parents=True, exist_ok=True)
    device = resolve_device(s.device)
    torch.manual_seed(s.seed)

    # 1. Data.
    h, w = s.size
    log(f"[1/5] generating {s.train_frames} training and {s.eval_frames} held-out scenes at {h}x{w} ...")
    data = out / "data"
    held = make_synthetic(data, s.train_frames, s.eval_frames, s.size, s.seed)
    names, samples, shadowed, gts = held.names, held.samples, held.shadowed, held.gts

    # 2. Baselines.
    log("[2/5] scoring the sparse input and the classical (non-learned) completion ...")
    preds: dict[str, dict[str, np.ndarray]] = {"sparse": {}, "classical": {}}
    for n, smp in zip(names, samples, strict=True):
        preds["sparse"][n] = smp["sparse"][0].numpy()  # the devkit fills its holes when scoring
        preds["classical"][n] = complete_classical(smp["sparse"][None])[0, 0].numpy()

    # 3. Training, same budget per model; 4. held-out completion.
    budget = s.minutes * 60.0 / len(_MODELS)
    steps: dict[str, dict[str, int]] = {}
    runs: dict[str, Path] = {}
    outputs: dict[str, dict[str, dict[str, np.ndarray]]] = {}
    for key, label, overrides in _MODELS:
        if s.steps is not None:
            n_bb, n_full = s.steps
        else:
            kw = {"width": s.width, **overrides}
            t_bb = step_seconds(s.size, s.batch_size, device, "semattnet_backbone", **kw)
            t_full = step_seconds(s.size, s.batch_size, device, "semattnet", **kw)
            n_bb = max(5, int(budget * s.backbone_share / t_bb))
            n_full = max(5, int(budget * (1.0 - s.backbone_share) / t_full))
        steps[key] = {"backbone": n_bb, "full": n_full}
        log(f"[3/5] training {label}: {n_bb} backbone steps, then {n_full} full-model steps ...")
        runs[key] = out / "runs" / key
        ckpt = train_variant(runs[key], data, n_bb, n_full, size=s.size, width=s.width, batch_size=s.batch_size,
                             lr=s.lr, seed=s.seed, device=device, log=log, **overrides)  # fmt: skip
        log(f"[4/5] completing the held-out scenes with {label} ...")
        outputs[key] = complete_held_out(ckpt, held, device)
        preds[key] = {n: o["refined_depth"] for n, o in outputs[key].items()}
    order = ("sparse", "classical", *reversed([k for k, _, _ in _MODELS]))
    metrics = {method: score(preds[method], held) for method in order}

    # 5. Pictures and report.
    log("[5/5] writing pictures and the report ...")
    pictures = out / "pictures"
    shown = [next(n for n in names if shadowed[n]), next(n for n in names if not shadowed[n])]
    figures: list[tuple[str, str]] = []
    labels = {"sparse": "Sparse input", "classical": "Classical completion"} | {k: lab for k, lab, _ in _MODELS}
    for n in shown:
        smp = samples[names.index(n)]
        rgb = smp["rgb"].permute(1, 2, 0).numpy().astype(np.uint8)
        sem = smp["semantic"].permute(1, 2, 0).numpy().astype(np.uint8)
        kind = "shadowed" if shadowed[n] else "unshadowed"
        branch_panel(pictures / f"branches_{kind}.png", rgb, sem, smp["sparse"][0].numpy(),
                     outputs["semattnet"][n], gts[n], columns=4)  # fmt: skip
        tiles = [("RGB", rgb), ("ground truth", colorize_depth(gts[n]))]
        for method in ("classical", "two_branch", "semattnet"):
            rmse = score({n: preds[method][n]}, held)["all"]["rmse_mm"]
            short = labels[method].split(" (")[0]
            tiles.append((f"{short}: depth, RMSE {rmse / 1000:.2f} m", colorize_depth(preds[method][n])))
            tiles.append((f"{short}: error", error_map(preds[method][n], gts[n])))
        save_panel(tiles, pictures / f"compare_{kind}.png", columns=2)
        figures += [(f"Comparison on a held-out {kind} scene: depth and KITTI error map per method "
                     "(error colours: blue = small, red = large)", f"pictures/compare_{kind}.png"),
                    (f"SemAttNet's intermediate depths on the {kind} scene: colour-, semantic- and depth-guided "
                     "branches, their fusion, the CSPN++ refinement and the branch confidences",
                     f"pictures/branches_{kind}.png")]  # fmt: skip
    for key, label, _ in _MODELS:
        for stage in ("backbone", "full"):
            curve = runs[key] / stage / "curves.png"
            if curve.is_file():
                target = pictures / f"curves_{key}_{stage}.png"
                shutil.copyfile(curve, target)
                figures.append((f"Training curves: {label}, {stage} stage", f"pictures/{target.name}"))

    seconds = time.perf_counter() - t_start
    setup = {
        "device": str(device), "torch_threads": torch.get_num_threads(), "seconds": round(seconds, 1),
        "held_out": {"frames": len(names), "shadowed": sum(shadowed.values())},
        "settings": asdict(s), "steps": steps,
    }  # fmt: skip
    (out / "metrics.json").write_text(json.dumps({"metrics": metrics, "setup": setup}, indent=2) + "\n")
    md, html = write_report(out, metrics, labels, figures, setup)
    best_base = min(metrics["sparse"]["all"]["rmse_mm"], metrics["classical"]["all"]["rmse_mm"])
    ours = metrics["semattnet"]["all"]["rmse_mm"]
    summary = ", ".join(
        f"{labels[k].split(' (')[0]} {metrics[k]['all']['rmse_mm'] / 1000:.2f} m" for k in reversed(order)
    )
    log(f"held-out RMSE: {summary} (SemAttNet {'beats' if ours < best_base else 'does not beat'} both baselines)")
    log(f"done in {seconds / 60:.1f} min. Report: {html.resolve()}")
    if not math.isfinite(ours):
        raise RuntimeError("the trained model produced no finite RMSE")
    return DemoResult(out, md, html, metrics, steps, seconds)
