"""What the demo trains and how: its settings, the learned models, the step plan and the training loop."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from semattnet.apps.experiment import HeldOut, VariantRecipe, complete_held_out, step_seconds, train_variant

__all__ = [
    "DEMO_MODELS",
    "LABELS",
    "MODEL_KEYS",
    "OVERHEAD",
    "RECIPE_NOTES",
    "REFERENCE_KEY",
    "DemoSettings",
    "Trained",
    "step_plan",
    "step_times",
    "train_models",
]


@dataclass(frozen=True)
class DemoSettings:
    """What the demo generates and trains.

    ``steps`` gives the (backbone, full) optimiser steps of each model and seed; the default
    (136, 80) is about 3.5 minutes of training for both models and both seeds on a quiet 2-core AVX-512
    CPU (numbers differ between CPUs: float arithmetic, hence training trajectories, does). With
    ``steps=None`` they come from ``minutes`` instead, the training budget of both models and all
    seeds together, split ``backbone_share`` : rest between the backbone stage and the full model,
    from a short timing of each model on this machine (noisy on shared machines). With
    ``equal_steps`` (the default, as the paper compares configurations at equal epochs) both
    models get the same step counts, so the slower three-branch model uses more of the time;
    ``equal_steps=False`` gives each model half the time. ``reference``: also evaluate the shipped
    reference checkpoint (:mod:`semattnet.apps.demo.reference`) on the held-out scenes.
    """

    size: tuple[int, int] = (96, 320)
    train_frames: int = 200
    eval_frames: int = 16
    width: float = 0.125
    batch_size: int = 2
    minutes: float = 5.5
    backbone_share: float = 0.4
    lr: float = 2e-3
    steps: tuple[int, int] | None = (136, 80)
    seed: int = 0
    device: str = "auto"
    #: training seeds (each model is trained once per seed; the headline is the mean); None: (seed,)
    seeds: tuple[int, ...] | None = (0, 1)
    #: held-out scenes in viewer.html (all by default: about 0.2 MB each at 96x320)
    viewer_frames: int = 16
    #: the same optimiser steps for both models (the paper's protocol), else the same time
    equal_steps: bool = True
    #: synthetic scene style (:data:`semattnet.synthetic.SCENE_STYLES`): "realistic" has the
    #: sensor failures and misleading colour edges where semantics carry information
    style: str = "realistic"
    #: evaluate the shipped reference checkpoint beside the live models
    reference: bool = True

    def training_seeds(self) -> tuple[int, ...]:
        return tuple(self.seeds) if self.seeds else (self.seed,)


#: (key, label, model overrides) of the learned models the demo trains.
DEMO_MODELS: tuple[tuple[str, str, dict[str, Any]], ...] = (
    ("semattnet", "SemAttNet (CG + SG + DG, SAMMAFB, CSPN++)", {"branches": 3}),
    ("two_branch", "Two-branch ablation (CG + DG, SAMMAFB, CSPN++)", {"branches": 2}),
)

#: The result keys of the learned models, in :data:`DEMO_MODELS`' order.
MODEL_KEYS: tuple[str, ...] = tuple(key for key, _, _ in DEMO_MODELS)

#: The result key of the shipped reference checkpoint.
REFERENCE_KEY = "reference"

#: method -> display name, for the baselines, the shipped reference and the learned models.
LABELS: dict[str, str] = {
    "sparse": "Sparse input",
    "classical": "Classical completion",
    REFERENCE_KEY: "SemAttNet reference checkpoints (shipped, trained once for longer; not trained by this run)",
    **{key: label for key, label, _ in DEMO_MODELS},
}

#: How the live recipe differs from the paper's (the report and results.json show these).
RECIPE_NOTES: tuple[str, ...] = (
    "Live recipe (both models, every seed): the paper's stage 1 (backbone, eq. 14 loss with the authors' "
    "branch weights) then its stage 2b (full model, CSPN++ head at the base learning rate, backbone at a "
    "quarter); the paper's stage 2a (refinement initialisation) is skipped to fit the time budget.",
    "Differences from the paper: width 1/8, 96x320 synthetic scenes instead of 352x1216 KITTI crops, batch 2, "
    "Adam at 2e-3 with a cosine schedule per stage instead of ReduceLROnPlateau, depth heads started at street "
    "scale, a few hundred steps instead of 60 + 95 epochs; the network itself is the paper's.",
)


@dataclass
class Trained:
    """Per learned model: its step counts, its run folder and its outputs on the held-out scenes
    (of the first seed), its refined depths and their uncertainty per seed, and its training wall time (all seeds)."""

    steps: dict[str, dict[str, int]] = field(default_factory=dict)
    runs: dict[str, Path] = field(default_factory=dict)
    outputs: dict[str, dict[str, dict[str, np.ndarray]]] = field(default_factory=dict)
    per_seed: dict[int, dict[str, dict[str, np.ndarray]]] = field(default_factory=dict)
    #: seed -> model -> scene -> per-pixel uncertainty of the refined depth (metres)
    uncertainty: dict[int, dict[str, dict[str, np.ndarray]]] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)


#: A training step in a real run (data loading, logging, validation, checkpoints, completing the
#: held-out scenes) costs this much more than the bare step :func:`step_seconds` times: measured
#: 490 s of training for a 360 s plan on a 2-core CPU (1.36x; the ablation's runs: about 1.3x).
OVERHEAD = 1.35


def step_plan(s: DemoSettings, device: torch.device) -> dict[str, tuple[int, int]]:
    """(backbone, full) steps per model: as set, or what the time budget allows here, at equal
    steps for both models (``equal_steps``) or an equal share of the time each."""
    if s.steps is not None:
        return {key: (s.steps[0], s.steps[1]) for key, _, _ in DEMO_MODELS}
    budget = s.minutes * 60.0 / len(s.training_seeds())
    times = {key: tuple(OVERHEAD * t for t in step_times(s, device, overrides)) for key, _, overrides in DEMO_MODELS}
    if s.equal_steps:  # one step of every model per "round": as many rounds as the budget holds
        t_bb, t_full = (sum(t[i] for t in times.values()) for i in (0, 1))
        n = (max(5, int(budget * s.backbone_share / t_bb)), max(5, int(budget * (1.0 - s.backbone_share) / t_full)))
        return dict.fromkeys(times, n)
    share = budget / len(DEMO_MODELS)
    return {
        key: (max(5, int(share * s.backbone_share / t_bb)), max(5, int(share * (1.0 - s.backbone_share) / t_full)))
        for key, (t_bb, t_full) in times.items()
    }


def step_times(s: DemoSettings, device: torch.device, overrides: dict[str, Any]) -> tuple[float, float]:
    """Seconds per backbone-stage step and per full-model step of one model, timed here."""
    kw = {"width": s.width, **overrides}
    t_bb = step_seconds(s.size, s.batch_size, device, "semattnet_backbone", **kw)
    return t_bb, step_seconds(s.size, s.batch_size, device, "semattnet", **kw)


def train_models(
    s: DemoSettings, device: torch.device, out: Path, held: HeldOut, log: Callable[[str], None]
) -> Trained:
    """Train each model of :data:`DEMO_MODELS` with the same budget per seed, then complete the held-out scenes."""
    trained = Trained()
    seeds = s.training_seeds()
    plan = step_plan(s, device)
    for key, label, overrides in DEMO_MODELS:
        n_bb, n_full = plan[key]
        trained.steps[key] = {"backbone": n_bb, "full": n_full}
        trained.runs[key] = out / "runs" / key
        start = time.perf_counter()
        for seed in seeds:
            run = trained.runs[key] if seed == seeds[0] else out / "runs" / f"{key}_seed{seed}"
            log(f"[3/5] training {label} (seed {seed}): {n_bb} backbone steps, then {n_full} full-model steps ...")
            recipe = VariantRecipe(n_bb, n_full, s.size, s.width, s.batch_size, s.lr, seed, fields=overrides)
            ckpt = train_variant(run, out / "data", recipe, device, log=log)
            log(f"[4/5] completing the held-out scenes with {label} (seed {seed}) ...")
            outputs = complete_held_out(ckpt, held, device)
            trained.per_seed.setdefault(seed, {})[key] = {n: o["refined_depth"] for n, o in outputs.items()}
            trained.uncertainty.setdefault(seed, {})[key] = {n: o["uncertainty"] for n, o in outputs.items()}
            if seed == seeds[0]:
                trained.outputs[key] = outputs
        trained.seconds[key] = time.perf_counter() - start
    return trained
