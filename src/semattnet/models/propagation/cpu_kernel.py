"""A fused CPU kernel for inference-time CSPN++ propagation (C++, compiled on first use).

:func:`propagate_iterations` runs ``iterations`` steps of one kernel size with re-injection,

    h'(p) = sum_{t != c} W_t(p - o_t) h(p - o_t) + W_c(p) h_0(p);   h = m d + (1 - m) h',

the kernel read in place (no shifted copy) and stored row by row (:func:`rows_layout`: each
row's taps side by side). Rows go through all the steps in bands of 8 (a wavefront: step i
computes a row once step i - 1 holds every row it reads), so a band's kernel rows are read from
memory once, not once per step: 2-2.5x faster at 352x1216, where the kernel (140 MB) does not fit
in any cache. Every channel of ``h`` (the four polyphase sub-grids of the dilation-2 stage)
reuses each kernel row while it is in cache, a band's rows run in parallel, and the products are
summed in the same order as :func:`~semattnet.models.propagation.shifted.propagate_shifted`, so
the outputs agree to float rounding (and to the bit with the steps run one at a time).
:func:`normalize_affinity` turns the raw guidance into that kernel (eq. 13) in one pass.

It is built with :func:`torch.utils.cpp_extension.load_inline` by :class:`~semattnet._utils.cpp_build.InlineKernel`
(needs a C++ compiler and the ``ninja`` package; the build is cached, ~30-60 s the first time, said on stderr with
the time it took). Without them (one line on stderr), or for autograd, CUDA, or non-float32 tensors, the refinement
uses the PyTorch implementation instead. Set ``SEMATTNET_NO_CPP=1`` to disable the kernel.
"""

from __future__ import annotations

import torch

from semattnet._errors import InputError
from semattnet._utils.cpp_build import InlineKernel

__all__ = ["available", "normalize_affinity", "propagate_iterations", "rows_layout"]

_SOURCE = r"""
#include <torch/extension.h>
#include <ATen/Parallel.h>
#include <algorithm>
#include <cmath>
#include <vector>

// One step for row y of batch item b: out = sum_t W_t(p - o_t) h(p - o_t) + W_c h0, then re-injection.
// affinity (B, H, K*K, W): the taps of each row side by side, so that a row's taps are a few long runs of
// memory; h, out, h0 (B, C, H, W); mask, sparse (B, 1, H, W).
static void step_row(const float* a, const float* h, float* out, const float* g, const float* m, const float* d,
                     int64_t b, int64_t y, int64_t C, int64_t H, int64_t W, int64_t k, int64_t dilation) {
  const int64_t KK = k * k, r = k / 2, centre = KK / 2, plane = H * W;
  const float* ab = a + b * KK * plane;
  const float* ac = ab + (y * KK + centre) * W;
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
    const float* at_ = ab + (sy * KK + t) * W - ox;  // W_t at the neighbour p - o_t
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

// `iterations` steps, in bands of rows that go through every step while their kernel rows are in cache (a
// wavefront: step i may compute a row once step i - 1 has every row it reads, `reach` rows further down).
// Each row's arithmetic is that of one plain step after another, so the result is the same to the bit.
// affinity (B, H, K*K, W); start, h0 (B, C, H, W); mask, sparse (B, 1, H, W); all float32, contiguous.
torch::Tensor propagate_iterations(torch::Tensor affinity, torch::Tensor start, torch::Tensor h0,
                                   torch::Tensor mask, torch::Tensor sparse, int64_t iterations,
                                   int64_t dilation) {
  const int64_t B = affinity.size(0), H = affinity.size(1), KK = affinity.size(2), W = affinity.size(3);
  const int64_t C = start.size(1);
  int64_t k = 1;
  while (k * k < KK) ++k;
  TORCH_CHECK(k * k == KK && k % 2 == 1, "affinity must have k*k channels for an odd k");
  if (iterations <= 0) return start.clone();
  const int64_t T = iterations, reach = (k / 2) * dilation, band = 8;
  torch::Tensor levels = torch::empty({T, B, C, H, W}, start.options());  // step i's result in levels[i - 1]
  const int64_t size = B * C * H * W;
  const float* a = affinity.data_ptr<float>();
  const float* g = h0.data_ptr<float>();
  const float* m = mask.data_ptr<float>();
  const float* d = sparse.data_ptr<float>();
  float* lv = levels.data_ptr<float>();
  for (int64_t b = 0; b < B; ++b) {
    std::vector<int64_t> done(T + 1, 0);  // rows of each step computed so far; step 0 is `start`
    done[0] = H;
    while (done[T] < H) {
      for (int64_t i = 1; i <= T; ++i) {
        const int64_t target = i == 1 ? std::min(H, done[1] + band)
                               : done[i - 1] >= H ? H : std::max(done[i], done[i - 1] - reach);
        const float* h = i == 1 ? start.data_ptr<float>() : lv + (i - 2) * size;
        float* out = lv + (i - 1) * size;
        at::parallel_for(done[i], target, 1, [&](int64_t y0, int64_t y1) {
          for (int64_t y = y0; y < y1; ++y) step_row(a, h, out, g, m, d, b, y, C, H, W, k, dilation);
        });
        done[i] = target;
      }
    }
  }
  return levels[T - 1].clone();
}

// guide (B, N, H, W) raw guidance of one kernel size (N = k*k - 1) -> out (B, H, N + 1, W), the layout
// propagate_iterations reads: eq. 13, each weight g_t / sum_t |g_t| and the centre 1 - sum of the weights
// inserted at N / 2, one row at a time. out: float32, contiguous, written in place (a buffer reused across
// frames costs no page faults).
torch::Tensor normalize_affinity(torch::Tensor guide, torch::Tensor out) {
  const int64_t B = guide.size(0), N = guide.size(1), H = guide.size(2), W = guide.size(3);
  const int64_t half = N / 2, plane = H * W;
  TORCH_CHECK(out.is_contiguous() && out.size(0) == B && out.size(1) == H && out.size(2) == N + 1 &&
              out.size(3) == W, "out must be a contiguous (B, H, N + 1, W) tensor");
  const float* g = guide.data_ptr<float>();
  float* o = out.data_ptr<float>();
  at::parallel_for(0, B * H, 1, [&](int64_t begin, int64_t end) {
    std::vector<float> norm(W), total(W);
    for (int64_t row = begin; row < end; ++row) {
      const int64_t b = row / H, y = row % H;
      const float* gb = g + b * N * plane + y * W;
      float* ob = o + (b * H + y) * (N + 1) * W;
      std::fill(norm.begin(), norm.end(), 0.0f);
      std::fill(total.begin(), total.end(), 0.0f);
      for (int64_t t = 0; t < N; ++t) {
        const float* gr = gb + t * plane;
        for (int64_t x = 0; x < W; ++x) norm[x] += std::abs(gr[x]);
      }
      for (int64_t t = 0; t < N; ++t) {
        const float* gr = gb + t * plane;
        float* orow = ob + (t < half ? t : t + 1) * W;
        for (int64_t x = 0; x < W; ++x) {
          const float w = gr[x] / norm[x];
          orow[x] = w;
          total[x] += w;
        }
      }
      float* centre = ob + half * W;
      for (int64_t x = 0; x < W; ++x) centre[x] = 1.0f - total[x];
    }
  });
  return out;
}
"""

