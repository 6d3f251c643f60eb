"""The on-disk cache of exported models: one ONNX file per (weights, architecture, size, versions).

Exporting the full model to ONNX takes minutes; converting it takes seconds. Both happen once:
the key is the sha256 of the weights (:func:`semattnet.weights.gate.tensor_digest`), the
architecture config, the input size and the versions of torch and semattnet, so changed weights
or a new release never reuse a stale file. Files are written atomically, so a killed export leaves
nothing that a later run could mistake for a finished one.

The cache is verified, not trusted: each file written is recorded with its sha256 beside it
(``model.onnx.sha256``), and checked before every use (:func:`intact`). A file that does not match its
record (damaged on disk, edited, truncated) or has none (written by an older release, or by hand) is
removed and built again, with one line saying so (the engine's ``log``, else stderr).
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
from pathlib import Path

import torch
from torch import nn

from semattnet._utils.atomic import atomic_path
from semattnet._utils.version import library_version
from semattnet.cache import get_cache_dir, sha256_file
from semattnet.inference.backends._base import LogFn
from semattnet.models.refinement import PropagationSettings
from semattnet.weights.export import export_onnx
from semattnet.weights.gate import tensor_digest

__all__ = ["cached_onnx", "engine_dir", "engine_key", "intact", "propagation_settings", "record_digest"]


def engine_key(model: nn.Module, size: tuple[int, int], extra: str = "") -> str:
    """A short hex key naming this model's weights and config at ``size`` (and ``extra``, e.g. a version)."""
    config = getattr(model, "config", None)
    facts = {
        "weights": tensor_digest(model.state_dict()),
        "config": config.to_dict() if config is not None else type(model).__name__,
        "size": list(size),
        "torch": torch.__version__,
        "semattnet": library_version(),
        "extra": extra,
        "graph": "network-without-propagation/v4-tap-lists",  # the export form: a new form never reuses old files
    }
    return hashlib.sha256(json.dumps(facts, sort_keys=True).encode()).hexdigest()[:24]


def engine_dir(key: str, cache_dir: str | os.PathLike[str] | None = None) -> Path:
    """``<cache>/engines/<key>/`` (created)."""
    path = get_cache_dir(cache_dir) / "engines" / key
    path.mkdir(parents=True, exist_ok=True)
    return path


def cached_onnx(model: nn.Module, size: tuple[int, int], folder: Path, log: LogFn | None = None) -> Path:
    """``folder/model.onnx``, exported (BatchNorm folded) unless it is already there.

    The graph stops before the CSPN++ propagation (``export_onnx(propagation=False)``): the
    engines finish it with the fused kernel (:func:`propagation_settings`),
    several times faster than the same steps as hundreds of small graph operations.
    """
    path = folder / "model.onnx"
    if not intact(path, log):
        if log is not None:
            log(f"exporting the model to ONNX at {size[0]}x{size[1]} (once; cached in {folder}) ...")
        export_onnx(model, path, size=size, propagation=False)
        record_digest(path)
    return path


def _record(path: Path) -> Path:
    return path.with_name(f"{path.name}.sha256")


def record_digest(path: Path) -> None:
    """Record ``path``'s sha256 beside it (``NAME.sha256``, written atomically) for :func:`intact`."""
    with atomic_path(_record(path)) as tmp:
        tmp.write_text(f"{sha256_file(path)}\n")


def intact(path: Path, log: LogFn | None = None) -> bool:
    """Whether the cached file ``path`` is there and matches its recorded sha256. A file without a record,
    or not matching it, is removed (with its record) and one line says so: the caller builds it again."""
    record = _record(path)
    if not path.is_file():
        record.unlink(missing_ok=True)
        return False
    try:
        want: str | None = record.read_text().strip()
    except (OSError, UnicodeDecodeError):
        want = None
    if want is not None and want == sha256_file(path):
        return True
    why = "has no recorded sha256" if want is None else "does not match its recorded sha256"
    (log or _stderr)(f"{path}: the cached file {why}: building it again")
    path.unlink(missing_ok=True)
    record.unlink(missing_ok=True)
    return False


def _stderr(line: str) -> None:
    print(line, file=sys.stderr)


def propagation_settings(model: nn.Module) -> PropagationSettings | None:
    """What a refining model's engine runs after the graph (steps per kernel size, kernel sizes), else None."""
    config = getattr(model, "config", None)
    if config is None or not config.refine:
        return None
    return PropagationSettings(int(config.iterations), tuple(int(k) for k in config.kernel_sizes), config.affinity)
