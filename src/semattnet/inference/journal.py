"""``frames.json``: what a run of the frame loop did with every frame, kept on disk while it runs.

The journal is how a long run survives bad frames and kills (:func:`semattnet.inference.pipeline.complete_frames`):

* every frame has a status: ``done`` (every output written atomically and in place), ``skipped`` (its input
  could not be read or completed; ``reason`` says why), ``dropped`` (``--realtime``: a newer frame came
  before the completer was free), ``failed`` (the frame that stopped an ``on_error="stop"`` run) or
  ``pending`` (not reached);
* a done frame records its output files (path relative to the folder -> size and SHA-256, taken when they
  were written), its input files (path -> size, modification time and SHA-256:
  :mod:`~semattnet.inference.stamps`) and its stage times (milliseconds);
* ``earlier`` keeps the records of done frames of an earlier run that a resume no longer has (their input
  is gone), so that no resume loses the record of a frame whose files are in the folder;
* ``run`` is the run's identity (the command's options, the weights' digest, the version): a resume with
  another identity is refused (:class:`ResumeError`), and a frame whose input changed is done again, so one
  folder never mixes two runs' outputs.

Nothing read back is trusted: on resume every field is type- and range-checked (a damaged journal is one
line naming ``frames.json`` and the field), and a done frame is kept only when each of its files is a regular
file inside the folder (no absolute path, no ``..``, no symlink) with its recorded size and digest; any
other frame is done again.

The file is rewritten atomically (:func:`semattnet._utils.atomic.atomic_path`) after every frame of a small
run and at most once per :data:`SAVE_INTERVAL_S` of a large or a paced (real-time) one (a kill loses at most
that much work; those frames are done again on resume), and at the end with ``complete: true``. Under
``torchrun`` each process keeps ``.frames.rankR.json`` while it runs and process 0 merges them into
``frames.json`` at the end.
"""

from __future__ import annotations

import hashlib
import json
import os
import stat
import tempfile
import time
from collections import Counter
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np

from semattnet._utils.atomic import atomic_path
from semattnet._utils.version import __version__
from semattnet.cache.store import sha256_file
from semattnet.data.io import read_depth
from semattnet.inference.journal_file import (
    FRAMES_FILE,
    MAX_BYTES_PER_FRAME,
    MAX_JOURNAL_BYTES,
    SCHEMA,
    STATUSES,
    FileRecord,
    FrameEntry,
    ResumeError,
    bounded_bytes,
    describe_counts,
    file_record,
    rank_file,
    read_inside,
    read_journal,
    run_difference,
)
from semattnet.inference.stamps import InputDigests, input_stamps, inputs_unchanged

__all__ = [
    "FRAMES_FILE",
    "MAX_BYTES_PER_FRAME",
    "MAX_JOURNAL_BYTES",
    "SAVE_INTERVAL_S",
    "SCHEMA",
    "STATUSES",
    "FileRecord",
    "FrameEntry",
    "ResumeError",
    "RunJournal",
    "describe_counts",
    "input_stamps",
]
#: A run of at most this many frames saves the journal after every frame; a larger one at most every
#: :data:`SAVE_INTERVAL_S` seconds.
SMALL_RUN = 500
SAVE_INTERVAL_S = 1.0
#: The identity of a run the caller did not describe (``run=None``).
_DEFAULT_RUN: dict[str, object] = {"command": "predict", "version": __version__}


