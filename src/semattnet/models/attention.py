"""SAMMAFB: the semantic-aware multi-modal attention-based fusion block (paper Sec. III-A).

SAMMAFB is CBAM (Woo et al. 2018) applied to a channel concatenation of branch features
``F = [F_RGB; F_Sem; F_D]``: channel attention (eq. 1) then spatial attention (eq. 2). Its
output has the width of its input; nothing is added back.

Attribute names (``ChannelGate.mlp``, ``SpatialGate.spatial.conv``/``.bn``) reproduce the
authors' state-dict keys.
"""

from __future__ import annotations

import torch
from torch import nn

__all__ = ["SAMMAFB", "ChannelGate", "SpatialGate"]


class ChannelGate(nn.Module):
    """Channel attention, paper eq. 1: ``A_c(F) = sigmoid(MLP(AvgPool F) + MLP(MaxPool F))``.

    Args:
        channels: width C of the concatenated features.
        reduction: ratio r of the shared MLP's bottleneck (C -> C//r -> C).
    """

    def __init__(self, channels: int, reduction: int = 16) -> None:
        super().__init__()
        hidden = max(1, channels // reduction)
        # Keys mlp.1 and mlp.3: Flatten, Linear (W_0), ReLU, Linear (W_1).
        self.mlp = nn.Sequential(
            nn.Flatten(), nn.Linear(channels, hidden), nn.ReLU(inplace=True), nn.Linear(hidden, channels)
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        avg = self.mlp(x.mean(dim=(2, 3)))
        mx = self.mlp(x.amax(dim=(2, 3)))
        return x * torch.sigmoid(avg + mx)[:, :, None, None]


class SpatialConv(nn.Module):
    """7x7 conv (2 -> 1, no bias) + BatchNorm with CBAM's momentum 0.01."""

    def __init__(self, kernel_size: int = 7) -> None:
        super().__init__()
        self.conv = nn.Conv2d(2, 1, kernel_size, padding=(kernel_size - 1) // 2, bias=False)
        self.bn: nn.Module = nn.BatchNorm2d(1, eps=1e-5, momentum=0.01)  # nn.Identity once folded

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.bn(self.conv(x))


class SpatialGate(nn.Module):
    """Spatial attention, paper eq. 2: ``A_s(F') = sigmoid(Conv([max_c F'; mean_c F']))``.

    The pooled maps are stacked max first, then mean (the authors' order).
    """

    def __init__(self, kernel_size: int = 7) -> None:
        super().__init__()
        self.spatial = SpatialConv(kernel_size)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        pooled = torch.cat((x.amax(dim=1, keepdim=True), x.mean(dim=1, keepdim=True)), dim=1)
        return x * torch.sigmoid(self.spatial(pooled))


class SAMMAFB(nn.Module):
    """Semantic-aware multi-modal attention-based fusion block.

    ``F'' = A_s(F') * F'`` with ``F' = A_c(F) * F`` (paper eqs. 1-2).

    Args:
        channels: width of the concatenated input (and of the output).
        reduction: channel-MLP reduction ratio r (16 in the paper's code).

    Shape:
        (B, C, H, W) -> (B, C, H, W)
    """

    def __init__(self, channels: int, reduction: int = 16) -> None:
        super().__init__()
        self.ChannelGate = ChannelGate(channels, reduction)
        self.SpatialGate = SpatialGate()

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.SpatialGate(self.ChannelGate(x))
