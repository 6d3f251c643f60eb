"""``semattnet._utils.extras``: the one way to need an optional package, and a ban on any other."""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

from semattnet._errors import MissingDependencyError, SemAttNetError
from semattnet._utils.extras import EXTRAS, call_with_newer, install_hint, optional, require

SRC = Path(__file__).resolve().parents[2] / "src" / "semattnet"


def _catches_import_error(handler: ast.ExceptHandler) -> bool:
    names = handler.type.elts if isinstance(handler.type, ast.Tuple) else [handler.type]
    return any(isinstance(n, ast.Name) and n.id in ("ImportError", "ModuleNotFoundError") for n in names)


def test_no_other_module_catches_an_import_error() -> None:
    """Optional packages are needed through ``require`` / ``optional`` only: one message, one error class."""
    offenders = []
    for path in sorted(SRC.rglob("*.py")):
        if path == SRC / "_utils" / "extras.py":
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ExceptHandler) and node.type is not None and _catches_import_error(node):
                offenders.append(f"{path.relative_to(SRC)}:{node.lineno}")
    assert not offenders, f"use semattnet._utils.extras.require/optional instead of except ImportError: {offenders}"


def test_every_extra_named_is_one_pyproject_declares() -> None:
    import tomllib

    pyproject = tomllib.loads((SRC.parents[1] / "pyproject.toml").read_text())
    declared = set(pyproject["project"]["optional-dependencies"])
    assert {extra for _, extra in EXTRAS.values() if extra} <= declared


def test_require_names_the_feature_the_package_and_the_command(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "foxglove", None)
    with pytest.raises(MissingDependencyError) as info:
        require("foxglove", "--live")
    assert str(info.value) == "--live needs the optional package 'foxglove-sdk': pip install 'semattnet[live]'"
    assert isinstance(info.value, SemAttNetError) and isinstance(info.value, ImportError)
    assert info.value.name == "foxglove"
    assert optional("foxglove") is None and optional("json") is sys.modules["json"]
    assert install_hint("plyfile") == "pip install plyfile"  # a core dependency: no extra provides it
    assert install_hint("no_such_package_xyz.sub") == "pip install no_such_package_xyz"


def test_call_with_newer_leaves_out_only_the_keywords_an_older_release_lacks() -> None:
    calls: list[dict[str, object]] = []

    def old(url: str, *, size: int = 0) -> str:
        calls.append({"url": url, "size": size})
        return "old"

    def new(url: str, *, size: int = 0, quiet: bool = False) -> str:
        calls.append({"url": url, "size": size, "quiet": quiet})
        return "new"

    assert call_with_newer(new, {"quiet": True}, "u", size=2) == "new"
    assert call_with_newer(old, {"quiet": True}, "u", size=2) == "old"
    assert calls == [{"url": "u", "size": 2, "quiet": True}, {"url": "u", "size": 2}]  # the old one ran once
    with pytest.raises(TypeError, match="'colour'"):  # a keyword not among the newer ones is the caller's bug
        call_with_newer(old, {"quiet": True}, "u", colour=1)
    with pytest.raises(TypeError, match="body"):  # a TypeError raised inside is never retried

        def broken(url: str, quiet: bool = False) -> None:
            raise TypeError("body")

        call_with_newer(broken, {"quiet": True}, "u")
