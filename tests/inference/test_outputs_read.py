"""Only what the outputs read is computed: the sinks say what they read, the frame loop tells the completer, the
uncertainty is left out when no sink reads it, and OpenVINO compiles only the part of the graph that is read."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
import torch

import semattnet
from semattnet._errors import InputError
from semattnet.data.frames import Frame, IndexedSource
from semattnet.inference import completer as completer_module
from semattnet.inference.backends import EngineSpec
from semattnet.inference.backends._base import graph_outputs
from semattnet.inference.completer import Completion, DepthCompleter
from semattnet.inference.options import OutputSpec
from semattnet.inference.pipeline import check_frames
from semattnet.inference.sinks import (
    LatencySink,
    OutputSettings,
    PanelOptions,
    PlySink,
    default_sinks,
    outputs_read,
)
from semattnet.inference.uncertainty import UncertaintyLimit
from semattnet.models.outputs import DepthCompletionOutput
from semattnet.models.uncertainty import UNCERTAINTY_READS, outputs_to_compute
from semattnet.robotics.sinks import BagSink

pytestmark = pytest.mark.filterwarnings("ignore:.*hole:UserWarning")  # an untrained model's holes

SIZE = (20, 28)
HEADS = ["refinement.depth", "refinement.sparse", "refinement.heads_s2", "refinement.heads"]
BRANCHES = ["color_depth", "semantic_depth", "guided_depth", "color_conf", "semantic_conf", "guided_conf"]


class Frames(IndexedSource):
    """Two tiny frames with a few LiDAR points each."""

    names = ("f0", "f1")

    def load(self, name: str) -> Frame:
        sparse = np.zeros(SIZE, np.float32)
        sparse[::3, ::4] = 6.0
        return Frame(name, np.full((*SIZE, 3), 90, np.uint8), sparse)

    def inputs(self) -> list[Path]:
        return []


def test_each_sink_reads_what_it_writes() -> None:
    assert outputs_read(default_sinks()) == {"refined_depth"}  # the depth and colour PNGs
    assert outputs_read([*default_sinks(OutputSettings(npy=True)), LatencySink()]) == {"refined_depth"}
    assert outputs_read(default_sinks(OutputSettings(uncertainty=True))) == {"refined_depth", "uncertainty"}
    assert outputs_read(default_sinks(None, PanelOptions(panel=True))) is None  # the panel draws every branch
    confidences = {"color_conf", "semantic_conf", "guided_conf"}
    assert outputs_read([PlySink()]) == {"refined_depth", *confidences}
    assert outputs_read([PlySink(max_uncertainty=UncertaintyLimit(1.0))]) == {
        "refined_depth",
        "uncertainty",
        *confidences,
    }
    assert outputs_read([BagSink(max_uncertainty=UncertaintyLimit(1.0))]) == {"refined_depth", "uncertainty"}


def test_the_uncertainty_asks_for_what_it_reads() -> None:
    assert outputs_to_compute(None) is None
    assert outputs_to_compute({"refined_depth"}) == {"refined_depth"}
    assert outputs_to_compute({"refined_depth", "uncertainty"}) == UNCERTAINTY_READS | {"uncertainty"}
    with pytest.raises(InputError, match="unknown output"):
        outputs_to_compute({"depth"})


def test_graph_outputs_for_each_kind_of_graph() -> None:
    paper = [*BRANCHES, "fused_depth", *HEADS]  # the propagation left to the engine
    whole = [*BRANCHES, "fused_depth", "refined_s2_depth", "refined_depth"]  # the real-time models
    backbone = [*BRANCHES, "fused_depth"]
    assert graph_outputs(paper, None) == paper
    assert graph_outputs(paper, {"refined_depth"}) == HEADS
    assert graph_outputs(whole, {"refined_depth"}) == ["refined_depth"]
    assert graph_outputs(backbone, {"refined_depth"}) == ["fused_depth"]  # its final depth
    assert graph_outputs(whole, {"refined_depth", "color_conf", "uncertainty"}) == ["color_conf", "refined_depth"]


def test_completion_without_fusion_weights_has_no_confidence() -> None:
    depth = torch.ones(1, 1, 2, 3)
    output = DepthCompletionOutput(None, None, None, None, None, None, None, refined_depth=depth)  # type: ignore[arg-type]
    completion = Completion(np.ones((2, 3), np.float32), output)
    assert completion.confidence is None and list(completion.outputs) == ["refined_depth"]


@pytest.fixture(scope="module")
def completer() -> DepthCompleter:
    torch.manual_seed(0)
    return DepthCompleter(semattnet.build_model("semattnet_rt_s", width=0.5, branches=2), EngineSpec(device="cpu"))


@pytest.mark.parametrize("uncertainty", [False, True])
def test_the_run_computes_the_uncertainty_only_when_a_sink_reads_it(
    completer: DepthCompleter, uncertainty: bool, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    calls: list[int] = []
    real = completer_module.with_uncertainty
    monkeypatch.setattr(completer_module, "with_uncertainty", lambda *a: calls.append(1) or real(*a))
    sinks = default_sinks(OutputSettings(uncertainty=uncertainty))
    run = check_frames(Frames(), sinks, tmp_path / "out", OutputSpec()).run(completer, log=lambda line: None)
    assert run.counts["done"] == 2 and len(calls) == 2 * uncertainty
    assert (tmp_path / "out" / "uncertainty" / "f0.png").is_file() == uncertainty
    assert completer.outputs is None and completer.compute_uncertainty  # the completer's own setting is back


def test_completer_outputs_are_checked_and_switch_the_uncertainty(completer: DepthCompleter) -> None:
    frame = Frames().load("f0")
    completer.outputs = ["refined_depth"]
    try:
        assert completer.outputs == {"refined_depth"} and completer(frame.rgb, frame.sparse).uncertainty is None
        completer.outputs = {"refined_depth", "uncertainty"}
        assert completer(frame.rgb, frame.sparse).uncertainty is not None
        with pytest.raises(InputError, match="outputs: unknown output"):
            completer.outputs = {"depth"}
    finally:
        completer.outputs = None
    assert completer(frame.rgb, frame.sparse).uncertainty is not None


def test_a_run_keeps_the_completers_own_uncertainty_switch(completer: DepthCompleter, tmp_path: Path) -> None:
    completer.compute_uncertainty = False
    try:
        check_frames(Frames(), default_sinks(), tmp_path / "out", OutputSpec()).run(completer, log=lambda line: None)
        assert not completer.compute_uncertainty and completer.outputs is None
    finally:
        completer.compute_uncertainty = True


@pytest.mark.skipif(importlib.util.find_spec("openvino") is None, reason="openvino is not installed")
def test_openvino_cut_keeps_only_the_results_asked_for(tmp_path: Path) -> None:
    """The IR cut to the results a field set needs: the other results' layers are gone, the compiled-blob cache
    gives back the cut model (not the whole one), and the kept result is the whole model's."""
    import openvino as ov
    import openvino.opset13 as ops

    from semattnet.inference.backends.openvino_engine import _cut

    x = ops.parameter([1, 1, 4, 4], np.float32, name="sparse")
    results = {name: ops.result(ops.multiply(x, np.float32(i + 1))) for i, name in enumerate(BRANCHES)}
    results["refined_depth"] = ops.result(ops.add(x, np.float32(1)))
    for name, r in results.items():
        r.output(0).get_tensor().set_names({name})
    whole = ov.Model(list(results.values()), [x], "whole")
    config = {"CACHE_DIR": str(tmp_path / "blobs")}
    for _ in range(2):  # compiled, then from the blob cache
        cut, names = _cut(ov, whole, frozenset({"refined_depth"}))
        compiled = ov.Core().compile_model(cut, "CPU", config)
        assert names == ["refined_depth"] and len(compiled.outputs) == 1
        value = compiled.create_infer_request().infer([np.full((1, 1, 4, 4), 2.0, np.float32)])[compiled.outputs[0]]
        np.testing.assert_array_equal(value, np.full((1, 1, 4, 4), 3.0, np.float32))


