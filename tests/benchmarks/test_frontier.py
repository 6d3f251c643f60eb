"""benchmarks/frontier.py: its variants, its refusals, and (slow) the whole training half at a tiny size with
the imports a GPU machine may lack blocked."""

from __future__ import annotations

import importlib.util
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
    frontier.main(
        [
            "--out",
            str(tmp_path),
            "--device",
            "cpu",
            "--steps",
            "1,1,1",
            "--frames",
            "4",
            "--size",
            "64x96",
            "--seeds",
            "0",
            "--variants",
            "paper_w1_8,semattnet_rt_s",
        ]
    )
    results = json.loads((tmp_path / "results.json").read_text())
    assert results["recipe"]["head_lr_factor"] == 5.0 and results["command"] == frontier.COMMAND
    scores = results["results"]
    assert set(scores) == {"classical", "paper_w1_8", "semattnet_rt_s"}
    for key in ("paper_w1_8", "semattnet_rt_s"):
        assert set(scores[key]["scores"]) == {"rmse", "mae", "irmse", "imae"}
        assert "ause_rmse" in scores[key]["uncertainty"]
        assert (tmp_path / "checkpoints" / f"{key}_seed0.safetensors").is_file()
    assert scores["semattnet_rt_s"]["params"] < scores["paper_w1_8"]["params"] / 10


@pytest.fixture(scope="module")
def tiny_run(frontier: ModuleType, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``--all`` on a tiny run (one variant trained: two steps a stage on 4 scenes at 32x64), timed at 64x96 in
    torch float32 only (OpenVINO's exports of the paper model take minutes on 2 busy cores; the int8 scores are
    taken in their own test). Returns its folder; the report went to ``docs/`` beside it."""
    root = tmp_path_factory.mktemp("frontier")
    docs = root / "docs"
    docs.mkdir()
    (docs / "performance.md").write_text(f"# P\n\n{report_module().BEGIN}\nPLACEHOLDER\n{report_module().END}\n")
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(frontier, "_backends", lambda: [frontier.BACKENDS[0]])
        frontier.main(
            [
                "--out",
                str(root / "run"),
                "--all",
                "--device",
                "cpu",
                "--frames",
                "4",
                "--steps",
                "2,1,2",
                "--size",
                "32x64",
                "--seeds",
                "0",
                "--variants",
                "semattnet_rt_s",
                "--time-size",
                "64x96",
                "--repeats",
                "1",
                "--docs",
                str(docs),
            ]
        )
    return root / "run"


@pytest.mark.slow  # trains one variant, times it and the paper model, runs the frame loop: a minute or more
def test_all_tiny_trains_times_and_reports(tiny_run: Path) -> None:
    """``--all``: the training half, the timing half (network + propagation, memory, the whole frame, the CPU)
    and the report."""
    timing = json.loads((tiny_run / "timing.json").read_text())
    keys = ("paper_w1_8", "semattnet_rt_s")
    assert set(timing["rows"]) == {f"{k}/torch-f32" for k in keys}
    assert timing["size"] == [64, 96] and timing["cpu"] and timing["threads"] >= 1 and "isa" in timing
    assert timing["rows"]["paper_w1_8/torch-f32"]["ratio"] == 1.0
    assert all(r["peak_mb"] > 0 and r["peak_mb"] >= r["growth_mb"] for r in timing["rows"].values())
    assert set(timing["frames"]) == set(keys) and all(f["frame_ms"] > 0 for f in timing["frames"].values())
    assert timing["frames"]["semattnet_rt_s"]["stages_ms"]["network"] > 0
    assert set(timing["models"]) == set(keys) and timing["classical_ms"] > 0 and timing["int8"] == {}
    text = (tiny_run.parent / "docs" / "performance.md").read_text()
    assert "PLACEHOLDER" not in text and "| `semattnet_rt_s` |" in text and "Acceptance" in text
    assert (tiny_run.parent / "docs" / "frontier.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow  # exports, quantises (NNCF) and runs the tiny variant at 32x64: about a minute on 2 busy cores
@pytest.mark.skipif(
    importlib.util.find_spec("openvino") is None or importlib.util.find_spec("nncf") is None,
    reason="int8 needs openvino and nncf (pip install 'semattnet[openvino]')",
)
def test_int8_scores_beside_float32(frontier: ModuleType, tiny_run: Path) -> None:
    found = frontier.int8_accuracy(tiny_run, ["paper_w1_8", "semattnet_rt_s"], log=lambda _: None)
    assert set(found) == {"semattnet_rt_s"}  # the paper model was not trained in this run
    entry = found["semattnet_rt_s"]
    results = json.loads((tiny_run / "results.json").read_text())["results"]["semattnet_rt_s"]
    assert entry["f32"] == results["scores"] and set(entry["per_seed"]) == {"0"}
    assert entry["change"]["rmse"] == pytest.approx(entry["scores"]["rmse"] / results["scores"]["rmse"] - 1)


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


@pytest.mark.slow  # reuses the tiny run (trained in its fixture)
def test_ship_packs_a_trained_variant_that_loads_by_its_config(
    frontier: ModuleType, tiny_run: Path, tmp_path: Path
) -> None:
    from semattnet.apps.demo.reference import load_reference

    (made,) = frontier.ship(tiny_run, "semattnet_rt_s", [0], assets=tmp_path, log=lambda _: None)
    assert made == tmp_path / "semattnet_rt_s_demo_seed0.safetensors.gz"
    model, info = load_reference(made)
    assert type(model).__name__ == "SemAttNetRT" and info["command"] == frontier.COMMAND
    assert set(info["val"]) >= {"reference", "classical"} and info["recipe"]["seed"] == 0
    with pytest.raises(InputError, match="no trained checkpoint of semattnet_rt_m, seed 0"):
        frontier.ship(tiny_run, "semattnet_rt_m", [0], assets=tmp_path)


def test_retiming_some_variants_keeps_the_others_rows_of_the_same_machine(frontier: ModuleType, tmp_path: Path) -> None:
    path = tmp_path / "timing.json"
    machine = {"cpu": "Xeon", "threads": 2, "isa": ["avx2"], "size": [352, 1216]}
    old = {
        **machine,
        "models": {"a": 1, "b": 2},
        "frames": {"a": 1, "b": 2},
        "int8": {"b": 2},
        "rows": {"a/torch-f32": 1, "b/torch-f32": 2, "b/openvino-f32": 2},
    }
    path.write_text(json.dumps(old))
    new = {
        **machine,
        "size": (352, 1216),
        "models": {"b": 9},
        "frames": {"b": 9},
        "int8": {"b": 9},
        "rows": {"b/torch-f32": 9},
    }
    merged = frontier.kept_from_earlier(path, new, ["b"])
    assert merged["rows"] == {"a/torch-f32": 1, "b/torch-f32": 9} and merged["models"] == {"a": 1, "b": 9}
    assert merged["int8"] == {"b": 9} and merged["frames"] == {"a": 1, "b": 9}
    assert frontier.kept_from_earlier(path, {**new, "cpu": "EPYC"}, ["b"])["rows"] == {"b/torch-f32": 9}
    assert frontier.kept_from_earlier(tmp_path / "none.json", new, ["b"]) is new
