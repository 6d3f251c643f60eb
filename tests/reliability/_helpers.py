"""Helpers shared by the reliability tests: the CLI run that must change nothing and say one line, a one-line
error from a call, and a tiny LiDAR scan with its rig."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from semattnet._errors import SemAttNetError
from semattnet.cli import main

RIG = {
    "K": [[50, 0, 16], [0, 50, 12], [0, 0, 1]],
    "T_cam_lidar": [[0, -1, 0, 0], [0, 0, -1, 0], [1, 0, 0, 0], [0, 0, 0, 1]],
    "image_size": [32, 24],
}


def hashes(root: Path) -> dict[str, str]:
    """sha256 of every regular file under ``root`` (symlinks left out), by relative path."""
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file() and not p.is_symlink()
    }


def cli(root: Path, *args: object) -> tuple[int, str]:
    """Run the CLI; assert no traceback, one message line and every file under ``root`` unchanged."""
    before = hashes(root)
    res = CliRunner().invoke(main, [str(a) for a in args])
    assert res.exception is None or isinstance(res.exception, SystemExit), repr(res.exception)
    err = [x for x in res.output.splitlines() if x.strip() and not x.startswith(("Usage: ", "Try '"))]
    assert "Traceback" not in res.output and len(err) == 1, res.output
    assert hashes(root) == before
    return res.exit_code, err[0]


def one_line(fn: Callable[[], object], cls: type[Exception] = SemAttNetError) -> str:
    """The message of the ``cls`` that ``fn()`` raises, asserted to be one line."""
    with pytest.raises(cls) as err:
        fn()
    assert "\n" not in str(err.value)
    return str(err.value)


def rig(tmp_path: Path) -> Path:
    """``tmp_path/rig.json``: a 32x24 pinhole camera looking along the LiDAR's x axis."""
    (tmp_path / "rig.json").write_text(json.dumps(RIG))
    return tmp_path / "rig.json"


def scan(tmp_path: Path, pts: list[list[float]] | None = None) -> Path:
    """``tmp_path/scan.npy``: ``pts`` (default two points 5-6 m ahead) as float32."""
    np.save(tmp_path / "scan.npy", np.array(pts or [[5.0, 0, 0], [6.0, 0.5, 0.2]], np.float32))
    return tmp_path / "scan.npy"
