"""The one gate every file read as weights passes before any deserialiser sees it.

:func:`inspect_weights_file` identifies the format from the bytes and checks the structure and
integrity without running anything from the file:

* **safetensors**: an 8-byte little-endian header length (< 100 MB and inside the file), a JSON
  header that parses, at most :data:`MAX_SAFETENSORS_TENSORS` tensors (counted before the header
  is parsed), known dtypes, at most :data:`MAX_TENSOR_DIMS` dimensions, ``data_offsets`` inside the
  data section, holding exactly each tensor's dtype and shape, and not overlapping; the JSON the
  loader reads from its metadata (``config``, ``args``) within the bounds of
  :mod:`semattnet._utils.documents`;
* **torch zip archive** (``torch.save``): only the members ``torch.save`` writes
  (``<prefix>/data.pkl``, ``<prefix>/data/<n>``, ``<prefix>/version``, ``byteorder``, ``.data/...``,
  ``.format_version``, ``.storage_alignment``), each name once. A TorchScript archive
  (``constants.pkl``, ``code/``, ``.py`` members) is refused: loading it runs its TorchScript.
  Uncompressed sizes are bounded (per member by the compression ratio, in total by the file size)
  before any member is read; then every member's CRC is checked;
* **legacy torch pickle** (non-zip ``torch.save``): the pickled magic number first;
* a **tar archive** (the pre-1.0 ``torch.save`` format, which ``torch.load`` reads from its members
  ``sys_info``, ``pickle``, ``tensors``, ``storages`` whatever the first bytes look like) is refused.

For both pickle formats the pickle is disassembled (``pickletools``, nothing executed, at most
:data:`MAX_PICKLE_OPS` opcodes) to list the globals it names, the highest protocol its opcodes need
and the sizes of the storages it asks for (each must fit in the file).

:func:`tensor_digest` is the sha256 of the tensor payload that ``save_safetensors`` and the
trainer store under :data:`DIGEST_KEY`; :func:`verify_digest` checks it after loading, and first
(:func:`check_tensor_bounds`) that no tensor is a view asking for more bytes than its storage holds
(a zero-stride or huge-shape view whose digest or copy would allocate gigabytes).
"""

from __future__ import annotations

import collections
import hashlib
import io
import itertools
import json
import math
import pickletools
import re
import struct
import tarfile
import zipfile
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

import torch

from semattnet._errors import SemAttNetError
from semattnet._utils.bounds import regular_file
from semattnet._utils.documents import loads_json
from semattnet.weights._safe_pickle import UnsafeCheckpointError

__all__ = [
    "DIGEST_KEY",
    "CheckpointError",
    "Inspected",
    "UnsafeCheckpointError",
    "check_tensor_bounds",
    "inspect_weights_file",
    "tensor_digest",
    "verify_digest",
]

#: Metadata key (safetensors metadata / top-level checkpoint dict entry) of the payload sha256.
DIGEST_KEY = "payload_sha256"

MAX_SAFETENSORS_HEADER = 100 * 1024 * 1024
#: Most tensors a safetensors header may list.
MAX_SAFETENSORS_TENSORS = 100_000
#: Most dimensions of one tensor (safetensors header).
MAX_TENSOR_DIMS = 32
#: Most opcodes in one pickle (the disassembly runs at about 2 million opcodes a second).
MAX_PICKLE_OPS = 5_000_000
#: A zip member larger than this (bytes) must not be compressed more than MAX_ZIP_RATIO : 1.
ZIP_RATIO_FLOOR = 64 * 1024 * 1024
MAX_ZIP_RATIO = 50
#: Nesting depth and container visits bound for the objects a pickle builds (the digest walks them).
MAX_OBJECT_DEPTH = 64
MAX_OBJECT_VISITS = 1_000_000

