"""The frames journal read back on ``--resume``: its size judged before a byte of it is read; an input replaced by
one of the same size and mtime told by its digest (hashed once per run); a kept depth read back from the bytes
checked, never through a link."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from semattnet.data.io import read_depth, write_depth
from semattnet.inference import journal, stamps
from semattnet.inference.pipeline import OutputSpec, check_frames
from semattnet.inference.sinks import default_sinks
from tests.reliability.test_journal_trust import _edit, _frames, _kept, _refusal, _run


def test_a_512_mb_journal_is_refused_in_one_line_without_being_read(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    source, out = _frames(tmp_path), tmp_path / "out"
    _run(source, out)
    big = out / "frames.json"
    with big.open("r+b") as f:
        f.truncate(512 * 2**20)  # sparse: no disk used

    def never(*_: object, **__: object) -> object:
        raise AssertionError("the oversized journal was read")

    monkeypatch.setattr(journal.json, "loads", never)
    monkeypatch.setattr(Path, "read_bytes", never)
    monkeypatch.setattr(Path, "read_text", never)
    message = _refusal(source, out)
    assert str(big) in message and f"{512 * 2**20} bytes" in message and "not read" in message, message
    assert os.path.getsize(big) == 512 * 2**20  # left as it was


def test_a_journal_within_the_bound_of_a_large_run_is_read(tmp_path: Path) -> None:
    names = [f"f{i}" for i in range(1000)]
    out = tmp_path / "out"
    out.mkdir()
    (out / "frames.json").write_text(" " * (journal.MAX_JOURNAL_BYTES + 2 * journal.MAX_BYTES_PER_FRAME) + "{}")
    with pytest.raises(journal.ResumeError, match="not a semattnet frames journal"):  # read, then judged by content
        journal.RunJournal(out, names, resume=True)
    with pytest.raises(journal.ResumeError, match="more than a frames journal of this run can hold"):
        journal.RunJournal(out, names[:1], resume=True)


def test_an_input_replaced_by_one_of_the_same_size_and_mtime_is_done_again(tmp_path: Path) -> None:
    source, out = _frames(tmp_path), tmp_path / "out"
    _run(source, out)
    image = tmp_path / "rgb" / "f1.png"
    before = image.stat()
    data = bytearray(image.read_bytes())
    data[-20] ^= 0xFF  # other bytes, the same size
    image.write_bytes(bytes(data))
    os.utime(image, ns=(before.st_atime_ns, before.st_mtime_ns))  # and the same mtime
    assert image.stat().st_size == before.st_size and image.stat().st_mtime_ns == before.st_mtime_ns
    assert _kept(source, out) == {"f0", "f2"}


def test_a_record_without_the_inputs_digest_is_done_again(tmp_path: Path) -> None:
    source, out = _frames(tmp_path), tmp_path / "out"
    _run(source, out)

    def drop_digests(doc: dict[str, Any]) -> None:
        for entry in doc["frames"]:
            entry["inputs"] = {k: v[:2] for k, v in entry["inputs"].items()}

    _edit(out, drop_digests)
    assert _kept(source, out) == set()


def test_an_input_every_frame_reads_is_hashed_once_per_run(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    bag = tmp_path / "drive.bag"
    bag.write_bytes(os.urandom(4096))
    hashed: list[Path] = []
    monkeypatch.setattr(stamps, "sha256_file", lambda p: hashed.append(p) or "0" * 64)
    digests = stamps.InputDigests()
    records = [stamps.input_stamps([bag], digests) for _ in range(100)]
    assert len(hashed) == 1 and all(stamps.inputs_unchanged(r, digests) for r in records) and len(hashed) == 1


def test_a_kept_depth_swapped_for_a_link_after_its_check_is_never_read_back(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The bytes checked are the bytes decoded: a link to a file out of OUT, swapped in between the check and the
    decoding, is not what the bag (or any replay) gets; one swapped in before is refused."""
    source, out = _frames(tmp_path), tmp_path / "out"
    _run(source, out)
    plan = check_frames(source, default_sinks(), out, OutputSpec(resume=True))
    plan.release()
    mine = read_depth(out / "f0.png")
    foreign = tmp_path / "foreign.png"
    write_depth(foreign, np.full(mine.shape, 7.0, np.float32))

    def swap_then_read(path: Path) -> np.ndarray:
        if not (out / "f0.png").is_symlink():
            (out / "f0.png").unlink()
            (out / "f0.png").symlink_to(foreign)  # the race: after the check, before the decoding
        return read_depth(path)

    monkeypatch.setattr(journal, "read_depth", swap_then_read)
    assert np.array_equal(plan.journal.stored_depth("f0", "f0.png"), mine)
    with pytest.raises(journal.ResumeError, match="f0.png: changed or replaced while the resume ran"):
        plan.journal.stored_depth("f0", "f0.png")  # the link is there now: refused, not followed


def test_overwrite_of_a_600_mb_journal_is_refused_in_one_line_without_reading_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``--overwrite`` keeps the journal it replaces (to put back if the run fails): one too large for the run is
    refused, naming it, before a byte of it is read, and left as it was."""
    source, out = _frames(tmp_path), tmp_path / "out"
    _run(source, out)
    big = out / "frames.json"
    with big.open("r+b") as f:
        f.truncate(600 * 2**20)  # sparse: no disk used
    read = Path.open

    def guarded(path: Path, mode: str = "r", *args: Any, **kwargs: Any) -> Any:
        assert path != big or "r" not in mode or "+" in mode, "the oversized journal was opened for reading"
        return read(path, mode, *args, **kwargs)

    monkeypatch.setattr(Path, "open", guarded)
    monkeypatch.setattr(Path, "read_bytes", lambda path: pytest.fail(f"{path} read whole"))
    with pytest.raises(journal.ResumeError) as info:
        check_frames(source, default_sinks(), out, OutputSpec(overwrite=True))
    message = str(info.value)
    assert "\n" not in message and str(big) in message and "not read" in message, message
    assert os.path.getsize(big) == 600 * 2**20  # left as it was


@pytest.mark.parametrize("paced", [False, True])
def test_a_paced_run_saves_its_journal_at_intervals_not_per_frame(tmp_path: Path, paced: bool) -> None:
    """A small run saves after every frame (a kill loses nothing); a real-time one, whose frames and drops come
    at the sensor's rate, at most once per SAVE_INTERVAL_S (a kill loses at most that much; resumed frames
    are done again), and always at the end."""
    run = journal.RunJournal(tmp_path, ["a", "b"], paced=paced)
    run.save(force=False)
    run.mark("a", "dropped", "a newer frame came first")
    run.save(force=False)  # within the interval of the first save
    status = json.loads((tmp_path / journal.FRAMES_FILE).read_text())["frames"][0]["status"]
    assert status == ("pending" if paced else "dropped")
    run.save(complete=True)
    assert json.loads((tmp_path / journal.FRAMES_FILE).read_text())["frames"][0]["status"] == "dropped"
