"""Fixtures shared by the reliability tests."""

from __future__ import annotations

import os
import signal
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest


@pytest.fixture
def small_fs(tmp_path: Path) -> Iterator[Path]:
    """A 256 KiB tmpfs at ``tmp_path/fs``: a disk that fills up (needs root and ``mount``; skipped otherwise)."""
    fs = tmp_path / "fs"
    fs.mkdir()
    if os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs needs root")
    res = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(fs)], capture_output=True)
    if res.returncode != 0:
        pytest.skip(f"mount -t tmpfs failed: {res.stderr.decode(errors='replace').strip()}")
    try:
        yield fs
    finally:
        subprocess.run(["umount", "-l", str(fs)], check=False)


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
