"""Depth-guided (DG) branch, paper Sec. III-B-3, eqs. 9-11.

Input ``X_dg = [D; D_cg; D_sg]`` (two-branch ablation: ``[D; D_cg]``). At every encoder scale
the DG features are concatenated with the CG decoder features and the SG decoder features
(order [CG, SG, DG]) and fused by SAMMAFB, so the DG encoder widens to 192, 448, 960 and 1984
channels in the paper model. Its decoder starts from a 1x1 transposed convolution of the
deepest DG features added to the CG and SG deepest features, uses its own encoder outputs as
skips and ends in a 3x3 convolution head giving the guided depth D_dg and its confidence C_dg.

Key names: ``depth_conv_init``, ``depth_layer{1..10}``, ``decoder_layer{0..6}`` and the fusion
blocks ``cbam_192/448/960/1984`` (SAMMAFB at scales 2, 4, 8, 16).
"""

from __future__ import annotations

from typing import NamedTuple

import torch
from torch import nn

from semattnet.models.branches.color_guided import ColorGuidedFeatures
from semattnet.models.branches.semantic_guided import SemanticGuidedFeatures
from semattnet.models.config import SemAttNetConfig, Widths
from semattnet.models.encoders.resnet import add_resnet_layers, run_resnet_layers
from semattnet.models.fusion import FusionMode, fuse_features, make_fusion_block
from semattnet.models.layers import convbnrelu, deconvbnrelu

__all__ = ["DG_FUSION_BLOCKS", "DepthGuidedBranch", "DepthGuidedFeatures"]

#: Fusion block (SAMMAFB) attribute name per scale, as in the authors' keys.
DG_FUSION_BLOCKS = {2: "cbam_192", 4: "cbam_448", 8: "cbam_960", 16: "cbam_1984"}
_STAGES = (2, 4, 8, 16, 32)


class DepthGuidedFeatures(NamedTuple):
    depth: torch.Tensor  # D_dg
    conf: torch.Tensor  # C_dg before the cross-branch softmax
    feature_s1: torch.Tensor  # full-resolution decoder features
    feature_s2: torch.Tensor  # half-resolution decoder features


class DepthGuidedBranch:
    """Mixin: builds and runs the depth-guided branch on an ``nn.Module``."""

    depth_conv_init: nn.Sequential
    decoder_layer0: nn.Sequential
    decoder_layer1: nn.Sequential  # decoder_layer1..5 are set in a loop (setattr)
    decoder_layer5: nn.Sequential
    decoder_layer6: nn.Sequential
    _dg_fusion: FusionMode

    def _build_depth_fusion(self, w: Widths, cfg: SemAttNetConfig) -> None:
        self._dg_fusion = cfg.fusion
        for s, name in DG_FUSION_BLOCKS.items():
            setattr(self, name, make_fusion_block(cfg.fusion, w.fused_dg[s], cfg.reduction))

    def _build_depth_guided(self, w: Widths, cfg: SemAttNetConfig) -> None:
        c, dg = w.base, w.dg
        extra = [w.fused_dg.get(s, dg[s]) - dg[s] for s in _STAGES]
        in_chans = cfg.branches - 1 + cfg.depth_channels
        add_resnet_layers(self, "depth_conv_init", "depth_layer", in_chans, [c[1], *(dg[s] for s in _STAGES)], extra)
        self.decoder_layer0 = deconvbnrelu(dg[32], c[32], kernel_size=1, stride=1, padding=0, output_padding=0)
        widths = (c[32], dg[16], dg[8], dg[4], dg[2], c[1])
        for j in range(5):
            setattr(self, f"decoder_layer{j + 1}", deconvbnrelu(widths[j], widths[j + 1]))
        self.decoder_layer6 = convbnrelu(c[1], 2, kernel_size=3, padding=1)

    def _depth_guided(
        self, sparse: torch.Tensor, cg: ColorGuidedFeatures, sg: SemanticGuidedFeatures | None
    ) -> DepthGuidedFeatures:
        inputs = (sparse, cg.depth) if sg is None else (sparse, cg.depth, sg.depth)

        def fuse(i: int, x: torch.Tensor) -> torch.Tensor:  # SAMMAFB after the stages at scales 2 .. 16
            s = _STAGES[i]
            guides = (cg.decoder[s], x) if sg is None else (cg.decoder[s], sg.decoder[s], x)
            return fuse_features(self._dg_fusion, getattr(self, DG_FUSION_BLOCKS[s]), guides)

        x = torch.cat(inputs, dim=1)
        _, features = run_resnet_layers(self, "depth_conv_init", "depth_layer", len(_STAGES), x, fuse)
        skips = dict(zip(_STAGES, features, strict=True))
        deepest = cg.encoder_out if sg is None else cg.encoder_out + sg.encoder_out
        x = self.decoder_layer1(deepest + self.decoder_layer0(skips[32]))
        for j, s in enumerate((16, 8, 4)):
            x = getattr(self, f"decoder_layer{j + 2}")(skips[s] + x)
        feature_s2 = x
        feature_s1 = self.decoder_layer5(skips[2] + x)
        out = self.decoder_layer6(feature_s1)
        return DepthGuidedFeatures(depth=out[:, 0:1], conf=out[:, 1:2], feature_s1=feature_s1, feature_s2=feature_s2)