@pytest.mark.slow  # ~5 s: the export of a tiny model to ONNX and OpenVINO IR
@pytest.mark.skipif(importlib.util.find_spec("openvino") is None, reason="openvino is not installed")
@pytest.mark.parametrize("name", ["semattnet_rt_s", "semattnet"])
def test_openvino_engine_asked_for_the_depth_computes_it_alone(name: str, tmp_path: Path) -> None:
    from semattnet.inference.backends import optimize_for_inference
    from tests._helpers import random_inputs

    torch.manual_seed(0)
    model = semattnet.build_model(name, width=0.25 if name != "semattnet" else 0.125, iterations=2).eval()
    x = random_inputs(b=1, h=32, w=64)
    whole = optimize_for_inference(model, backend="openvino", size=(32, 64), cache_dir=tmp_path)(**x)
    engine = optimize_for_inference(
        model, backend="openvino", size=(32, 64), cache_dir=tmp_path, outputs={"refined_depth"}
    )
    out = engine(**x)
    assert out.refined_depth is not None and whole.refined_depth is not None
    torch.testing.assert_close(out.refined_depth, whole.refined_depth, rtol=0, atol=1e-5)
    assert out.color_depth is None and out.fused_depth is None and out.guided_conf is None
    assert len(engine.compiled.outputs) == (1 if name != "semattnet" else len(HEADS))


