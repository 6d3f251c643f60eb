"""The built site: strict build, generated CLI and API reference, nothing loaded from the network."""

from __future__ import annotations

import importlib
import re
import types
from pathlib import Path

import click
import pytest

from semattnet.cli import main

#: The subpackages with an API page of their own (docs/reference/api/NAME.md).
SUBPACKAGES = [
    "models",
    "weights",
    "data",
    "geometry",
    "segmentation",
    "training",
    "evaluation",
    "inference",
    "baselines",
    "viz",
]


def _commands(group: click.Group, path: tuple[str, ...] = ()) -> list[tuple[tuple[str, ...], click.Command]]:
    found = []
    for name, cmd in sorted(group.commands.items()):
        found.append(((*path, name), cmd))
        if isinstance(cmd, click.Group):
            found += _commands(cmd, (*path, name))
    return found


@pytest.mark.slow  # builds the whole site (30 s on two busy cores); CI's make docs builds it strictly
def test_cli_page_lists_every_option_of_every_command(built_site: Path) -> None:
    """Read from the click objects: a new option shows up here with no docs edit (mkdocs-click)."""
    html = (built_site / "reference" / "cli" / "index.html").read_text(encoding="utf-8")
    text = re.sub(r"<[^>]+>", "", html)
    missing = []
    for path, cmd in _commands(main):
        if f"semattnet {' '.join(path)}" not in text:
            missing.append(" ".join(path))
        for param in cmd.params:
            missing += [f"{' '.join(path)} {opt}" for opt in param.opts if opt.startswith("--") and opt not in text]
    assert not missing, f"not on the CLI page: {missing}"


@pytest.mark.slow  # builds the whole site (30 s on two busy cores); CI's make docs builds it strictly
def test_api_pages_document_every_public_name(built_site: Path) -> None:
    pages = [("semattnet", built_site / "reference" / "api")]
    pages += [(f"semattnet.{name}", built_site / "reference" / "api" / name) for name in SUBPACKAGES]
    missing = []
    for module_name, folder in pages:
        ids = set(re.findall(r'id="([^"]+)"', (folder / "index.html").read_text(encoding="utf-8")))
        module = importlib.import_module(module_name)
        for name in module.__all__:
            if name.startswith("__") or isinstance(getattr(module, name), types.ModuleType):
                continue  # __version__; the palette module has its own subpackage page (data)
            if f"{module_name}.{name}" not in ids:
                missing.append(f"{module_name}.{name}")
    assert not missing, f"public names without an API entry: {missing}"


def test_every_subpackage_with_all_has_a_page() -> None:
    import semattnet

    root = Path(semattnet.__file__).parent
    with_all = sorted(p.parent.name for p in root.glob("*/__init__.py") if "__all__" in p.read_text(encoding="utf-8"))
    docs = Path(__file__).resolve().parents[2] / "docs" / "reference" / "api"
    assert [n for n in with_all if n != "cli" and not (docs / f"{n}.md").exists()] == []


@pytest.mark.slow  # builds the whole site (30 s on two busy cores); CI's make docs builds it strictly
def test_no_page_loads_anything_from_the_network(built_site: Path) -> None:
    pattern = re.compile(r"<(?:script|link|img|iframe)\b[^>]*(?:src|href)=\"(?:https?:)?//", re.I)
    offenders = [
        str(p.relative_to(built_site)) for p in built_site.rglob("*.html") if pattern.search(p.read_text("utf-8"))
    ]
    assert not offenders, f"pages referencing the network in script/link/img tags: {offenders}"
