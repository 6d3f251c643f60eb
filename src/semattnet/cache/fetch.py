"""Fetching one file into the cache: a cache hit is verified, a miss is downloaded, checked, moved in.

Every download lands in a temporary file in ``<dest folder>/.partial/``, is checked (size if
known, sha256 against the given value or the pin) and only then moved into place with
:func:`os.replace`; a file that fails a check is deleted. Mirrors are tried in order.
"""

from __future__ import annotations

import hashlib
import os
import re
from dataclasses import dataclass
from pathlib import Path

from semattnet._errors import InputError, MissingDependencyError
from semattnet._utils.atomic import disk_full_error, is_disk_full
from semattnet.cache.errors import ChecksumError, DownloadError, NotAFileError, OfflineError
from semattnet.cache.hf import fetch_hf
from semattnet.cache.store import (
    ENV_OFFLINE,
    announce_pin,
    cache_key,
    cache_lock,
    get_cache_dir,
    is_offline,
    pin_record,
    pins_path,
    read_pins,
    remove_empty_dirs,
    sha256_file,
    update_pins,
    verify_cached,
)
from semattnet.cache.transports import check_file_name, default_file_name, download_to, url_scheme

__all__ = ["Target", "check_sha256", "fetch", "fetch_target", "url_target"]


@dataclass(frozen=True)
class Target:
    """One file to have in the cache: where from (mirrors in order), where to, and how to check it."""

    urls: tuple[str, ...]
    dest: Path
    sha256: str | None
    size_bytes: int | None
    label: str


def check_sha256(sha256: str | None) -> str | None:
    """``sha256`` in lower case, or None; anything but 64 hex digits is an :class:`InputError`."""
    if sha256 is not None and not re.fullmatch(r"[0-9a-f]{64}", sha256.lower()):
        raise InputError(f"sha256 must be 64 hex digits, got {sha256!r}")
    return sha256.lower() if sha256 else None


def url_target(url: str, sha256: str | None, root: Path, file_name: str | None = None) -> Target:
    """The target of a plain URL: ``<root>/urls/<sha256(url)[:16]>/<file name>``."""
    name = check_file_name(file_name or default_file_name(url))
    slot = hashlib.sha256(url.encode()).hexdigest()[:16]
    return Target((url,), root / "urls" / slot / name, sha256, None, url)


def fetch(
    url: str,
    *,
    sha256: str | None = None,
    cache_dir: str | os.PathLike[str] | None = None,
    file_name: str | None = None,
    progress: bool = True,
) -> Path:
    """Download ``url`` into the cache (once) and return its local path.

    Args:
        url: ``http(s)://``, ``file://``, ``gdrive://<id>`` or ``hf://owner/repo[@rev][/file]``
            (without a file, the repository folder is returned).
        sha256: expected hex digest (None: pinned on first download).
        cache_dir: cache root (default ``$SEMATTNET_CACHE`` or the platform's user cache folder).
        file_name: name of the cached file (default: the URL's last path part).
        progress: show a progress bar.

    Raises:
        ChecksumError: the file does not match its checksum or size; nothing is left in the cache.
        OfflineError: offline mode and the file is not cached.
        DownloadError: every URL failed (the message lists each failure).
    """
    sha256 = check_sha256(sha256)
    if url_scheme(url) == "hf":
        return fetch_hf(url, sha256=sha256, cache_dir=cache_dir)
    root = get_cache_dir(cache_dir).resolve()
    return fetch_target(root, url_target(url, sha256, root, file_name), progress)[0]


