"""The CSPN++ kernel: guidance features -> normalised k x k affinity (paper eq. 13), and the
sparse depth at half resolution for the dilation-2 stage."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Literal

import torch
import torch.nn.functional as F
from torch import nn

from semattnet._errors import InputError
from semattnet.models.layers import convbn
from semattnet.models.propagation._common import kernel_size, window

__all__ = [
    "AFFINITY_FORMS",
    "AffinityForm",
    "AffinityHead",
    "check_affinity_form",
    "convex_affinity",
    "cspn_affinity",
    "downsample_sparse",
    "normalise_affinity",
]

#: How raw guidance becomes a propagation kernel: ``"eq13"`` (the paper's, :func:`cspn_affinity`) or ``"convex"``
#: (:func:`convex_affinity`).
AffinityForm = Literal["eq13", "convex"]


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


def convex_affinity(guide: torch.Tensor) -> torch.Tensor:
    """A convex CSPN kernel: what each pixel *receives* is the softmax of its guidance and a centre logit fixed at 0.

    The propagation sends ``W_t(p) h(p)`` from each pixel to its neighbour ``p + o_t`` (eq. 13's scatter form), so
    pixel q receives the weights ``W_t(q - o_t)`` of its neighbours. Eq. 13 bounds only the weights a pixel sends
    (their absolute values sum to 1, the centre's ``1 - sum_t W_t`` in [0, 2]): what a pixel receives can be
    negative or exceed 1, so a step can push a pixel far outside its neighbours' range (a 70 m return inside a
    6 m object sends a reduced-resolution refinement below zero). Here the received weights ``G = softmax(guide,
    0)`` are positive and sum to 1 at every pixel (less at the border, where the image ends): each step is a
    weighted mean of the pixel's neighbourhood, so the depth stays within the range of its inputs (the maximum
    principle). The kernel returned is ``G`` moved back to the senders, ``W_t(p) = G_t(p + o_t)`` (0 where
    ``p + o_t`` is outside), so every propagation form runs it unchanged.

    Args:
        guide: (B, k*k - 1, H, W) unnormalised logits of the neighbours.

    Returns:
        (B, k*k, H, W) weights in raster order, the centre's at index (k*k - 1) / 2.
    """
    half = guide.shape[1] // 2
    centre = torch.zeros_like(guide[:, :1])
    received = torch.softmax(torch.cat((guide[:, :half], centre, guide[:, half:]), dim=1), dim=1)
    k = kernel_size(received)
    r = k // 2
    sent = [window(received[:, t : t + 1], r - t // k, r - t % k) for t in range(k * k)]
    return torch.cat(sent, dim=1)


#: Each :data:`AffinityForm`'s normalisation.
AFFINITY_FORMS: dict[str, Callable[[torch.Tensor], torch.Tensor]] = {"eq13": cspn_affinity, "convex": convex_affinity}


def check_affinity_form(form: str) -> None:
    """Refuse a ``form`` that is not one of :data:`AFFINITY_FORMS` (a one-line :class:`~semattnet.InputError`)."""
    if form not in AFFINITY_FORMS:
        raise InputError(f"affinity must be one of {tuple(AFFINITY_FORMS)}, got {form!r}")


def normalise_affinity(guide: torch.Tensor, form: str = "eq13") -> torch.Tensor:
    """``guide`` normalised into a kernel by :data:`AFFINITY_FORMS` ``[form]``."""
    check_affinity_form(form)
    return AFFINITY_FORMS[form](guide)


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
