"""Window bookkeeping shared by every propagation form: kernel size, tap offsets, shifted windows."""

from __future__ import annotations

import math
from collections.abc import Iterator

import torch
import torch.nn.functional as F

from semattnet._errors import InputError

__all__ = ["kernel_size", "taps", "window"]


def kernel_size(affinity: torch.Tensor) -> int:
    kk = affinity.shape[1]
    k = math.isqrt(kk)
    if k * k != kk or k % 2 == 0:
        raise InputError(f"affinity must have k*k channels for an odd k, got {kk}")
    return k


def taps(
    k: int, dilation: int, height: int, width: int
) -> Iterator[tuple[int, tuple[slice, slice], tuple[slice, slice]]]:
    """For every non-centre tap t: (t, destination slices, source slices) with dst = src + o_t."""
    r = k // 2
    for t in range(k * k):
        if t == (k * k) // 2:
            continue
        oy, ox = (t // k - r) * dilation, (t % k - r) * dilation
        if abs(oy) >= height or abs(ox) >= width:
            continue
        dst = (slice(max(oy, 0), height + min(oy, 0)), slice(max(ox, 0), width + min(ox, 0)))
        src = (slice(max(-oy, 0), height - max(oy, 0)), slice(max(-ox, 0), width - max(ox, 0)))
        yield t, dst, src


def window(x: torch.Tensor, oy: int, ox: int) -> torch.Tensor:
    """``x(p - o)`` for every p (zero outside the image), by one pad and one slice."""
    height, width = x.shape[-2:]
    py, px = abs(oy), abs(ox)
    padded = F.pad(x, (px, px, py, py))
    return padded[..., py - oy : py - oy + height, px - ox : px - ox + width]
