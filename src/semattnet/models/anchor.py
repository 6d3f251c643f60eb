"""The classical (non-learned) depth completion, the algorithm itself: the baseline of
:mod:`semattnet.baselines.classical` and the generalist's anchor (:mod:`semattnet.models.generalist`).

Morphology on inverted depth (``max_depth - d``), so that a dilation prefers the nearer surface:

1. dilation with a diamond, larger for near points (they are sparser in the image);
2. a closing, then filling of small holes;
3. extension of each column's top value upwards (no LiDAR above the top beam);
4. filling of large holes with growing square kernels;
5. extrapolation to every remaining pixel: along each row from the nearest filled pixel, then along
   each column (the corner below and beside the LiDAR's field of view);
6. median and Gaussian smoothing.

Every step takes a maximum, a median or a weighted mean of measured values, so the output is bounded
by the input: every pixel lies in ``[min, max]`` of the valid input depths (inputs above ``max_depth``
count as ``max_depth``). An image without any measurement stays 0. No learning, no RGB.

Two implementations with the same values: PyTorch (CPU or GPU; the reference) and, for float32 CPU tensors outside
autograd, the C++ kernel of :mod:`semattnet.models.anchor_kernel`. On an AMD EPYC (AVX2, no AVX-512; 2 cores busy
with other jobs, load ~10, so every number is inflated), the KITTI frame cropped to 352x1216, one thread, medians
taken in turns (``benchmarks/bench_classical.py``, 2026-12-07): the completion 100-515 ms in PyTorch against 12-76 ms
in C++ (7-12x faster whatever the load), the kernel's stages summing to 5.6 ms at best (a standalone build of the
same code, the fastest of 40 runs).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from semattnet._errors import InputError
from semattnet.models import anchor_kernel
from semattnet.models.anchor_kernel import KernelImpl
from semattnet.models.checks import check_sparse_depth

__all__ = ["FILL_STEPS", "classical_fill_step", "complete_classical"]

#: (far limit in metres, diamond radius): points nearer than the limit get that dilation radius.
_DILATION_BANDS = ((15.0, 3), (30.0, 2), (float("inf"), 1))
_LARGE_FILLS = (9, 17, 31)  # square kernels of the large-hole fills, in turn
_CLOSE = 5  # closing kernel (square)


def _max_run(x: torch.Tensor, size: int, dim: int) -> torch.Tensor:
    """Maximum over a centred window of ``size`` (odd) pixels along ``dim``, by doubling: O(log size)."""
    r, n = size // 2, x.shape[dim]
    pad = [0, 0, 0, 0]
    pad[0 if dim == -1 else 2] = pad[1 if dim == -1 else 3] = r
    p = F.pad(x, pad, value=float("-inf"))
    m, width = p, 1  # m[i] = max of p[i : i + width]
    while width * 2 <= size:
        m = torch.maximum(m.narrow(dim, 0, m.shape[dim] - width), m.narrow(dim, width, m.shape[dim] - width))
        width *= 2
    rest = size - width
    if rest:
        m = torch.maximum(m.narrow(dim, 0, m.shape[dim] - rest), m.narrow(dim, rest, m.shape[dim] - rest))
    return m.narrow(dim, 0, n)


def _cross(x: torch.Tensor) -> torch.Tensor:
    """Grey dilation with the 3x3 cross (diamond of radius 1)."""
    return torch.maximum(_max_run(x, 3, -1), _max_run(x, 3, -2))


def _diamond(x: torch.Tensor, radius: int) -> torch.Tensor:
    """Grey dilation with a diamond of ``radius`` (repeated crosses)."""
    for _ in range(radius):
        x = _cross(x)
    return x


def _square(x: torch.Tensor, size: int) -> torch.Tensor:
    """Grey dilation with a ``size`` x ``size`` square (separable)."""
    return _max_run(_max_run(x, size, -2), size, -1)


def _fill(x: torch.Tensor, dilated: torch.Tensor) -> torch.Tensor:
    """Empty (0) pixels take ``dilated``; the others keep their value."""
    return torch.where(x > 0, x, dilated.clamp_min(0))


def _nearest(has: torch.Tensor, dim: int) -> torch.Tensor:
    """For each position along ``dim``, the index of the nearest ``True`` of ``has`` (the one before, else the one
    after; ``n - 1`` where there is none)."""
    n = has.shape[dim]
    shape = [1] * has.dim()
    shape[dim] = n
    pos = torch.arange(n, device=has.device, dtype=torch.int32).view(shape).expand_as(has)
    before = torch.where(has, pos, torch.full_like(pos, -1)).cummax(dim=dim).values
    after = torch.where(has, pos, torch.full_like(pos, n)).flip(dim).cummin(dim=dim).values.flip(dim)
    near = torch.where((before >= 0) & ((pos - before <= after - pos) | (after >= n)), before, after)
    return near.clamp(0, n - 1).long()


def _extend_along(x: torch.Tensor, dim: int) -> torch.Tensor:
    """Empty pixels copy the nearest filled pixel along ``dim`` (the one before, else the one after)."""
    return _fill(x, torch.gather(x, dim, _nearest(x > 0, dim)))


def _extend_rows_then_columns(x: torch.Tensor) -> torch.Tensor:
    """:func:`_extend_along` the rows, then the columns, of (B, 1, H, W) ``x``, touching only what is empty: the
    rows with a hole and a filled pixel, then, as each row is then all filled or all empty, whole rows copied from
    the nearest filled row (the same values as extending every column)."""
    w = x.shape[-1]
    rows = x.reshape(-1, w)
    has = rows > 0
    todo = ((~has).any(-1) & has.any(-1)).nonzero().squeeze(1)
    if todo.numel():
        rows = rows.clone()
        rows[todo] = _extend_along(rows[todo], -1)
    x = rows.view_as(x)
    filled = (x > 0).any(-1, keepdim=True)  # (B, 1, H, 1)
    if bool(filled.all()):
        return x
    return _fill(x, torch.gather(x, -2, _nearest(filled, -2).expand_as(x)))


def _extend_top(x: torch.Tensor) -> torch.Tensor:
    """Above each column's top filled pixel, copy its value."""
    h = x.shape[-2]
    rows = torch.arange(h, device=x.device).view(1, 1, h, 1)
    top = torch.where(x > 0, rows, torch.full_like(rows, h)).amin(dim=-2, keepdim=True)
    top_val = torch.gather(x, -2, top.clamp(max=h - 1))
    return torch.where((rows < top) & (top < h), top_val, x)


