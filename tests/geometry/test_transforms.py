from __future__ import annotations

import numpy as np
import pytest
import torch

from semattnet.geometry import check_rigid, invert_T, make_T, transform_points


def rot_z(deg: float) -> np.ndarray:
    a = np.radians(deg)
    return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])


def test_make_T_and_hand_computed_point() -> None:
    T = make_T(rot_z(90), [1.0, 2.0, 3.0])
    assert T.shape == (4, 4) and np.allclose(T[3], [0, 0, 0, 1])
    # Rz(90) maps x to y: (1, 0, 0) -> (0, 1, 0), then + t.
    assert np.allclose(transform_points(T, np.array([[1.0, 0.0, 0.0]])), [[1.0, 3.0, 3.0]])


def test_invert_and_compose_give_identity() -> None:
    rng = np.random.default_rng(0)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    T_a_b = make_T(q, rng.normal(size=3))
    T_b_a = invert_T(T_a_b)
    assert np.allclose(T_a_b @ T_b_a, np.eye(4), atol=1e-12)
    assert np.allclose(T_b_a, np.linalg.inv(T_a_b), atol=1e-12)
    pts = rng.normal(size=(50, 3))
    assert np.allclose(transform_points(T_b_a, transform_points(T_a_b, pts)), pts, atol=1e-12)
    T_c_b = make_T(rot_z(30), [0.5, 0, 0]) @ T_a_b  # compose: b -> a -> c
    assert np.allclose(
        transform_points(T_c_b, pts), transform_points(make_T(rot_z(30), [0.5, 0, 0]), transform_points(T_a_b, pts))
    )


def test_extra_columns_kept_and_torch_matches_numpy() -> None:
    T = make_T(rot_z(45), [1.0, -1.0, 0.5])
    pts = np.array([[1.0, 2.0, 3.0, 0.7], [-4.0, 0.0, 1.0, 0.2]], dtype=np.float32)
    out = transform_points(T, pts)
    assert out.dtype == np.float32 and np.allclose(out[:, 3], [0.7, 0.2])
    out_t = transform_points(torch.from_numpy(T), torch.from_numpy(pts))
    assert isinstance(out_t, torch.Tensor) and np.allclose(out_t.numpy(), out, atol=1e-5)
    Ti = invert_T(torch.from_numpy(T))
    assert torch.allclose(Ti @ torch.from_numpy(T), torch.eye(4, dtype=torch.float64), atol=1e-12)


def test_check_rigid_flags_bad_matrices() -> None:
    assert check_rigid(make_T(rot_z(10), [1, 2, 3])) is None
    assert "determinant" in check_rigid(make_T(np.diag([1.0, 1.0, -1.0]), [0, 0, 0]))
    assert "orthonormal" in check_rigid(make_T(2 * np.eye(3), [0, 0, 0]))
    bad = np.eye(4)
    bad[3, 0] = 1
    assert "last row" in check_rigid(bad)
    bad = np.eye(4)
    bad[0, 0] = np.nan
    assert "NaN" in check_rigid(bad)


def test_transform_points_rejects_too_few_columns() -> None:
    with pytest.raises(ValueError, match="at least 3 columns"):
        transform_points(np.eye(4), np.zeros((5, 2)))
