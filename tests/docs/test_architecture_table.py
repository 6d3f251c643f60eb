"""The package table of docs/concepts/architecture.md against the tree (issue 55, item 7): one row per
subpackage, every module named in its row (or under a nested ``pkg/`` it names), and no stale name."""

from __future__ import annotations

import re
from collections.abc import Mapping
from pathlib import Path

import semattnet

ARCHITECTURE = Path(__file__).resolve().parents[2] / "docs" / "concepts" / "architecture.md"
SRC = Path(semattnet.__file__).parent
#: The row of the package's own modules (``__init__.py``, ``_errors.py``, ``__main__.py``).
TOP = "(top level)"
ROW = re.compile(r"^\| (?:`(\w+)/`|(\(top level\))) \| (.*) \|$")
NAME = re.compile(r"`(\w+\.py|\w+/)`")


def parse_table(text: str) -> list[tuple[str, str]]:
    """(subpackage or ``TOP``, the row's text) for every row of the package table, in order."""
    return [(m[1] or m[2], m[3]) for m in map(ROW.match, text.splitlines()) if m]


def package_tree(root: Path) -> dict[str, list[str]]:
    """``TOP`` -> the top-level modules; each subpackage -> its module files, relative to it (``a/b.py``)."""
    tree = {TOP: sorted(p.name for p in root.glob("*.py"))}
    for init in sorted(root.glob("*/__init__.py")):
        tree[init.parent.name] = sorted(p.relative_to(init.parent).as_posix() for p in init.parent.rglob("*.py"))
    return tree


def label(pkg: str) -> str:
    return pkg if pkg == TOP else f"`{pkg}/`"


def check(rows: Mapping[str, str], tree: Mapping[str, list[str]]) -> list[str]:
    """What the table lacks (a subpackage, a module) and what it names that is not there, one line each."""
    problems = [f"no row for {label(pkg)}" for pkg in tree if pkg not in rows]
    problems += [f"row {label(pkg)} names no subpackage of semattnet" for pkg in rows if pkg not in tree]
    for pkg in (p for p in rows if p in tree):
        row = label(pkg)
        named = set(NAME.findall(rows[pkg]))
        files = {path.rsplit("/", 1)[-1] for path in tree[pkg]}
        dirs = {part + "/" for path in tree[pkg] for part in path.split("/")[:-1]}
        for path in tree[pkg]:
            *parents, name = path.split("/")
            if pkg != TOP and path == "__init__.py":
                continue  # the subpackage's own __init__: the row itself
            via_file = name in named and (name != "__init__.py" or not parents)
            if not via_file and not any(part + "/" in named for part in parents):
                problems.append(f"{row}: {path} is not named in its row")
        for name in sorted(named):
            if name.endswith(".py") and name not in files:
                problems.append(f"{row}: its row names `{name}`, which is no module under it")
            # a `name/` may also point at a sibling subpackage (data's row: the ROS bag's source is in `robotics/`)
            if name.endswith("/") and name not in dirs and name[:-1] not in tree:
                problems.append(f"{row}: its row names `{name}`, which is no package under it")
    return problems


def test_every_subpackage_has_exactly_one_row() -> None:
    names = [name for name, _ in parse_table(ARCHITECTURE.read_text(encoding="utf-8"))]
    twice = sorted({name for name in names if names.count(name) > 1})
    assert not twice, f"rows given twice in the package table of {ARCHITECTURE.name}: {twice}"
    assert len(names) > 10, f"the package table of {ARCHITECTURE.name} was not found (rows: {names})"


def test_the_table_names_every_module_and_nothing_stale() -> None:
    rows = dict(parse_table(ARCHITECTURE.read_text(encoding="utf-8")))
    problems = check(rows, package_tree(SRC))
    assert not problems, f"the package table of {ARCHITECTURE} against {SRC}:\n" + "\n".join(problems)


def test_the_checker_catches_a_missing_module_and_a_stale_name() -> None:
    tree = {
        TOP: ["__init__.py"],
        "models": ["__init__.py", "a.py", "b.py", "enc/__init__.py", "enc/x.py"],
        "viz": ["__init__.py", "depth.py"],
    }
    rows = {TOP: "`__init__.py` the names", "models": "`a.py`, `enc/`", "viz": "`depth.py`"}
    assert check(rows, tree) == ["`models/`: b.py is not named in its row"]
    rows["models"] = "`a.py`, `b.py`, `x.py`, `gone.py`, `old/`, `viz/`"
    assert check(rows, tree) == [
        "`models/`: enc/__init__.py is not named in its row",
        "`models/`: its row names `gone.py`, which is no module under it",
        "`models/`: its row names `old/`, which is no package under it",
    ]
    del rows["viz"]
    rows["gone"] = "`a.py`"
    assert check(rows, tree)[:2] == ["no row for `viz/`", "row `gone/` names no subpackage of semattnet"]
    assert parse_table("| `models/` | `a.py` |\n| 3 | `x` |\n| (top level) | `b.py` |") == [
        ("models", "`a.py`"),
        (TOP, "`b.py`"),
    ]
