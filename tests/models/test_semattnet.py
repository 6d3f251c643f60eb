"""Model variants: shapes, outputs, gradients, options and input validation."""

from __future__ import annotations

import pytest
import torch

import semattnet
from semattnet import SemAttNetConfig, build_model
from semattnet.models.outputs import DepthCompletionOutput
from tests._helpers import random_inputs

SMALL = 0.125


def test_fused_depth_is_eq12() -> None:
    model = build_model("semattnet_backbone", width=SMALL).eval()
    with torch.inference_mode():
        out = model(**random_inputs())
    blend = (
        out.color_conf * out.color_depth + out.semantic_conf * out.semantic_depth + out.guided_conf * out.guided_depth
    )
    assert torch.allclose(out.fused_depth, blend, rtol=1e-5, atol=1e-5)


def test_ablation_widths_differ() -> None:
    counts = {
        n: sum(p.numel() for p in build_model(n, width=0.25).parameters())
        for n in ("table2_a", "table2_b", "table2_d", "table2_f")
    }
    assert counts["table2_a"] < counts["table2_b"] < counts["table2_d"] < counts["table2_f"]
    assert not any(k.startswith("cbam") for k in build_model("table2_d", width=0.25).state_dict())


def test_width_multiplier_scales_channels() -> None:
    model = build_model("semattnet", width=0.25)
    assert model.backbone.rgb_conv_init[0].out_channels == 8
    assert model.backbone.cbam_1984.ChannelGate.mlp[1].in_features == 1984 // 4
    with torch.device("meta"):  # the full width's names only: no 360 M parameters to initialise
        full = build_model("semattnet")
    assert model.state_dict().keys() == full.state_dict().keys()


def _grads(model: torch.nn.Module) -> dict[str, torch.Tensor | None]:
    model.train()
    x = random_inputs(b=2, h=64, w=64, density=0.1)
    gt = torch.rand(2, 1, 64, 64) * 60 * (torch.rand(2, 1, 64, 64) < 0.3)
    out = model(**x)
    loss = sum(((t - gt) ** 2 * (gt > 0)).mean() for t in out.to_dict().values())
    loss.backward()
    return {n: p.grad for n, p in model.named_parameters()}


def test_gradients_reach_every_learnable_parameter() -> None:
    """Authors' mode: everything learns except dimhalf_s2 and att_12, which the aliasing bypasses."""
    # reduction=2: at this tiny width the default r=16 leaves SAMMAFB MLPs a single hidden unit,
    # which a random init can leave dead (ReLU) for a given input.
    grads = _grads(build_model("semattnet", width=SMALL, reduction=2))
    unused = {n for n, g in grads.items() if g is None}
    assert unused == {n for n in grads if n.startswith(("dimhalf_s2.", "att_12."))}
    assert len(unused) == 6  # conv weights + BN weight/bias of both
    assert all(torch.any(g != 0) for n, g in grads.items() if n not in unused), "a parameter got a zero gradient"


def test_clean_mode_trains_att_12() -> None:
    grads = _grads(build_model("semattnet", width=SMALL, reduction=2, refinement_mode="clean"))
    dead = {n for n, g in grads.items() if g is None or not torch.any(g != 0)}
    assert not dead


def test_clean_mode_differs_from_authors_mode() -> None:
    authors = build_model("semattnet", width=SMALL).eval()
    clean = build_model("semattnet", width=SMALL, refinement_mode="clean").eval()
    clean.load_state_dict(authors.state_dict())
    x = random_inputs()
    with torch.inference_mode():
        a, c = authors(**x), clean(**x)
    assert torch.equal(a.fused_depth, c.fused_depth)
    assert torch.equal(a.refined_s2_depth, c.refined_s2_depth)
    assert not torch.allclose(a.refined_depth, c.refined_depth)


