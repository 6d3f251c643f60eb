"""Multiply-accumulates of a forward pass, counted from the convolutions and linear layers it runs."""

from __future__ import annotations

from typing import cast

import torch
from torch import nn

__all__ = ["count_macs"]


def count_macs(model: nn.Module, inputs: dict[str, torch.Tensor]) -> float:
    """Multiply-accumulates of every convolution in one forward pass (GMACs)."""
    total = [0]

    def conv_hook(m: nn.Module, args: tuple[torch.Tensor, ...], out: torch.Tensor) -> None:
        w = cast(torch.Tensor, m.weight)
        if isinstance(m, nn.ConvTranspose2d):  # every input pixel meets the whole kernel
            total[0] += args[0].numel() * w.shape[1] * w.shape[2] * w.shape[3]
        else:
            total[0] += out.numel() * w.shape[1] * w.shape[2] * w.shape[3]

    def linear_hook(m: nn.Module, args: tuple[torch.Tensor, ...], out: torch.Tensor) -> None:
        total[0] += out.numel() * cast(torch.Tensor, m.weight).shape[1]

    handles = [
        m.register_forward_hook(conv_hook) for m in model.modules() if isinstance(m, nn.Conv2d | nn.ConvTranspose2d)
    ]
    handles += [m.register_forward_hook(linear_hook) for m in model.modules() if isinstance(m, nn.Linear)]
    try:
        with torch.inference_mode():
            model(**inputs)
    finally:
        for h in handles:
            h.remove()
    return total[0] / 1e9
