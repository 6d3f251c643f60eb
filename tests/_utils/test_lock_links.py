"""A lock file that is a link (symbolic, or hard: a file with another name) or not a regular file is refused in one
line and never opened for writing: the file it leads to keeps its bytes, whichever run (``predict``, ``adapt``)
takes the lock."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from semattnet._errors import SemAttNetError
from semattnet._utils.lock import LOCK_FILE, FolderLock, LockFileError
from semattnet.data.io import write_depth, write_image
from semattnet.data.sources import FolderSource
from semattnet.inference.pipeline import check_frames
from semattnet.inference.sinks import default_sinks

KEEP = b"a user's file: never truncated, never rewritten\n"


def _user_file(tmp_path: Path) -> Path:
    path = tmp_path / "mine.txt"
    path.write_bytes(KEEP)
    return path


def _refusal(out: Path, what: str) -> str:
    with pytest.raises(LockFileError) as info:
        FolderLock(out).acquire()
    message = str(info.value)
    assert isinstance(info.value, SemAttNetError) and "\n" not in message, message
    assert str(out / LOCK_FILE) in message and what in message, message
    return message


def test_a_lock_file_hard_linked_to_a_users_file_is_refused_and_the_file_kept(tmp_path: Path) -> None:
    mine, out = _user_file(tmp_path), tmp_path / "out"
    out.mkdir()
    os.link(mine, out / LOCK_FILE)
    _refusal(out, "hard link")
    assert mine.read_bytes() == KEEP and (out / LOCK_FILE).read_bytes() == KEEP
    assert os.stat(mine).st_nlink == 2  # the link is the user's to remove: left as it was


def test_a_lock_file_that_is_a_symbolic_link_is_refused_and_its_target_kept(tmp_path: Path) -> None:
    mine, out = _user_file(tmp_path), tmp_path / "out"
    out.mkdir()
    (out / LOCK_FILE).symlink_to(mine)
    _refusal(out, "symbolic link")
    assert mine.read_bytes() == KEEP and (out / LOCK_FILE).is_symlink()


def test_a_dangling_symbolic_lock_file_is_refused_and_nothing_created_where_it_points(tmp_path: Path) -> None:
    out, target = tmp_path / "out", tmp_path / "elsewhere.txt"
    out.mkdir()
    (out / LOCK_FILE).symlink_to(target)
    _refusal(out, "symbolic link")
    assert not target.exists()


def test_a_lock_file_that_is_a_fifo_or_a_folder_is_refused(tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    os.mkfifo(out / LOCK_FILE)
    _refusal(out, "not a regular file")
    (out / LOCK_FILE).unlink()
    (out / LOCK_FILE).mkdir()
    _refusal(out, "folder")


def test_a_plain_lock_file_left_by_a_killed_run_is_still_taken_over(tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / LOCK_FILE).write_text("999999999\n")
    lock = FolderLock(out).acquire()
    assert (out / LOCK_FILE).read_text() == f"{os.getpid()}\n"
    lock.release()
    assert not (out / LOCK_FILE).exists()


def test_predict_into_a_folder_whose_lock_is_a_hard_link_refuses_before_any_work(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    write_image(tmp_path / "rgb" / "f0.png", rng.integers(0, 255, (24, 32, 3), dtype=np.uint8))
    write_depth(tmp_path / "sparse" / "f0.png", np.full((24, 32), 5.0, np.float32))
    source = FolderSource.pair(tmp_path / "rgb", tmp_path / "sparse")
    mine, out = _user_file(tmp_path), tmp_path / "out"
    out.mkdir()
    os.link(mine, out / LOCK_FILE)
    with pytest.raises(LockFileError, match="hard link"):
        check_frames(source, default_sinks(), out)
    assert mine.read_bytes() == KEEP and {p.name for p in out.iterdir()} == {LOCK_FILE}
