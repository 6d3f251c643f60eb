"""The trainer's validation pass: the model being trained, as it is (not folded for inference), over the
validation loader's batches, scored with the dataset's metrics. ``semattnet evaluate`` scores a finished model
through the one frame loop instead (:func:`semattnet.evaluation.evaluate_split`)."""

from __future__ import annotations

from collections.abc import Callable
from functools import partial

import torch
from torch import nn
from torch.utils.data import DataLoader

from semattnet._utils import distributed as dist_utils
from semattnet._utils.device import autocast
from semattnet._utils.progress import progress as progress_bar
from semattnet.evaluation.metrics import KittiMetrics
from semattnet.inference.padding import crop_padding

__all__ = ["validate_model"]


def validate_model(
    model: nn.Module,
    loader: DataLoader,
    device: torch.device,
    amp: str = "none",
    metrics: Callable[[], KittiMetrics] = KittiMetrics,
    progress: bool = True,
) -> KittiMetrics:
    """Score ``model`` over ``loader`` on every rank (each its shard), the metrics summed over the ranks.

    Items that carry a ``pad`` (padded to the model's multiple of 32 by
    :class:`~semattnet.data.datasets.frames.FrameDataset`) are scored on the crop without it.
    """
    scores = metrics()
    was_training = model.training
    model.eval()
    with torch.inference_mode():
        for batch in progress_bar(loader, desc="validating", enabled=progress and dist_utils.is_main(), leave=False):
            x = {k: batch[k].to(device, non_blocking=True) for k in ("rgb", "semantic", "sparse")}
            with autocast(device, amp):
                out = model(**x)
            if "gt" not in batch:
                continue
            gt = batch["gt"]
            if "pad" in batch:  # padded by the dataset: score the protocol's crop
                top, bottom, left, right = (int(v) for v in batch["pad"][0].tolist())
                crop = partial(crop_padding, pad=(top, bottom, left, right))
                out, gt = out.map(crop), crop(gt)
            scores.update(out.depth.float(), gt.to(device), names=list(batch["name"]))
    model.train(was_training)
    scores.reduce()
    return scores
