"""The one place where :mod:`semattnet.hub` imports the rest of the package.

The checkpoint, registry, config and atomic-write modules are being moved; when they are, only
the imports below change.
"""

from __future__ import annotations

from .._atomic import atomic_path
from ..checkpoint import (
    Checkpoint,
    CheckpointError,
    UnsafeCheckpointError,
    config_from_state_dict,
    load_checkpoint,
    load_weights,
    save_safetensors,
)
from ..config import SemAttNetConfig
from ..registry import MODELS, build_model


def library_version() -> str:
    """``semattnet.__version__``, imported late so that ``semattnet/__init__`` may import the hub."""
    from .. import __version__

    return __version__


__all__ = [
    "MODELS",
    "Checkpoint",
    "CheckpointError",
    "SemAttNetConfig",
    "UnsafeCheckpointError",
    "atomic_path",
    "build_model",
    "config_from_state_dict",
    "library_version",
    "load_checkpoint",
    "load_weights",
    "save_safetensors",
]
