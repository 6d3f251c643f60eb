"""The classical completion (:mod:`semattnet.models.anchor`) and the LiDAR distance transform
(:func:`semattnet.models.uncertainty.lidar_distance`) as one C++ CPU kernel, compiled on first use.

Same values as the PyTorch path: the maxima, minima, copies and medians to the bit, the Gaussian by the same
weights (to float rounding: the sums may run in another order), the fill steps and the distances equal. Faster by
doing less, not by approximating: square dilations by doubling (log2 of the size), in strips of columns that stay in
cache; the banded diamond dilation scattered from the measured pixels only; the hole fills computed on the rows that
have a hole; buffers kept per thread across calls; the distance transform by the lower envelope of parabolas
(Felzenszwalb-Huttenlocher, exact integer arithmetic). The images of a batch run in parallel.

Used for float32 CPU tensors outside autograd and tracing (:func:`usable`), built by
:class:`~semattnet._utils.cpp_build.InlineKernel` (a C++ compiler and ninja; said on stderr; ``SEMATTNET_NO_CPP=1``
disables it, ``impl="pytorch"`` skips it per call).
"""

from __future__ import annotations

from typing import Literal

import torch

from semattnet._utils.cpp_build import InlineKernel
from semattnet.models._tracing import is_tracing

__all__ = ["KERNEL", "KernelImpl", "available", "complete", "distance", "usable"]

#: "auto": the kernel where :func:`usable`, else PyTorch; "pytorch": always the PyTorch path (the reference).
KernelImpl = Literal["auto", "pytorch"]

