"""A registry imports the modules of its entries itself (a source or sink registered anywhere is listed without
its module imported first), lists them in the order of those modules, and lets an entry declare its options."""

from __future__ import annotations

import sys
from dataclasses import dataclass, fields
from pathlib import Path

import pytest

from semattnet._utils.registry import Registry, option, volatile

#: The registry of the test's home module (written below); the home registers into it when imported.
THINGS: Registry[object] = Registry("thing", homes=("_registry_home_b", "_registry_home_a"))

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


def test_every_source_and_sink_lives_in_a_home_of_its_registry() -> None:
    from semattnet.data.sources.registry import SOURCES
    from semattnet.inference.sinks import SINKS

    for registry in (SOURCES, SINKS):
        assert {e.cls.__module__ for e in registry.values()} <= set(registry.homes), registry
    assert "bag" in SOURCES and {"bag", "rerun", "live"} <= set(SINKS)


def test_an_option_is_a_dataclass_field_with_its_metadata() -> None:
    @dataclass(frozen=True)
    class Opts:
        path: str | None = option("--path", help="A path.")
        quiet: bool = option("--quiet", type="flag", identity=False, help="Say less.")

    path, quiet = fields(Opts)
    assert Opts() == Opts(None, False) and path.metadata["option"].flags == ("--path",)
    assert quiet.metadata["option"].type == "flag" and volatile(Opts) == {"quiet"}
