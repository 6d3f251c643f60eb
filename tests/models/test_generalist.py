"""The generalist (models.generalist): scale-free inputs, the bounded correction of the classical anchor, the
calibration fit, and the registry and completer around it."""

from __future__ import annotations

import importlib.util
import math

import numpy as np
import pytest
import torch

import semattnet
from semattnet._errors import InputError
from semattnet.inference.backends import EngineSpec
from semattnet.models.generalist import (
    REFERENCE_DEPTH,
    Generalist,
    fit_calibration,
    frame_scale,
    standardise_colour,
)
from semattnet.models.registry import arch_for, build_model, model_config


def _frame(h: int = 64, w: int = 96, seed: int = 0, far: float = 30.0) -> tuple[torch.Tensor, ...]:
    g = torch.Generator().manual_seed(seed)
    rgb = torch.rand(1, 3, h, w, generator=g) * 255
    semantic = torch.rand(1, 3, h, w, generator=g) * 255
    sparse = (2 + torch.rand(1, 1, h, w, generator=g) * far) * (torch.rand(1, 1, h, w, generator=g) < 0.08)
    return rgb, semantic, sparse


def test_frame_scale_is_the_median_of_the_valid_points_and_one_without_points() -> None:
    sparse = torch.zeros(2, 1, 4, 4)
    sparse[0, 0, 0, :3] = torch.tensor([2.0, 5.0, 11.0])
    scale = frame_scale(sparse)
    assert scale.shape == (2, 1, 1, 1)
    assert scale[0].item() == 5.0 and scale[1].item() == 1.0
    sparse[1, 0, 3, :2] = torch.tensor([7.0, 3.0])  # an even count: the lower of the two middle values
    assert frame_scale(sparse)[1].item() == 3.0
    dense = _frame(96, 128, seed=3)[2]  # against the NaN-masked median over every pixel
    nan_masked = torch.where(dense > 0, dense, torch.full_like(dense, float("nan"))).reshape(1, -1)
    assert frame_scale(dense).item() == torch.nanmedian(nan_masked, dim=1).values.item()


def test_standardised_colours_have_the_same_statistics_whatever_the_exposure() -> None:
    rgb = _frame()[0]
    a, b = standardise_colour(rgb), standardise_colour(rgb * 0.3 + 20)
    torch.testing.assert_close(a, b, atol=1e-3, rtol=0)
    assert abs(a.mean().item() - 128) < 2 and abs(a.std().item() - 50) < 3


@pytest.mark.parametrize("name", ["semattnet_generalist", "semattnet_rt_generalist"])
def test_the_network_sees_the_same_depth_at_any_scale(name: str) -> None:
    """Step 1: the sparse channel the network reads is the same for a frame and the frame 7x larger."""
    model = build_model(name).eval()
    rgb, _, sparse = _frame()
    small, large = model.prepare(rgb, sparse), model.prepare(rgb, sparse * 7)
    torch.testing.assert_close(small.depth, large.depth, rtol=1e-4, atol=1e-4)  # points and anchor
    torch.testing.assert_close(small.anchor * 7, large.anchor, rtol=1e-4, atol=1e-4)
    assert (sparse[sparse > 0] / small.scale.flatten()).median().item() == pytest.approx(REFERENCE_DEPTH, rel=1e-5)


def test_points_that_disagree_with_the_anchor_are_left_out_of_the_networks_input() -> None:
    """A background return inside a foreground region (LiDAR bleed-through) is not read, nor re-injected."""
    sparse = torch.zeros(1, 1, 32, 32)
    sparse[0, 0, ::2, ::2] = 5.0  # a wall at 5 m
    sparse[0, 0, 16, 16] = 20.0  # one return from 20 m behind it
    model = build_model("semattnet_rt_generalist")
    points = model.prepare(torch.rand(1, 3, 32, 32) * 255, sparse).depth[:, :1]
    assert points[0, 0, 16, 16] == 0 and (points > 0).sum() == (sparse > 0).sum() - 1


def test_the_correction_returns_the_anchor_where_the_network_agrees_and_stays_within_the_bound() -> None:
    model = build_model("semattnet_rt_generalist", residual_bound=0.5)
    anchor = torch.rand(1, 1, 8, 8) * 40 + 1
    far = torch.full_like(anchor, 1e4)  # pixels far from every point: the whole bound
    torch.testing.assert_close(model.correct(anchor, anchor, far), anchor)
    wild = anchor * torch.exp(torch.randn(1, 1, 8, 8) * 5)
    ratio = torch.log(model.correct(anchor, wild, far) / anchor).abs()
    assert ratio.max().item() <= 0.5 + 1e-6  # tanh saturates in float32
    # monotone in the network's depth: a deeper prediction never gives a shallower output
    a = torch.full((1, 1, 1, 5), 10.0)
    out = model.correct(a, torch.tensor([2.0, 5.0, 10.0, 20.0, 50.0]).view(1, 1, 1, 5), far[..., :1, :5]).flatten()
    assert torch.all(out[1:] > out[:-1])


