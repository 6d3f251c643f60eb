"""A light encoder for the real-time variants: a strided stem, then depthwise-separable stages.

The blocks are written here rather than taken from timm: timm needs torchvision, whose PyPI wheels
are built against the CUDA torch and do not import beside the CPU-only torch this package runs on.
What they are: MobileNet-v1 style depthwise-separable convolutions (3x3 depthwise, 1x1 pointwise,
each followed by BatchNorm and ReLU) with a residual form for the non-strided block. Every
convolution is followed by BatchNorm then ReLU, the pattern OpenVINO (and
:func:`~semattnet.models.bn_folding.fold_batchnorm`) fold into one convolution, and nothing reads
the memory layout, so the module runs in ``channels_last`` as it is.

The stem brings the input to 1/2 or 1/4 resolution at once (``stem_stride``): the small paper
model spends most of its time on few-channel convolutions at full resolution, bound by memory
traffic (issue "real time on a CPU"), so the branches here never run at full resolution.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from semattnet._errors import InputError
from semattnet.models.encoders.base import FeatureInfo, StageHook
from semattnet.models.layers import convbnrelu

__all__ = ["LiteBlock", "LiteEncoder", "dwsep"]


def dwsep(in_ch: int, out_ch: int, stride: int = 1, relu: bool = True) -> nn.Sequential:
    """3x3 depthwise (stride) -> BN -> ReLU -> 1x1 pointwise -> BN (-> ReLU)."""
    layers: list[nn.Module] = [
        nn.Conv2d(in_ch, in_ch, 3, stride=stride, padding=1, groups=in_ch, bias=False),
        nn.BatchNorm2d(in_ch),
        nn.ReLU(inplace=True),
        nn.Conv2d(in_ch, out_ch, 1, bias=False),
        nn.BatchNorm2d(out_ch),
    ]
    if relu:
        layers.append(nn.ReLU(inplace=True))
    return nn.Sequential(*layers)


class LiteBlock(nn.Module):
    """Residual depthwise-separable block: ``ReLU(x + dwsep(x))``, width and resolution kept."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.body = dwsep(channels, channels, relu=False)
        self.relu = nn.ReLU(inplace=True)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.relu(x + self.body(x))


class LiteEncoder(nn.Module):
    """Stem (3x3 stride-2 convolution, one more stride-2 separable one for ``stem_stride=4``), then per
    stage a strided separable block and ``depth`` residual ones.

    Args:
        in_chans: input channels.
        channels: the stem's width, then one per stage.
        extra: channels a :data:`StageHook` adds after each stage.
        stem_stride: 2 or 4.
        depth: residual blocks per stage after the strided one.

    Shape:
        (B, in_chans, H, W) -> stem (B, channels[0], H / s, W / s), stage i (B, channels[i + 1], H / (s 2**(i+1)), ...).
    """

    def __init__(
        self,
        in_chans: int,
        channels: Sequence[int],
        extra: Sequence[int] | None = None,
        stem_stride: int = 4,
        depth: int = 1,
    ) -> None:
        super().__init__()
        if stem_stride not in (2, 4):
            raise InputError(f"stem_stride must be 2 or 4, got {stem_stride!r}")
        stem: list[nn.Module] = [convbnrelu(in_chans, channels[0], kernel_size=3, stride=2, padding=1)]
        if stem_stride == 4:
            stem.append(dwsep(channels[0], channels[0], stride=2))
        self.stem = nn.Sequential(*stem)
        n = len(channels) - 1
        self.feature_info = FeatureInfo(
            channels[0], stem_stride, tuple(stem_stride * 2 ** (i + 1) for i in range(n)), tuple(channels[1:])
        )
        stages = []
        prev = channels[0]
        for i, c in enumerate(channels[1:]):
            stages.append(nn.Sequential(dwsep(prev, c, stride=2), *(LiteBlock(c) for _ in range(depth))))
            prev = c + (extra[i] if extra is not None else 0)
        self.stages = nn.ModuleList(stages)

    def forward(self, x: torch.Tensor, hook: StageHook | None = None) -> tuple[torch.Tensor, list[torch.Tensor]]:
        x = first = self.stem(x)
        features = []
        for i, stage in enumerate(self.stages):
            x = stage(x)
            features.append(x)
            if hook is not None and i < len(self.stages) - 1:
                x = hook(i, x)
        return first, features
