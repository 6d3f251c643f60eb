"""A fused CPU kernel for inference-time CSPN++ propagation (C++, compiled on first use).

:func:`propagate_iterations` runs ``iterations`` steps of one kernel size with re-injection,

    h'(p) = sum_{t != c} W_t(p - o_t) h(p - o_t) + W_c(p) h_0(p);   h = m d + (1 - m) h',

in one pass over each row per step: the kernel is read in place (no shifted copy), every
channel of ``h`` (the four polyphase sub-grids of the dilation-2 stage) reuses each kernel row
while it is in cache, rows run in parallel, and the products are summed in the same order as
:func:`~semattnet.models.propagation.shifted.propagate_shifted`, so the outputs agree to float rounding.

It is built with :func:`torch.utils.cpp_extension.load_inline` (needs a C++ compiler and the
``ninja`` package; the build is cached, ~30 s the first time). Without them, or for autograd,
CUDA, or non-float32 tensors, the refinement uses the PyTorch implementation instead. Set
``SEMATTNET_NO_CPP=1`` to disable the kernel.
"""

from __future__ import annotations

import os
import threading
import warnings

import torch

__all__ = ["available", "propagate_iterations"]

_SOURCE = r"""
#include <torch/extension.h>
#include <ATen/Parallel.h>
#include <algorithm>
#include <vector>

// affinity (B, K*K, H, W); start, h0 (B, C, H, W); mask, sparse (B, 1, H, W); all float32, contiguous.
torch::Tensor propagate_iterations(torch::Tensor affinity, torch::Tensor start, torch::Tensor h0,
                                   torch::Tensor mask, torch::Tensor sparse, int64_t iterations,
                                   int64_t dilation) {
  const int64_t B = affinity.size(0), KK = affinity.size(1), H = affinity.size(2), W = affinity.size(3);
  const int64_t C = start.size(1);
  int64_t k = 1;
  while (k * k < KK) ++k;
  TORCH_CHECK(k * k == KK && k % 2 == 1, "affinity must have k*k channels for an odd k");
  const int64_t r = k / 2, centre = KK / 2, plane = H * W;
  torch::Tensor cur = start.clone();
  torch::Tensor nxt = torch::empty_like(cur);
  const float* a = affinity.data_ptr<float>();
  const float* g = h0.data_ptr<float>();
  const float* m = mask.data_ptr<float>();
  const float* d = sparse.data_ptr<float>();
  for (int64_t it = 0; it < iterations; ++it) {
    const float* h = cur.data_ptr<float>();
    float* out = nxt.data_ptr<float>();
    at::parallel_for(0, B * H, 1, [&](int64_t begin, int64_t end) {
      for (int64_t row = begin; row < end; ++row) {
        const int64_t b = row / H, y = row % H;
        const float* ab = a + b * KK * plane;
        const float* ac = ab + centre * plane + y * W;
        for (int64_t ch = 0; ch < C; ++ch) {
          float* o = out + (b * C + ch) * plane + y * W;
          const float* g0 = g + (b * C + ch) * plane + y * W;
          for (int64_t x = 0; x < W; ++x) o[x] = ac[x] * g0[x];
        }
        for (int64_t t = 0; t < KK; ++t) {
          if (t == centre) continue;
          const int64_t oy = (t / k - r) * dilation, ox = (t % k - r) * dilation;
          const int64_t sy = y - oy;
          if (sy < 0 || sy >= H) continue;
          const int64_t x0 = std::max<int64_t>(0, ox), x1 = std::min<int64_t>(W, W + ox);
          if (x0 >= x1) continue;
          const float* at_ = ab + t * plane + sy * W - ox;  // W_t at the neighbour p - o_t
          for (int64_t ch = 0; ch < C; ++ch) {
            float* o = out + (b * C + ch) * plane + y * W;
            const float* hs = h + (b * C + ch) * plane + sy * W - ox;
            for (int64_t x = x0; x < x1; ++x) o[x] += at_[x] * hs[x];
          }
        }
        const float* mr = m + b * plane + y * W;
        const float* dr = d + b * plane + y * W;
        for (int64_t ch = 0; ch < C; ++ch) {
          float* o = out + (b * C + ch) * plane + y * W;
          for (int64_t x = 0; x < W; ++x) o[x] = mr[x] * dr[x] + (1.0f - mr[x]) * o[x];
        }
      }
    });
    std::swap(cur, nxt);
  }
  return cur;
}
"""

_lock = threading.Lock()
_module: object | None = None
_failed: str | None = None


def _load() -> object | None:
    global _module, _failed
    if _module is not None or _failed is not None:
        return _module
    with _lock:
        if _module is not None or _failed is not None:
            return _module
        if os.environ.get("SEMATTNET_NO_CPP"):
            _failed = "disabled by SEMATTNET_NO_CPP"
            return None
        try:
            from torch.utils.cpp_extension import load_inline

            _module = load_inline(
                name="semattnet_propagation_v1",
                cpp_sources=[_SOURCE],
                functions=["propagate_iterations"],
                extra_cflags=["-O3", "-march=native", "-fno-math-errno"],
                verbose=False,
            )
        except Exception as err:  # no compiler, no ninja, ...: fall back to PyTorch
            _failed = f"{type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}"
            warnings.warn(f"semattnet: fused CPU propagation unavailable ({_failed}); using PyTorch", stacklevel=3)
        return _module


def available() -> bool:
    """Whether the compiled kernel can be used (builds it on the first call)."""
    return _load() is not None


def propagate_iterations(
    affinity: torch.Tensor,
    start: torch.Tensor,
    h0: torch.Tensor,
    mask: torch.Tensor,
    sparse: torch.Tensor,
    iterations: int,
    dilation: int = 1,
) -> torch.Tensor:
    """``iterations`` propagation steps with re-injection (module docstring), float32 on the CPU.

    Args:
        affinity: (B, k*k, H, W) normalised kernel (unshifted, as :func:`cspn_affinity` gives).
        start, h0: (B, C, H, W) initial estimate and fixed input.
        mask, sparse: (B, 1, H, W) re-injection weight and depth.
    """
    module = _load()
    if module is None:
        raise RuntimeError(f"fused propagation unavailable: {_failed}")
    args = [t.contiguous().float() for t in (affinity, start, h0.expand_as(start), mask, sparse)]
    return module.propagate_iterations(*args, int(iterations), int(dilation))  # type: ignore[attr-defined]
