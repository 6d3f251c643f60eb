"""A per-pixel uncertainty for every completion, in metres, from what the model already computes.

No retraining: SemAttNet's three branch depths ``D_cg``, ``D_sg``, ``D_dg`` (paper eqs. 4, 7, 10)
are mixed by the per-pixel softmax weights ``w_i`` of eq. 12 into ``D_f``, which the two CSPN++
stages (eq. 13) refine into ``D_r``. Three signals say where that prediction is weak:

* the **branch spread** ``s = sqrt(sum_i w_i (D_i - D_f)^2)``: the weighted standard deviation of the
  mixture of eq. 12 around its own mean ``D_f`` (zero where the branches agree);
* the **refinement change** ``c = |D_r - D_f|``: how far propagation moved the fused depth (zero for
  the variants without refinement);
* the **anchor term** ``a = (r + 1) g``: ``r`` the distance in pixels to the nearest LiDAR measurement
  (an exact Euclidean distance transform of the sparse input), ``g`` the local slope of the final
  depth in metres per pixel. To first order a pixel ``r`` pixels from its nearest measurement can be
  wrong by the depth change between it and the anchor that constrains it, ``r g`` metres; the ``+ 1``
  is the pixel's own footprint: even a measured pixel is wrong by ``g`` when a depth edge is placed
  one pixel off (projection, interpolation), where most of the error of a completion lies.

:func:`depth_uncertainty` combines them as ``u = sqrt(s^2 + c^2 + a^2)`` (independent error
sources add in quadrature). The result is a disagreement measure in metres, not a calibrated
standard deviation: it ranks pixels (see :mod:`semattnet.evaluation.sparsification` and
``docs/guides/uncertainty.md`` for how well), it does not promise coverage.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Collection

import torch
import torch.nn.functional as F

from semattnet.models import anchor_kernel
from semattnet.models.anchor_kernel import KernelImpl
from semattnet.models.outputs import CONFIDENCE_OUTPUTS, DEPTH_OUTPUTS, DepthCompletionOutput, check_output_names

__all__ = [
    "UNCERTAINTY_READS",
    "anchor_term",
    "branch_spread",
    "depth_slope",
    "depth_uncertainty",
    "lidar_distance",
    "outputs_to_compute",
    "refinement_change",
    "with_uncertainty",
]

#: The outputs :func:`depth_uncertainty` reads: the branch depths and their fusion weights (:func:`branch_spread`),
#: the fused and the final depth (:func:`refinement_change`, :func:`anchor_term`).
UNCERTAINTY_READS: frozenset[str] = (
    frozenset({"color_depth", "semantic_depth", "guided_depth", "fused_depth"}) | CONFIDENCE_OUTPUTS | DEPTH_OUTPUTS
)

_ROWS_PER_CHECK = 8  # distance transform: the rows still open are re-counted every that many offsets


def branch_spread(output: DepthCompletionOutput) -> torch.Tensor:
    """``sqrt(sum_i w_i (D_i - D_f)^2)``: the spread of the mixture of eq. 12 around ``D_f``, (B, 1, H, W) metres.

    ``w_i`` are the fusion weights (``*_conf``, after the softmax, summing to 1) and ``D_i`` the branch
    depths of eqs. 4, 7 and 10 (two of them for the two-branch variants, where ``semantic_depth`` is None).
    """
    pairs = [
        (output.color_depth, output.color_conf),
        (output.semantic_depth, output.semantic_conf),
        (output.guided_depth, output.guided_conf),
    ]
    fused = output.fused_depth.float()
    var = torch.zeros_like(fused)
    for depth, weight in pairs:
        if depth is not None and weight is not None:
            var = var + weight.float() * (depth.float() - fused) ** 2
    return var.sqrt()


def refinement_change(output: DepthCompletionOutput) -> torch.Tensor:
    """``|D_r - D_f|``: what the CSPN++ refinement (eq. 13) changed, (B, 1, H, W) metres; zero without it."""
    fused = output.fused_depth.float()
    if output.refined_depth is None:
        return torch.zeros_like(fused)
    return (output.refined_depth.float() - fused).abs()


def lidar_distance(sparse: torch.Tensor, impl: KernelImpl = "auto") -> torch.Tensor:
    """Euclidean distance in pixels from every pixel to the nearest measured one (``sparse > 0``), (B, 1, H, W).

    Exact and separable: the distance to the nearest measurement in the same column, then, along each
    row, ``d^2(y, x) = min_x' (x - x')^2 + g^2(y, x')``. An image without measurements gets ``H + W``
    everywhere (farther than any pixel can be). ``impl``: "auto" runs float32 CPU tensors outside autograd through
    the C++ kernel (:mod:`semattnet.models.anchor_kernel`, the same distances) when it can be built, "pytorch"
    always the PyTorch path.
    """
    if sparse.dim() == 4 and sparse.shape[1] == 1 and anchor_kernel.usable(sparse, impl):
        return anchor_kernel.distance(sparse)
    b, _, h, w = sparse.shape
    far = float(h + w)
    valid = sparse > 0
    rows = torch.arange(h, device=sparse.device).view(1, 1, h, 1).expand(b, 1, h, w)
    big = h + w
    above = torch.where(valid, rows, torch.full_like(rows, -big)).cummax(dim=-2).values
    below = torch.where(valid, rows, torch.full_like(rows, h + big)).flip(-2).cummin(dim=-2).values.flip(-2)
    col = torch.minimum(rows - above, below - rows).float().clamp(max=far)
    g2 = (col * col).reshape(b * h, w)
    d2 = _row_pass(g2)
    out = d2.sqrt().reshape(b, 1, h, w)
    has = valid.flatten(1).any(dim=1).view(b, 1, 1, 1)
    return torch.where(has, out, torch.full_like(out, far))


def _row_pass(g2: torch.Tensor) -> torch.Tensor:
    """``min_x' (x - x')^2 + g2[x']`` along each row of (N, W) ``g2``: offsets ``k`` = 1, 2, ... while one can
    still lower a value of the row (``d2 - min(g2) > k^2``; final rows are left out, re-counted every few offsets)."""
    d2 = g2.clone()
    n, w = g2.shape
    floor = g2.amin(dim=1)
    active = torch.arange(n, device=g2.device)
    k = 1
    while k < w and active.numel():
        sub, src = d2.index_select(0, active), g2.index_select(0, active)
        for step in range(k, min(k + _ROWS_PER_CHECK, w)):
            off = float(step * step)
            sub[:, step:].clamp_(max=src[:, :-step] + off)
            sub[:, :-step].clamp_(max=src[:, step:] + off)
        d2.index_copy_(0, active, sub)
        k = min(k + _ROWS_PER_CHECK, w)
        active = active[(sub.amax(dim=1) - floor.index_select(0, active)) > k * k]
    return d2


def depth_slope(depth: torch.Tensor) -> torch.Tensor:
    """Local slope of ``depth`` in metres per pixel, (B, 1, H, W): the larger of the central differences
    along rows and columns (one-sided at the border), the largest over each 3x3 neighbourhood."""
    d = F.pad(depth.float(), (1, 1, 1, 1), mode="replicate")
    dx = (d[..., 1:-1, 2:] - d[..., 1:-1, :-2]).abs() / 2
    dy = (d[..., 2:, 1:-1] - d[..., :-2, 1:-1]).abs() / 2
    return F.max_pool2d(torch.maximum(dx, dy), 3, stride=1, padding=1)


def anchor_term(sparse: torch.Tensor, depth: torch.Tensor) -> torch.Tensor:
    """``(r + 1) g``: the distance ``r`` to the nearest measurement (pixels, :func:`lidar_distance`) plus the
    pixel's own footprint, times the local slope ``g`` of ``depth`` (metres per pixel, :func:`depth_slope`):
    to first order the depth change between the pixel and the anchor that constrains it, (B, 1, H, W) metres."""
    return (lidar_distance(sparse.to(depth.device)) + 1) * depth_slope(depth)


def depth_uncertainty(output: DepthCompletionOutput, sparse: torch.Tensor) -> torch.Tensor:
    """The per-pixel uncertainty of ``output.depth`` in metres, (B, 1, H, W), from the outputs and the sparse input.

    ``u = sqrt(s^2 + c^2 + a^2)``: :func:`branch_spread` (the mixture of eq. 12), :func:`refinement_change`
    (eq. 13) and :func:`anchor_term` (one plus the distance to the LiDAR, times the local slope). A
    disagreement measure, not a calibrated probability.
    """
    s = branch_spread(output)
    c = refinement_change(output)
    a = anchor_term(sparse, output.depth.float())
    return (s * s + c * c + a * a).sqrt()


def with_uncertainty(output: DepthCompletionOutput, sparse: torch.Tensor) -> DepthCompletionOutput:
    """A copy of ``output`` with its ``uncertainty`` field set by :func:`depth_uncertainty`."""
    return dataclasses.replace(output, uncertainty=depth_uncertainty(output, sparse))


def outputs_to_compute(asked: Collection[str] | None) -> frozenset[str] | None:
    """The model outputs to compute for the outputs ``asked`` (field names of
    :class:`~semattnet.models.outputs.DepthCompletionOutput`, ``uncertainty`` among them; None: all): those, and
    what :func:`depth_uncertainty` reads (:data:`UNCERTAINTY_READS`) when the uncertainty is asked. None: all.

    Raises:
        InputError: an unknown output name.
    """
    if asked is None:
        return None
    names = check_output_names(asked)
    return names | UNCERTAINTY_READS if "uncertainty" in names else names
