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

from semattnet.models.propagation._common import kernel_size, taps
from semattnet.models.propagation.export import exporting, propagate_functional, shift_functional

__all__ = ["propagate", "propagate_shifted", "shift_affinity"]


class _ShiftAffinity(torch.autograd.Function):
    """``S_t(p) = W_t(p - o_t)``: one window copy per tap; the backward is the adjoint copy.

    (Slice assignments under autograd would clone the whole k*k-channel gradient once per tap.)
    """

    @staticmethod
    def forward(ctx, affinity: torch.Tensor, dilation: int) -> torch.Tensor:
        ctx.dilation = dilation
        return _shift_windows(affinity, dilation, adjoint=False)

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, grad: torch.Tensor) -> tuple[torch.Tensor, None]:
        return _shift_windows(grad, ctx.dilation, adjoint=True), None


def _shift_windows(x: torch.Tensor, dilation: int, adjoint: bool) -> torch.Tensor:
    k = math.isqrt(x.shape[1])
    centre = (k * k) // 2
    out = torch.zeros_like(x, memory_format=torch.contiguous_format)
    out[:, centre] = x[:, centre]
    for t, dst, src in taps(k, dilation, *x.shape[-2:]):
        if adjoint:
            dst, src = src, dst
        out[:, t, dst[0], dst[1]] = x[:, t, src[0], src[1]]
    return out


def shift_affinity(affinity: torch.Tensor, dilation: int = 1) -> torch.Tensor:
    """Move each tap's weight to the pixel it is sent to: ``S_t(p) = W_t(p - o_t)`` (0 outside).

    The affinity is fixed during a stage, so this is done once and every step then reads
    ``S_t(p) * h(p - o_t)``. The centre channel is unchanged (its offset is 0).
    """
    kernel_size(affinity)
    if exporting():
        return torch.cat(shift_functional(affinity, dilation), dim=1)
    return _ShiftAffinity.apply(affinity, dilation)


class _ShiftedPropagation(torch.autograd.Function):
    """``h'(p) = sum_{t != c} S_t(p) h(p - o_t) + S_c(p) h_0(p)`` by in-place shifted multiply-adds.

    One fused multiply-add per tap over the overlapping window, no k*k buffers; the backward
    pass is the same kind of loop (the adjoint shifts).
    """

    @staticmethod
    def forward(ctx, shifted: torch.Tensor, h: torch.Tensor, h0: torch.Tensor, dilation: int) -> torch.Tensor:
        k = math.isqrt(shifted.shape[1])
        c = (k * k) // 2
        height, width = h.shape[-2:]
        out = shifted[:, c : c + 1] * h0
        for t, (dy, dx), (sy, sx) in taps(k, dilation, height, width):
            out[:, :, dy, dx].addcmul_(shifted[:, t : t + 1, dy, dx], h[:, :, sy, sx])
        ctx.save_for_backward(shifted, h, h0)
        ctx.dilation = dilation
        return out

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, grad: torch.Tensor) -> tuple[torch.Tensor | None, torch.Tensor | None, torch.Tensor | None, None]:
        shifted, h, h0 = ctx.saved_tensors
        k = math.isqrt(shifted.shape[1])
        c = (k * k) // 2
        height, width = h.shape[-2:]
        grad_shifted: torch.Tensor | None = None
        grad_h: torch.Tensor | None = None
        grad_h0: torch.Tensor | None = None
        if ctx.needs_input_grad[0]:
            grad_shifted = torch.zeros_like(shifted)
            grad_shifted[:, c] = (grad * h0).sum(dim=1)
            for t, (dy, dx), (sy, sx) in taps(k, ctx.dilation, height, width):
                grad_shifted[:, t, dy, dx] = (grad[:, :, dy, dx] * h[:, :, sy, sx]).sum(dim=1)
        if ctx.needs_input_grad[1]:
            grad_h = torch.zeros_like(h)
            for t, (dy, dx), (sy, sx) in taps(k, ctx.dilation, height, width):
                grad_h[:, :, sy, sx].addcmul_(grad[:, :, dy, dx], shifted[:, t : t + 1, dy, dx])
        if ctx.needs_input_grad[2]:
            grad_h0 = grad * shifted[:, c : c + 1]
        return grad_shifted, grad_h, grad_h0, None


def propagate_shifted(shifted: torch.Tensor, h: torch.Tensor, h0: torch.Tensor, dilation: int = 1) -> torch.Tensor:
    """One CSPN++ step from a kernel already passed through :func:`shift_affinity`."""
    kernel_size(shifted)
    h0 = h0.expand_as(h)
    if exporting():
        return propagate_functional(shifted.split(1, dim=1), h, h0, dilation)
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
