"""SemAttNet-RT: the paper's structure built for a CPU frame budget.

The same three branches (colour-, semantic- and depth-guided, paper Sec. III-B), the same SAMMAFB
fusion between them (Sec. III-A), the same confidence fusion (eq. 12) and the same CSPN++ refinement
with atrous propagation (Sec. III-C), but:

* each branch's encoder is a registered light encoder (:mod:`semattnet.models.encoders`) whose stem
  brings the input to 1/2 or 1/4 resolution at once, so no branch runs at full resolution (the
  width-1/8 paper model spends most of its time on few-channel full-resolution convolutions,
  bound by memory traffic);
* the decoders have one stage per encoder stage (a 1x1 projection, a nearest 2x upsampling, the
  skip added, one residual separable block) and stop at the stem's resolution;
* the CSPN++ refinement (the paper's heads, both stages) runs at the stem's resolution; its depth is
  brought to full resolution by a learned convex upsampling (:func:`convex_upsample`: each full-resolution
  pixel a softmax-weighted mean of its 3x3 low-resolution neighbours, weights predicted from the refinement's
  features, as RAFT upsamples flow), which keeps depth edges sharp where a bilinear upsampling smears them
  over a stem-sized band; a learned upsampling (a 1x1 convolution and a pixel shuffle, as in sub-pixel
  convolution) gives a 3x3 affinity and a re-injection mask at full resolution, for :data:`FINAL_ITERATIONS`
  last propagation steps.

Every map of :class:`~semattnet.models.outputs.DepthCompletionOutput` is returned at full resolution
(the branch depths and fusion weights bilinearly upsampled); ``refined_s2_depth`` is the
reduced-resolution refinement, upsampled, before the last full-resolution steps.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Sequence
from typing import NamedTuple

import torch
import torch.nn.functional as F
from torch import nn

from semattnet._errors import InputError
from semattnet.models.backbone import init_depth_channel
from semattnet.models.checks import check_inputs, require_sparse
from semattnet.models.confidence_fusion import confidence_fusion
from semattnet.models.config import SemAttNetConfig
from semattnet.models.encoders import FeatureInfo, create_encoder, encoder_spec
from semattnet.models.encoders.lite import LiteBlock
from semattnet.models.fusion import fuse_features, make_fusion_block
from semattnet.models.layers import convbn, convbnrelu
from semattnet.models.outputs import DepthCompletionOutput
from semattnet.models.propagation import downsample_sparse
from semattnet.models.refinement import AtrousCSPNRefinement, affinity_kernel, run_cspn_stage

__all__ = [
    "FINAL_ITERATIONS",
    "RTBranch",
    "RTFeatures",
    "SemAttNetRT",
    "SemAttNetRTBackbone",
    "convex_upsample",
    "rt_channels",
]

#: Propagation steps at full resolution after the learned upsampling (3x3 kernel).
FINAL_ITERATIONS = 2


def rt_channels(cfg: SemAttNetConfig) -> tuple[int, ...]:
    """The encoder's registered widths (stem first) times ``cfg.width``, at least 4 channels each."""
    return tuple(max(4, round(c * cfg.width)) for c in encoder_spec(cfg.encoder).channels)


class RTFeatures(NamedTuple):
    """One branch's result, at the stem's resolution and below."""

    depth: torch.Tensor  # (B, 1, H/s, W/s)
    conf: torch.Tensor  # before the cross-branch softmax
    decoder: list[torch.Tensor]  # decoder features, stem's stride first (after the skip add)
    deepest: torch.Tensor  # the last encoder stage's output


