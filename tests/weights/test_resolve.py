"""The one resolver: every weights spec (name, file, folder, URL) is read by ``parse_weights_spec``, and the
modules of ``weights/`` import one another without a cycle."""

from __future__ import annotations

import ast
import json
from pathlib import Path

import pytest
import torch

from semattnet.weights import (
    ShadowedNameWarning,
    WeightsSpecError,
    from_pretrained,
    get_weights,
    load_model,
    parse_weights_spec,
    resolve_weights,
    save_pretrained,
)

REPO = Path(__file__).resolve().parents[2]
SRC = REPO / "src" / "semattnet"
#: Where a weights spec is parsed: the one parser. The cache (URLs of any file) and data (archive mirrors)
#: never see a weights spec.
PARSER = ("weights/resolve.py", "parse_weights_spec")
NOT_WEIGHTS = ("cache/", "data/")


def _spec_tests(tree: ast.AST) -> list[tuple[int, str]]:
    """(line, what) of each expression that tells weights specs apart: ``"://" in x``, membership in
    ``list_pretrained()``, and calls of an ``is_url``."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare) and any(isinstance(op, ast.In | ast.NotIn) for op in node.ops):
            sides = [node.left, *node.comparators]
            if any(isinstance(s, ast.Constant) and s.value == "://" for s in sides):
                found.append((node.lineno, '"://" in'))
            if any(
                isinstance(s, ast.Call) and getattr(s.func, "id", getattr(s.func, "attr", "")) == "list_pretrained"
                for s in sides
            ):
                found.append((node.lineno, "in list_pretrained()"))
        if isinstance(node, ast.Call) and getattr(node.func, "id", getattr(node.func, "attr", "")) == "is_url":
            found.append((node.lineno, "is_url("))
    return found


def _functions(tree: ast.AST) -> dict[int, str]:
    """Line -> name of the function that holds it."""
    lines: dict[int, str] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef):
            for inner in ast.walk(node):
                if hasattr(inner, "lineno"):
                    lines.setdefault(inner.lineno, node.name)
    return lines


def test_the_detector_sees_each_kind_of_spec_test() -> None:
    source = 'def f(s):\n    return "://" in s or s in list_pretrained() or w.is_url(s)\n'
    assert [what for _, what in _spec_tests(ast.parse(source))] == ['"://" in', "in list_pretrained()", "is_url("]


def test_one_function_parses_weight_specs() -> None:
    """grep, as the issue asks: no spec test outside ``parse_weights_spec`` (and it has them all)."""
    outside, inside = [], []
    files = [*SRC.rglob("*.py"), REPO / "hubconf.py"]
    for path in files:
        rel = path.relative_to(SRC).as_posix() if path.is_relative_to(SRC) else path.name
        if rel.startswith(NOT_WEIGHTS):
            continue
        tree = ast.parse(path.read_text())
        functions = _functions(tree)
        for line, what in _spec_tests(tree):
            where = (rel, functions.get(line))
            (inside if where == PARSER else outside).append(f"{rel}:{line}: {what} in {where[1]}")
    assert outside == []
    assert any('"://" in' in s for s in inside) and any("list_pretrained()" in s for s in inside), inside
    assert not any("resolve_weights_file" in p.read_text() for p in files)


def test_each_kind_of_spec(tmp_path: Path, tiny_model: torch.nn.Module) -> None:
    entry = get_weights("semattnet-demo-ref-seed0")
    assert parse_weights_spec("semattnet-demo-ref-seed0") is entry
    assert parse_weights_spec(entry) is entry
    assert parse_weights_spec("hf://owner/repo") == "hf://owner/repo"  # a URL: nothing fetched yet
    assert parse_weights_spec("gdrive://abc") == "gdrive://abc"
    folder = save_pretrained(tiny_model, tmp_path / "folder")
    assert parse_weights_spec(str(folder)) == folder and parse_weights_spec(folder) == folder
    with pytest.raises(WeightsSpecError, match="semattnet-demo-ref-seed1") as err:
        parse_weights_spec(str(tmp_path / "missing.safetensors"))
    assert "missing.safetensors" in str(err.value) and "\n" not in str(err.value)


def test_a_shipped_name_resolves_to_its_packed_file_and_record() -> None:
    resolved = resolve_weights("semattnet-demo-ref-seed1")
    entry = get_weights("semattnet-demo-ref-seed1")
    assert resolved.entry is entry and resolved.config == entry.model_config() and resolved.cache_root is None
    assert resolved.file.name == entry.file_name and resolved.file.stat().st_size == entry.size_bytes
    model = from_pretrained("semattnet-demo-ref-seed1")
    assert model.config.width == 0.125 and not model.training


def test_a_local_folder_named_like_a_registry_name_never_shadows_it(
    tmp_path: Path, tiny_model: torch.nn.Module, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    name = "semattnet-demo-ref-seed1"
    monkeypatch.chdir(tmp_path)
    save_pretrained(tiny_model, tmp_path / name)
    with pytest.warns(ShadowedNameWarning, match=f"the registered weights are used.*pass ./{name}"):
        resolved = resolve_weights(name)
    assert resolved.entry is get_weights(name)  # the registry's, as the name says
    local = resolve_weights(f"./{name}")  # the folder: asked for as a path
    assert local.entry is None and local.path.resolve() == (tmp_path / name).resolve()
    from semattnet.cli._options import WEIGHTS_SPEC

    capsys.readouterr()
    assert WEIGHTS_SPEC.convert(name, None, None) == name  # what every --weights does first
    notes = capsys.readouterr().err.splitlines()
    assert notes == [
        f"note: weights {name!r}: the registered weights are used, not the local {name} here (pass "
        f"./{name} for that one)"
    ]


def test_load_model_takes_a_folder_with_its_config(tmp_path: Path, tiny_model: torch.nn.Module) -> None:
    """A folder's config.json is read, not dropped: a field the tensors cannot tell (refinement_mode) survives."""
    folder = save_pretrained(tiny_model, tmp_path / "folder", config=tiny_model.config.replace(refinement_mode="clean"))
    resolved = resolve_weights(folder)
    assert resolved.file == folder / "model.safetensors" and resolved.config is not None
    assert resolved.config.refinement_mode == "clean"
    model = load_model(folder)
    assert model.config.refinement_mode == "clean" and model.config.iterations == tiny_model.config.iterations
    sd = model.state_dict()
    assert all(torch.equal(sd[k], v) for k, v in tiny_model.state_dict().items())
    meta = json.loads((folder / "config.json").read_text())
    meta["width"] = 0.25  # a config.json that contradicts the tensors is refused, naming the weights
    (folder / "config.json").write_text(json.dumps(meta))
    with pytest.raises(Exception, match="contradicts the weights"):
        load_model(folder)