def test_the_bound_shrinks_to_the_measurement_near_the_points() -> None:
    """t = 1 - exp(-r / R): a measured pixel keeps the anchor, the bound at r = R is (1 - 1/e) of the whole."""
    model = build_model("semattnet_rt_generalist", residual_bound=1.0, trust_radius=4.0)
    anchor, net = torch.full((1, 1, 1, 3), 10.0), torch.full((1, 1, 1, 3), 1e4)  # the network wants far more
    out = model.correct(anchor, net, torch.tensor([0.0, 4.0, 1e4]).view(1, 1, 1, 3)).flatten()
    assert out[0].item() == pytest.approx(10.0)
    assert math.log(out[1].item() / 10) == pytest.approx(1 - math.exp(-1), rel=1e-4)
    assert math.log(out[2].item() / 10) == pytest.approx(1.0, rel=1e-4)
    flat = build_model("semattnet_rt_generalist", trust_radius=0.0)
    assert flat.correct(anchor, net, torch.zeros(1, 1, 1, 3)).flatten()[0].item() == pytest.approx(
        10 * math.e, rel=1e-4
    )


def test_the_output_is_in_metres_with_a_positive_uncertainty_and_the_measurements_nearby() -> None:
    torch.manual_seed(0)
    model = build_model("semattnet_rt_generalist").eval()
    rgb, semantic, sparse = _frame(far=60.0)
    with torch.no_grad():
        out = model(rgb=rgb, semantic=semantic, sparse=sparse)
    anchor = model.prepare(rgb, sparse).anchor
    assert out.refined_depth.shape == sparse.shape
    ratio = (out.refined_depth / anchor).log().abs()
    assert ratio.max().item() < model.config.residual_bound + 1e-4
    assert out.uncertainty is not None and (out.uncertainty >= 0).all()


def test_fit_calibration_covers_95_percent_at_two_sigma() -> None:
    g = torch.Generator().manual_seed(0)
    sigma = torch.rand(200_000, generator=g, dtype=torch.float64) * 2 + 0.1
    error = torch.randn(200_000, generator=g, dtype=torch.float64) * sigma * 3  # raw under-states by 3x
    depth, far = torch.full_like(sigma, 10.0), torch.zeros_like(sigma)
    k, f, _ = fit_calibration(sigma, depth, far, error, coverage=(0.95, 0.99))  # no pixel is far
    covered = (error.abs() <= 2 * (k * sigma + f * depth)).double().mean().item()
    assert covered == pytest.approx(0.95, abs=0.002)
    # the sharpest fit is no wider on average than the floor-free one (k = the Gaussian's 95 % quantile / 2)
    assert (k * sigma + f * depth).mean().item() <= 3 * 1.96 / 2 * sigma.mean().item() * 1.01


def test_fit_calibration_puts_every_cell_within_bounds_with_the_distance_term() -> None:
    """Two cells: near the points the raw term tells the error; far from them (a share of the image's height)
    the error grows with the distance, which the raw term does not see. Without ``g`` no ``k`` serves both."""
    gen = torch.Generator().manual_seed(1)
    n = 100_000
    raw = torch.rand(2 * n, generator=gen, dtype=torch.float64) * 0.2 + 0.05
    depth = torch.full_like(raw, 10.0)
    far = torch.cat((torch.zeros(n, dtype=torch.float64), torch.rand(n, generator=gen, dtype=torch.float64) * 0.5))
    scale = raw + 3.0 * depth * far  # the truth's spread: the far cell's errors are mostly the distance's
    error = torch.randn(2 * n, generator=gen, dtype=torch.float64) * scale
    cell = torch.cat((torch.zeros(n), torch.ones(n)))
    k, f, far_term = fit_calibration(raw, depth, far, error, cell)
    inside = (error.abs() <= 2 * (k * raw + f * depth + far_term * depth * far)).double()
    shares = [inside[cell == c].mean().item() for c in (0, 1)]
    assert all(0.91 - 1e-3 <= x <= 0.99 for x in shares), (shares, (k, f, far_term))
    assert far_term > 0


