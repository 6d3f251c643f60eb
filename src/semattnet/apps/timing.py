"""Timing machinery of ``semattnet bench``: medians of repeated runs (synchronised on CUDA), interleaved
timing, peak memory, convolution MAC counts and the measured convolution peak of a device."""

from __future__ import annotations

import contextlib
import statistics
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path

import torch
from torch import nn

from semattnet._utils.cpu import has_native_bf16
from semattnet._utils.device import now
from semattnet.models.macs import count_macs

__all__ = ["conv_peak_gflops", "count_macs", "fast_mode_dtype", "interleaved", "peak_memory", "status_mib", "timeit"]


def timeit(fn: Callable[[], object], device: torch.device, repeats: int = 3, warmup: int = 1) -> float:
    """Median seconds of ``fn()`` over ``repeats`` runs after ``warmup`` runs."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        t0 = now(device)
        fn()
        times.append(now(device) - t0)
    return statistics.median(times)


def interleaved(fns: Mapping[str, Callable[[], object]], device: torch.device, repeats: int = 3) -> dict[str, float]:
    """Median seconds of each function, timed in turns (``a b c a b c ...``) so that slow drifts
    of the machine's speed affect all of them alike. Run each once before, as a warm-up."""
    times: dict[str, list[float]] = {k: [] for k in fns}
    for _ in range(repeats):
        for name, fn in fns.items():
            t0 = now(device)
            fn()
            times[name].append(now(device) - t0)
    return {k: statistics.median(v) for k, v in times.items()}


@contextlib.contextmanager
def peak_memory(device: torch.device) -> Iterator[dict[str, float]]:
    """Peak memory (MiB) while the block runs: CUDA allocator peak, or the process's peak
    resident set on Linux (reset through ``/proc/self/clear_refs``); ``nan`` elsewhere."""
    out: dict[str, float] = {"peak_mib": float("nan")}
    if device.type == "cuda":
        torch.cuda.reset_peak_memory_stats(device)
        yield out
        out["peak_mib"] = torch.cuda.max_memory_allocated(device) / 2**20
        return
    try:
        Path("/proc/self/clear_refs").write_text("5")
        ok = True
    except OSError:
        ok = False
    yield out
    if ok:
        out["peak_mib"] = status_mib("VmHWM")


def status_mib(field: str, pid: int | str = "self") -> float:
    """A memory field of Linux's ``/proc/PID/status`` (``VmRSS``, ``VmHWM``: the resident set, its high-water
    mark) in MiB; ``nan`` where the file or the field is missing."""
    try:
        lines = Path(f"/proc/{pid}/status").read_text().splitlines()
    except OSError:
        return float("nan")
    return next((int(ln.split()[1]) / 1024 for ln in lines if ln.startswith(f"{field}:")), float("nan"))


def fast_mode_dtype(device: torch.device) -> torch.dtype | None:
    """The autocast type of the fast mode: float16 on CUDA, bfloat16 on CPUs with native
    bfloat16 instructions (AVX-512 BF16 / AMX: :func:`semattnet._utils.cpu.has_native_bf16`), ``None``
    where it would be slower than float32 (oneDNN's own check also says yes where bf16 is emulated)."""
    if device.type == "cuda":
        return torch.float16
    if device.type == "cpu" and has_native_bf16():
        return torch.bfloat16
    return None


def conv_peak_gflops(
    device: torch.device, size: tuple[int, int] = (352, 1216), dtype: torch.dtype = torch.float32
) -> float:
    """Best achieved GFLOP/s of 3x3 convolutions of the model's typical shapes at ``size``
    (64 channels at 1/2, 256 at 1/8, 512 at 1/16 of the frame)."""
    best = 0.0
    for ch, f in ((64, 2), (256, 8), (512, 16)):
        h, w = max(1, size[0] // f), max(1, size[1] // f)
        conv = nn.Conv2d(ch, ch, 3, padding=1, bias=False).to(device)
        x = torch.randn(1, ch, h, w, device=device)
        with torch.inference_mode(), torch.autocast(device.type, dtype=dtype, enabled=dtype != torch.float32):
            seconds = timeit(lambda: conv(x), device, repeats=3)  # noqa: B023
        best = max(best, 2 * ch * ch * 9 * h * w / seconds / 1e9)
    return best
