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
unpacked safely (:mod:`semattnet.data.archives`: a member with an absolute path or ``..`` refuses the whole
archive; files already unpacked with the right size are skipped, so a second run resumes) and finally
:func:`semattnet.data.kitti.check.check_trees` checks the tree.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from semattnet._errors import InputError
from semattnet._utils.outputs import mark_tree
from semattnet.cache import fetch
from semattnet.data.archives import RESUME_HINT, LicenseNotAcceptedError, check_mirror, extract_zip
from semattnet.data.kitti import server as kf

__all__ = ["WHAT", "PlannedFile", "download_kitti", "drives_for", "parse_what", "plan_part"]

#: The parts ``what`` may name, in the order they are fetched.
WHAT = ("depth-completion", "raw-subset", "semantic")
Log = Callable[[str], None]


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
        mark_tree(out, "data download", False, resume=RESUME_HINT)
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