#: The compiled extension (a new name for new sources), built on first use.
KERNEL = InlineKernel(
    "semattnet_propagation_v5",
    _SOURCE,
    ["propagate_iterations", "normalize_affinity"],
    what="the fused CPU propagation kernel",
    fallback="the PyTorch propagation",
)


def available() -> bool:
    """Whether the compiled kernel can be used (builds it on the first call)."""
    return KERNEL.available()


def rows_layout(affinity: torch.Tensor) -> torch.Tensor:
    """(B, k*k, H, W) -> the same values laid out (B, H, k*k, W), contiguous: what the kernel reads (a view,
    no copy, for affinities :func:`normalize_affinity` wrote)."""
    return affinity.float().transpose(1, 2).contiguous()


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
        affinity: (B, k*k, H, W) normalised kernel (unshifted, as :func:`cspn_affinity` gives); read in the
            layout of :func:`rows_layout` (copied into it unless it is already, as from :func:`normalize_affinity`).
        start, h0: (B, C, H, W) initial estimate and fixed input.
        mask, sparse: (B, 1, H, W) re-injection weight and depth.
    """
    module = KERNEL.require()
    args = [t.contiguous().float() for t in (start, h0.expand_as(start), mask, sparse)]
    return module.propagate_iterations(rows_layout(affinity), *args, int(iterations), int(dilation))  # type: ignore[attr-defined]


def normalize_affinity(guide: torch.Tensor, out: torch.Tensor | None = None) -> torch.Tensor:
    """:func:`~semattnet.models.propagation.cspn_affinity` in one pass: (B, k*k - 1, H, W) raw guidance ->
    (B, k*k, H, W) kernel, float32 on the CPU (equal to float rounding), stored as :func:`rows_layout`
    (the result is a transposed view of that buffer).

    ``out``: a contiguous float32 (B, H, k*k, W) buffer to write into, e.g. one kept across frames: writing
    a fresh 140 MB tensor costs about 10x more in page faults than the arithmetic.
    """
    module = KERNEL.require()
    b, n, h, w = guide.shape
    if out is None:
        out = torch.empty(b, h, n + 1, w)
    elif out.shape != (b, h, n + 1, w) or out.dtype != torch.float32 or not out.is_contiguous():
        raise InputError(
            f"out must be a contiguous float32 {(b, h, n + 1, w)} tensor, got {tuple(out.shape)} {out.dtype}"
        )
    module.normalize_affinity(guide.contiguous().float(), out)  # type: ignore[attr-defined]
    return out.transpose(1, 2)
