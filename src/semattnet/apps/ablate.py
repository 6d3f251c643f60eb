"""The paper's Table 2 ablations on synthetic scenes (``semattnet ablate``).

Every configuration (a)-(g) of Table 2 is trained from scratch with the same budget of optimiser
steps and several seeds on one synthetic data set, then scored on held-out scenes, separately
for scenes with and without a hard shadow band (the paper's claim: semantics make depth robust
to illumination). One extra row, ``g_unknown_semantics``, trains and tests (g) with the
no-segmenter fallback map, to measure what real semantic maps are worth.

Results are kept per (configuration, seed) in ``results/``, so an interrupted run continues
where it stopped; ``ablation.md`` and ``ablation.json`` summarise mean, standard deviation and
every seed.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from semattnet._utils.atomic import atomic_path
from semattnet._utils.device import resolve_device
from semattnet.apps.experiment import (
    GROUPS,
    HeldOut,
    complete_held_out,
    load_held_out,
    make_synthetic,
    score,
    train_variant,
)
from semattnet.data.palette import unknown_map
from semattnet.models.registry import MODELS
from semattnet.segmentation.segmenter import Segmenter, segment_folder

__all__ = ["CONFIGS", "AblationSettings", "run_ablation"]

NO_SEMANTICS = "g_unknown_semantics"
#: Configurations: Table 2 rows plus the no-semantics variant of (g).
CONFIGS: tuple[str, ...] = (*(n for n in MODELS if n.startswith("table2_")), NO_SEMANTICS)


@dataclass(frozen=True)
class AblationSettings:
    """Common budget: ``backbone_steps + full_steps`` optimiser steps for every configuration
    (refining ones: backbone stage then full model; the others: all in the backbone stage)."""

    size: tuple[int, int] = (96, 320)
    train_frames: int = 200
    eval_frames: int = 16
    width: float = 0.125
    batch_size: int = 2
    lr: float = 2e-3
    backbone_steps: int = 90
    full_steps: int = 40
    seeds: tuple[int, ...] = (0, 1, 2)
    configs: tuple[str, ...] = CONFIGS
    data_seed: int = 0
    device: str = "auto"
    extra: dict[str, Any] = field(default_factory=dict)


def _variant(name: str) -> tuple[str, dict[str, Any]]:
    """Description and model options of a configuration."""
    if name == NO_SEMANTICS:
        return "(g) trained and tested with the no-segmenter fallback map", {"branches": 3, "fusion": "sammafb",
                                                                             "refine": True}  # fmt: skip
    if name not in MODELS or not name.startswith("table2_"):
        raise ValueError(f"unknown configuration {name!r}; choose from {', '.join(CONFIGS)}")
    description, cfg = MODELS[name]
    return description, {"branches": cfg.branches, "fusion": cfg.fusion, "refine": cfg.refine}


def _blank(semantic: torch.Tensor) -> torch.Tensor:
    """The no-segmenter fallback map (:func:`unknown_map`) in place of a batch of semantic maps."""
    height, width = semantic.shape[-2:]
    return torch.from_numpy(unknown_map(height, width)).permute(2, 0, 1).to(semantic.dtype).expand_as(semantic)


def _stats(values: Sequence[float]) -> dict[str, float]:
    a = np.asarray(values, dtype=np.float64)
    return {"mean": float(a.mean()), "std": float(a.std(ddof=1)) if len(a) > 1 else 0.0}


def run_ablation(
    out_dir: str | Path, settings: AblationSettings | None = None, log: Callable[[str], None] = print
) -> dict[str, Any]:
    """Train and score every configuration and seed; returns (and writes) the summary."""
    s = settings or AblationSettings()
    for name in s.configs:
        _variant(name)  # fail early on a typo
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    device = resolve_device(s.device)
    run = _Run(out, s, _held_out(out / "data", s, log), device, log)
    per_run: dict[str, dict[int, dict[str, float]]] = {}
    for name in s.configs:
        for seed in s.seeds:
            per_run.setdefault(name, {})[seed] = run.rmse(name, seed)
    summary = {name: _summary(name, runs) for name, runs in per_run.items()}
    result = {"settings": asdict(s), "device": str(device), "configs": summary}
    (out / "ablation.json").write_text(json.dumps(result, indent=2) + "\n")
    (out / "ablation.md").write_text(_markdown(summary, s))
    log(f"wrote {out / 'ablation.md'}")
    return result


def _held_out(data: Path, s: AblationSettings, log: Callable[[str], None]) -> HeldOut:
    """The held-out scenes: of a previous run's data if there is one (to continue it), else of new data."""
    if (data / "scenes.json").is_file():
        return load_held_out(data)
    log(f"generating {s.train_frames} training and {s.eval_frames} held-out scenes at {s.size[0]}x{s.size[1]} ...")
    return make_synthetic(data, s.train_frames, s.eval_frames, s.size, s.data_seed)


