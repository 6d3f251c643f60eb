"""How a model runs, as one value: :class:`EngineSpec` (backend, precision, device, calibration) and its one
:meth:`~EngineSpec.resolve` step.

>>> from semattnet.inference.backends.spec import EngineSpec
>>> spec = EngineSpec(backend="torch", precision="bf16", device="cpu").resolve()
>>> spec.backend, spec.precision, spec.device, spec.autocast
('torch', 'bf16', 'cpu', torch.bfloat16)

Every rule of which engine runs what lives in :meth:`EngineSpec.resolve` and the engine table
(:mod:`~semattnet.inference.backends.registry`): ``device="auto"`` (the backend's first device type when it
cannot run on the best one), ``backend="auto"``, the backend / precision / device agreement, and ``amp`` (the
older name of ``precision``, deprecated: mapped here, with one note).
"""

from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass

import torch

from semattnet._errors import InputError
from semattnet._utils.device import AMP_DTYPES
from semattnet._utils.distributed import process_device
from semattnet.inference.backends.calibration import CalibrationFrames
from semattnet.inference.backends.registry import EngineEntry, choose_backend, engine_entries, get_engine, precisions

__all__ = ["AMP_NOTE", "EngineSpec"]

#: The deprecation note of ``amp`` / ``--amp`` (shown once per process).
AMP_NOTE = "amp (--amp) is deprecated: it is the older name of precision (--precision); give precision instead"


@dataclass(frozen=True)
class EngineSpec:
    """Which engine runs a model, in which arithmetic, where.

    Args:
        backend: an engine's name (:func:`~semattnet.inference.backends.registry.engine_entries`) or ``auto``.
        precision: ``f32``, ``bf16``, ``fp16`` or ``int8`` (what the backend runs); None: ``amp``'s, else f32.
        device: ``auto``, ``cpu``, ``cuda[:N]`` or ``mps``.
        calibration: int8's calibration frames (a folder, a FrameSource or Frames; None: synthetic scenes).
        amp: deprecated, the older name of ``precision`` (``none``, ``bf16`` or ``fp16``).
    """

    backend: str = "torch"
    precision: str | None = None
    device: str | torch.device = "auto"
    calibration: CalibrationFrames = None
    amp: str | None = None

    def resolve(self, fixed_size: bool = True) -> EngineSpec:
        """The spec with every choice made and checked: a concrete backend, precision and device, no ``amp``.

        ``fixed_size``: whether the inputs' size is known when the engine is built (a completer's always is;
        ``backend="auto"`` then may pick an engine compiled for one size).

        Raises:
            InputError: an unknown name, ``precision`` and ``amp`` that disagree, or a backend that does not
                run the precision or the device.
        """
        precision = self._precision()
        backend = self.backend
        if backend != "auto":
            get_engine(backend)  # an unknown name, before the device is looked at
        device = process_device(self.device)
        if backend == "auto":  # choose_backend reads only whether a size is known
            backend = choose_backend(device, (32, 32) if fixed_size else None, precision)
        entry = get_engine(backend)
        if self.device == "auto" and device.type not in entry.devices:
            device = process_device(entry.devices[0])
        _check(entry, precision, device)
        return dataclasses.replace(self, backend=backend, precision=precision, device=str(device), amp=None)

    def _precision(self) -> str:
        """``precision``, or what ``amp`` (the older name, mapped here only) says; one deprecation note."""
        known = precisions()
        if self.precision is not None and self.precision not in known:
            raise InputError(f"unknown precision {self.precision!r}; choose one of {', '.join(known)}")
        if self.amp is None:
            return self.precision or "f32"
        warnings.warn(AMP_NOTE, FutureWarning, stacklevel=3)
        if self.amp not in AMP_DTYPES:
            raise InputError(f"amp must be one of {', '.join(AMP_DTYPES)}, got {self.amp!r}")
        if self.precision is not None and self.amp not in ("none", self.precision):
            raise InputError(
                f"precision {self.precision!r} and amp {self.amp!r} disagree: give one (amp is the older name)"
            )
        return self.precision or ("f32" if self.amp == "none" else self.amp)

    @property
    def entry(self) -> EngineEntry:
        """The backend's entry (a resolved spec's; ``auto`` has none)."""
        return get_engine(self.backend)

    @property
    def autocast(self) -> torch.dtype | None:
        """The autocast dtype a completer runs the ``torch`` engine under (bf16 / fp16), else None: the
        ``torch`` engine runs float32 inside the caller's autocast; the others run their precision themselves."""
        return AMP_DTYPES.get(self.precision or "f32") if self.backend == "torch" else None

    @property
    def engine_precision(self) -> str:
        """The precision the engine itself is built for (``f32`` for ``torch``: see :attr:`autocast`)."""
        return "f32" if self.backend == "torch" else self.precision or "f32"


def _check(entry: EngineEntry, precision: str, device: torch.device) -> None:
    """``entry`` runs ``precision`` on ``device`` (one-line errors naming what to give instead)."""
    if precision not in entry.precisions:
        runners = [e.name for e in engine_entries().values() if precision in e.precisions]
        raise InputError(
            f"precision: the {entry.name} backend runs {', '.join(entry.precisions)}, not {precision!r}; "
            f"{precision} runs on the {' or '.join(runners)} backend"
        )
    if device.type not in entry.devices:
        raise InputError(f"device: the {entry.name} backend runs on {' or '.join(entry.devices)}, got {device}")
