"""The libraries that move the bytes, one function per URL scheme; each writes into a staging folder.

* ``http(s)://``: :func:`huggingface_hub.file_download.http_get`. It resumes: an unfinished
  download is kept as ``<staging>/<file>.part`` and continued with an HTTP ``Range`` request (by
  the next call, or within the same call when the connection drops: ``http_get`` retries with
  ``Range`` on its own); a server that ignores ``Range`` (``200`` instead of ``206``) makes it
  start over cleanly, and a body shorter than the announced size is an error. It writes in chunks
  of 10 MiB, so a dropped connection loses at most the chunk in flight. Pooch was checked first:
  its ``HTTPDownloader`` (1.9) always rewrites the file from byte 0 and does not look at ``206`` vs
  ``200``, so it cannot resume. Without ``huggingface_hub`` installed, pooch's ``HTTPDownloader``
  is used instead (whole-file downloads, no resume).
* ``gdrive://<id>`` (and ``https://drive.google.com/file/d/<id>/...`` links): :func:`gdown.download`
  with ``resume=True`` (gdown keeps and continues its own ``.part`` file).
* ``file://``: a local copy (``shutil``), checked like a download.

``hf://`` URLs are not a transport into the staging folder: see :mod:`semattnet.cache.hf`.
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path
from urllib.parse import unquote, urlparse
from urllib.request import url2pathname

from semattnet._errors import InputError
from semattnet._utils.bounds import regular_file
from semattnet._utils.extras import call_with_newer, optional, require
from semattnet.cache.errors import DownloadError, NotAFileError

__all__ = ["check_file_name", "default_file_name", "download_to", "gdrive_id", "url_scheme"]

_GDRIVE_LINK = re.compile(r"^https?://drive\.google\.com/(?:file/d/|open\?id=|uc\?(?:.*&)?id=)([\w-]+)")


def gdrive_id(url: str) -> str | None:
    """The Google Drive file id of a ``gdrive://<id>`` URL or a drive.google.com link, else None."""
    if url.startswith("gdrive://"):
        return url[len("gdrive://") :].strip("/") or None
    m = _GDRIVE_LINK.match(url)
    return m.group(1) if m else None


def url_scheme(url: str) -> str:
    """``gdrive`` for Google Drive URLs and links, else the URL's scheme in lower case."""
    if gdrive_id(url):
        return "gdrive"
    return urlparse(url).scheme.lower()


def default_file_name(url: str) -> str:
    """The cached file's name for ``url``: its last path part (``gdrive-<id>`` for Google Drive)."""
    gid = gdrive_id(url)
    if gid:
        return f"gdrive-{gid}"
    name = Path(unquote(urlparse(url).path)).name
    return name or "download"


def check_file_name(name: str) -> str:
    """``name`` if it is a plain file name (no folders, not ``.``/``..``)."""
    if not name or name in (".", "..") or "/" in name or "\\" in name:
        raise InputError(f"invalid file name {name!r}: a plain name without folders is needed")
    return name


def download_to(url: str, staging: Path, name: str, progress: bool) -> Path:
    """Bring ``url`` into ``staging`` (as ``name`` or ``name.part``); return the (unverified) file."""
    scheme = url_scheme(url)
    if scheme == "gdrive":
        return _download_gdrive(gdrive_id(url) or "", staging / name, progress)
    if scheme in ("http", "https"):
        part = staging / f"{name}.part"
        _download_http(url, part, progress)
        return part
    if scheme == "file":
        src = regular_file(url2pathname(unquote(urlparse(url).path)), f"file (from {url})", NotAFileError)
        part = staging / f"{name}.part"
        shutil.copyfile(src, part)
        return part
    raise InputError(f"unsupported URL {url!r}: use http(s)://, file://, gdrive://<id> or hf://owner/repo")


def _download_http(url: str, part: Path, progress: bool) -> None:
    hf_download = optional("huggingface_hub.file_download")
    if hf_download is None:  # no resume without huggingface_hub: pooch
        _download_http_pooch(url, part, progress)
        return
    http_get = hf_download.http_get
    # No expected_size: http_get checks the body against Content-Length itself; the published size
    # is checked afterwards, so that a wrong file is deleted instead of being kept for resuming.
    shown = part.name.removesuffix(".part")
    newer = {} if progress else {"tqdm_class": _silent_tqdm()}  # older huggingface_hub releases lack it
    resume = part.stat().st_size if part.exists() else 0
    try:
        try:
            with open(part, "ab") as f:
                call_with_newer(http_get, newer, url, f, resume_size=resume, displayed_filename=shown)
        except Exception:
            if not resume:
                raise  # keep what arrived: the next call continues from there
            # The stored part could not be continued (e.g. 416: it was complete but unchecked, or the
            # file changed on the server): start over once from byte 0.
            part.unlink(missing_ok=True)
            with open(part, "ab") as f:
                call_with_newer(http_get, newer, url, f, resume_size=0, displayed_filename=shown)
    except BaseException:
        if part.exists() and part.stat().st_size == 0:
            part.unlink()
        raise


def _download_http_pooch(url: str, part: Path, progress: bool) -> None:
    pooch = require("pooch", "downloading over HTTP (huggingface_hub, resumable, or pooch)")
    pooch.HTTPDownloader(progressbar=progress)(url, str(part), None)


def _silent_tqdm() -> type:
    from tqdm.auto import tqdm

    class _Silent(tqdm):
        def __init__(self, *args: object, **kwargs: object) -> None:
            kwargs["disable"] = True
            super().__init__(*args, **kwargs)

    return _Silent


def _download_gdrive(file_id: str, output: Path, progress: bool) -> Path:
    gdown = require("gdown", "downloading from Google Drive")
    if not re.fullmatch(r"[\w-]+", file_id):
        raise InputError(f"invalid Google Drive file id {file_id!r}")
    result = gdown.download(id=file_id, output=str(output), quiet=not progress, resume=True)
    if not result or not output.is_file():
        raise DownloadError(f"gdown could not download Google Drive file {file_id} (quota exceeded or not shared?)")
    return output
