"""Dataset archives: the terms a download asks to accept, mirrors, and safe unpacking.

Shared by :mod:`semattnet.data.download` (the registered datasets) and :mod:`semattnet.data.kitti.download`
(KITTI's archives). An archive is unpacked safely: a member with an absolute path or ``..`` refuses the whole
archive, links and zip bombs are refused, a file the archive did not write is never replaced, and files already
unpacked with the right size are skipped, so a second run resumes.
"""

from __future__ import annotations

import os
import re
import shutil
import stat
import tarfile
import zipfile
from collections.abc import Callable, Sequence
from pathlib import Path, PurePosixPath

from semattnet._errors import DataError, InputError
from semattnet._utils.atomic import disk_full_error, is_disk_full

__all__ = [
    "ARCHIVE_RATIO_FLOOR",
    "MAX_ARCHIVE_RATIO",
    "RESUME_HINT",
    "ArchiveConflictError",
    "LicenseNotAcceptedError",
    "UnsafeArchiveError",
    "check_mirror",
    "extract_archive",
    "extract_tar",
    "extract_zip",
]

#: How to finish a download that was cut short (files already unpacked are kept and skipped).
RESUME_HINT = "run the same data download command again (it resumes)"


class LicenseNotAcceptedError(InputError):
    """A dataset's terms were not accepted (``accept_license=False``)."""


class UnsafeArchiveError(DataError):
    """An archive member would be written outside the target folder (absolute path or ``..``)."""


def check_mirror(mirror: str | None) -> str | None:
    """``mirror`` when it is an ``http(s)://`` or ``file://`` URL prefix (or None).

    Raises:
        InputError: anything else, naming ``--mirror`` (a bare path or text would be taken for a weights name).
    """
    if mirror is not None and not re.match(r"^(https?|file)://[^\s]*$", mirror):
        raise InputError(
            f"--mirror: expected an http(s):// or file:// URL prefix (a local folder: "
            f"file:///path/to/it), got {mirror!r}"
        )
    return mirror


def _safe_member(name: str, archive: Path) -> PurePosixPath:
    """The member's relative path, or :class:`UnsafeArchiveError` for absolute paths and ``..``."""
    parts = re.split(r"[\\/]+", name)
    if name.startswith(("/", "\\")) or re.match(r"^[A-Za-z]:", name) or ".." in parts:
        raise UnsafeArchiveError(f"{archive}: refusing member {name!r} (absolute path or '..'); nothing unpacked")
    return PurePosixPath(*[p for p in parts if p not in ("", ".")])


def _strip(rel: PurePosixPath, strip: Sequence[str]) -> PurePosixPath:
    if rel.parts and rel.parts[0] in strip:
        return PurePosixPath(*rel.parts[1:])
    return rel


class ArchiveConflictError(DataError):
    """Files in the target folder that an archive would replace but that it did not write."""


def _plan(
    path: Path, dest: Path, items: Sequence[tuple[object, PurePosixPath, int]]
) -> tuple[list[tuple[object, Path]], int]:
    """The members to write as (member, target) and the count already there (a file of the member's
    size: what an earlier run of ours wrote, as every file is moved into place complete).

    Raises:
        UnsafeArchiveError: a member resolves outside ``dest`` (through a symlink in the tree).
        ArchiveConflictError: targets that exist with other sizes or as folders (never replaced).
    """
    base = dest.resolve()
    todo: list[tuple[object, Path]] = []
    conflicts: list[Path] = []
    skipped = 0
    for member, rel, size in items:
        out = dest.joinpath(*rel.parts)
        if not out.parent.resolve().is_relative_to(base):
            raise UnsafeArchiveError(f"{path}: member {rel} leaves {dest}; nothing unpacked")
        if out.is_symlink():
            conflicts.append(out)  # never written through nor replaced
        elif out.is_file() and out.stat().st_size == size:
            skipped += 1
        elif out.exists():
            conflicts.append(out)
        else:
            todo.append((member, out))
    if conflicts:
        more = f" (and {len(conflicts) - 3} more)" if len(conflicts) > 3 else ""
        names = ", ".join(str(c) for c in conflicts[:3])
        msg = f"{len(conflicts)} file(s) where members unpack were not written by this archive: {names}{more}"
        raise ArchiveConflictError(f"{path}: {msg}; move them away and run again; nothing unpacked")
    return todo, skipped


def _write(opener: Callable[[object], object], todo: Sequence[tuple[object, Path]]) -> int:
    """Copy each member to a ``.part`` file next to its target, then move it into place; a failure
    (a full disk) removes the ``.part`` and raises :class:`OSError` naming the target and the space needed."""
    for member, out in todo:
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_name(f".{out.name}.part")
        try:
            with opener(member) as src, open(tmp, "wb") as dst:  # type: ignore[attr-defined]
                shutil.copyfileobj(src, dst, 1 << 20)
            os.replace(tmp, out)
        except OSError as exc:
            tmp.unlink(missing_ok=True)
            if is_disk_full(exc):
                raise disk_full_error(out, getattr(member, "file_size", getattr(member, "size", None))) from None
            raise
    return len(todo)


