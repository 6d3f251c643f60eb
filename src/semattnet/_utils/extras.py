"""The one way semattnet needs an optional package: :func:`require` (or :func:`optional` for a fallback).

Every feature whose package is not installed fails the same way: one
:class:`~semattnet._errors.MissingDependencyError` line naming the feature, the package and the
``pip install 'semattnet[EXTRA]'`` that provides it (the CLI prints it and exits 1). :data:`EXTRAS`
is the one table of which extra installs which module; ``pyproject.toml`` lists the same packages.
This module is the only place in ``src/`` that catches an ``ImportError`` (a test enforces it).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from types import MappingProxyType, ModuleType
from typing import TypeVar

from semattnet._errors import MissingDependencyError

__all__ = ["EXTRAS", "call_with_newer", "install_hint", "optional", "require"]

_T = TypeVar("_T")

#: Top-level module -> (the package to install, the extra of semattnet that installs it; "" for a package no
#: extra provides: a core dependency missing from a broken install, or one semattnet never installs).
EXTRAS: Mapping[str, tuple[str, str]] = MappingProxyType(
    {
        "huggingface_hub": ("huggingface_hub", "hub"),
        "pooch": ("pooch", "hub"),
        "gdown": ("gdown", "hub"),
        "onnx": ("onnx", "onnx"),
        "onnxruntime": ("onnxruntime", "onnx"),
        "openvino": ("openvino", "openvino"),
        "nncf": ("nncf", "openvino"),
        "transformers": ("transformers", "segment"),
        "rosbags": ("rosbags", "ros"),
        "cyclonedds": ("cyclonedds", "ros2"),
        "rerun": ("rerun-sdk", "rerun"),
        "foxglove": ("foxglove-sdk", "live"),
        "h5py": ("h5py", "nyu"),
        "plotly": ("plotly", ""),
        "torch_tensorrt": ("torch-tensorrt", "tensorrt"),
        "tensorboard": ("tensorboard", "tensorboard"),
        "yaml": ("pyyaml", ""),
        "plyfile": ("plyfile", ""),
        "torchvision": ("torchvision", ""),
    }
)


def install_hint(module: str) -> str:
    """``pip install 'semattnet[EXTRA]'`` for ``module`` (its top-level name decides), else ``pip install PKG``."""
    top = module.split(".")[0]
    package, extra = EXTRAS.get(top, (top, ""))
    return f"pip install 'semattnet[{extra}]'" if extra else f"pip install {package}"


def optional(module: str) -> ModuleType | None:
    """``module`` if it can be imported, else ``None``: for a feature with a fallback (e.g. pooch when
    huggingface_hub is absent, no TensorBoard log without tensorboard)."""
    try:
        return importlib.import_module(module)
    except ImportError:
        return None


def require(module: str, feature: str) -> ModuleType:
    """``module`` imported, or a one-line :class:`MissingDependencyError`: "FEATURE needs PACKAGE: pip install ...".

    Args:
        module: what to import, e.g. ``"huggingface_hub"`` or ``"rosbags.rosbag2"``.
        feature: what needs it, in a few words starting the message (e.g. ``"hf:// URLs"``, ``"--live"``).
    """
    found = optional(module)
    if found is not None:
        return found
    top = module.split(".")[0]
    package = EXTRAS.get(top, (top, ""))[0]
    raise MissingDependencyError(f"{feature} needs the optional package {package!r}: {install_hint(module)}", name=top)


def call_with_newer(fn: Callable[..., _T], newer: Mapping[str, object], /, *args: object, **kwargs: object) -> _T:
    """``fn(*args, **kwargs, **newer)``, or without ``newer`` (keywords that older releases of an optional package
    lack) when ``fn`` refuses one of them as an unexpected keyword: a call that binds its arguments first fails
    before doing anything, so the second call is the only one that runs."""
    try:
        return fn(*args, **kwargs, **newer)
    except TypeError as exc:
        if not any(f"keyword argument '{k}'" in str(exc) for k in newer):
            raise
    return fn(*args, **kwargs)