class RTBranch(nn.Module):
    """A branch: registered encoder, a light decoder back to the stem's stride, a (depth, confidence) head.

    Args:
        encoder: registered encoder name; in_chans: input channels; channels: stem width, then per stage;
        guide_channels: per stage but the last, the channels of the guidance fused in (0: none).
        fusion, reduction: the feature fusion (:func:`~semattnet.models.fusion.make_fusion_block`).
    """

    def __init__(
        self,
        encoder: str,
        in_chans: int,
        channels: Sequence[int],
        guide_channels: Sequence[int],
        fusion: str,
        reduction: int,
    ) -> None:
        super().__init__()
        concat = fusion != "add"
        extra = [g if concat else 0 for g in guide_channels] + [0]
        self.encoder = create_encoder(encoder, in_chans, channels, extra)
        assert isinstance(self.encoder, nn.Module)  # registered encoders are modules
        self.fusion_mode = fusion
        self.fusion = nn.ModuleList(
            make_fusion_block(fusion, c + e, reduction) if g else nn.Identity()  # type: ignore[arg-type]
            for c, e, g in zip(channels[1:], extra, guide_channels, strict=False)
        )
        self.up = nn.ModuleList(
            nn.Sequential(
                convbnrelu(channels[j + 1], channels[j], kernel_size=1, padding=0), nn.Upsample(scale_factor=2)
            )
            for j in range(len(channels) - 1)
        )
        self.decode = nn.ModuleList(LiteBlock(c) for c in channels[:-1])
        self.head = nn.Sequential(*convbn(channels[0], 2), nn.ReLU(inplace=True))

    @property
    def feature_info(self) -> FeatureInfo:
        return self.encoder.feature_info

    def forward(
        self, x: torch.Tensor, guides: Sequence[Sequence[torch.Tensor]] = (), deep: torch.Tensor | None = None
    ) -> RTFeatures:
        """``guides[i]``: tensors fused (SAMMAFB, in the paper's [CG, SG, DG] order) with stage i's output;
        ``deep``: the earlier branches' deepest features, added to this branch's before decoding."""

        def hook(i: int, feat: torch.Tensor) -> torch.Tensor:
            if i >= len(guides) or not guides[i]:
                return feat
            return fuse_features(self.fusion_mode, self.fusion[i], (*guides[i], feat))  # type: ignore[arg-type]

        stem, feats = self.encoder(x, hook)
        skips = [stem, *feats[:-1]]
        y = feats[-1] if deep is None else feats[-1] + deep
        decoder: list[torch.Tensor] = []
        for j in reversed(range(len(skips))):
            y = self.decode[j](self.up[j](y) + skips[j])
            decoder.insert(0, y)
        out = self.head(y)
        return RTFeatures(out[:, 0:1], out[:, 1:2], decoder, feats[-1])


class RTBackboneFeatures(NamedTuple):
    """The backbone's full-resolution output and what the refinement reads at the stem's resolution."""

    output: DepthCompletionOutput
    depth: torch.Tensor  # fused depth at the stem's resolution (B, 1, H/s, W/s)
    feature_s1: torch.Tensor  # the branches' decoder features at the stem's stride
    feature_s2: torch.Tensor  # ... at twice the stem's stride


def _up(x: torch.Tensor, size: Sequence[int]) -> torch.Tensor:
    return F.interpolate(x, size=tuple(size), mode="bilinear", align_corners=False)


def convex_upsample(x: torch.Tensor, logits: torch.Tensor, scale: int) -> torch.Tensor:
    """``x`` (B, C, h, w) to (B, C, h*scale, w*scale): each output pixel the convex combination of the 3x3
    neighbourhood of its low-resolution pixel (edge-replicated at the border), with weights
    ``softmax(logits)`` over the 9 neighbours; ``logits`` (B, 9*scale*scale, h, w), neighbour-major.
    Zero logits give every sub-pixel the 3x3 mean. Written with slices and 4-D tensors only, ending in a pixel
    shuffle (no unfold, no 7-D permute), so that every exporter takes it and OpenVINO keeps its blocked layouts."""
    b, c, h, w = x.shape
    if c != 1:  # one channel at a time: the same weights for each
        return torch.cat([convex_upsample(x[:, i : i + 1], logits, scale) for i in range(c)], dim=1)
    padded = F.pad(x, (1, 1, 1, 1), mode="replicate")
    patches = torch.cat([padded[:, :, i : i + h, j : j + w] for i in range(3) for j in range(3)], dim=1)
    weights = logits.view(b, 9, scale * scale, h * w).softmax(dim=1)
    up = (weights * patches.view(b, 9, 1, h * w)).sum(dim=1)  # (B, s*s, h*w): sub-pixel (i, j) at i*s + j
    return F.pixel_shuffle(up.view(b, scale * scale, h, w), scale)


