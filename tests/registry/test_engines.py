"""Every inference engine (:func:`~semattnet.inference.backends.engine_entries`: each backend at each
precision it runs) built on a tiny model and run on a 32x64 frame: the outputs of the eager model, refused
inputs, and parity with the eager model within the precision's tolerance. An engine this machine cannot run
(its package missing, no CUDA) is skipped with the reason."""

from __future__ import annotations

import importlib.util
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import pytest
import torch

import semattnet
from semattnet._errors import InputError
from semattnet.inference.backends import InferenceEngine, available_backends, engine_entries, optimize_for_inference
from tests._base import RegistryTester
from tests._helpers import random_inputs

SIZE = (32, 64)
Engines = dict[str, InferenceEngine]
Outputs = dict[str, torch.Tensor]


@dataclass(frozen=True)
class EngineFixture:
    """``rtol``: the largest error relative to the eager output's largest value, every output (``mean``: the
    mean error relative to the mean value, refined depth only: int8). ``cuda``: runs on CUDA only.
    ``fixed``: compiled for one size. ``slow``: marked slow (its build takes over 10 s on 2 cores)."""

    rtol: float
    fixed: bool = False
    cuda: bool = False
    mean: bool = False
    slow: bool = False
    needs: tuple[str, ...] = ()


FIXTURES = {
    "torch-f32": EngineFixture(1e-4),
    "torch-bf16": EngineFixture(0.1),
    "torch-fp16": EngineFixture(0.02),
    "openvino-f32": EngineFixture(1e-4, fixed=True),
    "openvino-bf16": EngineFixture(0.1, fixed=True),
    "openvino-int8": EngineFixture(0.05, fixed=True, mean=True, slow=True, needs=("nncf",)),
    "onnxruntime-f32": EngineFixture(1e-4, fixed=True),
    "tensorrt-f32": EngineFixture(1e-3, fixed=True, cuda=True),
    "tensorrt-fp16": EngineFixture(0.02, fixed=True, cuda=True),
}


def split(entry: str) -> tuple[str, str]:
    backend, precision = entry.rsplit("-", 1)
    return backend, precision


@pytest.fixture(scope="module")
def model() -> torch.nn.Module:
    """Width 1/8 with non-trivial BatchNorm statistics, so that folding is really exercised."""
    torch.manual_seed(0)
    net = semattnet.build_model("semattnet", width=0.125, iterations=2).eval()
    with torch.no_grad():
        for m in net.modules():
            if isinstance(m, torch.nn.BatchNorm2d):
                m.running_mean.uniform_(-0.1, 0.1)
                m.running_var.uniform_(0.5, 1.5)
    return net


@pytest.fixture(scope="module")
def reference(model: torch.nn.Module) -> dict[str, torch.Tensor]:
    """The eager model's outputs on :func:`inputs`."""
    with torch.inference_mode():
        return model(**inputs()).to_dict()


@pytest.fixture(scope="module")
def engines(model: torch.nn.Module, tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, InferenceEngine]]:
    """One engine per entry for the module, exported into one cache (the ONNX export is shared)."""
    cache = tmp_path_factory.mktemp("engines")
    built: dict[str, InferenceEngine] = _Engines(model, cache)
    yield built


class _Engines(dict[str, InferenceEngine]):
    def __init__(self, model: torch.nn.Module, cache: Path) -> None:
        super().__init__()
        self.model, self.cache = model, cache

    def __missing__(self, entry: str) -> InferenceEngine:
        backend, precision = split(entry)
        fx = FIXTURES[entry]
        missing = [p for p in (backend, *fx.needs) if p != "torch" and importlib.util.find_spec(p) is None]
        if backend not in available_backends() or missing:
            pytest.skip(f"{entry}: {', '.join(missing) or backend} is not installed")
        if fx.cuda and not torch.cuda.is_available():
            pytest.skip(f"{entry}: needs CUDA")
        device = "cuda" if fx.cuda else "cpu"
        engine = optimize_for_inference(
            self.model,
            backend=backend,
            precision=precision,
            size=SIZE,
            device=device,
            cache_dir=self.cache,
            calibration_frames=2,
        )
        self[entry] = engine
        return engine


def inputs(h: int = SIZE[0], w: int = SIZE[1], device: str = "cpu") -> dict[str, torch.Tensor]:
    return {k: v.to(device) for k, v in random_inputs(b=1, h=h, w=w).items()}


class TestEngines(RegistryTester[EngineFixture]):
    kind = "engine"
    fixtures: ClassVar[Mapping[str, EngineFixture]] = FIXTURES

    @classmethod
    def entries(cls) -> list[str]:
        return [f"{name}-{precision}" for name, entry in engine_entries().items() for precision in entry.precisions]

    @classmethod
    def marks(cls, name: str) -> tuple[pytest.MarkDecorator, ...]:
        return (pytest.mark.slow,) if name in FIXTURES and FIXTURES[name].slow else ()

    def _device(self, entry: str) -> str:
        return "cuda" if self.fixture(entry).cuda else "cpu"

    def test_smoke(self, entry: str, engines: dict[str, InferenceEngine]) -> None:
        self.fixture(entry)
        engine = engines[entry]
        assert (engine.backend, engine.precision) == split(entry)
        out = engine(**inputs(device=self._device(entry)))
        assert isinstance(out, semattnet.DepthCompletionOutput) and torch.isfinite(out.refined_depth).all()

    def test_cardinality(self, entry: str, engines: Engines, reference: Outputs) -> None:
        self.fixture(entry)
        ref = reference
        out = engines[entry](**inputs(device=self._device(entry))).to_dict()
        assert {k: tuple(v.shape) for k, v in out.items()} == {k: tuple(v.shape) for k, v in ref.items()}
        assert all(v.dtype == torch.float32 for v in out.values())

    def test_exception(self, entry: str, engines: dict[str, InferenceEngine]) -> None:
        fx = self.fixture(entry)
        engine, device = engines[entry], self._device(entry)
        if fx.fixed:
            with pytest.raises(InputError, match="compiled for 32x64 inputs, got 64x64"):
                engine(**inputs(64, 64, device))
        with pytest.raises(InputError, match="not a positive multiple of 32|compiled for 32x64 inputs, got 33x64"):
            engine(**inputs(33, 64, device))

    def test_numerics(self, entry: str, engines: Engines, reference: Outputs) -> None:
        """Parity with the eager model (the torch engine's own reference)."""
        fx, ref = self.fixture(entry), reference
        out = {k: v.float().cpu() for k, v in engines[entry](**inputs(device=self._device(entry))).to_dict().items()}
        if fx.mean:
            err = (out["refined_depth"] - ref["refined_depth"]).abs()
            assert float(err.mean() / ref["refined_depth"].abs().mean()) < fx.rtol
            return
        for name, tensor in ref.items():
            assert float((out[name] - tensor).abs().max() / tensor.abs().max()) < fx.rtol, name
