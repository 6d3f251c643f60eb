"""The fused propagation kernel's first build: said once with its time, a killed build's lock removed (not waited
on forever), no compiler -> the PyTorch propagation with one line. torch's build itself is faked: these tests take
milliseconds and never compile."""

from __future__ import annotations

import os
import time
from pathlib import Path
from types import SimpleNamespace

import pytest
import torch

from semattnet._utils import cpp_build
from semattnet.models.propagation import cpu_kernel


@pytest.fixture
def fresh(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> list[Path]:
    """The kernel not loaded yet, its build folder ``tmp_path`` (empty), torch's ``load_inline`` faked; the list
    gets the build folder at each (fake) build, checked for a lock then."""
    calls: list[Path] = []

    def load_inline(**kwargs: object) -> object:
        assert not (tmp_path / "lock").exists(), "torch would wait on this lock forever"
        calls.append(tmp_path)
        return object()

    monkeypatch.setattr(cpu_kernel.KERNEL, "module", None)
    monkeypatch.setattr(cpu_kernel.KERNEL, "failed", None)
    monkeypatch.setattr(cpu_kernel.KERNEL, "build_dir", lambda: tmp_path)
    monkeypatch.setattr("torch.utils.cpp_extension.load_inline", load_inline)
    monkeypatch.delenv("SEMATTNET_NO_CPP", raising=False)
    monkeypatch.setenv("CXX", "c++")
    monkeypatch.setattr(cpp_build.shutil, "which", lambda name: f"/usr/bin/{name}")
    return calls


def test_the_first_build_is_said_once_with_its_time(fresh: list[Path], capsys: pytest.CaptureFixture[str]) -> None:
    assert cpu_kernel.available() and cpu_kernel.available()
    err = capsys.readouterr().err.splitlines()
    assert len(fresh) == 1 and len(err) == 2, err
    assert "building the fused CPU propagation kernel" in err[0]
    assert err[1].startswith("semattnet: built the fused CPU propagation kernel in ") and " s (" in err[1]


def test_a_killed_builds_lock_is_removed(fresh: list[Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    lock = tmp_path / "lock"
    lock.touch()
    old = time.time() - 2 * cpp_build.STALE_LOCK_S
    os.utime(lock, (old, old))
    assert cpu_kernel.available() and fresh == [tmp_path] and not lock.exists()
    assert f"removing {lock}, left by a build that was killed" in capsys.readouterr().err


def test_a_running_builds_lock_is_waited_for_a_bounded_time(
    fresh: list[Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(cpu_kernel.KERNEL, "stale_lock_s", 0.3)
    (tmp_path / "lock").touch()
    start = time.monotonic()
    assert cpu_kernel.available()
    assert 0.2 < time.monotonic() - start < 5


def test_no_compiler_falls_back_with_one_line(
    fresh: list[Path], monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(cpp_build.shutil, "which", lambda name: None)
    monkeypatch.setenv("CXX", "g++-missing")
    assert not cpu_kernel.available() and fresh == []
    err = capsys.readouterr().err
    assert err == (
        "semattnet: the fused CPU propagation kernel is unavailable (no C++ compiler (g++-missing not found; "
        "install one or set CXX)); using the PyTorch propagation\n"
    )
    with pytest.raises(RuntimeError, match=r"no C\+\+ compiler"):
        cpu_kernel.normalize_affinity(torch.zeros(1, 8, 2, 2))


def test_each_compilation_is_said_once(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """``torch.compile`` (faked: no compilation) of the CUDA propagation: one line before and one after the first
    call at each size, nothing at a size seen."""
    from semattnet.inference.backends import compiled_propagation as cp

    monkeypatch.setattr(torch, "compile", lambda fn, **kw: lambda heads, it: (heads.depth, heads.depth))
    cp.compiled_propagation.cache_clear()
    try:
        run = cp.compiled_propagation("test-mode")
        heads = [SimpleNamespace(depth=torch.zeros(1, 1, h, 8)) for h in (4, 4, 6)]
        for h in heads:
            run(h, 3)  # type: ignore[arg-type]
    finally:
        cp.compiled_propagation.cache_clear()
    err = capsys.readouterr().err.splitlines()
    assert [line.split(" (")[0].split(" in ")[0] for line in err] == [
        "semattnet: compiling the propagation for 4x8, 3 iteration(s)",
        "semattnet: compiled the propagation",
        "semattnet: compiling the propagation for 6x8, 3 iteration(s)",
        "semattnet: compiled the propagation",
    ]
