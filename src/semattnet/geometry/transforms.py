"""Rigid transforms as 4x4 homogeneous matrices (column-vector convention).

``T_a_b`` maps a point from frame ``b`` to frame ``a``: ``p_a = T_a_b @ p_b`` with ``p`` homogeneous,
i.e. ``p_a = R p_b + t`` where ``R = T_a_b[:3, :3]`` and ``t = T_a_b[:3, 3]``. Transforms compose
right to left: ``T_a_c = T_a_b @ T_b_c``.

Every function accepts NumPy arrays or torch tensors and returns the same kind.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from semattnet._errors import InputError

__all__ = ["check_rigid", "check_rotation", "invert_T", "is_tensor", "make_T", "transform_points"]

Array = Any  # np.ndarray or torch.Tensor


def is_tensor(x: object) -> bool:
    """Whether ``x`` is a torch tensor (checked without importing torch; NumPy otherwise)."""
    return type(x).__module__.split(".")[0] == "torch"


def _swap_last(x: Array) -> Array:
    """Transpose of the last two axes, for NumPy arrays and torch tensors."""
    return x.transpose(-1, -2) if is_tensor(x) else np.swapaxes(x, -1, -2)


def make_T(R: Array, t: Array) -> Array:
    """Build ``T = [[R, t], [0, 0, 0, 1]]``.

    Args:
        R: (3, 3) rotation.
        t: (3,) translation in metres.

    Returns:
        (4, 4) transform, same kind (NumPy/torch) and dtype as ``R`` (float64 for NumPy integer input).
    """
    if is_tensor(R):
        import torch

        T = torch.eye(4, dtype=R.dtype, device=R.device)
        T[:3, :3] = R
        T[:3, 3] = torch.as_tensor(t, dtype=R.dtype, device=R.device).reshape(3)
        return T
    R = np.asarray(R)
    dtype = R.dtype if np.issubdtype(R.dtype, np.floating) else np.float64
    out = np.eye(4, dtype=dtype)
    out[:3, :3] = R
    out[:3, 3] = np.asarray(t, dtype=dtype).reshape(3)
    return out


def invert_T(T: Array) -> Array:
    """Closed-form inverse of a rigid transform: ``T^-1 = [[R^T, -R^T t], [0, 1]]``.

    Args:
        T: (4, 4) rigid transform ``T_a_b``.

    Returns:
        (4, 4) ``T_b_a``. Assumes ``R`` is a rotation (see :func:`check_rigid`); not a general matrix inverse.
    """
    R, t = T[:3, :3], T[:3, 3]
    Rt = _swap_last(R)
    return make_T(Rt, -(Rt @ t))


def transform_points(T: Array, xyz: Array) -> Array:
    """Apply ``T`` to points: ``p' = R p + t`` for each row.

    Args:
        T: (4, 4) transform ``T_a_b``.
        xyz: (N, 3) points in frame ``b`` (metres); (N, 3+k) keeps the extra columns unchanged.

    Returns:
        (N, 3) or (N, 3+k) points in frame ``a``, dtype of ``xyz`` for floating input.
    """
    if xyz.shape[-1] < 3:
        raise InputError(f"points must have at least 3 columns (x, y, z), got shape {tuple(xyz.shape)}")
    if is_tensor(xyz):
        import torch

        T = torch.as_tensor(T, dtype=xyz.dtype, device=xyz.device)
        out = xyz.clone()
        out[..., :3] = xyz[..., :3] @ T[:3, :3].transpose(0, 1) + T[:3, 3]
        return out
    xyz = np.asarray(xyz)
    out = xyz.astype(np.result_type(xyz.dtype, np.float32), copy=True)
    T = np.asarray(T, dtype=np.float64)
    x, y, z = (xyz[..., i].astype(np.float64) for i in range(3))
    for i in range(3):  # written out: a BLAS matmul of (N, 3) @ (3, 3) is slower and thread-hungry
        out[..., i] = T[i, 0] * x + T[i, 1] * y + T[i, 2] * z + T[i, 3]
    return out


def check_rigid(T: Array, tol: float = 1e-3) -> str | None:
    """Why ``T`` is not a rigid transform, or None when it is.

    Checks shape (4, 4), finiteness, last row ``[0, 0, 0, 1]``, ``R^T R = I`` and ``det R = +1`` to ``tol``.
    """
    T = np.asarray(T.detach().cpu() if is_tensor(T) else T, dtype=np.float64)
    if T.shape != (4, 4):
        return f"expected a 4x4 matrix, got shape {T.shape}"
    if not np.all(np.isfinite(T)):
        return "contains NaN or infinite values"
    if not np.allclose(T[3], [0, 0, 0, 1], atol=tol):
        return f"last row is {T[3].tolist()}, expected [0, 0, 0, 1]"
    return check_rotation(T[:3, :3], tol)


def check_rotation(R: np.ndarray, tol: float = 1e-3) -> str | None:
    """Why ``R`` (3, 3) is not a rotation (orthonormal, det +1, to ``tol``), or None when it is."""
    R = np.asarray(R, dtype=np.float64)
    if R.shape != (3, 3) or not np.all(np.isfinite(R)):
        return f"rotation must be a finite 3x3 matrix (shape {R.shape})"
    err = float(np.abs(R.T @ R - np.eye(3)).max())
    if err > tol:
        return f"rotation is not orthonormal (max |R^T R - I| = {err:.3g})"
    det = float(np.linalg.det(R))
    if abs(det - 1.0) > tol:
        return f"rotation has determinant {det:.4g}, expected +1 (reflection or singular)"
    return None
