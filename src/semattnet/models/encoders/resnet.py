"""The authors' ResNet-style encoder (paper Sec. III-B, from PENet): 5x5 stem, two basic blocks a stride-2 stage.

One implementation, two namings: :class:`ResNetEncoder` is the stand-alone module (``stem``,
``layer1`` ... ``layer{2n}``), registered as ``"resnet"``; the paper's branches build and run the same
layers directly on the backbone under the authors' flat names (``rgb_conv_init``,
``rgb_encoder_layer{1..10}``, ...) with :func:`add_resnet_layers` / :func:`run_resnet_layers`, so
the authors' checkpoints load unchanged. :func:`semattnet.weights.checkpoint_filter.authors_encoder_filter`
maps their keys onto a :class:`ResNetEncoder`.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from semattnet.models.encoders.base import FeatureInfo, StageHook
from semattnet.models.layers import BasicBlock, convbnrelu

__all__ = ["ResNetEncoder", "add_resnet_layers", "run_resnet_layers"]


def add_resnet_layers(
    owner: object, stem: str, prefix: str, in_chans: int, channels: Sequence[int], extra: Sequence[int] | None = None
) -> None:
    """Register the stem ``owner.<stem>`` and the blocks ``owner.<prefix>1`` ... ``<prefix>{2n}``.

    ``channels``: the stem's width, then one per stage; ``extra``: channels a hook adds after each stage.
    """
    setattr(owner, stem, convbnrelu(in_chans, channels[0], kernel_size=5, padding=2))
    prev = channels[0]
    for i, c in enumerate(channels[1:]):
        setattr(owner, f"{prefix}{2 * i + 1}", BasicBlock(prev, c, stride=2))
        setattr(owner, f"{prefix}{2 * i + 2}", BasicBlock(c, c))
        prev = c + (extra[i] if extra is not None else 0)


def run_resnet_layers(
    owner: object, stem: str, prefix: str, stages: int, x: torch.Tensor, hook: StageHook | None = None
) -> tuple[torch.Tensor, list[torch.Tensor]]:
    """The layers of :func:`add_resnet_layers`: (stem output, each stage's output before ``hook``).

    ``hook(i, features)`` runs after every stage but the last and gives the next stage's input.
    """
    x = getattr(owner, stem)(x)
    first = x
    features = []
    for i in range(stages):
        x = getattr(owner, f"{prefix}{2 * i + 2}")(getattr(owner, f"{prefix}{2 * i + 1}")(x))
        features.append(x)
        if hook is not None and i < stages - 1:
            x = hook(i, x)
    return first, features


class ResNetEncoder(nn.Module):
    """The authors' encoder as a module: stem (5x5, stride 1), then per stage two :class:`BasicBlock` (stride 2).

    Args:
        in_chans: input channels.
        channels: the stem's width, then one per stage (the paper: 32, 64, ..., 1024 at width 1).
        extra: channels a :data:`StageHook` adds after each stage (the paper's concatenated guidance).

    Shape:
        (B, in_chans, H, W) -> stem (B, channels[0], H, W) and, per stage i,
        (B, channels[i + 1], H / 2**(i + 1), W / 2**(i + 1)).
    """

    def __init__(self, in_chans: int, channels: Sequence[int], extra: Sequence[int] | None = None) -> None:
        super().__init__()
        self.stages = len(channels) - 1
        self.feature_info = FeatureInfo(
            channels[0], 1, tuple(2 ** (i + 1) for i in range(self.stages)), tuple(channels[1:])
        )
        add_resnet_layers(self, "stem", "layer", in_chans, channels, extra)

    def forward(self, x: torch.Tensor, hook: StageHook | None = None) -> tuple[torch.Tensor, list[torch.Tensor]]:
        return run_resnet_layers(self, "stem", "layer", self.stages, x, hook)