def test_refinement_keeps_measurements() -> None:
    """With a saturated mask the refined depth equals the LiDAR input where it is measured."""
    model = build_model("semattnet", width=SMALL).eval()
    with torch.no_grad():
        model.mask_layer[1].bias.fill_(50.0)  # sigmoid -> 1
    x = random_inputs()
    with torch.inference_mode():
        out = model(**x)
    valid = x["sparse"] > 0
    assert torch.allclose(out.refined_depth[valid], x["sparse"][valid])


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda x: x.update(rgb=x["rgb"][0]), "rgb must be \\(B, 3, H, W\\)"),
        (lambda x: x.update(rgb=x["rgb"][:, :2]), "rgb must have 3 channel"),
        (lambda x: x.update(semantic=x["semantic"][:, :1]), "semantic must have 3 channel"),
        (lambda x: x.update(sparse=x["sparse"][:, :, :32]), "sparse has shape .* but rgb has"),
        (lambda x: x.update(sparse=x["sparse"][:1]), "batch and size must match"),
        (
            lambda x: x.update(rgb=x["rgb"][..., :40], semantic=x["semantic"][..., :40], sparse=x["sparse"][..., :40]),
            "not a positive multiple of 32",
        ),
        (lambda x: x["rgb"].__setitem__((0, 0, 0, 0), float("nan")), "rgb contains NaN"),
        (lambda x: x["sparse"].__setitem__((0, 0, 0, 0), float("inf")), "sparse contains NaN or infinite"),
        (lambda x: x["sparse"].__setitem__((0, 0, 0, 0), -1.0), "negative"),
        (lambda x: x.update(sparse=x["sparse"].long()), "floating-point"),
        (lambda x: x.update(semantic=None), "semantic is required"),
    ],
)
def test_bad_inputs_are_refused(change, message: str) -> None:
    model = build_model("semattnet_backbone", width=SMALL).eval()
    x = random_inputs(b=2, h=64, w=64)
    change(x)
    with pytest.raises(ValueError, match=message):
        model(**x)


@pytest.mark.parametrize("name", ["semattnet_backbone", "semattnet"])
def test_sparse_is_required(name: str) -> None:
    x = random_inputs(h=64, w=64)
    with pytest.raises(semattnet.InputError, match="^sparse depth is required$"):
        build_model(name, width=SMALL)(rgb=x["rgb"], semantic=x["semantic"])


def test_branch_outputs_assemble_by_count() -> None:
    d = [torch.full((1, 1, 2, 2), float(i)) for i in range(3)]
    w = [torch.rand(1, 1, 2, 2) for _ in range(3)]
    fused = torch.ones(1, 1, 2, 2)
    three = DepthCompletionOutput.from_branches(d, w, fused)
    got = (three.color_depth, three.semantic_depth, three.guided_depth, three.color_conf, three.semantic_conf)
    assert all(a is b for a, b in zip(got, (*d, w[0], w[1]), strict=True))
    assert three.guided_conf is w[2] and three.fused_depth is fused and three.refined_depth is None
    two = DepthCompletionOutput.from_branches(d[::2], w[::2], fused)
    got = (two.color_depth, two.guided_depth, two.color_conf, two.guided_conf, two.fused_depth)
    assert all(a is b for a, b in zip(got, (d[0], d[2], w[0], w[2], fused), strict=True))
    assert two.semantic_depth is None and two.semantic_conf is None
    with pytest.raises(semattnet.InputError, match="2 or 3 depths and one weight each, got 3 and 2"):
        DepthCompletionOutput.from_branches(d, w[:2], fused)


def test_two_branch_model_needs_no_semantics() -> None:
    model = build_model("table2_c", width=SMALL).eval()
    x = random_inputs(h=64, w=64)
    with torch.inference_mode():
        out = model(rgb=x["rgb"], sparse=x["sparse"])
    assert out.refined_depth.shape == (2, 1, 64, 64)


def test_pad_and_crop_round_trip() -> None:
    x = torch.rand(1, 3, 375, 1242)
    padded, pad = semattnet.pad_to_multiple(x)
    assert padded.shape == (1, 3, 384, 1248) and pad == (9, 0, 3, 3)
    assert torch.equal(semattnet.crop_padding(padded, pad), x)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"branches": 4}, "branches"),
        ({"fusion": "mul"}, "fusion"),
        ({"width": 0.05}, "width"),
        ({"kernel_sizes": (3, 4)}, "odd"),
        ({"refinement_mode": "paper"}, "refinement_mode"),
    ],
)
def test_bad_config_is_refused(kwargs: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        SemAttNetConfig(**kwargs)


def test_unknown_model_or_field() -> None:
    with pytest.raises(ValueError, match="unknown model 'penet'"):
        build_model("penet")
    with pytest.raises(ValueError, match="unknown config field"):
        build_model("semattnet", depth=3)


def test_empty_sparse_map_is_fine() -> None:
    """A frame without any LiDAR point (legal in the data) must not produce NaNs anywhere."""
    model = build_model("semattnet", width=SMALL).eval()
    x = random_inputs(b=1, h=64, w=64)
    x["sparse"] = torch.zeros_like(x["sparse"])
    with torch.inference_mode():
        out = model(**x)
    assert all(torch.isfinite(t).all() for t in out.to_dict().values())
