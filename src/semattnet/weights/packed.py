"""Packed weights: quantised, gzip-compressed safetensors small enough to ship inside the package.

The demo's reference checkpoints (:data:`SHIPPED`) are stored this way, and any model can be
packed with :func:`save_packed`. A packed file is a gzip stream of one safetensors file whose
``__metadata__`` holds ``format`` (:data:`PACKED_FORMAT`), ``config`` (the model config as JSON),
``levels`` and ``info`` (JSON: the recipe, command, machine and scores of whoever made it), and whose
tensors are named by :func:`quantise`:

* ``q8/NAME`` (int8) and ``scale/NAME`` (float32, one per output channel): floating tensors of two or
  more dims, ``w = q * scale`` with ``scale = max|w| / levels`` per output channel;
* ``f16/NAME``: the other floating tensors, as float16;
* ``raw/NAME``: everything else, as is.

:func:`semattnet.weights.load_checkpoint` recognises the gzip magic and reads such a file through
:func:`read_packed` (bounded decompression; no pickle anywhere), so ``load_model``, ``from_pretrained``
and ``--weights`` take packed files and their registry names alike.
"""

from __future__ import annotations

import gzip
import json
import zlib
from collections.abc import Mapping
from pathlib import Path

import torch
from torch import nn

from semattnet._errors import InputError
from semattnet._utils.atomic import atomic_path
from semattnet.models.config import SemAttNetConfig
from semattnet.weights.gate import CheckpointError

__all__ = [
    "GZIP_MAGIC",
    "MAX_UNPACKED_BYTES",
    "PACKED_FORMAT",
    "SHIPPED",
    "dequantise",
    "encode_packed",
    "quantise",
    "read_packed",
    "save_packed",
    "shipped_path",
]

#: The ``format`` a packed file's metadata names (the first packed files were the demo's references).
PACKED_FORMAT = "semattnet-demo-reference/1"
#: The first bytes of every gzip stream.
GZIP_MAGIC = b"\x1f\x8b"
#: A packed file may not unpack to more than this (a gzip bomb stops here, with the file named).
MAX_UNPACKED_BYTES = 256 * 1024 * 1024
#: Packed files shipped inside the package (``semattnet/weights/assets``), by file name.
SHIPPED = Path(__file__).resolve().parent / "assets"


def shipped_path(file_name: str) -> Path:
    """The shipped packed file ``file_name`` (inside the installed package)."""
    return SHIPPED / file_name


def quantise(state_dict: dict[str, torch.Tensor], levels: int = 127) -> dict[str, torch.Tensor]:
    """Per output channel, ``levels`` steps per sign, for floating tensors of >= 2 dims (int8
    ``q8/NAME`` + ``scale/NAME``), float16 for the other floating tensors (``f16/NAME``), the rest
    as is (``raw/NAME``)."""
    out: dict[str, torch.Tensor] = {}
    for name, t in state_dict.items():
        t = t.detach().cpu()
        if t.is_floating_point() and t.dim() >= 2:
            scale = t.float().reshape(t.shape[0], -1).abs().amax(1).clamp_min(1e-12) / float(levels)
            q = torch.round(t.float() / scale.view(-1, *([1] * (t.dim() - 1)))).clamp(-levels, levels)
            out[f"q8/{name}"], out[f"scale/{name}"] = q.to(torch.int8).contiguous(), scale.float()
        elif t.is_floating_point():
            out[f"f16/{name}"] = t.half().contiguous()
        else:
            out[f"raw/{name}"] = t.contiguous()
    return out


def dequantise(tensors: dict[str, torch.Tensor], where: str = "packed weights") -> dict[str, torch.Tensor]:
    """The float32 state dict of :func:`quantise`'s tensors; ``where`` names the file in errors."""
    sd: dict[str, torch.Tensor] = {}
    for key, t in tensors.items():
        kind, _, name = key.partition("/")
        if kind == "q8":
            scale = tensors.get(f"scale/{name}")
            if scale is None or scale.numel() != t.shape[0]:
                raise CheckpointError(f"{where}: tensor {key!r} has no scale of one value per output channel")
            sd[name] = t.float() * scale.float().view(-1, *([1] * (t.dim() - 1)))
        elif kind == "f16":
            sd[name] = t.float()
        elif kind == "raw":
            sd[name] = t
        elif kind != "scale":
            raise CheckpointError(f"{where}: unexpected tensor {key!r} (expected q8/, scale/, f16/ or raw/ names)")
    return sd


def encode_packed(
    state_dict: dict[str, torch.Tensor], config: Mapping[str, object], info: Mapping[str, object], levels: int = 127
) -> bytes:
    """The bytes of a packed file: :func:`quantise`'s tensors with ``config`` and ``info``, gzip-compressed."""
    from safetensors.torch import save

    meta = {"format": PACKED_FORMAT, "config": json.dumps(config), "levels": str(levels), "info": json.dumps(info)}
    return gzip.compress(save(quantise(state_dict, levels), metadata=meta), compresslevel=9, mtime=0)


def save_packed(model: nn.Module, path: str | Path, info: Mapping[str, object], levels: int = 127) -> Path:
    """Write ``model`` (a SemAttNet: its ``config`` and weights) packed at ``levels``, atomically."""
    config = getattr(model, "config", None)
    if not isinstance(config, SemAttNetConfig):
        raise InputError(f"save_packed: the model has no SemAttNetConfig ({type(model).__name__})")
    path = Path(path)
    blob = encode_packed(model.state_dict(), config.to_dict(), info, levels)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        tmp.write_bytes(blob)
    return path


def _gunzip(path: Path) -> bytes:
    """The decompressed bytes, at most :data:`MAX_UNPACKED_BYTES`."""
    unzip = zlib.decompressobj(16 + zlib.MAX_WBITS)
    try:
        raw = unzip.decompress(path.read_bytes(), MAX_UNPACKED_BYTES + 1)
    except zlib.error as exc:
        raise CheckpointError(f"{path}: not a readable packed weights file (gzip: {exc})") from None
    if len(raw) > MAX_UNPACKED_BYTES:
        raise CheckpointError(f"{path}: unpacks to more than {MAX_UNPACKED_BYTES >> 20} MiB; refused")
    if not unzip.eof:
        raise CheckpointError(f"{path}: truncated gzip stream; the file is cut short")
    return raw


def read_packed(path: str | Path) -> tuple[dict[str, torch.Tensor], dict[str, str]]:
    """The float32 state dict and the metadata of a packed file.

    Raises:
        CheckpointError: one line naming the file: not gzip, truncated, too large unpacked, not
            safetensors inside, or not written by :func:`save_packed`.
    """
    from safetensors import SafetensorError
    from safetensors.torch import load

    path = Path(path)
    raw = _gunzip(path)
    n = int.from_bytes(raw[:8], "little")
    if len(raw) < 8 or n > len(raw) - 8:
        raise CheckpointError(f"{path}: gzip of something that is not safetensors (header length past the end)")
    try:
        meta = json.loads(raw[8 : 8 + n]).get("__metadata__") or {}
        tensors = load(raw)
    except (SafetensorError, ValueError, AttributeError) as exc:
        raise CheckpointError(f"{path}: gzip of something that is not safetensors ({exc})") from None
    if meta.get("format") != PACKED_FORMAT:
        raise CheckpointError(
            f"{path}: a gzip'd safetensors file, but not packed weights "
            f"(format {meta.get('format')!r}, expected {PACKED_FORMAT!r})"
        )
    return dequantise(tensors, str(path)), meta
