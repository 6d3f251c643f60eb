"""The weights gate against hostile files built here: it sees what the loader loads, keeps
allow-listed classes inert, bounds sizes before anything is allocated and never relays torch's
``weights_only=False`` advice. Every refusal is one line naming the file, fast, with no code run."""

from __future__ import annotations

import argparse
import io
import json
import pickle
import struct
import tarfile
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner
from safetensors.torch import save_file

import semattnet
from semattnet._errors import DataError, SemAttNetError
from semattnet._utils.documents import MAX_NESTING, loads_json, loads_yaml
from semattnet.cli import main
from semattnet.geometry.calibration import read_rig_json
from semattnet.models.config import RANGES, SemAttNetConfig
from semattnet.weights import from_pretrained
from semattnet.weights._safe_pickle import describe_torch_refusal
from semattnet.weights.checkpoint import StateDictMismatchError, load_checkpoint, load_weights
from semattnet.weights.gate import (
    DIGEST_KEY,
    MAX_SAFETENSORS_TENSORS,
    CheckpointError,
    UnsafeCheckpointError,
    inspect_weights_file,
)

_LEGACY_MAGIC = pickle.dumps(0x1950A86A20F9469CFC6C, protocol=2)


def _one_line_refusal(path: Path, cls: type[SemAttNetError] = SemAttNetError, seconds: float = 5.0) -> str:
    """Load ``path`` through the public API: a one-line ``cls`` naming the file, in ``seconds``."""
    start = time.monotonic()
    with pytest.raises(cls) as err:
        semattnet.weights.load_checkpoint(path)
    msg = str(err.value)
    assert str(path) in msg and "\n" not in msg, msg
    assert "weights_only" not in msg.lower() and "weights only" not in msg.lower(), msg
    assert time.monotonic() - start < seconds
    return msg


@pytest.fixture
def no_torch_load(monkeypatch: pytest.MonkeyPatch) -> None:
    """Fail if a deserialiser runs: the gate must refuse first."""

    def boom(*args: object, **kwargs: object) -> None:
        pytest.fail("torch.load ran before the gate refused the file")

    monkeypatch.setattr(torch, "load", boom)


def _torch_zip_with(path: Path, pkl: bytes, tmp_path: Path, protocol: int = 2) -> Path:
    """A torch.save archive whose ``data.pkl`` is replaced by ``pkl`` (all other members kept)."""
    base = tmp_path / f"base{protocol}.pt"
    torch.save({"w": torch.zeros(2)}, base, pickle_protocol=protocol)
    with zipfile.ZipFile(base) as zi, zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as zo:
        for info in zi.infolist():
            data = zi.read(info)
            name = info.filename.replace(base.stem, path.stem)
            zo.writestr(name, pkl if name.endswith("data.pkl") else data)
    return path


# ----------------------------------------------------------------------------- 1. what the loader reads


def _legacy_preamble() -> bytes:
    """Magic number, protocol version, system info and an empty dict: a 'harmless' legacy pickle."""
    return _LEGACY_MAGIC + pickle.dumps(1001, protocol=2) + b"\x80\x02}." + b"\x80\x02}."


def test_tar_whose_first_member_looks_like_a_legacy_checkpoint_is_refused(tmp_path: Path, no_torch_load) -> None:
    path = tmp_path / "model.pth.tar"
    name = _legacy_preamble().decode("utf-8", "surrogateescape")
    with tarfile.open(path, "w", format=tarfile.USTAR_FORMAT, encoding="utf-8", errors="surrogateescape") as tar:
        for member in (name, "sys_info", "pickle", "tensors", "storages"):
            info = tarfile.TarInfo(member)
            info.size = 4
            tar.addfile(info, fileobj=io.BytesIO(b"\x80\x02N."))
    assert path.read_bytes()[:1] == b"\x80"  # what the old gate took for a legacy pickle
    assert "tar" in _one_line_refusal(path, UnsafeCheckpointError)


