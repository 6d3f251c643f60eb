"""Pins are checked on every cache hit, and a web page is never pinned as weights (issue 27)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from semattnet.cache.errors import ChecksumError, DownloadError
from semattnet.cache.store import read_pins, verify_cached
from semattnet.weights import fetch_weights


def _same_size_and_time(path: Path, data: bytes) -> None:
    """Change a file's bytes while keeping its size and modification time (what a size+mtime shortcut misses)."""
    st = path.stat()
    assert len(data) == st.st_size
    path.write_bytes(data)
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns))


def test_a_file_placed_by_hand_is_hashed_again_on_every_hit(tmp_path: Path) -> None:
    root = tmp_path / "cache"
    placed = root / "weights" / "model.safetensors"
    placed.parent.mkdir(parents=True)
    placed.write_bytes(b"A" * 64)
    first = verify_cached(root, placed, None, "by hand", announce=False)  # pinned on first use, not written by us
    assert read_pins(root)[next(iter(read_pins(root)))]["written"] is False
    assert verify_cached(root, placed, None) == first  # unchanged: fine
    _same_size_and_time(placed, b"B" * 64)
    with pytest.raises(ChecksumError, match="does not match the pinned"):
        verify_cached(root, placed, None)


def test_a_download_records_that_we_wrote_it(tmp_path: Path) -> None:
    src = tmp_path / "model.bin"
    src.write_bytes(b"\x00weights" * 100)
    path = fetch_weights(src.as_uri(), cache_dir=tmp_path / "cache", progress=False)
    (record,) = read_pins(tmp_path / "cache").values()
    assert record["written"] is True and path.read_bytes() == src.read_bytes()


@pytest.mark.parametrize(
    "page",
    [
        b"<!DOCTYPE html><html><body>Quota exceeded</body></html>",
        b"\n  <html><head><title>Sign in</title></head></html>",
    ],
)
def test_a_web_page_is_never_pinned_and_the_fixed_server_is_then_trusted(tmp_path: Path, page: bytes) -> None:
    served = tmp_path / "model.bin"
    served.write_bytes(page)
    cache = tmp_path / "cache"
    with pytest.raises(DownloadError, match="web page"):
        fetch_weights(served.as_uri(), cache_dir=cache, progress=False)
    pins = cache / "pins.json"
    assert not pins.exists() or json.loads(pins.read_text()) == {}
    assert not [p for p in cache.rglob("*") if p.is_file() and p.name != "pins.json" and ".lock" not in p.name]
    served.write_bytes(b"\x00real weights" * 50)  # the mirror is fixed
    path = fetch_weights(served.as_uri(), cache_dir=cache, progress=False)
    assert path.read_bytes() == served.read_bytes()
