"""Fetching released weights: registry records and names on top of the verified download cache.

The cache itself (temporary file, size / sha256 check, atomic move, locks, the pin file with
trust on first use, the http / gdrive / file / hf transports, the offline switch) is
:mod:`semattnet._utils.download`; its public names are re-exported here. What is specific to
weights: a :class:`~semattnet.weights.PretrainedWeights` record (or its registry name) becomes a
cache target ``<cache>/<weights name>/<file name>`` with the record's mirrors, sha256 and size.
"""

from __future__ import annotations

import os
from pathlib import Path

from semattnet._utils.download import (
    ENV_CACHE,
    ENV_OFFLINE,
    PINS_FILE,
    ChecksumError,
    DownloadError,
    OfflineError,
    Target,
    check_sha256,
    fetch_hf,
    fetch_target,
    get_cache_dir,
    is_offline,
    parse_hf_url,
    read_pins,
    sha256_file,
    url_scheme,
    url_target,
    verify_cached,
)
from semattnet._utils.download import fetch as fetch_url
from semattnet._utils.download.transports import check_file_name
from semattnet.weights.pretrained import PretrainedWeights, get_weights

__all__ = [
    "ENV_CACHE",
    "ENV_OFFLINE",
    "PINS_FILE",
    "ChecksumError",
    "DownloadError",
    "OfflineError",
    "fetch",
    "fetch_hf",
    "get_cache_dir",
    "is_offline",
    "is_url",
    "parse_hf_url",
    "read_pins",
    "sha256_file",
    "verify_cached",
    "weights_target",
]


def weights_target(
    url_or_entry: str | PretrainedWeights, sha256: str | None, root: Path, file_name: str | None = None
) -> Target:
    """The cache target of a record, a registry name (no ``://``) or a plain URL."""
    if isinstance(url_or_entry, str) and "://" not in url_or_entry:
        url_or_entry = get_weights(url_or_entry)  # a registry name (else: a one-line error listing names)
    if isinstance(url_or_entry, PretrainedWeights):
        e = url_or_entry
        name = check_file_name(file_name or e.file_name)
        return Target(e.urls, root / e.name / name, sha256 or e.sha256, e.size_bytes, e.name)
    return url_target(url_or_entry, sha256, root, file_name)


def fetch(
    url_or_entry: str | PretrainedWeights,
    *,
    sha256: str | None = None,
    cache_dir: str | os.PathLike[str] | None = None,
    file_name: str | None = None,
    progress: bool = True,
) -> Path:
    """Download a weights file into the cache (once) and return its local path.

    Args:
        url_or_entry: a :class:`PretrainedWeights` record, a registry name, or a URL:
            ``http(s)://``, ``file://``, ``gdrive://<id>`` or ``hf://owner/repo[@rev][/file]``
            (without a file, the repository folder is returned).
        sha256: expected hex digest (overrides the record's; None: the record's, else pinned on
            first download).
        cache_dir: cache root (default ``$SEMATTNET_CACHE`` or the platform's user cache folder).
        file_name: name of the cached file (default: the record's, or the URL's last path part).
        progress: show a progress bar.

    Raises:
        UnknownWeightsError: a name that is not in the registry.
        ChecksumError: the file does not match its checksum or size; nothing is left in the cache.
        OfflineError: offline mode and the file is not cached.
        DownloadError: every URL failed (the message lists each failure).
    """
    sha256 = check_sha256(sha256)
    if isinstance(url_or_entry, str) and "://" in url_or_entry:
        return fetch_url(url_or_entry, sha256=sha256, cache_dir=cache_dir, file_name=file_name, progress=progress)
    root = get_cache_dir(cache_dir).resolve()
    return fetch_target(root, weights_target(url_or_entry, sha256, root, file_name), progress)[0]


def is_url(text: str) -> bool:
    """True for the URL forms weights can come from (``http(s)``, ``file``, ``gdrive``, ``hf``)."""
    return "://" in text and url_scheme(text) in ("http", "https", "file", "gdrive", "hf")