class SemAttNetRTBackbone(nn.Module):
    """The three (or two) branches on a registered light encoder, with SAMMAFB and eq. 12 fusion.

    Args:
        config: a config whose ``encoder`` is not ``"resnet"`` (:attr:`SemAttNetConfig.realtime`).

    Shape:
        rgb (B, 3, H, W) 0..255, semantic (B, 3, H, W) 0..255, sparse (B, 1, H, W) metres -> every map
        (B, 1, H, W); H and W multiples of 32.
    """

    def __init__(self, config: SemAttNetConfig) -> None:
        super().__init__()
        if not config.realtime:
            raise InputError(f"SemAttNetRTBackbone needs a light encoder, got encoder={config.encoder!r}")
        self.config = config
        c = rt_channels(config)
        n = len(c) - 2  # stages fused with guidance: all but the last
        three = config.branches == 3
        args = (config.fusion, config.reduction)
        dc = config.depth_channels  # 2 for the generalist: sparse and anchor
        self.rgb_branch = RTBranch(config.encoder, 3 + dc, c, [0] * n, *args)
        self.semantic_branch = RTBranch(config.encoder, 4 + dc, c, c[1:-1], *args) if three else None
        guide = [(config.branches - 1) * ch for ch in c[1:-1]]
        self.depth_branch = RTBranch(config.encoder, config.branches - 1 + dc, c, guide, *args)
        self.stem_stride = self.rgb_branch.feature_info.stem_stride

    @property
    def feature_channels(self) -> tuple[int, int]:
        """Channels of (feature_s1, feature_s2), the refinement's guidance features."""
        c = rt_channels(self.config)
        return self.config.branches * c[0], self.config.branches * c[1]

    def init_depth_heads(self, scale: float = 10.0, shift: float = 15.0) -> None:
        """As :meth:`SemAttNetBackbone.init_depth_heads`: each branch's depth starts at street scale."""
        branches = (self.rgb_branch, self.semantic_branch, self.depth_branch)
        init_depth_channel([b.head for b in branches if b is not None], scale, shift)

    def forward_features(
        self, rgb: torch.Tensor, semantic: torch.Tensor | None, sparse: torch.Tensor
    ) -> RTBackboneFeatures:
        check_inputs(
            rgb,
            semantic,
            sparse,
            need_semantic=self.semantic_branch is not None,
            sparse_channels=self.config.depth_channels,
        )
        size = sparse.shape[-2:]
        cg = self.rgb_branch(torch.cat((rgb, sparse), dim=1))
        guides: list[list[torch.Tensor]] = [[d] for d in cg.decoder[1:]]
        sg = None
        if self.semantic_branch is not None:
            assert semantic is not None  # check_inputs
            sg = self.semantic_branch(torch.cat((semantic, sparse, _up(cg.depth, size)), dim=1), guides, cg.deepest)
            guides = [[a, b] for a, b in zip(cg.decoder[1:], sg.decoder[1:], strict=True)]
        depths = [sparse, _up(cg.depth, size)] + ([] if sg is None else [_up(sg.depth, size)])
        deep = cg.deepest if sg is None else cg.deepest + sg.deepest
        dg = self.depth_branch(torch.cat(depths, dim=1), guides, deep)
        branches = [b for b in (cg, sg, dg) if b is not None]
        fused, weights = confidence_fusion([b.depth for b in branches], [b.conf for b in branches])
        output = DepthCompletionOutput.from_branches(
            [*depths[1:], _up(dg.depth, size)], [_up(t, size) for t in weights], _up(fused, size)
        )
        s1 = torch.cat([b.decoder[0] for b in branches], dim=1)
        s2 = torch.cat([b.decoder[1] for b in branches], dim=1)
        return RTBackboneFeatures(output, fused, s1, s2)

    def forward(
        self, rgb: torch.Tensor, semantic: torch.Tensor | None = None, sparse: torch.Tensor | None = None
    ) -> DepthCompletionOutput:
        """Complete depth. Inputs: RGB 0..255, colour-coded semantic map 0..255, sparse metres."""
        return self.forward_features(rgb, semantic, require_sparse(sparse)).output


