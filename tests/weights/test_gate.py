"""The loading gate: malformed, truncated and corrupt weight files are refused with one line naming the file."""

from __future__ import annotations

import json
import os
import struct
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
import torch

from semattnet.models.config import SemAttNetConfig
from semattnet.weights.checkpoint import Checkpoint, CheckpointError, load_checkpoint, save_safetensors
from semattnet.weights.gate import DIGEST_KEY, inspect_weights_file, tensor_digest

SRC = str(Path(__file__).resolve().parents[2] / "src")


def _state() -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(0)
    return {"conv.weight": torch.randn(64, 64, 3, 3, generator=g), "conv.bias": torch.randn(64, generator=g)}


def _refused(path: Path, match: str) -> str:
    with pytest.raises(CheckpointError, match=match) as err:
        load_checkpoint(path)
    msg = str(err.value)
    assert str(path) in msg and "\n" not in msg
    return msg


def _flip(path: Path, offset: int, n: int = 4096) -> None:
    data = bytearray(path.read_bytes())
    data[offset : offset + n] = bytes(b ^ 0xFF for b in data[offset : offset + n])
    path.write_bytes(bytes(data))


def _member_offset(path: Path, suffix: str) -> tuple[int, int]:
    """(offset of the data, size) of the first zip member whose name ends with ``suffix``."""
    with zipfile.ZipFile(path) as zf:
        info = next(i for i in zf.infolist() if i.filename.endswith(suffix))
    with open(path, "rb") as f:
        f.seek(info.header_offset)
        head = f.read(30)
    name_len, extra_len = struct.unpack("<HH", head[26:30])
    return info.header_offset + 30 + name_len + extra_len, info.file_size


# ----------------------------------------------------------------------------- torch zip


def test_zip_with_4kib_corrupted_inside_a_tensor_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "ckpt.pt"
    torch.save({"model": _state(), "epoch": 3}, path)
    start, size = _member_offset(path, "data/0")
    assert size > 8192
    _flip(path, start + 1000)
    _refused(path, "CRC")


def test_truncated_zip_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "ckpt.pt"
    torch.save({"model": _state()}, path)
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    _refused(path, "truncated or corrupt")


def test_zip_with_an_unexpected_member_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "ckpt.pt"
    torch.save({"model": _state()}, path)
    prefix = zipfile.ZipFile(path).namelist()[0].split("/")[0]
    with zipfile.ZipFile(path, "a") as zf:
        zf.writestr(f"{prefix}/extra/run.sh", "echo hi")
    _refused(path, "unexpected member")


def test_zip_not_written_by_torch_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "notes.zip"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("readme.txt", "hello")
    _refused(path, "not a checkpoint")


# ----------------------------------------------------------------------------- safetensors


def _safetensors(path: Path, header: dict, data: bytes, n: int | None = None) -> Path:
    raw = json.dumps(header).encode()
    path.write_bytes(struct.pack("<Q", len(raw) if n is None else n) + raw + data)
    return path


def test_oversized_safetensors_header_length_is_refused(tmp_path: Path) -> None:
    path = _safetensors(tmp_path / "big.safetensors", {}, b"", n=1 << 40)
    _refused(path, "header length")


def test_safetensors_offsets_outside_the_file_are_refused(tmp_path: Path) -> None:
    header = {"w": {"dtype": "F32", "shape": [1024], "data_offsets": [0, 4096]}}
    _refused(_safetensors(tmp_path / "out.safetensors", header, b"\0" * 16), "outside the file")


def test_overlapping_safetensors_offsets_are_refused(tmp_path: Path) -> None:
    header = {
        "a": {"dtype": "F32", "shape": [4], "data_offsets": [0, 16]},
        "b": {"dtype": "F32", "shape": [4], "data_offsets": [8, 24]},
    }
    _refused(_safetensors(tmp_path / "overlap.safetensors", header, b"\0" * 24), "overlap")


def test_non_json_safetensors_header_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "garbage.safetensors"
    path.write_bytes(struct.pack("<Q", 12) + b"{not json!!}" + b"\0" * 8)
    _refused(path, "not JSON")


@pytest.mark.parametrize(
    ("entry", "match"),
    [
        ({"dtype": "F99", "shape": [2], "data_offsets": [0, 8]}, "unknown dtype"),
        ({"dtype": "F32", "shape": [3], "data_offsets": [0, 8]}, "do not hold"),
        ({"dtype": "F32", "shape": [-2], "data_offsets": [0, 8]}, "malformed"),
        ({"dtype": "F32", "shape": [2]}, "malformed"),
    ],
)
def test_malformed_safetensors_entries_are_refused(tmp_path: Path, entry: dict, match: str) -> None:
    _refused(_safetensors(tmp_path / "bad.safetensors", {"w": entry}, b"\0" * 8), match)


