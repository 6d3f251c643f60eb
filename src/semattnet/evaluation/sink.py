"""The metrics of ``evaluate`` as an output sink of the one frame loop
(:func:`semattnet.inference.pipeline.complete_frames`): every completed frame with ground truth is scored as its
16-bit PNG stores it (``pred.stored``: the one clamp / hole rule and the one quantiser), and its uncertainty's
sparsification curves added."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import torch

from semattnet.evaluation.metrics import KittiMetrics
from semattnet.evaluation.sparsification import Sparsification
from semattnet.inference.sinks import Prediction, Sink

__all__ = ["MetricsSink"]


@dataclass
class MetricsSink(Sink):
    """Writes no file: accumulates ``metrics`` (the protocol's: :func:`~.protocols.protocol_metrics`) and the
    uncertainty's ``sparsification`` of every frame that has ground truth, on this process (reduce them over
    the ranks afterwards: :meth:`KittiMetrics.reduce`, :meth:`Sparsification.reduce`)."""

    metrics: KittiMetrics = field(default_factory=KittiMetrics)
    sparsification: Sparsification = field(default_factory=Sparsification)

    def path(self, name: str) -> str | None:
        return None

    def write(self, stage: Path, pred: Prediction) -> None:
        frame = pred.frame
        if frame.gt is None:
            return
        depth, gt = torch.from_numpy(pred.stored), torch.from_numpy(frame.gt)
        self.metrics.update(depth[None, None], gt[None, None], names=[frame.name])
        uncertainty = pred.completion.uncertainty  # as the method gave it (not cleaned at the holes)
        if uncertainty is not None:
            self.sparsification.add(depth, gt, torch.from_numpy(uncertainty))
