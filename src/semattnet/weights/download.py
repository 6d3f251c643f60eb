"""Fetching weight files into a local cache: verified, atomic, resumable and offline-aware.

Which library moves the bytes:

* ``http(s)://``: :func:`huggingface_hub.file_download.http_get`. It resumes: an unfinished
  download is kept as ``<cache>/<dir>/.partial/<file>.part`` and continued with an HTTP ``Range``
  request (by the next call, or within the same call when the connection drops: ``http_get``
  retries with ``Range`` on its own); a server that ignores ``Range`` (``200`` instead of ``206``)
  makes it start over cleanly, and a body shorter than the announced size is an error. It writes
  in chunks of 10 MiB, so a dropped connection loses at most the chunk in flight. Pooch was
  checked first: its ``HTTPDownloader`` (1.9) always rewrites the file from byte 0 and does not look
  at ``206`` vs ``200``, so it cannot resume. Without ``huggingface_hub`` installed, pooch's
  ``HTTPDownloader`` is used instead (whole-file downloads, no resume).
* ``gdrive://<id>`` (and ``https://drive.google.com/file/d/<id>/...`` links): :func:`gdown.download`
  with ``resume=True`` (gdown keeps and continues its own ``.part`` file).
* ``hf://owner/repo[@revision][/file]``: :func:`huggingface_hub.hf_hub_download` /
  :func:`huggingface_hub.snapshot_download`, in Hugging Face's own cache (``HF_HUB_CACHE``), or in
  ``<cache>/huggingface`` when ``cache_dir`` or ``$SEMATTNET_CACHE`` is set.
* ``file://``: a local copy (``shutil``), checked like a download.

Every download lands in a temporary file, is checked (size if known, sha256), and only then is
moved into place with :func:`os.replace`; a file that fails a check is deleted. Checksums come from
the caller, the registry record, or a pin: when nobody published one, the sha256 of the first
download is written to ``<cache>/pins.json``, printed, and every later download or cache hit of
that file must match it (trust on first use). A cached file is re-hashed whenever its size or
modification time differs from the values recorded when it was last verified.

``SEMATTNET_OFFLINE=1`` or ``HF_HUB_OFFLINE=1``: nothing touches the network; a cache hit works,
a miss raises :class:`OfflineError` naming the file and where to put it. (Both are read at each
call; huggingface_hub itself reads ``HF_HUB_OFFLINE`` once, when it is imported.)

Cache layout (``$SEMATTNET_CACHE``, default ``platformdirs.user_cache_dir("semattnet")``)::

    pins.json                              sha256, size, mtime and origin of every verified file
    <weights name>/<file name>             registry records
    urls/<sha256(url)[:16]>/<file name>    any other URL
    converted/<source sha256>.safetensors  pickles converted once (see semattnet.weights.api)
    huggingface/                           hf:// downloads when the cache is set explicitly
    .locks/                                inter-process locks
"""

from __future__ import annotations

import contextlib
import datetime
import hashlib
import inspect
import json
import os
import re
import shutil
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import unquote, urlparse
from urllib.request import url2pathname

from semattnet._utils.atomic import atomic_path
from semattnet.weights.pretrained import PretrainedWeights, get_weights

__all__ = [
    "ENV_CACHE",
    "ENV_OFFLINE",
    "ChecksumError",
    "DownloadError",
    "OfflineError",
    "fetch",
    "get_cache_dir",
    "is_offline",
    "parse_hf_url",
    "read_pins",
    "sha256_file",
]

ENV_CACHE = "SEMATTNET_CACHE"
ENV_OFFLINE = "SEMATTNET_OFFLINE"
PINS_FILE = "pins.json"
_TRUE = ("1", "true", "yes", "on")
_GDRIVE_LINK = re.compile(r"^https?://drive\.google\.com/(?:file/d/|open\?id=|uc\?(?:.*&)?id=)([\w-]+)")


class DownloadError(OSError):
    """A file could not be fetched (every URL failed)."""


class ChecksumError(DownloadError):
    """A file's sha256 or size differs from the published, given or pinned value."""


class OfflineError(DownloadError):
    """Offline mode is on and the file is not in the cache."""


def is_offline() -> bool:
    """True when ``SEMATTNET_OFFLINE`` or ``HF_HUB_OFFLINE`` is set to 1/true/yes/on."""
    return any(os.environ.get(v, "").strip().lower() in _TRUE for v in (ENV_OFFLINE, "HF_HUB_OFFLINE"))


