"""Reading and writing weights: the authors' ``.pth.tar``, plain state dicts, safetensors.

Every file passes :mod:`semattnet.weights.gate` first (format from the bytes, structure, CRCs,
TorchScript refused); torch pickles are then read by ``torch.load(weights_only=True)`` with an
allow-list built from the globals the pickle names.

The authors' released checkpoints are torch pickles of a dict with ``model`` (the state dict),
``epoch``, ``best_result`` (an object of their ``metrics.Result`` class), ``optimizer`` and
``args`` (an ``argparse.Namespace``). :func:`load_checkpoint` reads them *without executing
pickled code* (see :mod:`semattnet.weights._safe_pickle`): their classes become inert records and a
checkpoint that names e.g. ``os.system`` is refused. :func:`load_weights` loads a state dict into
a model and names every missing, unexpected or mis-shaped key.
"""

from __future__ import annotations

import errno
import json
import os
import pickle
import threading
import warnings
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
from torch import nn

from semattnet._errors import SemAttNetError
from semattnet._utils.atomic import atomic_path, disk_full_error
from semattnet._utils.documents import loads_json
from semattnet.models.config import SemAttNetConfig
from semattnet.weights._safe_pickle import (
    InertObject,
    UnsafeCheckpointError,
    describe_torch_refusal,
    resolve_global,
    safe_pickle_module,
)
from semattnet.weights.gate import (
    DIGEST_KEY,
    CheckpointError,
    Inspected,
    inspect_weights_file,
    tensor_digest,
    verify_digest,
)

__all__ = [
    "Checkpoint",
    "CheckpointError",
    "StateDictMismatchError",
    "UnsafeCheckpointError",
    "config_from_state_dict",
    "filter_state_dict",
    "load_checkpoint",
    "load_weights",
    "save_safetensors",
]


class StateDictMismatchError(SemAttNetError):
    """Keys or shapes of a state dict do not match the model."""


@dataclass
class Checkpoint:
    """Weights and whatever metadata the file carried.

    Attributes:
        path: the file read.
        state_dict: parameter and buffer tensors by name (a ``module.`` prefix is removed).
        format: ``"torch"`` (a pickled dict with a ``model``/``state_dict`` entry), ``"state_dict"``
            (a pickled plain state dict), ``"safetensors"`` or ``"packed"`` (:mod:`semattnet.weights.packed`).
        epoch: training epoch if recorded.
        args: the training arguments (authors' ``argparse.Namespace``) as a dict, if recorded.
        best_result: the authors' best validation result, as an inert record, if recorded.
        config: our model config if the file records one.
        extra: any other top-level entries (e.g. ``optimizer``).
        neutralised: qualified names of pickled classes that were replaced by inert records.
    """

    path: Path
    state_dict: dict[str, torch.Tensor]
    format: str
    epoch: int | None = None
    args: dict[str, object] | None = None
    best_result: object = None
    config: SemAttNetConfig | None = None
    extra: dict[str, Any] = field(default_factory=dict)  # whatever the file's top level holds besides weights
    neutralised: set[str] = field(default_factory=set)


#: Key prefixes removed from every state dict read (``module.``: saved from DataParallel / DDP).
KEY_PREFIXES = ("module.",)


