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
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar, Protocol

from semattnet._errors import InputError
from semattnet._utils.registry import Registry, UnknownEntryError, option
from semattnet.data.datasets.frames import check_split_in
from semattnet.data.datasets.nyuv2 import NYU_SPLITS, NyuV2Source
from semattnet.data.datasets.void import VOID_SPLITS, VoidSource
from semattnet.data.frames import IndexedSource
from semattnet.data.sources.registry import SOURCES, SourceOptions

if TYPE_CHECKING:
    from semattnet.data.datasets.frames import FrameDataset
    from semattnet.data.kitti.splits import KittiDepthCompletion

    #: The torch Dataset of a split (:meth:`DatasetSpec.dataset`): dicts of tensors, ``load(i)`` the raw sample.
    SplitDataset = KittiDepthCompletion | FrameDataset

__all__ = [
    "DATASETS",
    "DEFAULT_DATASET",
    "DatasetArchive",
    "DatasetOptions",
    "DatasetSpec",
    "UnknownDatasetError",
    "check_split",
    "get_dataset",
]

PathLike = str | os.PathLike[str]
DEFAULT_DATASET = "kitti-dc"
#: Where alexklwong/void-dataset's README (at b17f271) says the release zip is (OneDrive; its wget command).
VOID_RELEASE_URL = (
    "https://yaleedu-my.sharepoint.com/:u:/g/personal/alex_wong_yale_edu/"
    "Ebwvk0Ji8HhNinmAcKI5vSkBEjJTIWlA8PXwKNQX_FvB7g?e=0Zqe7g&download=1"
)


#: The registry's one unknown-name error (the old name kept).
UnknownDatasetError = UnknownEntryError


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
        crop_splits: the splits whose full frames the protocol bottom-crops to ``crop`` (:meth:`eval_crop`).
        make_source: its frames' reader; make_dataset: its own torch Dataset (None: frames of ``make_source``,
            :class:`~semattnet.data.datasets.frames.FrameDataset`).
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
    recipe: dict[str, object] = field(default_factory=dict)
    archives: tuple[DatasetArchive, ...] = ()
    make_source: Callable[..., IndexedSource] | None = field(default=None, repr=False)
    crop_splits: tuple[str, ...] = ()
    make_dataset: Callable[..., SplitDataset] | None = field(default=None, repr=False)

    def check_split(self, split: str | None, train: bool = False) -> str:
        """``split`` (default: the train / eval split) if this dataset has it."""
        return check_split_in(self.name, split or (self.train_split if train else self.eval_split), self.splits)

    def source(
        self,
        root: PathLike,
        split: str | None = None,
        *,
        semantic_root: PathLike | None = None,
        raw_root: PathLike | None = None,
        max_frames: int | None = None,
        seed: int = 0,
    ) -> IndexedSource:
        """The frames of ``split`` as a :class:`~semattnet.data.frames.FrameSource` (full KITTI frames).

        Raises:
            MissingSplitError: the split has no file under ``root`` (``data check`` skips it).
        """
        split = self.check_split(split)
        if self.make_source is None:
            raise InputError(f"dataset {self.name}: no frame reader registered")
        return self.make_source(
            root, split, raw_root=raw_root, semantic_root=semantic_root, max_frames=max_frames, seed=seed
        )

    def eval_crop(self, split: str, size: tuple[int, int]) -> tuple[int, int] | None:
        """The (H, W) bottom crop the protocol scores frames of ``size`` in ``split`` at, or None (as they are):
        the frames of ``crop_splits`` (KITTI's full ``val``: 352x1216; frames smaller than that, as in small
        synthetic trees, stay whole); other splits (``val_select``) and datasets are scored as their source gives
        them."""
        if split not in self.crop_splits or self.crop is None or min(size) < self.crop[0]:
            return None
        return None if size == self.crop else self.crop

    def dataset(
        self,
        root: PathLike,
        split: str | None = None,
        *,
        train: bool = False,
        seed: int = 0,
        raw_root: PathLike | None = None,
        semantic_root: PathLike | None = None,
        config: TrainRecipe | None = None,
    ) -> SplitDataset:
        """The torch Dataset of ``split``: augmented for training (``train``; ``config`` a
        :class:`~semattnet.training.TrainConfig` for KITTI's crop and jitter), else as the protocol scores it
        (:meth:`eval_crop`; the model's padding to multiples of 32 is the evaluation loop's)."""
        split = self.check_split(split, train)
        if self.make_dataset is not None:
            return self.make_dataset(self, root, split, train, seed, raw_root, semantic_root, config)
        from semattnet.data.datasets.frames import FrameDataset, IndoorTrainTransform

        transform = None
        if train:
            flip, jitter, drop = (config.flip, config.jitter, config.semantic_dropout) if config else (True, 0.1, 0.0)
            transform = IndoorTrainTransform(self.sparse_samples, flip, jitter, drop)
        source = self.source(root, split, semantic_root=semantic_root, seed=seed)
        return FrameDataset(source, transform, seed)

    def check(
        self,
        roots: Sequence[PathLike],
        raw_root: PathLike | None = None,
        semantic_root: PathLike | None = None,
        sample: int | None = None,
        log: Callable[[str], None] = print,
    ) -> int:
        """``data check``: every split found under each root decoded; returns the number of problems
        (:func:`semattnet.data.datasets.check.check_dataset`, the one loop for every dataset)."""
        from semattnet.data.datasets.check import check_dataset

        return check_dataset(self, roots, raw_root, semantic_root, sample, log)


