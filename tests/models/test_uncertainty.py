"""The per-pixel uncertainty (semattnet.models.uncertainty) and the classical baseline's proxy."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

import semattnet
from semattnet.baselines.classical import ClassicalCompleter, classical_fill_step, classical_uncertainty
from semattnet.inference import DepthCompleter
from semattnet.inference.backends import EngineSpec, available_backends
from semattnet.models.outputs import DepthCompletionOutput
from semattnet.models.registry import list_models
from semattnet.models.uncertainty import (
    anchor_term,
    branch_spread,
    depth_slope,
    depth_uncertainty,
    lidar_distance,
    refinement_change,
)
from tests._helpers import random_inputs


def _t(*values: float) -> torch.Tensor:
    """A (1, 1, 1, N) tensor."""
    return torch.tensor(values, dtype=torch.float32).view(1, 1, 1, -1)


def _output(
    depths: list[list[float]], weights: list[list[float]], refined: list[float] | None = None, three: bool = True
) -> DepthCompletionOutput:
    """A hand-made output: per branch its depths and weights along one row; D_f by eq. 12."""
    d, w = [_t(*x) for x in depths], [_t(*x) for x in weights]
    fused = sum(di * wi for di, wi in zip(d, w, strict=True))
    assert isinstance(fused, torch.Tensor)
    ref = None if refined is None else _t(*refined)
    return DepthCompletionOutput(
        color_depth=d[0],
        semantic_depth=d[1] if three else None,
        guided_depth=d[-1],
        color_conf=w[0],
        semantic_conf=w[1] if three else None,
        guided_conf=w[-1],
        fused_depth=fused,
        refined_depth=ref,
    )


def test_branch_spread_by_hand() -> None:
    # pixel 0: depths 10, 12, 14 with weights 0.5, 0.25, 0.25 -> D_f = 5 + 3 + 3.5 = 11.5,
    #          spread^2 = 0.5 * 1.5^2 + 0.25 * 0.5^2 + 0.25 * 2.5^2 = 1.125 + 0.0625 + 1.5625 = 2.75
    # pixel 1: all three 20 m -> D_f = 20, spread 0
    out = _output([[10, 20], [12, 20], [14, 20]], [[0.5, 0.2], [0.25, 0.3], [0.25, 0.5]])
    torch.testing.assert_close(out.fused_depth, _t(11.5, 20.0))
    torch.testing.assert_close(branch_spread(out), _t(math.sqrt(2.75), 0.0))


def test_two_branch_spread_by_hand() -> None:
    # depths 10 and 20 with weights 0.75, 0.25 -> D_f = 12.5, spread^2 = 0.75 * 6.25 + 0.25 * 56.25 = 18.75
    out = _output([[10], [20]], [[0.75], [0.25]], three=False)
    torch.testing.assert_close(branch_spread(out), _t(math.sqrt(18.75)))


def test_spread_is_zero_when_branches_agree_and_grows_with_disagreement() -> None:
    w = [[0.2], [0.3], [0.5]]
    assert float(branch_spread(_output([[15], [15], [15]], w))) == 0.0
    spreads = [float(branch_spread(_output([[15 - k], [15], [15 + k]], w))) for k in (0.5, 1, 2, 4)]
    assert spreads == sorted(spreads) and spreads[0] > 0


def test_refinement_change_by_hand() -> None:
    out = _output([[10, 20], [10, 20], [10, 20]], [[1 / 3] * 2] * 3, refined=[11.5, 19.0])
    torch.testing.assert_close(refinement_change(out), _t(1.5, 1.0))
    torch.testing.assert_close(refinement_change(_output([[10]], [[1.0]], three=False)), _t(0.0))  # no refinement


def test_lidar_distance_by_hand() -> None:
    sparse = torch.zeros(1, 1, 4, 5)
    sparse[0, 0, 1, 1] = 7.0
    sparse[0, 0, 3, 4] = 9.0
    rows, cols = np.mgrid[0:4, 0:5]
    expected = np.minimum(np.hypot(rows - 1, cols - 1), np.hypot(rows - 3, cols - 4))
    np.testing.assert_allclose(lidar_distance(sparse)[0, 0].numpy(), expected, atol=1e-6)
    assert float(lidar_distance(torch.zeros(1, 1, 3, 4)).min()) == 7.0  # no point: H + W everywhere


def test_lidar_distance_is_exact_on_random_masks() -> None:
    g = torch.Generator().manual_seed(1)
    sparse = (torch.rand(2, 1, 23, 31, generator=g) < 0.03).float() * 5
    sparse[1, 0, 0, 0] = 5.0
    got = lidar_distance(sparse)
    for b in range(2):
        ys, xs = np.nonzero(sparse[b, 0].numpy())
        rows, cols = np.mgrid[0:23, 0:31]
        brute = np.min(np.hypot(rows[..., None] - ys, cols[..., None] - xs), axis=-1)
        np.testing.assert_allclose(got[b, 0].numpy(), brute, atol=1e-5)


def test_anchor_term_on_a_ramp_is_one_plus_the_distance() -> None:
    # depth rises 1 m per column: the slope is 1 m/px everywhere, so (r + 1) g = r + 1
    depth = torch.arange(6, dtype=torch.float32).view(1, 1, 1, 6).expand(1, 1, 4, 6) + 10
    torch.testing.assert_close(depth_slope(depth), torch.ones(1, 1, 4, 6))
    sparse = torch.zeros(1, 1, 4, 6)
    sparse[0, 0, 0, 0] = 10.0
    torch.testing.assert_close(anchor_term(sparse, depth), lidar_distance(sparse) + 1)


def test_combination_by_hand() -> None:
    # one pixel (slope 0, so no anchor term): D_f = 11.5, spread^2 = 2.75 (above), D_r = 12 -> change 0.5,
    # u = sqrt(2.75 + 0.25) = sqrt(3)
    out = _output([[10], [12], [14]], [[0.5], [0.25], [0.25]], refined=[12.0])
    torch.testing.assert_close(depth_uncertainty(out, _t(0.0)), _t(math.sqrt(3.0)))
    # branches agreeing on a ramp (1 m per column), nothing refined: u = the anchor term = distance + 1
    ramp = [[10.0, 11.0, 12.0, 13.0]] * 3
    out = _output(ramp, [[0.2] * 4, [0.3] * 4, [0.5] * 4], refined=ramp[0])
    torch.testing.assert_close(depth_uncertainty(out, _t(10.0, 0, 0, 0)), _t(1.0, 2.0, 3.0, 4.0))


# the generalists' uncertainty is their own calibrated sigma (tests/models/test_generalist.py)
@pytest.mark.parametrize("name", [n for n in list_models() if not n.endswith("_generalist")])
def test_every_variant_gets_an_uncertainty(name: str) -> None:
    torch.manual_seed(0)
    model = semattnet.build_model(name, width=0.125, iterations=2).eval()
    completer = DepthCompleter(model, EngineSpec(device="cpu"))
    x = random_inputs(b=2, h=30, w=45)
    out = completer.run(x["rgb"], x["semantic"] if completer.needs_semantic else None, x["sparse"])
    assert out.uncertainty is not None and out.uncertainty.shape == (2, 1, 30, 45)
    assert torch.isfinite(out.uncertainty).all() and (out.uncertainty >= 0).all()
    torch.testing.assert_close(out.uncertainty, depth_uncertainty(out, x["sparse"]))
    assert "uncertainty" in out.to_dict() and out.map(lambda t: t[..., :3]).uncertainty.shape[-1] == 3


def test_completion_uncertainty_is_an_array_in_metres() -> None:
    completer = DepthCompleter(semattnet.build_model("semattnet", width=0.125, iterations=2), EngineSpec(device="cpu"))
    rgb = np.full((20, 30, 3), 90, np.uint8)
    sparse = np.zeros((20, 30), np.float32)
    sparse[15, 5], sparse[12, 25] = 12.5, 30.0
    result = completer(rgb, sparse, rgb)
    assert result.uncertainty is not None
    assert result.uncertainty.shape == (20, 30) and result.uncertainty.dtype == np.float32
    np.testing.assert_array_equal(result.uncertainty, result.outputs["uncertainty"])
    completer.compute_uncertainty = False  # switched off: the field stays None
    assert completer(rgb, sparse, rgb).uncertainty is None


def test_classical_proxy_by_hand() -> None:
    sparse = torch.zeros(1, 1, 5, 9)
    sparse[0, 0, 2, 4] = 10.0
    step = classical_fill_step(sparse)[0, 0]
    assert int(step[2, 4]) == 0 and int(step[2, 5]) == 1 and int(step[2, 7]) == 1  # measured; diamond of radius 3
    assert int(step.max()) >= 1
    # one measurement: the completion is flat, slope 0, so the proxy is 0 everywhere
    assert float(classical_uncertainty(sparse).abs().max()) == 0.0
    # on a given ramp (1 m per column) the proxy is one plus the distance to the point
    ramp = torch.arange(9, dtype=torch.float32).view(1, 1, 1, 9).expand(1, 1, 5, 9) + 6
    rows, cols = np.mgrid[0:5, 0:9]
    np.testing.assert_allclose(
        classical_uncertainty(sparse, ramp)[0, 0].numpy(), np.hypot(rows - 2, cols - 4) + 1, atol=1e-6
    )


def test_classical_completion_carries_its_uncertainty() -> None:
    sparse = np.zeros((12, 16), np.float32)
    sparse[8, 2], sparse[9, 13] = 10.0, 20.0
    result = ClassicalCompleter()(np.zeros((12, 16, 3), np.uint8), sparse)
    assert result.uncertainty is not None and result.uncertainty.shape == (12, 16)
    assert result.uncertainty.dtype == np.float32 and (result.uncertainty >= 0).all()
    assert result.uncertainty.max() > 0  # two depths: a slope between them


@pytest.mark.parametrize("backend", ["onnxruntime", "openvino"])
def test_uncertainty_is_the_same_for_every_engine(backend: str) -> None:
    if backend not in available_backends():
        pytest.skip(f"{backend} is not installed")
    torch.manual_seed(0)
    model = semattnet.build_model("semattnet", width=0.125, iterations=2).eval()
    x = random_inputs(b=1, h=32, w=64)
    ref = DepthCompleter(model, EngineSpec(device="cpu")).run(x["rgb"], x["semantic"], x["sparse"])
    out = DepthCompleter(model, EngineSpec(backend=backend, device="cpu")).run(x["rgb"], x["semantic"], x["sparse"])
    assert ref.uncertainty is not None and out.uncertainty is not None
    scale = float(ref.uncertainty.abs().max())
    assert float((out.uncertainty - ref.uncertainty).abs().max()) <= 1e-3 * scale + 1e-4
