"""The inference engines as one table: each backend module declares its :class:`EngineEntry`.

An entry says what the engine is (its name, the precisions and device types it runs, the package it needs,
whether it compiles for one input size) and how it is built from a model (:class:`EngineRequest`). The
table loads its own entries (:data:`ENGINE_MODULES`) the first time it is read, so ``--backend``'s choices,
``backend="auto"`` and :func:`~semattnet.inference.backends.optimize_for_inference` all read one table.

A new engine is one module that calls :func:`register_engine` (a built-in one also has its line in
:data:`ENGINE_MODULES`; a plugin's module is imported before the table is read)::

    register_engine(EngineEntry("myengine", precisions=("f32",), devices=("cpu",), build=MyEngine.build))
"""

from __future__ import annotations

import importlib
import importlib.util
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType

import torch
from torch import nn

from semattnet._errors import InputError
from semattnet._utils.extras import install_hint
from semattnet._utils.registry import DuplicateEntryError, Registry, UnknownEntryError
from semattnet.inference.backends._base import InferenceEngine, LogFn
from semattnet.inference.backends.calibration import DEFAULT_CALIBRATION_FRAMES, CalibrationFrames

__all__ = [
    "ENGINES",
    "ENGINE_MODULES",
    "EngineEntry",
    "EngineRequest",
    "choose_backend",
    "engine_entries",
    "get_engine",
    "precisions",
    "register_engine",
]

#: The modules of :mod:`semattnet.inference.backends` that declare the built-in engines (each its ``ENTRY``), in the
#: table's order.
ENGINE_MODULES: tuple[str, ...] = ("torch_engine", "openvino_engine", "onnxruntime_engine", "tensorrt_engine")


@dataclass(frozen=True)
class EngineRequest:
    """What an entry's ``build`` gets besides the model (eval mode, on the CPU or already on ``device``).

    ``outputs``: the fields of :class:`~semattnet.models.outputs.DepthCompletionOutput` the caller reads (None: all);
    an engine may compute only those (the others None; :func:`~semattnet.inference.backends._base.graph_outputs`
    says which graph outputs they need) or ignore it and return them all."""

    size: tuple[int, int] | None
    precision: str
    device: torch.device
    needs_semantic: bool
    cache_dir: str | os.PathLike[str] | None = None
    log: LogFn | None = None
    inplace: bool = False
    calibration: CalibrationFrames = None
    calibration_frames: int = DEFAULT_CALIBRATION_FRAMES
    compile_propagation: bool | None = None
    outputs: frozenset[str] | None = None

    def fixed_size(self) -> tuple[int, int]:
        """``size``, which an engine compiled for one size needs (optimize_for_inference checks it first)."""
        if self.size is None:
            raise InputError("size: this engine compiles for one input size: pass size=(H, W)")
        return self.size


#: How an entry builds its engine.
EngineBuilder = Callable[[nn.Module, EngineRequest], InferenceEngine]


@dataclass(frozen=True)
class EngineEntry:
    """One inference engine.

    Args:
        name: the ``--backend`` / ``backend=`` name.
        precisions: the precisions it runs (the first is its default).
        devices: the device types it runs on (``cpu``, ``cuda``, ``mps``).
        build: ``build(model, request) -> InferenceEngine``.
        package: the module it imports (its install hint names the extra), or None (torch only).
        fixed_size: compiled for one input size (``size=`` required; one engine per size).
        auto: a candidate of ``backend="auto"``.
        summary: one line for ``--help`` and the docs.
    """

    name: str
    precisions: tuple[str, ...]
    devices: tuple[str, ...]
    build: EngineBuilder
    package: str | None = None
    fixed_size: bool = False
    auto: bool = False
    summary: str = ""

    def installed(self) -> bool:
        """Whether its package can be imported (torch-only engines always)."""
        return self.package is None or importlib.util.find_spec(self.package) is not None

    def install_hint(self) -> str:
        """``pip install 'semattnet[EXTRA]'`` for its package ('' when it needs none)."""
        return "" if self.package is None else install_hint(self.package)

    def runs(self, precision: str, device_type: str) -> bool:
        """Whether it runs ``precision`` on a device of ``device_type``."""
        return precision in self.precisions and device_type in self.devices


def _home_of(entry: EngineEntry) -> str:
    return getattr(entry.build, "__module__", "")


#: Engine name -> :class:`EngineEntry`: the built-in engines first (:data:`ENGINE_MODULES`' order, their modules
#: imported on first read), then those registered elsewhere.
ENGINES: Registry[EngineEntry] = Registry(
    "backend", homes=tuple(f"{__package__}.{m}" for m in ENGINE_MODULES), home_of=_home_of
)


def register_engine(entry: EngineEntry) -> EngineEntry:
    """Add ``entry`` to :data:`ENGINES` (a second entry of one name, or one named ``auto``, is refused); gives
    ``entry``."""
    if entry.name == "auto":
        raise DuplicateEntryError("backend 'auto' names the choice among engines: an engine cannot take it")
    return ENGINES.add(entry.name, entry)


def unregister_engine(name: str) -> None:
    """Remove engine ``name`` from :data:`ENGINES` (a plugin's or a test's own)."""
    ENGINES.remove(name)


def engine_entries() -> Mapping[str, EngineEntry]:
    """Every engine by name (:data:`ENGINES`), installed or not."""
    return MappingProxyType({name: ENGINES[name] for name in ENGINES})


def get_engine(name: str) -> EngineEntry:
    """The entry of backend ``name``; an unknown name is one :class:`UnknownEntryError` line listing the choices."""
    if name in ENGINES:
        return ENGINES[name]
    raise UnknownEntryError(f"unknown backend {name!r}; choose one of auto, {', '.join(ENGINES)}")


def precisions() -> tuple[str, ...]:
    """Every precision some engine runs, in the order the entries name them."""
    return tuple(dict.fromkeys(p for e in engine_entries().values() for p in e.precisions))


def choose_backend(
    device: torch.device | str = "cpu", size: tuple[int, int] | None = None, precision: str = "f32"
) -> str:
    """What ``backend="auto"`` picks: an ``auto`` entry that is installed and runs ``precision`` on ``device``,
    those compiled for one size first when ``size`` is known (they are faster at it), else in the table's order:
    OpenVINO for CPU inference at one size, else torch. A precision no such entry runs (int8) goes to the first
    entry that runs it at all."""
    kind = torch.device(device).type
    entries = list(engine_entries().values())
    for entry in sorted(entries, key=lambda e: not e.fixed_size):
        if (
            entry.auto
            and entry.runs(precision, kind)
            and entry.installed()
            and (size is not None or not entry.fixed_size)
        ):
            return entry.name
    runners = [e.name for e in entries if precision in e.precisions]
    return runners[0] if runners else "torch"