class TrainRecipe(Protocol):
    """What :meth:`DatasetSpec.dataset` reads of a :class:`~semattnet.training.TrainConfig`."""

    @property
    def crop(self) -> tuple[int, int]: ...

    @property
    def random_crop_height(self) -> int | None: ...

    @property
    def flip(self) -> bool: ...

    @property
    def jitter(self) -> float: ...

    @property
    def semantic_dropout(self) -> float: ...


def _kitti_dataset(
    spec: DatasetSpec,
    root: PathLike,
    split: str,
    train: bool,
    seed: int,
    raw_root: PathLike | None,
    semantic_root: PathLike | None,
    cfg: TrainRecipe | None,
) -> SplitDataset:
    from semattnet.data.kitti.splits import KittiDepthCompletion
    from semattnet.data.transforms import EvalTransform, TrainTransform

    if not train:
        ds = KittiDepthCompletion(root, split, raw_root, semantic_root)
        ds.transform = EvalTransform(spec.eval_crop(split, ds.load(0).size))
        return ds
    t = (
        TrainTransform(cfg.crop, cfg.random_crop_height or cfg.crop[0], cfg.flip, cfg.jitter, cfg.semantic_dropout)
        if cfg
        else TrainTransform()
    )
    return KittiDepthCompletion(root, split, raw_root, semantic_root, seed=seed, transform=t)


def _kitti_source(
    root: PathLike,
    split: str,
    *,
    raw_root: PathLike | None,
    semantic_root: PathLike | None,
    max_frames: int | None,
    seed: int,
) -> IndexedSource:
    from semattnet.data.sources import KittiSplitSource

    return KittiSplitSource(root, split, raw_root, semantic_root, max_frames)


def _nyu_source(
    root: PathLike,
    split: str,
    *,
    raw_root: PathLike | None,
    semantic_root: PathLike | None,
    max_frames: int | None,
    seed: int,
) -> IndexedSource:
    return NyuV2Source(root, split, semantic_root=semantic_root, max_frames=max_frames, seed=seed)


def _void_source(
    root: PathLike,
    split: str,
    *,
    raw_root: PathLike | None,
    semantic_root: PathLike | None,
    max_frames: int | None,
    seed: int,
) -> IndexedSource:
    return VoidSource(root, split, semantic_root=semantic_root, max_frames=max_frames)


