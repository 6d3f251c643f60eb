"""The cache folder, the offline switch, sha256, inter-process locks and the pin file.

Pins: ``<cache>/pins.json`` records, per file (keyed by its path relative to the cache), the
sha256, size, modification time and origin of the last verification. A file that nobody
published a checksum for is pinned on first download (trust on first use); every later download
or cache hit must match the pin. A cached file is re-hashed whenever its size or modification
time differs from the recorded values.
"""

from __future__ import annotations

import contextlib
import datetime
import hashlib
import json
import os
import re
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import TypedDict

from semattnet._utils.atomic import atomic_path
from semattnet.cache.errors import ChecksumError, DownloadError

__all__ = [
    "ENV_CACHE",
    "ENV_OFFLINE",
    "PINS_FILE",
    "PinRecord",
    "announce_pin",
    "cache_key",
    "cache_lock",
    "get_cache_dir",
    "hf_cache_dir",
    "is_offline",
    "pin_record",
    "pins_path",
    "read_pins",
    "remove_empty_dirs",
    "sha256_file",
    "sha256_tree",
    "update_pins",
    "verify_cached",
]

ENV_CACHE = "SEMATTNET_CACHE"
ENV_OFFLINE = "SEMATTNET_OFFLINE"
PINS_FILE = "pins.json"
_TRUE = ("1", "true", "yes", "on")


class PinRecord(TypedDict, total=False):
    """One file's entry in ``pins.json`` (see :func:`pin_record`)."""

    written: bool
    sha256: str
    size: int
    mtime_ns: int
    origin: str
    trust: str
    verified: str


def is_offline() -> bool:
    """True when ``SEMATTNET_OFFLINE`` or ``HF_HUB_OFFLINE`` is set to 1/true/yes/on (read at each call)."""
    return any(os.environ.get(v, "").strip().lower() in _TRUE for v in (ENV_OFFLINE, "HF_HUB_OFFLINE"))


def get_cache_dir(cache_dir: str | os.PathLike[str] | None = None) -> Path:
    """``cache_dir`` if given, else ``$SEMATTNET_CACHE``, else the platform's user cache folder."""
    if cache_dir is not None:
        return Path(cache_dir).expanduser()
    if os.environ.get(ENV_CACHE):
        return Path(os.environ[ENV_CACHE]).expanduser()
    import platformdirs

    return Path(platformdirs.user_cache_dir("semattnet"))


def hf_cache_dir(cache_dir: str | os.PathLike[str] | None) -> Path | None:
    """Where hf:// files go: ours when the cache is set explicitly, else (None) Hugging Face's own cache."""
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


def sha256_tree(folder: str | os.PathLike[str]) -> str:
    """Hex sha256 of a folder: every regular file under it (symlinks followed), by relative path and content."""
    h, root = hashlib.sha256(), Path(folder)
    for p in sorted(q for q in root.rglob("*") if q.is_file()):
        h.update(f"{p.relative_to(root).as_posix()}\0{sha256_file(p)}\n".encode())
    return h.hexdigest()


def pins_path(root: Path) -> Path:
    """The pin file of the cache ``root``."""
    return root / PINS_FILE


def cache_key(root: Path, path: Path) -> str:
    """A cached file's key in the pin file: its path relative to the cache, with ``/``."""
    return path.relative_to(root).as_posix()


def read_pins(cache_dir: str | os.PathLike[str] | None = None) -> dict[str, PinRecord]:
    """The pin records, keyed by the file's path relative to the cache."""
    path = pins_path(get_cache_dir(cache_dir))
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        return {}
    except (OSError, ValueError) as exc:
        raise DownloadError(f"{path}: unreadable pin file ({exc}); fix or delete it") from exc
    return data if isinstance(data, dict) else {}


@contextlib.contextmanager
def cache_lock(root: Path, name: str) -> Iterator[None]:
    """An inter-process lock (``filelock``, a dependency of torch) in ``<cache>/.locks``."""
    from filelock import FileLock

    folder = root / ".locks"
    folder.mkdir(parents=True, exist_ok=True)
    safe = re.sub(r"[^\w.-]", "_", name)
    with FileLock(str(folder / f"{safe}.lock")):
        yield


def update_pins(root: Path, key: str, record: PinRecord | None) -> None:
    """Set (or, with None, remove) one pin record, atomically and under a lock."""
    with cache_lock(root, PINS_FILE):
        pins = read_pins(root)
        if record is None:
            if pins.pop(key, None) is None:
                return
        else:
            pins[key] = record
        with atomic_path(pins_path(root)) as tmp:
            tmp.write_text(json.dumps(pins, indent=2, sort_keys=True) + "\n")


def pin_record(path: Path, sha: str, origin: str, trust: str, written: bool = False) -> PinRecord:
    """The pin of ``path``: sha256, size, mtime, origin, trust (``given``, ``first-use``, ``pinned``, ...) and
    ``written`` (this library wrote the file and hashed it as it wrote it)."""
    st = path.stat()
    now = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    return PinRecord(
        written=written, sha256=sha, size=st.st_size, mtime_ns=st.st_mtime_ns, origin=origin, trust=trust, verified=now
    )


def verify_cached(root: Path, path: Path, expected: str | None, origin: str = "", *, announce: bool = True) -> str:
    """Check a cached file against ``expected`` or its pin and return its sha256.

    The hash is recomputed on every call, unless this library wrote the file itself and recorded its
    digest then (``written``) and its size and modification time are still the recorded ones: a
    file placed or changed by anyone else is hashed again. A file without any record (e.g. placed by
    hand for offline use) is pinned now.

    Raises:
        ChecksumError: the file does not match.
    """
    key = cache_key(root, path)
    rec = read_pins(root).get(key, PinRecord())
    st = path.stat()
    if rec.get("written") is True and rec.get("size") == st.st_size and rec.get("mtime_ns") == st.st_mtime_ns:
        if expected is None or rec.get("sha256") == expected:
            return rec["sha256"]
    digest = sha256_file(path)
    want = expected or rec.get("sha256")
    if want and digest != want:
        source = "expected" if expected else "pinned"
        raise ChecksumError(f"{path}: sha256 {digest} does not match the {source} {want}; delete it to download again")
    trust = "given" if expected else rec.get("trust", "first-use")
    update_pins(root, key, pin_record(path, digest, rec.get("origin", origin), trust))
    if not want and announce:
        announce_pin(path, digest, root)
    return digest


def announce_pin(path: Path, digest: str, root: Path) -> None:
    """Tell the user (stderr) that ``path`` was pinned on first use."""
    print(
        f"semattnet: no published sha256 for {path.name}; pinned {digest} ({path.stat().st_size} bytes) "
        f"in {pins_path(root)} (trust on first use): later downloads must match it. Please report this hash.",
        file=sys.stderr,
    )


def remove_empty_dirs(folder: Path, root: Path) -> None:
    """Remove ``folder`` and its parents up to (not including) ``root`` while they are empty."""
    folder = folder.resolve()
    while folder != root and root in folder.parents:
        try:
            folder.rmdir()
        except OSError:
            return
        folder = folder.parent
