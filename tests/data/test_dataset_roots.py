"""A dataset root one level too high (``nyu/`` holding ``nyudepthv2/``, a folder holding ``void_release/``) is
one line naming the folder to pass: in the reader, in ``data check`` and through ``evaluate``."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from semattnet._errors import DataError
from semattnet.cli import main
from semattnet.data.datasets import get_dataset
from tests.data._datasets import make_nyu, make_void

pytest.importorskip("h5py")


def test_nyu_root_one_level_too_high_names_the_folder(tmp_path: Path) -> None:
    inner = make_nyu(tmp_path / "nyu" / "nyudepthv2", train=1, test=1)
    with pytest.raises(DataError, match=f"pass {inner}$"):
        get_dataset("nyuv2").source(tmp_path / "nyu", "test")
    lines: list[str] = []
    assert get_dataset("nyuv2").check([tmp_path / "nyu"], log=lines.append) == 1
    assert sum(f"pass {inner}" in line for line in lines) == 1
    with pytest.raises(DataError, match="split folder not found"):  # nothing below either: as before
        get_dataset("nyuv2").source(tmp_path / "nyu" / "nyudepthv2" / "train", "test")


def test_void_root_one_level_too_high_names_the_folder(tmp_path: Path) -> None:
    release = make_void(tmp_path / "data" / "void_release", train=1, test=1, h=32, w=48)
    assert len(get_dataset("void").source(release, "test").names) == 1  # the release folder itself reads
    with pytest.raises(DataError, match=f"pass {release}$"):
        get_dataset("void").source(tmp_path / "data", "test")


def test_evaluate_with_a_root_too_high_is_one_line(tmp_path: Path) -> None:
    inner = make_nyu(tmp_path / "nyu" / "nyudepthv2", train=0, test=1)
    args = [
        "evaluate",
        "--dataset",
        "nyuv2",
        "--data",
        tmp_path / "nyu",
        "--method",
        "classical",
        "--sparsity",
        "keep=1",
        "--out",
        tmp_path / "o",
    ]
    res = CliRunner().invoke(main, [str(a) for a in args])
    assert res.exit_code == 1 and len(res.output.strip().splitlines()) == 1, res.output
    assert f"pass {inner}" in res.output and "Traceback" not in res.output