def fetch_target(root: Path, t: Target, progress: bool) -> tuple[Path, str]:
    """The cached file of ``t`` and its sha256, downloading it if needed (under a lock)."""
    dest = t.dest
    if dest.is_file():
        try:
            return dest, verify_cached(root, dest, t.sha256, t.urls[0])
        except ChecksumError:
            if is_offline():
                raise
            # A damaged cached file: download again; the check below uses the same checksum.
    if is_offline():
        raise OfflineError(
            f"offline mode ({ENV_OFFLINE}/HF_HUB_OFFLINE) and {dest.name} is not cached: "
            f"download it from {t.urls[0]} and place it at {dest}"
        )
    with cache_lock(root, cache_key(root, dest)):
        if dest.is_file() and not _stale(root, dest, t.sha256):
            return dest, verify_cached(root, dest, t.sha256, t.urls[0])
        failures: list[str] = []
        checksum_failed = False
        for url in t.urls:
            try:
                return dest, _download_verified(root, url, t, progress)
            except ChecksumError as exc:
                checksum_failed = True
                failures.append(f"{url}: {exc}")
            except (NotAFileError, MissingDependencyError):
                raise  # a bad URL (a file:// URL of a FIFO or device), a missing package: no mirror changes it
            except OSError as exc:
                if is_disk_full(exc):
                    raise  # another mirror would fill the disk too
                failures.append(f"{url}: {type(exc).__name__}: {exc}")
            except Exception as exc:  # any library's network or HTTP error: try the next mirror
                failures.append(f"{url}: {type(exc).__name__}: {exc}")
        remove_empty_dirs(dest.parent, root)
        cls = ChecksumError if checksum_failed else DownloadError
        raise cls(f"could not fetch {t.label}: " + " | ".join(failures))


def refuse_web_page(path: Path, url: str) -> None:
    """A server that answers 200 with an HTML page (a login wall, a quota notice, an error page) sent no
    weights and no archive: the download is refused and never pinned."""
    with open(path, "rb") as f:
        head = f.read(512).lstrip().lower()
    if head.startswith((b"<!doctype html", b"<html", b"<head", b"<?xml")):
        raise DownloadError(f"{url}: the server sent a web page, not the file (not pinned; check the URL or mirror)")


def _stale(root: Path, dest: Path, expected: str | None) -> bool:
    try:
        verify_cached(root, dest, expected)
    except ChecksumError:
        return True
    return False


def _download_verified(root: Path, url: str, t: Target, progress: bool) -> str:
    """Download ``url`` into a temporary file, check it, move it to ``t.dest``; return its sha256."""
    staging = t.dest.parent / ".partial"
    staging.mkdir(parents=True, exist_ok=True)
    try:
        tmp = download_to(url, staging, t.dest.name, progress)
    except BaseException as exc:
        if is_disk_full(exc):  # a .part that filled the disk is no use: remove it, say how much is needed
            (staging / f"{t.dest.name}.part").unlink(missing_ok=True)
            remove_empty_dirs(staging, root)
            raise disk_full_error(t.dest, t.size_bytes) from None
        remove_empty_dirs(staging, root)  # a non-empty .part stays, to be resumed
        raise
    try:
        size = tmp.stat().st_size
        if t.size_bytes is not None and size != t.size_bytes:
            raise ChecksumError(f"{t.dest.name}: got {size} bytes, expected {t.size_bytes} (truncated download?)")
        refuse_web_page(tmp, url)
        digest = sha256_file(tmp)
        key = cache_key(root, t.dest)
        pinned = read_pins(root).get(key, {}).get("sha256")
        want = t.sha256 or pinned
        if want and digest != want:
            source = "expected" if t.sha256 else f"pinned (in {pins_path(root)})"
            raise ChecksumError(
                f"{t.dest.name}: sha256 of the download {digest} does not match the {source} {want}; "
                "the file on the server changed or the download is corrupt"
            )
        os.replace(tmp, t.dest)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    finally:
        remove_empty_dirs(staging, root)
    trust = "given" if t.sha256 else ("first-use" if not pinned else "pinned")
    update_pins(root, key, pin_record(t.dest, digest, url, trust, written=True))
    if not want:
        announce_pin(t.dest, digest, root)
    return digest