def _imports(path: Path, package: str, modules: set[str]) -> set[str]:
    """The modules of ``package`` that ``path`` imports (top level or inside functions)."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name in modules}
        elif isinstance(node, ast.ImportFrom) and node.module:
            subs = {f"{node.module}.{a.name}" for a in node.names} & modules
            out |= subs or ({node.module} & modules)
    return out


def test_no_import_cycle_inside_weights() -> None:
    """No module of weights/ imports one that imports it back, directly or through others, at any depth."""
    folder = SRC / "weights"
    names = {p.stem: p for p in folder.glob("*.py")}
    modules = {f"semattnet.weights.{n}" if n != "__init__" else "semattnet.weights" for n in names}
    graph = {
        (f"semattnet.weights.{n}" if n != "__init__" else "semattnet.weights"): _imports(p, "weights", modules)
        for n, p in names.items()
    }
    assert graph["semattnet.weights.hub"] >= {"semattnet.weights.resolve"}  # the graph sees the imports

    def reach(start: str) -> set[str]:
        seen, todo = set(), list(graph[start])
        while todo:
            m = todo.pop()
            if m not in seen:
                seen.add(m)
                todo += graph.get(m, set())
        return seen

    cycles = sorted(m for m in graph if m in reach(m))
    assert cycles == []
