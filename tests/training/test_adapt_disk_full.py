"""``adapt`` on a full disk: at its first state and at its final weights, one ``OSError`` line naming the file it
could not write (never torch's ``inline_container`` ``RuntimeError``), and no temporary file left. Needs root and
``mount -t tmpfs``; skipped otherwise."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import pytest

from semattnet.training.adapt import FINAL, STATE, adapt
from semattnet.training.adapt import run as adapt_run
from tests._helpers import mounted_tmpfs
from tests.training._adapt_runs import rt_checkpoint
from tests.training.test_adapt import _cfg, _Frames, _quiet

pytestmark = pytest.mark.filterwarnings("ignore:no semantic maps given")


@pytest.fixture
def tiny_fs(tmp_path: Path) -> Iterator[Path]:
    """64 KiB: the log fits, the first state (~550 KiB) does not."""
    yield from mounted_tmpfs(tmp_path / "fs", "64k")


@pytest.fixture
def roomy_fs(tmp_path: Path) -> Iterator[Path]:
    """2 MiB: the run's states fit."""
    yield from mounted_tmpfs(tmp_path / "fs", "2m")


@pytest.fixture(scope="module")
def weights(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return rt_checkpoint(tmp_path_factory.mktemp("rt-weights") / "rt.safetensors")


def _temps(folder: Path) -> list[Path]:
    return [p for p in folder.rglob(".*.p*") if p.is_file()]


def test_a_full_disk_at_the_first_state_is_one_line_naming_the_state(tiny_fs: Path, weights: Path) -> None:
    out = tiny_fs / "run"
    with pytest.raises(OSError) as info:
        adapt(_cfg(weights, out), _Frames(), log=_quiet)
    message = str(info.value)
    assert type(info.value) is OSError and "no space left" in message and "\n" not in message, message
    assert info.value.filename == str(out / STATE) and "inline_container" not in message, message
    assert not (out / STATE).exists() and not _temps(tiny_fs)


def test_a_full_disk_at_the_final_weights_is_one_line_naming_them(
    roomy_fs: Path, weights: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    write_final = adapt_run.Adapter._write_final

    def fill_then_write(self: adapt_run.Adapter) -> Path:
        fd = os.open(roomy_fs / "filler", os.O_WRONLY | os.O_CREAT)  # the disk fills after the last state
        try:
            while os.write(fd, b"\0" * 4096):
                pass
        except OSError:
            pass
        finally:
            os.close(fd)
        return write_final(self)

    monkeypatch.setattr(adapt_run.Adapter, "_write_final", fill_then_write)
    out = roomy_fs / "run"
    with pytest.raises(OSError) as info:
        adapt(_cfg(weights, out), _Frames(), log=_quiet)
    message = str(info.value)
    assert "no space left" in message and info.value.filename == str(out / FINAL) and "\n" not in message, message
    assert (out / STATE).is_file() and not (out / FINAL).exists() and not _temps(roomy_fs)
