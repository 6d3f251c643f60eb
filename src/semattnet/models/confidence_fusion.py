"""Confidence-weighted fusion of the three branch depths (paper eq. 12).

``D_f = sum_b exp(C_b) D_b / sum_b exp(C_b)``: a per-pixel softmax over the branches' confidence
maps weights their depth maps.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

__all__ = ["confidence_fusion"]


def confidence_fusion(
    depths: Sequence[torch.Tensor], confidences: Sequence[torch.Tensor]
) -> tuple[torch.Tensor, list[torch.Tensor]]:
    """Paper eq. 12: softmax the confidences across branches and blend the depths.

    Args:
        depths: per-branch depth maps, each (B, 1, H, W).
        confidences: per-branch (post-ReLU) confidence maps, each (B, 1, H, W).

    Returns:
        The fused depth (B, 1, H, W) and the per-branch fusion weights (post-softmax).
    """
    weights = torch.softmax(torch.cat(tuple(confidences), dim=1), dim=1)
    fused = (weights * torch.cat(tuple(depths), dim=1)).sum(dim=1, keepdim=True)
    return fused, list(weights.split(1, dim=1))
