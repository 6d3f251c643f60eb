"""Activation checkpointing of the branches (``TrainConfig.activation_checkpointing``,
``semattnet train --activation-checkpointing``).

Each branch of the backbone (colour-, semantic- and depth-guided: encoder and decoder) runs
under :func:`torch.utils.checkpoint.checkpoint` (``use_reentrant=False``): its forward keeps only
the branch's inputs and outputs, and the backward recomputes the branch's activations, one
branch at a time. Loss and gradients are unchanged (tested); the recomputation does not update
the BatchNorm running statistics a second time (they are exactly those of a run without it).
Costs one more forward of the backbone per step; the measured trade-off is in
``docs/performance.md``.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from typing import Any

import torch
import torch.utils.checkpoint
from torch import nn

from semattnet.models.backbone import SemAttNetBackbone

__all__ = ["BRANCH_METHODS", "set_activation_checkpointing"]

#: The backbone's branch methods (``SemAttNetBackbone.forward_features`` calls them) that are checkpointed.
BRANCH_METHODS: tuple[str, ...] = ("_color_guided", "_semantic_guided", "_depth_guided")


def _count(m: nn.Module) -> torch.Tensor:
    """A tracking BatchNorm's batch counter (a tensor whenever ``track_running_stats`` is on)."""
    count = m.num_batches_tracked
    assert isinstance(count, torch.Tensor)
    return count


@contextlib.contextmanager
def _frozen_running_stats(module: nn.Module) -> Iterator[None]:
    """BatchNorm as in the forward, but the running statistics left as they are: momentum 0 (the
    update ``(1 - 0) * running + 0 * batch`` is exact) and the batch counter restored. (Turning
    ``track_running_stats`` off would change what autograd saves, which checkpointing refuses.)"""
    norms = [m for m in module.modules() if isinstance(m, nn.BatchNorm2d | nn.SyncBatchNorm) and m.track_running_stats]
    saved = [(m.momentum, _count(m).clone()) for m in norms]
    for m in norms:
        m.momentum = 0.0
    try:
        yield
    finally:
        with torch.no_grad():
            for m, (momentum, count) in zip(norms, saved, strict=True):
                m.momentum = momentum
                _count(m).copy_(count)


class _Checkpointed:
    """A branch method that, in training with autograd on, runs under non-reentrant checkpointing."""

    def __init__(self, module: nn.Module, fn: Callable[..., Any]) -> None:
        self.module, self.fn = module, fn

    def __call__(self, *args: Any) -> Any:
        if not (self.module.training and torch.is_grad_enabled()):
            return self.fn(*args)
        return torch.utils.checkpoint.checkpoint(
            self.fn, *args, use_reentrant=False,
            context_fn=lambda: (contextlib.nullcontext(), _frozen_running_stats(self.module)),
        )  # fmt: skip


def set_activation_checkpointing(model: nn.Module, enabled: bool = True) -> int:
    """Checkpoint (or stop checkpointing) every branch of every backbone in ``model``; returns the
    number of branches changed. Works on a model, its DDP wrapper or a full SemAttNet."""
    changed = 0
    for backbone in (m for m in model.modules() if isinstance(m, SemAttNetBackbone)):
        for name in BRANCH_METHODS:
            method = getattr(type(backbone), name)  # a missing name fails here, loudly
            if enabled and name not in backbone.__dict__:
                object.__setattr__(backbone, name, _Checkpointed(backbone, method.__get__(backbone)))
                changed += 1
            elif not enabled and name in backbone.__dict__:
                del backbone.__dict__[name]
                changed += 1
    return changed
