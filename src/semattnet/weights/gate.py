"""The one gate every file read as weights passes before any deserialiser sees it.

:func:`inspect_weights_file` identifies the format from the bytes and checks the structure and
integrity without running anything from the file:

* **safetensors**: an 8-byte little-endian header length (< 100 MB and inside the file), a JSON
  header that parses, known dtypes, ``data_offsets`` inside the data section, matching each
  tensor's shape, and not overlapping;
* **torch zip archive** (``torch.save``): only the members ``torch.save`` writes
  (``<prefix>/data.pkl``, ``<prefix>/data/<n>``, ``<prefix>/version``, ``byteorder``, ``.data/...``,
  ``.format_version``, ``.storage_alignment``). A TorchScript archive (``constants.pkl``, ``code/``,
  ``.py`` members) is refused: loading it runs its TorchScript. Every member's CRC is checked;
* **legacy torch pickle** (non-zip ``torch.save``): the pickled magic number first.

For both pickle formats the pickle is disassembled (``pickletools``, nothing executed) to list the
globals it names and the sizes of the storages it asks for (each must fit in the file).

:func:`tensor_digest` is the sha256 of the tensor payload that ``save_safetensors`` and the
trainer store under :data:`DIGEST_KEY`; :func:`verify_digest` checks it after loading.
"""

from __future__ import annotations

import hashlib
import io
import itertools
import json
import math
import pickletools
import re
import struct
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

import torch

from semattnet._errors import SemAttNetError
from semattnet.weights._safe_pickle import UnsafeCheckpointError

__all__ = [
    "DIGEST_KEY",
    "CheckpointError",
    "Inspected",
    "UnsafeCheckpointError",
    "inspect_weights_file",
    "tensor_digest",
    "verify_digest",
]

#: Metadata key (safetensors metadata / top-level checkpoint dict entry) of the payload sha256.
DIGEST_KEY = "payload_sha256"

MAX_SAFETENSORS_HEADER = 100 * 1024 * 1024

_SAFETENSORS_ITEMSIZE = {
    "BOOL": 1, "U8": 1, "I8": 1, "F8_E4M3": 1, "F8_E4M3FNUZ": 1, "F8_E5M2": 1, "F8_E5M2FNUZ": 1,
    "I16": 2, "U16": 2, "F16": 2, "BF16": 2, "I32": 4, "U32": 4, "F32": 4, "I64": 8, "U64": 8, "F64": 8,
    "C64": 8,
}  # fmt: skip

# Members torch.save writes into its zip archive, relative to the one top-level folder.
_ZIP_MEMBER = re.compile(
    r"data\.pkl|version|byteorder|\.format_version|\.storage_alignment|\.data/serialization_id|\.data/version|data/\d+"
)
_TORCHSCRIPT_HINT = "TorchScript archives are not loaded as weights (they run code); export the state dict"
_LEGACY_MAGIC = 0x1950A86A20F9469CFC6C


class CheckpointError(SemAttNetError):
    """A checkpoint file that cannot be read or holds no weights."""


@dataclass
class Inspected:
    """What the gate found out about a file.

    Attributes:
        path: the file.
        format: ``"safetensors"``, ``"torch-zip"`` or ``"torch-legacy"``.
        protocol: pickle protocol of the object pickle (torch formats).
        globals: ``module.name`` of every global the object pickle names (torch formats).
        header: the parsed safetensors header (safetensors).
    """

    path: Path
    format: str
    protocol: int = 0
    globals: set[str] = field(default_factory=set)
    header: dict[str, Any] = field(default_factory=dict)


def inspect_weights_file(path: str | Path) -> Inspected:
    """Identify ``path``'s format from its bytes and check its structure and integrity.

    Raises:
        CheckpointError: not a checkpoint, malformed, truncated or corrupt (CRC).
        UnsafeCheckpointError: a TorchScript archive.
    """
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"{path}: no such checkpoint file")
    size = path.stat().st_size
    with open(path, "rb") as f:
        head = f.read(16)
    if head.startswith(b"PK\x03\x04"):  # torch.save's zip archives start with a local file header
        return _inspect_zip(path, size)
    if len(head) >= 9 and head[8:9] == b"{":  # an 8-byte header length, then the JSON header
        return _inspect_safetensors(path, size)
    if head[:1] == b"\x80":  # pickle PROTO: a legacy torch.save file starts with its magic number
        return _inspect_legacy(path, size)
    raise CheckpointError(
        f"not a checkpoint: {path} is not a readable weights file, neither safetensors nor torch.save "
        f"(first bytes {head[:8]!r})"
    )


# ----------------------------------------------------------------------------- safetensors