_SOURCE = r"""
#include <torch/extension.h>
#include <ATen/Parallel.h>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

namespace {

constexpr int64_t STRIP = 64;  // columns a vertical pass takes at once (its buffers stay in L2)
const float INF = std::numeric_limits<float>::infinity();

// Per-thread buffers, kept across calls (fresh pages cost more in page faults than the arithmetic).
struct Buffers {
  std::vector<float> tmp, close, a, b, ra, rb, row;
  std::vector<uint8_t> step;
  std::vector<int32_t> ia, ib;
  std::vector<int64_t> zn, zd;
};
thread_local Buffers buffers;

template <bool MIN> inline float pick(float a, float b) { return MIN ? std::min(a, b) : std::max(a, b); }

template <bool MIN> void shift_op(const float* __restrict in, float* __restrict out, int64_t count, int64_t shift) {
  for (int64_t i = 0; i < count; ++i) out[i] = pick<MIN>(in[i], in[i + shift]);
}

// Runs of k (odd) items along `len` padded items of `unit` floats, by doubling (ping-pong between a and b): returns the
// buffer whose item i is the max (min) of padded items i .. i + k - 1.
template <bool MIN> float* run(float* a, float* b, int64_t len, int64_t k, int64_t unit) {
  int64_t w = 1;
  while (w * 2 <= k) {
    shift_op<MIN>(a, b, (len - w) * unit, w * unit);
    std::swap(a, b);
    len -= w;
    w *= 2;
  }
  const int64_t rest = k - w;
  if (rest) {
    shift_op<MIN>(a, b, (len - rest) * unit, rest * unit);
    std::swap(a, b);
  }
  return a;
}

// dst rows [y0, y1) = the max (min) over rows y - k/2 .. y + k/2 of src (clipped to the image), in strips of columns.
template <bool MIN>
void run_cols(const float* src, float* dst, int64_t H, int64_t W, int64_t y0, int64_t y1, int64_t k, Buffers& buf) {
  const int64_t r = k / 2, len = y1 - y0 + k - 1;
  const float pad = MIN ? INF : -INF;
  buf.a.resize(len * STRIP);
  buf.b.resize(len * STRIP);
  for (int64_t x0 = 0; x0 < W; x0 += STRIP) {
    const int64_t s = std::min(STRIP, W - x0);
    float* a = buf.a.data();
    for (int64_t i = 0; i < len; ++i) {
      const int64_t y = y0 - r + i;
      if (y < 0 || y >= H) std::fill(a + i * STRIP, a + (i + 1) * STRIP, pad);
      else std::copy(src + y * W + x0, src + y * W + x0 + s, a + i * STRIP);
    }
    const float* res = run<MIN>(a, buf.b.data(), len, k, STRIP);
    for (int64_t y = y0; y < y1; ++y) std::copy(res + (y - y0) * STRIP, res + (y - y0) * STRIP + s, dst + y * W + x0);
  }
}

// The max (min) over src[x - k/2 .. x + k/2] (clipped) of one row of n: a buffer of n.
template <bool MIN> const float* run_row(const float* src, int64_t n, int64_t k, Buffers& buf) {
  const int64_t r = k / 2, len = n + k - 1;
  const float pad = MIN ? INF : -INF;
  buf.ra.resize(len);
  buf.rb.resize(len);
  float* a = buf.ra.data();
  std::fill(a, a + r, pad);
  std::copy(src, src + n, a + r);
  std::fill(a + r + n, a + len, pad);
  return run<MIN>(a, buf.rb.data(), len, k, 1);
}

bool has_empty(const float* row, int64_t n) {
  bool empty = false;
  for (int64_t x = 0; x < n; ++x) empty |= !(row[x] > 0);
  return empty;
}

// dst = the max (min) over the k x k square (clipped to the image) of src, through the frame tmp. With `fill`, only
// the empty (0) pixels of dst (which is then src) take it, and only the rows with one are computed.
template <bool MIN>
void square(const float* src, float* tmp, float* dst, int64_t H, int64_t W, int64_t k, bool fill, Buffers& buf) {
  int64_t y0 = 0, y1 = H;
  if (fill) {
    while (y0 < H && !has_empty(src + y0 * W, W)) ++y0;
    while (y1 > y0 && !has_empty(src + (y1 - 1) * W, W)) --y1;
    if (y0 >= y1) return;
  }
  run_cols<MIN>(src, tmp, H, W, y0, y1, k, buf);
  for (int64_t y = y0; y < y1; ++y) {
    float* out = dst + y * W;
    if (fill && !has_empty(out, W)) continue;
    const float* res = run_row<MIN>(tmp + y * W, W, k, buf);
    if (fill) {
      for (int64_t x = 0; x < W; ++x) out[x] = out[x] > 0 ? out[x] : res[x];
    } else {
      std::copy(res, res + W, out);
    }
  }
}

// Pixels that are filled now and not yet marked: step k.
void mark(uint8_t* step, const float* inv, int64_t n, uint8_t k) {
  if (step == nullptr) return;
  for (int64_t i = 0; i < n; ++i) step[i] = (inv[i] > 0 && step[i] > k) ? k : step[i];
}

// Max of (max_depth + 1 - d) over each measured pixel's diamond, its radius by the depth band (3, 2, 1 for d up to
// 15 m, 30 m, beyond): the banded diamond dilation. inv must be zero. Returns [min, max] of d (min: inf if none).
std::pair<float, float> dilate(const float* s, float* inv, uint8_t* step, int64_t H, int64_t W, float maxd,
                               float top) {
  float lo = INF, hi = 0.0f;
  for (int64_t y = 0; y < H; ++y) {
    for (int64_t x = 0; x < W; ++x) {
      const float d = std::min(std::max(s[y * W + x], 0.0f), maxd);
      if (step) step[y * W + x] = d > 0 ? 0 : 5;
      if (!(d > 0)) continue;
      lo = std::min(lo, d);
      hi = std::max(hi, d);
      const float v = top - d;
      const int64_t rad = d <= 15.0f ? 3 : d <= 30.0f ? 2 : 1;
      for (int64_t dy = -rad; dy <= rad; ++dy) {
        const int64_t yy = y + dy, rr = rad - std::abs(dy);
        if (yy < 0 || yy >= H) continue;
        float* row = inv + yy * W;
        const int64_t xa = std::max<int64_t>(0, x - rr), xb = std::min<int64_t>(W - 1, x + rr);
        for (int64_t xx = xa; xx <= xb; ++xx) row[xx] = std::max(row[xx], v);
      }
    }
  }
  return {lo, hi};
}

// Above each column's top filled pixel, its value.
void extend_top(float* inv, int64_t H, int64_t W, Buffers& buf) {
  std::vector<int32_t>& top = buf.ia;
  top.assign(W, static_cast<int32_t>(H));
  int64_t left = W;
  for (int64_t y = 0; y < H && left; ++y) {
    const float* row = inv + y * W;
    for (int64_t x = 0; x < W; ++x) {
      if (top[x] == H && row[x] > 0) {
        top[x] = static_cast<int32_t>(y);
        --left;
      }
    }
  }
  int64_t reach = 0;
  for (int64_t x = 0; x < W; ++x) reach = top[x] < H ? std::max<int64_t>(reach, top[x]) : reach;
  for (int64_t y = 0; y < reach; ++y) {
    float* row = inv + y * W;
    for (int64_t x = 0; x < W; ++x) {
      if (y < top[x] && top[x] < H) row[x] = inv[top[x] * W + x];
    }
  }
}

// Empty items of a line of n take the nearest filled one (the one before on a tie): item i at p + i * stride, of
// `len` floats each; `filled` says which items are filled.
template <typename Filled>
void extend_line(float* p, int64_t n, int64_t stride, int64_t len, Filled filled) {
  auto copy = [&](int64_t to, int64_t from) { std::copy(p + from * stride, p + from * stride + len, p + to * stride); };
  int64_t prev = -1;
  for (int64_t i = 0; i < n; ++i) {
    if (!filled(i)) continue;
    for (int64_t j = prev + 1; j < i; ++j) copy(j, prev >= 0 && j - prev <= i - j ? prev : i);
    prev = i;
  }
  if (prev >= 0)
    for (int64_t j = prev + 1; j < n; ++j) copy(j, prev);
}

// Each row from its nearest filled pixel, then each empty row from the nearest filled row.
void extend_rows_then_columns(float* inv, int64_t H, int64_t W, Buffers& buf) {
  std::vector<int32_t>& full = buf.ib;
  full.assign(H, 0);
  for (int64_t y = 0; y < H; ++y) {
    float* row = inv + y * W;
    int64_t count = 0;
    for (int64_t x = 0; x < W; ++x) count += row[x] > 0;
    full[y] = count > 0;
    if (count > 0 && count < W) extend_line(row, W, 1, 1, [&](int64_t x) { return row[x] > 0; });
  }
  extend_line(inv, H, W, W, [&](int64_t y) { return full[y] != 0; });
}

inline float median5(float a, float b, float c, float d, float e) {
  const float lo = std::max(std::min(a, b), std::min(c, d));
  const float hi = std::min(std::max(a, b), std::max(c, d));
  return std::max(std::min(e, lo), std::min(std::max(e, lo), hi));
}

// row (n) with its edges replicated twice on each side, in buf.row: item x + 2 is row[x].
const float* replicate2(const float* row, int64_t n, Buffers& buf) {
  buf.row.resize(n + 4);
  float* p = buf.row.data();
  p[0] = p[1] = row[0];
  std::copy(row, row + n, p + 2);
  p[n + 2] = p[n + 3] = row[n - 1];
  return p;
}

// The separable 5 x 5 median (rows, then columns; edges replicated): inv -> tmp -> inv.
void median(float* inv, float* tmp, int64_t H, int64_t W, Buffers& buf) {
  for (int64_t y = 0; y < H; ++y) {
    const float* p = replicate2(inv + y * W, W, buf);
    float* o = tmp + y * W;
    for (int64_t x = 0; x < W; ++x) o[x] = median5(p[x], p[x + 1], p[x + 2], p[x + 3], p[x + 4]);
  }
  for (int64_t y = 0; y < H; ++y) {
    const float* r[5];
    for (int64_t j = 0; j < 5; ++j) r[j] = tmp + std::min(std::max<int64_t>(y + j - 2, 0), H - 1) * W;
    float* o = inv + y * W;
    for (int64_t x = 0; x < W; ++x) o[x] = median5(r[0][x], r[1][x], r[2][x], r[3][x], r[4][x]);
  }
}

// The separable 5-tap Gaussian g (columns, then rows; edges replicated), then depth = top - it, clamped to [lo, hi]:
// inv -> tmp -> inv.
void gauss_to_depth(float* inv, float* tmp, int64_t H, int64_t W, const float* g, float top, float lo, float hi,
                    Buffers& buf) {
  for (int64_t y = 0; y < H; ++y) {
    const float* r[5];
    for (int64_t j = 0; j < 5; ++j) r[j] = inv + std::min(std::max<int64_t>(y + j - 2, 0), H - 1) * W;
    float* o = tmp + y * W;
    for (int64_t x = 0; x < W; ++x) {
      float v = g[0] * r[0][x];  // in tap order, no fused multiply-add (built with -ffp-contract=off)
      for (int64_t j = 1; j < 5; ++j) v = v + g[j] * r[j][x];
      o[x] = v;
    }
  }
  for (int64_t y = 0; y < H; ++y) {
    const float* p = replicate2(tmp + y * W, W, buf);
    float* o = inv + y * W;
    for (int64_t x = 0; x < W; ++x) {
      float v = g[0] * p[x];
      for (int64_t j = 1; j < 5; ++j) v = v + g[j] * p[x + j];
      o[x] = std::min(std::max(top - v, lo), hi);
    }
  }
}

// One image: out (the completion), step (the fill step per pixel, or nullptr).
void complete_one(const float* s, float* out, uint8_t* step, int64_t H, int64_t W, float maxd, float top,
                  const float* g, Buffers& buf) {
  const int64_t n = H * W;
  buf.tmp.resize(n);
  buf.close.resize(n);
  float* tmp = buf.tmp.data();
  std::fill(out, out + n, 0.0f);
  const auto [lo, hi] = dilate(s, out, step, H, W, maxd, top);
  if (!(lo <= hi)) return;  // no measurement: 0 (and every step 5)
  mark(step, out, n, 1);
  square<false>(out, tmp, buf.close.data(), H, W, 5, false, buf);
  square<true>(buf.close.data(), tmp, out, H, W, 5, false, buf);
  square<false>(out, tmp, out, H, W, 7, true, buf);
  mark(step, out, n, 2);
  extend_top(out, H, W, buf);
  mark(step, out, n, 3);
  for (int64_t k : {9, 17, 31}) square<false>(out, tmp, out, H, W, k, true, buf);
  mark(step, out, n, 4);
  extend_rows_then_columns(out, H, W, buf);
  median(out, tmp, H, W, buf);
  gauss_to_depth(out, tmp, H, W, g, top, lo, hi, buf);
}

// d^2(x) = min_x' (x - x')^2 + f(x') along one row of n (the lower envelope of parabolas, Felzenszwalb-Huttenlocher,
// in exact integer arithmetic).
void envelope(const float* f2, float* out, int64_t n, Buffers& buf) {
  std::vector<int32_t>& v = buf.ib;
  v.resize(n);
  buf.zn.resize(n + 1);
  buf.zd.resize(n + 1);
  int64_t* zn = buf.zn.data();  // the boundary between parabolas k - 1 and k: zn[k] / zd[k] (zd > 0)
  int64_t* zd = buf.zd.data();
  auto F = [&](int64_t q) { return static_cast<int64_t>(f2[q]) + q * q; };
  int64_t k = 0;
  v[0] = 0;
  for (int64_t q = 1; q < n; ++q) {
    int64_t num, den;
    while (true) {
      const int64_t p = v[k];
      num = F(q) - F(p);
      den = 2 * (q - p);
      if (k > 0 && num * zd[k] <= zn[k] * den) --k;
      else break;
    }
    ++k;
    v[k] = static_cast<int32_t>(q);
    zn[k] = num;
    zd[k] = den;
  }
  const int64_t last = k;
  k = 0;
  for (int64_t x = 0; x < n; ++x) {
    while (k < last && zn[k + 1] < x * zd[k + 1]) ++k;
    const int64_t dx = x - v[k];
    out[x] = static_cast<float>(dx * dx + static_cast<int64_t>(f2[v[k]]));
  }
}

// min_x' (x - x')^2 + f2[x'] over the offsets |x - x'| <= reach, along one row of n.
void offsets(const float* __restrict f2, float* __restrict out, int64_t n, int64_t reach) {
  std::copy(f2, f2 + n, out);
  for (int64_t k = 1; k <= reach && k < n; ++k) {
    const float kk = static_cast<float>(k * k);
    for (int64_t x = k; x < n; ++x) out[x] = std::min(out[x], f2[x - k] + kk);
    for (int64_t x = 0; x < n - k; ++x) out[x] = std::min(out[x], f2[x + k] + kk);
  }
}

// The row pass of one row in place: f2 -> min_x' (x - x')^2 + f2[x']. The offsets up to 8 first (vectorised); that is
// exact when every result is within 81 of the row's minimum (a farther offset cannot lower it), else the envelope.
void row_pass(float* row, int64_t W, Buffers& buf) {
  const int64_t reach = std::min<int64_t>(8, W - 1);
  const float bound = static_cast<float>((reach + 1) * (reach + 1));
  buf.tmp.resize(W);
  float* f = buf.tmp.data();
  std::copy(row, row + W, f);
  float lo = f[0];
  for (int64_t x = 1; x < W; ++x) lo = std::min(lo, f[x]);
  offsets(f, row, W, reach);
  bool exact = true;
  for (int64_t x = 0; x < W; ++x) exact &= row[x] - lo <= bound;
  if (!exact) envelope(f, row, W, buf);
}

// One image: the squared Euclidean distance to the nearest s > 0 (exact integers); false (out untouched) without one.
// The column pass (rows to the nearest measurement above and below, capped at H + W), then the rows in parallel.
bool distance_one(const float* s, float* out, int64_t H, int64_t W, Buffers& buf) {
  const int64_t n = H * W;
  const int32_t far = static_cast<int32_t>(H + W);
  bool any = false;
  for (int64_t i = 0; i < n && !any; ++i) any = s[i] > 0;
  if (!any) return false;
  buf.ia.resize(n + W);
  int32_t* up = buf.ia.data();
  int32_t* run = up + n;  // the count of each column since its last measurement
  std::fill(run, run + W, far);
  for (int64_t y = 0; y < H; ++y)
    for (int64_t x = 0; x < W; ++x) {
      run[x] = s[y * W + x] > 0 ? 0 : std::min(run[x] + 1, far);
      up[y * W + x] = run[x];
    }
  std::fill(run, run + W, far);
  for (int64_t y = H - 1; y >= 0; --y)
    for (int64_t x = 0; x < W; ++x) {
      run[x] = s[y * W + x] > 0 ? 0 : std::min(run[x] + 1, far);
      const float c = static_cast<float>(std::min(up[y * W + x], run[x]));
      out[y * W + x] = c * c;
    }
  at::parallel_for(0, H, 16, [&](int64_t y0, int64_t y1) {
    for (int64_t y = y0; y < y1; ++y) row_pass(out + y * W, W, buffers);  // this thread's buffers
  });
  return true;
}

void check(const torch::Tensor& t) {
  TORCH_CHECK(t.dim() == 4 && t.size(1) == 1 && t.scalar_type() == torch::kFloat32 && t.is_contiguous() &&
                  t.device().is_cpu(), "expected a contiguous float32 (B, 1, H, W) CPU tensor");
}

}  // namespace

// The classical completion of sparse (B, 1, H, W): {completion, fill step (int64; empty unless with_step)}.
// gauss: the 5 weights of the Gaussian.
std::vector<torch::Tensor> complete(torch::Tensor sparse, double max_depth, torch::Tensor gauss, bool with_step) {
  check(sparse);
  const int64_t B = sparse.size(0), H = sparse.size(2), W = sparse.size(3), n = H * W;
  torch::Tensor out = torch::empty_like(sparse);
  const auto int64 = sparse.options().dtype(torch::kInt64);
  torch::Tensor step = with_step ? torch::empty(sparse.sizes(), int64) : torch::empty({0}, int64);
  const float maxd = static_cast<float>(max_depth), top = static_cast<float>(max_depth + 1.0);
  const torch::Tensor g = gauss.to(torch::kFloat32).contiguous();
  const float* gp = g.data_ptr<float>();
  const float* s = sparse.data_ptr<float>();
  float* o = out.data_ptr<float>();
  int64_t* st = with_step ? step.data_ptr<int64_t>() : nullptr;
  if (n == 0) return {out, step};
  at::parallel_for(0, B, 1, [&](int64_t b0, int64_t b1) {
    Buffers& buf = buffers;
    for (int64_t b = b0; b < b1; ++b) {
      if (with_step) buf.step.resize(n);
      uint8_t* sb = with_step ? buf.step.data() : nullptr;
      complete_one(s + b * n, o + b * n, sb, H, W, maxd, top, gp, buf);
      if (with_step) std::copy(sb, sb + n, st + b * n);
    }
  });
  return {out, step};
}

// The squared Euclidean distance in pixels from each pixel of sparse (B, 1, H, W) to the nearest one > 0, and per
// image whether it has one (bool, B; the distances of an image without are undefined). The square root is left to
// torch, whose float sqrt is not always the correctly rounded one: the same function gives the same bits.
std::vector<torch::Tensor> lidar_distance2(torch::Tensor sparse) {
  check(sparse);
  const int64_t B = sparse.size(0), H = sparse.size(2), W = sparse.size(3), n = H * W;
  torch::Tensor out = torch::empty_like(sparse);
  torch::Tensor has = torch::zeros({B}, sparse.options().dtype(torch::kBool));
  if (n == 0) return {out, has};
  const float* s = sparse.data_ptr<float>();
  float* o = out.data_ptr<float>();
  bool* h = has.data_ptr<bool>();
  at::parallel_for(0, B, 1, [&](int64_t b0, int64_t b1) {
    for (int64_t b = b0; b < b1; ++b) h[b] = distance_one(s + b * n, o + b * n, H, W, buffers);
  });
  return {out, has};
}
"""

