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
from typing import TypeVar

import torch
import torch.utils.checkpoint
from torch import nn

from semattnet._errors import InputError
from semattnet.models.backbone import SemAttNetBackbone

__all__ = ["BranchCheckpointing", "set_activation_checkpointing"]

F = TypeVar("F")


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


class BranchCheckpointing:
    """A :attr:`SemAttNetBackbone.branch_runner`: in training with autograd on, each branch runs
    under non-reentrant checkpointing (BatchNorm statistics updated once); otherwise directly."""

    def __init__(self, module: nn.Module) -> None:
        self.module = module

    def __call__(self, branch: Callable[..., F], *inputs: object) -> F:
        if not (self.module.training and torch.is_grad_enabled()):
            return branch(*inputs)
        return torch.utils.checkpoint.checkpoint(
            branch,
            *inputs,
            use_reentrant=False,
            context_fn=lambda: (contextlib.nullcontext(), _frozen_running_stats(self.module)),
        )


def set_activation_checkpointing(model: nn.Module, enabled: bool = True) -> int:
    """Checkpoint (or stop checkpointing) every branch of every backbone in ``model``; returns the
    number of branches changed. Works on a model, its DDP wrapper or a full SemAttNet. Refuses to
    replace a :attr:`~SemAttNetBackbone.branch_runner` it did not set."""
    changed = 0
    for backbone in (m for m in model.modules() if isinstance(m, SemAttNetBackbone)):
        runner = backbone.branch_runner
        if runner is not None and not isinstance(runner, BranchCheckpointing):
            raise InputError(f"set_activation_checkpointing: the backbone already has a branch_runner ({runner!r})")
        if enabled == (runner is not None):
            continue
        backbone.branch_runner = BranchCheckpointing(backbone) if enabled else None
        changed += backbone.config.branches
    return changed