def filter_state_dict(sd: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """The one place key renames happen: a prefix of :data:`KEY_PREFIXES` shared by every key is removed.

    Applied by :func:`load_checkpoint`, :func:`load_weights` and :func:`config_from_state_dict`.
    """
    for prefix in KEY_PREFIXES:
        if sd and all(k.startswith(prefix) for k in sd):
            return {k[len(prefix) :]: v for k, v in sd.items()}
    return dict(sd)


def _config_from_metadata(raw: object, path: Path) -> SemAttNetConfig | None:
    if raw is None:
        return None
    if not isinstance(raw, str | Mapping):
        raise CheckpointError(f"{path}: invalid model config in checkpoint: a {type(raw).__name__}")
    try:
        data = json.loads(raw) if isinstance(raw, str) else dict(raw)
        if "kernel_sizes" in data:
            data["kernel_sizes"] = tuple(data["kernel_sizes"])
        return SemAttNetConfig(**data)
    except (TypeError, ValueError) as exc:
        raise CheckpointError(f"{path}: invalid model config in checkpoint: {exc}") from exc


def _load_safetensors(path: Path) -> Checkpoint:
    from safetensors import SafetensorError, safe_open

    try:
        with safe_open(str(path), framework="pt", device="cpu") as f:
            meta = f.metadata() or {}
            sd = {k: f.get_tensor(k) for k in f.keys()}
    except (SafetensorError, OSError, ValueError) as exc:
        raise CheckpointError(f"{path}: not a readable safetensors file ({exc})") from exc
    verify_digest(path, sd, meta.get(DIGEST_KEY))
    epoch = meta.get("epoch")
    return Checkpoint(
        path=path,
        state_dict=sd,
        format="safetensors",
        epoch=int(epoch) if epoch not in (None, "") else None,
        args=json.loads(meta["args"]) if "args" in meta else None,
        config=_config_from_metadata(meta.get("config"), path),
        extra={k: v for k, v in meta.items() if k not in ("epoch", "args", "config", DIGEST_KEY)},
    )


def _load_packed(path: Path) -> Checkpoint:
    """A packed file (:mod:`semattnet.weights.packed`): dequantised weights, its config and record."""
    from semattnet.weights.packed import read_packed

    sd, meta = read_packed(path)
    info = loads_json(meta.get("info", "{}"), f"{path} (packed metadata 'info')", error=CheckpointError)
    return Checkpoint(
        path=path,
        state_dict=sd,
        format="packed",
        config=_config_from_metadata(meta.get("config"), path),
        extra={"info": info, "levels": meta.get("levels")},
    )


_SAFE_GLOBALS_LOCK = threading.Lock()  # torch's safe-globals list is process-wide


def _allow_list(info: Inspected) -> tuple[list[Any], set[str]]:
    """``(object, "module.name")`` pairs for ``torch.serialization.safe_globals`` from the policy of
    :func:`~semattnet.weights._safe_pickle.resolve_global`; raises on a code-running name."""
    neutralised: set[str] = set()
    pairs = []
    for full in sorted(info.globals - {"<stack global>"}):
        module, _, name = full.rpartition(".")
        pairs.append((resolve_global(module, name, neutralised), full))
    if any(full.startswith("numpy") for full in info.globals):  # a NumPy array (e.g. the RNG state) is built
        import numpy as np  # by its dtype's class, which torch wants allow-listed too

        pairs += [(cls, f"numpy.dtypes.{cls.__name__}") for cls in {type(np.dtype(c)) for c in "?bBhHiIlLqQefdFD"}]
    return pairs, neutralised


def _load_pickle(info: Inspected) -> tuple[object, set[str]]:
    """Unpickle a torch file the gate accepted: ``weights_only=True`` with our allow-list for
    pickle protocols it supports (<= 3, what torch.save writes), else the safe unpickler."""
    if info.protocol <= 3:
        pairs, neutralised = _allow_list(info)
        with _SAFE_GLOBALS_LOCK, torch.serialization.safe_globals(pairs), warnings.catch_warnings():
            warnings.simplefilter("ignore")  # torch's advice to re-run with weights_only=False
            try:
                return torch.load(info.path, map_location="cpu", weights_only=True), neutralised
            except pickle.UnpicklingError as exc:  # never relay torch's advice to use weights_only=False
                raise UnsafeCheckpointError(describe_torch_refusal(exc)) from None
    module, neutralised = safe_pickle_module()
    return torch.load(info.path, map_location="cpu", pickle_module=module, weights_only=False), neutralised


def load_checkpoint(path: str | os.PathLike[str]) -> Checkpoint:
    """Read weights from an authors' ``.pth.tar``, a saved state dict or a ``.safetensors`` file.

    The file first passes :func:`~semattnet.weights.gate.inspect_weights_file` (format from the
    bytes, structure, CRCs, no TorchScript); a recorded tensor sha256 is verified after loading.
    Never executes code from the file: see the module docstring. Tensors are loaded on CPU.

    Raises:
        CheckpointError: missing, truncated or corrupt file, or no state dict inside.
        UnsafeCheckpointError: a TorchScript archive, or a pickle that references a code-executing callable.
    """
    path = Path(path)
    try:
        info = inspect_weights_file(path)
        if info.format == "safetensors":
            return _load_safetensors(path)
        if info.format == "packed":
            return _load_packed(path)
        obj, neutralised = _load_pickle(info)
    except UnsafeCheckpointError as exc:
        msg = str(exc)
        raise UnsafeCheckpointError(msg if msg.startswith(str(path)) else f"{path}: {msg}") from None
    except CheckpointError:
        raise
    except (
        RuntimeError,
        pickle.UnpicklingError,
        EOFError,
        OSError,
        ValueError,
        KeyError,
        TypeError,
        AttributeError,
        zipfile.BadZipFile,
    ) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise CheckpointError(f"{path}: not a readable PyTorch checkpoint (truncated or corrupt?): {first}") from None
    if isinstance(obj, Mapping):
        verify_digest(path, obj, obj.get(DIGEST_KEY))
    return _checkpoint_from_object(obj, path, neutralised)


def _checkpoint_from_object(obj: object, path: Path, neutralised: set[str]) -> Checkpoint:
    if isinstance(obj, Mapping) and obj and all(isinstance(v, torch.Tensor) for v in obj.values()):
        return Checkpoint(path=path, state_dict=filter_state_dict(obj), format="state_dict", neutralised=neutralised)
    if not isinstance(obj, Mapping):
        raise CheckpointError(f"{path}: expected a dict of tensors or a checkpoint dict, got {type(obj).__name__}")
    key = next((k for k in ("model", "state_dict", "model_state") if isinstance(obj.get(k), Mapping)), None)
    if key is None:
        raise CheckpointError(f"{path}: no state dict found (looked for 'model', 'state_dict'); keys: {list(obj)}")
    sd = obj[key]
    bad = [k for k, v in sd.items() if not isinstance(v, torch.Tensor)]
    if bad:
        raise CheckpointError(f"{path}: entry {key!r} holds non-tensors, e.g. {bad[:3]}")
    args = obj.get("args")
    if args is not None and not isinstance(args, Mapping):
        args = dict(vars(args)) if hasattr(args, "__dict__") else {"value": args}
    epoch = obj.get("epoch")
    return Checkpoint(
        path=path,
        state_dict=filter_state_dict(sd),
        format="torch",
        epoch=int(epoch) if isinstance(epoch, int) else None,
        args=dict(args) if args is not None else None,
        best_result=obj.get("best_result"),
        config=_config_from_metadata(obj.get("config"), path),
        extra={k: v for k, v in obj.items() if k not in (key, "epoch", "args", "best_result", "config", DIGEST_KEY)},
        neutralised=neutralised,
    )


def load_weights(model: nn.Module, state_dict: Mapping[str, torch.Tensor] | Checkpoint, strict: bool = True) -> dict:
    """Load ``state_dict`` into ``model``, reporting every mismatch by name.

    Args:
        model: the target.
        state_dict: tensors by name, or a :class:`Checkpoint`.
        strict: raise on any missing, unexpected or mis-shaped key (default). Otherwise load
            the matching entries and return what was skipped.

    Returns:
        ``{"missing": [...], "unexpected": [...], "mismatched": [...]}``.

    Raises:
        StateDictMismatchError: with ``strict`` and any mismatch; the message names the keys.
    """
    source = state_dict.path if isinstance(state_dict, Checkpoint) else "state dict"
    sd = filter_state_dict(state_dict.state_dict if isinstance(state_dict, Checkpoint) else state_dict)
    upgrade = getattr(model, "upgrade_state_dict", None)  # a model that reads its older files (the generalist)
    if callable(upgrade):
        sd = upgrade(sd)
    own = model.state_dict()
    missing = [k for k in own if k not in sd]
    unexpected = [k for k in sd if k not in own]
    mismatched = [
        f"{k}: checkpoint {tuple(sd[k].shape)} vs model {tuple(own[k].shape)}"
        for k in own
        if k in sd and sd[k].shape != own[k].shape
    ]
    kind = {k: (v.is_floating_point(), v.is_complex(), v.dtype == torch.bool) for k, v in own.items()}
    retyped = [  # e.g. a safetensors F32 tensor relabelled I32: its bytes would load as huge floats
        f"{k}: checkpoint {sd[k].dtype} vs model {own[k].dtype}"
        for k in own
        if k in sd and (sd[k].is_floating_point(), sd[k].is_complex(), sd[k].dtype == torch.bool) != kind[k]
    ]
    mismatched += retyped
    report = {"missing": missing, "unexpected": unexpected, "mismatched": mismatched}
    if strict and (missing or unexpected or mismatched):
        parts = []
        shapes = mismatched[: len(mismatched) - len(retyped)]
        for label, items in (
            ("missing", missing),
            ("unexpected", unexpected),
            ("shape mismatch", shapes),
            ("dtype mismatch", retyped),
        ):
            if items:
                shown = ", ".join(items[:8]) + (f", ... ({len(items) - 8} more)" if len(items) > 8 else "")
                parts.append(f"{len(items)} {label}: {shown}")
        hint = ""
        if missing and all(("backbone." + k) in own for k in sd):
            hint = " (this is a backbone checkpoint: load it into model.backbone)"
        raise StateDictMismatchError(f"{source} does not fit the model: " + "; ".join(parts) + hint)
    skip = {m.split(":")[0] for m in mismatched}
    model.load_state_dict({k: v for k, v in sd.items() if k in own and k not in skip}, strict=strict)
    return report


def config_from_state_dict(
    sd: Mapping[str, torch.Tensor], source: str | os.PathLike[str] | None = None
) -> SemAttNetConfig:
    """Infer the architecture of a SemAttNet state dict (ours or the authors'); ``source`` (the file) starts
    the message of a :class:`CheckpointError`."""
    where = f"{source}: " if source is not None else ""
    sd = filter_state_dict(sd)
    refine = any(k.startswith("backbone.") for k in sd)
    bb = {k.removeprefix("backbone."): v for k, v in sd.items() if not refine or k.startswith("backbone.")}
    need = ["rgb_conv_init.0.weight"]
    need += [] if "cbam_192.ChannelGate.mlp.1.weight" in bb else ["depth_layer3.conv1.weight"]
    absent = [k for k in need if k not in bb or bb[k].dim() < 2]
    if absent:
        raise CheckpointError(f"{where}not a SemAttNet state dict: no {absent[0]} ({len(sd)} tensors)")
    base = bb["rgb_conv_init.0.weight"].shape[0]
    branches = 3 if "segment_conv_init.0.weight" in bb else 2
    if "cbam_192.ChannelGate.mlp.1.weight" in bb:
        fusion = "sammafb"
    else:
        fusion = "add" if bb["depth_layer3.conv1.weight"].shape[1] == 2 * base else "concat"
    kernel_sizes = tuple(
        sorted(
            int(k.split(".")[0].removeprefix("iter_guide_layer"))
            for k in sd
            if k.endswith("generate.0.weight") and k.split(".")[0].removeprefix("iter_guide_layer").isdigit()
        )
    )
    try:  # sizes read from the tensors are held to the config's ranges
        cfg = SemAttNetConfig(branches=branches, fusion=fusion, refine=refine, width=base / 32)  # type: ignore[arg-type]
        return cfg.replace(kernel_sizes=kernel_sizes) if kernel_sizes else cfg
    except ValueError as exc:
        raise CheckpointError(f"{where}not a SemAttNet state dict that can be built: {exc}") from None


def _json_default(o: object) -> object:
    if isinstance(o, InertObject):
        return {k: v for k, v in vars(o).items() if not k.startswith("_")}
    return str(o)


def save_safetensors(ckpt: Checkpoint | Mapping[str, torch.Tensor], path: str | os.PathLike[str]) -> Path:
    """Write weights (and epoch/args/config metadata) as safetensors, atomically."""
    from safetensors.torch import save_file

    path = Path(path)
    if isinstance(ckpt, Checkpoint):
        sd, meta = ckpt.state_dict, {"source": ckpt.path.name}
        if ckpt.epoch is not None:
            meta["epoch"] = str(ckpt.epoch)
        if ckpt.args is not None:
            meta["args"] = json.dumps(ckpt.args, default=_json_default, sort_keys=True)
        cfg = ckpt.config or config_from_state_dict(sd, ckpt.path)
    else:
        sd, meta, cfg = dict(ckpt), {}, config_from_state_dict(ckpt)
    meta["config"] = json.dumps(cfg.to_dict())
    meta["format"] = "semattnet"
    tensors = {k: v.detach().contiguous() for k, v in sd.items()}
    meta[DIGEST_KEY] = tensor_digest(tensors)  # verified by load_checkpoint: catches corrupt tensor bytes
    with atomic_path(path) as tmp:
        try:
            save_file(tensors, str(tmp), metadata=meta)
        except Exception as exc:  # safetensors reports I/O errors as its own SafetensorError
            if "os error 28" in str(exc) or "No space left" in str(exc):
                raise disk_full_error(path, sum(t.numel() * t.element_size() for t in tensors.values())) from None
            if isinstance(exc, OSError) or "I/O error" not in str(exc):
                raise
            raise OSError(errno.EIO, f"could not write the file: {exc}", str(path)) from None
    return path