def get_cache_dir(cache_dir: str | os.PathLike[str] | None = None) -> Path:
    """``cache_dir`` if given, else ``$SEMATTNET_CACHE``, else the platform's user cache folder."""
    if cache_dir is not None:
        return Path(cache_dir).expanduser()
    if os.environ.get(ENV_CACHE):
        return Path(os.environ[ENV_CACHE]).expanduser()
    import platformdirs

    return Path(platformdirs.user_cache_dir("semattnet"))


def _hf_cache_dir(cache_dir: str | os.PathLike[str] | None) -> Path | None:
    """Where hf:// files go: ours when the cache is set explicitly, else Hugging Face's own cache."""
    if cache_dir is None and not os.environ.get(ENV_CACHE):
        return None
    return get_cache_dir(cache_dir) / "huggingface"


def sha256_file(path: str | os.PathLike[str], chunk: int = 1 << 20) -> str:
    """Hex sha256 of a file, read in 1 MiB chunks."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


# ----------------------------------------------------------------------------- pins


def _pins_path(root: Path) -> Path:
    return root / PINS_FILE


def read_pins(cache_dir: str | os.PathLike[str] | None = None) -> dict[str, dict[str, Any]]:
    """The pin records, keyed by the file's path relative to the cache."""
    path = _pins_path(get_cache_dir(cache_dir))
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        return {}
    except (OSError, ValueError) as exc:
        raise DownloadError(f"{path}: unreadable pin file ({exc}); fix or delete it") from exc
    return data if isinstance(data, dict) else {}


@contextlib.contextmanager
def _lock(root: Path, name: str) -> Iterator[None]:
    """An inter-process lock (``filelock``, a dependency of torch) in ``<cache>/.locks``."""
    from filelock import FileLock

    folder = root / ".locks"
    folder.mkdir(parents=True, exist_ok=True)
    safe = re.sub(r"[^\w.-]", "_", name)
    with FileLock(str(folder / f"{safe}.lock")):
        yield


def _update_pins(root: Path, key: str, record: dict[str, Any] | None) -> None:
    """Set (or, with None, remove) one pin record, atomically and under a lock."""
    with _lock(root, PINS_FILE):
        pins = read_pins(root)
        if record is None:
            if pins.pop(key, None) is None:
                return
        else:
            pins[key] = record
        with atomic_path(_pins_path(root)) as tmp:
            tmp.write_text(json.dumps(pins, indent=2, sort_keys=True) + "\n")


def _record(path: Path, sha: str, origin: str, trust: str) -> dict[str, Any]:
    st = path.stat()
    return {
        "sha256": sha,
        "size": st.st_size,
        "mtime_ns": st.st_mtime_ns,
        "origin": origin,
        "trust": trust,
        "verified": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
    }


def _key(root: Path, path: Path) -> str:
    return path.relative_to(root).as_posix()


def verify_cached(root: Path, path: Path, expected: str | None, origin: str = "", *, announce: bool = True) -> str:
    """Check a cached file against ``expected`` or its pin and return its sha256.

    The hash is recomputed unless size and modification time equal the recorded ones. A file
    without any record (e.g. placed by hand for offline use) is pinned now.

    Raises:
        ChecksumError: the file does not match.
    """
    key = _key(root, path)
    rec = read_pins(root).get(key)
    st = path.stat()
    if rec and rec.get("size") == st.st_size and rec.get("mtime_ns") == st.st_mtime_ns:
        if expected is None or rec.get("sha256") == expected:
            return str(rec["sha256"])
    digest = sha256_file(path)
    want = expected or (rec or {}).get("sha256")
    if want and digest != want:
        source = "expected" if expected else "pinned"
        raise ChecksumError(f"{path}: sha256 {digest} does not match the {source} {want}; delete it to download again")
    trust = "given" if expected else (rec or {}).get("trust", "first-use")
    _update_pins(root, key, _record(path, digest, (rec or {}).get("origin", origin), trust))
    if not want and announce:
        _announce_pin(path, digest, root)
    return digest


def _announce_pin(path: Path, digest: str, root: Path) -> None:
    print(
        f"semattnet: no published sha256 for {path.name}; pinned {digest} ({path.stat().st_size} bytes) "
        f"in {_pins_path(root)} (trust on first use): later downloads must match it. Please report this hash.",
        file=sys.stderr,
    )


# ----------------------------------------------------------------------------- targets


@dataclass(frozen=True)
class _Target:
    urls: tuple[str, ...]
    dest: Path
    sha256: str | None
    size_bytes: int | None
    label: str


def _gdrive_id(url: str) -> str | None:
    if url.startswith("gdrive://"):
        return url[len("gdrive://") :].strip("/") or None
    m = _GDRIVE_LINK.match(url)
    return m.group(1) if m else None


