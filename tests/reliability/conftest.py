"""Fixtures shared by the reliability tests."""

from __future__ import annotations

import signal
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests._helpers import mounted_tmpfs


@pytest.fixture
def small_fs(tmp_path: Path) -> Iterator[Path]:
    """A 256 KiB tmpfs at ``tmp_path/fs``: a disk that fills up (needs root and ``mount``; skipped otherwise)."""
    yield from mounted_tmpfs(tmp_path / "fs", "256k")


@pytest.fixture
def no_hang() -> Iterator[None]:
    """A reader that opened a FIFO would block forever: fail the test after 20 s instead."""

    def fail(*_: object) -> None:
        raise TimeoutError("blocked: a special file was opened")

    old = signal.signal(signal.SIGALRM, fail)
    signal.alarm(20)
    yield
    signal.alarm(0)
    signal.signal(signal.SIGALRM, old)