def _median3(x: torch.Tensor, y: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
    return torch.maximum(torch.minimum(x, y), torch.minimum(torch.maximum(x, y), z))


def _median5_along(x: torch.Tensor, dim: int) -> torch.Tensor:
    """Median of the 5 centred pixels along ``dim`` (edges replicated), with a min/max network."""
    pad = (2, 2, 0, 0) if dim == -1 else (0, 0, 2, 2)
    p, n = F.pad(x, pad, mode="replicate"), x.shape[dim]
    a, b, c, d, e = (p.narrow(dim, k, n) for k in range(5))
    lo = torch.maximum(torch.minimum(a, b), torch.minimum(c, d))
    hi = torch.minimum(torch.maximum(a, b), torch.maximum(c, d))
    return _median3(e, lo, hi)


def _median5(x: torch.Tensor) -> torch.Tensor:
    """Separable 5x5 median: the median of 5 along rows, then along columns."""
    return _median5_along(_median5_along(x, -1), -2)


def _gauss_weights(device: torch.device | str = "cpu", dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """The 5 weights of the smoothing Gaussian (sigma 1 pixel, summing to 1)."""
    g = torch.exp(-(torch.arange(-2, 3, device=device, dtype=dtype) ** 2) / 2.0)
    return g / g.sum()


def _gauss_along(x: torch.Tensor, dim: int) -> torch.Tensor:
    """The 5-tap Gaussian along ``dim`` (edges replicated), its products summed in tap order (no fused multiply-add:
    the C++ kernel sums them the same way, to the bit)."""
    g = _gauss_weights(x.device, x.dtype)
    pad = (2, 2, 0, 0) if dim == -1 else (0, 0, 2, 2)
    p, n = F.pad(x, pad, mode="replicate"), x.shape[dim]
    out = g[0] * p.narrow(dim, 0, n)
    for k in range(1, 5):
        out = out + g[k] * p.narrow(dim, k, n)
    return out


def _gauss5(x: torch.Tensor) -> torch.Tensor:
    """Separable 5-tap Gaussian: along columns, then rows (edges replicated)."""
    return _gauss_along(_gauss_along(x, -2), -1)


def _dilate_by_depth(d: torch.Tensor, inv: torch.Tensor) -> torch.Tensor:
    """Multi-scale dilation: each depth band with its own diamond; the nearer surface wins overlaps."""
    out, low = torch.zeros_like(inv), 0.0
    for far, radius in _DILATION_BANDS:
        band = torch.where((d > low) & (d <= far), inv, torch.zeros_like(inv))
        out = torch.maximum(out, _diamond(band, radius))
        low = far
    return out


#: The fill steps of :func:`classical_fill_step`, by number.
FILL_STEPS = ("measured", "dilation", "closing", "top extension", "large-hole fill", "extrapolation")


def _complete(
    sparse: torch.Tensor, max_depth: float, impl: KernelImpl = "auto", with_step: bool = True
) -> tuple[torch.Tensor, torch.Tensor | None]:
    """The completion and, per pixel, the first step that filled it (an index into :data:`FILL_STEPS`; None
    when the kernel runs without ``with_step``): the C++ kernel where :func:`anchor_kernel.usable`, else
    :func:`_complete_torch`."""
    if sparse.dim() != 4 or sparse.shape[1] != 1:
        raise InputError(f"sparse must be (B, 1, H, W), got {tuple(sparse.shape)}")
    check_sparse_depth(sparse)  # NaN / inf / negative / too far: refused as the model refuses them
    if anchor_kernel.usable(sparse, impl):
        return anchor_kernel.complete(sparse, max_depth, _gauss_weights(), with_step)
    return _complete_torch(sparse, max_depth)


def _complete_torch(sparse: torch.Tensor, max_depth: float) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`_complete` in PyTorch (CPU or GPU): the reference."""
    d = sparse.float().clamp(0, max_depth)
    valid = d > 0
    step = torch.where(valid, 0, len(FILL_STEPS) - 1)

    def mark(x: torch.Tensor, k: int) -> None:
        step.copy_(torch.where((x > 0) & (step > k), k, step))

    inv = torch.where(d > 0, max_depth + 1.0 - d, torch.zeros_like(d))  # near = large, valid > 0
    inv = _dilate_by_depth(d, inv)
    mark(inv, 1)
    inv = -_square(-_square(inv, _CLOSE), _CLOSE)  # closing
    inv = _fill(inv, _square(inv, 7))
    mark(inv, 2)
    inv = _extend_top(inv)
    mark(inv, 3)
    for size in _LARGE_FILLS:
        inv = _fill(inv, _square(inv, size))
    mark(inv, 4)
    inv = _extend_rows_then_columns(inv)
    inv = _gauss5(_median5(inv))
    big = torch.finfo(d.dtype).max
    lo = torch.where(valid, d, torch.full_like(d, big)).amin(dim=(-2, -1), keepdim=True)
    hi = d.amax(dim=(-2, -1), keepdim=True)
    out = (max_depth + 1.0 - inv).clamp(lo, hi)
    return torch.where(valid.any(dim=(-2, -1), keepdim=True), out, torch.zeros_like(out)), step


def complete_classical(sparse: torch.Tensor, max_depth: float = 100.0, impl: KernelImpl = "auto") -> torch.Tensor:
    """Complete (B, 1, H, W) sparse depth in metres (0 = missing) without learning.

    Returns dense depth of the same shape: every pixel of an image with at least one measurement is
    filled, within ``[min, max]`` of that image's valid input (capped at ``max_depth``); an image
    without any measurement stays 0 (the per-frame :class:`ClassicalCompleter` refuses it). ``impl``: "auto" runs
    float32 CPU tensors outside autograd through the C++ kernel (:mod:`semattnet.models.anchor_kernel`, the same
    values) when it can be built, "pytorch" always the PyTorch path.

    Raises:
        InputError: NaN / infinite, negative or too large depth
            (:func:`semattnet.models.checks.check_sparse_depth`, as the model).
    """
    return _complete(sparse, max_depth, impl, with_step=False)[0]


def classical_fill_step(sparse: torch.Tensor, max_depth: float = 100.0, impl: KernelImpl = "auto") -> torch.Tensor:
    """(B, 1, H, W) int: the step of :func:`complete_classical` that first filled each pixel, an index into
    :data:`FILL_STEPS` (0 measured, 1 dilation, ..., 5 extrapolation); a later step reaches farther. ``impl``: as
    :func:`complete_classical`'s."""
    step = _complete(sparse, max_depth, impl)[1]
    assert step is not None  # asked for
    return step
