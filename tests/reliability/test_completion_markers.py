"""Generated trees (synth, data download) carry a completion marker written last: a tree cut short (kill -9,
a failure) is refused by ``data check`` with one line saying how to finish it, and a rerun says how to resume."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest
from click.testing import CliRunner

from semattnet._utils.outputs import TREE_MARKER, incomplete_tree, mark_tree
from semattnet.cli import main


def _invoke(*args: object) -> tuple[int, str]:
    res = CliRunner().invoke(main, [str(a) for a in args])
    assert not isinstance(res.exception, AssertionError)
    return res.exit_code, res.output


def test_marker_states(tmp_path: Path) -> None:
    assert incomplete_tree(tmp_path) is None  # a tree we did not generate: checked as before
    mark_tree(tmp_path, "synth", False, resume="run synth again with --overwrite")
    msg = incomplete_tree(tmp_path)
    assert msg is not None and "incomplete" in msg and "--overwrite" in msg and "\n" not in msg
    mark_tree(tmp_path, "synth", True)
    assert incomplete_tree(tmp_path) is None
    for garbage in ("{", "[]", '{"complete": "yes"}'):
        (tmp_path / TREE_MARKER).write_text(garbage)
        assert incomplete_tree(tmp_path) is not None


def test_synth_writes_the_marker_last_and_check_accepts_it(tmp_path: Path) -> None:
    code, out = _invoke(
        "synth", "--out", tmp_path / "t", "--frames", 2, "--eval-frames", 2, "--size", "32x64", "--workers", 1
    )
    assert code == 0, out
    assert json.loads((tmp_path / "t" / TREE_MARKER).read_text())["complete"] is True
    code, out = _invoke("data", "check", tmp_path / "t")
    assert code == 0, out
    (tmp_path / "t" / TREE_MARKER).write_text(json.dumps({"generator": "synth", "complete": False}))
    code, out = _invoke("data", "check", tmp_path / "t")
    assert code == 1 and "incomplete tree" in out, out


def test_synth_killed_with_sigkill_is_refused_then_regenerated(tmp_path: Path) -> None:
    out = tmp_path / "t"
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    cmd = [
        sys.executable,
        "-m",
        "semattnet",
        "synth",
        "--out",
        str(out),
        "--frames",
        "400",
        "--size",
        "64x128",
        "--workers",
        "1",
    ]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        while not list(out.rglob("*.png")) and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.05)
        assert proc.poll() is None, "synth ended before it could be killed"
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait()
    assert list(out.rglob("*.png")) and not (out / "scenes.json").exists()
    code, text = _invoke("data", "check", out)
    assert code == 1 and "incomplete tree" in text and "--overwrite" in text, text
    code, text = _invoke("synth", "--out", out, "--frames", 2, "--eval-frames", 2, "--size", "32x64", "--workers", 1)
    assert code == 1 and "incomplete tree" in text and "--overwrite" in text and "Traceback" not in text, text
    code, text = _invoke(
        "synth", "--out", out, "--frames", 2, "--eval-frames", 2, "--size", "32x64", "--workers", 1, "--overwrite"
    )
    assert code == 0, text
    code, text = _invoke("data", "check", out)
    assert code == 0, text


def test_a_failed_download_leaves_an_incomplete_tree_and_a_rerun_completes_it(tmp_path: Path) -> None:
    from semattnet.data.archives import ArchiveConflictError
    from semattnet.data.download import download_dataset

    mirror = tmp_path / "mirror"
    mirror.mkdir()
    from semattnet.data.datasets import get_dataset

    spec = get_dataset("void")
    for a in spec.archives:
        with zipfile.ZipFile(mirror / a.file, "w") as zf:
            zf.writestr("void/readme.txt", "hello")
    out = tmp_path / "out"
    (out / "void").mkdir(parents=True)
    (out / "void" / "readme.txt").write_text("the user's own file, other size")
    kw = {
        "accept_license": True,
        "mirror": mirror.as_uri(),
        "cache_dir": tmp_path / "cache",
        "check": False,
        "progress": False,
        "log": lambda s: None,
    }
    with pytest.raises(ArchiveConflictError):
        download_dataset("void", out, **kw)
    assert (out / "void" / "readme.txt").read_text() == "the user's own file, other size"
    msg = incomplete_tree(out)
    assert msg is not None and "data download" in msg and "again" in msg
    (out / "void" / "readme.txt").unlink()
    download_dataset("void", out, **kw)
    assert incomplete_tree(out) is None
