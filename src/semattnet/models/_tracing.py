"""One answer to "is this forward being recorded?" (ONNX export, TorchScript tracing or scripting,
``torch.compile``): recorded graphs get plain tensor ops (no in-place writes, no ``autograd.Function``,
no compiled kernel) and no data-dependent checks."""

from __future__ import annotations

import torch

__all__ = ["is_tracing"]


def is_tracing() -> bool:
    """True while exporting to ONNX, tracing or scripting with TorchScript, or compiling with torch.compile."""
    compiling = getattr(getattr(torch, "compiler", None), "is_compiling", None)  # torch >= 2.3
    return bool(
        torch.onnx.is_in_onnx_export()
        or torch.jit.is_scripting()
        or torch.jit.is_tracing()
        or (compiling is not None and compiling())
    )