def test_tar_header_without_the_ustar_magic_is_still_a_tar(tmp_path: Path, no_torch_load) -> None:
    """An old-style (v7) header: tarfile, and so torch.load, read it by its checksum alone."""
    header = bytearray(512)
    header[:30] = _legacy_preamble()
    header[100:108], header[108:116], header[116:124] = b"0000644\0", b"0000000\0", b"0000000\0"
    header[124:136], header[136:148], header[156:157] = b"00000000000\0", b"00000000000\0", b"0"
    header[148:156] = b" " * 8
    header[148:156] = b"%06o\0 " % sum(header)
    path = tmp_path / "v7.pt"
    path.write_bytes(bytes(header) + b"\0" * 1024)
    assert tarfile.is_tarfile(path)
    _one_line_refusal(path, UnsafeCheckpointError)


def test_zip_with_a_member_name_twice_is_refused(tmp_path: Path, no_torch_load) -> None:
    path = tmp_path / "dup.pt"
    torch.save({"w": torch.zeros(2)}, path)
    with pytest.warns(UserWarning, match="Duplicate name"), zipfile.ZipFile(path, "a") as zf:
        zf.writestr("dup/data.pkl", pickle.dumps({"w": 1}, protocol=2))
    assert "dup/data.pkl" in _one_line_refusal(path, UnsafeCheckpointError)


# ----------------------------------------------------------------------------- 2. no weights_only advice


@pytest.mark.parametrize(
    "pkl",
    [
        b"\x80\x02cos\nsystem\n\x85.",  # GLOBAL, named statically
        b"\x80\x02\x8c\x02os\x8c\x06system\x93\x8c\x04true\x85R.",  # STACK_GLOBAL behind a PROTO 2 header
        b"\x80\x04\x8c\x02os\x8c\x06system\x93\x8c\x04true\x85R.",  # protocol 4: our unpickler
    ],
    ids=["global", "stack-global-proto2", "proto4"],
)
def test_disallowed_global_is_named_without_torch_advice(tmp_path: Path, pkl: bytes) -> None:
    path = _torch_zip_with(tmp_path / "evil.pt", pkl, tmp_path)
    msg = _one_line_refusal(path, UnsafeCheckpointError)
    assert "os.system" in msg


def test_torch_refusal_text_is_rewritten() -> None:
    """torch's own message (with its advice) becomes one line naming the global."""
    buf = io.BytesIO()
    torch.save({"args": argparse.Namespace(a=1)}, buf)
    buf.seek(0)
    with pytest.raises(pickle.UnpicklingError) as err:
        torch.load(buf, weights_only=True)
    assert "weights_only" in str(err.value)  # torch does give the advice
    text = describe_torch_refusal(err.value)
    assert "argparse.Namespace" in text and "\n" not in text
    assert "weights_only" not in text and "safe_globals" not in text


# ----------------------------------------------------------------------------- 3. allow-listed classes are inert

_NAMESPACE = b"cargparse\nNamespace\n"
_HOSTILE_BUILDS = {
    "dict-state-on-class": b"\x80\x04" + _NAMESPACE + b"}\x8c\x05pwned\x88sb.",
    "slot-state-on-class": b"\x80\x04" + _NAMESPACE + b"N}\x8c\x05pwned\x88s\x86b.",
    "proto2-slot-state": b"\x80\x02" + _NAMESPACE + b"N}X\x05\x00\x00\x00pwned\x88s\x86b.",
    "state-on-a-function": b"\x80\x04ctorch._utils\n_rebuild_tensor\n}\x8c\x05pwned\x88sb.",
    "setitems-on-class": b"\x80\x04" + _NAMESPACE + b"(\x8c\x05pwned\x88u.",
}


@pytest.mark.parametrize("pkl", list(_HOSTILE_BUILDS.values()), ids=list(_HOSTILE_BUILDS))
def test_state_is_never_applied_to_a_class_or_function(tmp_path: Path, pkl: bytes) -> None:
    path = _torch_zip_with(tmp_path / "build.pt", pkl, tmp_path)
    msg = _one_line_refusal(path, UnsafeCheckpointError)
    assert "build" in msg.lower() or "SETITEMS" in msg, msg  # the reason, not a generic refusal
    assert not hasattr(argparse.Namespace, "pwned")
    assert not hasattr(torch._utils._rebuild_tensor, "pwned")


