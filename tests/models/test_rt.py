"""SemAttNet-RT: the paper's structure on light encoders (shapes, typed outputs, gradients, bad input)."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

import semattnet
from semattnet._errors import InputError
from semattnet.models import registry
from semattnet.models.bn_folding import fold_batchnorm
from semattnet.models.encoders import UnknownEncoderError
from semattnet.models.outputs import DepthCompletionOutput
from semattnet.models.registry import arch_for, model_class
from semattnet.models.rt import SemAttNetRT, SemAttNetRTBackbone
from tests._base import BaseTester

RT_MODELS = ("semattnet_rt_s", "semattnet_rt_m", "semattnet_rt_md", "semattnet_rt_l")


def _frame(b: int = 1, h: int = 32, w: int = 64, seed: int = 0) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    sparse = (torch.rand(b, 1, h, w, generator=g) < 0.2) * (1 + 79 * torch.rand(b, 1, h, w, generator=g))
    return {
        "rgb": 255 * torch.rand(b, 3, h, w, generator=g),
        "semantic": 255 * torch.rand(b, 3, h, w, generator=g),
        "sparse": sparse,
    }


def _tiny(name: str, **overrides: object) -> torch.nn.Module:
    torch.manual_seed(0)
    return semattnet.build_model(name, width=0.5, **overrides)


class TestSemAttNetRT(BaseTester):
    @pytest.mark.parametrize("name", RT_MODELS)
    def test_smoke(self, name: str) -> None:
        model = _tiny(name).eval()
        assert isinstance(model, SemAttNetRT) and isinstance(model.backbone, SemAttNetRTBackbone)
        with torch.no_grad():
            out = model(**_frame())
        assert isinstance(out, DepthCompletionOutput)
        maps = out.to_dict()
        assert set(maps) == {
            "color_depth",
            "semantic_depth",
            "guided_depth",
            "color_conf",
            "semantic_conf",
            "guided_conf",
            "fused_depth",
            "refined_s2_depth",
            "refined_depth",
        }
        assert all(t.shape == (1, 1, 32, 64) and torch.isfinite(t).all() for t in maps.values())

    @pytest.mark.parametrize(("b", "h", "w", "branches"), [(1, 64, 32, 3), (2, 32, 64, 2)])
    def test_cardinality(self, b: int, h: int, w: int, branches: int) -> None:
        model = _tiny("semattnet_rt_s", branches=branches).eval()
        x = _frame(b, h, w)
        if branches == 2:
            x["semantic"] = None  # type: ignore[assignment]
        with torch.no_grad():
            out = model(**x)
        assert out.refined_depth is not None and out.refined_depth.shape == (b, 1, h, w)
        assert (out.semantic_depth is None) == (branches == 2)
        backbone = semattnet.build_model("semattnet_rt_s", refine=False, branches=branches, width=0.5).eval()
        assert isinstance(backbone, SemAttNetRTBackbone) and backbone(**x).fused_depth.shape == (b, 1, h, w)

    def test_exception(self) -> None:
        model = _tiny("semattnet_rt_s")
        x = _frame()
        with pytest.raises(InputError, match="sparse depth is required"):
            model(x["rgb"], x["semantic"])
        with pytest.raises(InputError, match="semantic is required"):
            model(x["rgb"], None, x["sparse"])
        with pytest.raises(InputError, match="multiple"):
            model(**_frame(h=40))
        with pytest.raises(UnknownEncoderError, match="unknown encoder 'mobilenet'"):
            semattnet.build_model("semattnet_rt_s", encoder="mobilenet")
        with pytest.raises(InputError, match="needs a light encoder"):
            SemAttNetRTBackbone(semattnet.SemAttNetConfig(refine=False))
        with pytest.raises(InputError, match="refined model"):
            SemAttNetRT(semattnet.SemAttNetConfig(encoder="lite_s4", refine=False))

    @pytest.mark.parametrize("name", RT_MODELS)
    def test_numerics(self, name: str) -> None:
        """Fusion weights sum to 1; BN folding and the compiled CPU propagation change nothing but rounding."""
        model = _tiny(name).eval()
        x = _frame(seed=1)
        with torch.inference_mode():
            out = model(**x)
            folded = fold_batchnorm(model)(**x)
            model.propagation_impl = "pytorch"
            plain = model(**x)
        total = out.color_conf + out.semantic_conf + out.guided_conf  # type: ignore[operator]
        self.assert_close(total, torch.ones_like(total))
        self.assert_close(folded.depth, out.depth, rtol=1e-4, atol=1e-3)
        self.assert_close(plain.depth, out.depth, rtol=1e-4, atol=1e-3)
        torch.testing.assert_close(model.backbone(**x).fused_depth, out.fused_depth)

    def test_gradcheck(self) -> None:
        """Gradients reach the image and every parameter but the authors-mode hand-over (``att_12``,
        ``dimhalf_s2``: unused in that mode by design); a float64 gradcheck of a whole network is too slow here."""
        model = _tiny("semattnet_rt_s").train()
        model.backbone.init_depth_heads()
        x = _frame(b=2)
        x["rgb"].requires_grad_(True)
        model(**x).refined_depth.mean().backward()
        assert x["rgb"].grad is not None and x["rgb"].grad.abs().sum() > 0
        dead = [n for n, p in model.named_parameters() if p.grad is None]
        assert dead and all(n.startswith(("att_12.", "dimhalf_s2.")) for n in dead), dead


def test_registry_rows_and_paper_names() -> None:
    cfg = registry.model_config("semattnet_rt_s")
    assert model_class(cfg) is SemAttNetRT and arch_for(cfg.replace(width=2.0)) == "semattnet_rt_s"
    assert model_class(cfg.replace(refine=False)) is SemAttNetRTBackbone
    keys = _tiny("semattnet_rt_s").state_dict()
    assert any(k.startswith("backbone.rgb_branch.encoder.") for k in keys) and "mask_layer.0.weight" in keys
    plain = [s.name for s in registry._SPECS if s.config.realtime and s.config.anchor == "none"]
    assert plain == list(RT_MODELS)  # the generalist is not a frontier row


@pytest.mark.slow  # a forward of each real-time model at 352x1216: seconds
def test_models_listing_counts_macs_of_the_real_time_rows() -> None:
    rows = [spec for spec in registry._SPECS if spec.config.realtime]  # the paper's rows take seconds to build
    assert all(registry._params_and_macs(s).endswith("GMAC") for s in rows)


@pytest.mark.parametrize(
    ("backend", "name"),
    [
        pytest.param("openvino", "semattnet_rt_s", marks=pytest.mark.slow),
        ("onnxruntime", "semattnet_rt_s"),
        pytest.param("onnxruntime", "semattnet_rt_md", marks=pytest.mark.slow),  # ~6 s; rt_s covers the export
    ],
)
def test_exports_through_the_engines(backend: str, name: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The whole forward (network and propagation, eq. 13 in rt_s, the convex kernel in rt_md) exports through the
    engines' path and matches eager."""
    pytest.importorskip(backend)
    monkeypatch.setenv("SEMATTNET_CACHE", str(tmp_path))
    from semattnet.inference.backends import optimize_for_inference

    model = _tiny(name).eval()
    x = _frame(h=32, w=64)
    engine = optimize_for_inference(model, backend=backend, size=(32, 64))
    with torch.inference_mode():
        torch.testing.assert_close(engine(**x).depth, model(**x).depth, rtol=1e-4, atol=1e-3)


