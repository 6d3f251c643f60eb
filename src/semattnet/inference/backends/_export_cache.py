"""The on-disk cache of exported models: one ONNX file per (weights, architecture, size, versions).

Exporting the full model to ONNX takes minutes; converting it takes seconds. Both happen once:
the key is the sha256 of the weights (:func:`semattnet.weights.gate.tensor_digest`), the
architecture config, the input size and the versions of torch and semattnet, so changed weights
or a new release never reuse a stale file. Files are written atomically, so a killed export leaves
nothing that a later run could mistake for a finished one.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import torch
from torch import nn

from semattnet._utils.version import library_version
from semattnet.inference.backends._base import LogFn
from semattnet.weights.download import get_cache_dir
from semattnet.weights.export import export_onnx
from semattnet.weights.gate import tensor_digest

__all__ = ["cached_onnx", "engine_dir", "engine_key", "propagation_steps"]


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
        "graph": "network-without-propagation",  # the export form: a new form never reuses old files
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
    engines finish it with the fused kernel (:func:`propagation_steps` steps per kernel size),
    several times faster than the same steps as hundreds of small graph operations.
    """
    path = folder / "model.onnx"
    if not path.is_file():
        if log is not None:
            log(f"exporting the model to ONNX at {size[0]}x{size[1]} (once; cached in {folder}) ...")
        export_onnx(model, path, size=size, propagation=False)
    return path


def propagation_steps(model: nn.Module) -> int | None:
    """Propagation steps per kernel size of a refining model (what its engine runs after the graph), else None."""
    config = getattr(model, "config", None)
    return config.iterations if config is not None and config.refine else None
