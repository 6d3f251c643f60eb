"""The one builder: every build path goes through it; config from the weights, overrides, strict load."""

from __future__ import annotations

import ast
import importlib.util
from pathlib import Path

import pytest
import torch

import semattnet
from semattnet import SemAttNetError
from semattnet._errors import InputError
from semattnet.weights import (
    PretrainedWeights,
    WeightsMismatchError,
    builder,
    from_pretrained,
    load_model,
    save_pretrained,
    save_safetensors,
)

from .conftest import predict

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory, tiny_model) -> dict[str, Path]:
    """The tiny model as a save_pretrained folder and its safetensors file (the config in its metadata)."""
    folder = save_pretrained(tiny_model, tmp_path_factory.mktemp("builder") / "folder")
    return {"file": folder / "model.safetensors", "folder": folder}


@pytest.fixture
def calls(monkeypatch: pytest.MonkeyPatch) -> list[dict]:
    """Every call of the builder, as the keyword arguments it got (plus ``weights``)."""
    seen: list[dict] = []
    real = builder.build_model_with_weights

    def spy(weights=None, **kwargs):  # type: ignore[no-untyped-def]
        seen.append({"weights": weights, **kwargs})
        return real(weights, **kwargs)

    monkeypatch.setattr(builder, "build_model_with_weights", spy)
    return seen


def _hubconf():  # type: ignore[no-untyped-def]
    spec = importlib.util.spec_from_file_location("hubconf_builder_test", REPO / "hubconf.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_build_path_goes_through_the_builder(
    files: dict[str, Path], calls: list[dict], cache: Path, tiny_inputs, expected
) -> None:
    paths = {
        "load_model": lambda: load_model(files["file"]),
        "from_pretrained(file)": lambda: from_pretrained(files["file"]),
        "from_pretrained(folder)": lambda: from_pretrained(files["folder"]),
        "from_pretrained(file://)": lambda: from_pretrained(files["file"].as_uri(), progress=False),
        "hubconf(pretrained=path)": lambda: _hubconf().semattnet(pretrained=str(files["file"])),
    }
    for label, make in paths.items():
        before = len(calls)
        model = make()
        assert len(calls) == before + 1, label
        assert calls[-1]["weights"] is not None, label
        assert torch.equal(predict(model, tiny_inputs), expected), label
    record = PretrainedWeights(
        name="tiny",
        arch="semattnet",
        urls=("file:///nowhere",),
        file_name="t.safetensors",
        format="safetensors",
        license="t",
        config={"width": 0.125},
    )
    fresh = [record.build(), _hubconf().semattnet(pretrained=False, width=0.125)]
    assert [c["weights"] for c in calls[-2:]] == [None, None]
    assert [m.config.width for m in fresh] == [0.125, 0.125] and all(m.training for m in fresh)


def test_config_from_the_weights_then_overrides(files: dict[str, Path], tiny_model) -> None:
    model = load_model(files["file"], refinement_mode="clean", iterations=1)
    assert model.config == tiny_model.config.replace(refinement_mode="clean", iterations=1)
    assert not model.training
    same = load_model(files["file"], width=0.125)  # repeating what the weights have is no contradiction
    assert same.config.width == 0.125


@pytest.mark.parametrize(
    ("override", "shown"),
    [
        ({"width": 0.5}, "width=0.5 (the weights have 0.125)"),
        ({"refine": False}, "refine=False"),
        ({"branches": 2}, "branches=2"),
        ({"kernel_sizes": (3, 5)}, "kernel_sizes=(3, 5)"),
    ],
)
def test_an_override_that_contradicts_the_weights_is_one_line(files: dict[str, Path], override, shown) -> None:
    for load in (load_model, from_pretrained):
        with pytest.raises(SemAttNetError) as err:
            load(files["file"], **override)
        msg = str(err.value)
        assert isinstance(err.value, WeightsMismatchError) and "\n" not in msg
        assert str(files["file"]) in msg and shown in msg and "contradicts the weights" in msg


def test_unknown_override_and_state_dict_input(tiny_model, tiny_inputs, expected) -> None:
    sd = {f"module.{k}": v for k, v in tiny_model.state_dict().items()}  # as saved from DataParallel
    model = builder.build_model_with_weights(sd, overrides={"iterations": 2})  # filter_state_dict drops the prefix
    assert torch.equal(predict(model, tiny_inputs), expected)
    with pytest.raises(InputError, match=r"unknown config field\(s\) \['depth_scale'\]"):
        builder.build_model_with_weights(sd, overrides={"depth_scale": 2})


def test_arch_must_be_of_the_weights_model_class(files: dict[str, Path]) -> None:
    with pytest.raises(WeightsMismatchError, match="are for the full model"):
        from_pretrained(files["file"], arch="semattnet_backbone")
    assert type(from_pretrained(files["file"], arch="table2_g")).__name__ == "SemAttNet"  # an alias
    backbone = semattnet.build_model("semattnet_backbone", width=0.125).state_dict()
    with pytest.raises(WeightsMismatchError, match="are for the backbone"):
        builder.build_model_with_weights(backbone, arch="semattnet")


def test_a_file_whose_recorded_config_contradicts_its_tensors(tmp_path: Path, tiny_model) -> None:
    from semattnet.weights import Checkpoint

    wrong = tiny_model.config.replace(width=0.25)
    path = save_safetensors(
        Checkpoint(path=tmp_path / "x", state_dict=tiny_model.state_dict(), format="state_dict", config=wrong),
        tmp_path / "lying.safetensors",
    )
    with pytest.raises(WeightsMismatchError) as err:
        load_model(path)
    assert "config in the file's metadata contradicts" in str(err.value) and "width 0.25 recorded" in str(err.value)


def test_a_file_contradicting_itself_is_refused_beside_a_record(tiny_model) -> None:
    from semattnet.weights import Checkpoint

    lying = tiny_model.config.replace(width=0.25)  # the file's own config; the record (config.json) is true
    ckpt = Checkpoint(path=Path("mine.gz"), state_dict=tiny_model.state_dict(), format="packed", config=lying)
    with pytest.raises(WeightsMismatchError) as err:
        builder.build_model_with_weights(ckpt, config=tiny_model.config)
    assert str(err.value) == (
        "mine.gz: the config in the file's metadata contradicts the weights: width 0.25 recorded, 0.125 in the tensors"
    )


def test_no_private_names_cross_modules_in_weights_and_the_cache() -> None:
    """``from semattnet.x import _name`` is forbidden between modules (one home, public names)."""
    offenders = []
    for folder in ("weights", "cache"):
        for path in (REPO / "src" / "semattnet" / folder).glob("*.py"):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("semattnet"):
                    offenders += [f"{path.name}: {node.module}.{a.name}" for a in node.names if a.name.startswith("_")]
    assert offenders == []


def test_a_record_contradicting_the_kernel_the_file_was_trained_with_is_refused(tiny_model) -> None:
    """The affinity form changes no shape: the same tensors would load and propagate with another kernel."""
    from semattnet.weights import Checkpoint

    ckpt = Checkpoint(path=Path("rt.gz"), state_dict=tiny_model.state_dict(), format="packed", config=tiny_model.config)
    with pytest.raises(WeightsMismatchError) as err:
        builder.build_model_with_weights(ckpt, config=tiny_model.config.replace(affinity="convex"))
    assert str(err.value) == (
        "rt.gz: the recorded config contradicts the file's own: affinity 'convex' recorded, 'eq13' in the file"
    )
    assert builder.build_model_with_weights(ckpt, config=tiny_model.config).config.affinity == "eq13"