#: A dataset archive's member above this many bytes may not inflate more than MAX_ARCHIVE_RATIO : 1, nor may
#: all members together inflate beyond that ratio of the archive (image and scan data compress < 10:1).
ARCHIVE_RATIO_FLOOR = 64 * 1024 * 1024
MAX_ARCHIVE_RATIO = 100


def _refuse_bombs(path: Path, sizes: Sequence[tuple[str, int, int]]) -> None:
    """(name, inflated, compressed) of each member: a zip bomb is refused before anything is written."""
    for name, full, packed in sizes:
        if full > ARCHIVE_RATIO_FLOOR and full > MAX_ARCHIVE_RATIO * max(packed, 1):
            raise UnsafeArchiveError(
                f"{path}: member {name!r} inflates {packed} bytes to {full} (more than "
                f"{MAX_ARCHIVE_RATIO}:1); refusing a zip bomb; nothing unpacked"
            )
    total, limit = sum(s[1] for s in sizes), MAX_ARCHIVE_RATIO * path.stat().st_size + ARCHIVE_RATIO_FLOOR
    if total > limit:
        raise UnsafeArchiveError(
            f"{path}: members inflate to {total} bytes, more than the {limit} accepted for "
            f"this archive's size; refusing a bomb; nothing unpacked"
        )


def _refuse_links_and_duplicates(zf: zipfile.ZipFile, path: Path) -> None:
    """Symlink members (Unix mode in ``external_attr``) and a name given twice are refused, as in tar."""
    seen: set[str] = set()
    for info in zf.infolist():
        if stat.S_ISLNK(info.external_attr >> 16):
            raise UnsafeArchiveError(f"{path}: refusing member {info.filename!r} (a symbolic link); nothing unpacked")
        if info.filename in seen:
            raise UnsafeArchiveError(f"{path}: member {info.filename!r} is in the archive twice; nothing unpacked")
        seen.add(info.filename)


def extract_zip(
    path: str | Path, dest: str | Path, strip: Sequence[str] = (), keep: Sequence[str] = ()
) -> tuple[int, int]:
    """Unpack ``path`` into ``dest`` safely; return (files written, files already there).

    Args:
        strip: a leading folder with one of these names is removed from member paths.
        keep: unpack only members with one of these folder names in their path (empty: all).

    Raises:
        UnsafeArchiveError: a member has an absolute path or ``..`` (checked before anything is written).
        ArchiveConflictError: files the archive did not write sit where members unpack (nothing written).
    """
    path, dest = Path(path), Path(dest)
    try:
        zf = zipfile.ZipFile(path)
    except zipfile.BadZipFile as exc:
        raise DataError(f"{path}: not a zip archive ({exc})") from None
    with zf:
        _refuse_links_and_duplicates(zf, path)
        _refuse_bombs(path, [(i.filename, i.file_size, i.compress_size) for i in zf.infolist()])
        members = [(info, _strip(_safe_member(info.filename, path), strip)) for info in zf.infolist()]
        items = [
            (info, rel, info.file_size)
            for info, rel in members
            if not info.is_dir() and rel.parts and (not keep or set(keep) & set(rel.parts[:-1]))
        ]
        dest.mkdir(parents=True, exist_ok=True)
        todo, skipped = _plan(path, dest, items)
        return _write(zf.open, todo), skipped  # type: ignore[arg-type]


def extract_tar(path: str | Path, dest: str | Path, strip: Sequence[str] = ()) -> tuple[int, int]:
    """Unpack a (compressed) tar archive into ``dest`` as :func:`extract_zip` does: members checked before
    anything is written (absolute paths, ``..``, links refused, files we did not write never replaced),
    files already there with their size skipped."""
    path, dest = Path(path), Path(dest)
    try:
        tf = tarfile.open(path)
    except tarfile.TarError as exc:
        raise DataError(f"{path}: not a tar archive ({exc})") from None
    with tf:
        infos = tf.getmembers()
        for info in infos:
            if info.issym() or info.islnk() or info.isdev():
                raise UnsafeArchiveError(f"{path}: refusing member {info.name!r} (a link or device); nothing unpacked")
        _refuse_bombs(path, [("(all members)", sum(i.size for i in infos if i.isfile()), path.stat().st_size)])
        members = [(info, _strip(_safe_member(info.name, path), strip)) for info in infos if info.isfile()]
        dest.mkdir(parents=True, exist_ok=True)
        todo, skipped = _plan(path, dest, [(info, rel, info.size) for info, rel in members if rel.parts])
        return _write(tf.extractfile, todo), skipped  # type: ignore[arg-type]


def extract_archive(path: str | Path, dest: str | Path, strip: Sequence[str] = ()) -> tuple[int, int]:
    """:func:`extract_zip` or :func:`extract_tar`, by the file's content."""
    return extract_zip(path, dest, strip) if zipfile.is_zipfile(path) else extract_tar(path, dest, strip)
