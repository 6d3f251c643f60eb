"""An in-process stand-in for the authors' propagation, for speed comparisons only.

The authors' CSPN step (from PENet) pads every weight channel and the current depth into k*k
full-size shifted copies, multiplies and sums them, then crops: 2 * k * k padded
(H + 2r) x (W + 2r) tensors per step. This module rebuilds that pattern from the update rule in
ARCHITECTURE.md (it is not their code) so benchmarks can report ratios in one process.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F


def pad_and_sum_propagate(affinity: torch.Tensor, h: torch.Tensor, h0: torch.Tensor, dilation: int = 1) -> torch.Tensor:
    _b, kk, height, width = affinity.shape
    k = round(kk**0.5)
    r = (k // 2) * dilation
    centre = kk // 2
    total = None
    for t in range(kk):
        i, j = divmod(t, k)
        # Place tap t of every pixel q at q + o_t inside a padded canvas (zero padding around).
        top, left = r + (i - k // 2) * dilation, r + (j - k // 2) * dilation
        pads = (left, 2 * r - left, top, 2 * r - top)
        w_pad = F.pad(affinity[:, t : t + 1], pads)
        h_pad = F.pad(h0 if t == centre else h, pads)
        term = w_pad * h_pad
        total = term if total is None else total + term
    assert total is not None
    return total[:, :, r : r + height, r : r + width]
