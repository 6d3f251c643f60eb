"""Replacing an earlier run in its folder (``--overwrite``): nothing of it goes before the new run has its first state.

A new run into a folder that holds an earlier one (``adapt --overwrite``, ``train --overwrite``) checks its inputs
and trains with the earlier run's files left alone. Its first state is written into a stage folder inside the run
folder, ``OUT/.semattnet-replace.PID.XXXXXXXX``; the stage is then marked ready (:data:`READY`, written atomically:
the commit), its files are moved over the earlier run's, and the earlier run's other files are removed last.

A kill before the commit leaves the earlier run whole (its stage is removed by the next run into the folder); a kill
after it is completed by the next run (:func:`finish_replacements`): the folder holds one run or the other, never a
mix that a resume would read.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from collections.abc import Callable, Iterable
from pathlib import Path, PurePosixPath

from semattnet._errors import InputError
from semattnet._utils.atomic import atomic_path, fsync_dir, pid_alive
from semattnet._utils.outputs import OutputError

__all__ = [
    "READY",
    "REPLACE_PREFIX",
    "Owned",
    "commit_stage",
    "drop_stages",
    "finish_replacements",
    "open_stage",
    "refuse_inputs_inside",
    "replace_run",
]

#: The stage folder of a run replacing an earlier one: ``OUT/.semattnet-replace.PID.XXXXXXXX``.
REPLACE_PREFIX = ".semattnet-replace."

#: The commit mark inside a stage: JSON, ``{"move": [relative paths]}``, written once the stage holds the first state.
READY = ".ready.json"

#: The files (and folders) of a run that lie in ``folder``, as paths relative to it.
Owned = Callable[[Path], list[str]]


def refuse_inputs_inside(out: str | os.PathLike[str], inputs: Iterable[str | os.PathLike[str] | None]) -> None:
    """Refuse every existing input that lies inside the run folder ``out`` (by its path or where it resolves to, ``out``
    as given or resolved): a run there, or an ``--overwrite`` of it, could replace or remove it.

    Raises:
        InputError: naming the input and the folder.
    """
    roots = (Path(os.path.abspath(Path(out).expanduser())), Path(out).expanduser().resolve())
    for item in inputs:
        if item is None or not (Path(item).exists() or Path(item).is_symlink()):
            continue
        places = (Path(os.path.abspath(Path(item).expanduser())), Path(item).expanduser().resolve())
        if any(place.is_relative_to(root) for place in places for root in roots):
            raise InputError(
                f"{item}: an input of this run lies inside its run folder {out}, where the run (or "
                "--overwrite) replaces files: move it out of the folder or choose another --out"
            )


def open_stage(out: Path) -> Path:
    """A fresh stage folder inside ``out`` for a run that replaces the earlier one there: the run writes into it (with
    the names its files have in ``out``) until :func:`commit_stage`."""
    out.mkdir(parents=True, exist_ok=True)
    return Path(tempfile.mkdtemp(prefix=f"{REPLACE_PREFIX}{os.getpid()}.", dir=out))


def commit_stage(stage: Path, out: Path, owned: Owned) -> None:
    """Mark ``stage`` ready (atomically: the commit), then move it over the earlier run in ``out`` and remove the
    earlier run's files that it does not replace (``owned(out)``). Call it once the stage holds a whole state."""
    _mark(stage, owned)
    _complete(stage, out, owned)


def replace_run(out: Path, owned: Owned, write: Callable[[Path], None]) -> None:
    """The first state of a run that replaces the earlier one in ``out``: ``write(stage)`` writes it into a fresh
    stage (:func:`open_stage`), which is then committed (:func:`commit_stage`). An error (or a kill) before the commit
    leaves ``out`` as it was."""
    stage = open_stage(out)
    try:
        write(stage)
        _mark(stage, owned)
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise
    _complete(stage, out, owned)


def _mark(stage: Path, owned: Owned) -> None:
    """The commit: :data:`READY` in ``stage``, listing the run's files there, written atomically."""
    with atomic_path(stage / READY, suffix=".json") as tmp:
        tmp.write_text(json.dumps({"move": owned(stage)}) + "\n")


def finish_replacements(out: Path, owned: Owned) -> None:
    """Before a run reads or writes ``out``: complete the replacements that a killed run had committed (its stage
    ready) and remove the stages it had not (the earlier run stays). Stages of live processes are left alone."""
    if not out.is_dir():
        return
    for stage in sorted(out.glob(f"{REPLACE_PREFIX}*")):
        pid = stage.name[len(REPLACE_PREFIX) :].split(".")[0]
        if stage.is_symlink() or not stage.is_dir() or not pid.isdigit() or pid_alive(int(pid)):
            continue
        if (stage / READY).is_file():
            _complete(stage, out, owned)
        else:
            shutil.rmtree(stage, ignore_errors=True)


def drop_stages(out: Path) -> None:
    """Remove this process's stages in ``out`` that are not committed (a run that failed before its first state):
    the earlier run stays as it was. A committed one is left for :func:`finish_replacements`."""
    for stage in out.glob(f"{REPLACE_PREFIX}{os.getpid()}.*"):
        if stage.is_dir() and not stage.is_symlink() and not (stage / READY).exists():
            shutil.rmtree(stage, ignore_errors=True)


def _complete(stage: Path, out: Path, owned: Owned) -> None:
    """Move the committed ``stage`` over the earlier run in ``out`` (what a kill already moved is skipped), remove
    the earlier run's other files, then the stage (its mark first). Repeatable after a kill at any point."""
    moves = _read_ready(stage, out)
    parents = {out}
    for rel in moves:
        source, target = stage / rel, out / rel
        if not (source.exists() or source.is_symlink()):
            continue  # moved before a kill
        target.parent.mkdir(parents=True, exist_ok=True)
        if target.is_dir() and not target.is_symlink():
            shutil.rmtree(target)  # a run's folder (tensorboard/): the staged one replaces it whole
        os.replace(source, target)
        parents.add(target.parent)
    for rel in owned(out):
        if rel not in moves:
            _remove(out / rel)
    for parent in parents:
        fsync_dir(parent)
    (stage / READY).unlink()
    shutil.rmtree(stage, ignore_errors=True)


def _read_ready(stage: Path, out: Path) -> list[str]:
    """The relative paths a ready stage moves; a mark that is not what :func:`replace_run` writes is one line."""
    mark = stage / READY
    try:
        doc = json.loads(mark.read_text())
        moves = doc["move"] if isinstance(doc, dict) else None
    except (OSError, ValueError, KeyError, RecursionError) as exc:
        raise _damaged(mark, out, f"unreadable ({type(exc).__name__})") from None
    if not isinstance(moves, list) or not all(isinstance(m, str) and _plain(m) for m in moves):
        raise _damaged(mark, out, "not a list of the run's files")
    return moves


def _plain(rel: str) -> bool:
    """A relative path that stays inside its folder (no ``..``, not absolute, not empty)."""
    path = PurePosixPath(rel)
    return bool(rel) and not path.is_absolute() and ".." not in path.parts and "\\" not in rel


def _damaged(mark: Path, out: Path, what: str) -> OutputError:
    return OutputError(
        f"{mark}: damaged mark of a run replacing the one in {out} ({what}); remove {mark.parent} "
        "if the earlier run is whole, or start over with --overwrite"
    )


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    else:
        path.unlink(missing_ok=True)