def test_weights_calibrated_before_the_distance_term_load_with_it_zero() -> None:
    model = build_model("semattnet_rt_generalist")
    state = model.state_dict()
    state["calibration"] = torch.tensor([0.5, 0.02])
    model.load_state_dict(state)
    assert model.calibration.tolist() == pytest.approx([0.5, 0.02, 0.0])


def test_a_plain_config_cannot_build_the_generalist_and_the_names_map_back() -> None:
    cfg = model_config("semattnet_rt_generalist")
    assert arch_for(cfg) == "semattnet_rt_generalist"
    assert arch_for(model_config("semattnet_generalist")) == "semattnet_generalist"
    with pytest.raises(InputError, match="anchor"):
        build_model("semattnet_rt_md", config=cfg)
    with pytest.raises(InputError, match="anchor must be"):
        cfg.replace(anchor="monocular")
    with pytest.raises(InputError, match="residual_bound"):
        cfg.replace(residual_bound=math.inf)
    assert isinstance(build_model("semattnet_generalist"), Generalist)


def test_the_completer_runs_the_network_between_the_generalists_own_steps() -> None:
    """DepthCompleter: the engine runs the network; scale, colour, anchor and uncertainty are the generalist's."""
    torch.manual_seed(0)
    model = build_model("semattnet_rt_generalist").eval()
    rgb, semantic, sparse = _frame(h=70, w=100)  # padded to 96x128 inside the completer
    completer = semattnet.DepthCompleter(model, EngineSpec(device="cpu"))
    c = completer(
        rgb[0].permute(1, 2, 0).numpy(), sparse[0, 0].numpy(), semantic[0].permute(1, 2, 0).numpy().astype(np.uint8)
    )
    assert c.depth.shape == (70, 100) and c.uncertainty is not None and np.isfinite(c.uncertainty).all()
    anchor = model.prepare(rgb, sparse).anchor[0, 0].numpy()
    assert np.abs(np.log(c.depth / anchor)).max() < model.config.residual_bound + 1e-4


@pytest.mark.slow  # two OpenVINO engines and an int8 quantisation: tens of seconds
@pytest.mark.skipif(
    importlib.util.find_spec("openvino") is None or importlib.util.find_spec("nncf") is None,
    reason="needs openvino and nncf",
)
def test_openvino_runs_the_network_and_int8_calibrates_on_prepared_inputs() -> None:
    """The engines run the network alone (two depth channels); int8 calibrates on what prepare_inputs makes."""
    torch.manual_seed(0)
    model = build_model("semattnet_rt_generalist").eval()
    rgb, semantic, sparse = _frame()
    args = (rgb[0].permute(1, 2, 0).numpy(), sparse[0, 0].numpy(), semantic[0].permute(1, 2, 0).numpy())
    ref = semattnet.DepthCompleter(model, EngineSpec(device="cpu"))(*args)
    spec = {"device": "cpu", "backend": "openvino"}
    f32 = semattnet.DepthCompleter(model, EngineSpec(**spec))(*args)  # the suite's engines go to a temporary cache
    int8 = semattnet.DepthCompleter(model, EngineSpec(precision="int8", **spec))(*args)
    np.testing.assert_allclose(f32.depth, ref.depth, rtol=1e-4, atol=1e-3)
    assert np.abs(np.log(int8.depth / ref.depth)).mean() < 0.05 and int8.uncertainty is not None


def test_bench_times_the_generalists_network_and_notes_its_anchor() -> None:
    """`semattnet bench --weights` of a generalist: the rows are its network on prepared (two-channel) inputs."""
    from semattnet.apps.benchmark import run_benchmark

    model = build_model("semattnet_rt_generalist").eval()
    lines: list[str] = []
    res = run_benchmark((64, 96), "cpu", repeats=1, parts=("full",), model=model, log=lines.append)
    assert [r["what"] for r in res.rows] == ["full model, naive reference", "full model, ours (float32)"]
    assert any(n.startswith("generalist: the rows time its network") for n in res.notes)


