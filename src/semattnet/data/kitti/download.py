"""Download KITTI depth completion (and the raw drives it needs) into the layout the loaders read.

What ``semattnet data download`` runs. Three parts, chosen with ``what``:

* ``depth-completion``: ``data_depth_annotated.zip``, ``data_depth_velodyne.zip`` and
  ``data_depth_selection.zip`` into ``ROOT/data_depth_annotated``, ``ROOT/data_depth_velodyne`` and
  ``ROOT/data_depth_selection`` (:mod:`semattnet.data.kitti.layout`).
* ``raw-subset``: the raw drive of every drive folder found under ``ROOT/data_depth_annotated/{train,val}``
  (or, before that archive is unpacked, the lists in :mod:`semattnet.data.kitti.server`), of which
  only ``image_02`` / ``image_03`` are unpacked, into ``ROOT/kitti_raw/<date>/<drive>/``, and each
  day's calibration files into ``ROOT/kitti_raw/<date>/``.
* ``semantic``: the authors' semantic maps, from an archive the user names (their Google Drive
  link is not recorded, so it cannot be fetched automatically), into ``ROOT/semantic``.

Every file goes through :func:`semattnet.cache.fetch` (resumable, atomic, checked against
its pin: KITTI publishes no checksums, so the first download of each archive is pinned), then is
unpacked safely (a member with an absolute path or ``..`` refuses the whole archive; files already
unpacked with the right size are skipped, so a second run resumes) and finally
:func:`semattnet.data.kitti.check.check_trees` checks the tree.
"""

from __future__ import annotations

import os
import re
import shutil
import stat
import tarfile
import zipfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from semattnet._errors import DataError, InputError
from semattnet._utils.atomic import disk_full_error, is_disk_full
from semattnet._utils.outputs import mark_tree
from semattnet.cache import fetch
from semattnet.data.kitti import server as kf

__all__ = [
    "WHAT",
    "ArchiveConflictError",
    "LicenseNotAcceptedError",
    "PlannedFile",
    "UnsafeArchiveError",
    "check_mirror",
    "download_dataset",
    "download_kitti",
    "drives_for",
    "extract_archive",
    "extract_tar",
    "extract_zip",
    "parse_what",
    "plan_part",
]

#: The parts ``what`` may name, in the order they are fetched.
WHAT = ("depth-completion", "raw-subset", "semantic")
Log = Callable[[str], None]


class LicenseNotAcceptedError(InputError):
    """KITTI's licence was not accepted (``accept_license=False``)."""


class UnsafeArchiveError(DataError):
    """An archive member would be written outside the target folder (absolute path or ``..``)."""


@dataclass(frozen=True)
class PlannedFile:
    """One file to fetch: from ``url`` (None: must be fetched by hand) into ``target``."""

    part: str
    url: str | None
    target: Path
    size: str | None = None
    archive: kf.KittiArchive | None = None


def parse_what(text: str | Sequence[str]) -> tuple[str, ...]:
    """``"depth-completion,raw-subset"`` (or ``"all"``) -> the parts, in fetch order."""
    items = text.split(",") if isinstance(text, str) else list(text)
    chosen = {t.strip() for t in items if t.strip()}
    if "all" in chosen:
        return WHAT
    unknown = chosen - set(WHAT)
    if unknown or not chosen:
        raise InputError(f"unknown part(s) {sorted(unknown) or '(none)'}; choose from {', '.join(WHAT)} or all")
    return tuple(w for w in WHAT if w in chosen)


def drives_for(root: str | Path) -> tuple[list[str], str]:
    """Drives whose raw images the benchmark needs, and where the list came from.

    The drive folders under ``root/data_depth_annotated/{train,val}`` when there are any, else the
    lists shipped in :mod:`semattnet.data.kitti.server`.
    """
    annotated = Path(root) / "data_depth_annotated"
    found = sorted(
        {
            p.name
            for split in ("train", "val")
            if (annotated / split).is_dir()
            for p in (annotated / split).iterdir()
            if p.is_dir() and re.fullmatch(r"\d{4}_\d\d_\d\d_drive_\d{4}_sync", p.name)
        }
    )
    if found:
        return found, f"{annotated}/{{train,val}}"
    shipped = sorted(kf.TRAIN_DRIVES + kf.VAL_DRIVES)
    return shipped, "the drive list shipped with semattnet (semattnet.data.kitti.server)"


