"""The one engine spec: :meth:`EngineSpec.resolve` makes every choice (auto backend and device, the precision
and the deprecated ``amp``) and refuses what does not go together, reading the engine table."""

from __future__ import annotations

import warnings

import pytest
import torch

import semattnet
from semattnet._errors import InputError
from semattnet.inference import DepthCompleter, EngineSpec
from semattnet.inference.backends import available_backends, choose_backend, engine_entries, get_engine, precisions
from semattnet.inference.backends.spec import AMP_NOTE


def test_the_table_holds_every_builtin_engine() -> None:
    entries = engine_entries()
    assert list(entries) == ["torch", "openvino", "onnxruntime", "tensorrt"]
    assert entries["tensorrt"].devices == ("cuda",) and entries["tensorrt"].fixed_size
    assert entries["openvino"].precisions == ("f32", "bf16", "int8") and entries["openvino"].package == "openvino"
    assert precisions() == ("f32", "bf16", "fp16", "int8")
    assert available_backends()[0] == "torch"
    assert entries["onnxruntime"].install_hint() == "pip install 'semattnet[onnx]'"


def test_resolve_makes_every_choice() -> None:
    spec = EngineSpec().resolve()
    assert (spec.backend, spec.precision, spec.amp) == ("torch", "f32", None)
    assert spec.device == ("cuda" if torch.cuda.is_available() else "cpu")
    assert spec.resolve() == spec  # a resolved spec is a fixed point
    bf16 = EngineSpec(precision="bf16", device="cpu").resolve()
    assert (bf16.autocast, bf16.engine_precision) == (torch.bfloat16, "f32")  # torch: autocast around an f32 engine
    if "openvino" in available_backends():
        ov = EngineSpec("openvino", "bf16").resolve()  # auto device: the backend's (CPU), even on a CUDA machine
        assert (ov.device, ov.autocast, ov.engine_precision) == ("cpu", None, "bf16")
        assert EngineSpec("auto", device="cpu").resolve().backend == "openvino"  # a completer's size is known
        assert EngineSpec("auto", device="cpu").resolve(fixed_size=False).backend == "torch"
    assert EngineSpec("auto", "int8", "cpu").resolve().backend == "openvino"  # the only int8 engine
    assert choose_backend("cpu", None, "fp16") == "torch"


@pytest.mark.parametrize(
    ("spec", "words"),
    [
        (EngineSpec("tpu"), "unknown backend 'tpu'; choose one of auto, torch, openvino"),
        (EngineSpec(precision="f8"), "unknown precision 'f8'"),
        (EngineSpec(precision="int8"), "the torch backend runs f32, bf16, fp16, not 'int8'; int8 runs on the openvino"),
        (EngineSpec("onnxruntime", "bf16"), "the onnxruntime backend runs f32, not 'bf16'"),
        (EngineSpec("tensorrt", device="cpu"), "device: the tensorrt backend runs on cuda, got cpu"),
        (EngineSpec("openvino", device="meta"), "type 'meta' cannot run a model"),
    ],
)
def test_resolve_refuses_what_does_not_go_together(spec: EngineSpec, words: str) -> None:
    with pytest.raises(InputError, match=words):
        spec.resolve()


def test_amp_is_precision_under_its_older_name_with_one_note() -> None:
    with pytest.warns(FutureWarning, match="amp") as notes:
        spec = EngineSpec(amp="bf16", device="cpu").resolve()
    assert spec.precision == "bf16" and spec.amp is None and len(notes) == 1 and str(notes[0].message) == AMP_NOTE
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        spec.resolve()  # resolved: amp is gone, no second note
    with pytest.warns(FutureWarning):
        assert EngineSpec(precision="fp16", amp="fp16", device="cpu").resolve().precision == "fp16"
        assert EngineSpec(amp="none", device="cpu").resolve().precision == "f32"
        with pytest.raises(InputError, match="precision 'bf16' and amp 'fp16' disagree"):
            EngineSpec(precision="bf16", amp="fp16").resolve()


def test_a_completer_runs_its_spec() -> None:
    model = semattnet.build_model("semattnet", width=0.125)
    spec = EngineSpec(precision="bf16", device="cpu")
    completer = DepthCompleter(model, spec=spec)
    assert completer.spec == spec.resolve() and completer.amp is torch.bfloat16 and completer.device.type == "cpu"
    with pytest.warns(FutureWarning):
        assert DepthCompleter(model, EngineSpec(device="cpu", amp="fp16")).spec.precision == "fp16"
    with pytest.raises(InputError, match="give spec or device"):
        DepthCompleter(model, spec, backend="openvino")
    with pytest.warns(DeprecationWarning, match="deprecated since 0.2"):
        assert DepthCompleter(model, "cpu").spec.device == "cpu"  # the older form, until 0.3
    assert get_engine(completer.backend).name == "torch"
