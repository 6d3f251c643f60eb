"""Inference engines: parity of every backend with the eager model, the on-disk cache, bad input."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest
import torch

import semattnet
from semattnet.inference.backends import _export_cache, available_backends, choose_backend, optimize_for_inference
from tests._helpers import random_inputs

SIZE = (64, 96)


@pytest.fixture(scope="module")
def model() -> torch.nn.Module:
    torch.manual_seed(0)
    net = semattnet.build_model("semattnet", width=0.125, iterations=2).eval()
    with torch.no_grad():  # non-trivial BatchNorm statistics, so folding is really exercised
        for m in net.modules():
            if isinstance(m, torch.nn.BatchNorm2d):
                m.running_mean.uniform_(-0.1, 0.1)
                m.running_var.uniform_(0.5, 1.5)
    return net


def _rel(a: torch.Tensor, b: torch.Tensor) -> float:
    return float((a - b).abs().max() / b.abs().max())


@pytest.mark.skipif(importlib.util.find_spec("onnxruntime") is None, reason="onnxruntime is not installed")
def test_export_is_cached_by_weights_and_size(model: torch.nn.Module, tmp_path: Path, monkeypatch) -> None:
    optimize_for_inference(model, backend="onnxruntime", size=SIZE, cache_dir=tmp_path)
    assert len(list((tmp_path / "engines").glob("*/model.onnx"))) == 1
    calls = []
    monkeypatch.setattr(_export_cache, "export_onnx", lambda *a, **k: calls.append(a))
    optimize_for_inference(model, backend="onnxruntime", size=SIZE, cache_dir=tmp_path)  # a cache hit
    assert calls == []
    other = semattnet.build_model("semattnet", width=0.125, iterations=2).eval()  # other weights: new key
    assert _export_cache.engine_key(other, SIZE) != _export_cache.engine_key(model, SIZE)
    assert _export_cache.engine_key(model, (32, 32)) != _export_cache.engine_key(model, SIZE)


def test_bad_backend_precision_and_size(model: torch.nn.Module, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="unknown backend 'tpu'"):
        optimize_for_inference(model, backend="tpu")
    with pytest.raises(ValueError, match="unknown precision"):
        optimize_for_inference(model, backend="torch", precision="int4")
    with pytest.raises(ValueError, match="compiles for one input size"):
        optimize_for_inference(model, backend="onnxruntime")
    if "onnxruntime" in available_backends():
        engine = optimize_for_inference(model, backend="onnxruntime", size=SIZE, cache_dir=tmp_path)
        with pytest.raises(ValueError, match="compiled for 64x96 inputs, got 32x32"):
            engine(**random_inputs(b=1, h=32, w=32))


def test_auto_choice() -> None:
    assert choose_backend("cpu", None) == "torch"  # no fixed size: only torch runs any size
    expected = "openvino" if "openvino" in available_backends() else "torch"
    assert choose_backend("cpu", SIZE) == expected
    assert choose_backend("cuda", SIZE) == "torch"


def test_torch_engine_leaves_the_model_unchanged(model: torch.nn.Module) -> None:
    before = {k: v.clone() for k, v in model.state_dict().items()}
    optimize_for_inference(model, backend="torch")
    after = model.state_dict()
    assert before.keys() == after.keys() and all(torch.equal(before[k], after[k]) for k in before)


@pytest.mark.skipif(importlib.util.find_spec("onnxruntime") is None, reason="onnxruntime is not installed")
@pytest.mark.parametrize("affinity", ["eq13", "convex"])
def test_engines_run_the_network_in_the_graph_and_the_propagation_in_torch(tmp_path: Path, affinity: str) -> None:
    """The cached graph ends at the refinement heads; the engine's propagation gives the eager result
    (also in the paper's "clean" hand-over mode, whose blend weights come out of the graph, and with the
    convex kernel, which the engine's propagation must apply as the model does)."""
    import onnx

    torch.manual_seed(1)
    net = semattnet.build_model(
        "semattnet", width=0.125, iterations=3, refinement_mode="clean", affinity=affinity
    ).eval()
    engine = optimize_for_inference(net, backend="onnxruntime", size=SIZE, cache_dir=tmp_path)
    outputs = [o.name for o in onnx.load(next((tmp_path / "engines").glob("*/model.onnx"))).graph.output]
    assert "refined_depth" not in outputs and "fused_depth" in outputs
    assert {"refinement.att", "refinement.heads", "refinement.heads_s2"} <= set(outputs)
    assert not any("affinities" in n or "mask" in n for n in outputs)  # no split, no normalisation in the graph
    x = random_inputs(b=1, h=SIZE[0], w=SIZE[1])
    with torch.inference_mode():
        ref = net(**x)
    out = engine(**x)
    for name in ("refined_s2_depth", "refined_depth"):
        assert _rel(out.to_dict()[name], ref.to_dict()[name]) < 1e-4, name


@pytest.mark.slow  # ~16 s (the unrolled propagation); the whole-model ONNX parity test exports it too (slow)
def test_whole_model_export_keeps_the_propagation(model: torch.nn.Module, tmp_path: Path) -> None:
    onnx = pytest.importorskip("onnx")
    from semattnet.weights.export import export_onnx

    path = export_onnx(model, tmp_path / "m.onnx", size=(32, 64))
    outputs = [o.name for o in onnx.load(path).graph.output]
    assert "refined_depth" in outputs and not any(n.startswith("refinement.") for n in outputs)


def test_refinement_heads_round_trip_and_need_the_propagation_settings(model: torch.nn.Module) -> None:
    from semattnet.inference.backends import output_from_arrays
    from semattnet.models.refinement import PropagationSettings, RefinementHeads

    x = random_inputs(b=1, h=32, w=64)
    with torch.inference_mode():
        out, heads = model.forward_network(**x)
        ref = model(**x)
    flat = heads.to_dict()
    assert sorted(flat) == ["refinement.depth", "refinement.heads", "refinement.heads_s2", "refinement.sparse"]
    assert flat["refinement.heads"].shape[1] == 3 + 1 + 8 + 24 + 48  # confidences, mask, guidance of 3, 5, 7
    back = RefinementHeads.from_dict(flat, (3, 5, 7))
    assert torch.equal(back.heads, heads.heads) and back.att is None and back.kernel_sizes == (3, 5, 7)
    got = output_from_arrays({**out.to_dict(), **flat}, PropagationSettings(2, (3, 5, 7)))
    assert _rel(got.refined_depth, ref.refined_depth) < 1e-5
    with pytest.raises(ValueError, match="propagation settings"):
        output_from_arrays({**out.to_dict(), **flat})
    with pytest.raises(ValueError, match="84 channels, expected 35"):  # kernel sizes that do not fit the heads
        output_from_arrays({**out.to_dict(), **flat}, PropagationSettings(2, (3, 5)))
    with pytest.raises(ValueError, match="missing refinement.heads_s2"):
        RefinementHeads.from_dict({k: v for k, v in flat.items() if k != "refinement.heads_s2"}, (3, 5, 7))


@pytest.mark.parametrize("backend", [b for b in ("openvino", "onnxruntime", "torch") if b in available_backends()])
def test_engines_reuse_their_affinity_buffers_and_results_stay_their_own(
    model: torch.nn.Module, backend: str, tmp_path: Path
) -> None:
    """Each frame's affinities go into the same buffers (no fresh 180 MB a frame at 352x1216), and what a
    call returned is not changed by the next call (nor are the runtime's output buffers kept)."""
    from semattnet.models.propagation import cpu_kernel

    engine = optimize_for_inference(model, backend=backend, size=SIZE, cache_dir=tmp_path)
    x1, x2 = random_inputs(b=1, h=SIZE[0], w=SIZE[1], seed=1), random_inputs(b=1, h=SIZE[0], w=SIZE[1], seed=2)
    with torch.inference_mode():
        want1 = model(**x1)
    out1 = engine(**x1)
    kept = {k: v.clone() for k, v in out1.to_dict().items()}
    workspace = engine.workspace if backend != "torch" else engine.refiner.propagation_workspace
    pointers = {k: v.data_ptr() for k, v in workspace.items()}
    out2 = engine(**x2)
    for name, value in out1.to_dict().items():
        assert torch.equal(value, kept[name]), name  # the second frame did not write into the first's output
    assert _rel(out1.refined_depth, want1.refined_depth) < 1e-4
    assert not torch.equal(out2.refined_depth, out1.refined_depth)
    if cpu_kernel.available():
        assert sorted(pointers) == ["s1.0", "s1.1", "s1.2", "s2.0", "s2.1", "s2.2"]
        assert {k: v.data_ptr() for k, v in workspace.items()} == pointers
