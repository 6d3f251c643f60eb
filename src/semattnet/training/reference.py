"""A reconstruction of the authors' training step from their recipe (not their code): the naive reference of
``benchmarks/bench_training.py`` (its ``recipe-reconstruction`` variant; the ``authors-code`` variant runs their
own model from ``--authors-src``, with this step's optimiser and loss).

The reconstruction: plain Adam (the single-tensor loop: no ``foreach``,
no ``fused``), the model with its BatchNorm layers as they are and their pad-and-sum
propagation under autograd (``propagation_impl="naive"``), a fresh ``zero_grad()`` that zeroes
the gradients in place (``set_to_none=False``, PyTorch < 2.0's default, which their code ran),
and every tensor of the batch copied to the device each step (``.to(device)``: a copy on CUDA). Same model,
loss (eq. 14, :func:`~semattnet.training.losses.semattnet_loss`) and batch as ours
(:func:`our_step`, what :class:`~semattnet.training.trainer.Trainer` runs).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import torch
from torch import nn
from torch.optim.optimizer import ParamsT

from semattnet._utils.device import autocast
from semattnet.models.refinement import AtrousCSPNRefinement
from semattnet.training.losses import semattnet_loss

__all__ = ["ParamGroup", "authors_adam", "authors_step", "make_adam", "our_step"]

#: One parameter group of Adam: ``{"params": [...], "lr": ...}``.
ParamGroup = dict[str, list[nn.Parameter] | float | None]

_INPUTS = ("rgb", "semantic", "sparse")


def authors_adam(
    params: ParamsT, lr: float, betas: tuple[float, float] = (0.9, 0.99), weight_decay: float = 1e-6
) -> torch.optim.Adam:
    """The authors' optimiser: ``torch.optim.Adam`` in its single-tensor form."""
    return torch.optim.Adam(params, lr=lr, betas=betas, weight_decay=weight_decay, foreach=False, fused=False)


def make_adam(
    params: Iterable[torch.Tensor] | list[ParamGroup],
    device: torch.device,
    lr: float = 1e-3,
    betas: tuple[float, float] = (0.9, 0.999),
    weight_decay: float = 0.0,
) -> torch.optim.Adam:
    """Our optimiser: the same Adam, fused (one kernel over all parameters) where PyTorch has it for
    ``device`` (CUDA, and the CPU since PyTorch 2.4), else ``foreach`` (multi-tensor). ``lr``,
    ``betas`` and ``weight_decay`` are Adam's (and its defaults); parameter groups may set their own ``lr``."""
    params = params if isinstance(params, list) else list(params)
    if device.type in ("cuda", "cpu"):
        try:
            return torch.optim.Adam(params, lr=lr, betas=betas, weight_decay=weight_decay, fused=True)
        except (RuntimeError, TypeError):  # an old PyTorch without the fused kernel for this device
            pass
    return torch.optim.Adam(params, lr=lr, betas=betas, weight_decay=weight_decay, foreach=True)


def authors_step(
    model: nn.Module,
    optimizer: torch.optim.Optimizer,
    batch: Mapping[str, torch.Tensor],
    device: torch.device,
    branch_weight: float = 0.0,
) -> float:
    """One step as the authors train: batch copied to the device, naive propagation, ``zero_grad()`` in place."""
    batch = {k: v.to(device) for k, v in batch.items()}
    refined = model if isinstance(model, AtrousCSPNRefinement) else None
    impl = refined.propagation_impl if refined is not None else None
    if refined is not None:
        refined.propagation_impl = "naive"
    try:
        out = model(**{k: batch[k] for k in _INPUTS})
        loss = semattnet_loss(out, batch["gt"], branch_weight)
        optimizer.zero_grad(set_to_none=False)
        loss.backward()
        optimizer.step()
    finally:
        if refined is not None and impl is not None:
            refined.propagation_impl = impl
    return loss.item()


def our_step(
    model: nn.Module,
    optimizer: torch.optim.Optimizer,
    batch: Mapping[str, torch.Tensor],
    device: torch.device,
    branch_weight: float = 0.0,
    amp: str = "none",
    scaler: torch.amp.GradScaler | None = None,
    loss: str = "l2",
) -> torch.Tensor:
    """One step of our trainer: the batch moved (not copied) to the device, the shifted propagation
    with its hand-written backward, gradients set to ``None``, AMP-aware; returns the loss tensor."""
    x = {k: batch[k].to(device, non_blocking=True) for k in _INPUTS}
    gt = batch["gt"].to(device, non_blocking=True)
    with autocast(device, amp):
        out = model(**x)
    loss_value = semattnet_loss(out.map(lambda t: t.float()), gt, branch_weight, loss)
    optimizer.zero_grad(set_to_none=True)
    if scaler is None:
        loss_value.backward()
        optimizer.step()
    else:
        scaler.scale(loss_value).backward()
        scaler.step(optimizer)
        scaler.update()
    return loss_value
