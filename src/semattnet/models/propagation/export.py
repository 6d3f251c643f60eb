"""The export form of the propagation: plain, out-of-place tensor ops that ONNX, TorchScript
tracing and ``torch.compile`` can record (no ``autograd.Function``, no in-place writes).
Same results as :mod:`semattnet.models.propagation.shifted`.

The shifted kernel is a list of one (B, 1, H, W) tensor per tap, not one stacked tensor: a stacked one is
concatenated once and split again at every step, which a runtime executes as full-resolution copies (in
OpenVINO, 17 of the 119 ms of ``semattnet_rt_md`` at 352x1216 were that concatenation and its splits)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch

from semattnet.models._tracing import is_tracing
from semattnet.models.propagation._common import kernel_size, window

__all__ = ["exporting", "propagate_functional", "shift_functional"]


def exporting() -> bool:
    """Tracing for ONNX / TorchScript or compiling: use plain tensor ops (no in-place, no autograd.Function)."""
    return is_tracing()


def shift_functional(affinity: torch.Tensor, dilation: int) -> list[torch.Tensor]:
    """``S_t(p) = W_t(p - o_t)`` of a (B, k*k, H, W) kernel: one (B, 1, H, W) tensor per tap, in raster order."""
    k = kernel_size(affinity)
    r = k // 2
    taps = []
    for t in range(k * k):
        oy, ox = (t // k - r) * dilation, (t % k - r) * dilation
        taps.append(window(affinity[:, t : t + 1], oy, ox))
    return taps


def propagate_functional(
    shifted: Sequence[torch.Tensor], h: torch.Tensor, h0: torch.Tensor, dilation: int
) -> torch.Tensor:
    """One step from the taps of :func:`shift_functional`: ``sum_{t != c} S_t h(p - o_t) + S_c h_0``."""
    k = math.isqrt(len(shifted))
    r, c = k // 2, (k * k) // 2
    out = shifted[c] * h0
    for t in range(k * k):
        if t != c:
            oy, ox = (t // k - r) * dilation, (t % k - r) * dilation
            out = out + shifted[t] * window(h, oy, ox)
    return out