_KITTI = DatasetSpec(
    "kitti-dc",
    "KITTI depth completion",
    "data_depth_{velodyne,annotated,selection}/, kitti_raw/, semantic/",
    ("train", "val", "val_select", "test"),
    "train",
    "val_select",
    (352, 1216),
    (0.0, 255.0),
    None,
    None,
    "mm",
    ("rmse_mm", "mae_mm", "irmse_per_km", "imae_per_km"),
    "cityscapes",
    "CC BY-NC-SA 3.0 (KITTI)",
    make_source=_kitti_source,
    crop_splits=("train", "val", "test"),
    make_dataset=_kitti_dataset,
)
_NYU = DatasetSpec(
    "nyuv2",
    "NYU Depth v2 (sparse-to-dense HDF5)",
    "train/<scene>/<NNNNN>.h5, val/official/<NNNNN>.h5",
    tuple(NYU_SPLITS),
    "train",
    "test",
    (228, 304),
    (0.1, 10.0),
    (0.0, 10.0),
    500,
    "m",
    ("rmse", "abs_rel", "delta1", "delta2", "delta3", "mae", "irmse_per_km", "imae_per_km"),
    "nyu40",
    "NYU Depth v2: research use, cite Silberman et al. (ECCV 2012); the HDF5 conversion: Ma & Karaman",
    recipe={
        "epochs": 25,
        "batch_size": 12,
        "lr": 0.001,
        "lr_schedule": "cosine",
        "crop": (228, 304),
        "val_split": "test",
    },
    archives=(
        DatasetArchive(
            "nyudepthv2.tar.gz",
            "http://datasets.lids.mit.edu/sparse-to-dense/data/nyudepthv2.tar.gz",
            ("nyudepthv2",),
            "about 32 GB",
        ),
    ),
    make_source=_nyu_source,
)
_VOID = DatasetSpec(
    "void",
    "VOID (visual-inertial odometry sparse depth)",
    "void_NNNN/{train,test}_{image,sparse_depth,validity_map,ground_truth,intrinsics}.txt + data/<sequence>/...",
    VOID_SPLITS,
    "train",
    "test",
    None,
    (0.2, 5.0),
    (0.0, math.inf),
    None,
    "mm",
    ("mae_mm", "rmse_mm", "imae_per_km", "irmse_per_km"),
    "cityscapes",
    "VOID: see github.com/alexklwong/void-dataset (research use; cite Wong et al., RA-L 2020)",
    recipe={
        "epochs": 10,
        "batch_size": 8,
        "lr": 0.0001,
        "lr_schedule": "cosine",
        "crop": (480, 640),
        "val_split": "test",
    },
    archives=(DatasetArchive("void_release.zip", VOID_RELEASE_URL, ("void_release",), None),),
    make_source=_void_source,
)

#: Every dataset by name.
DATASETS: Registry[DatasetSpec] = Registry("dataset")
for _spec in (_KITTI, _NYU, _VOID):
    DATASETS.add(_spec.name, _spec)


def get_dataset(name: str | DatasetSpec | None = None) -> DatasetSpec:
    """The entry called ``name`` (None: ``kitti-dc``)."""
    if isinstance(name, DatasetSpec):
        return name
    name = name or DEFAULT_DATASET
    return DATASETS[name]


def check_split(name: str, split: str | None) -> str:
    """:meth:`DatasetSpec.check_split` of the dataset ``name``."""
    return get_dataset(name).check_split(split)


@dataclass(frozen=True)
class DatasetOptions(SourceOptions):
    """``--data --dataset --split``: a split of a registered dataset (the options of the default dataset's source,
    ``kitti-dc``)."""

    heading: ClassVar[str] = "Inputs: dataset"
    usage: ClassVar[str] = "--data (with --dataset)"
    selects: ClassVar[tuple[str, ...]] = ("data_root",)
    accepts: ClassVar[tuple[str, ...]] = ("semantic", "segment_spec")

    data_root: Path | None = option(
        "--data", type="folder", help="A dataset root (instead of --rgb/--sparse): the frames of --split."
    )
    dataset: str = option(
        "--dataset",
        type="choice",
        choices=tuple(DATASETS),
        default=DEFAULT_DATASET,
        show_default=True,
        help="The dataset whose root --data is.",
    )
    split: str | None = option("--split", help="The split [the dataset's evaluation split].")

    def segment_split(self) -> tuple[str, Path, str] | None:
        assert self.data_root is not None  # it chose this input
        return self.dataset, self.data_root, self.split or get_dataset(self.dataset).eval_split

    def source(self, semantic: Path | None, log: Callable[[str], None]) -> IndexedSource:
        assert self.data_root is not None  # it chose this input
        return get_dataset(self.dataset).source(self.data_root, self.split, semantic_root=semantic)


SOURCES.attach("kitti-dc", DatasetOptions)
