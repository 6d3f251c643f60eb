"""``frames.json``: what a run of the frame loop did with every frame, kept on disk while it runs.

The journal is how a long run survives bad frames and kills (:func:`semattnet.inference.pipeline.complete_frames`):

* every frame has a status: ``done`` (every output written atomically and in place), ``skipped`` (its input
  could not be read or completed; ``reason`` says why), ``dropped`` (``--realtime``: a newer frame came
  before the completer was free), ``failed`` (the frame that stopped an ``on_error="stop"`` run) or
  ``pending`` (not reached);
* a done frame records its output files and their sizes and its stage times (milliseconds), so that a
  resumed run keeps it only when every file is still there, whole, and its latency table covers it;
* ``run`` is the run's identity (the command's options, the weights' digest, the inputs): a resume with
  another identity is refused (:class:`ResumeError`), so one folder never mixes two runs' outputs.

The file is rewritten atomically (:func:`semattnet._utils.atomic.atomic_path`) after every frame of a small
run and at most once per :data:`SAVE_INTERVAL_S` of a large one (a kill loses at most that much work; those
frames are done again on resume), and at the end with ``complete: true``. Under ``torchrun`` each process
keeps ``.frames.rankR.json`` while it runs and process 0 merges them into ``frames.json`` at the end.
"""

from __future__ import annotations

import json
import time
from collections import Counter
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TypedDict

from semattnet._errors import SemAttNetError
from semattnet._utils.atomic import atomic_path

__all__ = [
    "FRAMES_FILE",
    "SAVE_INTERVAL_S",
    "SCHEMA",
    "STATUSES",
    "FrameEntry",
    "ResumeError",
    "RunJournal",
    "describe_counts",
]

#: The journal's name in the output folder.
FRAMES_FILE = "frames.json"
#: Its schema tag.
SCHEMA = "semattnet.frames/1"
#: A frame's possible statuses.
STATUSES = ("done", "skipped", "dropped", "failed", "pending")
#: A run of at most this many frames saves the journal after every frame; a larger one at most every
#: :data:`SAVE_INTERVAL_S` seconds.
SMALL_RUN = 500
SAVE_INTERVAL_S = 1.0


class _Entry(TypedDict):
    name: str
    status: str


class FrameEntry(_Entry, total=False):
    """One frame of the journal: ``name``, ``status`` (:data:`STATUSES`), and ``reason`` (not done) or ``files``
    (relative path -> size in bytes) and ``stage_ms`` (stage -> milliseconds) (done)."""

    reason: str
    files: dict[str, int]
    stage_ms: dict[str, float]


class ResumeError(SemAttNetError):
    """A resume that cannot continue the run in its folder (no journal, another run's options or weights)."""


def _rank_file(rank: int) -> str:
    return f".frames.rank{rank}.json"


def _read(path: Path) -> dict[str, object] | None:
    """A journal file's content, None when absent; a damaged one is a one-line :class:`ResumeError`."""
    if not path.is_file():
        return None
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise ResumeError(f"{path}: not a readable frames journal ({exc}); start a new --out") from None
    if not isinstance(doc, dict) or doc.get("schema") != SCHEMA or not isinstance(doc.get("frames"), list):
        raise ResumeError(f"{path}: not a semattnet frames journal (schema {SCHEMA}); start a new --out")
    return doc


def _difference(old: Mapping[str, object], new: Mapping[str, object]) -> str | None:
    """The first option whose value differs between two run identities, as a phrase, or None."""

    def said(value: object) -> str:
        return "not given" if value is None else "given" if value is True else repr(value)

    for key in sorted(set(old) | set(new)):
        if old.get(key) != new.get(key):
            return f"--{key.replace('_', '-')} was {said(old.get(key))} in the first run, now {said(new.get(key))}"
    return None


