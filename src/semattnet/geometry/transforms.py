"""Rigid transforms as 4x4 homogeneous matrices (column-vector convention).

``T_a_b`` maps a point from frame ``b`` to frame ``a``: ``p_a = T_a_b @ p_b`` with ``p`` homogeneous,
i.e. ``p_a = R p_b + t`` where ``R = T_a_b[:3, :3]`` and ``t = T_a_b[:3, 3]``. Transforms compose
right to left: ``T_a_c = T_a_b @ T_b_c``.

Every function accepts NumPy arrays or torch tensors and returns the same kind.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, TypeAlias, overload

import numpy as np
import numpy.typing as npt

from semattnet._errors import InputError

if TYPE_CHECKING:
    from torch import Tensor
    from typing_extensions import TypeIs

__all__ = [
    "Array",
    "ArrayInput",
    "check_rigid",
    "check_rotation",
    "invert_T",
    "is_tensor",
    "make_T",
    "transform_points",
]

Array: TypeAlias = "np.ndarray | Tensor"
"""A NumPy array or a torch tensor: what the functions here take, returning the same kind."""
ArrayInput: TypeAlias = "np.ndarray | Tensor | npt.ArrayLike"
"""What a matrix argument may be: an array, a tensor or nested sequences of numbers."""


def is_tensor(x: object) -> TypeIs[Tensor]:
    """Whether ``x`` is a torch tensor (checked without importing torch; NumPy otherwise)."""
    return type(x).__module__.split(".")[0] == "torch"


@overload
def _swap_last(x: Tensor) -> Tensor: ...
@overload
def _swap_last(x: np.ndarray) -> np.ndarray: ...
def _swap_last(x: Array) -> Array:
    """Transpose of the last two axes, for NumPy arrays and torch tensors."""
    return x.transpose(-1, -2) if is_tensor(x) else np.swapaxes(x, -1, -2)


@overload
def make_T(R: Tensor, t: ArrayInput) -> Tensor: ...
@overload
def make_T(R: np.ndarray, t: npt.ArrayLike) -> np.ndarray: ...
def make_T(R: Array, t: ArrayInput) -> Array:
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


@overload
def invert_T(T: Tensor) -> Tensor: ...
@overload
def invert_T(T: np.ndarray) -> np.ndarray: ...
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


@overload
def transform_points(T: ArrayInput, xyz: Tensor) -> Tensor: ...
@overload
def transform_points(T: ArrayInput, xyz: np.ndarray) -> np.ndarray: ...
def transform_points(T: ArrayInput, xyz: Array) -> Array:
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

        Tt = torch.as_tensor(T, dtype=xyz.dtype, device=xyz.device)
        moved = xyz.clone()
        moved[..., :3] = xyz[..., :3] @ Tt[:3, :3].transpose(0, 1) + Tt[:3, 3]
        return moved
    pts = np.asarray(xyz)
    out = pts.astype(np.result_type(pts.dtype, np.float32), copy=True)
    M = np.asarray(T, dtype=np.float64)
    x, y, z = (pts[..., i].astype(np.float64) for i in range(3))
    for i in range(3):  # written out: a BLAS matmul of (N, 3) @ (3, 3) is slower and thread-hungry
        out[..., i] = M[i, 0] * x + M[i, 1] * y + M[i, 2] * z + M[i, 3]
    return out


def check_rigid(T: ArrayInput, tol: float = 1e-3) -> str | None:
    """Why ``T`` is not a rigid transform, or None when it is.

    Checks shape (4, 4), finiteness, last row ``[0, 0, 0, 1]``, ``R^T R = I`` and ``det R = +1`` to ``tol``.
    """
    M = np.asarray(T.detach().cpu() if is_tensor(T) else T, dtype=np.float64)
    if M.shape != (4, 4):
        return f"expected a 4x4 matrix, got shape {M.shape}"
    if not np.all(np.isfinite(M)):
        return "contains NaN or infinite values"
    if not np.allclose(M[3], [0, 0, 0, 1], atol=tol):
        return f"last row is {M[3].tolist()}, expected [0, 0, 0, 1]"
    return check_rotation(M[:3, :3], tol)


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
