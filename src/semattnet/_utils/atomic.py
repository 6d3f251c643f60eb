"""Atomic file writes: write a temporary file beside the target, then rename it into place.

The temporary file is ``.NAME.pPID.XXXXXXXX[SUFFIX]`` in the target's folder. A process killed
mid-write leaves it behind; the next write of the same target (by any process) removes such
orphans whose process is gone. Files end up with the mode the umask gives a new file
(``0o666 & ~umask``), or the mode of the file they replace, and are fsynced (file and folder)
before the call returns, so a power cut leaves either the old or the new content.
"""

from __future__ import annotations

import errno
import os
import re
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = [
    "atomic_path",
    "clean_stale_temps",
    "disk_full_error",
    "fsync_dir",
    "full_disk_named",
    "is_disk_full",
    "new_file_mode",
    "no_space_left",
    "pid_alive",
]

#: errno values of a full disk or an exhausted quota.
_FULL = {errno.ENOSPC, errno.EDQUOT}


def is_disk_full(exc: BaseException) -> bool:
    """Whether ``exc`` is an :class:`OSError` of a full disk (ENOSPC) or quota (EDQUOT)."""
    return isinstance(exc, OSError) and exc.errno in _FULL


def _mib(n: int) -> str:
    return f"{n / 2**20:.1f} MiB" if n >= 2**20 else f"{n / 2**10:.1f} KiB"


def disk_full_error(path: str | os.PathLike[str], needed: int | None = None) -> OSError:
    """The one-line :class:`OSError` (ENOSPC) for a write of ``path`` that filled the disk: names the path,
    the space free on its file system and ``needed`` (bytes the write needed at least, when known)."""
    probe = Path(path)
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    try:
        free: int | None = shutil.disk_usage(probe).free
    except OSError:
        free = None
    facts = ([f"{_mib(free)} free"] if free is not None else []) + (
        [f"at least {_mib(needed)} needed"] if needed else []
    )
    detail = f" ({', '.join(facts)})" if facts else ""
    return OSError(errno.ENOSPC, f"no space left on the device{detail}; nothing was written", str(path))


def is_named_disk_full(exc: BaseException) -> bool:
    """Whether ``exc`` is already a :func:`disk_full_error` (naming its path and the space)."""
    return is_disk_full(exc) and bool(getattr(exc, "filename", None)) and "no space left on the device" in str(exc)


def no_space_left(path: Path) -> bool:
    """Whether the file system that holds (or would hold) ``path`` has less than 1 MiB free."""
    while not path.exists() and path != path.parent:
        path = path.parent
    try:
        return shutil.disk_usage(path).free < 2**20
    except OSError:
        return False


@contextmanager
def full_disk_named(path: str | os.PathLike[str], staged: str | os.PathLike[str] | None = None) -> Iterator[None]:
    """Inside the block, a full disk is the one-line :func:`disk_full_error` naming ``path`` (``staged``: the
    folder whose size says what was written so far). Covers a bare ENOSPC without a path and the errors of
    writers that hide it (a ``RuntimeError`` from a library's writer thread while the file system of ``path``
    has no space left)."""
    try:
        yield
    except (OSError, RuntimeError) as exc:
        folder = Path(staged) if staged is not None else None
        name = getattr(exc, "filename", None)
        inner = is_named_disk_full(exc) and folder is not None and Path(str(name)).is_relative_to(folder)
        if (is_named_disk_full(exc) and not inner) or not (is_disk_full(exc) or no_space_left(Path(path))):
            raise
        size = sum(p.stat().st_size for p in folder.rglob("*") if p.is_file()) if folder and folder.is_dir() else 0
        raise disk_full_error(path, size or None) from None


def new_file_mode() -> int:
    """The mode ``open()`` gives a new file under the current umask: ``0o666 & ~umask``."""
    mask = os.umask(0o022)
    os.umask(mask)
    return 0o666 & ~mask


def pid_alive(pid: int) -> bool:
    """Whether process ``pid`` exists (ours counts; one of another user counts too)."""
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return pid < 2**22  # exists but belongs to someone else (or an impossible pid)
    return True


def clean_stale_temps(path: str | os.PathLike[str]) -> list[Path]:
    """Remove temporary files a killed write of ``path`` left (``.NAME.pPID.*`` whose process is
    gone, and the older ``.NAME.XXXXXXXX*`` form); returns what was removed."""
    path = Path(path)
    pattern = re.compile(rf"^\.{re.escape(path.name)}\.(?:p(\d+)\.)?[a-z0-9_]{{8}}(?:\.[A-Za-z0-9]+)?$")
    removed: list[Path] = []
    try:
        entries = list(path.parent.iterdir())
    except OSError:
        return removed
    for entry in entries:
        m = pattern.match(entry.name)
        if m is None or not entry.is_file() or (m.group(1) and pid_alive(int(m.group(1)))):
            continue
        try:
            entry.unlink()
            removed.append(entry)
        except FileNotFoundError:
            pass
    return removed


def _fsync_file(path: str) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def fsync_dir(folder: str | os.PathLike[str]) -> None:
    """Flush a folder's entries (a rename into it) to disk; a no-op where folders cannot be opened."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextmanager
def atomic_path(path: str | os.PathLike[str], suffix: str = "", fsync: bool = True) -> Iterator[Path]:
    """Yield a temporary path in ``path``'s folder; on success it replaces ``path`` in one step.

    If the block raises, ``path`` keeps its previous content and the temporary file is removed (a full
    disk raises :func:`disk_full_error` naming ``path``);
    after a kill the temporary file is removed by the next write of ``path``. The new file gets
    the umask's mode (or the replaced file's mode); with ``fsync`` it is on disk on return. A ``path`` that
    is a FIFO, a device or a socket (``--json /dev/null`` as root) is never replaced: :class:`FileExistsError`.
    """
    path = Path(path)
    if not path.is_symlink() and path.exists() and not path.is_file() and not path.is_dir():
        raise FileExistsError(f"{path} is a FIFO, device or socket, not a regular file; refusing to replace it")
    path.parent.mkdir(parents=True, exist_ok=True)
    clean_stale_temps(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.p{os.getpid()}.", suffix=suffix, dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        try:
            mode = path.stat().st_mode & 0o7777
        except OSError:
            mode = new_file_mode()
        os.chmod(tmp, mode)
        if fsync:
            _fsync_file(tmp)
        os.replace(tmp, path)
        if fsync:
            fsync_dir(path.parent)
    except OSError as exc:
        if not is_disk_full(exc) or exc.filename == str(path):
            raise
        size = os.path.getsize(tmp) if os.path.exists(tmp) else 0
        raise disk_full_error(path, size + 1) from None
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
