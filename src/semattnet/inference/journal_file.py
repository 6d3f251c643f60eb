"""The frames journal's file (``frames.json``): its names, statuses and records, and how a journal written by an
earlier run is read back: judged by its size before any byte is read, every field type- and range-checked, an
output file read only inside the folder (:class:`~semattnet.inference.journal.RunJournal` keeps it while a run
goes on). Nothing read back is trusted: a damaged journal is one :class:`ResumeError` line naming the file and the
field.
"""

from __future__ import annotations

import json
import os
import stat
from collections.abc import Mapping
from pathlib import Path, PurePosixPath
from typing import TypedDict, cast

from semattnet._errors import SemAttNetError
from semattnet.cache.store import sha256_file
from semattnet.inference.stamps import InputStamp, is_input_stamp

__all__ = [
    "FRAMES_FILE",
    "MAX_BYTES_PER_FRAME",
    "MAX_JOURNAL_BYTES",
    "OLD_SCHEMAS",
    "SCHEMA",
    "STATUSES",
    "FileRecord",
    "FrameEntry",
    "JournalDoc",
    "ResumeError",
    "bounded_bytes",
    "describe_counts",
    "file_record",
    "rank_file",
    "read_inside",
    "read_journal",
    "run_difference",
]

#: The journal's name in the output folder.
FRAMES_FILE = "frames.json"
#: Its schema tag.
SCHEMA = "semattnet.frames/2"
#: Schemas of earlier versions: their journals recorded no digests, so they are refused, not trusted.
OLD_SCHEMAS = ("semattnet.frames/1",)
#: A frame's possible statuses.
STATUSES = ("done", "skipped", "dropped", "failed", "pending")
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


class JournalDoc(TypedDict):
    """What :func:`read_journal` gives: a journal whose fields :func:`_checked` checked."""

    run: dict[str, object]
    wall_s: float
    frames: list[FrameEntry]
    earlier: list[FrameEntry]


class ResumeError(SemAttNetError):
    """A resume that cannot continue the run in its folder (no journal, a damaged one, another run's options,
    weights or inputs)."""


def rank_file(rank: int) -> str:
    return f".frames.rank{rank}.json"


def _what(mode: int) -> str:
    kinds = ((stat.S_ISDIR, "a folder"), (stat.S_ISLNK, "a symbolic link"), (stat.S_ISFIFO, "a FIFO"))
    return next((name for test, name in kinds if test(mode)), "a special file")


def read_journal(path: Path, limit: int = MAX_JOURNAL_BYTES) -> JournalDoc | None:
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
        doc = json.loads(bounded_bytes(path, st.st_size, limit))
    except RecursionError:
        raise ResumeError(f"{path}: not a frames journal (its JSON is nested too deeply); choose a new --out") from None
    except (OSError, ValueError) as exc:
        raise ResumeError(f"{path}: not a readable frames journal ({exc}); start a new --out") from None
    return _checked(path, doc)


def bounded_bytes(path: Path, size: int, limit: int) -> bytes:
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


def _checked(path: Path, doc: object) -> JournalDoc:
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
    return cast(JournalDoc, doc)


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


def read_inside(out: Path, rel: str, size: int) -> bytes | None:
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


def file_record(path: Path) -> FileRecord:
    return {"size": path.stat().st_size, "sha256": sha256_file(path)}


def run_difference(old: Mapping[str, object], new: Mapping[str, object]) -> str | None:
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


def describe_counts(counts: Mapping[str, int]) -> str:
    """``"5 done, 2 skipped"``: the non-zero statuses, in order."""
    return ", ".join(f"{counts[s]} {s}" for s in STATUSES if counts.get(s)) or "no frame"
