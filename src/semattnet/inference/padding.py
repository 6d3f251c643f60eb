"""Padding frames of any size to the model's multiple of 32, and cropping the outputs back."""

from __future__ import annotations

import torch

from semattnet.models.checks import SIZE_MULTIPLE

__all__ = ["crop_padding", "pad_to_multiple"]


def pad_to_multiple(
    x: torch.Tensor, multiple: int = SIZE_MULTIPLE, value: float = 0.0
) -> tuple[torch.Tensor, tuple[int, int, int, int]]:
    """Pad (..., H, W) so both are multiples of ``multiple``: rows at the top (KITTI's sky side,
    keeping the image bottom-aligned as in training), columns split left/right.

    Returns the padded tensor and ``(top, bottom, left, right)`` for :func:`crop_padding`.
    """
    h, w = x.shape[-2:]
    ph, pw = (-h) % multiple, (-w) % multiple
    pad = (ph, 0, pw // 2, pw - pw // 2)
    if ph or pw:
        x = torch.nn.functional.pad(x, (pad[2], pad[3], pad[0], pad[1]), value=value)
    return x, pad


def crop_padding(x: torch.Tensor, pad: tuple[int, int, int, int]) -> torch.Tensor:
    """Undo :func:`pad_to_multiple` on (..., H, W)."""
    top, bottom, left, right = pad
    return x[..., top : x.shape[-2] - bottom, left : x.shape[-1] - right]
