"""benchmarks/frontier.py: its variants, its refusals, and (slow) the whole training half at a tiny size with
the imports a GPU machine may lack blocked."""

from __future__ import annotations

import json
import sys
from collections.abc import Iterator
from importlib.machinery import ModuleSpec
from pathlib import Path
from types import ModuleType

import pytest
import torch

from semattnet._errors import InputError
from semattnet.models.registry import list_models, model_config
from semattnet.training.config import TrainConfig
from tests.benchmarks._scripts import load_script


@pytest.fixture(scope="module")
def frontier() -> ModuleType:
    return load_script("frontier")


def report_module() -> ModuleType:
    return load_script("frontier_report")


def test_variants_are_the_paper_at_two_widths_and_every_real_time_model(frontier: ModuleType) -> None:
    keys = [key for key, _, _ in frontier.variants()]
    rt = [n for n in list_models() if model_config(n).realtime]
    assert keys == ["paper_w1_8", "paper_w1_4", *rt] and len(rt) >= 2
    assert "--device cuda" in frontier.COMMAND and frontier.COMMAND in frontier.__doc__


def test_refusals_are_one_line_errors(frontier: ModuleType, tmp_path: Path) -> None:
    (tmp_path / "results.json").write_text("{}")
    with pytest.raises(InputError, match="results.json exists; pass --overwrite"):
        frontier.main(["--out", str(tmp_path)])
    with pytest.raises(InputError, match="--size must be HxW"):
        frontier.main(["--out", str(tmp_path / "new"), "--size", "big"])
    with pytest.raises(InputError, match="unknown model 'nope'"):
        TrainConfig(model="nope", data=str(tmp_path))


class _Blocked:
    """A meta-path finder refusing what a bare GPU machine may not have."""

    def find_spec(self, name: str, path: object = None, target: object = None) -> ModuleSpec | None:
        if name.split(".")[0] in ("plotly", "openvino", "rosbags"):
            raise ImportError(f"blocked: {name}")
        return None


@pytest.fixture
def bare_machine(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    for name in [m for m in sys.modules if m.split(".")[0] in ("plotly", "openvino", "rosbags")]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setattr(sys, "meta_path", [_Blocked(), *sys.meta_path])
    yield


@pytest.mark.slow  # trains two models through the three stages: ~40 s on 2 cores
def test_training_half_tiny(frontier: ModuleType, tmp_path: Path, bare_machine: None) -> None:
    frontier.main(["--out", str(tmp_path), "--device", "cpu", "--steps", "1,1,1", "--frames", "4", "--size", "64x96",
                   "--seeds", "0", "--variants", "paper_w1_8,semattnet_rt_s"])  # fmt: skip
    results = json.loads((tmp_path / "results.json").read_text())
    assert results["recipe"]["head_lr_factor"] == 5.0 and results["command"] == frontier.COMMAND
    scores = results["results"]
    assert set(scores) == {"classical", "paper_w1_8", "semattnet_rt_s"}
    for key in ("paper_w1_8", "semattnet_rt_s"):
        assert set(scores[key]["scores"]) == {"rmse", "mae", "irmse", "imae"}
        assert "ause_rmse" in scores[key]["uncertainty"]
        assert (tmp_path / "checkpoints" / f"{key}_seed0.safetensors").is_file()
    assert scores["semattnet_rt_s"]["params"] < scores["paper_w1_8"]["params"] / 10


@pytest.mark.slow  # trains one variant, builds its and the paper model's engines (f32, int8): minutes on 2 busy cores
def test_all_tiny_trains_times_and_reports(frontier: ModuleType, tmp_path: Path) -> None:
    """``--all``: the training half, the timing half (every backend, the whole frame, memory, int8 scores) and
    the report, on a tiny run."""
    docs = tmp_path / "docs"
    docs.mkdir()
    (docs / "performance.md").write_text(f"# P\n\n{report_module().BEGIN}\nold\n{report_module().END}\n")
    frontier.main(["--out", str(tmp_path / "run"), "--all", "--device", "cpu", "--frames", "4", "--steps", "2,1,2",
                   "--size", "32x64", "--seeds", "0", "--variants", "semattnet_rt_s", "--time-size", "64x96",
                   "--repeats", "1", "--docs", str(docs)])  # fmt: skip
    timing = json.loads((tmp_path / "run" / "timing.json").read_text())
    keys = ("paper_w1_8", "semattnet_rt_s")
    backends = [b for b, _, _ in frontier._backends()]
    assert set(timing["rows"]) == {f"{k}/{b}" for k in keys for b in backends} and "torch-f32" in backends
    assert timing["size"] == [64, 96] and timing["cpu"] and timing["threads"] >= 1 and "isa" in timing
    assert timing["rows"]["paper_w1_8/torch-f32"]["ratio"] == 1.0
    assert all(r["peak_mb"] > 0 for r in timing["rows"].values())
    assert set(timing["frames"]) == set(keys) and all(f["frame_ms"] > 0 for f in timing["frames"].values())
    assert set(timing["models"]) == set(keys) and timing["classical_ms"] > 0
    if "openvino-int8" in backends:  # the trained variant's int8 scores beside its float32 ones
        assert set(timing["int8"]) == {"semattnet_rt_s"}
        assert set(timing["int8"]["semattnet_rt_s"]["change"]) == {"rmse", "mae", "irmse", "imae"}
    text = (docs / "performance.md").read_text()
    assert "old" not in text and "| `semattnet_rt_s` |" in text
    assert (docs / "frontier.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_variant_trained_earlier_is_read_back_not_trained_again(frontier: ModuleType, tmp_path: Path) -> None:
    """A run resumes variant by variant: the first call trains and saves, the second reads the saved weights."""
    from semattnet.models.registry import build_model
    from semattnet.weights.checkpoint import Checkpoint, save_safetensors

    model = build_model("semattnet_rt_s")
    first = tmp_path / "first.safetensors"
    save_safetensors(Checkpoint(first, model.state_dict(), "state_dict", config=model.config), first)
    calls: list[int] = []

    def train() -> Path:
        calls.append(1)
        return first

    a = frontier.trained(tmp_path, "rt", 0, train, log=lambda _: None)
    b = frontier.trained(tmp_path, "rt", 0, train, log=lambda _: None)
    assert calls == [1] and (tmp_path / "checkpoints" / "rt_seed0.safetensors").is_file()
    assert all(torch.equal(x, y) for x, y in zip(a.state_dict().values(), b.state_dict().values(), strict=True))
