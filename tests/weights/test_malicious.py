"""Hostile weight files: TorchScript archives and code-running pickles are refused before anything runs.

Each hostile file is first shown to be live (the unguarded loader runs it and the marker appears),
then shown to be refused by every entry point with the marker absent.
"""

from __future__ import annotations

import functools
import os
import pathlib
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from semattnet.weights import from_pretrained
from semattnet.weights.checkpoint import UnsafeCheckpointError, load_checkpoint
from semattnet.weights.hub import load_model

MARKER = "SEMATTNET_TS_MARKER"
SRC = str(Path(__file__).resolve().parents[2] / "src")


class _Hostile(torch.nn.Module):
    """Scripted module whose TorchScript ``__setstate__`` prints a marker when the archive is loaded."""

    def __init__(self) -> None:
        super().__init__()
        self.n = 1

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x * self.n

    @torch.jit.export
    def __getstate__(self) -> tuple[int, bool]:
        return (self.n, self.training)

    @torch.jit.export
    def __setstate__(self, state: tuple[int, bool]) -> None:
        print("SEMATTNET_TS_MARKER")
        self.n = state[0]
        self.training = state[1]


@pytest.fixture(scope="module")
def torchscript_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("ts") / "model.pth.tar"
    torch.jit.script(_Hostile()).save(str(path))
    return path


@pytest.fixture
def no_deserialiser(monkeypatch: pytest.MonkeyPatch) -> None:
    """Fail the test if the refusal comes after torch.load / torch.jit.load was called."""

    def boom(*args: object, **kwargs: object) -> None:
        pytest.fail("a deserialiser ran before the gate refused the file")

    monkeypatch.setattr(torch.jit, "load", boom)
    monkeypatch.setattr(torch, "load", boom)


def test_torchscript_fixture_is_live(torchscript_file: Path, capfd: pytest.CaptureFixture[str]) -> None:
    torch.jit.load(str(torchscript_file))
    assert MARKER in capfd.readouterr().out  # the unguarded loader runs the archive's code


@pytest.mark.parametrize("loader", ["load_checkpoint", "load_model", "from_pretrained", "from_pretrained_str"])
def test_torchscript_is_refused_before_loading(
    torchscript_file: Path, loader: str, no_deserialiser: None, capfd: pytest.CaptureFixture[str]
) -> None:
    call = {
        "load_checkpoint": lambda: load_checkpoint(torchscript_file),
        "load_model": lambda: load_model(torchscript_file),
        "from_pretrained": lambda: from_pretrained(torchscript_file),
        "from_pretrained_str": lambda: from_pretrained(str(torchscript_file)),
    }[loader]
    with pytest.raises(UnsafeCheckpointError, match="TorchScript archives are not loaded as weights") as err:
        call()
    assert str(torchscript_file) in str(err.value) and "\n" not in str(err.value)
    assert MARKER not in capfd.readouterr().out


def test_torchscript_named_safetensors_in_a_folder_is_refused(
    tmp_path: Path, torchscript_file: Path, no_deserialiser: None, capfd: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "model.safetensors").write_bytes(torchscript_file.read_bytes())
    with pytest.raises(UnsafeCheckpointError, match="TorchScript"):
        from_pretrained(tmp_path)
    assert MARKER not in capfd.readouterr().out


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": SRC}
    return subprocess.run(
        [sys.executable, "-m", "semattnet.cli", *args], capture_output=True, text=True, env=env, timeout=300
    )


def test_cli_info_refuses_torchscript_in_one_line(torchscript_file: Path) -> None:
    res = _cli("info", str(torchscript_file))
    assert res.returncode == 1
    assert MARKER not in res.stdout + res.stderr
    assert "Traceback" not in res.stderr
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "TorchScript" in lines[0] and str(torchscript_file) in lines[0]


# ----------------------------------------------------------------------------- pickle payloads


class _Reduce:
    """Pickles as ``func(*args)``."""

    def __init__(self, func: object, args: tuple) -> None:
        self.func, self.args = func, args

    def __reduce__(self) -> tuple:
        return (self.func, self.args)

    def __call__(self) -> None:  # so that pickle accepts it as the callable of another reduce
        raise AssertionError


def _payloads(marker: Path, inner: Path, ts: Path) -> dict[str, object]:
    m = str(marker)
    return {
        "os.system": _Reduce(os.system, (f"touch {m}",)),
        "eval": _Reduce(eval, (f"open({m!r}, 'w').write('x')",)),
        "exec": _Reduce(exec, (f"open({m!r}, 'w').write('x')",)),
        "subprocess": _Reduce(subprocess.call, (["touch", m],)),
        "getattr-chain": _Reduce(_Reduce(getattr, (pathlib.Path(m), "touch")), ()),
        "nested-torch.load": _Reduce(functools.partial(torch.load, weights_only=False), (str(inner),)),
        "nested-torch.jit.load": _Reduce(torch.jit.load, (str(ts),)),
    }


PAYLOADS = ["os.system", "eval", "exec", "subprocess", "getattr-chain", "nested-torch.load", "nested-torch.jit.load"]
FORMATS = ["zip", "legacy"]


def _write(tmp_path: Path, payload: str, fmt: str, ts: Path) -> tuple[Path, Path]:
    marker = tmp_path / "marker"
    inner = tmp_path / "inner.pt"
    torch.save({"x": _Reduce(os.system, (f"touch {marker}",))}, inner)
    obj = {"model": {"w": torch.zeros(3)}, "payload": _payloads(marker, inner, ts)[payload]}
    path = tmp_path / f"{payload}-{fmt}.pth"
    torch.save(obj, path, _use_new_zipfile_serialization=fmt == "zip")
    return path, marker


@pytest.mark.parametrize("payload", PAYLOADS)
def test_payload_is_live(tmp_path: Path, payload: str, torchscript_file: Path, capfd) -> None:
    path, marker = _write(tmp_path, payload, "zip", torchscript_file)
    torch.load(path, weights_only=False)  # the unguarded loader runs it
    assert marker.exists() or MARKER in capfd.readouterr().out


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("payload", PAYLOADS)
def test_payload_is_refused(tmp_path: Path, payload: str, fmt: str, torchscript_file: Path, capfd) -> None:
    path, marker = _write(tmp_path, payload, fmt, torchscript_file)
    with pytest.raises(UnsafeCheckpointError) as err:
        load_checkpoint(path)
    assert str(err.value).startswith(str(path)) and "\n" not in str(err.value)
    assert not marker.exists()
    assert MARKER not in capfd.readouterr().out


@pytest.mark.parametrize("fmt", FORMATS)
def test_payload_is_refused_by_from_pretrained(tmp_path: Path, fmt: str, torchscript_file: Path) -> None:
    path, marker = _write(tmp_path, "os.system", fmt, torchscript_file)
    with pytest.raises(UnsafeCheckpointError):
        from_pretrained(path)
    assert not marker.exists()


def test_protocol_4_pickle_goes_through_the_safe_unpickler(tmp_path: Path, torchscript_file: Path) -> None:
    """torch's weights_only unpickler cannot read protocol 4; the project's unpickler refuses the payload."""
    marker = tmp_path / "marker"
    path = tmp_path / "p4.pth"
    torch.save(
        {"model": {"w": torch.zeros(3)}, "x": _Reduce(os.system, (f"touch {marker}",))},
        path,
        _use_new_zipfile_serialization=False,
        pickle_protocol=4,
    )
    with pytest.raises(UnsafeCheckpointError, match="os.system|posix.system"):
        load_checkpoint(path)
    assert not marker.exists()
