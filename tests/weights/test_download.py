"""fetch_weights(): cache, offline mode, resume, checksums, trust on first use, mirrors, gdrive, file://."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest

from semattnet.weights import (
    ChecksumError,
    DownloadError,
    OfflineError,
    PretrainedWeights,
    fetch_weights,
    read_pins,
)

from .conftest import Server, cache_files

BLOB = bytes(range(256)) * 400  # 102,400 bytes
SHA = hashlib.sha256(BLOB).hexdigest()


def test_download_then_cache_hit_with_server_stopped(server: Server, cache: Path) -> None:
    url = server.add("/w/blob.bin", BLOB)
    path = fetch_weights(url, sha256=SHA, progress=False)
    assert path.read_bytes() == BLOB and cache in path.parents
    assert cache_files(cache) == [path.relative_to(cache).as_posix()]  # no temporary files left
    server.stop()
    assert fetch_weights(url, sha256=SHA, progress=False) == path
    assert len(server.gets("/w/blob.bin")) == 1


def test_offline_cache_hit_and_miss(server: Server, cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    url = server.add("/w/blob.bin", BLOB)
    path = fetch_weights(url, progress=False)
    monkeypatch.setenv("SEMATTNET_OFFLINE", "1")
    assert fetch_weights(url, progress=False) == path
    missing = server.add("/w/other-weights.pth", b"x")
    with pytest.raises(OfflineError) as err:
        fetch_weights(missing, progress=False)
    msg = str(err.value)
    assert "\n" not in msg and "other-weights.pth" in msg and str(cache) in msg and missing in msg
    monkeypatch.delenv("SEMATTNET_OFFLINE")
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    with pytest.raises(OfflineError, match="other-weights.pth"):
        fetch_weights(missing, progress=False)
    assert server.gets("/w/other-weights.pth") == []  # the network was never touched


def test_offline_file_placed_by_hand_is_used(cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SEMATTNET_OFFLINE", "1")
    url = "http://127.0.0.1:9/never/model.bin"
    with pytest.raises(OfflineError) as err:
        fetch_weights(url, progress=False)
    where = Path(str(err.value).rsplit("place it at ", 1)[1])
    where.parent.mkdir(parents=True)
    where.write_bytes(BLOB)
    assert fetch_weights(url, sha256=SHA, progress=False) == where


def test_resume_after_cut_connection(server: Server, cache: Path) -> None:
    # huggingface_hub writes what it received in chunks of 10 MiB, so cut well past the first chunk.
    big = hashlib.sha256(b"seed").digest() * (12 * 2**20 // 32)
    url = server.add("/w/big.bin", big)
    server.state.cut_after["/w/big.bin"] = 11 * 2**20
    path = fetch_weights(url, sha256=hashlib.sha256(big).hexdigest(), progress=False)
    assert path.read_bytes() == big
    first, second = server.gets("/w/big.bin")
    assert first is None and second is not None
    start = int(second.removeprefix("bytes=").rstrip("-"))
    assert 0 < start <= 11 * 2**20  # the second request continued where the first one broke off


def test_resume_from_part_file_of_an_earlier_run(server: Server, cache: Path) -> None:
    url = server.add("/w/big.bin", BLOB)
    first = fetch_weights(server.add("/w/probe.bin", b"p"), progress=False)  # learn where this URL's slot is
    slot = cache / "urls" / hashlib.sha256(url.encode()).hexdigest()[:16]
    assert first.parent.parent == slot.parent
    part = slot / ".partial" / "big.bin.part"
    part.parent.mkdir(parents=True)
    part.write_bytes(BLOB[:40_000])
    assert fetch_weights(url, sha256=SHA, progress=False).read_bytes() == BLOB
    assert server.gets("/w/big.bin") == ["bytes=40000-"]
    assert not part.exists()


def test_server_ignoring_range_restarts_cleanly(server: Server, cache: Path) -> None:
    url = server.add("/w/big.bin", BLOB)
    server.state.honour_range = False
    server.state.cut_after["/w/big.bin"] = 10_000
    assert fetch_weights(url, sha256=SHA, progress=False).read_bytes() == BLOB


def test_wrong_checksum_refused_nothing_cached(server: Server, cache: Path) -> None:
    url = server.add("/w/blob.bin", BLOB)
    with pytest.raises(ChecksumError, match="does not match the expected"):
        fetch_weights(url, sha256="0" * 64, progress=False)
    assert cache_files(cache) == []
    assert read_pins() == {}


def test_truncated_file_refused(server: Server, cache: Path) -> None:
    url = server.add("/w/blob.bin", BLOB[:-100])  # the server itself has a truncated copy
    with pytest.raises(ChecksumError):
        fetch_weights(url, sha256=SHA, progress=False)
    assert cache_files(cache) == []
    entry = PretrainedWeights(
        name="t", arch="semattnet", urls=(url,), file_name="t.bin", format="torch", license="x", size_bytes=len(BLOB)
    )
    with pytest.raises(ChecksumError, match="expected 102400"):
        fetch_weights(entry, progress=False)  # no sha256 known: the size alone refuses it
    assert cache_files(cache) == [] and read_pins() == {}


def test_trust_on_first_use(server: Server, cache: Path, capsys: pytest.CaptureFixture[str]) -> None:
    url = server.add("/w/blob.bin", BLOB)
    path = fetch_weights(url, progress=False)
    err = capsys.readouterr().err
    assert SHA in err and "pinned" in err
    pins = read_pins()
    (record,) = pins.values()
    assert record["sha256"] == SHA and record["origin"] == url and record["trust"] == "first-use"
    assert json.loads((cache / "pins.json").read_text()) == pins
    path.unlink()  # the cached copy goes; the pin stays
    server.state.files["/w/blob.bin"] = BLOB[::-1]  # the server now serves something else
    with pytest.raises(ChecksumError, match="pinned"):
        fetch_weights(url, progress=False)
    assert cache_files(cache) == []
    server.state.files["/w/blob.bin"] = BLOB
    assert fetch_weights(url, progress=False).read_bytes() == BLOB


def test_cached_file_damaged_is_downloaded_again(server: Server, cache: Path) -> None:
    url = server.add("/w/blob.bin", BLOB)
    path = fetch_weights(url, progress=False)
    path.write_bytes(BLOB[:-1] + b"\x00")
    assert fetch_weights(url, progress=False).read_bytes() == BLOB
    assert len(server.gets("/w/blob.bin")) == 2


def test_mirror_used_when_primary_fails(server: Server, cache: Path) -> None:
    mirror = server.add("/mirror/m.bin", BLOB)
    entry = PretrainedWeights(
        name="mirrored",
        arch="semattnet",
        urls=(server.url("/gone/m.bin"), mirror),
        file_name="m.bin",
        format="torch",
        license="x",
        sha256=SHA,
    )
    path = fetch_weights(entry, progress=False)
    assert path == cache / "mirrored" / "m.bin" and path.read_bytes() == BLOB
    dead = PretrainedWeights(
        name="dead",
        arch="semattnet",
        urls=(server.url("/gone/a"), server.url("/gone/b")),
        file_name="d.bin",
        format="torch",
        license="x",
    )
    with pytest.raises(DownloadError) as err:
        fetch_weights(dead, progress=False)
    assert "/gone/a" in str(err.value) and "/gone/b" in str(err.value)
    assert cache_files(cache) == ["mirrored/m.bin"]  # no empty .part left by the failures


def test_file_url(tmp_path: Path, cache: Path) -> None:
    src = tmp_path / "local weights.bin"
    src.write_bytes(BLOB)
    path = fetch_weights(src.as_uri(), sha256=SHA, progress=False)
    assert path.read_bytes() == BLOB and path.name == "local weights.bin" and cache in path.parents


def test_gdrive_through_gdown(cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    gdown = pytest.importorskip("gdown")
    calls = []

    def fake_download(*, id: str, output: str, quiet: bool, resume: bool) -> str:
        calls.append((id, resume))
        Path(output).write_bytes(BLOB)
        return output

    monkeypatch.setattr(gdown, "download", fake_download)
    entry = PretrainedWeights(
        name="drive",
        arch="semattnet",
        urls=("gdrive://abc_DEF-123",),
        file_name="w.pth.tar",
        format="torch",
        license="x",
        sha256=SHA,
    )
    assert fetch_weights(entry, progress=False).read_bytes() == BLOB
    link = fetch_weights("https://drive.google.com/file/d/XyZ-9/view?usp=sharing", progress=False)
    assert calls == [("abc_DEF-123", True), ("XyZ-9", True)]
    assert link.name == "gdrive-XyZ-9"


def test_pooch_used_without_huggingface_hub(server: Server, cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    pytest.importorskip("pooch")
    import sys

    monkeypatch.setitem(sys.modules, "huggingface_hub.file_download", None)  # import fails
    url = server.add("/w/blob.bin", BLOB)
    assert fetch_weights(url, sha256=SHA, progress=False).read_bytes() == BLOB


def test_registry_name_and_bad_arguments(cache: Path) -> None:
    with pytest.raises(ValueError, match="known: semattnet-kitti"):
        fetch_weights("no-such-weights")
    with pytest.raises(ValueError, match="64 hex"):
        fetch_weights("http://127.0.0.1:9/x", sha256="abc")
    with pytest.raises(DownloadError, match="unsupported URL"):
        fetch_weights("ftp://127.0.0.1:9/x", progress=False)


def test_errors_derive_from_the_root_and_stay_os_errors() -> None:
    import semattnet.cache as cache_pkg
    from semattnet import SemAttNetError
    from semattnet.weights import UnknownWeightsError

    for cls in (DownloadError, ChecksumError, OfflineError):
        assert issubclass(cls, SemAttNetError) and issubclass(cls, OSError), cls
    assert issubclass(UnknownWeightsError, SemAttNetError)
    assert cache_pkg.DownloadError is DownloadError  # one home (semattnet.cache), re-exported
    assert fetch_weights.__module__ == "semattnet.weights.resolve"  # the weights layer: registry names and records
    with pytest.raises(UnknownWeightsError):
        fetch_weights("no-such-weights")


def test_the_generic_cache_takes_urls_only(tmp_path: Path, cache: Path) -> None:
    from semattnet.cache import fetch as fetch_url

    src = tmp_path / "a.bin"
    src.write_bytes(BLOB)
    assert fetch_url(src.as_uri(), sha256=SHA, progress=False) == fetch_weights(
        src.as_uri(), sha256=SHA, progress=False
    )
    with pytest.raises(DownloadError, match="unsupported URL"):
        fetch_url("semattnet-kitti", progress=False)  # a registry name means nothing to the generic cache
