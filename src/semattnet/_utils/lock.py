"""The lock on an output folder a run writes into over time (rule 6 of :mod:`semattnet._utils.outputs`)."""

from __future__ import annotations

import errno
import os
import stat
import weakref
from pathlib import Path

from semattnet._utils.extras import optional
from semattnet._utils.outputs import OutputError

__all__ = ["LOCK_FILE", "FolderBusyError", "FolderLock", "LockFileError"]

#: The lock file of an output folder a run is writing into (:class:`FolderLock`).
LOCK_FILE = ".semattnet.lock"


class FolderBusyError(OutputError):
    """An output folder another semattnet run is writing into (:class:`FolderLock`)."""


class LockFileError(OutputError):
    """A lock file that is a link (symbolic, or a hard link: a file with another name) or not a regular file: refused,
    never opened for writing (writing it would rewrite someone else's file)."""


class FolderLock:
    """An advisory lock on the output folder ``folder``: ``folder/.semattnet.lock``, ``flock``-ed and holding
    the process id, while a run writes into it. The operating system releases it when the process ends (a kill
    too); where ``flock`` is not supported, a lock file whose process is gone is stale and taken over.
    :meth:`release` removes the file (and the folder when :meth:`acquire` created it and it is empty).

    Raises:
        FolderBusyError: (:meth:`acquire`) another run holds the folder, naming its process.
        LockFileError: (:meth:`acquire`) the lock file is a symbolic or hard link, or not a regular file.
    """

    def __init__(self, folder: str | os.PathLike[str]) -> None:
        self.folder = Path(folder)
        self.path = self.folder / LOCK_FILE
        self.created = False
        self._release: weakref.finalize[[int, Path], FolderLock] | None = None  # runs when dropped too

    def acquire(self) -> FolderLock:
        """Take the lock (a path that is not a folder is left to the output checks: nothing is taken)."""
        if (self.folder.exists() or self.folder.is_symlink()) and not self.folder.is_dir():
            return self  # a file or a dangling link
        self.created = not self.folder.exists()
        self.folder.mkdir(parents=True, exist_ok=True)
        try:
            for _ in range(5):  # the file was removed by the holder between open and flock: again
                fd = self._open()
                if self._lock(fd) and _same_file(fd, self.path):
                    os.ftruncate(fd, 0)
                    os.write(fd, f"{os.getpid()}\n".encode())
                    self._release = weakref.finalize(self, _unlock, fd, self.path)
                    return self
                os.close(fd)
        except BaseException:
            self.release()
            raise
        raise FolderBusyError(f"{self.path}: could not be locked; choose another --out")

    def _open(self) -> int:
        """The lock file, opened (created if missing) without following a symbolic link, and refused unless it is a
        regular file of one name: checked on the open file, before anything is written."""
        if self.path.is_symlink():  # where O_NOFOLLOW is missing; where it is there, the open refuses it too
            raise self._refuse("is a symbolic link")
        try:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0), 0o644)
        except OSError as exc:
            if exc.errno == errno.ELOOP or self.path.is_symlink():
                raise self._refuse("is a symbolic link") from None
            if self.path.is_dir():
                raise self._refuse("is a folder") from None
            raise
        info = os.fstat(fd)
        if stat.S_ISREG(info.st_mode) and info.st_nlink <= 1:  # 0: its holder removed it meanwhile (tried again)
            return fd
        os.close(fd)
        raise self._refuse(
            f"has {info.st_nlink} names (a hard link)" if stat.S_ISREG(info.st_mode) else "is not a regular file"
        )

    def _refuse(self, what: str) -> LockFileError:
        return LockFileError(
            f"{self.path}: the lock file {what}; semattnet writes its process id into a plain file of its own "
            "only: remove it, or choose another --out"
        )

    def _lock(self, fd: int) -> bool:
        """``flock`` ``fd``; a lock held by a live process is :class:`FolderBusyError`."""
        fcntl = optional("fcntl")  # None off POSIX
        try:
            if fcntl is None:
                raise OSError("no flock")
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return True
        except BlockingIOError:
            holder = _holder(fd)
        except OSError:  # no flock here: the process id alone says whether it is held
            from semattnet._utils.atomic import pid_alive

            holder = _holder(fd)
            if holder is None or holder == os.getpid() or not pid_alive(holder):
                return True
        os.close(fd)
        who = f"process {holder}" if holder is not None else "another process"
        raise FolderBusyError(
            f"{self.folder}: another semattnet run ({who}) is writing into it ({self.path}); "
            "wait for it to end or choose another --out"
        )

    def release(self) -> None:
        """Give the lock up (idempotent)."""
        if self._release is not None:
            self._release()
            self._release = None
        if self.created and self.folder.is_dir() and not any(self.folder.iterdir()):
            self.folder.rmdir()  # a run that left nothing leaves no empty folder it made
        self.created = False

    def __enter__(self) -> FolderLock:
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()


def _unlock(fd: int, path: Path) -> None:
    path.unlink(missing_ok=True)
    os.close(fd)


def _same_file(fd: int, path: Path) -> bool:
    """Whether ``path`` is still the file open as ``fd`` (the holder removes it when it lets go)."""
    try:
        return os.fstat(fd).st_ino == path.stat().st_ino
    except OSError:
        return False


def _holder(fd: int) -> int | None:
    """The process id written in the lock file ``fd``, None when unreadable."""
    try:
        text = os.pread(fd, 32, 0).decode("ascii").strip()
    except (OSError, UnicodeDecodeError):
        return None
    return int(text) if text.isdigit() else None
