"""Fusion of branch features: SAMMAFB, concatenation or addition (paper Sec. III-A, Table 2).

Feature fusion (paper Sec. III-A and Table 2): at each encoder scale a guided branch merges its
own features with the decoder features of the branches before it. The paper's SemAttNet
concatenates them and applies :class:`~semattnet.models.attention.SAMMAFB`; the ablations of Table 2
use plain concatenation (``"concat"``) or element-wise addition (``"add"``).

The fusion of the branches' *depths* (eq. 12) is :mod:`semattnet.models.confidence_fusion`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import torch
from torch import nn

from semattnet._errors import InputError
from semattnet.models.attention import SAMMAFB

__all__ = ["FEATURE_FUSION_MODES", "FusionMode", "fuse_features", "make_fusion_block"]

FusionMode = Literal["sammafb", "concat", "add"]
FEATURE_FUSION_MODES: tuple[str, ...] = ("sammafb", "concat", "add")


def make_fusion_block(mode: FusionMode, channels: int, reduction: int = 16) -> nn.Module:
    """The module applied after merging: SAMMAFB, or nothing (``nn.Identity``) for concat/add."""
    if mode == "sammafb":
        return SAMMAFB(channels, reduction)
    if mode in ("concat", "add"):
        return nn.Identity()
    raise InputError(f"unknown feature fusion {mode!r}; choose one of {FEATURE_FUSION_MODES}")


def fuse_features(mode: FusionMode, block: nn.Module, features: Sequence[torch.Tensor]) -> torch.Tensor:
    """Merge branch features (concat order as given, i.e. [CG, SG, DG]) and apply ``block``."""
    if mode == "add":
        out = features[0]
        for f in features[1:]:
            out = out + f
        return block(out)
    return block(torch.cat(tuple(features), dim=1))
