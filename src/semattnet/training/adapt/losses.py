"""The self-supervised losses of ``semattnet adapt``: no ground truth, only the frames' own sensors.

* :func:`hide_points` / :func:`sparse_loss`: a random share of the LiDAR points is hidden from the input and the
  prediction is supervised at the hidden points and (weighted) at the kept ones, masked L1.
* :func:`photometric_loss`: the other views (a stereo partner, neighbouring frames) warped into the target camera
  with the predicted depth (:func:`semattnet.geometry.warp.inverse_warp`) must reproduce the target image:
  SSIM (3x3) and L1 mixed 0.85 / 0.15, the per-pixel minimum over the views, auto-masking (Monodepth2).
* :func:`smoothness_loss`: edge-aware smoothness of the mean-normalised inverse depth (Monodepth2).

The equations are on the documentation page (docs/guides/adapt.md).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from semattnet.geometry.warp import inverse_warp, sample_at_pixels
from semattnet.training.adapt.batch import ViewBatch
from semattnet.training.losses import masked_l1

__all__ = [
    "AUTOMASK_MARGIN",
    "SSIM_WEIGHT",
    "hide_points",
    "photometric_error",
    "photometric_loss",
    "smoothness_loss",
    "sparse_loss",
    "ssim_dissimilarity",
]

#: The SSIM share of the photometric error (Monodepth2): ``0.85 (1 - SSIM) / 2 + 0.15 |a - b|``.
SSIM_WEIGHT = 0.85
#: How much better than the unwarped view a warped pixel must match to count (auto-masking): ties (a static
#: scene, rounding) are left out.
AUTOMASK_MARGIN = 1e-3
_C1, _C2 = 0.01**2, 0.03**2


def hide_points(
    sparse: torch.Tensor, share: torch.Tensor, generator: torch.Generator | None = None
) -> tuple[torch.Tensor, torch.Tensor]:
    """Split each item's valid points (``sparse > 0``) into kept and hidden ones: each point is hidden with
    probability ``share`` (B,) of its item. Returns ``(kept, hidden)``, two maps like ``sparse`` (0 elsewhere).
    The draw is on the CPU with ``generator`` (so the same on every device)."""
    draw = torch.rand(sparse.shape, generator=generator).to(sparse.device)
    hidden_at = (sparse > 0) & (draw < share.to(sparse.device).reshape(-1, *([1] * (sparse.dim() - 1))))
    zero = torch.zeros_like(sparse)
    return torch.where(hidden_at, zero, sparse), torch.where(hidden_at, sparse, zero)


def sparse_loss(pred: torch.Tensor, kept: torch.Tensor, hidden: torch.Tensor, kept_weight: float) -> torch.Tensor:
    """``L1(pred, hidden) + kept_weight L1(pred, kept)``, each the mean absolute error (metres) over its points."""
    return masked_l1(pred, hidden) + kept_weight * masked_l1(pred, kept)


def ssim_dissimilarity(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """``(1 - SSIM(a, b)) / 2`` per pixel and channel, SSIM over 3x3 windows (reflection padding), images in
    [0, 1]: 0 for identical images (Monodepth2's ``SSIM`` module)."""
    a, b = F.pad(a, (1, 1, 1, 1), mode="reflect"), F.pad(b, (1, 1, 1, 1), mode="reflect")
    mu_a, mu_b = F.avg_pool2d(a, 3, 1), F.avg_pool2d(b, 3, 1)
    var_a = F.avg_pool2d(a * a, 3, 1) - mu_a**2
    var_b = F.avg_pool2d(b * b, 3, 1) - mu_b**2
    cov = F.avg_pool2d(a * b, 3, 1) - mu_a * mu_b
    num = (2 * mu_a * mu_b + _C1) * (2 * cov + _C2)
    den = (mu_a**2 + mu_b**2 + _C1) * (var_a + var_b + _C2)
    return ((1 - num / den) / 2).clamp(0, 1)


def photometric_error(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """(B, 1, H, W) ``0.85 (1 - SSIM) / 2 + 0.15 |a - b|``, averaged over the channels; images in [0, 1]."""
    l1 = (a - b).abs().mean(1, keepdim=True)
    return SSIM_WEIGHT * ssim_dissimilarity(a, b).mean(1, keepdim=True) + (1 - SSIM_WEIGHT) * l1


def _whole_windows(valid: torch.Tensor) -> torch.Tensor:
    """Pixels whose whole 3x3 window (the SSIM's) is valid: a sample outside the view spoils its neighbours."""
    return -F.max_pool2d(-valid.float(), 3, 1, 1) > 0.5


def photometric_loss(
    target: torch.Tensor, depth: torch.Tensor, views: ViewBatch, automask: bool = True
) -> tuple[torch.Tensor, torch.Tensor]:
    """The photometric loss of ``depth`` (B, 1, H, W, metres) for the ``target`` image (B, 3, H, W, [0, 1]).

    Each view (``views``: :class:`ViewBatch`) is warped into the target camera; the error is the per-pixel minimum
    over the views present there. With ``automask`` a pixel counts only where that minimum is below the minimum of
    the unwarped views' errors (the view's image at the same pixel) by :data:`AUTOMASK_MARGIN`: static scenes,
    objects moving with the camera and the sky are left out. Returns ``(loss, mask)``: the mean error over the kept
    pixels (0 when none) and the (B, 1, H, W) kept pixels."""
    big = torch.tensor(1e4, device=target.device)
    warped_min, identity_min = torch.full_like(depth, 1e4), torch.full_like(depth, 1e4)
    for i in range(views.images.shape[1]):
        image, K_view, T = views.images[:, i], views.K_view[:, i], views.T_view_cam[:, i]
        warped, valid = inverse_warp(image, depth, views.K, K_view, T, views.offset)
        valid = _whole_windows(valid & views.present[:, i].reshape(-1, 1, 1, 1))
        warped_min = torch.minimum(warped_min, torch.where(valid, photometric_error(warped, target), big))
        if automask:
            same, inside = sample_at_pixels(image, (depth.shape[-2], depth.shape[-1]), views.offset)
            inside = _whole_windows(inside & views.present[:, i].reshape(-1, 1, 1, 1))
            identity_min = torch.minimum(identity_min, torch.where(inside, photometric_error(same, target), big))
    mask = warped_min + AUTOMASK_MARGIN < identity_min if automask else warped_min < big
    loss = (warped_min * mask).sum() / mask.sum().clamp_min(1)
    return loss, mask


def smoothness_loss(depth: torch.Tensor, image: torch.Tensor, eps: float = 1e-3) -> torch.Tensor:
    """Edge-aware smoothness of the inverse depth ``d* = d / mean(d)`` (``d = 1 / depth``, per item):
    ``mean |dx d*| exp(-|dx I|) + mean |dy d*| exp(-|dy I|)``, ``|dx I|`` the mean over the image's channels
    ([0, 1]). 0 for a constant map; image edges excuse depth edges."""
    inv = 1.0 / depth.clamp_min(eps)
    norm = inv / (inv.mean((2, 3), keepdim=True) + 1e-7)
    dx, dy = (norm[..., :, :-1] - norm[..., :, 1:]).abs(), (norm[..., :-1, :] - norm[..., 1:, :]).abs()
    ix = (image[..., :, :-1] - image[..., :, 1:]).abs().mean(1, keepdim=True)
    iy = (image[..., :-1, :] - image[..., 1:, :]).abs().mean(1, keepdim=True)
    return (dx * torch.exp(-ix)).mean() + (dy * torch.exp(-iy)).mean()
