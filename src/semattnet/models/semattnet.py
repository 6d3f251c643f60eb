"""SemAttNet: the three-branch backbone followed by CSPN++ with atrous propagation (Fig. 2)."""

from __future__ import annotations

import dataclasses

import torch
from torch import nn

from semattnet._errors import InputError
from semattnet.models.backbone import SemAttNetBackbone
from semattnet.models.checks import require_sparse
from semattnet.models.config import SemAttNetConfig
from semattnet.models.outputs import DepthCompletionOutput
from semattnet.models.refinement import AtrousCSPNRefinement, RefinementHeads

__all__ = ["SemAttNet"]


class SemAttNet(AtrousCSPNRefinement, nn.Module):
    """The full model (the authors' ``A_CSPN_plus_plus``): ``backbone.*`` plus the CSPN++ heads.

    Args:
        config: architecture options (``config.refine`` must be True; build a backbone-only
            model with :class:`~semattnet.models.backbone.SemAttNetBackbone`).

    Shape:
        rgb (B, 3, H, W) 0..255, semantic (B, 3, H, W) 0..255, sparse (B, 1, H, W) metres ->
        :class:`~semattnet.models.outputs.DepthCompletionOutput` with every map (B, 1, H, W).
    """

    def __init__(self, config: SemAttNetConfig | None = None) -> None:
        nn.Module.__init__(self)
        self.config = config = config if config is not None else SemAttNetConfig()
        if not config.refine:
            raise InputError("SemAttNet is the refined model; use SemAttNetBackbone for refine=False")
        self.backbone = SemAttNetBackbone(config)
        self._build_refinement(self.backbone.feature_channels, config)

    def forward(
        self, rgb: torch.Tensor, semantic: torch.Tensor | None = None, sparse: torch.Tensor | None = None
    ) -> DepthCompletionOutput:
        """Complete and refine depth. Inputs: RGB 0..255, semantic colours 0..255, sparse metres."""
        out, heads = self.forward_network(rgb, semantic, sparse)
        refined_s2, refined = self.propagation(heads)
        return dataclasses.replace(out, refined_s2_depth=refined_s2, refined_depth=refined)

    def forward_network(
        self, rgb: torch.Tensor, semantic: torch.Tensor | None = None, sparse: torch.Tensor | None = None
    ) -> tuple[DepthCompletionOutput, RefinementHeads]:
        """Everything but the propagation: the backbone's output and the refinement heads.

        ``forward`` is ``forward_network`` followed by :meth:`propagation`; inference engines
        run this part in another runtime and the propagation in PyTorch's fused kernel.
        """
        sparse = require_sparse(sparse)
        out, feature_s1, feature_s2 = self.backbone.forward_features(rgb, semantic, sparse)
        # the refinement re-injects the measurements: the first channel of a generalist's two-channel input
        return out, self.refinement_heads(out.fused_depth, sparse[:, :1], feature_s1, feature_s2)
