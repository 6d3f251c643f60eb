"""A classical (non-learned) depth completion baseline in the spirit of IP-Basic (Ku et al.,
"In Defense of Classical Image Processing: Fast Depth Completion on the CPU", CRV 2018).

The algorithm (morphology on inverted depth, bounded by its input, about 40 ms of one CPU core at 375x1242)
lives in :mod:`semattnet.models.anchor`, where the generalist reads it as its anchor; this module is the
baseline around it: its per-pixel uncertainty and the :class:`ClassicalCompleter` that ``--method classical``
runs.
"""

from __future__ import annotations

import numpy as np
import torch

from semattnet.inference.completer import Completion
from semattnet.models.anchor import FILL_STEPS, classical_fill_step, complete_classical
from semattnet.models.checks import check_has_points
from semattnet.models.uncertainty import anchor_term

__all__ = ["FILL_STEPS", "ClassicalCompleter", "classical_fill_step", "classical_uncertainty", "complete_classical"]


def classical_uncertainty(
    sparse: torch.Tensor, depth: torch.Tensor | None = None, max_depth: float = 100.0
) -> torch.Tensor:
    """A per-pixel uncertainty of :func:`complete_classical` in metres, (B, 1, H, W), from its own construction.

    Every filled pixel copies (a maximum, median or mean of) measurements up to ``r`` pixels away, ``r`` the
    distance to the nearest measurement (:func:`semattnet.models.uncertainty.lidar_distance`): to first order
    it is off by the depth change over that distance plus its own pixel, ``(r + 1) g``, ``g`` the local slope
    of the completed ``depth`` in metres per pixel (:func:`semattnet.models.uncertainty.anchor_term`, the
    model's anchor term). Measured on the demo's held-out scenes it ranks the errors better than the distance
    alone or the fill step (:func:`classical_fill_step`); see ``docs/guides/uncertainty.md``. ``depth``: the
    completion of ``sparse`` when already computed.
    """
    if depth is None:
        depth = complete_classical(sparse, max_depth)
    return anchor_term(sparse, depth)


class ClassicalCompleter:
    """:func:`complete_classical` behind the :class:`~semattnet.inference.DepthCompleter` call:
    ``completer(rgb, sparse, semantic=None)`` -> ``Completion`` (the image and semantics are unused)."""

    needs_semantic = False
    #: Every completion has its uncertainty (:func:`classical_uncertainty`): a live node advertises it.
    gives_uncertainty = True
    #: Unused (it reads no semantic map); the frame loop's :class:`~semattnet.inference.pipeline.Completer` asks.
    palette = "cityscapes"
    device = "cpu"

    def __call__(self, rgb: np.ndarray, sparse: np.ndarray, semantic: np.ndarray | None = None) -> Completion:
        t = torch.from_numpy(np.ascontiguousarray(sparse, dtype=np.float32))
        check_has_points(t)
        dense = complete_classical(t[None, None])
        unc = classical_uncertainty(t[None, None], dense)
        return Completion(depth=dense[0, 0].numpy(), uncertainty=unc[0, 0].numpy())