def test_the_work_resolution_keeps_each_blocks_nearest_point_mean_colour_and_one_class() -> None:
    """work_resolution at 2 of a 3x5 frame (padded to 4x6): hand-computed blocks."""
    from semattnet.models.generalist import work_resolution

    sparse = torch.zeros(1, 1, 3, 5)
    sparse[0, 0, 0, 0], sparse[0, 0, 1, 1], sparse[0, 0, 1, 0] = 9.0, 4.0, 0.0  # block (0, 0): 9 and 4 -> 4
    sparse[0, 0, 2, 4] = 7.0  # the padded corner block: its only point
    rgb = torch.arange(15.0).view(1, 1, 3, 5).expand(1, 3, 3, 5).clone()
    semantic = torch.arange(15.0).view(1, 1, 3, 5).expand(1, 3, 3, 5).clone()
    colour, small, labels = work_resolution(rgb, sparse, semantic, 2)
    assert small.shape == (1, 1, 2, 3)
    assert small[0, 0].tolist() == [[4.0, 0.0, 0.0], [0.0, 0.0, 7.0]]
    assert colour[0, 0, 0, 0].item() == (0 + 1 + 5 + 6) / 4
    assert colour[0, 0, 1, 2].item() == (14 + 14 + 14 + 14) / 4  # rows and columns replicated at the edges
    assert labels is not None and labels[0, 0].tolist() == [[0.0, 2.0, 4.0], [10.0, 12.0, 14.0]]


def test_a_half_resolution_generalist_corrects_the_full_resolution_anchor_by_its_upsampled_log_ratio() -> None:
    """work_scale 2, written out step by step: scale, outliers, anchor and distances at full resolution; the
    network on each block's nearest point, mean colour, one class and the anchor's block mean; its log ratio to
    that half-resolution anchor upsampled bilinearly and bounded onto the full-resolution anchor."""
    import torch.nn.functional as F

    from semattnet.models.anchor import complete_classical
    from semattnet.models.generalist import consistent_points
    from semattnet.models.uncertainty import lidar_distance

    torch.manual_seed(0)
    half = build_model("semattnet_rt_half_generalist").eval()
    rgb, semantic, sparse = _frame(h=128, w=192)
    with torch.no_grad():
        out = half(rgb, semantic, sparse)
        s = frame_scale(sparse) / REFERENCE_DEPTH
        points = consistent_points(sparse / s, complete_classical(sparse / s))
        anchor = complete_classical(points)
        far = torch.where(points > 0, points, torch.full_like(points, 1e9))
        nearest = -F.max_pool2d(-far, 2)
        small = torch.cat((torch.where(nearest < 1e8, nearest, 0.0), F.avg_pool2d(anchor, 2)), dim=1)
        colour = standardise_colour(F.avg_pool2d(rgb, 2))
        net = half.net(colour, semantic[..., ::2, ::2], small).depth
    ratio = torch.log((net * s).clamp_min(1e-3)) - torch.log((small[:, 1:] * s).clamp_min(1e-3))
    ratio = F.interpolate(ratio, scale_factor=2, mode="bilinear", align_corners=False)
    trust = 1 - torch.exp(-lidar_distance(points) / half.config.trust_radius)
    expected = anchor * s * torch.exp(trust * torch.tanh(ratio))  # residual_bound 1
    assert out.depth.shape == (1, 1, 128, 192) and out.uncertainty is not None
    assert out.uncertainty.shape == (1, 1, 128, 192)
    torch.testing.assert_close(out.depth, expected, rtol=1e-5, atol=1e-5)
    measured = points > 0  # no trust in the network there: the output is the anchor
    torch.testing.assert_close(out.depth[measured], (anchor * s)[measured], rtol=1e-5, atol=1e-5)


def test_the_completer_gives_a_half_resolution_generalists_depth_at_the_frames_odd_size() -> None:
    model = build_model("semattnet_rt_half_generalist").eval()
    rgb, semantic, sparse = _frame(h=75, w=101)
    c = semattnet.DepthCompleter(model, EngineSpec(device="cpu"))(
        rgb[0].permute(1, 2, 0).numpy(), sparse[0, 0].numpy(), semantic[0].permute(1, 2, 0).numpy().astype(np.uint8)
    )
    assert c.depth.shape == (75, 101) and c.uncertainty is not None and c.uncertainty.shape == (75, 101)
    assert np.isfinite(c.depth).all() and (c.depth > 0).all()


def test_a_plain_model_cannot_work_at_a_lower_resolution_and_the_crop_follows_the_work_scale() -> None:
    from semattnet.training.generalist import GeneralistTrainConfig

    with pytest.raises(InputError, match="work_scale"):
        model_config("semattnet_rt_md").replace(work_scale=2)
    with pytest.raises(InputError, match="work_scale"):
        model_config("semattnet_rt_generalist").replace(work_scale=3)
    with pytest.raises(InputError, match="multiples of 64"):
        GeneralistTrainConfig(model="semattnet_rt_half_generalist", crop=(160, 256))
    assert GeneralistTrainConfig(model="semattnet_rt_half_generalist", crop=(192, 256)).crop == (192, 256)
