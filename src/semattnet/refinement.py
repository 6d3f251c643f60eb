"""CSPN++ refinement with atrous convolutions (paper Sec. III-C and "Effectiveness of CSPN++").

The fused backbone depth is refined by 12 propagation steps per kernel size (3, 5, 7): six
with dilation 2 at half-resolution guidance, then six with dilation 1 at full resolution. After
every step the LiDAR measurements are re-injected through a learned mask,
``h = m * d + (1 - m) * h``; each stage blends its per-kernel results with learned per-pixel
kernel confidences (CSPN++'s adaptive kernel size).

The dilation-2 stage runs on the four 2x2 polyphase sub-grids of the depth at once (they are
independent; the half-resolution heads, sparse depth and mask are shared by all four), which is
a full-resolution dilation-2 CSPN with nearest-upsampled heads.

Two readings of the stage hand-over (``SemAttNetConfig.refinement_mode``):

* ``"authors"`` (default; the released weights need it). The authors' code writes the stage-1
  sub-grids back *into the backbone output tensor*. Hence stage 2 starts from the stage-1
  result D' and also uses D' as its fixed input h_0; the learned blend
  ``att_12[0] * D' + att_12[1] * D`` degenerates to D', so ``att_12`` and ``dimhalf_s2`` have no
  effect and receive no gradient. We compute exactly that, without the in-place writes.
* ``"clean"``: the paper's reading. h_0 is the backbone output in both stages; stage 2 starts
  from ``a_0 * D' + a_1 * D`` with ``a = softmax(att_12([F_s1; up(dimhalf_s2(F_s2))]))``.

Parameter names are the authors' (``kernel_conf_layer``, ``mask_layer``,
``iter_guide_layer{3,5,7}`` and their ``_s2`` twins, ``dimhalf_s2``, ``att_12``).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
import torch.nn.functional as F
from torch import nn

from .config import RefinementMode
from .layers import convbn, convbnrelu
from .propagation import AffinityHead, downsample_sparse, propagate_shifted, shift_affinity

__all__ = ["AtrousCSPNRefinement", "run_cspn_stage"]


def run_cspn_stage(
    start: torch.Tensor,
    h0: torch.Tensor,
    affinities: Sequence[torch.Tensor],
    kernel_conf: torch.Tensor,
    sparse: torch.Tensor,
    mask: torch.Tensor,
    iterations: int,
) -> torch.Tensor:
    """Propagate once per kernel size with re-injection, then blend by kernel confidence.

    Args:
        start: (B, C, H, W) initial estimate; h0: (B, C, H, W) fixed input.
        affinities: per kernel size, (B, k*k, H, W) normalised kernels.
        kernel_conf: (B, len(affinities), H, W) softmax weights of the kernel sizes.
        sparse, mask: (B, 1, H, W) depth to re-inject and its learned mask in [0, 1].
        iterations: steps per kernel size.
    """
    keep = 1.0 - mask
    blended: torch.Tensor | None = None
    for i, affinity in enumerate(affinities):
        shifted = shift_affinity(affinity)
        h = start
        for _ in range(iterations):
            h = propagate_shifted(shifted, h, h0)
            h = mask * sparse + keep * h
        term = kernel_conf[:, i : i + 1] * h
        blended = term if blended is None else blended + term
    assert blended is not None
    return blended


class AtrousCSPNRefinement:
    """Mixin: the CSPN++ heads and the two-stage atrous propagation on an ``nn.Module``."""

    kernel_conf_layer: nn.Sequential
    mask_layer: nn.Sequential
    kernel_conf_layer_s2: nn.Sequential
    mask_layer_s2: nn.Sequential
    dimhalf_s2: nn.Sequential
    att_12: nn.Sequential

    def _build_refinement(
        self, channels_s1: int, channels_s2: int, kernel_sizes: Sequence[int], iterations: int, mode: RefinementMode
    ) -> None:
        self._kernel_sizes = tuple(kernel_sizes)
        self._iterations = iterations
        self._refinement_mode = mode
        n = len(self._kernel_sizes)
        for suffix, ch in (("", channels_s1), ("_s2", channels_s2)):
            setattr(self, f"kernel_conf_layer{suffix}", convbn(ch, n))
            setattr(self, f"mask_layer{suffix}", convbn(ch, 1))
            for k in self._kernel_sizes:
                setattr(self, f"iter_guide_layer{k}{suffix}", AffinityHead(ch, k))
        self.dimhalf_s2 = convbnrelu(channels_s2, channels_s1, kernel_size=1, padding=0)
        self.att_12 = convbnrelu(2 * channels_s1, 2, kernel_size=3, padding=1)

    def _heads(self, feature: torch.Tensor, suffix: str) -> tuple[list[torch.Tensor], torch.Tensor, torch.Tensor]:
        affinities = [getattr(self, f"iter_guide_layer{k}{suffix}")(feature) for k in self._kernel_sizes]
        kernel_conf = torch.softmax(getattr(self, f"kernel_conf_layer{suffix}")(feature), dim=1)
        mask = torch.sigmoid(getattr(self, f"mask_layer{suffix}")(feature))
        return affinities, kernel_conf, mask

    def _refine(
        self, depth: torch.Tensor, sparse: torch.Tensor, feature_s1: torch.Tensor, feature_s2: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Refine ``depth`` (B, 1, H, W); returns (after the dilation-2 stage, final)."""
        with torch.autocast(device_type=depth.device.type, enabled=False):
            depth, sparse = depth.float(), sparse.float()
            feature_s1, feature_s2 = feature_s1.float(), feature_s2.float()

            # Stage 1: dilation 2, i.e. dilation 1 on each 2x2 polyphase sub-grid.
            sparse_s2, valid_s2 = downsample_sparse(sparse, 2)
            affinities, kernel_conf, mask = self._heads(feature_s2, "_s2")
            grids = F.pixel_unshuffle(depth, 2)  # (B, 4, H/2, W/2): D[a::2, b::2] at channel 2a + b
            refined_grids = run_cspn_stage(
                grids, grids, affinities, kernel_conf, sparse_s2, mask * valid_s2, self._iterations
            )
            refined_s2 = F.pixel_shuffle(refined_grids, 2)

            # Stage 2: dilation 1 at full resolution.
            if self._refinement_mode == "authors":
                start = h0 = refined_s2
            else:
                half = F.interpolate(self.dimhalf_s2(feature_s2), scale_factor=2.0, mode="nearest")
                att = torch.softmax(self.att_12(torch.cat((feature_s1, half), dim=1)), dim=1)
                start, h0 = att[:, 0:1] * refined_s2 + att[:, 1:2] * depth, depth
            affinities, kernel_conf, mask = self._heads(feature_s1, "")
            valid = (sparse > 0).to(sparse.dtype)
            refined = run_cspn_stage(start, h0, affinities, kernel_conf, sparse, mask * valid, self._iterations)
        return refined_s2, refined
