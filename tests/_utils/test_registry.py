"""The one registry shape: names refused twice, one unknown-name error that lists the names (and aliases), a class
registry that imports its homes itself (a source or sink of its layer is listed without its module imported first)
and lists them in the order of those modules, an entry that declares its options; the layers above enrol their
own entries."""

from __future__ import annotations

import sys
from dataclasses import dataclass, fields
from pathlib import Path

import pytest

from semattnet._utils.registry import ClassRegistry, DuplicateEntryError, Registry, UnknownEntryError, option, volatile

#: The registry of the test's home module (written below); the home registers into it when imported.
THINGS: ClassRegistry[object] = ClassRegistry("thing", homes=("_registry_home_b", "_registry_home_a"))

HOME = """
from tests._utils.test_registry import THINGS

@THINGS.register({name!r})
class Thing{name}:
    pass
"""


def test_a_registry_imports_its_homes_in_their_order(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    for name in ("a", "b"):
        (tmp_path / f"_registry_home_{name}.py").write_text(HOME.format(name=name))
    monkeypatch.syspath_prepend(str(tmp_path))

    @THINGS.register("late")
    class Late:
        pass

    try:
        assert "_registry_home_a" not in sys.modules
        assert THINGS.names() == ["b", "a", "late"]  # the homes' entries first, in their order
        assert THINGS["a"].cls.__module__ == "_registry_home_a"
    finally:
        for name in ("_registry_home_a", "_registry_home_b"):
            sys.modules.pop(name, None)


def test_every_source_and_sink_lives_in_a_home_or_a_layer_above() -> None:
    from semattnet.data.sources.registry import SOURCES
    from semattnet.inference.sinks import SINKS

    for registry in (SOURCES, SINKS):
        outside = {e.cls.__module__ for e in registry.values()} - set(registry.homes)
        assert {m.split(".")[1] for m in outside} <= {"robotics"}, registry
    assert "bag" in SOURCES and {"bag", "rerun", "live"} <= set(SINKS)  # robotics enrolled them (import semattnet)


def test_a_name_is_taken_once_and_an_unknown_one_lists_the_names() -> None:
    sizes: Registry[int] = Registry("size")
    sizes.add("small", 1)
    sizes.add("large", 3)
    sizes.alias("s", "small")
    assert sizes["s"] == 1 and "s" in sizes and list(sizes) == ["small", "large"] and len(sizes) == 2
    assert sizes.resolve("s") == "small" and sizes.aliases == {"s": "small"}
    with pytest.raises(DuplicateEntryError, match="size 'small' is already registered"):
        sizes.add("small", 2)
    with pytest.raises(DuplicateEntryError, match="alias 's' is already taken"):
        sizes.alias("s", "large")
    with pytest.raises(UnknownEntryError) as err:
        sizes["medium"]
    assert str(err.value) == "unknown size 'medium'; available: small, large (aliases: s)"
    assert sizes.add("small", 5, replace=True) == 5 and sizes["small"] == 5
    sizes.remove("small")
    assert sizes.names() == ["large"] and "s" not in sizes


def test_an_option_is_a_dataclass_field_with_its_metadata() -> None:
    @dataclass(frozen=True)
    class Opts:
        path: str | None = option("--path", help="A path.")
        quiet: bool = option("--quiet", type="flag", identity=False, help="Say less.")

    path, quiet = fields(Opts)
    assert Opts() == Opts(None, False) and path.metadata["option"].flags == ("--path",)
    assert quiet.metadata["option"].type == "flag" and volatile(Opts) == {"quiet"}
