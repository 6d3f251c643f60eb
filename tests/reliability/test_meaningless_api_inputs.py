"""The Python API refuses numbers that mean nothing, in one line naming the function or the input: intrinsics
(zero, NaN, a negative focal length, not 3x3) given to ``project_points`` and ``depth_to_points``, non-finite
depth, and colours outside 0..255 given to a ``DepthCompleter``."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from semattnet._errors import InputError
from semattnet.inference.backends import EngineSpec
from tests.reliability._helpers import one_line as _one_line

BAD_K = [np.zeros((3, 3)), np.diag([np.nan, 1.0, 1.0]), np.diag([-50.0, 50.0, 1.0]), np.eye(4)]


@pytest.mark.parametrize("K", BAD_K, ids=["zero", "nan", "negative", "4x4"])
def test_geometry_api_refuses_meaningless_intrinsics(K: np.ndarray) -> None:
    from semattnet.geometry import depth_to_points, project_points

    msg = _one_line(lambda: project_points(np.array([[0.0, 0, 5.0]]), K, np.eye(4), (32, 24)), InputError)
    assert "project_points: K" in msg
    assert "depth_to_points: K" in _one_line(lambda: depth_to_points(np.ones((4, 4)), K), InputError)


def test_depth_to_points_refuses_non_finite_depth() -> None:
    from semattnet.geometry import depth_to_points

    K = np.array([[50, 0, 2], [0, 50, 2], [0, 0, 1.0]])
    assert "NaN" in _one_line(lambda: depth_to_points(np.full((4, 4), np.nan), K), InputError)


@pytest.fixture(scope="module")
def completer():  # type: ignore[no-untyped-def]
    import semattnet

    torch.manual_seed(0)
    return semattnet.DepthCompleter(semattnet.build_model("semattnet", width=0.125).eval(), EngineSpec(device="cpu"))


@pytest.mark.parametrize(
    ("which", "value"), [("semantic", 1e9), ("semantic", -1.0), ("rgb", 256.0), ("rgb", -5.0), ("semantic", np.inf)]
)
def test_depth_completer_refuses_colours_outside_0_255(completer, which: str, value: float) -> None:  # type: ignore[no-untyped-def]
    frame = {"rgb": np.zeros((16, 16, 3)), "semantic": np.zeros((16, 16, 3))}
    frame[which][2, 3, 1] = value
    sparse = np.zeros((16, 16), np.float32)
    sparse[3, 3] = 5.0
    msg = _one_line(lambda: completer(frame["rgb"], sparse, frame["semantic"]), InputError)
    assert msg.startswith(which), msg
