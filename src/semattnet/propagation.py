"""CSPN++ propagation with atrous (dilated) neighbourhoods (paper Sec. III-C, eq. 13).

One step of the convolutional spatial propagation network, in the form the authors' code
computes it: for a k x k window with raster offsets ``o_t`` (scaled by the dilation) and centre
``c``,

    h'(p) = sum_{t != c} W_t(p - o_t) * h(p - o_t) + W_c(p) * h_0(p)

where ``W`` is the normalised affinity of eq. 13 (``W_t = g_t / sum |g|``, ``W_c = 1 - sum g``),
the affinity is taken at the *neighbour* position, ``h`` and ``W`` are zero outside the image,
and ``h_0`` is the fixed input of the propagation. Every pixel spreads ``W_t h`` to its
neighbours, which is exactly ``torch.nn.functional.fold`` (col2im): one pass, no padded k*k
copies of the image (the authors' pad-and-sum built 2 * k * k of them per step).
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from .layers import convbn

__all__ = ["AffinityHead", "cspn_affinity", "downsample_sparse", "propagate"]


def cspn_affinity(guide: torch.Tensor) -> torch.Tensor:
    """Normalise raw guidance into a CSPN kernel (eq. 13).

    Args:
        guide: (B, k*k - 1, H, W) unnormalised affinities of the neighbours.

    Returns:
        (B, k*k, H, W) weights in raster order, the centre weight ``1 - sum_t W_t`` inserted at
        index (k*k - 1) / 2. Like the authors' code there is no epsilon in the normaliser.
    """
    g = guide / guide.abs().sum(dim=1, keepdim=True)
    centre = 1.0 - g.sum(dim=1, keepdim=True)
    half = g.shape[1] // 2
    return torch.cat((g[:, :half], centre, g[:, half:]), dim=1)


class AffinityHead(nn.Module):
    """3x3 conv + BN producing a k x k CSPN kernel per pixel (the authors' ``CSPNGenerate``).

    Args:
        in_channels: width of the guidance features.
        kernel_size: propagation window k (odd).
    """

    def __init__(self, in_channels: int, kernel_size: int) -> None:
        super().__init__()
        self.kernel_size = kernel_size
        self.generate = convbn(in_channels, kernel_size * kernel_size - 1)

    def forward(self, feature: torch.Tensor) -> torch.Tensor:
        return cspn_affinity(self.generate(feature))


def propagate(affinity: torch.Tensor, h: torch.Tensor, h0: torch.Tensor, dilation: int = 1) -> torch.Tensor:
    """One CSPN++ step (module docstring) for every channel of ``h`` with one shared kernel.

    Args:
        affinity: (B, k*k, H, W) normalised kernel from :func:`cspn_affinity`.
        h: (B, C, H, W) current estimate h_n; the C channels (e.g. the four polyphase
            sub-grids of the dilation-2 stage) are propagated independently.
        h0: (B, C, H, W) fixed input h_0 weighted by the centre tap.
        dilation: spacing of the window taps.

    Returns:
        (B, C, H, W) the next estimate h_{n+1}.
    """
    b, kk, height, width = affinity.shape
    k = math.isqrt(kk)
    if k * k != kk or k % 2 == 0:
        raise ValueError(f"affinity must have k*k channels for an odd k, got {kk}")
    c = h.shape[1]
    centre = kk // 2
    is_centre = torch.zeros(kk, dtype=torch.bool, device=h.device)
    is_centre[centre] = True
    # Per tap: the value each pixel sends, W_t(q) * h(q), or W_c(q) * h_0(q) at the centre.
    source = torch.where(is_centre[:, None, None], h0.unsqueeze(2), h.unsqueeze(2))  # (B, C, K, H, W)
    sent = affinity.unsqueeze(1) * source
    # fold adds tap t of pixel q into q + o_t: out(p) = sum_t sent_t(p - o_t).
    return F.fold(
        sent.reshape(b, c * kk, height * width),
        output_size=(height, width),
        kernel_size=k,
        dilation=dilation,
        padding=(k // 2) * dilation,
    )


def downsample_sparse(sparse: torch.Tensor, factor: int = 2) -> tuple[torch.Tensor, torch.Tensor]:
    """Sparse depth at 1/factor resolution: the nearest (minimum) valid depth of each block.

    Returns:
        ``(depth, mask)``: depth (0 where a block has no measurement) and a float mask of the
        blocks holding at least one measurement, each (B, 1, H/factor, W/factor).
    """
    valid = sparse > 0
    nearest = -F.max_pool2d(-torch.where(valid, sparse, torch.full_like(sparse, math.inf)), factor)
    mask = F.max_pool2d(valid.to(sparse.dtype), factor)
    return torch.where(mask > 0, nearest, torch.zeros_like(nearest)), mask