def _url(prefix: str, archive: kf.KittiArchive) -> str:
    return prefix.rstrip("/") + "/" + archive.path


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


def plan_part(
    part: str, root: str | Path, mirror: str | None = None, semantic_archive: str | None = None
) -> tuple[list[PlannedFile], str]:
    """The files of one part (see :data:`WHAT`) and a note on where the list came from."""
    root, prefix = Path(root), check_mirror(mirror) or kf.KITTI_PREFIX
    if part == "depth-completion":
        archives = list(kf.DEPTH_COMPLETION_ARCHIVES)
        return [PlannedFile(part, _url(prefix, a), root / a.target, a.size, a) for a in archives], ""
    if part == "raw-subset":
        drives, source = drives_for(root)
        archives = [kf.calib_archive(d) for d in sorted({d[:10] for d in drives})]
        archives += [kf.raw_drive_archive(d) for d in drives]
        files = [PlannedFile(part, _url(prefix, a), root / a.target, a.size, a) for a in archives]
        return files, f"{len(drives)} drives from {source}"
    if part == "semantic":
        target = root / str(kf.SEMANTIC_MAPS["target"])
        archive = kf.KittiArchive("semantic", str(kf.SEMANTIC_MAPS["target"]), strip=("semantic", "semantics"))
        return [PlannedFile(part, semantic_archive, target, None, archive)], ""
    raise InputError(f"unknown part {part!r}; choose from {', '.join(WHAT)}")


# ----------------------------------------------------------------------------- unpacking


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


#: How to finish a download that was cut short (files already unpacked are kept and skipped).
_RESUME = "run the same data download command again (it resumes)"


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


# ----------------------------------------------------------------------------- the command


def _show(files: Sequence[PlannedFile], note: str, log: Log) -> None:
    if note:
        log(f"  ({note})")
    for f in files:
        if f.url is None:
            log(f"  [manual]  -> {f.target}")
            log("    " + str(kf.SEMANTIC_MAPS["instructions"]))
        else:
            only = f" (only {', '.join(f.archive.keep)})" if f.archive is not None and f.archive.keep else ""
            log(f"  {f.url}  [{f.size or 'size unknown'}]  -> {f.target}{only}")


def _get(f: PlannedFile, cache_dir: str | Path | None, progress: bool, delete: bool, log: Log) -> None:
    """Fetch one planned file (a URL, or a local path for the semantic archive) and unpack it."""
    assert f.archive is not None and f.url is not None
    local = Path(f.url).expanduser()
    is_local = "://" not in f.url and local.is_file()
    if not is_local:
        local = fetch(f.url, cache_dir=cache_dir, file_name=f.url.rsplit("/", 1)[-1] or None, progress=progress)
    written, skipped = extract_zip(local, f.target, f.archive.strip, f.archive.keep)
    again = f" ({skipped} already there)" if skipped else ""
    log(f"  {local.name}: {written} files unpacked into {f.target}{again}")
    if delete and not is_local:
        local.unlink()