def test_png_level_of_a_run() -> None:
    from semattnet.data.io import PNG_COMPRESS_LEVEL, STREAM_PNG_COMPRESS_LEVEL
    from semattnet.inference.options import RunOptions

    assert RunOptions().png_level() == PNG_COMPRESS_LEVEL == 3
    assert RunOptions(realtime=1.0).png_level() == RunOptions(prefetch=2).png_level() == STREAM_PNG_COMPRESS_LEVEL == 1
    assert RunOptions(realtime=1.0, write_ahead=0).png_level() == PNG_COMPRESS_LEVEL  # written in line
    assert RunOptions(realtime=1.0, png_compress_level=6).png_level() == 6
    with pytest.raises(InputError, match="png_compress_level must be 0 to 9"):
        RunOptions(png_compress_level=10)


@pytest.mark.parametrize("prefetch", [0, 2])
def test_the_run_writes_its_pngs_at_its_level(prefetch: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from semattnet.baselines import ClassicalCompleter
    from semattnet.data.io import read_depth
    from semattnet.inference.options import RunOptions
    from semattnet.inference.sinks import files as sinks

    levels: list[int] = []
    for name in ("write_depth", "write_image"):
        real = getattr(sinks, name)
        monkeypatch.setattr(sinks, name, lambda *a, real=real, **k: levels.append(k["compress_level"]) or real(*a, **k))
    options = RunOptions(prefetch=prefetch)
    out = tmp_path / f"p{prefetch}"
    check_frames(Frames(), default_sinks(), out, OutputSpec(), options).run(ClassicalCompleter(), log=lambda s: None)
    assert levels == [options.png_level()] * 4 and levels[0] == (1 if prefetch else 3)
    assert read_depth(out / "f0.png").shape == SIZE


def test_a_call_leaves_the_callers_float_arrays_unchanged(completer: DepthCompleter) -> None:
    """A batch of one goes to the engine uncopied (float32 inputs as views): nothing writes into them."""
    rng = np.random.default_rng(0)
    rgb = rng.uniform(0, 255, (*SIZE, 3)).astype(np.float32)
    sparse = np.where(rng.random(SIZE) < 0.2, rng.uniform(1, 50, SIZE), 0).astype(np.float32)
    kept = rgb.copy(), sparse.copy()
    completer(rgb, sparse)
    np.testing.assert_array_equal(rgb, kept[0])
    np.testing.assert_array_equal(sparse, kept[1])
