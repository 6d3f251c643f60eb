"""What evaluation reads of each registered dataset (:mod:`semattnet.data.datasets`): the frames a split is
scored on and the metrics of its protocol. Every dataset, KITTI included, goes through its registry entry."""

from __future__ import annotations

import os

from semattnet.data.datasets import DatasetSpec, get_dataset
from semattnet.data.datasets.frames import CroppedSource
from semattnet.data.frames import IndexedSource
from semattnet.evaluation.metrics import KittiMetrics, RangeMetrics

__all__ = ["eval_source", "protocol_metrics"]

PathLike = str | os.PathLike[str]


def protocol_metrics(dataset: str | DatasetSpec = "kitti-dc", keep_per_image: bool = True) -> KittiMetrics:
    """A fresh accumulator of the dataset's metrics: KITTI's devkit rule (:class:`KittiMetrics`, holes
    filled) for an entry without a ``clamp``, else the range protocol (:class:`RangeMetrics`: NYU v2's
    0.1-10 m, VOID's 0.2-5 m) with the entry's table columns."""
    spec = get_dataset(dataset)
    if spec.clamp is None:
        return KittiMetrics(keep_per_image=keep_per_image)
    return RangeMetrics(
        keep_per_image=keep_per_image,
        min_depth=spec.depth_range[0],
        max_depth=spec.depth_range[1],
        clamp=spec.clamp,
        columns=spec.columns,
    )


def eval_source(
    dataset: str | DatasetSpec,
    data: PathLike,
    split: str | None = None,
    *,
    raw_root: PathLike | None = None,
    semantic_root: PathLike | None = None,
    max_frames: int | None = None,
) -> IndexedSource:
    """The frames of ``split`` (default: the entry's evaluation split; ``max_frames``: the first ones) as the
    protocol scores them: the entry's frame source, bottom-cropped where
    :meth:`~semattnet.data.datasets.DatasetSpec.eval_crop` says (KITTI's full ``val``: 352x1216)."""
    spec = get_dataset(dataset)
    split = spec.check_split(split)
    source = spec.source(data, split, raw_root=raw_root, semantic_root=semantic_root, max_frames=max_frames)
    crop = spec.eval_crop(split, source.load(source.names[0]).size) if source.names else None
    return source if crop is None else CroppedSource(source, crop)
