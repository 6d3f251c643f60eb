"""Training losses (paper eqs. 5, 8, 11, 13, 14): masked L2 over pixels with ground truth.

``loss="l1+l2"`` (not the paper's: the demo's reference checkpoint, as LRRU and CompletionFormer train)
adds the masked L1 to every L2 term, so near pixels, whose errors are small in metres, still pull.
"""

from __future__ import annotations

import torch

from semattnet._errors import InputError
from semattnet.models.outputs import DepthCompletionOutput

__all__ = ["LOSSES", "masked_l1", "masked_mse", "semattnet_loss"]

#: Per-pixel losses :func:`semattnet_loss` knows: the paper's ``l2`` and the demo's ``l1+l2``.
LOSSES: tuple[str, ...] = ("l2", "l1+l2")


def masked_mse(pred: torch.Tensor, gt: torch.Tensor) -> torch.Tensor:
    """Mean of (gt - pred)^2 over pixels with gt > 0, across the whole batch (authors' form).

    Returns 0 (with a gradient path) when no pixel has ground truth.
    """
    valid = gt > 0
    diff = torch.where(valid, gt - pred, torch.zeros_like(pred))
    return (diff * diff).sum() / valid.sum().clamp_min(1)


def masked_l1(pred: torch.Tensor, gt: torch.Tensor) -> torch.Tensor:
    """Mean of |gt - pred| over pixels with gt > 0, across the whole batch (0 when there are none)."""
    valid = gt > 0
    diff = torch.where(valid, gt - pred, torch.zeros_like(pred))
    return diff.abs().sum() / valid.sum().clamp_min(1)


def semattnet_loss(
    out: DepthCompletionOutput, gt: torch.Tensor, branch_weight: float = 0.0, loss: str = "l2"
) -> torch.Tensor:
    """Eq. 14 as the authors train it (``loss="l2"``; ``"l1+l2"``: L1 + L2 for every term L).

    Backbone (no refined depth): ``(1 - n w) L(D_f) + w sum_b L(D_b)`` over the n branches.
    Full model: ``L(refined)`` plus ``w sum_b L(D_b)`` when ``branch_weight`` is set.
    """
    if loss not in LOSSES:
        raise InputError(f"loss must be one of {LOSSES}, got {loss!r}")

    def term(pred: torch.Tensor) -> torch.Tensor:
        return masked_mse(pred, gt) + (masked_l1(pred, gt) if loss == "l1+l2" else 0.0)

    branches = [d for d in (out.color_depth, out.semantic_depth, out.guided_depth) if d is not None]
    branch_loss = sum((term(d) for d in branches), torch.zeros((), device=gt.device))
    if out.refined_depth is None:
        return (1.0 - len(branches) * branch_weight) * term(out.fused_depth) + branch_weight * branch_loss
    return term(out.refined_depth) + branch_weight * branch_loss