def _scheme(url: str) -> str:
    if _gdrive_id(url):
        return "gdrive"
    return urlparse(url).scheme.lower()


def _default_file_name(url: str) -> str:
    gid = _gdrive_id(url)
    if gid:
        return f"gdrive-{gid}"
    name = Path(unquote(urlparse(url).path)).name
    return name or "download"


def _check_file_name(name: str) -> str:
    if not name or name in (".", "..") or "/" in name or "\\" in name:
        raise ValueError(f"invalid file name {name!r}: a plain name without folders is needed")
    return name


def _target(url_or_entry: str | PretrainedWeights, sha256: str | None, root: Path, file_name: str | None) -> _Target:
    if isinstance(url_or_entry, str) and "://" not in url_or_entry:
        url_or_entry = get_weights(url_or_entry)  # a registry name (else: a one-line error listing names)
    if isinstance(url_or_entry, PretrainedWeights):
        e = url_or_entry
        name = _check_file_name(file_name or e.file_name)
        return _Target(e.urls, root / e.name / name, sha256 or e.sha256, e.size_bytes, e.name)
    url = url_or_entry
    name = _check_file_name(file_name or _default_file_name(url))
    slot = hashlib.sha256(url.encode()).hexdigest()[:16]
    return _Target((url,), root / "urls" / slot / name, sha256, None, url)


# ----------------------------------------------------------------------------- fetch


def fetch(
    url_or_entry: str | PretrainedWeights,
    *,
    sha256: str | None = None,
    cache_dir: str | os.PathLike[str] | None = None,
    file_name: str | None = None,
    progress: bool = True,
) -> Path:
    """Download a file into the cache (once) and return its local path.

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
        ChecksumError: the file does not match its checksum or size; nothing is left in the cache.
        OfflineError: offline mode and the file is not cached.
        DownloadError: every URL failed (the message lists each failure).
    """
    if sha256 is not None and not re.fullmatch(r"[0-9a-f]{64}", sha256.lower()):
        raise ValueError(f"sha256 must be 64 hex digits, got {sha256!r}")
    sha256 = sha256.lower() if sha256 else None
    if isinstance(url_or_entry, str) and _scheme(url_or_entry) == "hf":
        return fetch_hf(url_or_entry, sha256=sha256, cache_dir=cache_dir)
    root = get_cache_dir(cache_dir).resolve()
    target = _target(url_or_entry, sha256, root, file_name)
    return _fetch_target(root, target, progress)[0]


def _fetch_target(root: Path, t: _Target, progress: bool) -> tuple[Path, str]:
    """The cached file and its sha256, downloading it if needed."""
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
    with _lock(root, _key(root, dest)):
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
            except Exception as exc:  # any library's network or HTTP error: try the next mirror
                failures.append(f"{url}: {type(exc).__name__}: {exc}")
        _remove_empty_dirs(dest.parent, root)
        cls = ChecksumError if checksum_failed else DownloadError
        raise cls(f"could not fetch {t.label}: " + " | ".join(failures))


def _stale(root: Path, dest: Path, expected: str | None) -> bool:
    try:
        verify_cached(root, dest, expected)
    except ChecksumError:
        return True
    return False


def _download_verified(root: Path, url: str, t: _Target, progress: bool) -> str:
    """Download ``url`` into a temporary file, check it, move it to ``t.dest``; return its sha256."""
    staging = t.dest.parent / ".partial"
    staging.mkdir(parents=True, exist_ok=True)
    try:
        tmp = _download(url, staging, t.dest.name, progress)
    except BaseException:
        _remove_empty_dirs(staging, root)  # a non-empty .part stays, to be resumed
        raise
    try:
        size = tmp.stat().st_size
        if t.size_bytes is not None and size != t.size_bytes:
            raise ChecksumError(f"{t.dest.name}: got {size} bytes, expected {t.size_bytes} (truncated download?)")
        digest = sha256_file(tmp)
        key = _key(root, t.dest)
        pinned = read_pins(root).get(key, {}).get("sha256")
        want = t.sha256 or pinned
        if want and digest != want:
            source = "expected" if t.sha256 else f"pinned (in {_pins_path(root)})"
            raise ChecksumError(
                f"{t.dest.name}: sha256 of the download {digest} does not match the {source} {want}; "
                "the file on the server changed or the download is corrupt"
            )
        os.replace(tmp, t.dest)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    finally:
        _remove_empty_dirs(staging, root)
    trust = "given" if t.sha256 else ("first-use" if not pinned else "pinned")
    _update_pins(root, key, _record(t.dest, digest, url, trust))
    if not want:
        _announce_pin(t.dest, digest, root)
    return digest


