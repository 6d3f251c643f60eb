"""Fusion: of branch features (SAMMAFB, concatenation or addition) and of branch depths (eq. 12).

Feature fusion (paper Sec. III-A and Table 2): at each encoder scale a guided branch merges its
own features with the decoder features of the branches before it. The paper's SemAttNet
concatenates them and applies :class:`~semattnet.attention.SAMMAFB`; the ablations of Table 2
use plain concatenation (``"concat"``) or element-wise addition (``"add"``).

Depth fusion (paper eq. 12): ``D_f = sum_b exp(C_b) D_b / sum_b exp(C_b)``, a per-pixel softmax
over the branches' confidence maps.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import torch
from torch import nn

from .attention import SAMMAFB

__all__ = ["FEATURE_FUSION_MODES", "FusionMode", "confidence_fusion", "fuse_features", "make_fusion_block"]

FusionMode = Literal["sammafb", "concat", "add"]
FEATURE_FUSION_MODES: tuple[str, ...] = ("sammafb", "concat", "add")


def make_fusion_block(mode: FusionMode, channels: int, reduction: int = 16) -> nn.Module:
    """The module applied after merging: SAMMAFB, or nothing (``nn.Identity``) for concat/add."""
    if mode == "sammafb":
        return SAMMAFB(channels, reduction)
    if mode in ("concat", "add"):
        return nn.Identity()
    raise ValueError(f"unknown feature fusion {mode!r}; choose one of {FEATURE_FUSION_MODES}")


def fuse_features(mode: FusionMode, block: nn.Module, features: Sequence[torch.Tensor]) -> torch.Tensor:
    """Merge branch features (concat order as given, i.e. [CG, SG, DG]) and apply ``block``."""
    if mode == "add":
        out = features[0]
        for f in features[1:]:
            out = out + f
        return block(out)
    return block(torch.cat(tuple(features), dim=1))


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
