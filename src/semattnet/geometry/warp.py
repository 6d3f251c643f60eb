"""Inverse warping: another calibrated view of a scene sampled at the pixels of a target camera, given the
target's depth (the view synthesis of self-supervised depth, Monodepth2 / Ma et al. 2019).

A target pixel ``p = (u, v, 1)`` (full-image coordinates: a crop's pixel plus the crop's ``offset``) at depth ``d``
is the point ``X = d K^-1 p`` of the target camera; in the view's camera it is ``X' = T_view_cam X`` and lands on
``p' ~ K_view X'``. The view's image is sampled there (bilinear, :func:`torch.nn.functional.grid_sample`); a pixel
whose point is behind the view's camera or lands outside its image is marked invalid. Conventions as in
:mod:`semattnet.geometry` (``T_a_b``: frame ``b`` to frame ``a``; pixel centres at integer coordinates).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

__all__ = ["inverse_warp", "pixel_coordinates", "sample_at_pixels"]

#: Points nearer the view's camera than this (metres) are invalid: behind it, or too close to project stably.
MIN_VIEW_DEPTH_M = 1e-3


def pixel_coordinates(shape: tuple[int, int, int], offset: torch.Tensor | None = None) -> torch.Tensor:
    """(B, 3, H*W) homogeneous pixel coordinates ``(u, v, 1)`` of a (B, H, W) grid, each item shifted by its
    ``offset`` (B, 2) ``(x0, y0)`` (a crop's top-left corner in the full image; None: no shift), float32."""
    b, h, w = shape
    device = offset.device if offset is not None else None
    v, u = torch.meshgrid(
        torch.arange(h, dtype=torch.float32, device=device),
        torch.arange(w, dtype=torch.float32, device=device),
        indexing="ij",
    )
    grid = torch.stack([u.reshape(-1), v.reshape(-1), torch.ones(h * w, device=device)]).expand(b, 3, h * w).clone()
    if offset is not None:
        grid[:, :2] += offset.to(torch.float32)[:, :, None]
    return grid


def inverse_warp(
    view: torch.Tensor,
    depth: torch.Tensor,
    K: torch.Tensor,
    K_view: torch.Tensor,
    T_view_cam: torch.Tensor,
    offset: torch.Tensor | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """The view's image seen from the target camera.

    Args:
        view: (B, C, Hv, Wv) the other view's image.
        depth: (B, 1, H, W) target depth, metres (> 0).
        K: (B, 3, 3) target intrinsics, full-image pixels. K_view: (B, 3, 3) the view's intrinsics.
        T_view_cam: (B, 4, 4) target camera -> the view's camera, metres.
        offset: (B, 2) ``(x0, y0)`` of the target crop in the full image (None: the whole image).

    Returns:
        ``(warped, valid)``: (B, C, H, W) the view sampled at each target pixel, and (B, 1, H, W) bool, True
        where the point is in front of the view's camera and inside its image.
    """
    b, _, h, w = depth.shape
    pix = pixel_coordinates((b, h, w), offset if offset is not None else depth.new_zeros(b, 2))
    points = torch.linalg.solve(K.float(), pix) * depth.float().reshape(b, 1, h * w)  # (B, 3, N) target camera
    T = T_view_cam.float()
    seen = K_view.float() @ (T[:, :3, :3] @ points + T[:, :3, 3:])
    z = seen[:, 2]
    front = z > MIN_VIEW_DEPTH_M
    z_safe = torch.where(front, z, torch.ones_like(z))
    return _sample(view, seen[:, 0] / z_safe, seen[:, 1] / z_safe, front, (h, w))


def sample_at_pixels(
    view: torch.Tensor, size: tuple[int, int], offset: torch.Tensor | None = None
) -> tuple[torch.Tensor, torch.Tensor]:
    """The view's image at the target's own pixels (no motion: Monodepth2's identity reprojection), exactly: the
    (H, W) ``size`` window at ``offset`` (B, 2) ``(x0, y0)``; returns ``(image, valid)`` as :func:`inverse_warp`."""
    b = view.shape[0]
    pix = pixel_coordinates((b, *size), offset if offset is not None else view.new_zeros(b, 2))
    return _sample(view, pix[:, 0], pix[:, 1], torch.ones_like(pix[:, 0], dtype=torch.bool), size)


def _sample(
    view: torch.Tensor, u: torch.Tensor, v: torch.Tensor, front: torch.Tensor, size: tuple[int, int]
) -> tuple[torch.Tensor, torch.Tensor]:
    """``view`` sampled bilinearly at pixels (u, v) (B, N) reshaped to ``size``; invalid where not ``front`` or
    outside the image (those samples are zeros)."""
    b, (h, w), (hv, wv) = view.shape[0], size, view.shape[-2:]
    inside = front & (u >= 0) & (u <= wv - 1) & (v >= 0) & (v <= hv - 1)
    grid = torch.stack([2 * u / max(wv - 1, 1) - 1, 2 * v / max(hv - 1, 1) - 1], -1).reshape(b, h, w, 2)
    grid = torch.where(inside.reshape(b, h, w, 1), grid, torch.full_like(grid, -2.0))  # far outside: zeros
    warped = F.grid_sample(view.float(), grid, mode="bilinear", padding_mode="zeros", align_corners=True)
    return warped, inside.reshape(b, 1, h, w)
