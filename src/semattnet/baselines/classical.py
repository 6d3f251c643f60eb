"""A classical (non-learned) depth completion baseline in the spirit of IP-Basic (Ku et al.,
"In Defense of Classical Image Processing: Fast Depth Completion on the CPU", CRV 2018).

Morphology on inverted depth, so that dilation prefers the nearer surface: diamond dilation,
closing, filling of small and then large holes, extension of the top measurements upwards,
median and Gaussian smoothing. Pure PyTorch (CPU or GPU), no learning, no RGB.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from semattnet.inference.completer import Completion

__all__ = ["ClassicalCompleter", "complete_classical"]


def _kernel(size: int, shape: str) -> list[tuple[int, int]]:
    r = size // 2
    offsets = [(dy, dx) for dy in range(-r, r + 1) for dx in range(-r, r + 1)]
    if shape == "diamond":
        offsets = [(dy, dx) for dy, dx in offsets if abs(dy) + abs(dx) <= r]
    return offsets


def _dilate(x: torch.Tensor, offsets: list[tuple[int, int]]) -> torch.Tensor:
    """Grey dilation of (B, 1, H, W) with a structuring element given as pixel offsets."""
    r = max(max(abs(dy), abs(dx)) for dy, dx in offsets)
    padded = F.pad(x, (r, r, r, r), value=float("-inf"))
    h, w = x.shape[-2:]
    out = torch.full_like(x, float("-inf"))
    for dy, dx in offsets:
        out = torch.maximum(out, padded[..., r + dy : r + dy + h, r + dx : r + dx + w])
    return out


def _erode(x: torch.Tensor, offsets: list[tuple[int, int]]) -> torch.Tensor:
    return -_dilate(-x, offsets)


def _fill(x: torch.Tensor, offsets: list[tuple[int, int]]) -> torch.Tensor:
    """Fill empty (0) pixels with the dilation; keep valid ones."""
    return torch.where(x > 0, x, _dilate(x, offsets).clamp_min(0))


def complete_classical(sparse: torch.Tensor, max_depth: float = 100.0) -> torch.Tensor:
    """Complete (B, 1, H, W) sparse depth in metres (0 = missing) without learning.

    Returns dense depth of the same shape (0 only where an image has no measurement at all).
    """
    if sparse.dim() != 4 or sparse.shape[1] != 1:
        raise ValueError(f"sparse must be (B, 1, H, W), got {tuple(sparse.shape)}")
    d = sparse.float()
    valid = d > 0
    inv = torch.where(valid, max_depth - d.clamp(max=max_depth - 0.1), torch.zeros_like(d))  # near = large
    inv = torch.where(valid, inv, _dilate(inv, _kernel(5, "diamond")).clamp_min(0))
    inv = _erode(_dilate(inv, _kernel(5, "full")), _kernel(5, "full")).clamp_min(0)  # closing
    inv = _fill(inv, _kernel(7, "full"))
    # Extend the top-most measurement of each column upwards (no LiDAR above the top beam).
    h = inv.shape[-2]
    rows = torch.arange(h, device=inv.device).view(1, 1, h, 1)
    has = inv > 0
    top = torch.where(has, rows, torch.full_like(rows, h)).amin(dim=-2, keepdim=True)
    top_val = torch.gather(inv, -2, top.clamp(max=h - 1))
    inv = torch.where((rows < top) & (top < h), top_val, inv)
    inv = _fill(inv, _kernel(31, "full")) if inv.shape[-1] <= 4096 else inv
    # Median then Gaussian smoothing of the filled map (valid pixels only change slightly).
    padded = F.pad(inv, (2, 2, 2, 2), mode="replicate")
    inv = padded.unfold(-2, 5, 1).unfold(-2, 5, 1).reshape(*inv.shape, 25).median(dim=-1).values
    g = torch.exp(-(torch.arange(-2, 3, device=inv.device, dtype=inv.dtype) ** 2) / 2.0)
    g = (g[:, None] * g[None, :] / (g.sum() ** 2)).view(1, 1, 5, 5)
    smooth = F.conv2d(F.pad(inv, (2, 2, 2, 2), mode="replicate"), g)
    inv = torch.where(inv > 0, smooth, inv)
    return torch.where(inv > 0, max_depth - inv, torch.zeros_like(inv))


class ClassicalCompleter:
    """:func:`complete_classical` behind the :class:`~semattnet.inference.DepthCompleter` call:
    ``completer(rgb, sparse, semantic=None)`` -> ``Completion`` (the image and semantics are unused)."""

    needs_semantic = False

    def __call__(self, rgb: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None) -> Completion:
        dense = complete_classical(torch.from_numpy(np.ascontiguousarray(sparse, dtype=np.float32))[None, None])
        depth = dense[0, 0].numpy()
        return Completion(depth=depth, outputs={"refined_depth": depth})