def test_our_safetensors_with_4kib_corrupted_is_refused_by_its_sha256(tmp_path: Path) -> None:
    path = tmp_path / "model.safetensors"
    save_safetensors(Checkpoint(path=path, state_dict=_state(), format="state_dict", config=SemAttNetConfig()), path)
    good = load_checkpoint(path)
    assert DIGEST_KEY not in good.extra and torch.equal(good.state_dict["conv.weight"], _state()["conv.weight"])
    (n,) = struct.unpack("<Q", path.read_bytes()[:8])
    _flip(path, 8 + n + 2048)
    _refused(path, "sha256")


def test_corrupt_safetensors_through_the_cli_is_one_line(tmp_path: Path) -> None:
    path = _safetensors(
        tmp_path / "bad.safetensors", {"w": {"dtype": "F32", "shape": [9], "data_offsets": [0, 36]}}, b"\0" * 4
    )
    res = subprocess.run(
        [sys.executable, "-m", "semattnet.cli", "info", str(path)],
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONPATH": SRC},
        timeout=300,
    )
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.returncode == 1 and "Traceback" not in res.stderr
    assert len(lines) == 1 and str(path) in lines[0]


# ----------------------------------------------------------------------------- payload digest and legacy


def test_recorded_digest_is_verified_for_torch_checkpoints(tmp_path: Path) -> None:
    sd = _state()
    good, bad = tmp_path / "good.pt", tmp_path / "bad.pt"
    torch.save({"model": sd, DIGEST_KEY: tensor_digest({"model": sd})}, good)
    torch.save({"model": sd, DIGEST_KEY: tensor_digest({"model": {**sd, "conv.bias": sd["conv.bias"] + 1}})}, bad)
    ckpt = load_checkpoint(good)
    assert DIGEST_KEY not in ckpt.extra
    _refused(bad, "sha256")


def test_legacy_pickle_with_corrupted_tensor_bytes_is_refused_by_its_sha256(tmp_path: Path) -> None:
    path = tmp_path / "legacy.pt"
    sd = _state()
    torch.save({"model": sd, DIGEST_KEY: tensor_digest({"model": sd})}, path, _use_new_zipfile_serialization=False)
    assert inspect_weights_file(path).format == "torch-legacy"
    assert torch.equal(load_checkpoint(path).state_dict["conv.weight"], sd["conv.weight"])
    _flip(path, path.stat().st_size - 8192)  # inside the raw storage bytes at the end (no CRC in this format)
    _refused(path, "sha256")


def test_legacy_pickle_asking_for_a_huge_storage_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "legacy.pt"
    torch.save({"w": torch.zeros(3)}, path, _use_new_zipfile_serialization=False)
    data = path.read_bytes()
    i = data.index(b"X\x03\x00\x00\x00cpu") + 10  # the storage's location, memoised, then its element count
    assert data[i : i + 2] == b"K\x03"  # BININT1 3
    path.write_bytes(data[:i] + b"J" + struct.pack("<i", 2**31 - 1) + data[i + 2 :])
    _refused(path, "storages larger than the file")


@pytest.mark.parametrize(
    ("content", "match"),
    [
        (b"hello, I am text, not weights\n", "not a checkpoint"),
        (b"\x80\x02}q\x00.", "not a torch.save file"),  # a pickle, but not torch.save's
        (b"", "not a checkpoint"),
    ],
)
def test_files_that_are_not_checkpoints_are_refused(tmp_path: Path, content: bytes, match: str) -> None:
    path = tmp_path / "x.pth"
    path.write_bytes(content)
    _refused(path, match)


def test_torch_pickles_are_read_with_weights_only(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    calls = []
    real = torch.load

    def spy(*args: object, **kwargs: object) -> object:
        calls.append(kwargs.get("weights_only"))
        return real(*args, **kwargs)

    monkeypatch.setattr(torch, "load", spy)
    for zip_format in (True, False):
        path = tmp_path / f"sd-{zip_format}.pt"
        torch.save(_state(), path, _use_new_zipfile_serialization=zip_format)
        assert set(load_checkpoint(path).state_dict) == set(_state())
    assert calls == [True, True]