_SAFETENSORS_ITEMSIZE = {
    "BOOL": 1,
    "U8": 1,
    "I8": 1,
    "F8_E4M3": 1,
    "F8_E4M3FNUZ": 1,
    "F8_E5M2": 1,
    "F8_E5M2FNUZ": 1,
    "I16": 2,
    "U16": 2,
    "F16": 2,
    "BF16": 2,
    "I32": 4,
    "U32": 4,
    "F32": 4,
    "I64": 8,
    "U64": 8,
    "F64": 8,
    "C64": 8,
}

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
        format: ``"safetensors"``, ``"torch-zip"``, ``"torch-legacy"`` or ``"packed"`` (a gzip stream,
            read only by :func:`semattnet.weights.packed.read_packed`).
        protocol: pickle protocol of the object pickle (torch formats).
        globals: ``module.name`` of every global the object pickle names (torch formats).
        header: the parsed safetensors header (safetensors).
    """

    path: Path
    format: str
    protocol: int = 0
    globals: set[str] = field(default_factory=set)
    header: dict[str, object] = field(default_factory=dict)


def inspect_weights_file(path: str | Path) -> Inspected:
    """Identify ``path``'s format from its bytes and check its structure and integrity.

    Raises:
        CheckpointError: not a checkpoint, malformed, truncated or corrupt (CRC).
        UnsafeCheckpointError: a TorchScript archive.
    """
    path = regular_file(path, "checkpoint file", CheckpointError)
    size = path.stat().st_size
    with open(path, "rb") as f:
        head = f.read(512)
    if head.startswith(b"PK\x03\x04"):  # torch.save's zip archives start with a local file header
        return _inspect_zip(path, size)
    if _is_tar(head):
        raise UnsafeCheckpointError(
            f"{path}: a tar archive (the pre-1.0 torch.save format, read from its own 'pickle' member); "
            "it is not loaded as weights: convert it with a trusted PyTorch and save a state dict"
        )
    if len(head) >= 9 and head[8:9] == b"{":  # an 8-byte header length, then the JSON header
        return _inspect_safetensors(path, size)
    if head[:1] == b"\x80":  # pickle PROTO: a legacy torch.save file starts with its magic number
        return _inspect_legacy(path, size)
    if head.startswith(b"\x1f\x8b"):  # gzip: packed weights (semattnet.weights.packed checks the rest)
        return Inspected(path=path, format="packed")
    raise CheckpointError(
        f"not a checkpoint: {path} is not a readable weights file, neither safetensors nor torch.save "
        f"(first bytes {head[:8]!r})"
    )


def _is_tar(head: bytes) -> bool:
    """Whether ``head`` (a file's first 512 bytes) is a tar header exactly as ``tarfile`` (and so the
    legacy ``torch.load``) reads one: a header whose checksum holds, with or without the ``ustar``
    magic (old v7 headers have none; the magic alone could be bytes of a safetensors header)."""
    try:
        tarfile.TarInfo.frombuf(head, "utf-8", "surrogateescape")
    except tarfile.HeaderError:
        return False
    return True


# ----------------------------------------------------------------------------- safetensors


def _read_safetensors_header(path: Path, size: int) -> tuple[dict[str, object], int]:
    """The parsed header and its length; the tensor count is bounded before parsing."""
    with open(path, "rb") as f:
        (n,) = struct.unpack("<Q", f.read(8))
        if n >= MAX_SAFETENSORS_HEADER or 8 + n > size:
            raise CheckpointError(f"{path}: safetensors header length {n} is not sane for a {size}-byte file")
        raw = f.read(n)
    count = raw.count(b'"data_offsets"')  # cheap bound before the header is parsed
    if count > MAX_SAFETENSORS_TENSORS:
        raise CheckpointError(f"{path}: safetensors header lists {count} tensors; at most {MAX_SAFETENSORS_TENSORS}")
    try:
        header = json.loads(raw.decode("utf-8"))
    except RecursionError:
        raise CheckpointError(f"{path}: safetensors header is nested too deeply; the file is corrupt") from None
    except (UnicodeDecodeError, ValueError) as exc:
        raise CheckpointError(f"{path}: safetensors header is not JSON ({exc}); the file is corrupt") from None
    if not isinstance(header, dict):
        raise CheckpointError(f"{path}: safetensors header is not a JSON object")
    if len(header) > MAX_SAFETENSORS_TENSORS + 1:
        raise CheckpointError(
            f"{path}: safetensors header lists {len(header)} tensors; at most {MAX_SAFETENSORS_TENSORS}"
        )
    return header, n


def _inspect_safetensors(path: Path, size: int) -> Inspected:
    header, n = _read_safetensors_header(path, size)
    meta = header.get("__metadata__", {})
    if not isinstance(meta, dict) or not all(isinstance(v, str) for v in meta.values()):
        raise CheckpointError(f"{path}: safetensors __metadata__ must map names to strings")
    for key in ("config", "args"):  # the JSON documents the loader parses
        if key in meta:
            loads_json(meta[key], f"{path} (safetensors metadata {key!r})", error=CheckpointError)
    spans = sorted(_tensor_span(path, k, v, size - 8 - n) for k, v in header.items() if k != "__metadata__")
    for (_, e0, k0), (b1, _, k1) in itertools.pairwise(spans):
        if b1 < e0:
            raise CheckpointError(f"{path}: safetensors tensors {k0!r} and {k1!r} overlap; the file is corrupt")
    return Inspected(path=path, format="safetensors", header=header)


def _tensor_span(path: Path, name: str, entry: object, data_size: int) -> tuple[int, int, str]:
    if not isinstance(entry, dict) or set(entry) != {"dtype", "shape", "data_offsets"}:
        raise CheckpointError(f"{path}: safetensors entry {name!r} is malformed")
    dtype, shape, offsets = entry["dtype"], entry["shape"], entry["data_offsets"]
    if dtype not in _SAFETENSORS_ITEMSIZE:
        raise CheckpointError(f"{path}: safetensors tensor {name!r} has unknown dtype {dtype!r}")
    ints = isinstance(shape, list) and isinstance(offsets, list) and len(offsets) == 2
    if not ints or not all(isinstance(x, int) and not isinstance(x, bool) and x >= 0 for x in [*shape, *offsets]):
        raise CheckpointError(f"{path}: safetensors tensor {name!r} has a malformed shape or data_offsets")
    if len(shape) > MAX_TENSOR_DIMS:
        raise CheckpointError(f"{path}: safetensors tensor {name!r} has {len(shape)} dimensions (> {MAX_TENSOR_DIMS})")
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
            _check_zip_sizes(path, zf.infolist(), size)
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
    """The archive's top-level folder; refuses TorchScript, members torch.save does not write and
    a member name given twice (torch would read one copy, the gate might check the other)."""
    twice = sorted(n for n, k in collections.Counter(names).items() if k > 1)
    if twice:
        raise UnsafeCheckpointError(f"{path}: zip member {twice[0]!r} appears more than once; refusing the archive")
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


def _check_zip_sizes(path: Path, infos: list[zipfile.ZipInfo], size: int) -> None:
    """Bound what reading the archive inflates, from its directory, before any member is read:
    torch.save stores members uncompressed, so a member above :data:`ZIP_RATIO_FLOOR` compressed
    more than :data:`MAX_ZIP_RATIO` : 1 or a total far above the file size is a zip bomb."""
    for info in infos:
        if info.file_size > ZIP_RATIO_FLOOR and info.file_size > MAX_ZIP_RATIO * max(info.compress_size, 1):
            raise CheckpointError(
                f"{path}: zip member {info.filename!r} inflates {info.compress_size} bytes to {info.file_size} "
                f"(more than {MAX_ZIP_RATIO}:1); refusing a zip bomb"
            )
    total, limit = sum(i.file_size for i in infos), 4 * size + ZIP_RATIO_FLOOR
    if total > limit:
        raise CheckpointError(
            f"{path}: zip members inflate to {total} bytes, more than the {limit} accepted for a {size}-byte file"
        )


# ----------------------------------------------------------------------------- legacy torch pickle


def _inspect_legacy(path: Path, size: int) -> Inspected:
    with open(path, "rb") as f:
        first = list(itertools.islice(_pickle_ops(path, f), 5))
        longs = [arg for op, arg, _ in first if op == "LONG1"]
        if longs != [_LEGACY_MAGIC] or len(first) > 4:
            raise CheckpointError(f"not a checkpoint: {path} is a pickle but not a torch.save file (no magic number)")
        for _ in itertools.chain(_pickle_ops(path, f), _pickle_ops(path, f)):  # protocol version, system info
            pass
        protocol, names, storages = _scan_pickle(path, f)
    _check_storage_sizes(path, storages, size)
    return Inspected(path=path, format="torch-legacy", protocol=protocol, globals=names)


# ----------------------------------------------------------------------------- pickle disassembly


def _pickle_ops(path: Path, f: BinaryIO) -> Iterator[tuple[str, object, int]]:
    """``(name, argument, protocol the opcode needs)`` of one pickle's opcodes, at most :data:`MAX_PICKLE_OPS`."""
    try:
        for i, (op, arg, _) in enumerate(pickletools.genops(f)):
            if i >= MAX_PICKLE_OPS:
                raise CheckpointError(f"{path}: the pickle has more than {MAX_PICKLE_OPS} opcodes; refusing it")
            yield op.name, arg, op.proto
    except (ValueError, EOFError, struct.error, UnicodeDecodeError) as exc:
        if isinstance(exc, SemAttNetError):
            raise
        raise CheckpointError(f"{path}: not a readable PyTorch checkpoint (truncated or corrupt?): {exc}") from None


