"""The output policy: umask modes, orphaned temp files, staging, input overlap, submit ownership."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from semattnet._utils.atomic import atomic_path
from semattnet._utils.outputs import OutputError, check_no_input_overlap, staged_outputs
from semattnet.evaluation.submission import SubmissionError, write_submission_files


def test_atomic_files_follow_the_umask(tmp_path: Path) -> None:
    old = os.umask(0o022)
    try:
        with atomic_path(tmp_path / "a.txt") as tmp:
            tmp.write_text("x")
    finally:
        os.umask(old)
    assert (tmp_path / "a.txt").stat().st_mode & 0o777 == 0o644


def test_orphaned_temp_files_are_cleaned_on_the_next_write(tmp_path: Path) -> None:
    orphan = tmp_path / ".last.pt.p999999999.abcd1234"  # a killed process's temp file
    orphan.write_bytes(b"0" * 100)
    unrelated = tmp_path / ".last.pt.notes"
    unrelated.write_text("keep")
    with atomic_path(tmp_path / "last.pt") as tmp:
        tmp.write_bytes(b"new")
    assert not orphan.exists() and unrelated.exists() and (tmp_path / "last.pt").read_bytes() == b"new"


def test_a_failed_staged_write_leaves_the_folder_unchanged(tmp_path: Path) -> None:
    (tmp_path / "keep.txt").write_text("x")
    with pytest.raises(RuntimeError), staged_outputs(tmp_path) as stage:
        (stage / "frame1.png").write_text("1")
        raise RuntimeError("frame 2 is corrupt")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.txt"]
    with pytest.raises(FileExistsError), staged_outputs(tmp_path) as stage:
        (stage / "keep.txt").write_text("y")
    assert (tmp_path / "keep.txt").read_text() == "x"


def test_outputs_never_go_into_inputs(tmp_path: Path) -> None:
    (tmp_path / "in").mkdir()
    (tmp_path / "in" / "a.png").write_text("x")
    for out in (tmp_path / "in", tmp_path / "in" / "sub"):
        with pytest.raises(OutputError):
            check_no_input_overlap([tmp_path / "in"], out_dir=out)
    with pytest.raises(OutputError):
        check_no_input_overlap([tmp_path / "in" / "a.png"], out_files=[tmp_path / "in" / "." / "a.png"])
    check_no_input_overlap([tmp_path / "in"], out_dir=tmp_path / "out")


def test_submit_overwrite_never_deletes_files_it_does_not_own(tmp_path: Path) -> None:
    expected = {"0.png": (4, 5)}
    preds = [("0.png", np.full((4, 5), 10.0))]
    write_submission_files(preds, tmp_path / "sub", expected)
    (tmp_path / "sub" / "notes.txt").write_text("mine")
    with pytest.raises(SubmissionError, match="notes.txt"):
        write_submission_files(preds, tmp_path / "sub", expected, overwrite=True)
    assert (tmp_path / "sub" / "notes.txt").read_text() == "mine"
    (tmp_path / "sub" / "notes.txt").unlink()
    write_submission_files(preds, tmp_path / "sub", expected, overwrite=True)