def test_state_is_never_applied_to_a_shared_numpy_dtype(tmp_path: Path) -> None:
    """``numpy.dtype('f8', False, False)`` is the process's float64 singleton, not a new object."""
    pkl = b"\x80\x04cnumpy\ndtype\n\x8c\x02f8\x89\x89\x87R(K\x03\x8c\x01>NNNJ\xff\xff\xff\xffJ\xff\xff\xff\xffK\x00tb."
    path = _torch_zip_with(tmp_path / "dtype.pt", pkl, tmp_path)
    _one_line_refusal(path, UnsafeCheckpointError)
    assert np.dtype("f8").byteorder == "="


def test_protocol4_checkpoint_with_args_and_numpy_still_loads(tmp_path: Path) -> None:
    path = tmp_path / "ok.pt"
    state = {"w": torch.arange(4.0)}
    torch.save(
        {"model": state, "args": argparse.Namespace(lr=0.1), "rng": np.arange(3), "epoch": 2}, path, pickle_protocol=4
    )
    assert inspect_weights_file(path).protocol == 4
    ckpt = load_checkpoint(path)
    assert ckpt.args == {"lr": 0.1} and ckpt.epoch == 2 and torch.equal(ckpt.state_dict["w"], state["w"])
    assert np.array_equal(ckpt.extra["rng"], np.arange(3))


# ----------------------------------------------------------------------------- 4. safetensors against the model


def test_safetensors_dtype_relabelled_does_not_load_into_a_float_parameter(tmp_path: Path) -> None:
    model = torch.nn.Linear(2, 2)
    path = tmp_path / "relabelled.safetensors"
    save_file({k: v.detach().contiguous() for k, v in model.state_dict().items()}, str(path))
    data = path.read_bytes()
    n = struct.unpack("<Q", data[:8])[0]
    header = data[8 : 8 + n].replace(b'"F32"', b'"I32"')
    path.write_bytes(data[:8] + header + data[8 + n :])
    ckpt = load_checkpoint(path)  # a well-formed file...
    assert ckpt.state_dict["weight"].dtype == torch.int32
    before = model.weight.detach().clone()
    with pytest.raises(StateDictMismatchError) as err:  # ...that does not fit a float model
        load_weights(model, ckpt)
    msg = str(err.value)
    assert str(path) in msg and "weight" in msg and "dtype" in msg and "\n" not in msg
    assert torch.equal(model.weight.detach(), before)
    report = load_weights(model, ckpt, strict=False)
    assert len(report["mismatched"]) == 2 and torch.equal(model.weight.detach(), before)


def test_half_precision_weights_still_load_into_a_float_model() -> None:
    model = torch.nn.Linear(2, 2)
    load_weights(model, {k: v.half() for k, v in model.state_dict().items()})


def _safetensors(path: Path, header: dict, data: bytes = b"") -> Path:
    raw = json.dumps(header).encode()
    path.write_bytes(struct.pack("<Q", len(raw)) + raw + data)
    return path


def test_safetensors_header_with_200k_tensors_is_refused_fast(tmp_path: Path) -> None:
    entry = {"dtype": "F32", "shape": [0], "data_offsets": [0, 0]}
    path = _safetensors(tmp_path / "many.safetensors", {f"t{i}": entry for i in range(200_000)})
    assert str(MAX_SAFETENSORS_TENSORS) in _one_line_refusal(path, CheckpointError, seconds=2.0)


def test_safetensors_tensor_with_too_many_dimensions_is_refused(tmp_path: Path) -> None:
    entry = {"dtype": "F32", "shape": [1] * 40, "data_offsets": [0, 4]}
    path = _safetensors(tmp_path / "dims.safetensors", {"t": entry}, b"\0" * 4)
    assert "dimensions" in _one_line_refusal(path, CheckpointError)


def test_zero_stride_view_whose_digest_would_need_gibibytes_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "view.pt"
    huge = torch.zeros(1).expand(1 << 20, 1 << 14)  # 64 GiB if made contiguous, 4 bytes stored
    torch.save({"model": {"w": huge}, DIGEST_KEY: "0" * 64}, path)
    assert path.stat().st_size < 10_000
    assert "storage" in _one_line_refusal(path, CheckpointError)
    torch.save({"model": {"w": huge}}, path)  # no digest: still refused (convert would copy it)
    _one_line_refusal(path, CheckpointError)


