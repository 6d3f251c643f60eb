"""The export form of the propagation: plain, out-of-place tensor ops that ONNX, TorchScript
tracing and ``torch.compile`` can record (no ``autograd.Function``, no in-place writes).
Same results as :mod:`semattnet.models.propagation.shifted`."""

from __future__ import annotations

import torch

from semattnet.models._tracing import is_tracing
from semattnet.models.propagation._common import kernel_size, window

__all__ = ["exporting", "propagate_functional", "shift_functional"]


def exporting() -> bool:
    """Tracing for ONNX / TorchScript or compiling: use plain tensor ops (no in-place, no autograd.Function)."""
    return is_tracing()


def shift_functional(affinity: torch.Tensor, dilation: int) -> torch.Tensor:
    k = kernel_size(affinity)
    r = k // 2
    taps = []
    for t in range(k * k):
        oy, ox = (t // k - r) * dilation, (t % k - r) * dilation
        taps.append(window(affinity[:, t : t + 1], oy, ox))
    return torch.cat(taps, dim=1)


def propagate_functional(shifted: torch.Tensor, h: torch.Tensor, h0: torch.Tensor, dilation: int) -> torch.Tensor:
    k = kernel_size(shifted)
    r, c = k // 2, (k * k) // 2
    out = shifted[:, c : c + 1] * h0
    for t in range(k * k):
        if t != c:
            oy, ox = (t // k - r) * dilation, (t % k - r) * dilation
            out = out + shifted[:, t : t + 1] * window(h, oy, ox)
    return out
