"""``semattnet data download --dataset NAME``: the archives of a registered dataset
(:mod:`semattnet.data.datasets`) fetched, unpacked safely (:mod:`semattnet.data.archives`) and checked; KITTI's
through :func:`semattnet.data.kitti.download.download_kitti`."""

from __future__ import annotations

from pathlib import Path

from semattnet._utils.outputs import mark_tree
from semattnet.data.archives import RESUME_HINT, LicenseNotAcceptedError, check_mirror, extract_archive
from semattnet.data.kitti.download import Log, download_kitti

__all__ = ["download_dataset"]


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
        mark_tree(out, "data download", False, resume=RESUME_HINT)
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