#: The compiled extension (a new name for new sources), built on first use.
KERNEL = InlineKernel(
    "semattnet_anchor_v3",
    _SOURCE,
    ["complete", "lidar_distance2"],
    what="the CPU classical-completion kernel",
    fallback="the PyTorch classical completion",
    cflags=["-ffp-contract=off"],  # the Gaussian's sums as PyTorch's, to the bit
)


def available() -> bool:
    """Whether the compiled kernel can be used (builds it on the first call)."""
    return KERNEL.available()


def usable(sparse: torch.Tensor, impl: KernelImpl = "auto") -> bool:
    """Whether ``sparse`` goes through the kernel: ``impl`` "auto", a float32 CPU tensor that needs no gradient,
    not while tracing or exporting, and the kernel available."""
    if impl != "auto" or sparse.device.type != "cpu" or sparse.dtype != torch.float32:
        return False
    if (torch.is_grad_enabled() and sparse.requires_grad) or is_tracing():
        return False
    return available()


def complete(
    sparse: torch.Tensor, max_depth: float, gauss: torch.Tensor, with_step: bool = True
) -> tuple[torch.Tensor, torch.Tensor | None]:
    """The completion of checked (B, 1, H, W) float32 CPU ``sparse`` and its fill step (int64; None unless
    ``with_step``); ``gauss``: the 5 weights of the smoothing Gaussian."""
    module = KERNEL.require()
    out, step = module.complete(sparse.contiguous(), float(max_depth), gauss, bool(with_step))  # type: ignore[attr-defined]
    return out, step if with_step else None


def distance(sparse: torch.Tensor) -> torch.Tensor:
    """:func:`semattnet.models.uncertainty.lidar_distance` of (B, 1, H, W) float32 CPU ``sparse``."""
    module = KERNEL.require()
    d2, has = module.lidar_distance2(sparse.contiguous())  # type: ignore[attr-defined]
    out: torch.Tensor = d2.sqrt_()  # torch's sqrt, as the PyTorch path's
    if not bool(has.all()):
        out[~has] = float(sparse.shape[-2] + sparse.shape[-1])
    return out
