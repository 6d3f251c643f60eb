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
from pathlib import Path, PurePosixPath
from typing import TypedDict, cast

import numpy as np

from semattnet._errors import SemAttNetError
from semattnet._utils.atomic import atomic_path
from semattnet._utils.version import __version__
from semattnet.cache.store import sha256_file
from semattnet.data.io import read_depth
from semattnet.inference.stamps import InputDigests, InputStamp, input_stamps, inputs_unchanged, is_input_stamp

__all__ = [
    "FRAMES_FILE",
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

#: The journal's name in the output folder.
FRAMES_FILE = "frames.json"
#: Its schema tag.
SCHEMA = "semattnet.frames/2"
#: Schemas of earlier versions: their journals recorded no digests, so they are refused, not trusted.
OLD_SCHEMAS = ("semattnet.frames/1",)
#: A frame's possible statuses.
STATUSES = ("done", "skipped", "dropped", "failed", "pending")
#: A run of at most this many frames saves the journal after every frame; a larger one at most every
#: :data:`SAVE_INTERVAL_S` seconds.
SMALL_RUN = 500
SAVE_INTERVAL_S = 1.0
#: The identity of a run the caller did not describe (``run=None``).
_DEFAULT_RUN: dict[str, object] = {"command": "predict", "version": __version__}
#: The largest number of seconds or milliseconds a journal may hold (about 30 years).
_MAX_TIME = 1e9
#: A journal read back may be at most this many bytes, plus :data:`MAX_BYTES_PER_FRAME` per frame of the run: judged
#: from its size before it is read (a 512 MB ``frames.json`` would take gigabytes to parse).
MAX_JOURNAL_BYTES = 64 * 2**20
#: What one frame's record may add to :data:`MAX_JOURNAL_BYTES` (a done frame with several outputs is under 1 KiB).
MAX_BYTES_PER_FRAME = 4096


class _Entry(TypedDict):
    name: str
    status: str


class FileRecord(TypedDict):
    """One output file of a done frame, as it was written: its size in bytes and its SHA-256 (hex)."""

    size: int
    sha256: str


class FrameEntry(_Entry, total=False):
    """One frame of the journal: ``name``, ``status`` (:data:`STATUSES`), and ``reason`` (not done) or ``files``
    (relative path -> :class:`FileRecord`), ``inputs`` (path -> :data:`~semattnet.inference.stamps.InputStamp`)
    and ``stage_ms`` (stage -> milliseconds) (done)."""

    reason: str
    files: dict[str, FileRecord]
    inputs: dict[str, InputStamp]
    stage_ms: dict[str, float]


class _Journal(TypedDict):
    """What :func:`_read` gives: a journal whose fields :func:`_checked` checked."""

    run: dict[str, object]
    wall_s: float
    frames: list[FrameEntry]
    earlier: list[FrameEntry]


class ResumeError(SemAttNetError):
    """A resume that cannot continue the run in its folder (no journal, a damaged one, another run's options,
    weights or inputs)."""


def _rank_file(rank: int) -> str:
    return f".frames.rank{rank}.json"


def _what(mode: int) -> str:
    kinds = ((stat.S_ISDIR, "a folder"), (stat.S_ISLNK, "a symbolic link"), (stat.S_ISFIFO, "a FIFO"))
    return next((name for test, name in kinds if test(mode)), "a special file")


def _read(path: Path, limit: int = MAX_JOURNAL_BYTES) -> _Journal | None:
    """A journal file's content, checked (:func:`_checked`); None when absent. Anything else (a folder, a
    FIFO, a symlink, a file over ``limit`` bytes, bad JSON, a damaged field) is a one-line :class:`ResumeError`
    naming the file."""
    try:
        st = path.lstat()
    except FileNotFoundError:
        return None
    except OSError as exc:
        raise ResumeError(f"{path}: cannot be read ({exc.strerror}); fix it or choose a new --out") from None
    if not stat.S_ISREG(st.st_mode):
        raise ResumeError(
            f"{path} is {_what(st.st_mode)}, not a frames journal semattnet wrote; move it away or choose a new --out"
        )
    try:
        doc = json.loads(_bounded_bytes(path, st.st_size, limit))
    except RecursionError:
        raise ResumeError(f"{path}: not a frames journal (its JSON is nested too deeply); choose a new --out") from None
    except (OSError, ValueError) as exc:
        raise ResumeError(f"{path}: not a readable frames journal ({exc}); start a new --out") from None
    return _checked(path, doc)


def _bounded_bytes(path: Path, size: int, limit: int) -> bytes:
    """The bytes of ``path`` (``size``: its size by ``lstat``), judged by its size before any is read: a file over
    ``limit`` bytes (or grown past it while read) is a one-line :class:`ResumeError` naming it."""
    if size > limit:
        raise ResumeError(
            f"{path}: {size} bytes, more than a frames journal of this run can hold ({limit} bytes at most); "
            "not read: move it away or choose a new --out"
        )
    with path.open("rb") as f:
        data = f.read(limit + 1)  # the file may have grown since: never more than the limit
    if len(data) > limit:
        raise ResumeError(f"{path}: grew past {limit} bytes while it was read; not read: choose a new --out")
    return data


def _damaged(path: Path, field: str, what: str) -> ResumeError:
    return ResumeError(f"{path}: damaged field {field}: {what}; run again with --overwrite or choose a new --out")


def _shown(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _time(path: Path, field: str, value: object) -> float:
    """``value`` as a finite number of seconds or milliseconds in [0, 1e9], else :func:`_damaged`."""
    if isinstance(value, int | float) and not isinstance(value, bool) and 0 <= value <= _MAX_TIME:
        return float(value)  # NaN fails the comparison
    raise _damaged(path, field, f"{_shown(value)} is not a time (a number from 0 to {_MAX_TIME:g})")


def _checked(path: Path, doc: object) -> _Journal:
    """``doc`` when it is a journal of :data:`SCHEMA` whose every field has its type and range."""
    schema = doc.get("schema") if isinstance(doc, dict) else None
    if schema in OLD_SCHEMAS:
        raise ResumeError(
            f"{path}: written by an earlier semattnet ({schema}) that recorded no digest of "
            "the outputs, so it cannot be verified; rerun with --overwrite or a new --out"
        )
    if not isinstance(doc, dict) or schema != SCHEMA:
        raise ResumeError(f"{path}: not a semattnet frames journal (schema {SCHEMA}); start a new --out")
    run = doc.get("run")
    if not isinstance(run, dict) or not all(isinstance(run.get(k), str) for k in ("command", "version")):
        raise _damaged(path, "run", f"{_shown(run)} is not the record of a run (its command, version and options)")
    _time(path, "wall_s", doc.get("wall_s"))
    frames = doc.get("frames")
    if not isinstance(frames, list):
        raise _damaged(path, "frames", f"{_shown(frames)} is not a list of frames")
    earlier = doc.setdefault("earlier", [])
    if not isinstance(earlier, list):
        raise _damaged(path, "earlier", f"{_shown(earlier)} is not a list of frames")
    for key, entries in (("frames", frames), ("earlier", earlier)):
        for i, entry in enumerate(entries):
            _check_entry(path, f"{key}[{i}]", entry)
    return cast(_Journal, doc)


def _check_entry(path: Path, where: str, entry: object) -> None:
    """One frame record: a name and a status; a done one's files (inside the folder) and stage times."""
    if not isinstance(entry, dict) or not isinstance(entry.get("name"), str) or entry.get("status") not in STATUSES:
        raise _damaged(path, where, f"{_shown(entry)} is not a frame record (a name and a status)")
    if entry["status"] != "done":
        return
    files, stage_ms, stamps = entry.get("files"), entry.get("stage_ms", {}), entry.get("inputs")
    if not isinstance(stamps, dict) or not all(is_input_stamp(v) for v in stamps.values()):
        raise _damaged(path, f"{where}.inputs", f"{_shown(stamps)} is not a table of input files (path -> stamp)")
    if not isinstance(files, dict):
        raise _damaged(path, f"{where}.files", f"{_shown(files)} is not a table of output files")
    for rel, record in files.items():
        _check_relative(path, f"{where}.files", rel)
        ok = isinstance(record, dict) and type(record.get("size")) is int and record["size"] >= 0
        if not ok or not _is_digest(record.get("sha256")):
            raise _damaged(path, f"{where}.files[{rel!r}]", f"{_shown(record)} is not a size and a sha256")
    if not isinstance(stage_ms, dict):
        raise _damaged(path, f"{where}.stage_ms", f"{_shown(stage_ms)} is not a table of stage times")
    for stage, ms in stage_ms.items():
        _time(path, f"{where}.stage_ms[{stage!r}]", ms)


def _check_relative(path: Path, where: str, rel: str) -> None:
    """``rel`` is a path inside the output folder: relative, without ``..``, not empty."""
    parts = PurePosixPath(rel).parts
    if not rel or "\\" in rel or PurePosixPath(rel).is_absolute() or ".." in parts or not parts:
        raise _damaged(path, where, f"{rel!r} is not a path inside the output folder")


def _is_digest(value: object) -> bool:
    return isinstance(value, str) and len(value) == 64 and all(c in "0123456789abcdef" for c in value)


def _read_inside(out: Path, rel: str, size: int) -> bytes | None:
    """The bytes of ``out/rel`` when it is a regular file of ``size`` bytes, every folder of ``rel`` and the file
    opened without following a symbolic link (None otherwise); :class:`OSError` where one is a link."""
    parts = PurePosixPath(rel).parts
    fd = os.open(out, os.O_RDONLY | os.O_DIRECTORY)
    try:
        for part in parts[:-1]:
            inner = os.open(part, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW, dir_fd=fd)
            os.close(fd)
            fd = inner
        file_fd = os.open(parts[-1], os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK, dir_fd=fd)
    finally:
        os.close(fd)
    with os.fdopen(file_fd, "rb") as f:
        st = os.fstat(f.fileno())
        return f.read(size + 1) if stat.S_ISREG(st.st_mode) and st.st_size == size else None


def _record(path: Path) -> FileRecord:
    return {"size": path.stat().st_size, "sha256": sha256_file(path)}


def _difference(old: Mapping[str, object], new: Mapping[str, object]) -> str | None:
    """The first thing that differs between two run identities, as a phrase, or None."""

    def said(value: object) -> str:
        return "not given" if value is None else "given" if value is True else repr(value)

    if old.get("command") != new.get("command"):
        return f"it holds a `semattnet {old.get('command')}` run, not `semattnet {new.get('command')}`"
    if old.get("version") != new.get("version"):
        return f"it was written by semattnet {old.get('version')}, this is semattnet {new.get('version')}"
    for key in sorted((set(old) | set(new)) - {"command", "version"}):
        if old.get(key) != new.get(key):
            return f"--{key.replace('_', '-')} was {said(old.get(key))} in the first run, now {said(new.get(key))}"
    return None


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
        return self.out / (FRAMES_FILE if self.world == 1 else _rank_file(self.rank))

    def _snapshot(self) -> bytes | None:
        """The journal this process would replace (a regular file, judged by its size first), for :meth:`restore`."""
        try:
            st = self.path.lstat()
            if not stat.S_ISREG(st.st_mode):
                return None
            return _bounded_bytes(self.path, st.st_size, MAX_JOURNAL_BYTES + MAX_BYTES_PER_FRAME * len(self.names))
        except OSError:
            return None

    def _resume(self) -> None:
        limit = MAX_JOURNAL_BYTES + MAX_BYTES_PER_FRAME * len(self.names)
        main = _read(self.out / FRAMES_FILE, limit)
        parts = [d for r in range(max(self.world, 1)) if (d := _read(self.out / _rank_file(r), limit)) is not None]
        found = [d for d in (main, *parts) if d is not None]
        if not found:
            raise ResumeError(
                f"{self.out}: no {FRAMES_FILE} to resume from (not a semattnet predict folder, or "
                "its run was killed before the first frame); run without --resume"
            )
        for doc in found:
            why = _difference(doc["run"], self.run)
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
        """A done frame of an earlier run (checked by :func:`_read`) whose inputs are unchanged and whose every
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
            data = _read_inside(self.out, rel, record["size"]) if record is not None else None
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
        records = {rel: _record(self.out / rel) for rel in files}
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
            (self.out / _rank_file(r)).unlink(missing_ok=True)


def describe_counts(counts: Mapping[str, int]) -> str:
    """``"5 done, 2 skipped"``: the non-zero statuses, in order."""
    return ", ".join(f"{counts[s]} {s}" for s in STATUSES if counts.get(s)) or "no frame"