_SCALAR_OPS = {
    "BININT",
    "BININT1",
    "BININT2",
    "INT",
    "LONG",
    "LONG1",
    "LONG4",
    "BINUNICODE",
    "SHORT_BINUNICODE",
    "BINUNICODE8",
    "UNICODE",
    "BINSTRING",
    "SHORT_BINSTRING",
    "STRING",
}


def _scan_pickle(path: Path, f: BinaryIO) -> tuple[int, set[str], list[int]]:
    """Protocol, named globals and requested storage sizes of one pickle, without running it.

    The protocol is the highest the opcodes need (a ``PROTO 2`` pickle using ``STACK_GLOBAL`` is a
    protocol-4 pickle to the loader). A storage is requested by a persistent id
    ``('storage', type, key, location, numel, ...)``; the scan follows the scalars pushed since the
    last MARK (and memo gets) to read ``numel``.
    """
    protocol, names, sizes = 0, set(), []
    memo: dict[object, object] = {}
    window: list[object] = []
    last: object = None
    for op, arg, needs in _pickle_ops(path, f):
        protocol = max(protocol, needs)
        if op == "PROTO":
            protocol = max(protocol, int(str(arg)))
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


def _update(h: hashlib._Hash, where: str, obj: object) -> None:
    if isinstance(obj, torch.Tensor):
        t = obj.detach().to("cpu").contiguous().reshape(-1)
        h.update(f"{where}|{t.dtype}|{tuple(obj.shape)}\n".encode())
        h.update(t.view(torch.uint8).numpy().data if t.numel() else b"")  # .data: the array's memoryview
    elif isinstance(obj, Mapping):
        for k in sorted(obj, key=str):
            _update(h, f"{where}/{k}", obj[k])
    elif isinstance(obj, list | tuple):
        for i, v in enumerate(obj):
            _update(h, f"{where}/{i}", v)


