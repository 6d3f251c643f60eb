"""Every qualified cross-reference in a docstring (``:class:`~semattnet.x.Y```, ``:func:`~.module.f```) names
something that exists, read from the source with ``ast`` (nothing imported: the optional extras need not be
installed). The docs build does not check these roles, so a module renamed or a class moved leaves them behind.
"""

from __future__ import annotations

import ast
import re
from functools import cache
from pathlib import Path

import semattnet

SRC = Path(semattnet.__file__).resolve().parent
ROLE = re.compile(r":(?:class|func|meth|mod|data|attr|exc|obj):`~?(\.*[A-Za-z_][\w.]*)`")


def _module_name(path: Path) -> str:
    parts = path.relative_to(SRC.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


@cache
def _modules() -> dict[str, Path]:
    """Every module of the package: dotted name -> file."""
    return {_module_name(p): p for p in sorted(SRC.rglob("*.py"))}


@cache
def _tree(module: str) -> ast.Module:
    return ast.parse(_modules()[module].read_text(encoding="utf-8"))


@cache
def _defined(module: str, owner: tuple[str, ...] = ()) -> dict[str, ast.AST]:
    """What ``module`` (or its class at path ``owner``) defines, read once."""
    if not owner:
        return _names(_tree(module).body)
    node = _defined(module, owner[:-1])[owner[-1]]
    assert isinstance(node, ast.ClassDef)
    return _names(node.body, node)


def _names(body: list[ast.stmt], owner: ast.ClassDef | None = None) -> dict[str, ast.AST]:
    """What a module or class body defines (an import by its target), with a class's ``self.X`` attributes."""
    found: dict[str, ast.AST] = {}
    for node in body:
        if isinstance(node, ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            found[node.name] = node
        elif isinstance(node, ast.Assign | ast.AnnAssign):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            found |= {t.id: node for t in targets if isinstance(t, ast.Name)}
        elif isinstance(node, ast.ImportFrom | ast.Import):
            found |= {(a.asname or a.name).split(".")[0]: node for a in node.names}
        elif isinstance(node, ast.If):  # TYPE_CHECKING imports, optional definitions
            found |= _names(node.body + node.orelse)
    if owner is not None:
        found |= {t.attr: t for t in ast.walk(owner) if isinstance(t, ast.Attribute) and isinstance(t.ctx, ast.Store)}
    return found


def _resolves(target: str, seen: int = 0) -> bool:
    """Whether dotted ``target`` (absolute) names a module or something a module defines or imports."""
    parts = target.split(".")
    heads = [i for i in range(len(parts), 0, -1) if ".".join(parts[:i]) in _modules()]
    if not heads or seen > 5:
        return not target.startswith("semattnet")  # outside the package: not ours to check
    i = heads[0]
    module, rest = ".".join(parts[:i]), parts[i:]
    for k, part in enumerate(rest):
        node = _defined(module, tuple(rest[:k])).get(part)
        if node is None:
            return False
        if isinstance(node, ast.ImportFrom):
            base = _absolute(node, module)
            return any(
                _resolves(".".join([f"{base}.{a.name}", *rest[k + 1 :]]), seen + 1)
                for a in node.names
                if (a.asname or a.name) == part
            )
        if not isinstance(node, ast.ClassDef):
            return k == len(rest) - 1
    return True


def _absolute(node: ast.ImportFrom, module: str) -> str:
    """The module an ``ImportFrom`` in ``module`` reads from."""
    if not node.level:
        return node.module or ""
    is_package = _modules()[module].name == "__init__.py"
    base = module.split(".")[: len(module.split(".")) - node.level + is_package]
    return ".".join([*base, *([node.module] if node.module else [])])


def _qualified(target: str, module: str) -> str | None:
    """``target`` as an absolute dotted name, or None when it is bare (a name of the enclosing class or module)."""
    if target.startswith("."):
        dots = len(target) - len(target.lstrip("."))
        is_package = _modules()[module].name == "__init__.py"
        base = module.split(".")[: len(module.split(".")) - dots + is_package]
        return ".".join([*base, target.lstrip(".")])
    return target if target.startswith("semattnet.") else None


def _broken(text: str, module: str) -> list[str]:
    return [
        m.group(0)
        for m in ROLE.finditer(text)
        if (q := _qualified(m.group(1), module)) is not None and not _resolves(q)
    ]


def test_every_qualified_cross_reference_resolves() -> None:
    broken = [
        f"{path.relative_to(SRC)}: {ref}"
        for name, path in _modules().items()
        for ref in _broken(path.read_text(encoding="utf-8"), name)
    ]
    assert broken == []


def test_the_check_finds_what_does_not_resolve() -> None:
    module = "semattnet.robotics.live"
    good = ":class:`~semattnet.robotics.sinks.BagSink` :func:`~.gate.Gate` :mod:`semattnet.inference.feed`"
    assert _broken(":class:`~semattnet.inference.sinks.BagSink` :class:`~.kitti_raw.RawDriveSource`", module) == [
        ":class:`~semattnet.inference.sinks.BagSink`",
        ":class:`~.kitti_raw.RawDriveSource`",
    ]
    assert _broken(good.replace(":func:`~.gate.Gate` ", ""), module) == []
    assert _broken(":meth:`~semattnet.evaluation.metrics.KittiMetrics.compute`", module) == []
    assert _broken(":meth:`~semattnet.evaluation.metrics.KittiMetrics.nothing`", module) != []
