"""Inference speed-ups must not change the numbers: fused propagation, BN folding, export path."""

from __future__ import annotations

import pytest
import torch

from semattnet import build_model
from semattnet.models.bn_folding import fold_batchnorm
from semattnet.models.propagation import cpu_kernel as fused_propagation
from semattnet.models.propagation import cspn_affinity, propagate_shifted, shift_affinity
from semattnet.models.propagation.export import propagate_functional, shift_functional

needs_kernel = pytest.mark.skipif(not fused_propagation.available(), reason="no C++ toolchain for the fused kernel")


def _inputs(k: int, channels: int, h: int = 13, w: int = 17, seed: int = 0):  # type: ignore[no-untyped-def]
    g = torch.Generator().manual_seed(seed)
    aff = cspn_affinity(torch.randn(2, k * k - 1, h, w, generator=g))
    start = torch.rand(2, channels, h, w, generator=g) * 50
    h0 = torch.rand(2, channels, h, w, generator=g) * 50
    mask = torch.rand(2, 1, h, w, generator=g) * (torch.rand(2, 1, h, w, generator=g) < 0.2)
    sparse = torch.rand(2, 1, h, w, generator=g) * 60
    return aff, start, h0, mask, sparse


@needs_kernel
@pytest.mark.parametrize(("k", "dilation", "channels"), [(3, 1, 1), (5, 1, 4), (7, 2, 1), (7, 1, 4)])
def test_fused_kernel_matches_pytorch_steps(k: int, dilation: int, channels: int) -> None:
    aff, start, h0, mask, sparse = _inputs(k, channels)
    shifted = shift_affinity(aff, dilation)
    h = start
    for _ in range(6):
        h = propagate_shifted(shifted, h, h0, dilation)
        h = mask * sparse + (1 - mask) * h
    fused = fused_propagation.propagate_iterations(aff, start, h0, mask, sparse, 6, dilation)
    assert torch.allclose(fused, h, rtol=1e-5, atol=1e-4), float((fused - h).abs().max())


@needs_kernel
@pytest.mark.parametrize(
    ("k", "dilation", "channels", "h"), [(7, 1, 1, 37), (5, 2, 4, 23), (3, 1, 2, 5), (7, 2, 1, 61)]
)
def test_wavefront_equals_one_step_after_another_to_the_bit(k: int, dilation: int, channels: int, h: int) -> None:
    """The kernel runs all steps band by band (rows go through every step while in cache); each row's
    arithmetic must be that of whole steps run one after another, so the results are identical."""
    aff, start, h0, mask, sparse = _inputs(k, channels, h=h, w=29, seed=h)
    for iterations in (1, 2, 6):
        stepped = start
        for _ in range(iterations):
            stepped = fused_propagation.propagate_iterations(aff, stepped, h0, mask, sparse, 1, dilation)
        banded = fused_propagation.propagate_iterations(aff, start, h0, mask, sparse, iterations, dilation)
        assert torch.equal(banded, stepped), (iterations, float((banded - stepped).abs().max()))
    assert torch.equal(fused_propagation.propagate_iterations(aff, start, h0, mask, sparse, 0, dilation), start)


@needs_kernel
@pytest.mark.parametrize("k", [3, 5, 7])
def test_fused_normalisation_matches_eq13(k: int) -> None:
    """normalize_affinity: cspn_affinity in one pass, also on a channel slice of stacked heads (B = 1 and 2)."""
    g = torch.Generator().manual_seed(k)
    stacked = torch.randn(2, 4 + k * k - 1, 7, 9, generator=g)
    guide = stacked[:, 4:]  # as RefinementHeads.finish reads it: a view, not a copy
    want = cspn_affinity(guide)
    for b in (slice(0, 1), slice(0, 2)):
        got = fused_propagation.normalize_affinity(guide[b])
        assert got.shape == want[b].shape
        torch.testing.assert_close(got, want[b], rtol=1e-6, atol=1e-6)
    with pytest.raises(ValueError, match="out must be a contiguous float32"):
        fused_propagation.normalize_affinity(guide, torch.empty(2, k * k, 7, 9))  # the planar shape, not rows
    # by hand at one pixel: the centre is 1 - the sum of the normalised neighbours
    one = fused_propagation.normalize_affinity(guide[:1, :, 3:4, 5:6].contiguous())[0, :, 0, 0]
    raw = guide[0, :, 3, 5]
    w = raw / raw.abs().sum()
    half = (k * k - 1) // 2
    torch.testing.assert_close(one, torch.cat((w[:half], (1 - w.sum()).view(1), w[half:])))


@pytest.mark.parametrize(("k", "dilation"), [(3, 1), (5, 2), (7, 1)])
def test_naive_reference_matches(k: int, dilation: int) -> None:
    from semattnet.models.propagation import propagate, propagate_pad_and_sum

    aff, start, h0, _, _ = _inputs(k, 2)
    assert torch.allclose(
        propagate_pad_and_sum(aff, start, h0, dilation), propagate(aff, start, h0, dilation), rtol=1e-5, atol=1e-4
    )


@pytest.mark.parametrize(("k", "dilation"), [(3, 1), (5, 2), (7, 1)])
def test_export_friendly_path_matches(k: int, dilation: int) -> None:
    aff, start, h0, _, _ = _inputs(k, 3)
    a = propagate_shifted(shift_affinity(aff, dilation), start, h0, dilation)
    b = propagate_functional(shift_functional(aff, dilation), start, h0, dilation)
    assert torch.allclose(a, b, rtol=1e-5, atol=1e-4)