class RunJournal:
    """The frames of one run in ``out`` (``names`` in order) and what happened to each.

    ``run``: the run's identity (JSON values; ``command`` and ``version`` default to ``predict`` and this
    version). ``resume``: continue the run in ``out`` (its journal must exist and hold the same identity); else a
    new journal is started. ``rank`` / ``world``: this process under
    ``torchrun`` (its own partial file while running). ``expect``: a frame's output files (relative paths); a
    resume keeps a done frame only when it recorded exactly those.

    Raises:
        ResumeError: ``resume`` without a journal in ``out``, a damaged one or another identity.
    """

    def __init__(
        self,
        out: str | Path,
        names: Sequence[str],
        run: Mapping[str, object] | None = None,
        resume: bool = False,
        rank: int = 0,
        world: int = 1,
        expect: Callable[[str], Sequence[str]] | None = None,
        paced: bool = False,
    ) -> None:
        self.out, self.names, self.run = Path(out), list(names), {**_DEFAULT_RUN, **(run or {})}
        self.paced = paced  # a real-time run: its frames (and drops) come at the sensor's rate, saves at intervals
        self.rank, self.world, self.expect = rank, world, expect
        self.frames: dict[str, FrameEntry] = {n: {"name": n, "status": "pending"} for n in self.names}
        self.earlier_wall_s = 0.0
        self.kept: set[str] = set()
        self.earlier: dict[str, FrameEntry] = {}  # done frames of earlier runs that this run does not have
        self._saved_at = 0.0
        self._digests = InputDigests()  # each input hashed once per run (a bag every frame reads, too)
        if resume:
            self._resume()  # first: a journal too large to resume is refused before any of it is read
        self._before = self._snapshot()

    @property
    def path(self) -> Path:
        """The file this process writes while running."""
        return self.out / (FRAMES_FILE if self.world == 1 else rank_file(self.rank))

    def _snapshot(self) -> bytes | None:
        """The journal this process would replace (a regular file, judged by its size first), for :meth:`restore`."""
        try:
            st = self.path.lstat()
            if not stat.S_ISREG(st.st_mode):
                return None
            return bounded_bytes(self.path, st.st_size, MAX_JOURNAL_BYTES + MAX_BYTES_PER_FRAME * len(self.names))
        except OSError:
            return None

    def _resume(self) -> None:
        limit = MAX_JOURNAL_BYTES + MAX_BYTES_PER_FRAME * len(self.names)
        main = read_journal(self.out / FRAMES_FILE, limit)
        parts = [
            d for r in range(max(self.world, 1)) if (d := read_journal(self.out / rank_file(r), limit)) is not None
        ]
        found = [d for d in (main, *parts) if d is not None]
        if not found:
            raise ResumeError(
                f"{self.out}: no {FRAMES_FILE} to resume from (not a semattnet predict folder, or "
                "its run was killed before the first frame); run without --resume"
            )
        for doc in found:
            why = run_difference(doc["run"], self.run)
            if why is not None:
                raise ResumeError(
                    f"{self.out / FRAMES_FILE}: cannot resume: {why}; resume with the first run's "
                    "options and weights, or choose a new --out"
                )
        self.earlier_wall_s = max(float(d["wall_s"]) for d in found)
        for doc in found:
            for entry in [*doc["earlier"], *doc["frames"]]:
                if entry["status"] == "done" and entry["name"] not in self.frames:
                    self.earlier[entry["name"]] = entry  # its input is gone: its record stays
                kept = self._kept(entry)
                if kept is not None:
                    self.frames[kept["name"]] = kept
                    self.kept.add(kept["name"])

    def _kept(self, entry: FrameEntry) -> FrameEntry | None:
        """A done frame of an earlier run (checked by :func:`read_journal`) whose inputs are unchanged and whose every
        output is whole, else None."""
        name, files, stamps = entry["name"], entry.get("files", {}), entry.get("inputs", {})
        if entry["status"] != "done" or name not in self.frames or not inputs_unchanged(stamps, self._digests):
            return None
        if self.expect is not None and set(files) != set(self.expect(name)):
            return None  # not the files this run writes (an edited journal): done again
        if not files or not all(self._whole(rel, record) for rel, record in files.items()):
            return None
        return {
            "name": name,
            "status": "done",
            "files": dict(files),
            "inputs": dict(stamps),
            "stage_ms": dict(entry.get("stage_ms", {})),
        }

    def _whole(self, rel: str, record: FileRecord) -> bool:
        """``out/rel`` is a regular file (no symlink) inside ``out`` with the recorded size and digest."""
        p = self.out / rel
        try:
            st = p.lstat()
            inside = p.resolve().is_relative_to(self.out.resolve())
        except OSError:
            return False
        if not (stat.S_ISREG(st.st_mode) and inside and st.st_size == record["size"]):
            return False
        return sha256_file(p) == record["sha256"]

    def stored(self, name: str, rel: str) -> Path:
        """The output ``rel`` of the kept frame ``name``, checked again as the resume checked it (a regular file
        inside ``out`` with its recorded size and digest), to be read back (e.g. into a bag).

        Raises:
            ResumeError: it changed since (or is not among the frame's recorded files).
        """
        record = self.frames[name].get("files", {}).get(rel)
        if record is None or not self._whole(rel, record):
            raise ResumeError(
                f"{self.out / rel}: changed or replaced while the resume ran (not the file "
                f"{FRAMES_FILE} records); run the resume again"
            )
        return self.out / rel

    def stored_depth(self, name: str, rel: str) -> np.ndarray:
        """The depth PNG ``rel`` of the kept frame ``name``, decoded from the bytes whose size and digest were just
        checked: read once, each folder of ``rel`` and the file opened without following a link, so a link swapped in
        after the resume's check (to a file out of ``out``) is never read back (e.g. into a bag).

        Raises:
            ResumeError: it changed since, is a link or is not among the frame's recorded files.
        """
        record = self.frames[name].get("files", {}).get(rel)
        try:
            data = read_inside(self.out, rel, record["size"]) if record is not None else None
        except OSError:
            data = None
        if record is None or data is None or hashlib.sha256(data).hexdigest() != record["sha256"]:
            raise ResumeError(
                f"{self.out / rel}: changed or replaced while the resume ran (not the file "
                f"{FRAMES_FILE} records); run the resume again"
            )
        with tempfile.TemporaryDirectory(prefix="semattnet-replay.") as private:
            copy = Path(private) / Path(rel).name
            copy.write_bytes(data)
            return read_depth(copy)

    def done(
        self,
        name: str,
        files: Sequence[str],
        stage_ms: Mapping[str, float],
        inputs: Iterable[str | os.PathLike[str]] = (),
    ) -> None:
        """Frame ``name``'s outputs (paths relative to ``out``, already in place), its stage times and the input
        files (or folders) it was read from."""
        records = {rel: file_record(self.out / rel) for rel in files}
        times = {k: round(float(v), 3) for k, v in stage_ms.items()}
        stamps = input_stamps(inputs, self._digests)
        self.frames[name] = {"name": name, "status": "done", "files": records, "inputs": stamps, "stage_ms": times}

    def mark(self, name: str, status: str, reason: str) -> None:
        """Frame ``name`` ``skipped`` / ``dropped`` / ``failed`` for ``reason`` (one line)."""
        assert status in STATUSES and status != "done"
        self.frames[name] = {"name": name, "status": status, "reason": reason}

    def counts(self) -> dict[str, int]:
        """Frames per status (every status present)."""
        c = Counter(e["status"] for e in self.frames.values())
        return {s: c.get(s, 0) for s in STATUSES}

    def reasons(self, status: str = "skipped") -> list[tuple[str, str]]:
        """(name, reason) of the frames with ``status``, in order."""
        return [(n, e.get("reason", "")) for n, e in self.frames.items() if e["status"] == status]

    def to_doc(self, complete: bool, wall_s: float = 0.0) -> dict[str, object]:
        return {
            "schema": SCHEMA,
            "complete": complete,
            "run": self.run,
            "counts": self.counts(),
            "wall_s": round(self.earlier_wall_s + wall_s, 3),
            "frames": [self.frames[n] for n in self.names],
            "earlier": list(self.earlier.values()),
        }

    def save(self, complete: bool = False, wall_s: float = 0.0, force: bool = True) -> None:
        """Write this process's file atomically (``force=False``: only when it is due, see the module doc)."""
        now = time.monotonic()
        by_interval = self.paced or len(self.names) > SMALL_RUN
        if not force and by_interval and now - self._saved_at < SAVE_INTERVAL_S:
            return
        self.out.mkdir(parents=True, exist_ok=True)
        with atomic_path(self.path, suffix=".json") as tmp:
            tmp.write_text(json.dumps(self.to_doc(complete, wall_s), indent=1, allow_nan=False) + "\n")
        self._saved_at = now

    def restore(self) -> None:
        """Undo this process's saves: the journal it found put back (an earlier run's record is never lost), or
        none when there was none."""
        if self._before is None:
            self.path.unlink(missing_ok=True)
            return
        with atomic_path(self.path, suffix=".json") as tmp:
            tmp.write_bytes(self._before)

    def merge(self, entries: Sequence[FrameEntry], complete: bool, wall_s: float) -> None:
        """Process 0 under ``torchrun``: every process's entries into ``frames.json``; the partial files go."""
        for e in entries:
            if e["status"] != "pending" or self.frames[e["name"]]["status"] == "pending":
                self.frames[e["name"]] = e
        self.world, keep = 1, self.world
        self.save(complete=complete, wall_s=wall_s)
        for r in range(keep):
            (self.out / rank_file(r)).unlink(missing_ok=True)