def _inspect_safetensors(path: Path, size: int) -> Inspected:
    with open(path, "rb") as f:
        (n,) = struct.unpack("<Q", f.read(8))
        if n >= MAX_SAFETENSORS_HEADER or 8 + n > size:
            raise CheckpointError(f"{path}: safetensors header length {n} is not sane for a {size}-byte file")
        raw = f.read(n)
    try:
        header = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise CheckpointError(f"{path}: safetensors header is not JSON ({exc}); the file is corrupt") from None
    if not isinstance(header, dict):
        raise CheckpointError(f"{path}: safetensors header is not a JSON object")
    meta = header.get("__metadata__", {})
    if not isinstance(meta, dict) or not all(isinstance(v, str) for v in meta.values()):
        raise CheckpointError(f"{path}: safetensors __metadata__ must map names to strings")
    spans = sorted(_tensor_span(path, k, v, size - 8 - n) for k, v in header.items() if k != "__metadata__")
    for (_, e0, k0), (b1, _, k1) in itertools.pairwise(spans):
        if b1 < e0:
            raise CheckpointError(f"{path}: safetensors tensors {k0!r} and {k1!r} overlap; the file is corrupt")
    return Inspected(path=path, format="safetensors", header=header)


def _tensor_span(path: Path, name: str, entry: Any, data_size: int) -> tuple[int, int, str]:
    if not isinstance(entry, dict) or set(entry) != {"dtype", "shape", "data_offsets"}:
        raise CheckpointError(f"{path}: safetensors entry {name!r} is malformed")
    dtype, shape, offsets = entry["dtype"], entry["shape"], entry["data_offsets"]
    if dtype not in _SAFETENSORS_ITEMSIZE:
        raise CheckpointError(f"{path}: safetensors tensor {name!r} has unknown dtype {dtype!r}")
    ints = isinstance(shape, list) and isinstance(offsets, list) and len(offsets) == 2
    if not ints or not all(isinstance(x, int) and not isinstance(x, bool) and x >= 0 for x in [*shape, *offsets]):
        raise CheckpointError(f"{path}: safetensors tensor {name!r} has a malformed shape or data_offsets")
    begin, end = offsets
    if not begin <= end <= data_size:
        raise CheckpointError(
            f"{path}: safetensors tensor {name!r} points outside the file (bytes {begin}..{end} of {data_size})"
        )
    if end - begin != math.prod(shape) * _SAFETENSORS_ITEMSIZE[dtype]:
        raise CheckpointError(f"{path}: safetensors tensor {name!r}: {end - begin} bytes do not hold {dtype}{shape}")
    return begin, end, name


# ----------------------------------------------------------------------------- torch zip


def _inspect_zip(path: Path, size: int) -> Inspected:
    try:
        with zipfile.ZipFile(path) as zf:
            prefix = _check_zip_members(path, zf.namelist())
            bad = zf.testzip()
            if bad is not None:
                raise CheckpointError(f"{path}: member {bad} fails its CRC check; the file is corrupt, fetch it again")
            pkl = zf.read(f"{prefix}/data.pkl")
    except SemAttNetError:
        raise
    except (zipfile.BadZipFile, zipfile.LargeZipFile, EOFError, OSError, ValueError) as exc:
        raise CheckpointError(f"{path}: not a readable PyTorch checkpoint (truncated or corrupt?): {exc}") from None
    protocol, names, storages = _scan_pickle(path, io.BytesIO(pkl))
    _check_storage_sizes(path, storages, size)
    return Inspected(path=path, format="torch-zip", protocol=protocol, globals=names)


def _check_zip_members(path: Path, names: list[str]) -> str:
    """The archive's top-level folder; refuses TorchScript and members torch.save does not write."""
    prefixes = {n.split("/", 1)[0] for n in names}
    if len(prefixes) != 1 or any("/" not in n for n in names):
        raise CheckpointError(f"not a checkpoint: {path} is a zip archive but not one written by torch.save")
    prefix = prefixes.pop()
    rel = [n.split("/", 1)[1] for n in names]
    if any(r == "constants.pkl" or r.startswith("code/") or r.endswith((".py", ".debug_pkl")) for r in rel):
        raise UnsafeCheckpointError(f"{path}: {_TORCHSCRIPT_HINT}")
    unexpected = [n for n, r in zip(names, rel, strict=True) if not _ZIP_MEMBER.fullmatch(r)]
    if unexpected:
        raise CheckpointError(f"{path}: unexpected member(s) {unexpected[:3]} in a torch.save archive; refusing it")
    if "data.pkl" not in rel:
        raise CheckpointError(f"{path}: torch.save archive without data.pkl; the file is incomplete")
    return prefix


# ----------------------------------------------------------------------------- legacy torch pickle


