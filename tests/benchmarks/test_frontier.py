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


@pytest.mark.slow  # converts the paper model and one variant with OpenVINO: about 2 minutes on 2 busy cores
def test_timing_half_tiny(frontier: ModuleType, tmp_path: Path) -> None:
    args = ["--time", "--size", "64x96", "--repeats", "1", "--variants", "semattnet_rt_s"]
    frontier.main(["--out", str(tmp_path), *args])
    timing = json.loads((tmp_path / "timing.json").read_text())
    keys = ("paper_w1_8", "semattnet_rt_s")
    assert {f"{k}/torch-f32" for k in keys} == {k for k in timing["rows"] if k.endswith("torch-f32")}
    assert timing["size"] == [64, 96]
    assert timing["rows"]["paper_w1_8/torch-f32"]["ratio"] == 1.0 and timing["cpu"]


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


def test_the_width_1_8_paper_model_is_the_shipped_reference_only_for_its_own_recipe(frontier: ModuleType) -> None:
    import dataclasses

    from semattnet.apps.demo.reference import REFERENCE_RECIPE, shipped_references

    shipped = shipped_references()
    r1 = dataclasses.replace(REFERENCE_RECIPE, seed=1)
    assert frontier.shipped_reference("paper_w1_8", 0, REFERENCE_RECIPE) == shipped[0]
    assert frontier.shipped_reference("paper_w1_8", 1, r1) == shipped[1]
    assert frontier.shipped_reference("paper_w1_8", 7, REFERENCE_RECIPE) is None  # no such seed shipped
    assert frontier.shipped_reference("paper_w1_8", 0, dataclasses.replace(REFERENCE_RECIPE, full_steps=1)) is None
    assert frontier.shipped_reference("semattnet_rt_s", 0, REFERENCE_RECIPE) is None


def test_a_synthetic_tree_of_other_settings_is_refused_not_reused(frontier: ModuleType, tmp_path: Path) -> None:
    manifest = {"seed": 1000, "size": [96, 320], "style": "realistic", "counts": {"train": 400, "val_select": 16}}
    (tmp_path / "scenes.json").write_text(json.dumps(manifest))
    with pytest.raises(InputError, match=r"scenes.json: written with .*'seed': 1000.*this run needs .*'seed': 7"):
        frontier.synthetic(tmp_path, 400, 16, (96, 320), 7, "realistic")
