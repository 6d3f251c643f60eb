"""The package's structure rules (issue 22's acceptance), read from the source with ``ast``.

One error root; at most a handful of bare ``raise ValueError``/``TypeError`` (each with its reason);
no module imports another module's private names; ``geometry`` does not depend on ``data``; no file
over 500 lines and no function over 60 lines, measured on the code as ``ruff format`` lays it out (the
formatter switched off on a handful of lines at most, issue 55); ``Any`` in type hints held under a ceiling
(issue 44).
"""

from __future__ import annotations

import ast
import importlib
import inspect
import pkgutil
import re
import shutil
import subprocess
import sys
from collections import Counter
from collections.abc import Iterable, Iterator, Mapping
from functools import cache
from pathlib import Path

import pytest

import semattnet
from semattnet import SemAttNetError

SRC = Path(semattnet.__file__).resolve().parent
MAX_BARE_RAISES = 5
MAX_FILE_LINES = 500
MAX_FUNCTION_LINES = 60
#: Lines the formatter may leave alone (``# fmt: skip``, or ``# fmt: off`` regions): aligned numeric tables only.
MAX_FORMATTER_OFF = 20
#: Uses of ``typing.Any`` in the package (178 before issue 44); lower it as they go, never raise it.
MAX_ANY = 92  # 90, and click's Group.main signature passed through (cli._group: Ctrl-C at start)


