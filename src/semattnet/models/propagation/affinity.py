"""The CSPN++ kernel: guidance features -> normalised k x k affinity (paper eq. 13), and the
sparse depth at half resolution for the dilation-2 stage."""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from semattnet.models.layers import convbn

__all__ = ["AffinityHead", "cspn_affinity", "downsample_sparse"]


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
