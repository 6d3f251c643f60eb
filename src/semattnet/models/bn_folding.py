"""Inference-only graph simplification: fold every BatchNorm into the convolution before it.

In eval mode BatchNorm is an affine map per channel, so ``BN(conv(x))`` equals one convolution
with scaled weights and a bias (for ``ConvTranspose2d`` too). Folding removes one full pass over
every activation tensor. The folded model computes the same function (to float rounding) but
its state dict no longer has the ``bn`` keys, so keep the original for checkpoints.
"""

from __future__ import annotations

import copy
from typing import TypeVar

from torch import nn
from torch.nn.utils.fusion import fuse_conv_bn_eval

from semattnet.models.attention import SpatialConv
from semattnet.models.layers import BasicBlock

__all__ = ["fold_batchnorm"]

_CONVS = (nn.Conv2d, nn.ConvTranspose2d)


_Conv = TypeVar("_Conv", bound=nn.Conv2d | nn.ConvTranspose2d)


def _fused(conv: _Conv, bn: nn.BatchNorm2d) -> _Conv:
    return fuse_conv_bn_eval(conv, bn, transpose=isinstance(conv, nn.ConvTranspose2d))


def fold_batchnorm(model: nn.Module, inplace: bool = False) -> nn.Module:
    """Return ``model`` (a copy unless ``inplace``) in eval mode with BatchNorms folded away.

    Handles the project's patterns: ``nn.Sequential(conv, BN, ...)`` (convbn, convbnrelu,
    deconvbnrelu, downsample), :class:`BasicBlock` (conv1/bn1, conv2/bn2) and the SAMMAFB
    spatial gate (conv/bn). Returns the number of folds in ``model.folded_batchnorms``.
    """
    model = model if inplace else copy.deepcopy(model)
    model.eval()
    folds = 0
    for module in list(model.modules()):
        if isinstance(module, nn.Sequential):
            children = list(module)
            for i in range(len(children) - 1):
                first, second = children[i], children[i + 1]
                if isinstance(first, _CONVS) and isinstance(second, nn.BatchNorm2d):
                    module[i] = _fused(first, second)
                    module[i + 1] = nn.Identity()
                    folds += 1
        elif isinstance(module, BasicBlock):
            for conv, bn in (("conv1", "bn1"), ("conv2", "bn2")):
                if isinstance(getattr(module, bn), nn.BatchNorm2d):
                    setattr(module, conv, _fused(getattr(module, conv), getattr(module, bn)))
                    setattr(module, bn, nn.Identity())
                    folds += 1
        elif isinstance(module, SpatialConv) and isinstance(module.bn, nn.BatchNorm2d):
            module.conv = _fused(module.conv, module.bn)
            module.bn = nn.Identity()
            folds += 1
    remaining = sum(isinstance(m, nn.BatchNorm2d) for m in model.modules())
    if remaining:
        raise RuntimeError(f"{remaining} BatchNorm layers have no convolution to fold into")
    model.folded_batchnorms = folds  # type: ignore[assignment]
    return model