class RunJournal:
    """The frames of one run in ``out`` (``names`` in order) and what happened to each.

    ``run``: the run's identity (JSON values). ``resume``: continue the run in ``out`` (its journal must
    exist and hold the same identity); else a new journal is started. ``rank`` / ``world``: this process
    under ``torchrun`` (its own partial file while running).

    Raises:
        ResumeError: ``resume`` without a journal in ``out``, or with another identity.
    """

    def __init__(self, out: str | Path, names: Sequence[str], run: Mapping[str, object] | None = None,
                 resume: bool = False, rank: int = 0, world: int = 1) -> None:  # fmt: skip
        self.out, self.names, self.run = Path(out), list(names), dict(run or {})
        self.rank, self.world = rank, world
        self.frames: dict[str, FrameEntry] = {n: {"name": n, "status": "pending"} for n in self.names}
        self.earlier_wall_s = 0.0
        self.kept: set[str] = set()
        self._saved_at = 0.0
        if resume:
            self._resume()

    @property
    def path(self) -> Path:
        """The file this process writes while running."""
        return self.out / (FRAMES_FILE if self.world == 1 else _rank_file(self.rank))

    def _resume(self) -> None:
        main = _read(self.out / FRAMES_FILE)
        parts = [d for r in range(max(self.world, 1)) if (d := _read(self.out / _rank_file(r))) is not None]
        found = [d for d in (main, *parts) if d is not None]
        if not found:
            raise ResumeError(f"{self.out}: no {FRAMES_FILE} to resume from (not a semattnet predict folder, or "
                              "its run was killed before the first frame); run without --resume")  # fmt: skip
        for doc in found:
            run = doc.get("run", {})
            why = _difference(run if isinstance(run, dict) else {}, self.run)
            if why is not None:
                raise ResumeError(f"{self.out / FRAMES_FILE}: cannot resume: {why}; resume with the first run's "
                                  "options and weights, or choose a new --out")  # fmt: skip
        self.earlier_wall_s = max(_seconds(d.get("wall_s", 0.0)) for d in found)
        for doc in found:
            for entry in _list(doc["frames"]):
                kept = self._kept(entry)
                if kept is not None:
                    self.frames[kept["name"]] = kept
                    self.kept.add(kept["name"])

    def _kept(self, entry: object) -> FrameEntry | None:
        """A done frame of an earlier run with every output file there at its recorded size, else None."""
        if not isinstance(entry, dict) or entry.get("status") != "done" or entry.get("name") not in self.frames:
            return None
        name, files, stage_ms = str(entry["name"]), entry.get("files"), entry.get("stage_ms", {})
        if not isinstance(files, dict) or not isinstance(stage_ms, dict):
            return None
        for rel, size in files.items():
            p = self.out / str(rel)
            if not p.is_file() or p.stat().st_size != size:
                return None
        kept: FrameEntry = {"name": name, "status": "done", "files": dict(files)}
        if "stage_ms" in entry:
            kept["stage_ms"] = dict(stage_ms)
        return kept

    def done(self, name: str, files: Sequence[str], stage_ms: Mapping[str, float]) -> None:
        """Frame ``name``'s outputs (paths relative to ``out``, already in place) and its stage times."""
        sizes = {rel: (self.out / rel).stat().st_size for rel in files}
        times = {k: round(float(v), 3) for k, v in stage_ms.items()}
        self.frames[name] = {"name": name, "status": "done", "files": sizes, "stage_ms": times}

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
        return {"schema": SCHEMA, "complete": complete, "run": self.run, "counts": self.counts(),
                "wall_s": round(self.earlier_wall_s + wall_s, 3),
                "frames": [self.frames[n] for n in self.names]}  # fmt: skip

    def save(self, complete: bool = False, wall_s: float = 0.0, force: bool = True) -> None:
        """Write this process's file atomically (``force=False``: only when it is due, see the module doc)."""
        now = time.monotonic()
        if not force and len(self.names) > SMALL_RUN and now - self._saved_at < SAVE_INTERVAL_S:
            return
        self.out.mkdir(parents=True, exist_ok=True)
        with atomic_path(self.path, suffix=".json") as tmp:
            tmp.write_text(json.dumps(self.to_doc(complete, wall_s), indent=1) + "\n")
        self._saved_at = now

    def merge(self, entries: Sequence[FrameEntry], complete: bool, wall_s: float) -> None:
        """Process 0 under ``torchrun``: every process's entries into ``frames.json``; the partial files go."""
        for e in entries:
            if e["status"] != "pending" or self.frames[e["name"]]["status"] == "pending":
                self.frames[e["name"]] = e
        self.world, keep = 1, self.world
        self.save(complete=complete, wall_s=wall_s)
        for r in range(keep):
            (self.out / _rank_file(r)).unlink(missing_ok=True)


def _seconds(value: object) -> float:
    return float(value) if isinstance(value, int | float | str) else 0.0


def _list(value: object) -> list[object]:
    return list(value) if isinstance(value, list) else []


def describe_counts(counts: Mapping[str, int]) -> str:
    """``"5 done, 2 skipped"``: the non-zero statuses, in order."""
    return ", ".join(f"{counts[s]} {s}" for s in STATUSES if counts.get(s)) or "no frame"
