"""The authors' pad-and-sum propagation, kept as the naive reference for tests and benchmarks."""

from __future__ import annotations

import torch
import torch.nn.functional as F

from semattnet.models.propagation._common import kernel_size

__all__ = ["propagate_pad_and_sum"]


def propagate_pad_and_sum(affinity: torch.Tensor, h: torch.Tensor, h0: torch.Tensor, dilation: int = 1) -> torch.Tensor:
    """The authors' pattern for one step, kept as the *naive reference* for benchmarks and tests.

    Every weight channel and the current depth are zero-padded into k*k full-size shifted
    copies, stacked, multiplied, summed and cropped: 2 * k * k padded (H + 2r) x (W + 2r)
    tensors per step (rebuilt from the update rule of the spec, not their code). Same result
    as :func:`propagate`.
    """
    k = kernel_size(affinity)
    r = (k // 2) * dilation
    centre = (k * k) // 2
    height, width = affinity.shape[-2:]
    weights, depths = [], []
    for t in range(k * k):
        i, j = divmod(t, k)
        top, left = r + (i - k // 2) * dilation, r + (j - k // 2) * dilation
        pads = (left, 2 * r - left, top, 2 * r - top)
        weights.append(F.pad(affinity[:, t : t + 1], pads))
        depths.append(F.pad(h0 if t == centre else h, pads))
    total = (torch.stack(weights) * torch.stack(depths)).sum(dim=0)
    return total[:, :, r : r + height, r : r + width]
