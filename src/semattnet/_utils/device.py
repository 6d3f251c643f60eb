"""Devices and number formats: ``--device auto|cpu|cuda[:N]``, ``--amp none|bf16|fp16``, clocks.

The one home of the device rules every command shares: which device ``auto`` means, which
autocast type each ``--amp`` name selects, and how to wait for queued GPU work before reading a
clock.
"""

from __future__ import annotations

import contextlib
import time

import torch

from semattnet._errors import InputError

__all__ = ["AMP_DTYPES", "DEVICE_TYPES", "amp_dtype", "autocast", "now", "resolve_device", "synchronize"]

#: ``--amp`` names and the autocast type each selects (``none``: float32, no autocast).
AMP_DTYPES: dict[str, torch.dtype | None] = {"none": None, "bf16": torch.bfloat16, "fp16": torch.float16}


#: Device types a model can run on here (``meta`` holds no data; others are not supported).
DEVICE_TYPES = ("cpu", "cuda", "mps")


def resolve_device(name: str | torch.device = "auto") -> torch.device:
    """``auto`` -> CUDA if available, else CPU; anything else as given, checked for availability.

    Raises:
        InputError: a name torch does not parse (``foo``, ``cuda:abc``), a type not in :data:`DEVICE_TYPES`
            (``meta``), or a device that is not available (no CUDA, ``cuda:7`` on a one-GPU machine).
    """
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        device = name if isinstance(name, torch.device) else torch.device(str(name))
    except (RuntimeError, ValueError, TypeError):
        raise InputError(f"device {str(name)[:40]!r} is not a device name; use auto, cpu, cuda or cuda:N") from None
    if device.type not in DEVICE_TYPES:
        raise InputError(f"device {str(name)[:40]!r}: type {device.type!r} cannot run a model; use auto, cpu or cuda")
    if device.type == "cuda" and not torch.cuda.is_available():
        raise InputError(f"device {name!r} requested but CUDA is not available; use --device cpu or auto")
    if device.type == "cuda" and device.index is not None and device.index >= torch.cuda.device_count():
        raise InputError(f"device {name!r}: this machine has {torch.cuda.device_count()} CUDA device(s)")
    if device.type == "mps" and not (hasattr(torch.backends, "mps") and torch.backends.mps.is_available()):
        raise InputError(f"device {name!r} requested but MPS is not available; use --device cpu or auto")
    return device


def amp_dtype(amp: str) -> torch.dtype | None:
    """The autocast dtype for an ``--amp`` name (``None`` for ``none``).

    >>> amp_dtype("bf16")
    torch.bfloat16
    >>> amp_dtype("none") is None
    True
    """
    if amp not in AMP_DTYPES:
        raise InputError(f"amp must be one of {sorted(AMP_DTYPES)}, got {amp!r}")
    return AMP_DTYPES[amp]


def autocast(device: torch.device, amp: str) -> contextlib.AbstractContextManager:
    """``torch.autocast`` for ``amp`` on ``device``; a no-op context for ``none``."""
    dtype = amp_dtype(amp)
    return torch.autocast(device_type=device.type, dtype=dtype, enabled=dtype is not None)


def synchronize(device: torch.device) -> None:
    """Wait for queued CUDA work on ``device`` (nothing to wait for on the CPU)."""
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def now(device: torch.device) -> float:
    """``time.perf_counter()`` after :func:`synchronize`: a clock reading that includes queued GPU work."""
    synchronize(device)
    return time.perf_counter()