def download_kitti(
    out: str | Path,
    what: str | Sequence[str] = "depth-completion,raw-subset",
    *,
    accept_license: bool = False,
    dry_run: bool = False,
    mirror: str | None = None,
    semantic_archive: str | None = None,
    cache_dir: str | Path | None = None,
    delete_archives: bool = False,
    check: bool = True,
    progress: bool = True,
    log: Log = print,
) -> int:
    """Download, unpack and check; returns the number of problems the check found (0 for a dry run).

    Raises:
        LicenseNotAcceptedError: ``accept_license`` is false (a dry run only prints the licence).
        UnsafeArchiveError: an archive tries to write outside its folder.
        semattnet.cache.DownloadError: a download failed (resume by running again).
    """
    out, parts = Path(out), parse_what(what)
    if not accept_license and not dry_run:
        raise LicenseNotAcceptedError(f"{kf.KITTI_LICENSE} -- pass --accept-kitti-license to accept it")
    log(kf.KITTI_LICENSE)
    if not dry_run:
        mark_tree(out, "data download", False, resume=_RESUME)
    for part in parts:
        files, note = plan_part(part, out, mirror, semantic_archive)
        log(f"{part}:")
        if dry_run:
            _show(files, note, log)
            continue
        for f in files:
            if f.url is None:
                log("  " + str(kf.SEMANTIC_MAPS["instructions"]))
            else:
                _get(f, cache_dir, progress, delete_archives, log)
    if not dry_run:
        mark_tree(out, "data download", True)
    if dry_run or not check:
        return 0
    from semattnet.data.kitti.check import check_trees

    raw, sem = out / "kitti_raw", out / str(kf.SEMANTIC_MAPS["target"])
    return check_trees([out], raw if raw.is_dir() else None, sem if sem.is_dir() else None, log=log)


def download_dataset(
    dataset: str,
    out: str | Path,
    *,
    accept_license: bool = False,
    dry_run: bool = False,
    mirror: str | None = None,
    cache_dir: str | Path | None = None,
    delete_archives: bool = False,
    check: bool = True,
    progress: bool = True,
    log: Log = print,
) -> int:
    """``data download --dataset NYUV2|VOID``: each archive of the entry (:mod:`semattnet.data.datasets`)
    through :func:`semattnet.cache.fetch` (``MIRROR/FILE`` when ``mirror`` is given: an
    ``https://`` or ``file://`` prefix; sha256 pinned on first use; resumable), unpacked into ``out``, then
    checked (``data check --dataset``). Returns the number of problems the check found.

    Raises:
        LicenseNotAcceptedError: ``accept_license`` is false (a dry run only prints the terms).
        semattnet.cache.DownloadError: a download failed (resume by running again).
    """
    from semattnet.data.datasets import get_dataset

    spec, out = get_dataset(dataset), Path(out)
    check_mirror(mirror)
    if spec.name == "kitti-dc":
        return download_kitti(
            out,
            accept_license=accept_license,
            dry_run=dry_run,
            mirror=mirror,
            cache_dir=cache_dir,
            delete_archives=delete_archives,
            check=check,
            progress=progress,
            log=log,
        )
    log(f"{spec.title}: {spec.licence}")
    if not accept_license and not dry_run:
        raise LicenseNotAcceptedError(f"{spec.name}: {spec.licence} -- pass --accept-license to accept the terms")
    if not dry_run:
        mark_tree(out, "data download", False, resume=_RESUME)
    for a in spec.archives:
        url = mirror.rstrip("/") + "/" + a.file if mirror else a.url
        if url is None:
            log(
                f"  {a.file}: no URL recorded for {spec.name} (the authors share it by a link): "
                f"download it by hand and pass --mirror file:///FOLDER/HOLDING/IT, or an HTTP mirror"
            )
            continue
        if dry_run:
            log(f"  {url}  [{a.size or 'size unknown'}]  -> {out}")
            continue
        _get_archive(url, a, out, cache_dir, progress, delete_archives, log)
    if not dry_run:
        mark_tree(out, "data download", True)
    if dry_run or not check:
        return 0
    return spec.check([out], log=log)


def _get_archive(
    url: str, archive: object, out: Path, cache_dir: str | Path | None, progress: bool, delete: bool, log: Log
) -> None:
    from semattnet.cache import fetch

    local = fetch(url, cache_dir=cache_dir, file_name=url.rsplit("/", 1)[-1] or None, progress=progress)
    written, skipped = extract_archive(local, out, getattr(archive, "strip", ()))
    again = f" ({skipped} already there)" if skipped else ""
    log(f"  {local.name}: {written} files unpacked into {out}{again}")
    if delete:
        local.unlink()
