"""What the CPU can do: its model name, its ISA flags, and whether bfloat16 is native.

oneDNN's own check (``torch.ops.mkldnn._is_mkldnn_bf16_supported()``) answers True on AVX-512
CPUs that merely *emulate* bfloat16, where bfloat16 convolutions are several times slower than
float32. Native support means the ``avx512_bf16`` or ``amx_bf16`` instructions.
"""

from __future__ import annotations

import functools
import platform
from pathlib import Path

import torch

__all__ = ["cpu_flags", "cpu_model", "cpu_summary", "has_native_bf16"]

_CPUINFO = Path("/proc/cpuinfo")
#: Instruction sets that run bfloat16 matrix/convolution math natively.
NATIVE_BF16_FLAGS = ("avx512_bf16", "amx_bf16")
#: Flags worth naming in benchmark tables.
SHOWN_FLAGS = ("avx2", "fma", "avx512f", "avx512_vnni", "avx512_bf16", "amx_bf16", "amx_int8", "avx_vnni")


def _cpuinfo_field(name: str, text: str) -> str | None:
    for line in text.splitlines():
        key, _, value = line.partition(":")
        if key.strip() == name:
            return value.strip()
    return None


@functools.lru_cache(maxsize=1)
def cpu_flags() -> frozenset[str]:
    """The CPU's ISA flags from ``/proc/cpuinfo`` (empty where it cannot be read)."""
    try:
        flags = _cpuinfo_field("flags", _CPUINFO.read_text())
    except OSError:
        return frozenset()
    return frozenset((flags or "").split())


@functools.lru_cache(maxsize=1)
def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``; else ``platform.processor()``)."""
    try:
        name = _cpuinfo_field("model name", _CPUINFO.read_text())
    except OSError:
        name = None
    return name or platform.processor() or "unknown CPU"


def has_native_bf16() -> bool:
    """True where the CPU runs bfloat16 natively (AVX-512 BF16 or AMX), so autocast to bf16 pays off."""
    return any(flag in cpu_flags() for flag in NATIVE_BF16_FLAGS)


def cpu_summary() -> str:
    """One line for benchmark tables: model, cores, PyTorch's SIMD level and the notable ISA flags."""
    shown = [f for f in SHOWN_FLAGS if f in cpu_flags()]
    capability = torch.backends.cpu.get_cpu_capability()
    return f"{cpu_model()} ({torch.get_num_threads()} threads, torch {capability}; flags: {' '.join(shown) or 'n/a'})"