def _randomised_bn(model: torch.nn.Module) -> torch.nn.Module:
    g = torch.Generator().manual_seed(3)
    for m in model.modules():
        if isinstance(m, torch.nn.BatchNorm2d):
            m.running_mean.copy_(torch.randn(m.num_features, generator=g) * 0.1)
            m.running_var.copy_(torch.rand(m.num_features, generator=g) + 0.5)
            m.weight.data.copy_(torch.rand(m.num_features, generator=g) + 0.5)
            m.bias.data.copy_(torch.randn(m.num_features, generator=g) * 0.1)
    return model.eval()


def _frame(h: int = 64, w: int = 96) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(1)
    sparse = torch.rand(1, 1, h, w, generator=g) * 60 * (torch.rand(1, 1, h, w, generator=g) < 0.1)
    return {
        "rgb": torch.rand(1, 3, h, w, generator=g) * 255,
        "semantic": torch.rand(1, 3, h, w, generator=g) * 255,
        "sparse": sparse,
    }


def test_fold_batchnorm_keeps_outputs() -> None:
    model = _randomised_bn(build_model("semattnet", width=0.125))
    folded = fold_batchnorm(model)
    assert not any(isinstance(m, torch.nn.BatchNorm2d) for m in folded.modules())
    assert folded.folded_batchnorms == sum(isinstance(m, torch.nn.BatchNorm2d) for m in model.modules())
    assert any(isinstance(m, torch.nn.BatchNorm2d) for m in model.modules())  # the original is untouched
    x = _frame()
    with torch.inference_mode():
        a, b = model(**x), folded(**x)
    for name, ref in a.to_dict().items():
        got = b.to_dict()[name]
        assert torch.allclose(got, ref, rtol=1e-4, atol=1e-4 * float(ref.abs().max())), name


@needs_kernel
def test_model_with_fused_kernel_matches_autograd_path() -> None:
    model = _randomised_bn(build_model("semattnet", width=0.125))
    x = _frame()
    with torch.inference_mode():
        fast = model(**x).refined_depth  # fused kernel
    with torch.enable_grad():
        x_req = {k: v.clone().requires_grad_(k == "sparse") for k, v in x.items()}
        slow = model(**x_req).refined_depth.detach()  # autograd path (grad needed)
    assert torch.allclose(fast, slow, rtol=1e-5, atol=1e-4)


@pytest.mark.slow  # ~15 s; tests/inference/test_backends.py checks the ONNX engines by default
def test_onnx_export_parity(tmp_path) -> None:  # type: ignore[no-untyped-def]
    ort = pytest.importorskip("onnxruntime")
    # Two propagation steps per kernel instead of six keep the graph (and the test) small.
    model = _randomised_bn(build_model("semattnet", width=0.125, iterations=2))
    x = _frame()
    path = tmp_path / "semattnet.onnx"
    from semattnet.weights.export import export_onnx

    export_onnx(model, path, size=(64, 96))
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    feeds = {i.name: x[i.name].numpy() for i in session.get_inputs()}
    outputs = dict(zip([o.name for o in session.get_outputs()], session.run(None, feeds), strict=True))
    with torch.inference_mode():
        ref = model(**x)
    for name in ("refined_depth", "fused_depth", "color_conf"):
        r = getattr(ref, name)
        got = torch.from_numpy(outputs[name])
        rel = float((got - r).abs().max() / r.abs().max())
        assert rel <= 1e-4, (name, rel)


@pytest.mark.slow
def test_torchscript_export_runs(tmp_path) -> None:  # type: ignore[no-untyped-def]
    from semattnet.weights.export import export_torchscript, output_names

    model = _randomised_bn(build_model("semattnet", width=0.125))
    path = export_torchscript(model, tmp_path / "m.pt", size=(64, 96))
    loaded = torch.jit.load(str(path))
    x = _frame()
    outs = loaded(x["rgb"], x["semantic"], x["sparse"])
    names = output_names(model)
    assert "refined_depth" in names and "fused_depth" in names
    with torch.inference_mode():
        ref = model(**x).to_dict()
    for name, got in zip(names, outs, strict=True):
        assert torch.allclose(got, ref[name], rtol=1e-4, atol=1e-4 * float(ref[name].abs().max())), name


@pytest.mark.slow
def test_bench_smoke(tmp_path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """Every part of `semattnet bench` runs and reports ratios and matching outputs (tiny model)."""
    from semattnet.apps.benchmark import run_benchmark
    from semattnet.inference.backends import available_backends

    monkeypatch.setenv("SEMATTNET_CACHE", str(tmp_path))  # exported engines go here, not to the user's cache

    lines: list[str] = []
    res = run_benchmark((64, 96), "cpu", repeats=1, width=0.125, train_size=(64, 96), log=lines.append)
    whats = [r["what"] for r in res.rows]
    assert any(w.startswith("propagation, ours") for w in whats)
    from semattnet.apps.benchmark import fast_mode_dtype

    if fast_mode_dtype(torch.device("cpu")) is not None:
        assert any(w.startswith("full model, fast") for w in whats)
    else:  # no native bf16 here: skipped with a note, never run through the slow emulation
        assert any("fast mode skipped" in n for n in res.notes)
    assert len([w for w in whats if w.startswith("training step")]) == 3
    assert {f"full model, backend {b} (f32)" for b in available_backends()} <= set(whats)
    assert "CPU: " in "\n".join(lines)
    for r in res.rows:
        assert r["seconds"] > 0
        if r["max_rel_diff"] is None or "fast" in r["what"] or "bf16" in r["what"]:
            continue
        if "int8" in r["what"]:  # quantised, on random weights: bounded, not exact (bench_int8_accuracy: metrics)
            assert r["max_rel_diff"] < 0.5, r
        else:
            assert r["max_rel_diff"] < 1e-4, r
    assert any("GMACs" in n for n in res.notes) and "x naive" in "\n".join(lines)