@dataclass(frozen=True)
class _Run:
    """One ablation run: where it writes, its settings, the held-out scenes, the device, where progress goes."""

    out: Path
    settings: AblationSettings
    held: HeldOut
    device: torch.device
    log: Callable[[str], None]

    def rmse(self, name: str, seed: int) -> dict[str, float]:
        """RMSE per group of one (configuration, seed): saved by an earlier run, or trained, scored and saved."""
        path = self.out / "results" / f"{name}_seed{seed}.json"
        if path.is_file():
            return json.loads(path.read_text())["rmse_mm"]
        self.log(f"{name} ({_variant(name)[0]}), seed {seed} ...")
        t0 = time.perf_counter()
        metrics = self.train_and_score(name, seed)
        rmse = {g: metrics[g]["rmse_mm"] for g in GROUPS}
        with atomic_path(path, suffix=".json") as tmp:
            tmp.write_text(json.dumps({"rmse_mm": rmse, "metrics": metrics,
                                       "seconds": time.perf_counter() - t0}, indent=1))  # fmt: skip
        self.log(f"  RMSE {rmse['all']:.0f} mm (shadowed {rmse['shadowed']:.0f}, unshadowed {rmse['unshadowed']:.0f})")
        return rmse

    def train_and_score(self, name: str, seed: int) -> dict[str, dict[str, float]]:
        """Train a configuration from scratch with the common step budget; KITTI metrics on the held-out scenes."""
        s, data, (_, opts) = self.settings, self.out / "data", _variant(name)
        extra: dict[str, Any] = {}
        semantic = None
        if name == NO_SEMANTICS:  # trained on fallback maps written beside the real ones, tested on them too
            blank_root = data / "semantic_unknown"
            segment_folder(Segmenter(None, "unknown"), data / "kitti_raw", blank_root, progress=False)
            extra, semantic = {"semantic_root": str(blank_root), "val_split": ""}, _blank
        refine = opts["refine"]
        ckpt = train_variant(
            self.out / "runs" / name / f"seed{seed}", data,
            s.backbone_steps if refine else s.backbone_steps + s.full_steps, s.full_steps,
            size=s.size, width=s.width, batch_size=s.batch_size, lr=s.lr, seed=seed, device=self.device,
            refine=refine, log=lambda _m: None, branches=opts["branches"], fusion=opts["fusion"], **extra,
        )  # fmt: skip
        outputs = complete_held_out(ckpt, self.held, self.device, semantic=semantic)
        key = "refined_depth" if refine else "fused_depth"
        return score({n: o[key] for n, o in outputs.items()}, self.held)


def _summary(name: str, runs: dict[int, dict[str, float]]) -> dict[str, Any]:
    """One configuration's summary: description, seeds, mean and std per group, every seed's RMSE."""
    seeds = sorted(runs)
    return {"description": _variant(name)[0], "seeds": seeds,
            **{g: _stats([runs[sd][g] for sd in seeds]) for g in GROUPS},
            "per_seed": {str(sd): runs[sd] for sd in seeds}}  # fmt: skip


def _markdown(summary: dict[str, Any], s: AblationSettings) -> str:
    def cell(v: dict[str, float]) -> str:
        return f"{v['mean']:.0f} ± {v['std']:.0f}" if math.isfinite(v["std"]) else f"{v['mean']:.0f}"

    lines = [
        f"Synthetic {s.size[0]}x{s.size[1]} scenes ({s.train_frames} training, {s.eval_frames} held out, half with a "
        f"shadow band), width {s.width}, {s.backbone_steps} + {s.full_steps} steps of batch {s.batch_size}, "
        f"seeds {', '.join(map(str, s.seeds))}. RMSE in mm, mean ± standard deviation over seeds.",
        "",
        "| Config | Model | RMSE | shadowed | unshadowed | per seed |",
        "|---|---|---:|---:|---:|---|",
    ]
    for name, row in summary.items():
        seeds = ", ".join(f"{row['per_seed'][str(sd)]['all']:.0f}" for sd in row["seeds"])
        lines.append(f"| {name} | {row['description']} | {cell(row['all'])} | {cell(row['shadowed'])} | "
                     f"{cell(row['unshadowed'])} | {seeds} |")  # fmt: skip
    return "\n".join(lines) + "\n"
