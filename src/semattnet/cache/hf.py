"""``hf://owner/repo[@revision][/file]``: files and folders through huggingface_hub, in its own cache."""

from __future__ import annotations

import os
from pathlib import Path

from semattnet._errors import InputError
from semattnet._utils.extras import require
from semattnet.cache.errors import ChecksumError, DownloadError, OfflineError
from semattnet.cache.store import hf_cache_dir, is_offline, sha256_file

__all__ = ["fetch_hf", "parse_hf_url"]


def parse_hf_url(url: str) -> tuple[str, str | None, str | None]:
    """``hf://owner/repo[@revision][/path/in/repo]`` -> (repo_id, revision, filename)."""
    if not url.startswith("hf://"):
        raise InputError(f"not an hf:// URL: {url!r}")
    parts = [p for p in url[len("hf://") :].split("/") if p]
    if len(parts) < 2:
        raise InputError(f"expected hf://owner/repo[@revision][/file], got {url!r}")
    owner, repo = parts[0], parts[1]
    revision = None
    if "@" in repo:
        repo, revision = repo.split("@", 1)
    filename = "/".join(parts[2:]) or None
    return f"{owner}/{repo}", revision or None, filename


def fetch_hf(
    url: str,
    *,
    sha256: str | None = None,
    cache_dir: str | os.PathLike[str] | None = None,
    allow_patterns: list[str] | None = None,
) -> Path:
    """Fetch ``hf://owner/repo[@rev][/file]`` with huggingface_hub; a folder when no file is named.

    Files go to Hugging Face's cache (``HF_HUB_CACHE``), or to ``<cache>/huggingface`` when
    ``cache_dir`` or ``$SEMATTNET_CACHE`` is set. ``sha256`` checks the named file, or
    ``model.safetensors`` of a folder.
    """
    huggingface_hub = require("huggingface_hub", "hf:// URLs")
    repo_id, revision, filename = parse_hf_url(url)
    offline = is_offline()
    kwargs: dict[str, str | bool | None] = {"repo_id": repo_id, "revision": revision, "local_files_only": offline}
    hf_cache = hf_cache_dir(cache_dir)
    if hf_cache is not None:
        kwargs["cache_dir"] = str(hf_cache)
    try:
        if filename:
            path = Path(huggingface_hub.hf_hub_download(filename=filename, **kwargs))
        else:
            path = Path(huggingface_hub.snapshot_download(allow_patterns=allow_patterns, **kwargs))
    except Exception as exc:
        if offline:
            where = hf_cache or "the Hugging Face cache (HF_HUB_CACHE)"
            raise OfflineError(
                f"offline mode and {filename or repo_id} of {url} is not cached in {where}: "
                f"run once online or copy the repository there ({type(exc).__name__})"
            ) from exc
        raise DownloadError(f"could not fetch {url}: {type(exc).__name__}: {exc}") from exc
    if sha256:
        checked = path if path.is_file() else path / "model.safetensors"
        digest = sha256_file(checked)
        if digest != sha256:
            raise ChecksumError(f"{url}: sha256 of {checked.name} is {digest}, expected {sha256}")
    return path