def _module_name(path: Path) -> str:
    parts = path.relative_to(SRC.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


@cache
def _sources() -> dict[str, tuple[Path, ast.Module]]:
    """Every module of the package: dotted name -> (file, syntax tree)."""
    out = {}
    for path in sorted(SRC.rglob("*.py")):
        out[_module_name(path)] = (path, ast.parse(path.read_text(encoding="utf-8"), filename=str(path)))
    return out


def _is_package(name: str) -> bool:
    return _sources()[name][0].name == "__init__.py"


def _resolve(module: str, node: ast.ImportFrom) -> str:
    """The absolute module a ``from ... import`` in ``module`` reads from."""
    if node.level == 0:
        return node.module or ""
    package = module if _is_package(module) else module.rpartition(".")[0]
    for _ in range(node.level - 1):
        package = package.rpartition(".")[0]
    return f"{package}.{node.module}" if node.module else package


def _imports(module: str, tree: ast.AST) -> Iterator[tuple[ast.stmt, str, list[str]]]:
    """(node, imported module, imported names) for every import statement, at any depth."""
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            yield node, _resolve(module, node), [a.name for a in node.names]
        elif isinstance(node, ast.Import):
            for alias in node.names:
                yield node, alias.name, []


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _where(module: str, node: ast.AST) -> str:
    return f"{_sources()[module][0].relative_to(SRC.parent)}:{getattr(node, 'lineno', 0)}"


def test_the_source_tree_is_found() -> None:
    assert len(_sources()) > 80 and "semattnet._errors" in _sources()


# (a) one error root --------------------------------------------------------------------------------


def _all_modules() -> Iterator[object]:
    for info in pkgutil.walk_packages([str(SRC)], prefix="semattnet."):
        if info.name.endswith("__main__"):  # running them would start the CLI
            continue
        try:
            yield importlib.import_module(info.name)
        except ImportError as exc:  # an optional dependency (onnxruntime, openvino, ...) is absent
            if (getattr(exc, "name", None) or "").startswith("semattnet"):
                raise


def test_every_exception_class_derives_from_the_root() -> None:
    found, outside = [], []
    for mod in _all_modules():
        for _, cls in inspect.getmembers(mod, inspect.isclass):
            if cls.__module__ != mod.__name__ or not issubclass(cls, BaseException) or issubclass(cls, Warning):
                continue
            found.append(cls)
            if not issubclass(cls, SemAttNetError):
                outside.append(f"{cls.__module__}.{cls.__qualname__} (bases: {[b.__name__ for b in cls.__bases__]})")
    assert len(found) >= 8, found  # the test sees the package's error classes at all
    assert not outside, "exception classes outside SemAttNetError:\n" + "\n".join(outside)


# (b) bare ValueError / TypeError -------------------------------------------------------------------


def _bare_raises() -> Iterator[tuple[str, ast.Raise]]:
    for module, (_, tree) in _sources().items():
        for node in ast.walk(tree):
            if not isinstance(node, ast.Raise) or node.exc is None:
                continue
            exc = node.exc.func if isinstance(node.exc, ast.Call) else node.exc
            if isinstance(exc, ast.Name) and exc.id in ("ValueError", "TypeError"):
                yield module, node


def test_at_most_a_few_bare_value_or_type_errors_each_with_a_reason() -> None:
    raises = list(_bare_raises())
    listing = "\n".join(_where(m, n) for m, n in raises)
    assert len(raises) <= MAX_BARE_RAISES, f"{len(raises)} bare raise ValueError/TypeError:\n{listing}"
    for module, node in raises:
        lines = _sources()[module][0].read_text(encoding="utf-8").splitlines()
        near = lines[node.lineno - 2 : node.lineno]  # the raise line and the one above it
        assert any("#" in line for line in near), f"{_where(module, node)}: a bare raise needs a comment saying why"


def test_the_bare_raise_detector_sees_raises() -> None:
    tree = ast.parse("def f():\n    raise ValueError('x')\n\ndef g():\n    raise TypeError\n")
    kinds = [n.exc for n in ast.walk(tree) if isinstance(n, ast.Raise)]
    assert len(kinds) == 2  # the walk above sees call and bare-name forms alike


# (c) no private names across modules ---------------------------------------------------------------


def _private_imports() -> Iterator[str]:
    modules = _sources()
    for module, (_, tree) in modules.items():
        bound: dict[str, str] = {}  # local name -> semattnet module it refers to
        for node, target, _ in _imports(module, tree):
            if not target.startswith("semattnet") or target == module:
                continue
            if isinstance(node, ast.Import):
                for alias in node.names:
                    bound[alias.asname or alias.name.split(".")[0]] = alias.name if alias.asname else "semattnet"
                continue
            for alias in node.names:
                if f"{target}.{alias.name}" in modules:  # a submodule, not a name
                    bound[alias.asname or alias.name] = f"{target}.{alias.name}"
                elif _private(alias.name):
                    yield f"{_where(module, node)}: from {target} import {alias.name}"
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and _private(node.attr):
                target = bound.get(node.value.id)
                if target is not None and f"{target}.{node.attr}" not in modules:
                    yield f"{_where(module, node)}: {node.value.id}.{node.attr} (a private name of {target})"


def test_no_module_imports_another_modules_private_names() -> None:
    found = sorted(set(_private_imports()))
    assert not found, "private names used across modules:\n" + "\n".join(found)


# (d) layers: the table of docs/concepts/architecture.md, enforced ------------------------------------

ARCHITECTURE = Path(__file__).resolve().parents[2] / "docs" / "concepts" / "architecture.md"
ROOT = "semattnet"


def _layer_rows() -> list[list[str]]:
    """The layers, lowest first: the parts named (in backticks) in each row of the "Layers" table."""
    section = ARCHITECTURE.read_text(encoding="utf-8").split("\n## Layers\n", 1)[1].split("\n## ", 1)[0]
    rows = [re.match(r"\|\s*(\d+)\s*\|([^|]*)\|", line) for line in section.splitlines()]
    return [re.findall(r"`([\w.]+)`", m.group(2)) for m in rows if m]


@cache
def _layers() -> dict[str, int]:
    """Part (a subpackage or top-level module, ``semattnet`` for the package itself) -> its layer."""
    return {part: i for i, row in enumerate(_layer_rows()) for part in row}


def _part(module: str) -> str:
    return module.split(".")[1] if "." in module else ROOT


def _targets(module: str, tree: ast.AST) -> Iterator[tuple[ast.stmt, str]]:
    """(node, imported module of this package) for every import at any depth (``from p import m``: ``p.m``
    when ``m`` is a module)."""
    for node, target, names in _imports(module, tree):
        for name in names or [""]:
            full = f"{target}.{name}" if name and f"{target}.{name}" in _sources() else target
            if full in _sources() and full != module:
                yield node, full


@cache
def _module_graph() -> dict[str, dict[str, str]]:
    """Module -> {imported module: where}."""
    graph: dict[str, dict[str, str]] = {m: {} for m in _sources()}
    for module, (_, tree) in _sources().items():
        for node, target in _targets(module, tree):
            graph[module].setdefault(target, _where(module, node))
    return graph


def _part_graph() -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {}
    for module, targets in _module_graph().items():
        graph.setdefault(_part(module), set()).update(_part(t) for t in targets if _part(t) != _part(module))
    return graph


def _cycles(graph: Mapping[str, Iterable[str]]) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan's algorithm, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is None:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = stack[stack.index(node) :]
                    del stack[stack.index(node) :]
                    found += [sorted(component)] if len(component) > 1 else []
            elif child not in index:
                index[child] = low[child] = len(index)
                stack.append(child)
                work.append((child, iter(sorted(graph.get(child, ())))))
            elif child in stack:
                low[node] = min(low[node], index[child])
    return found


def test_every_part_is_in_exactly_one_layer() -> None:
    named = [part for row in _layer_rows() for part in row]
    parts = {_part(m) for m in _sources()}
    assert len(named) == len(set(named)), f"named twice in the layer table: {sorted(named)}"
    assert parts == set(named), f"not in the table: {sorted(parts - set(named))}; gone: {sorted(set(named) - parts)}"


def test_no_import_runs_up_the_layers() -> None:
    layers, found = _layers(), []
    for module, targets in _module_graph().items():
        for target, where in targets.items():
            if layers[_part(target)] > layers[_part(module)]:
                found.append(
                    f"{where}: {_part(module)} (layer {layers[_part(module)]}) imports {target} "
                    f"(layer {layers[_part(target)]})"
                )
    assert not found, "imports against docs/concepts/architecture.md's layers:\n" + "\n".join(found)


def test_no_import_cycle_between_modules_or_parts() -> None:
    graph = _module_graph()
    found = [
        " <-> ".join(c) + "\n    " + "\n    ".join(f"{graph[a][b]}: {a} -> {b}" for a in c for b in c if b in graph[a])
        for c in _cycles(graph)
    ]
    found += ["parts: " + " <-> ".join(c) for c in _cycles(_part_graph())]
    assert not found, "import cycles:\n" + "\n".join(found)


def _reduced(graph: Mapping[str, set[str]]) -> set[tuple[str, str]]:
    """The edges of the transitive reduction of an acyclic graph (an edge no longer path implies)."""

    def reach(start: str, skip: tuple[str, str]) -> set[str]:
        seen: set[str] = set()
        todo = [start]
        while todo:
            node = todo.pop()
            for n in graph.get(node, set()):
                if (node, n) != skip and n not in seen:
                    seen.add(n)
                    todo.append(n)
        return seen

    return {(a, b) for a in graph for b in graph[a] if b not in reach(a, (a, b))}


def test_the_architecture_diagram_is_drawn_from_the_imports() -> None:
    text = ARCHITECTURE.read_text(encoding="utf-8").split("\n## Layers\n", 1)[1].split("\n## ", 1)[0]
    drawn = set(re.findall(r"^\s+([\w.]+) --> ([\w.]+)$", text, flags=re.M))
    expected = _reduced(_part_graph())
    lines = "\n".join(f"  {a} --> {b}" for a, b in sorted(expected, key=lambda e: (-_layers()[e[0]], e)))
    assert drawn == expected, f"the diagram differs from the imports; draw:\n{lines}"


def test_the_layer_rules_catch_what_they_should() -> None:
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []
    assert _reduced({"a": {"b", "c"}, "b": {"c"}, "c": set()}) == {("a", "b"), ("b", "c")}
    assert _layers()["_errors"] == 0 and _layers()["cli"] > _layers()["inference"] > _layers()["data"]


# registries -----------------------------------------------------------------------------------------

#: Every table of named things, and where it lives.
REGISTRIES = {
    "MODELS": "semattnet.models.registry",
    "ENCODERS": "semattnet.models.encoders.base",
    "WEIGHTS": "semattnet.weights.pretrained",
    "ENGINES": "semattnet.inference.backends.registry",
    "DATASETS": "semattnet.data.datasets",
    "SOURCES": "semattnet.data.sources.registry",
    "SINKS": "semattnet.inference.sinks.base",
}


def test_one_registry_class_behind_every_table() -> None:
    from semattnet._utils.registry import Registry

    for name, module in REGISTRIES.items():
        table = getattr(importlib.import_module(module), name)
        assert isinstance(table, Registry), f"{module}.{name} is a {type(table).__name__}, not a Registry"
    made = {
        _where(module, node)
        for module, (_, tree) in _sources().items()
        for node in ast.walk(tree)
        if isinstance(node, ast.Call) and getattr(node.func, "id", "") in ("Registry", "ClassRegistry")
    }
    assert len(made) == len(REGISTRIES), f"registries made: {sorted(made)}; the table above lists {list(REGISTRIES)}"


def _registry_homes(tree: ast.AST) -> Iterator[tuple[ast.Call, str]]:
    """(call, home) for every module named in the ``homes`` of a ``Registry(...)`` / ``ClassRegistry(...)``."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and getattr(node.func, "id", "") in ("Registry", "ClassRegistry"):
            homes = [k.value for k in node.keywords if k.arg == "homes"] + node.args[1:2]
            for home in homes:
                for c in ast.walk(home):
                    if isinstance(c, ast.Constant) and isinstance(c.value, str) and c.value.startswith("semattnet"):
                        yield node, c.value


def test_no_registry_names_a_module_above_its_own_layer() -> None:
    layers, above = _layers(), []
    for module, (_, tree) in _sources().items():
        for node, home in _registry_homes(tree):
            if layers[_part(home)] > layers[_part(module)]:
                above.append(f"{_where(module, node)} names {home} ({_part(home)} is above {_part(module)})")
    assert not above, "\n".join(above)


def test_the_homes_rule_sees_a_home_above() -> None:
    tree = ast.parse('T = ClassRegistry("t", homes=("semattnet.robotics.sinks", "semattnet.data.io"))')
    assert [h for _, h in _registry_homes(tree)] == ["semattnet.robotics.sinks", "semattnet.data.io"]


# one meaning per name ------------------------------------------------------------------------------

#: Public module-level names defined in more than one module with the same meaning (issue 55, item 5).
SAME_MEANING = {
    "ENTRY": "each engine module's registry entry",
    "T": "a type variable",
    "F": "a type variable",
    "PathLike": "str | os.PathLike[str]",
    "log": "the module's logger",
    "MAX_MEDIAN_M": "each dataset's largest median depth",
    "RUN_FILES": "the files a run writes (a training run, an adapt run)",
    "run_files": "the files of a run a folder holds (a training run, an adapt run)",
    "prepare_run_folder": "a new run's folder refused or replaced (a training run, an adapt run)",
    "train": "the command and the library function it calls",
    "adapt": "the command and the library function it calls",
    "generate_launch_description": "the entry point ROS 2's launch reads in each shipped launch file",
    "KERNEL": "each compiled C++ kernel's module: its extension (propagation, classical completion)",
    "available": "each compiled C++ kernel's module: whether the kernel can be used",
}


def _public_definitions() -> dict[str, set[str]]:
    """Public module-level name -> the modules that define it (functions, classes, assignments)."""
    found: dict[str, set[str]] = {}
    for module, (_, tree) in _sources().items():
        for node in tree.body:
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
                names = [node.name]
            elif isinstance(node, ast.Assign):
                names = [t.id for t in node.targets if isinstance(t, ast.Name)]
            elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
                names = [node.target.id]
            else:
                names = []
            for name in names:
                if not name.startswith("_"):
                    found.setdefault(name, set()).add(module)
    return found


def test_no_public_name_is_defined_twice_with_two_meanings() -> None:
    twice = {name: sorted(mods) for name, mods in _public_definitions().items() if len(mods) > 1}
    unexplained = {name: mods for name, mods in twice.items() if name not in SAME_MEANING}
    assert not unexplained, f"names defined in several modules (rename one, or list it in SAME_MEANING): {unexplained}"
    assert set(SAME_MEANING) <= set(twice), f"no longer twice: {sorted(set(SAME_MEANING) - set(twice))}"


# (e), (f) sizes -------------------------------------------------------------------------------------


def test_no_file_over_500_lines() -> None:
    long = {
        str(p.relative_to(SRC.parent)): n
        for p, _ in _sources().values()
        if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_FILE_LINES
    }
    assert not long, f"files over {MAX_FILE_LINES} lines: {long}"


def _formatter_off(text: str) -> int:
    """Lines ``ruff format`` leaves as written: each ``# fmt: skip`` and each ``# fmt: off`` region."""
    return len(re.findall(r"#\s*fmt:\s*(?:skip|off)\b", text))


def test_the_formatter_decides_the_layout() -> None:
    counts = {str(p.relative_to(SRC.parent)): n for p, _ in _sources().values() if (n := _formatter_off(p.read_text()))}
    assert sum(counts.values()) <= MAX_FORMATTER_OFF, (
        f"the formatter is switched off {sum(counts.values())} times: {counts}"
    )


def test_the_formatter_count_sees_every_spelling() -> None:
    assert _formatter_off("x = 1  # fmt: skip\n# fmt: off\ny = [1,  2]\n# fmt: on\nz = 2 #fmt:skip\n") == 3
    assert _formatter_off("# the formatter decides; fmt: skipped nothing\n") == 0


def test_ruff_format_leaves_the_tree_as_it_is() -> None:
    ruff = shutil.which("ruff") or str(Path(sys.executable).parent / "ruff")
    if not Path(ruff).exists():
        pytest.skip("ruff is not installed (the dev extra)")
    done = subprocess.run([ruff, "format", "--check", str(SRC)], capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stdout + done.stderr


def test_no_function_over_60_lines() -> None:
    long = []
    for module, (_, tree) in _sources().items():
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                n = (node.end_lineno or node.lineno) - node.lineno + 1
                if n > MAX_FUNCTION_LINES:
                    long.append(f"{_where(module, node)} {node.name}: {n} lines")
    assert not long, f"functions over {MAX_FUNCTION_LINES} lines:\n" + "\n".join(long)


# (g) typing -----------------------------------------------------------------------------------------


def _any_uses(tree: ast.AST) -> list[int]:
    """The lines of every use of ``Any`` (``Any``, ``typing.Any``, and inside string annotations); the import
    itself is not a use."""
    lines = []
    for node in ast.walk(tree):
        if (isinstance(node, ast.Name) and node.id == "Any") or (
            isinstance(node, ast.Attribute) and node.attr == "Any"
        ):
            lines.append(node.lineno)
        elif isinstance(node, ast.arg | ast.AnnAssign | ast.FunctionDef | ast.AsyncFunctionDef):
            hint = node.returns if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) else node.annotation
            if isinstance(hint, ast.Constant) and isinstance(hint.value, str):
                lines += [node.lineno] * len(_any_uses(ast.parse(hint.value, mode="eval")))
    return lines


def test_any_stays_under_its_ceiling() -> None:
    per_file = Counter({str(path.relative_to(SRC.parent)): len(_any_uses(tree)) for path, tree in _sources().values()})
    total = sum(per_file.values())
    most = ", ".join(f"{f} ({n})" for f, n in per_file.most_common(8))
    assert total <= MAX_ANY, f"{total} uses of Any in type hints (at most {MAX_ANY}); most in: {most}"


def test_the_any_count_sees_every_spelling() -> None:
    source = 'from typing import Any\nimport typing\ndef f(a: Any, b: "list[Any]") -> typing.Any:\n    c: "Any" = a\n'
    assert len(_any_uses(ast.parse(source))) == 4


@pytest.mark.parametrize(
    ("source", "expected"),
    [
        ("from semattnet.x import _y\n", ["from semattnet.x import _y"]),
        ("from semattnet.x import y, __version__\n", []),
    ],
)
def test_the_private_import_rule_on_examples(source: str, expected: list[str]) -> None:
    tree = ast.parse(source)
    got = [
        f"from {target} import {n}"
        for _, target, names in _imports("semattnet._errors", tree)
        for n in names
        if _private(n)
    ]
    assert got == expected
