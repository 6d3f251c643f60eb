"""Small synthetic experiments shared by ``semattnet demo`` and ``semattnet ablate``.

Generate a synthetic KITTI tree, train a model variant through the real training engine
(backbone stage, then the full model when it refines), complete the held-out scenes and score_held_out
them with the KITTI metrics, overall and separately for shadowed and unshadowed scenes.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from semattnet._utils.device import now
from semattnet.data.kitti.splits import KittiDepthCompletion
from semattnet.data.transforms import EvalTransform
from semattnet.evaluation.metrics import KittiMetrics
from semattnet.inference.backends import EngineSpec
from semattnet.inference.completer import DepthCompleter
from semattnet.models.registry import build_model
from semattnet.palette import unknown_map
from semattnet.synthetic.tree import write_synthetic_kitti
from semattnet.training.config import TrainConfig
from semattnet.training.losses import semattnet_loss
from semattnet.training.trainer import train

__all__ = [
    "GROUPS",
    "HeldOut",
    "VariantRecipe",
    "complete_held_out",
    "load_held_out",
    "make_synthetic",
    "score_held_out",
    "step_seconds",
    "train_variant",
]

GROUPS = ("all", "shadowed", "unshadowed")


@dataclass
class HeldOut:
    """The held-out (val_select) scenes of a synthetic tree, in memory."""

    names: list[str]
    samples: list[dict[str, Any]]  # as KittiDepthCompletion returns them (tensors, 0..255 images)
    shadowed: dict[str, bool]

    @functools.cached_property
    def gts(self) -> dict[str, np.ndarray]:
        return {n: s["gt"][0].numpy() for n, s in zip(self.names, self.samples, strict=True)}


def make_synthetic(
    root: Path,
    frames: int,
    eval_frames: int,
    size: tuple[int, int],
    seed: int = 0,
    style: str = "ideal",
    domain: str = "source",
) -> HeldOut:
    """Write a synthetic tree at ``root`` (half of each split shadowed, scenes of ``style`` seen by the rig of
    ``domain``, see :mod:`semattnet.synthetic.domain`) and load its held-out scenes."""
    write_synthetic_kitti(
        root, frames=frames, size=size, seed=seed, eval_frames=eval_frames, style=style, domain=domain
    )
    return load_held_out(root)


def load_held_out(root: Path) -> HeldOut:
    """The held-out scenes of a synthetic tree written by :func:`make_synthetic`."""
    manifest = json.loads((root / "scenes.json").read_text())
    shadowed = {e["name"]: bool(e["shadowed"]) for e in manifest["frames"] if e["split"] == "val_select"}
    ds = KittiDepthCompletion(root, "val_select", transform=EvalTransform(None))
    return HeldOut([f.name for f in ds.frames], [ds[i] for i in range(len(ds))], shadowed)


def score_held_out(preds: dict[str, np.ndarray], held: HeldOut) -> dict[str, dict[str, float]]:
    """KITTI metrics (means over images, devkit hole filling) per group of :data:`GROUPS`."""
    gts = held.gts
    out: dict[str, dict[str, float]] = {}
    for group in GROUPS:
        names = [n for n in preds if group == "all" or held.shadowed[n] == (group == "shadowed")]
        if not names:
            continue
        m = KittiMetrics(keep_per_image=False)
        for n in names:
            m.update(torch.from_numpy(preds[n])[None, None], torch.from_numpy(gts[n])[None, None])
        out[group] = m.compute()
    return out


def step_seconds(
    size: tuple[int, int],
    batch_size: int,
    device: torch.device,
    model: str = "semattnet",
    repeats: int = 4,
    **overrides: Any,
) -> float:
    """Wall time of one training step of a registered model: the fastest of ``repeats`` steps after
    two warm-up steps (the minimum, because on a shared machine every disturbance only adds time)."""
    h, w = size
    g = torch.Generator().manual_seed(0)
    x = {
        "rgb": torch.rand(batch_size, 3, h, w, generator=g) * 255,
        "semantic": torch.rand(batch_size, 3, h, w, generator=g) * 255,
        "sparse": torch.rand(batch_size, 1, h, w, generator=g)
        * 50
        * (torch.rand(batch_size, 1, h, w, generator=g) < 0.05),
    }
    x = {k: v.to(device) for k, v in x.items()}
    gt = torch.full((batch_size, 1, h, w), 20.0, device=device)
    net = build_model(model, **overrides).to(device).train()
    opt = torch.optim.Adam(net.parameters(), lr=1e-6)
    times = []
    for _ in range(2 + repeats):
        start = now(device)
        loss = semattnet_loss(net(**x), gt, 0.1)
        opt.zero_grad()
        loss.backward()
        opt.step()
        times.append(now(device) - start)
    return float(np.min(times[2:]))


@dataclass(frozen=True)
class VariantRecipe:
    """How :func:`train_variant` trains one variant: the stages' steps (``backbone_steps``, then, with ``refine``,
    ``refine_init_steps`` of the refinement initialisation when > 0 and ``full_steps`` of the full model), the crop
    ``size``, the model ``width``, ``batch_size``, the learning rate ``lr`` (the CSPN++ head's times
    ``head_lr_factor``), the training ``seed``, the ``loss`` (:func:`~semattnet.training.losses.semattnet_loss`),
    ``semantic_dropout`` (the share of frames given the fallback semantic map) and ``fields``: further
    :class:`~semattnet.training.TrainConfig` fields (``branches``, ``fusion``, ``model``, ...)."""

    backbone_steps: int
    full_steps: int
    size: tuple[int, int]
    width: float
    batch_size: int
    lr: float
    seed: int = 0
    refine: bool = True
    refine_init_steps: int = 0
    head_lr_factor: float = 1.0
    loss: str = "l2"
    semantic_dropout: float = 0.0
    fields: Mapping[str, object] = field(default_factory=dict)


def train_variant(
    run_dir: Path, data: Path, recipe: VariantRecipe, device: torch.device, log: Callable[[str], None] = print
) -> Path:
    """Train one variant by ``recipe`` on the synthetic tree ``data`` into ``run_dir`` and return its final
    checkpoint: the backbone stage (heads started at street scale, cosine schedule), then, if ``recipe.refine``,
    the refinement initialisation (the authors' stage 2a: backbone frozen, CSPN++ head at ``lr * head_lr_factor``)
    when it has steps, then the full model (backbone at lr / 4, CSPN++ head at ``lr * head_lr_factor``)."""
    r = recipe
    common: dict[str, Any] = {
        "data": str(data),
        "width": r.width,
        "batch_size": r.batch_size,
        "crop": r.size,
        "workers": 0,
        "epochs": 10**6,
        "lr_schedule": "cosine",
        "val_split": "val_select",
        "seed": r.seed,
        "device": str(device),
        "log_every": 1,
        "loss": r.loss,
        "semantic_dropout": r.semantic_dropout,
        **r.fields,
    }
    backbone = TrainConfig(
        stage="backbone",
        out=str(run_dir / "backbone"),
        lr=r.lr,
        max_steps=r.backbone_steps,
        depth_head_init=(10.0, 15.0),
        **common,
    )
    train(backbone, log=log)
    last = run_dir / "backbone" / "checkpoints" / "last.pt"
    if not r.refine:
        return last
    head_lr = r.lr * r.head_lr_factor
    if r.refine_init_steps > 0:
        init = TrainConfig(
            stage="refine-init",
            out=str(run_dir / "refine_init"),
            init=str(last),
            lr=head_lr,
            max_steps=r.refine_init_steps,
            **common,
        )
        train(init, log=log)
        last = run_dir / "refine_init" / "checkpoints" / "last.pt"
    full = TrainConfig(
        stage="full",
        out=str(run_dir / "full"),
        init=str(last),
        lr=r.lr / 4,
        head_lr=head_lr,
        max_steps=r.full_steps,
        **common,
    )
    train(full, log=log)
    return run_dir / "full" / "checkpoints" / "last.pt"


def fallback_semantic(semantic: torch.Tensor) -> torch.Tensor:
    """The no-segmenter fallback map (:func:`~semattnet.palette.unknown_map`) in place of a batch of semantic maps."""
    height, width = semantic.shape[-2:]
    return torch.from_numpy(unknown_map(height, width)).permute(2, 0, 1).to(semantic.dtype).expand_as(semantic)


def complete_held_out(
    model: Path | torch.nn.Module,
    held: HeldOut,
    device: torch.device,
    semantic: Callable[[torch.Tensor], torch.Tensor] | None = None,
) -> dict[str, dict[str, np.ndarray]]:
    """Every output of ``model`` (or of the model of a weights file) on every held-out scene:
    name -> output -> (H, W).

    ``semantic`` optionally replaces each scene's semantic map (e.g. the no-segmenter fallback).
    """
    if isinstance(model, torch.nn.Module):
        completer = DepthCompleter(model, EngineSpec(device=device))
    else:
        completer = DepthCompleter.from_pretrained(model, EngineSpec(device=device))
    out = {}
    for n, smp in zip(held.names, held.samples, strict=True):
        sem = smp["semantic"][None] if semantic is None else semantic(smp["semantic"][None])
        res = completer.run(smp["rgb"][None], sem, smp["sparse"][None])
        out[n] = {k: v[0, 0].cpu().numpy() for k, v in res.to_dict().items()}
    return out