def test_self_referencing_objects_are_refused_before_the_digest(tmp_path: Path) -> None:
    loop: list = []
    loop.append(loop)
    path = tmp_path / "loop.pt"
    torch.save({"model": {"w": torch.zeros(1)}, "x": loop, DIGEST_KEY: "0" * 64}, path)
    _one_line_refusal(path, CheckpointError)


# ----------------------------------------------------------------------------- 5. slow paths


def test_torch_save_writes_stored_members(tmp_path: Path) -> None:
    """What the zip-bomb bound relies on: torch.save never compresses."""
    path = tmp_path / "plain.pt"
    torch.save({"model": {"w": torch.zeros(1000)}}, path)
    with zipfile.ZipFile(path) as zf:
        assert all(i.compress_type == zipfile.ZIP_STORED and i.file_size == i.compress_size for i in zf.infolist())


def test_zip_bomb_member_is_refused_before_it_is_inflated(tmp_path: Path, no_torch_load) -> None:
    path = _torch_zip_with(tmp_path / "bomb.pt", pickle.dumps({"w": 1}, protocol=2), tmp_path)
    with zipfile.ZipFile(path, "a", zipfile.ZIP_DEFLATED, compresslevel=1) as zf, zf.open("bomb/data/1", "w") as f:
        chunk = bytes(1 << 20)
        for _ in range(80):  # 80 MiB of zeros in a few hundred KiB
            f.write(chunk)
    assert path.stat().st_size < 1 << 20
    assert "bomb/data/1" in _one_line_refusal(path, CheckpointError, seconds=3.0)


def test_zip_members_inflating_far_beyond_the_file_are_refused(tmp_path: Path, no_torch_load) -> None:
    """Sizes are judged from the central directory: a forged total is refused without reading."""
    path = _torch_zip_with(tmp_path / "forged.pt", pickle.dumps({"w": 1}, protocol=2), tmp_path)
    data, at = bytearray(path.read_bytes()), -1
    for _ in range(3):  # three central-directory entries claim 60 MB uncompressed each (under the ratio floor)
        at = data.find(b"PK\x01\x02", at + 1)
        data[at + 24 : at + 28] = struct.pack("<I", 60_000_000)
    path.write_bytes(bytes(data))
    assert "inflate" in _one_line_refusal(path, CheckpointError)


def test_deeply_nested_metadata_json_is_refused(tmp_path: Path) -> None:
    for depth in (MAX_NESTING + 1, 100_000):
        meta = {"config": "[" * depth + "]" * depth}
        path = tmp_path / f"nested{depth}.safetensors"
        save_file({"w": torch.zeros(1)}, str(path), metadata=meta)
        assert "nested deeper" in _one_line_refusal(path, CheckpointError)


def test_oversized_or_nested_config_json_is_refused(tmp_path: Path) -> None:
    folder = tmp_path / "pretrained"
    folder.mkdir()
    (folder / "model.safetensors").write_bytes(b"")
    for text, why in (
        ('{"width": 1.0, "x": "' + "a" * (2 << 20) + '"}', "larger than"),
        ('{"x": ' + "[" * 40 + "]" * 40 + "}", "nested deeper"),
    ):
        (folder / "config.json").write_text(text)
        with pytest.raises(CheckpointError, match=why) as err:
            from_pretrained(folder)
        assert str(folder / "config.json") in str(err.value) and "\n" not in str(err.value)


def test_yaml_alias_bomb_is_refused_fast(tmp_path: Path) -> None:
    lines = ['a: &a ["x","x","x","x","x","x","x","x","x"]']
    for p, c in zip("abcdefgh", "bcdefghi", strict=True):  # 9**9 strings from 9 lines
        lines.append(f"{c}: &{c} [" + ",".join([f"*{p}"] * 9) + "]")
    path = tmp_path / "rig.yaml"
    path.write_text("\n".join([*lines, "K: *i", "T_cam_lidar: *i", "image_size: *i"]) + "\n")
    assert path.stat().st_size < 500
    start = time.monotonic()
    with pytest.raises(DataError, match="alias") as err:
        read_rig_json(path)
    assert str(path) in str(err.value) and time.monotonic() - start < 2


