"""Colour-guided (CG) branch, paper Sec. III-B-1, eqs. 3-5.

Input ``X_cg = [C; D]`` (RGB 0..255 and sparse depth in metres). A ResNet encoder of ten basic
blocks (five stride-2 stages) and a decoder of five transposed convolutions with additive skips,
then a head giving the colour depth D_cg and its confidence C_cg. The decoder features at each
scale ("cg2+", "cg4+", ... in the authors' code) guide the SG and DG branches.

Key names: ``rgb_conv_init``, ``rgb_encoder_layer{1..10}``, ``rgb_decoder_layer{8,6,4,2,0}``
(named after the encoder block whose output they are added to), ``rgb_decoder_output``.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
from torch import nn

from semattnet.models.config import Widths
from semattnet.models.encoders.resnet import add_resnet_layers, run_resnet_layers
from semattnet.models.layers import deconvbnrelu

__all__ = ["ColorGuidedBranch", "ColorGuidedFeatures"]

_STAGES = (2, 4, 8, 16, 32)  # downsampling factor after encoder blocks 2i+1, 2i+2


class ColorGuidedFeatures(NamedTuple):
    """What the CG branch hands to the fusion and to the later branches."""

    depth: torch.Tensor  # D_cg, (B, 1, H, W)
    conf: torch.Tensor  # C_cg before the cross-branch softmax, >= 0
    decoder: dict[int, torch.Tensor]  # decoder features after the skip add, by scale 2..16
    encoder_out: torch.Tensor  # deepest encoder features (scale 32), fused into SG and DG
    feature_s1: torch.Tensor  # full-resolution decoder features (refinement guidance)


class ColorGuidedBranch:
    """Mixin: builds and runs the colour-guided branch on an ``nn.Module``."""

    rgb_conv_init: nn.Sequential
    rgb_decoder_output: nn.Sequential

    def _build_color_guided(self, w: Widths, depth_channels: int = 1) -> None:
        c = w.base
        stages = [c[s] for s in (1, *_STAGES)]
        add_resnet_layers(self, "rgb_conv_init", "rgb_encoder_layer", 3 + depth_channels, stages)
        for s in (16, 8, 4, 2, 1):  # rgb_decoder_layer8 ... rgb_decoder_layer0
            setattr(self, f"rgb_decoder_layer{_encoder_index(s)}", deconvbnrelu(2 * c[s], c[s]))
        self.rgb_decoder_output = nn.Sequential(
            nn.ConvTranspose2d(c[1], 2, 3, stride=1, padding=1, bias=False), nn.BatchNorm2d(2), nn.ReLU(inplace=True)
        )

    def _color_guided(self, rgb: torch.Tensor, sparse: torch.Tensor) -> ColorGuidedFeatures:
        x = torch.cat((rgb, sparse), dim=1)
        stem, features = run_resnet_layers(self, "rgb_conv_init", "rgb_encoder_layer", len(_STAGES), x)
        skips = {1: stem, **dict(zip(_STAGES, features, strict=True))}
        x = skips[32]
        decoder: dict[int, torch.Tensor] = {}
        for s in (16, 8, 4, 2, 1):
            x = getattr(self, f"rgb_decoder_layer{_encoder_index(s)}")(x) + skips[s]
            decoder[s] = x
        out = self.rgb_decoder_output(x)
        return ColorGuidedFeatures(
            depth=out[:, 0:1],
            conf=out[:, 1:2],
            decoder={s: decoder[s] for s in (2, 4, 8, 16)},
            encoder_out=skips[32],
            feature_s1=decoder[1],
        )


def _encoder_index(scale: int) -> int:
    """Index of the encoder block whose output lives at ``scale`` (1 -> 0 for the stem)."""
    return 0 if scale == 1 else 2 * _STAGES.index(scale) + 2
