"""Checks on model inputs, with one-line errors that name the offending tensor."""

from __future__ import annotations

import math

import numpy as np
import torch

from semattnet._errors import InputError
from semattnet.models._tracing import is_tracing

__all__ = [
    "MAX_INPUT_DEPTH_M",
    "SIZE_MULTIPLE",
    "check_has_points",
    "check_inputs",
    "check_sparse_depth",
    "require_sparse",
]

#: H and W must be multiples of this (five stride-2 stages).
SIZE_MULTIPLE = 32
#: Largest input depth accepted, metres: the home of this bound for the model and the classical
#: completer. LiDARs reach ~300 m and KITTI's 16-bit PNGs hold 256 m; larger values are unit errors
#: (millimetres given as metres) or garbage.
MAX_INPUT_DEPTH_M = 1000.0


def require_sparse(sparse: torch.Tensor | None) -> torch.Tensor:
    """``sparse``, the one input a model's ``forward`` cannot do without (its keyword default is None)."""
    if sparse is None:
        raise InputError("sparse depth is required")
    return sparse


def check_sparse_depth(sparse: torch.Tensor, name: str = "sparse") -> None:
    """Refuse NaN / infinite, negative or implausibly large (> :data:`MAX_INPUT_DEPTH_M`) depth, with the
    same one-line :class:`~semattnet.InputError` for the model and the classical completer."""
    low, top = _range(sparse)  # one pass: NaN and infinities show in the extremes
    if not (math.isfinite(low) and math.isfinite(top)):
        raise InputError(f"{name} contains NaN or infinite values; depth is in metres with 0 = missing")
    if low < 0:
        raise InputError(f"{name} depth contains negative values; depth is in metres with 0 = missing")
    if top > MAX_INPUT_DEPTH_M:
        bound = f"{MAX_INPUT_DEPTH_M:g} m (semattnet.models.checks.MAX_INPUT_DEPTH_M)"
        raise InputError(f"{name} depth reaches {top:.6g} m, above {bound}; depth is in metres, not millimetres")


def _cpu_array(t: torch.Tensor) -> np.ndarray | None:
    """A CPU float tensor as a NumPy view (no copy), else None. One frame's checks run on it: PyTorch's
    reductions wake its thread pool for each call (measured 7-16 ms a 352x1216 map on 2 busy cores, against
    under 0.1 ms in NumPy)."""
    if t.device.type != "cpu" or t.dtype not in (torch.float32, torch.float64, torch.float16):
        return None
    return t.detach().numpy()


def _range(sparse: torch.Tensor) -> tuple[float, float]:
    """(smallest, largest) value of ``sparse`` in one pass ((0, 0) when empty; NaN when it holds one)."""
    if not sparse.numel():
        return 0.0, 0.0
    array = _cpu_array(sparse)
    if array is not None:
        return float(array.min()), float(array.max())
    low, top = torch.aminmax(sparse.detach())
    return float(low), float(top)


def check_has_points(sparse: torch.Tensor, name: str = "sparse") -> None:
    """Refuse a frame whose sparse map has no valid point (every pixel 0): a completion of it means nothing."""
    array = _cpu_array(sparse)
    if not bool((array > 0).any() if array is not None else (sparse > 0).any()):
        raise InputError(f"{name} has no valid depth point (every pixel is 0 = missing); nothing to complete")


def check_inputs(
    rgb: torch.Tensor,
    semantic: torch.Tensor | None,
    sparse: torch.Tensor,
    *,
    need_semantic: bool,
    sparse_channels: int = 1,
) -> None:
    """Raise :class:`~semattnet.InputError` unless the inputs are what SemAttNet expects.

    Expected: ``rgb`` (B, 3, H, W) 0..255, ``semantic`` (B, 3, H, W) colour-coded 0..255,
    ``sparse`` (B, 1, H, W) metres with 0 = missing; float tensors of one size, H and W
    multiples of 32, finite values, depth in [0, :data:`MAX_INPUT_DEPTH_M`] (``sparse_channels``: 2 for the
    generalist's network, sparse and anchor). Use
    :func:`semattnet.pad_to_multiple` to run on other sizes.
    """
    named = [("rgb", rgb, 3), ("sparse", sparse, sparse_channels)]
    if need_semantic:
        if semantic is None:
            raise InputError("semantic is required by this model (three-branch); got None")
        named.insert(1, ("semantic", semantic, 3))
    for name, t, channels in named:
        if not isinstance(t, torch.Tensor):
            raise InputError(f"{name} must be a torch.Tensor, got {type(t).__name__}")
        if t.dim() != 4:
            raise InputError(f"{name} must be (B, {channels}, H, W), got shape {tuple(t.shape)}")
        if t.shape[1] != channels:
            raise InputError(f"{name} must have {channels} channel(s), got shape {tuple(t.shape)}")
        if not t.is_floating_point():
            raise InputError(f"{name} must be a floating-point tensor, got {t.dtype}")
    b, _, h, w = rgb.shape
    for name, t, _ in named[1:]:
        if (t.shape[0], t.shape[2], t.shape[3]) != (b, h, w):
            raise InputError(
                f"{name} has shape {tuple(t.shape)} but rgb has {tuple(rgb.shape)}: batch and size must match"
            )
        if t.device != rgb.device:
            raise InputError(f"{name} is on {t.device} but rgb is on {rgb.device}")
    if h % SIZE_MULTIPLE or w % SIZE_MULTIPLE or h == 0 or w == 0:
        raise InputError(
            f"input size {h}x{w} is not a positive multiple of {SIZE_MULTIPLE} in both dimensions; "
            "pad with semattnet.pad_to_multiple (and crop the outputs back)"
        )
    if is_tracing():
        return
    for name, t, _ in named[:-1]:
        if not bool(torch.isfinite(t).all()):
            raise InputError(f"{name} contains NaN or infinite values")
    check_sparse_depth(sparse)
