"""Semantic-guided (SG) branch, paper Sec. III-B-2, eqs. 6-8.

Input ``X_sg = [S; D; D_cg]`` (the colour-coded semantic map 0..255, the sparse depth and the
colour depth, in the authors' channel order). At every encoder scale the SG features are
concatenated with the CG decoder features and fused by SAMMAFB (or the ablation's concat/add)
before the next stage. The decoder's skips are the SG encoder's own block outputs (taken before
fusion); its first input is the sum of the CG and SG deepest features. It gives the semantic
depth D_sg and its confidence C_sg. The decoder features *before* their skip add guide DG.

Key names: ``segment_conv_init``, ``segment_encoder_layer{1..10}``,
``segment_decoder_layer{1..6}`` and the fusion blocks ``cbam_128/256/512/1024`` (SAMMAFB at
scales 2, 4, 8, 16; the number is the fused width of the paper model, kept at any width).
"""

from __future__ import annotations

from typing import NamedTuple

import torch
from torch import nn

from semattnet.models.branches.color_guided import ColorGuidedFeatures
from semattnet.models.config import SemAttNetConfig, Widths
from semattnet.models.encoders.resnet import add_resnet_layers, run_resnet_layers
from semattnet.models.fusion import FusionMode, fuse_features, make_fusion_block
from semattnet.models.layers import deconvbnrelu

__all__ = ["SG_FUSION_BLOCKS", "SemanticGuidedBranch", "SemanticGuidedFeatures"]

#: Fusion block (SAMMAFB) attribute name per scale, as in the authors' keys.
SG_FUSION_BLOCKS = {2: "cbam_128", 4: "cbam_256", 8: "cbam_512", 16: "cbam_1024"}
_STAGES = (2, 4, 8, 16, 32)


class SemanticGuidedFeatures(NamedTuple):
    depth: torch.Tensor  # D_sg
    conf: torch.Tensor  # C_sg before the cross-branch softmax
    decoder: dict[int, torch.Tensor]  # decoder outputs before their skip add, by scale 2..16
    encoder_out: torch.Tensor  # deepest SG encoder features (scale 32)
    feature_s1: torch.Tensor  # full-resolution decoder features (refinement guidance)


class SemanticGuidedBranch:
    """Mixin: builds and runs the semantic-guided branch on an ``nn.Module``."""

    segment_conv_init: nn.Sequential
    _sg_fusion: FusionMode

    def _build_semantic_fusion(self, w: Widths, cfg: SemAttNetConfig) -> None:
        self._sg_fusion = cfg.fusion
        for s, name in SG_FUSION_BLOCKS.items():
            setattr(self, name, make_fusion_block(cfg.fusion, w.fused_sg[s], cfg.reduction))

    def _build_semantic_guided(self, w: Widths, depth_channels: int = 1) -> None:
        c = w.base
        extra = [w.fused_sg.get(s, w.sg[s]) - w.sg[s] for s in _STAGES]
        stages = [c[1], *(w.sg[s] for s in _STAGES)]
        add_resnet_layers(self, "segment_conv_init", "segment_encoder_layer", 4 + depth_channels, stages, extra)
        for j, s in enumerate((16, 8, 4, 2, 1)):
            setattr(self, f"segment_decoder_layer{j + 1}", deconvbnrelu(2 * c[s], c[s]))
        self.segment_decoder_layer6 = nn.Sequential(
            nn.ConvTranspose2d(c[1], 2, 3, stride=1, padding=1, bias=False), nn.BatchNorm2d(2), nn.ReLU(inplace=True)
        )

    def _semantic_guided(
        self, semantic: torch.Tensor, sparse: torch.Tensor, cg: ColorGuidedFeatures
    ) -> SemanticGuidedFeatures:

        def fuse(i: int, x: torch.Tensor) -> torch.Tensor:  # SAMMAFB after the stages at scales 2 .. 16
            s = _STAGES[i]
            return fuse_features(self._sg_fusion, getattr(self, SG_FUSION_BLOCKS[s]), (cg.decoder[s], x))

        x = torch.cat((semantic, sparse, cg.depth), dim=1)
        _, features = run_resnet_layers(self, "segment_conv_init", "segment_encoder_layer", len(_STAGES), x, fuse)
        skips = dict(zip(_STAGES, features, strict=True))
        decoder: dict[int, torch.Tensor] = {}
        x = cg.encoder_out + skips[32]
        for j, s in enumerate((16, 8, 4, 2, 1)):
            x = getattr(self, f"segment_decoder_layer{j + 1}")(x)
            decoder[s] = x
            if s > 1:
                x = x + skips[s]
        out = self.segment_decoder_layer6(x)
        return SemanticGuidedFeatures(
            depth=out[:, 0:1],
            conf=out[:, 1:2],
            decoder={s: decoder[s] for s in (2, 4, 8, 16)},
            encoder_out=skips[32],
            feature_s1=decoder[1],
        )