def _inspect_legacy(path: Path, size: int) -> Inspected:
    with open(path, "rb") as f:
        first = _pickle_ops(path, f)
        longs = [arg for op, arg in first if op == "LONG1"]
        if longs != [_LEGACY_MAGIC] or len(first) > 4:
            raise CheckpointError(f"not a checkpoint: {path} is a pickle but not a torch.save file (no magic number)")
        _pickle_ops(path, f)  # protocol version
        _pickle_ops(path, f)  # system info
        protocol, names, storages = _scan_pickle(path, f)
    _check_storage_sizes(path, storages, size)
    return Inspected(path=path, format="torch-legacy", protocol=protocol, globals=names)


# ----------------------------------------------------------------------------- pickle disassembly


def _pickle_ops(path: Path, f: BinaryIO) -> list[tuple[str, Any]]:
    try:
        return [(op.name, arg) for op, arg, _ in pickletools.genops(f)]
    except (ValueError, EOFError, struct.error, UnicodeDecodeError) as exc:
        raise CheckpointError(f"{path}: not a readable PyTorch checkpoint (truncated or corrupt?): {exc}") from None


_SCALAR_OPS = {
    "BININT", "BININT1", "BININT2", "INT", "LONG", "LONG1", "LONG4", "BINUNICODE", "SHORT_BINUNICODE",
    "BINUNICODE8", "UNICODE", "BINSTRING", "SHORT_BINSTRING", "STRING",
}  # fmt: skip


def _scan_pickle(path: Path, f: BinaryIO) -> tuple[int, set[str], list[int]]:
    """Protocol, named globals and requested storage sizes of one pickle, without running it.

    A storage is requested by a persistent id ``('storage', type, key, location, numel, ...)``; the
    scan follows the scalars pushed since the last MARK (and memo gets) to read ``numel``.
    """
    protocol, names, sizes = 0, set(), []
    memo: dict[Any, Any] = {}
    window: list[Any] = []
    last: Any = None
    for op, arg in _pickle_ops(path, f):
        if op == "PROTO":
            protocol = int(arg)
        elif op in ("GLOBAL", "INST"):
            module, _, name = str(arg).partition(" ")
            names.add(f"{module}.{name}")
            last = f"{module}.{name}"
            window.append(last)
        elif op == "STACK_GLOBAL":
            names.add("<stack global>")  # module/name computed on the stack: resolved at load by find_class
        elif op == "MARK":
            window, last = [], None
        elif op in _SCALAR_OPS:
            last = arg
            window.append(arg)
        elif op in ("BINPUT", "LONG_BINPUT", "PUT", "MEMOIZE"):
            memo[len(memo) if op == "MEMOIZE" else arg] = last
        elif op in ("BINGET", "LONG_BINGET", "GET"):
            last = memo.get(arg)
            window.append(last)
        elif op in ("BINPERSID", "PERSID"):
            if len(window) >= 5 and window[0] == "storage" and isinstance(window[4], int):
                sizes.append(window[4])
            window = []
        else:
            last = None
    return protocol, names, sizes


def _check_storage_sizes(path: Path, sizes: list[int], file_size: int) -> None:
    if any(n < 0 or n > file_size for n in sizes) or sum(sizes) > file_size:
        raise CheckpointError(f"{path}: the pickle asks for storages larger than the file; it is corrupt or hostile")


# ----------------------------------------------------------------------------- payload digest


def _update(h: Any, where: str, obj: Any) -> None:
    if isinstance(obj, torch.Tensor):
        t = obj.detach().to("cpu").contiguous().reshape(-1)
        h.update(f"{where}|{t.dtype}|{tuple(obj.shape)}\n".encode())
        h.update(memoryview(t.view(torch.uint8).numpy()) if t.numel() else b"")
    elif isinstance(obj, Mapping):
        for k in sorted(obj, key=str):
            _update(h, f"{where}/{k}", obj[k])
    elif isinstance(obj, list | tuple):
        for i, v in enumerate(obj):
            _update(h, f"{where}/{i}", v)


def tensor_digest(obj: Any) -> str:
    """sha256 of every tensor in ``obj`` (nested dicts, lists, tuples): path, dtype, shape and bytes.

    The :data:`DIGEST_KEY` entry of a top-level mapping is left out, so a checkpoint can carry it.
    """
    h = hashlib.sha256()
    if isinstance(obj, Mapping):
        obj = {k: v for k, v in obj.items() if k != DIGEST_KEY}
    _update(h, "", obj)
    return h.hexdigest()


def verify_digest(path: Path, obj: Any, expected: Any) -> None:
    """Refuse ``path`` when ``expected`` (the stored digest, if any) does not match its tensors."""
    if expected is None:
        return
    got = tensor_digest(obj)
    if got != expected:
        raise CheckpointError(
            f"{path}: tensor payload sha256 {got[:16]}... does not match the {expected!s:.16}... recorded at save "
            "time; the file is corrupt, restore or download it again"
        )
