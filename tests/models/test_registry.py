"""The model registry: each architecture once, aliases, build_model's name vs config rule."""

from __future__ import annotations

import pytest

import semattnet
from semattnet._errors import InputError, SemAttNetError
from semattnet.models import registry
from semattnet.models.config import SemAttNetConfig
from semattnet.models.registry import (
    ALIASES,
    ARCH_FIELDS,
    MODELS,
    TABLE2,
    UnknownModelError,
    arch_for,
    build_model,
    describe_models,
    list_models,
    model_class,
    resolve_model_name,
)


def _arch(cfg: SemAttNetConfig) -> tuple:
    return tuple(getattr(cfg, f) for f in ARCH_FIELDS)


def test_list_models_names_each_architecture_once() -> None:
    names = list_models()
    assert names[:2] == ["semattnet", "semattnet_backbone"]
    assert len({_arch(MODELS[n].config) for n in names}) == len(names) == 16  # no two rows build the same model
    assert list(MODELS) == names and len(MODELS) == 16 and set(ALIASES) == {"table2_f", "table2_g"}


def test_aliases_resolve_everywhere() -> None:
    assert resolve_model_name("table2_g") == "semattnet" and resolve_model_name("table2_f") == "semattnet_backbone"
    assert "table2_g" in MODELS and MODELS["table2_f"] == MODELS["semattnet_backbone"]
    assert build_model("table2_g", width=0.125).config == build_model("semattnet", width=0.125).config
    assert type(build_model("table2_f", width=0.125)).__name__ == "SemAttNetBackbone"
    # Every Table 2 row, (a) to (g), is accepted, and the paper's models are (f) and (g).
    assert [resolve_model_name(n) for n in TABLE2][-2:] == ["semattnet_backbone", "semattnet"]
    assert registry.model_config("table2_c") == SemAttNetConfig(branches=2, fusion="concat")


def test_describe_models_lists_aliases() -> None:
    lines = describe_models().splitlines()
    assert len(lines) == 16
    full = next(line for line in lines if line.startswith("semattnet "))
    assert "[alias: table2_g]" in full and "Table 2 g" in full
    assert not any(line.startswith("table2_g") for line in lines)


def test_unknown_name_is_one_line_input_error() -> None:
    with pytest.raises(UnknownModelError) as err:
        build_model("penet")
    assert isinstance(err.value, InputError) and isinstance(err.value, ValueError)
    assert "\n" not in str(err.value) and "semattnet_backbone" in str(err.value) and "table2_g" in str(err.value)
    with pytest.raises(UnknownModelError):
        MODELS["penet"]
    assert MODELS.get("penet") is None


def test_name_selects_the_architecture_config_fills_it() -> None:
    small = SemAttNetConfig(refine=False, width=0.125)
    assert type(build_model("semattnet_backbone", config=small)).__name__ == "SemAttNetBackbone"
    assert type(build_model(config=small)).__name__ == "SemAttNetBackbone"  # no name: the config's own
    with pytest.raises(SemAttNetError) as err:
        build_model("semattnet", config=small)  # a backbone config under the full model's name
    msg = str(err.value)
    assert isinstance(err.value, InputError) and "\n" not in msg
    assert "refine=False (the model has True)" in msg and "'semattnet_backbone'" in msg
    with pytest.raises(InputError, match="branches=2"):
        build_model("table2_d", config=SemAttNetConfig(branches=2, fusion="concat", refine=False))
    with pytest.raises(InputError, match=r"unknown config field\(s\) \['depth'\]"):
        build_model("semattnet", depth=3)
    # Overrides change fields of the named model, as the trainer does for the Table 2 variants.
    two = build_model("semattnet_backbone", branches=2, fusion="add", width=0.125)
    assert _arch(two.config) == _arch(MODELS["table2_a"].config)


def test_one_home_for_the_model_class_and_arch_names() -> None:
    assert model_class(SemAttNetConfig()) is semattnet.SemAttNet
    assert model_class(SemAttNetConfig(refine=False)) is semattnet.SemAttNetBackbone
    for name in list_models():
        assert arch_for(MODELS[name].config.replace(width=0.25)) == name
    assert arch_for(SemAttNetConfig(branches=2, fusion="add")) == "semattnet"  # not a paper row: by class
