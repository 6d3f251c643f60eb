"""A new engine is one entry in the engine table: registered here (a fixture standing for its module), it is a
``--backend`` choice of ``predict --help`` and runs ``predict`` end to end, with no edit elsewhere. And ``--amp``,
the older name of ``--precision``, still works and says so once."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner, Result
from torch import nn

from semattnet.cli import main
from semattnet.data.io import read_depth, write_depth, write_image
from semattnet.inference.backends import (
    EngineEntry,
    EngineRequest,
    InferenceEngine,
    register_engine,
    registry,
)
from semattnet.models.outputs import DepthCompletionOutput


class EchoEngine(InferenceEngine):
    """The eager model, counting its calls: a stand-in for a new backend's engine."""

    backend = "echo"
    calls = 0

    def __init__(self, model: nn.Module, request: EngineRequest) -> None:
        super().__init__(request.size, request.precision, request.needs_semantic)
        self.net = model.to(request.device)

    def forward(
        self, rgb: torch.Tensor, semantic: torch.Tensor | None = None, sparse: torch.Tensor | None = None
    ) -> DepthCompletionOutput:
        EchoEngine.calls += 1
        with torch.inference_mode():
            out: DepthCompletionOutput = self.net(rgb=rgb, semantic=semantic, sparse=sparse)
        return out


@pytest.fixture
def echo(monkeypatch: pytest.MonkeyPatch) -> Iterator[EngineEntry]:
    """The new engine's module: one :func:`register_engine` call (the table is restored afterwards)."""
    entry = register_engine(
        EngineEntry(
            "echo", precisions=("f32",), devices=("cpu",), build=EchoEngine, summary="the eager model, for a test"
        )
    )
    EchoEngine.calls = 0
    try:
        yield entry
    finally:
        registry.unregister_engine("echo")


@pytest.fixture
def frame(tmp_path: Path) -> list[str]:
    """One tiny frame (rgb, sparse, semantic) as ``predict`` options."""
    rng = np.random.default_rng(0)
    write_image(tmp_path / "rgb" / "f.png", rng.integers(0, 256, (32, 32, 3), dtype=np.uint8))
    write_image(tmp_path / "semantic" / "f.png", np.full((32, 32, 3), (128, 64, 128), np.uint8))
    write_depth(tmp_path / "sparse" / "f.png", np.where(rng.random((32, 32)) < 0.2, 10.0, 0).astype(np.float32))
    return [f"--{d}={tmp_path / d}" for d in ("rgb", "sparse", "semantic")]


def _predict(*args: str) -> Result:
    return CliRunner().invoke(main, ["predict", *args])


def test_a_registered_engine_is_a_choice(echo: EngineEntry, frame: list[str], tmp_path: Path) -> None:
    weights = tmp_path / "unread.safetensors"  # the checks come before the model is read
    weights.write_bytes(b"x")
    frame = [*frame, f"--weights={weights}"]
    assert "[torch|openvino|onnxruntime|tensorrt|echo|auto]" in _predict("--help").output
    res = _predict(*frame, "--backend", "echo", "--precision", "bf16", "--out", str(tmp_path / "b"))
    assert res.exit_code == 2 and "--precision: the echo backend runs f32, not 'bf16'" in res.output, res.output
    assert "deprecated" not in res.output
    res = _predict(*frame, "--backend", "echo", "--amp", "bf16", "--out", str(tmp_path / "b"))  # --precision's name
    assert res.exit_code == 2 and "--precision: the echo backend runs f32, not 'bf16'" in res.output, res.output
    assert res.output.count("deprecated") == 1 and "note: amp (--amp) is deprecated" in res.output, res.output
    assert not (tmp_path / "b").exists() and EchoEngine.calls == 0


@pytest.mark.slow  # two predict runs: a few seconds on 2 cores
def test_a_registered_engine_runs_predict(echo: EngineEntry, frame: list[str], tmp_path: Path) -> None:
    from tests.inference._raw_sample import tiny_checkpoint

    frame = [*frame, f"--weights={tiny_checkpoint(tmp_path / 'tiny.safetensors')}"]
    res = _predict(*frame, "--backend", "echo", "--out", str(tmp_path / "o"))
    assert res.exit_code == 0 and EchoEngine.calls == 1, res.output
    assert read_depth(tmp_path / "o" / "f.png").max() > 0
    res = _predict(*frame, "--backend", "echo", "--amp", "none", "--out", str(tmp_path / "a"))  # still works
    assert res.exit_code == 0 and EchoEngine.calls == 2, res.output
    assert res.output.count("deprecated") == 1, res.output
    np.testing.assert_array_equal(read_depth(tmp_path / "a" / "f.png"), read_depth(tmp_path / "o" / "f.png"))


def test_one_model_section_for_every_command_that_runs_a_model() -> None:
    """predict, evaluate, submit and the ROS nodes take the one Model section (submit: no --method); predict stays
    within its 49 options (48, and --prior since --method prior)."""
    names = ("predict", "evaluate", "submit", "ros1", "ros2")
    commands = {name: {p.name: p for p in main.commands[name].params} for name in names}
    model = ["weights", "device", "backend", "precision", "calibration", "amp"]
    for name, params in commands.items():
        assert set(model) <= set(params) and ("method" in params) == (name != "submit"), name
        assert [params[m].help for m in model] == [commands["predict"][m].help for m in model], name
    assert len(commands["predict"]) <= 49
