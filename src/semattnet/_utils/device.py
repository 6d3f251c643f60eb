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

__all__ = ["AMP_DTYPES", "amp_dtype", "autocast", "now", "resolve_device", "synchronize"]

#: ``--amp`` names and the autocast type each selects (``none``: float32, no autocast).
AMP_DTYPES: dict[str, torch.dtype | None] = {"none": None, "bf16": torch.bfloat16, "fp16": torch.float16}


def resolve_device(name: str | torch.device = "auto") -> torch.device:
    """``auto`` -> CUDA if available, else CPU; anything else as given, checked for availability."""
    if isinstance(name, torch.device):
        return name
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    device = torch.device(name)
    if device.type == "cuda" and not torch.cuda.is_available():
        raise InputError(f"device {name!r} requested but CUDA is not available; use --device cpu or auto")
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
