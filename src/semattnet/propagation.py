"""CSPN++ propagation with atrous (dilated) neighbourhoods (paper Sec. III-C, eq. 13).

One step of the convolutional spatial propagation network, in the form the authors' code
computes it: for a k x k window with raster offsets ``o_t`` (scaled by the dilation) and centre
``c``,

    h'(p) = sum_{t != c} W_t(p - o_t) * h(p - o_t) + W_c(p) * h_0(p)

where ``W`` is the normalised affinity of eq. 13 (``W_t = g_t / sum |g|``, ``W_c = 1 - sum g``),
the affinity is taken at the *neighbour* position, ``h`` and ``W`` are zero outside the image,
and ``h_0`` is the fixed input of the propagation. Every pixel spreads ``W_t h`` to its
neighbours. Since ``W`` is fixed during a stage, we move each tap's weight to the pixel it is
sent to once per stage (:func:`shift_affinity`); every step is then one fused in-place
multiply-add per tap over the overlapping window (:func:`propagate_shifted`), with a hand-written
backward of the same form. No padded k*k copies of the image are made per step (the authors'
pad-and-sum built 2 * k * k of them).
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from .layers import convbn

__all__ = [
    "AffinityHead",
    "cspn_affinity",
    "downsample_sparse",
    "propagate",
    "propagate_pad_and_sum",
    "propagate_shifted",
    "shift_affinity",
]


def cspn_affinity(guide: torch.Tensor) -> torch.Tensor:
    """Normalise raw guidance into a CSPN kernel (eq. 13).

    Args:
        guide: (B, k*k - 1, H, W) unnormalised affinities of the neighbours.

    Returns:
        (B, k*k, H, W) weights in raster order, the centre weight ``1 - sum_t W_t`` inserted at
        index (k*k - 1) / 2. Like the authors' code there is no epsilon in the normaliser.
    """
    g = guide / guide.abs().sum(dim=1, keepdim=True)
    centre = 1.0 - g.sum(dim=1, keepdim=True)
    half = g.shape[1] // 2
    return torch.cat((g[:, :half], centre, g[:, half:]), dim=1)


class AffinityHead(nn.Module):
    """3x3 conv + BN producing a k x k CSPN kernel per pixel (the authors' ``CSPNGenerate``).

    Args:
        in_channels: width of the guidance features.
        kernel_size: propagation window k (odd).
    """

    def __init__(self, in_channels: int, kernel_size: int) -> None:
        super().__init__()
        self.kernel_size = kernel_size
        self.generate = convbn(in_channels, kernel_size * kernel_size - 1)

    def forward(self, feature: torch.Tensor) -> torch.Tensor:
        return cspn_affinity(self.generate(feature))


def _taps(k: int, dilation: int, height: int, width: int):  # type: ignore[no-untyped-def]
    """For every non-centre tap t: (t, destination slices, source slices) with dst = src + o_t."""
    r = k // 2
    for t in range(k * k):
        if t == (k * k) // 2:
            continue
        oy, ox = (t // k - r) * dilation, (t % k - r) * dilation
        if abs(oy) >= height or abs(ox) >= width:
            continue
        dst = (slice(max(oy, 0), height + min(oy, 0)), slice(max(ox, 0), width + min(ox, 0)))
        src = (slice(max(-oy, 0), height - max(oy, 0)), slice(max(-ox, 0), width - max(ox, 0)))
        yield t, dst, src


def _kernel_size(affinity: torch.Tensor) -> int:
    kk = affinity.shape[1]
    k = math.isqrt(kk)
    if k * k != kk or k % 2 == 0:
        raise ValueError(f"affinity must have k*k channels for an odd k, got {kk}")
    return k


class _ShiftAffinity(torch.autograd.Function):
    """``S_t(p) = W_t(p - o_t)``: one window copy per tap; the backward is the adjoint copy.

    (Slice assignments under autograd would clone the whole k*k-channel gradient once per tap.)
    """

    @staticmethod
    def forward(ctx, affinity: torch.Tensor, dilation: int) -> torch.Tensor:  # type: ignore[override]
        ctx.dilation = dilation
        return _shift_windows(affinity, dilation, adjoint=False)

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, grad: torch.Tensor):  # type: ignore[no-untyped-def, override]
        return _shift_windows(grad, ctx.dilation, adjoint=True), None


def _shift_windows(x: torch.Tensor, dilation: int, adjoint: bool) -> torch.Tensor:
    k = math.isqrt(x.shape[1])
    centre = (k * k) // 2
    out = torch.zeros_like(x, memory_format=torch.contiguous_format)
    out[:, centre] = x[:, centre]
    for t, dst, src in _taps(k, dilation, *x.shape[-2:]):
        if adjoint:
            dst, src = src, dst
        out[:, t, dst[0], dst[1]] = x[:, t, src[0], src[1]]
    return out


def shift_affinity(affinity: torch.Tensor, dilation: int = 1) -> torch.Tensor:
    """Move each tap's weight to the pixel it is sent to: ``S_t(p) = W_t(p - o_t)`` (0 outside).

    The affinity is fixed during a stage, so this is done once and every step then reads
    ``S_t(p) * h(p - o_t)``. The centre channel is unchanged (its offset is 0).
    """
    _kernel_size(affinity)
    if _exporting():
        return _shift_functional(affinity, dilation)
    return _ShiftAffinity.apply(affinity, dilation)


class _ShiftedPropagation(torch.autograd.Function):
    """``h'(p) = sum_{t != c} S_t(p) h(p - o_t) + S_c(p) h_0(p)`` by in-place shifted multiply-adds.

    One fused multiply-add per tap over the overlapping window, no k*k buffers; the backward
    pass is the same kind of loop (the adjoint shifts).
    """

    @staticmethod
    def forward(ctx, shifted: torch.Tensor, h: torch.Tensor, h0: torch.Tensor, dilation: int) -> torch.Tensor:  # type: ignore[override]
        k = math.isqrt(shifted.shape[1])
        c = (k * k) // 2
        height, width = h.shape[-2:]
        out = shifted[:, c : c + 1] * h0
        for t, (dy, dx), (sy, sx) in _taps(k, dilation, height, width):
            out[:, :, dy, dx].addcmul_(shifted[:, t : t + 1, dy, dx], h[:, :, sy, sx])
        ctx.save_for_backward(shifted, h, h0)
        ctx.dilation = dilation
        return out

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, grad: torch.Tensor):  # type: ignore[no-untyped-def, override]
        shifted, h, h0 = ctx.saved_tensors
        k = math.isqrt(shifted.shape[1])
        c = (k * k) // 2
        height, width = h.shape[-2:]
        grad_shifted = grad_h = grad_h0 = None
        if ctx.needs_input_grad[0]:
            grad_shifted = torch.zeros_like(shifted)
            grad_shifted[:, c] = (grad * h0).sum(dim=1)
            for t, (dy, dx), (sy, sx) in _taps(k, ctx.dilation, height, width):
                grad_shifted[:, t, dy, dx] = (grad[:, :, dy, dx] * h[:, :, sy, sx]).sum(dim=1)
        if ctx.needs_input_grad[1]:
            grad_h = torch.zeros_like(h)
            for t, (dy, dx), (sy, sx) in _taps(k, ctx.dilation, height, width):
                grad_h[:, :, sy, sx].addcmul_(grad[:, :, dy, dx], shifted[:, t : t + 1, dy, dx])
        if ctx.needs_input_grad[2]:
            grad_h0 = grad * shifted[:, c : c + 1]
        return grad_shifted, grad_h, grad_h0, None


def _exporting() -> bool:
    """Tracing for ONNX / TorchScript or compiling: use plain tensor ops (no in-place, no autograd.Function)."""
    return torch.onnx.is_in_onnx_export() or torch.jit.is_tracing() or torch.compiler.is_compiling()


def _window(x: torch.Tensor, oy: int, ox: int) -> torch.Tensor:
    """``x(p - o)`` for every p (zero outside the image), by one pad and one slice."""
    height, width = x.shape[-2:]
    py, px = abs(oy), abs(ox)
    padded = F.pad(x, (px, px, py, py))
    return padded[..., py - oy : py - oy + height, px - ox : px - ox + width]


def _shift_functional(affinity: torch.Tensor, dilation: int) -> torch.Tensor:
    k = _kernel_size(affinity)
    r = k // 2
    taps = []
    for t in range(k * k):
        oy, ox = (t // k - r) * dilation, (t % k - r) * dilation
        taps.append(_window(affinity[:, t : t + 1], oy, ox))
    return torch.cat(taps, dim=1)


def _propagate_functional(shifted: torch.Tensor, h: torch.Tensor, h0: torch.Tensor, dilation: int) -> torch.Tensor:
    k = _kernel_size(shifted)
    r, c = k // 2, (k * k) // 2
    out = shifted[:, c : c + 1] * h0
    for t in range(k * k):
        if t != c:
            oy, ox = (t // k - r) * dilation, (t % k - r) * dilation
            out = out + shifted[:, t : t + 1] * _window(h, oy, ox)
    return out


def propagate_shifted(shifted: torch.Tensor, h: torch.Tensor, h0: torch.Tensor, dilation: int = 1) -> torch.Tensor:
    """One CSPN++ step from a kernel already passed through :func:`shift_affinity`."""
    _kernel_size(shifted)
    h0 = h0.expand_as(h)
    if _exporting():
        return _propagate_functional(shifted, h, h0, dilation)
    return _ShiftedPropagation.apply(shifted, h, h0, dilation)


def propagate(affinity: torch.Tensor, h: torch.Tensor, h0: torch.Tensor, dilation: int = 1) -> torch.Tensor:
    """One CSPN++ step (module docstring) for every channel of ``h`` with one shared kernel.

    Args:
        affinity: (B, k*k, H, W) normalised kernel from :func:`cspn_affinity`.
        h: (B, C, H, W) current estimate h_n; the C channels (e.g. the four polyphase
            sub-grids of the dilation-2 stage) are propagated independently.
        h0: (B, C, H, W) fixed input h_0 weighted by the centre tap.
        dilation: spacing of the window taps.

    Returns:
        (B, C, H, W) the next estimate h_{n+1}. For several steps with one kernel, shift it once
        with :func:`shift_affinity` and call :func:`propagate_shifted`.
    """
    return propagate_shifted(shift_affinity(affinity, dilation), h, h0, dilation)


def downsample_sparse(sparse: torch.Tensor, factor: int = 2) -> tuple[torch.Tensor, torch.Tensor]:
    """Sparse depth at 1/factor resolution: the nearest (minimum) valid depth of each block.

    Returns:
        ``(depth, mask)``: depth (0 where a block has no measurement) and a float mask of the
        blocks holding at least one measurement, each (B, 1, H/factor, W/factor).
    """
    valid = sparse > 0
    nearest = -F.max_pool2d(-torch.where(valid, sparse, torch.full_like(sparse, math.inf)), factor)
    mask = F.max_pool2d(valid.to(sparse.dtype), factor)
    return torch.where(mask > 0, nearest, torch.zeros_like(nearest)), mask


def propagate_pad_and_sum(affinity: torch.Tensor, h: torch.Tensor, h0: torch.Tensor, dilation: int = 1) -> torch.Tensor:
    """The authors' pattern for one step, kept as the *naive reference* for benchmarks and tests.

    Every weight channel and the current depth are zero-padded into k*k full-size shifted
    copies, stacked, multiplied, summed and cropped: 2 * k * k padded (H + 2r) x (W + 2r)
    tensors per step (rebuilt from the update rule of the spec, not their code). Same result
    as :func:`propagate`.
    """
    k = _kernel_size(affinity)
    r = (k // 2) * dilation
    centre = (k * k) // 2
    height, width = affinity.shape[-2:]
    weights, depths = [], []
    for t in range(k * k):
        i, j = divmod(t, k)
        top, left = r + (i - k // 2) * dilation, r + (j - k // 2) * dilation
        pads = (left, 2 * r - left, top, 2 * r - top)
        weights.append(F.pad(affinity[:, t : t + 1], pads))
        depths.append(F.pad(h0 if t == centre else h, pads))
    total = (torch.stack(weights) * torch.stack(depths)).sum(dim=0)
    return total[:, :, r : r + height, r : r + width]
