"""The dataset registry: every command's ``--dataset NAME`` (``kitti-dc``, the default; ``nyuv2``; ``void``).

Each entry (:class:`DatasetSpec`, frozen) knows its layout, splits, protocol crop, depth range, sparse
sampling, metrics and units, semantic palette, training recipe and archives, and builds from ONE reader both
the :class:`~semattnet.data.frames.FrameSource` that ``predict`` completes and the torch Dataset that
``train`` and ``evaluate`` read (:class:`~semattnet.data.datasets.frames.FrameDataset` wraps the source).

    >>> from semattnet.data.datasets import get_dataset
    >>> spec = get_dataset("nyuv2")
    >>> spec.crop, spec.depth_range, spec.sparse_samples, spec.palette
    ((228, 304), (0.1, 10.0), 500, 'nyu40')
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from semattnet._errors import InputError

__all__ = ["DATASETS", "DEFAULT_DATASET", "DatasetArchive", "DatasetSpec", "UnknownDatasetError", "check_split",
           "get_dataset"]  # fmt: skip

PathLike = str | os.PathLike[str]
DEFAULT_DATASET = "kitti-dc"
#: Where alexklwong/void-dataset's README (at b17f271) says the release zip is (OneDrive; its wget command).
VOID_RELEASE_URL = ("https://yaleedu-my.sharepoint.com/:u:/g/personal/alex_wong_yale_edu/"
                    "Ebwvk0Ji8HhNinmAcKI5vSkBEjJTIWlA8PXwKNQX_FvB7g?e=0Zqe7g&download=1")  # fmt: skip


class UnknownDatasetError(InputError):
    """A ``--dataset`` name that is not in :data:`DATASETS`."""


@dataclass(frozen=True)
class DatasetArchive:
    """One archive of a dataset: ``file`` (fetched from ``url``, or from ``MIRROR/file``), unpacked into ROOT
    (a leading folder named ``strip`` removed). ``url`` None: only a ``--mirror`` can fetch it."""

    file: str
    url: str | None
    strip: tuple[str, ...] = ()
    size: str | None = None


@dataclass(frozen=True)
class DatasetSpec:
    """One dataset and its protocol.

    Attributes:
        name, title: registry name and display name. layout: the folder layout (one line).
        splits: split names; ``train_split`` / ``eval_split`` the defaults of ``train`` / ``evaluate``.
        crop: the protocol's (H, W) (None: full frames). depth_range: metres scored (gt within).
        clamp: predictions clamped to this before scoring (None: KITTI's devkit rule, holes filled).
        sparse_samples: depth samples drawn per frame (None: the dataset's own sparse maps).
        units: ``mm`` or ``m`` (the metrics table). columns: keys of the metrics table.
        palette: the semantic palette of its maps. recipe: :class:`~semattnet.training.TrainConfig`
            defaults for ``train --dataset`` (starting points from the literature, see the docs).
        licence: the terms, named. archives: what ``data download`` fetches.
    """

    name: str
    title: str
    layout: str
    splits: tuple[str, ...]
    train_split: str
    eval_split: str
    crop: tuple[int, int] | None
    depth_range: tuple[float, float]
    clamp: tuple[float, float] | None
    sparse_samples: int | None
    units: str
    columns: tuple[str, ...]
    palette: str
    licence: str
    recipe: dict[str, Any] = field(default_factory=dict)
    archives: tuple[DatasetArchive, ...] = ()
    make_source: Callable[..., Any] | None = field(default=None, repr=False)

    def check_split(self, split: str | None, train: bool = False) -> str:
        """``split`` (default: the train / eval split) if this dataset has it."""
        split = split or (self.train_split if train else self.eval_split)
        if split not in self.splits:
            raise InputError(f"split: {self.name} has no split {split!r}; choose one of {', '.join(self.splits)}")
        return split

    def source(self, root: PathLike, split: str | None = None, *, semantic_root: PathLike | None = None,
               raw_root: PathLike | None = None, max_frames: int | None = None, seed: int = 0) -> Any:  # fmt: skip
        """The frames of ``split`` as a :class:`~semattnet.data.frames.FrameSource`."""
        split = self.check_split(split)
        if self.make_source is None:  # kitti-dc
            from semattnet.data.sources import KittiSplitSource

            return KittiSplitSource(root, split, raw_root, semantic_root, max_frames)
        kw = {"seed": seed} if self.sparse_samples else {}
        return self.make_source(root, split, semantic_root=semantic_root, max_frames=max_frames, **kw)

    def dataset(self, root: PathLike, split: str | None = None, *, train: bool = False, seed: int = 0,
                raw_root: PathLike | None = None, semantic_root: PathLike | None = None,
                config: Any = None) -> Any:  # fmt: skip
        """The torch Dataset of ``split``: augmented for training (``train``; ``config`` a
        :class:`~semattnet.training.TrainConfig` for KITTI's crop and jitter), else as the protocol scores it
        (the model's padding to multiples of 32 is the evaluation loop's; metrics on the protocol's crop)."""
        split = self.check_split(split, train)
        if self.make_source is None:
            return _kitti_dataset(root, split, train, seed, raw_root, semantic_root, config)
        from semattnet.data.datasets.frames import FrameDataset, IndoorTrainTransform

        transform = None
        if train:
            flip, jitter = (config.flip, config.jitter) if config is not None else (True, 0.1)
            transform = IndoorTrainTransform(self.sparse_samples, flip, jitter)
        return FrameDataset(self.source(root, split, semantic_root=semantic_root, seed=seed), transform, seed)

    def metrics(self, keep_per_image: bool = True) -> Any:
        """A fresh accumulator of this protocol's metrics (:mod:`semattnet.evaluation.metrics`)."""
        from semattnet.evaluation.metrics import KittiMetrics, RangeMetrics

        if self.clamp is None:
            return KittiMetrics(keep_per_image=keep_per_image)
        return RangeMetrics(keep_per_image=keep_per_image, min_depth=self.depth_range[0],
                            max_depth=self.depth_range[1], clamp=self.clamp, columns=self.columns)  # fmt: skip

    def check(self, roots: Sequence[PathLike], raw_root: PathLike | None = None,
              semantic_root: PathLike | None = None, sample: int | None = None,
              log: Callable[[str], None] = print) -> int:  # fmt: skip
        """``data check``: every split found under each root decoded; returns the number of problems."""
        if self.make_source is None:
            from semattnet.data.check import check_trees

            return check_trees(roots, raw_root, semantic_root, sample, log=log)
        from semattnet.data.datasets.check import check_sources

        return check_sources(self, roots, semantic_root, sample, log)


def _kitti_dataset(root: PathLike, split: str, train: bool, seed: int, raw_root: PathLike | None,
                   semantic_root: PathLike | None, cfg: Any) -> Any:  # fmt: skip
    from semattnet.data.kitti import KittiDepthCompletion
    from semattnet.data.transforms import TrainTransform

    if not train:
        from semattnet.evaluation.split import eval_dataset

        return eval_dataset(root, split, raw_root, semantic_root)
    t = TrainTransform(tuple(cfg.crop), cfg.random_crop_height or cfg.crop[0], cfg.flip, cfg.jitter) if cfg else (
        TrainTransform())  # fmt: skip
    return KittiDepthCompletion(root, split, raw_root, semantic_root, seed=seed, transform=t)


def _nyu_source(root: PathLike, split: str, **kw: Any) -> Any:
    from semattnet.data.datasets.nyuv2 import NyuV2Source

    return NyuV2Source(root, split, **kw)


def _void_source(root: PathLike, split: str, **kw: Any) -> Any:
    from semattnet.data.datasets.void import VoidSource

    return VoidSource(root, split, **kw)


_KITTI = DatasetSpec(
    "kitti-dc", "KITTI depth completion", "data_depth_{velodyne,annotated,selection}/, kitti_raw/, semantic/",
    ("train", "val", "val_select", "test"), "train", "val_select", (352, 1216), (0.0, 255.0), None, None, "mm",
    ("rmse_mm", "mae_mm", "irmse_per_km", "imae_per_km"), "cityscapes", "CC BY-NC-SA 3.0 (KITTI)",
)  # fmt: skip
_NYU = DatasetSpec(
    "nyuv2", "NYU Depth v2 (sparse-to-dense HDF5)", "train/<scene>/<NNNNN>.h5, val/official/<NNNNN>.h5",
    ("train", "test"), "train", "test", (228, 304), (0.1, 10.0), (0.0, 10.0), 500, "m",
    ("rmse", "abs_rel", "delta1", "delta2", "delta3", "mae", "irmse_per_km", "imae_per_km"), "nyu40",
    "NYU Depth v2: research use, cite Silberman et al. (ECCV 2012); the HDF5 conversion: Ma & Karaman",
    recipe={"epochs": 25, "batch_size": 12, "lr": 0.001, "lr_schedule": "cosine", "crop": (228, 304),
            "val_split": "test"},
    archives=(DatasetArchive("nyudepthv2.tar.gz", "http://datasets.lids.mit.edu/sparse-to-dense/data/nyudepthv2.tar.gz",
                             ("nyudepthv2",), "about 32 GB"),),
    make_source=_nyu_source,
)  # fmt: skip
_VOID = DatasetSpec(
    "void", "VOID (visual-inertial odometry sparse depth)", "void_NNNN/{train,test}_{image,sparse_depth,"
    "validity_map,ground_truth,intrinsics}.txt + data/<sequence>/...", ("train", "test"), "train", "test", None,
    (0.2, 5.0), (0.0, math.inf), None, "mm", ("mae_mm", "rmse_mm", "imae_per_km", "irmse_per_km"), "cityscapes",
    "VOID: see github.com/alexklwong/void-dataset (research use; cite Wong et al., RA-L 2020)",
    recipe={"epochs": 10, "batch_size": 8, "lr": 0.0001, "lr_schedule": "cosine", "crop": (480, 640),
            "val_split": "test"},
    archives=(DatasetArchive("void_release.zip", VOID_RELEASE_URL, ("void_release",), None),),
    make_source=_void_source,
)  # fmt: skip

#: Every dataset by name.
DATASETS: dict[str, DatasetSpec] = {d.name: d for d in (_KITTI, _NYU, _VOID)}


def get_dataset(name: str | DatasetSpec | None = None) -> DatasetSpec:
    """The entry called ``name`` (None: ``kitti-dc``)."""
    if isinstance(name, DatasetSpec):
        return name
    name = name or DEFAULT_DATASET
    if name not in DATASETS:
        raise UnknownDatasetError(f"dataset: unknown dataset {name!r}; choose one of {', '.join(DATASETS)}")
    return DATASETS[name]


def check_split(name: str, split: str | None) -> str:
    """:meth:`DatasetSpec.check_split` of the dataset ``name``."""
    return get_dataset(name).check_split(split)
