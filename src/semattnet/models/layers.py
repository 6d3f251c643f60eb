"""Convolutional building blocks shared by the three branches.

The names and layouts follow the authors' release (itself derived from PENet) so that
state-dict keys line up: ``convbnrelu`` and ``deconvbnrelu`` are ``nn.Sequential`` with the
convolution at index 0 and the BatchNorm at index 1, and :class:`BasicBlock` is the
torchvision ResNet block with attributes ``conv1``/``bn1``/``conv2``/``bn2``/``downsample``.
All convolutions are bias-free; BatchNorm uses PyTorch defaults.
"""

from __future__ import annotations

import torch
import torch.utils.checkpoint
from torch import nn

__all__ = ["BasicBlock", "convbn", "convbnrelu", "deconvbnrelu", "set_gradient_checkpointing", "stacked_heads"]


def convbn(in_ch: int, out_ch: int, kernel_size: int = 3, stride: int = 1, padding: int = 1) -> nn.Sequential:
    """Conv2d -> BatchNorm2d (keys ``0.weight``, ``1.*``)."""
    return nn.Sequential(
        nn.Conv2d(in_ch, out_ch, kernel_size, stride=stride, padding=padding, bias=False),
        nn.BatchNorm2d(out_ch),
    )


def _same_geometry(convs: list[nn.Conv2d]) -> bool:
    keys = {(c.in_channels, c.kernel_size, c.stride, c.padding, c.dilation, c.groups, c.padding_mode) for c in convs}
    return len(keys) == 1 and convs[0].groups == 1 and convs[0].padding_mode == "zeros"


def stacked_heads(x: torch.Tensor, heads: list[nn.Sequential]) -> torch.Tensor:
    """``torch.cat([head(x) for head in heads], dim=1)`` with the heads' first convolutions run as one.

    Heads that read the same tensor through convolutions of the same geometry (the CSPN++ guide,
    confidence and mask heads: 84 output channels in all at full resolution) are one convolution
    with the weights stacked; each head's remaining layers (its BatchNorm) then run on its own
    channels. After :func:`~semattnet.models.bn_folding.fold_batchnorm` those are ``Identity``
    and the convolution's output is the result: no split, no copy. The same function with the
    same gradients; one wide convolution runs several times faster than five narrow ones (1-48
    output channels underfill the vector width).
    """
    convs = [h[0] for h in heads if type(h[0]) is nn.Conv2d]
    if len(heads) < 2 or len(convs) != len(heads) or not _same_geometry(convs):
        return torch.cat([h(x) for h in heads], dim=1)
    first = convs[0]
    bias = None  # the training form has none; the folded form has all: zeros only for a mix
    if any(c.bias is not None for c in convs):
        bias = torch.cat([c.bias if c.bias is not None else c.weight.new_zeros(c.out_channels) for c in convs])
    y = nn.functional.conv2d(x, torch.cat([c.weight for c in convs]), bias, first.stride, first.padding, first.dilation)
    if all(type(m) is nn.Identity for h in heads for m in list(h)[1:]):
        return y
    parts = torch.split(y, [c.out_channels for c in convs], dim=1)
    return torch.cat([head[1:](part) for head, part in zip(heads, parts, strict=True)], dim=1)


def convbnrelu(in_ch: int, out_ch: int, kernel_size: int = 3, stride: int = 1, padding: int = 1) -> nn.Sequential:
    """Conv2d -> BatchNorm2d -> ReLU."""
    return nn.Sequential(*convbn(in_ch, out_ch, kernel_size, stride, padding), nn.ReLU(inplace=True))


def deconvbnrelu(
    in_ch: int,
    out_ch: int,
    kernel_size: int = 5,
    stride: int = 2,
    padding: int = 2,
    output_padding: int = 1,
) -> nn.Sequential:
    """ConvTranspose2d -> BatchNorm2d -> ReLU; with the defaults it doubles H and W."""
    return nn.Sequential(
        nn.ConvTranspose2d(
            in_ch, out_ch, kernel_size, stride=stride, padding=padding, output_padding=output_padding, bias=False
        ),
        nn.BatchNorm2d(out_ch),
        nn.ReLU(inplace=True),
    )


class BasicBlock(nn.Module):
    """ResNet basic block (He et al. 2016), as in torchvision.

    ``conv3x3(stride) -> BN -> ReLU -> conv3x3 -> BN``, plus the identity (a strided 1x1
    convolution + BN when the stride or the width changes), then ReLU.

    Args:
        inplanes: input channels.
        planes: output channels.
        stride: 1, or 2 to halve H and W.
    """

    def __init__(self, inplanes: int, planes: int, stride: int = 1) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(inplanes, planes, 3, stride=stride, padding=1, bias=False)
        self.bn1 = nn.BatchNorm2d(planes)
        self.relu = nn.ReLU(inplace=True)
        self.conv2 = nn.Conv2d(planes, planes, 3, stride=1, padding=1, bias=False)
        self.bn2 = nn.BatchNorm2d(planes)
        self.downsample: nn.Module | None = None
        if stride != 1 or inplanes != planes:
            self.downsample = nn.Sequential(
                nn.Conv2d(inplanes, planes, 1, stride=stride, bias=False),
                nn.BatchNorm2d(planes),
            )

    #: Recompute this block in the backward pass instead of storing its activations (set by
    #: :func:`set_gradient_checkpointing`). BN running statistics then see each batch twice.
    checkpointing: bool = False

    def _forward(self, x: torch.Tensor) -> torch.Tensor:
        identity = x if self.downsample is None else self.downsample(x)
        out = self.relu(self.bn1(self.conv1(x)))
        out = self.bn2(self.conv2(out))
        return self.relu(out + identity)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.checkpointing and self.training and torch.is_grad_enabled():
            return torch.utils.checkpoint.checkpoint(self._forward, x, use_reentrant=False)
        return self._forward(x)


def set_gradient_checkpointing(model: nn.Module, enabled: bool = True) -> int:
    """Turn activation checkpointing of every :class:`BasicBlock` in ``model`` on or off.

    Returns the number of blocks changed.
    """
    blocks = [m for m in model.modules() if isinstance(m, BasicBlock)]
    for m in blocks:
        m.checkpointing = enabled
    return len(blocks)
