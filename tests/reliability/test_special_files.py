"""A special file (a FIFO, a device, a folder) where a regular file belongs is refused without being opened: by
every reader of a file, for the command line's inputs, as a pretrained folder's ``config.json`` and behind a
``file://`` URL. Each refusal is one line naming the file, and nothing is changed."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from tests.reliability._helpers import cli as _cli
from tests.reliability._helpers import one_line as _one_line

pytestmark = pytest.mark.usefixtures("no_hang")


def _special(path: Path, kind: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "device":
        path.symlink_to("/dev/zero")
    else:
        path.mkdir()
    return path


def _readers() -> dict[str, Callable[[Path], object]]:
    from semattnet.data.io import read_depth, read_image
    from semattnet.geometry import read_oxts_motion, read_points, read_rig_json
    from semattnet.geometry.calibration import read_cam_to_cam
    from semattnet.training.config import TrainConfig
    from semattnet.weights import load_checkpoint

    return {
        "a.png": read_image,
        "d.png": read_depth,
        "s.bin": read_points,
        "rig.json": read_rig_json,
        "calib_cam_to_cam.txt": read_cam_to_cam,
        "oxts.txt": read_oxts_motion,
        "w.pt": load_checkpoint,
        "config.json": TrainConfig.load,
    }


@pytest.mark.parametrize("kind", ["fifo", "device", "folder"])
@pytest.mark.parametrize("name", sorted(_readers()))
def test_every_reader_refuses_special_files_without_opening_them(tmp_path: Path, name: str, kind: str) -> None:
    path = _special(tmp_path / name, kind)
    msg = _one_line(lambda: _readers()[name](path))
    assert str(path) in msg and ("a FIFO" in msg or "device" in msg or "folder" in msg), msg


@pytest.mark.parametrize("kind", ["fifo", "device"])
def test_cli_inputs_that_are_special_files(tmp_path: Path, kind: str) -> None:
    from semattnet.data.io import write_depth

    _special(tmp_path / "cfg.json", kind)
    code, msg = _cli(tmp_path, "train", "--data", tmp_path, "--config", tmp_path / "cfg.json", "--out", tmp_path / "r")
    assert code == 1 and "cfg.json" in msg, msg
    write_depth(tmp_path / "pred" / "a.png", np.full((4, 6), 5.0))
    _special(tmp_path / "gt" / "a.png", kind)
    code, msg = _cli(tmp_path, "metrics", tmp_path / "pred", tmp_path / "gt")
    assert code == 1 and "gt/a.png" in msg, msg


@pytest.mark.parametrize("kind", ["fifo", "device", "folder"])
def test_a_pretrained_folder_with_a_special_config_is_refused(tmp_path: Path, kind: str) -> None:
    import semattnet
    from tests.inference._raw_sample import tiny_checkpoint

    tiny_checkpoint(tmp_path / "pre" / "model.safetensors")
    _special(tmp_path / "pre" / "config.json", kind)
    msg = _one_line(lambda: semattnet.from_pretrained(tmp_path / "pre"))
    assert "config.json" in msg and "not a regular" in msg, msg


@pytest.mark.parametrize("kind", ["fifo", "device"])
def test_a_file_url_of_a_special_file_is_refused(tmp_path: Path, kind: str) -> None:
    from semattnet.weights import fetch_weights

    src = _special(tmp_path / "remote.bin", kind)
    assert "not a regular" in _one_line(
        lambda: fetch_weights(src.as_uri(), cache_dir=tmp_path / "cache", progress=False)
    )
    assert not [p for p in (tmp_path / "cache").rglob("*.part")]