class SemAttNetRT(AtrousCSPNRefinement, nn.Module):
    """The real-time model: :class:`SemAttNetRTBackbone`, CSPN++ at the stem's resolution, a learned
    upsampling and :data:`FINAL_ITERATIONS` full-resolution propagation steps (module docstring).

    Parameters are ``backbone.*`` plus the CSPN++ heads (the paper's names) and ``upsample``, so
    the training stages of the paper (backbone, then the full model) apply unchanged.
    """

    def __init__(self, config: SemAttNetConfig) -> None:
        nn.Module.__init__(self)
        if not config.refine:
            raise InputError("SemAttNetRT is the refined model; use SemAttNetRTBackbone for refine=False")
        self.config = config
        self.backbone = SemAttNetRTBackbone(config)
        self._build_refinement(self.backbone.feature_channels, config)
        c1, s = self.backbone.feature_channels[0], self.backbone.stem_stride
        self.upsample = nn.Sequential(nn.Conv2d(c1, 9 * s * s, 1), nn.PixelShuffle(s))  # 8 guidance + 1 mask
        self.convex = nn.Conv2d(c1, 9 * s * s, 1)  # the convex upsampling's weights (logits)
        with torch.no_grad():  # zero logits: every sub-pixel starts as the 3x3 mean
            for p in self.convex.parameters():
                p.zero_()

    def _upsampled_heads(self, feature: torch.Tensor, sizes: tuple[int, ...]) -> list[torch.Tensor]:
        """``upsample``'s 1x1 convolution as one convolution per group of ``sizes`` output channels (its weights
        sliced: the same numbers), so that no runtime splits its output (a copy in a slow layout in OpenVINO)."""
        conv = self.upsample[0]
        assert isinstance(conv, nn.Conv2d) and conv.bias is not None
        ends = list(itertools.accumulate(sizes))
        return [F.conv2d(feature, conv.weight[a:b], conv.bias[a:b]) for a, b in zip([0, *ends[:-1]], ends, strict=True)]

    def forward(
        self, rgb: torch.Tensor, semantic: torch.Tensor | None = None, sparse: torch.Tensor | None = None
    ) -> DepthCompletionOutput:
        """Complete and refine depth. Inputs: RGB 0..255, semantic colours 0..255, sparse metres."""
        depth_in = require_sparse(sparse)
        out, depth, feature_s1, feature_s2 = self.backbone.forward_features(rgb, semantic, depth_in)
        sparse = depth_in[:, :1]  # the measurements: a generalist's second channel is its anchor
        sparse_lr, _ = downsample_sparse(sparse, self.backbone.stem_stride)
        _, refined_lr = self.propagation(self.refinement_heads(depth, sparse_lr, feature_s1, feature_s2))
        s = self.backbone.stem_stride
        guide, mask = (F.pixel_shuffle(t, s) for t in self._upsampled_heads(feature_s1, (8 * s * s, s * s)))
        start = convex_upsample(refined_lr, self.convex(feature_s1), s)
        valid = (sparse > 0).to(sparse.dtype)
        affinity = affinity_kernel(guide.float(), self.propagation_impl, form=self.config.affinity)
        refined = run_cspn_stage(
            start,
            start,
            [affinity],
            torch.ones_like(start),
            sparse,
            torch.sigmoid(mask) * valid,
            FINAL_ITERATIONS,
            self.propagation_impl,
        )
        return dataclasses.replace(out, refined_s2_depth=start, refined_depth=refined)
