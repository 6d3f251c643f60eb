"""The one frame loop's run summary (:class:`semattnet.inference.loop.FrameRun`)."""

from __future__ import annotations

from pathlib import Path


def test_the_summary_groups_skip_reasons_by_kind_and_names_their_frames(tmp_path: Path) -> None:
    from semattnet.inference.journal import RunJournal
    from semattnet.inference.loop import FrameRun

    names = [f"{i:05d}" for i in range(1, 9)]
    journal = RunJournal(tmp_path, names)
    hdf5 = "not a readable HDF5 file (OSError: Unable to synchronously open file ({}))"
    journal.mark("00001", "skipped", f"/nyu/00001.h5: {hdf5.format('file signature not found')}")
    journal.mark("00002", "skipped", f"/nyu/00002.h5: {hdf5.format('bad superblock version number')}")
    for name in names[2:]:
        journal.mark(name, "skipped", f"/nyu/{name}.h5: no 'depth' dataset (keys: rgb)")
    lines = FrameRun(journal, []).summary().splitlines()
    assert lines[1:] == [
        "  skipped x6: no 'depth' dataset: 00003, 00004, 00005, 00006, 00007 and 1 more",
        "  skipped x2: not a readable HDF5 file: 00001, 00002",
    ]
