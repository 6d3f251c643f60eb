"""A refusal about an option names the option, before any work and with nothing written: options that only mean
something with another one that is absent (``--camera``, ``--K``, ``--scan-period``), malformed numbers (``--T``,
``--K``), malformed frame specs (``--frames``) and a ``--mirror`` that is not a URL."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from semattnet._errors import DataError, InputError
from tests.reliability._helpers import cli as _cli
from tests.reliability._helpers import one_line as _one_line
from tests.reliability._helpers import rig as _rig
from tests.reliability._helpers import scan as _scan

T16 = "0,-1,0,0,0,0,-1,0,1,0,0,0,0,0,0,1"


def _tree(tmp_path: Path) -> None:
    from semattnet.data.io import write_depth, write_image

    write_image(tmp_path / "rgb" / "a.png", np.zeros((8, 12, 3), np.uint8))
    sparse = np.zeros((8, 12))
    sparse[4, 6] = 5.0
    write_depth(tmp_path / "sparse" / "a.png", sparse)


@pytest.mark.parametrize(
    ("extra", "named", "why"),
    [
        (["--camera", "3"], "--camera", "is an option of --kitti-raw"),
        (["--K", "kitti"], "--K", "only mean"),
        (["--K", "50,50,6,4"], "--K", "only mean"),
    ],
)
def test_predict_refuses_options_it_would_ignore(tmp_path: Path, extra: list[str], named: str, why: str) -> None:
    _tree(tmp_path)
    code, msg = _cli(
        tmp_path,
        "predict",
        "--method",
        "classical",
        "--rgb",
        tmp_path / "rgb",
        "--sparse",
        tmp_path / "sparse",
        "--out",
        tmp_path / "o",
        *extra,
    )
    assert code == 2 and named in msg and why in msg and not (tmp_path / "o").exists(), msg


@pytest.mark.parametrize(
    ("extra", "named"), [(["--scan-period", "0.2"], "--scan-period"), (["--camera", "3"], "--camera")]
)
def test_project_refuses_options_it_would_ignore(tmp_path: Path, extra: list[str], named: str) -> None:
    code, msg = _cli(
        tmp_path, "project", "--points", _scan(tmp_path), "--rig", _rig(tmp_path), "--out", tmp_path / "o.png", *extra
    )
    assert code == 2 and named in msg and not (tmp_path / "o.png").exists(), msg


@pytest.mark.parametrize(("args", "named"), [(["--T", ",".join(["1"] * 15)], "--T"), (["--K", "1,2,3"], "--K")])
def test_project_number_options_are_named(tmp_path: Path, args: list[str], named: str) -> None:
    base = {"--K": "50,50,16,12", "--T": T16}
    base[args[0]] = args[1]
    code, msg = _cli(
        tmp_path,
        "project",
        "--points",
        _scan(tmp_path),
        "--K",
        base["--K"],
        "--T",
        base["--T"],
        "--size",
        "32x24",
        "--out",
        tmp_path / "o.png",
    )
    assert code == 1 and msg.split(": ")[1].startswith(named), msg


@pytest.mark.parametrize("frames", ["0-5,abc", "-1", "3-1"])
def test_frame_specs_name_the_option(frames: str) -> None:
    from semattnet.data.kitti.raw import parse_frames

    assert "--frames" in _one_line(lambda: parse_frames(frames), DataError)


@pytest.mark.parametrize("mirror", ["not a url", "/some/folder", "ftp://host/x", ""])
def test_a_mirror_that_is_not_a_url_is_refused_first(tmp_path: Path, mirror: str) -> None:
    from semattnet.data.download import download_dataset

    msg = _one_line(lambda: download_dataset("void", tmp_path / "o", accept_license=True, mirror=mirror), InputError)
    assert "--mirror" in msg and not (tmp_path / "o").exists()
    code, msg = _cli(
        tmp_path,
        "data",
        "download",
        "--dataset",
        "void",
        "--accept-license",
        "--mirror",
        mirror,
        "--out",
        tmp_path / "o",
        "--cache-dir",
        tmp_path / "cache",
    )
    assert code == 1 and "--mirror" in msg and not (tmp_path / "o").exists(), msg