def _remove_empty_dirs(folder: Path, root: Path) -> None:
    folder = folder.resolve()
    while folder != root and root in folder.parents:
        try:
            folder.rmdir()
        except OSError:
            return
        folder = folder.parent


def _download(url: str, staging: Path, name: str, progress: bool) -> Path:
    """Bring ``url`` into ``staging``; return the (unverified) file."""
    scheme = _scheme(url)
    if scheme == "gdrive":
        return _download_gdrive(_gdrive_id(url) or "", staging / name, progress)
    if scheme in ("http", "https"):
        part = staging / f"{name}.part"
        _download_http(url, part, progress)
        return part
    if scheme == "file":
        src = Path(url2pathname(unquote(urlparse(url).path)))
        part = staging / f"{name}.part"
        shutil.copyfile(src, part)
        return part
    raise ValueError(f"unsupported URL {url!r}: use http(s)://, file://, gdrive://<id> or hf://owner/repo")


def _download_http(url: str, part: Path, progress: bool) -> None:
    try:
        from huggingface_hub.file_download import http_get
    except ImportError:
        http_get = None
    if http_get is None:
        _download_http_pooch(url, part, progress)
        return
    # No expected_size: http_get checks the body against Content-Length itself; the published size
    # is checked afterwards, so that a wrong file is deleted instead of being kept for resuming.
    kwargs: dict[str, Any] = {"displayed_filename": part.name.removesuffix(".part")}
    if not progress and "tqdm_class" in inspect.signature(http_get).parameters:
        kwargs["tqdm_class"] = _silent_tqdm()
    resume = part.stat().st_size if part.exists() else 0
    try:
        try:
            with open(part, "ab") as f:
                http_get(url, f, resume_size=resume, **kwargs)
        except Exception:
            if not resume:
                raise  # keep what arrived: the next call continues from there
            # The stored part could not be continued (e.g. 416: it was complete but unchecked, or the
            # file changed on the server): start over once from byte 0.
            part.unlink(missing_ok=True)
            with open(part, "ab") as f:
                http_get(url, f, resume_size=0, **kwargs)
    except BaseException:
        if part.exists() and part.stat().st_size == 0:
            part.unlink()
        raise


def _download_http_pooch(url: str, part: Path, progress: bool) -> None:
    try:
        import pooch
    except ImportError as exc:
        raise ImportError(
            "downloading over HTTP needs huggingface_hub (resumable) or pooch: pip install 'semattnet[hub]'"
        ) from exc
    pooch.HTTPDownloader(progressbar=progress)(url, str(part), None)


def _silent_tqdm() -> type:
    from tqdm.auto import tqdm

    class _Silent(tqdm):  # type: ignore[misc,valid-type]
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            kwargs["disable"] = True
            super().__init__(*args, **kwargs)

    return _Silent


def _download_gdrive(file_id: str, output: Path, progress: bool) -> Path:
    try:
        import gdown
    except ImportError as exc:
        raise ImportError("downloading from Google Drive needs gdown: pip install 'semattnet[hub]'") from exc
    if not re.fullmatch(r"[\w-]+", file_id):
        raise ValueError(f"invalid Google Drive file id {file_id!r}")
    result = gdown.download(id=file_id, output=str(output), quiet=not progress, resume=True)
    if not result or not output.is_file():
        raise DownloadError(f"gdown could not download Google Drive file {file_id} (quota exceeded or not shared?)")
    return output


# ----------------------------------------------------------------------------- Hugging Face


def parse_hf_url(url: str) -> tuple[str, str | None, str | None]:
    """``hf://owner/repo[@revision][/path/in/repo]`` -> (repo_id, revision, filename)."""
    if not url.startswith("hf://"):
        raise ValueError(f"not an hf:// URL: {url!r}")
    parts = [p for p in url[len("hf://") :].split("/") if p]
    if len(parts) < 2:
        raise ValueError(f"expected hf://owner/repo[@revision][/file], got {url!r}")
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

    ``sha256`` checks the named file, or ``model.safetensors`` of a folder.
    """
    try:
        import huggingface_hub
    except ImportError as exc:
        raise ImportError("hf:// URLs need huggingface_hub: pip install 'semattnet[hub]'") from exc
    repo_id, revision, filename = parse_hf_url(url)
    offline = is_offline()
    kwargs: dict[str, Any] = {"repo_id": repo_id, "revision": revision, "local_files_only": offline}
    hf_cache = _hf_cache_dir(cache_dir)
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
