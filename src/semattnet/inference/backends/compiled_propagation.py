"""The CSPN++ propagation for CUDA: :func:`semattnet.models.refinement.refine` (the heads finished, then
:func:`~semattnet.models.refinement.propagate_refinement`) through ``torch.compile``.

The fused C++ kernel serves float32 CPU inference only; on CUDA the eager path is the shifted
form (one in-place multiply-add per tap and step: 2 x 3 x 6 steps x up to 49 taps, each a small
kernel launch). Under ``torch.compile`` the same function takes its recorded form
(:func:`semattnet.models.propagation.export.propagate_functional`, chosen by
:func:`semattnet.models._tracing.is_tracing`), which Inductor fuses into a few Triton kernels.
Compiled once per input size and iteration count (``dynamic=False``; each first compilation said on
stderr with the time it took); on the CPU the same compilation works but takes minutes on 2 cores, so the
tests check the recorded form through TorchScript tracing (:func:`traced_propagation`), which takes the
same code path.
"""

from __future__ import annotations

import functools
import sys
import time
from collections.abc import Callable

import torch

from semattnet.models.refinement import RefinementHeads, refine

__all__ = ["compiled_propagation", "traced_propagation"]

Propagation = Callable[[RefinementHeads, int], tuple[torch.Tensor, torch.Tensor]]


@functools.cache
def compiled_propagation(mode: str | None = None) -> Propagation:
    """``refine`` compiled by Inductor (``mode``: e.g. ``"max-autotune-no-cudagraphs"``); the first call at each
    size and iteration count (a compilation) is said on stderr, with the time it took."""
    compiled = torch.compile(refine, dynamic=False, mode=mode)
    seen: set[tuple[object, ...]] = set()

    def run(heads: RefinementHeads, iterations: int) -> tuple[torch.Tensor, torch.Tensor]:
        key = (tuple(heads.depth.shape), heads.depth.device.type, iterations)
        if key in seen:
            return compiled(heads, iterations)
        size = "x".join(map(str, key[0][-2:]))
        print(
            f"semattnet: compiling the propagation for {size}, {iterations} iteration(s) (once per size) ...",
            file=sys.stderr,
            flush=True,
        )
        start = time.perf_counter()
        out = compiled(heads, iterations)
        seen.add(key)
        print(
            f"semattnet: compiled the propagation in {time.perf_counter() - start:.1f} s", file=sys.stderr, flush=True
        )
        return out

    return run


def traced_propagation(heads: RefinementHeads, iterations: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The recorded form of ``refine`` (what ``torch.compile`` compiles), run through
    TorchScript tracing: the CPU-cheap check of the compiled path's code."""
    flat = heads.to_dict()
    names = list(flat)

    def run(*tensors: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        rebuilt = RefinementHeads.from_dict(
            dict(zip(names, tensors, strict=True)), heads.kernel_sizes, affinity=heads.affinity
        )
        return refine(rebuilt, iterations)

    with torch.no_grad():
        traced = torch.jit.trace(run, tuple(flat.values()), check_trace=False)
        out: tuple[torch.Tensor, torch.Tensor] = traced(*flat.values())
        return out