def test_document_bounds_directly() -> None:
    assert loads_json('{"a": [1, [2]]}', "x.json") == {"a": [1, [2]]}
    assert loads_yaml("a: [1, {b: 2}]", "x.yaml") == {"a": [1, {"b": 2}]}
    with pytest.raises(DataError, match=r"x\.yaml: YAML nested deeper"):
        loads_yaml("[" * 40 + "]" * 40, "x.yaml")
    with pytest.raises(DataError, match=r"x\.json: document of"):
        loads_json(" " * (2 << 20), "x.json")


def test_pickle_with_too_many_opcodes_is_refused_fast(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import semattnet.weights.gate as gate

    monkeypatch.setattr(gate, "MAX_PICKLE_OPS", 1000)
    path = _torch_zip_with(tmp_path / "long.pt", b"\x80\x02" + b"N0" * 2000 + b"}.", tmp_path)
    assert "opcodes" in _one_line_refusal(path, CheckpointError)


# ----------------------------------------------------------------------------- 6. config ranges


@pytest.mark.parametrize(
    ("field", "value"),
    [("iterations", 1e9), ("iterations", 10**9), ("width", 64), ("kernel_sizes", [3, 99]), ("reduction", 0)],
)
def test_config_from_file_out_of_range_is_refused_before_any_model(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, field: str, value: object
) -> None:
    import semattnet.models.registry as registry

    monkeypatch.setattr(registry, "build_model", lambda *a, **k: pytest.fail("a model was built"))
    config = {**SemAttNetConfig().to_dict(), field: value}
    path = tmp_path / "model.safetensors"
    save_file({"w": torch.zeros(1)}, str(path), metadata={"config": json.dumps(config)})
    msg = _one_line_refusal(path, CheckpointError)
    assert field in msg and (field == "kernel_sizes" or f"{RANGES[field][1]:g}" in msg)


def test_config_ranges_accept_the_paper_and_the_small_models() -> None:
    SemAttNetConfig()
    SemAttNetConfig(width=0.125, iterations=0, kernel_sizes=(3,), reduction=2)
    SemAttNetConfig(width=np.float32(0.25), iterations=np.int64(2))
    with pytest.raises(ValueError, match=r"width must be a number in \[0.125, 4\], got nan"):
        SemAttNetConfig(width=float("nan"))
    with pytest.raises(ValueError, match="iterations"):
        SemAttNetConfig(iterations=True)


def test_out_of_range_config_json_names_the_file_and_field(tmp_path: Path) -> None:
    folder = tmp_path / "pretrained"
    folder.mkdir()
    (folder / "model.safetensors").write_bytes(b"")
    (folder / "config.json").write_text(json.dumps({"width": 64}))
    with pytest.raises(CheckpointError, match="width must be") as err:
        from_pretrained(folder)
    assert str(folder / "config.json") in str(err.value)


# ----------------------------------------------------------------------------- 7. info


_ONE_KEY = {
    "rgb-only": {"rgb_conv_init.0.weight": torch.zeros(4, 4, 3, 3)},
    "other": {"x": torch.zeros(1)},
    "0-dim": {"rgb_conv_init.0.weight": torch.tensor(1.0)},
    "huge-width": {"rgb_conv_init.0.weight": torch.zeros(4096, 1), "cbam_192.ChannelGate.mlp.1.weight": torch.zeros(1)},
}


@pytest.mark.parametrize("state", list(_ONE_KEY.values()), ids=list(_ONE_KEY))
def test_info_on_a_state_dict_with_one_key_is_one_line(tmp_path: Path, state: dict) -> None:
    path = tmp_path / "one.pt"
    torch.save(state, path)
    res = CliRunner().invoke(main, ["info", str(path)])
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert res.exit_code != 0 and isinstance(res.exception, SystemExit | None), res.output
    assert "Traceback" not in res.output and len(lines) == 1 and str(path) in lines[0], res.output
    assert "not a SemAttNet state dict" in lines[0]
