"""The three-branch backbone of SemAttNet (paper Sec. III-B, Fig. 2).

The colour-guided branch runs first; its depth and decoder features guide the semantic-guided
branch; both guide the depth-guided branch; the three depths are fused with learned
confidences (eq. 12). This module composes the branches of :mod:`semattnet.models.branches`.

Parameter names are the authors' (``three_branch_bb`` in their code), so their backbone
checkpoints load with ``strict=True``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import NamedTuple, Protocol, TypeVar

import torch
from torch import nn

from semattnet.models.branches import ColorGuidedBranch, DepthGuidedBranch, SemanticGuidedBranch
from semattnet.models.checks import check_inputs, require_sparse
from semattnet.models.confidence_fusion import confidence_fusion
from semattnet.models.config import SemAttNetConfig
from semattnet.models.outputs import DepthCompletionOutput

__all__ = ["BackboneFeatures", "SemAttNetBackbone", "init_depth_channel"]

F = TypeVar("F")


class BranchRunner(Protocol):
    """What :attr:`SemAttNetBackbone.branch_runner` holds: calls ``branch(*inputs)`` its own way."""

    def __call__(self, branch: Callable[..., F], *inputs: object) -> F: ...


def init_depth_channel(heads: Iterable[nn.Sequential], scale: float, shift: float) -> None:
    """Set the depth channel (0) of each branch head's BatchNorm (the heads end in BatchNorm, ReLU) to ``scale``
    and ``shift`` (:meth:`SemAttNetBackbone.init_depth_heads`)."""
    with torch.no_grad():
        for head in heads:
            bn = head[1]
            assert isinstance(bn, nn.BatchNorm2d)
            bn.weight[0], bn.bias[0] = scale, shift


class BackboneFeatures(NamedTuple):
    """Backbone result plus the decoder features the refinement is guided by."""

    output: DepthCompletionOutput
    feature_s1: torch.Tensor  # cat of the branches' full-resolution decoder features
    feature_s2: torch.Tensor  # cat of the branches' half-resolution decoder features


class SemAttNetBackbone(ColorGuidedBranch, SemanticGuidedBranch, DepthGuidedBranch, nn.Module):
    """Three-branch (or, for the ablation, two-branch) backbone with confidence fusion.

    Args:
        config: architecture options; ``config.refine`` is ignored here.

    Shape:
        rgb (B, 3, H, W), semantic (B, 3, H, W), sparse (B, 1, H, W) -> every map (B, 1, H, W);
        H and W multiples of 32.

    Example:
        >>> import torch, semattnet
        >>> net = semattnet.build_model("semattnet_backbone", width=0.125).eval()
        >>> out = net(rgb=torch.zeros(1, 3, 64, 64), semantic=torch.zeros(1, 3, 64, 64),
        ...           sparse=torch.zeros(1, 1, 64, 64))
        >>> out.fused_depth.shape
        torch.Size([1, 1, 64, 64])
    """

    #: Runs each branch (encoder + decoder) as ``branch_runner(branch, *inputs)``; None calls the
    #: branch directly. The hook for wrapping whole branches, e.g. activation checkpointing
    #: (:func:`semattnet.training.checkpointing.set_activation_checkpointing`).
    branch_runner: BranchRunner | None = None

    def __init__(self, config: SemAttNetConfig | None = None) -> None:
        nn.Module.__init__(self)
        self.config = config = config if config is not None else SemAttNetConfig(refine=False)
        w = config.widths
        # Registration order reproduces the authors' state-dict order: fusion blocks first.
        if config.branches == 3:
            self._build_semantic_fusion(w, config)
        self._build_depth_fusion(w, config)
        self._build_color_guided(w, config.depth_channels)
        if config.branches == 3:
            self._build_semantic_guided(w, config.depth_channels)
        self._build_depth_guided(w, config)

    def init_depth_heads(self, scale: float = 10.0, shift: float = 15.0) -> None:
        """Start each branch's depth output at ``ReLU(scale * z + shift)`` metres (z ~ N(0, 1)).

        The heads end in BatchNorm + ReLU, so with PyTorch's default init (scale 1, shift 0)
        every depth starts near 0.5 m, and Adam moves the BN affine parameters by about lr per
        step: tens of thousands of steps before outputs reach street depths. The authors did
        that; for short or small runs a KITTI-scale start trains orders of magnitude faster.
        Only the depth channel is changed, not the confidence channel.
        """
        heads = [self.rgb_decoder_output, self.decoder_layer6]
        if self.config.branches == 3:
            heads.append(self.segment_decoder_layer6)
        init_depth_channel(heads, scale, shift)

    @property
    def feature_channels(self) -> tuple[int, int]:
        """Channels of (feature_s1, feature_s2), the refinement's guidance features."""
        w = self.config.widths
        return self.config.branches * w.base[1], (self.config.branches - 1) * w.base[2] + w.dg[2]

    def run_branch(self, branch: Callable[..., F], *inputs: object) -> F:
        """``branch(*inputs)``, through :attr:`branch_runner` when one is set."""
        return branch(*inputs) if self.branch_runner is None else self.branch_runner(branch, *inputs)

    def forward_features(
        self, rgb: torch.Tensor, semantic: torch.Tensor | None, sparse: torch.Tensor
    ) -> BackboneFeatures:
        three = self.config.branches == 3
        check_inputs(rgb, semantic, sparse, need_semantic=three, sparse_channels=self.config.depth_channels)
        cg = self.run_branch(self._color_guided, rgb, sparse)
        sg = self.run_branch(self._semantic_guided, semantic, sparse, cg) if three else None
        dg = self.run_branch(self._depth_guided, sparse, cg, sg)
        guides = (cg,) if sg is None else (cg, sg)  # the branches that guide DG
        depths = [*(b.depth for b in guides), dg.depth]
        fused, weights = confidence_fusion(depths, [*(b.conf for b in guides), dg.conf])
        s1 = torch.cat([*(b.feature_s1 for b in guides), dg.feature_s1], dim=1)
        s2 = torch.cat([*(b.decoder[2] for b in guides), dg.feature_s2], dim=1)
        return BackboneFeatures(DepthCompletionOutput.from_branches(depths, weights, fused), s1, s2)

    def forward(
        self, rgb: torch.Tensor, semantic: torch.Tensor | None = None, sparse: torch.Tensor | None = None
    ) -> DepthCompletionOutput:
        """Complete depth. Inputs: RGB 0..255, colour-coded semantic map 0..255, sparse metres."""
        return self.forward_features(rgb, semantic, require_sparse(sparse)).output