class TestConvexUpsample:
    """:func:`semattnet.models.rt.convex_upsample` against independent references (pooling, nearest)."""

    def test_zero_logits_give_every_sub_pixel_the_3x3_mean(self) -> None:
        import torch.nn.functional as F

        from semattnet.models.rt import convex_upsample

        x = torch.rand(2, 3, 5, 7)
        mean = F.avg_pool2d(F.pad(x, (1, 1, 1, 1), mode="replicate"), 3, stride=1)
        up = convex_upsample(x, torch.zeros(2, 9 * 16, 5, 7), 4)
        torch.testing.assert_close(up, F.interpolate(mean, scale_factor=4, mode="nearest"))

    @pytest.mark.parametrize(("neighbour", "shift"), [(4, (0, 0)), (5, (0, -1)), (1, (1, 0))])
    def test_a_one_hot_weight_picks_that_neighbour(self, neighbour: int, shift: tuple[int, int]) -> None:
        import torch.nn.functional as F

        from semattnet.models.rt import convex_upsample

        x = torch.arange(35.0).view(1, 1, 5, 7)
        logits = torch.full((1, 9, 4, 5, 7), -50.0)
        logits[:, neighbour] = 50.0
        up = convex_upsample(x, logits.view(1, 36, 5, 7), 2)
        padded = F.pad(x, (1, 1, 1, 1), mode="replicate")
        di, dj = 1 - shift[0], 1 - shift[1]  # neighbour (i, j) of pixel (y, x) is padded[y + i, x + j]
        picked = padded[..., di : di + 5, dj : dj + 7]
        torch.testing.assert_close(up, F.interpolate(picked, scale_factor=2, mode="nearest"))

    def test_sub_pixels_get_their_own_weights_and_gradients_flow(self) -> None:
        from semattnet.models.rt import convex_upsample

        x = torch.rand(1, 1, 3, 3, requires_grad=True)
        logits = torch.zeros(1, 9, 2, 2, 3, 3, requires_grad=True)
        with torch.no_grad():
            logits[:, 0, 0, 0] = 50.0  # the top-left sub-pixel takes the top-left neighbour
        up = convex_upsample(x, logits.view(1, 36, 3, 3), 2)
        assert abs(up[0, 0, 2, 2].item() - x[0, 0, 0, 0].item()) < 1e-5  # pixel (1, 1)'s top-left sub-pixel
        up.sum().backward()
        assert x.grad is not None and logits.grad is not None and torch.isfinite(logits.grad).all()

    def test_random_weights_against_a_per_pixel_loop(self) -> None:
        """Every output pixel of a 2-channel map, with random logits, against the definition written as loops."""
        import torch.nn.functional as F

        from semattnet.models.rt import convex_upsample

        torch.manual_seed(0)
        s, h, w = 3, 4, 5
        x, logits = torch.rand(1, 2, h, w), torch.randn(1, 9 * s * s, h, w)
        padded = F.pad(x, (1, 1, 1, 1), mode="replicate")
        weights = logits.view(9, s, s, h, w).softmax(dim=0)
        want = torch.zeros(1, 2, h * s, w * s)
        for y in range(h * s):
            for xx in range(w * s):
                (py, i), (px, j) = divmod(y, s), divmod(xx, s)
                for n in range(9):
                    want[0, :, y, xx] += weights[n, i, j, py, px] * padded[0, :, py + n // 3, px + n % 3]
        torch.testing.assert_close(convex_upsample(x, logits, s), want)