def tensor_digest(obj: object) -> str:
    """sha256 of every tensor in ``obj`` (nested dicts, lists, tuples): path, dtype, shape and bytes.

    The :data:`DIGEST_KEY` entry of a top-level mapping is left out, so a checkpoint can carry it.
    """
    h = hashlib.sha256()
    if isinstance(obj, Mapping):
        obj = {k: v for k, v in obj.items() if k != DIGEST_KEY}
    _update(h, "", obj)
    return h.hexdigest()


def check_tensor_bounds(path: Path, obj: object) -> None:
    """Refuse ``path`` when the objects it built (walked as :func:`tensor_digest` walks them) nest
    deeper than :data:`MAX_OBJECT_DEPTH` or more than :data:`MAX_OBJECT_VISITS` times (cycles, shared
    containers), or hold a tensor view asking for more bytes than its storage has (zero strides,
    huge shapes): hashing or copying such a view would allocate them."""
    stack, visits, seen = [(obj, 0)], 0, set()
    while stack:
        item, depth = stack.pop()
        if isinstance(item, torch.Tensor):
            if id(item) not in seen:
                seen.add(id(item))
                _check_view(path, item)
            continue
        if not isinstance(item, Mapping | list | tuple):
            continue
        visits += 1
        if depth > MAX_OBJECT_DEPTH or visits > MAX_OBJECT_VISITS:
            raise CheckpointError(f"{path}: the checkpoint's objects nest too deeply or refer to themselves")
        stack.extend((v, depth + 1) for v in (item.values() if isinstance(item, Mapping) else item))


def _check_view(path: Path, t: torch.Tensor) -> None:
    if t.layout != torch.strided or t.device.type == "meta":
        raise CheckpointError(f"{path}: a {t.layout} tensor on {t.device.type}; only dense tensors are weights")
    need, have = t.numel() * t.element_size(), t.untyped_storage().nbytes()
    if need > have:
        raise CheckpointError(
            f"{path}: a tensor of shape {tuple(t.shape)} (stride {t.stride()}) needs {need} bytes but its storage "
            f"holds {have}; refusing an overlapping view"
        )


def verify_digest(path: Path, obj: object, expected: object) -> None:
    """Refuse ``path`` when its objects are out of bounds (:func:`check_tensor_bounds`) or when
    ``expected`` (the stored digest, if any) does not match its tensors."""
    check_tensor_bounds(path, obj)
    if expected is None:
        return
    got = tensor_digest(obj)
    if got != expected:
        raise CheckpointError(
            f"{path}: tensor payload sha256 {got[:16]}... does not match the {expected!s:.16}... recorded at save "
            "time; the file is corrupt, restore or download it again"
        )
