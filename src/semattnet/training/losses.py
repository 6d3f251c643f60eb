"""Training losses (paper eqs. 5, 8, 11, 13, 14): masked L2 over pixels with ground truth."""

from __future__ import annotations

import torch

from semattnet.models.outputs import DepthCompletionOutput

__all__ = ["masked_mse", "semattnet_loss"]


def masked_mse(pred: torch.Tensor, gt: torch.Tensor) -> torch.Tensor:
    """Mean of (gt - pred)^2 over pixels with gt > 0, across the whole batch (authors' form).

    Returns 0 (with a gradient path) when no pixel has ground truth.
    """
    valid = gt > 0
    diff = torch.where(valid, gt - pred, torch.zeros_like(pred))
    return (diff * diff).sum() / valid.sum().clamp_min(1)


def semattnet_loss(out: DepthCompletionOutput, gt: torch.Tensor, branch_weight: float = 0.0) -> torch.Tensor:
    """Eq. 14 as the authors train it.

    Backbone (no refined depth): ``(1 - n w) L(D_f) + w sum_b L(D_b)`` over the n branches.
    Full model: ``L(refined)`` plus ``w sum_b L(D_b)`` when ``branch_weight`` is set.
    """
    branches = [d for d in (out.color_depth, out.semantic_depth, out.guided_depth) if d is not None]
    branch_loss = sum((masked_mse(d, gt) for d in branches), torch.zeros((), device=gt.device))
    if out.refined_depth is None:
        return (1.0 - len(branches) * branch_weight) * masked_mse(out.fused_depth, gt) + branch_weight * branch_loss
    return masked_mse(out.refined_depth, gt) + branch_weight * branch_loss
