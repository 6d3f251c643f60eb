"""A :class:`~semattnet.data.frames.FrameSource` as a torch Dataset: the one frame reader serves predict,
evaluate and train (each dataset entry builds its source, and this wraps it)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

from semattnet._errors import DataError, InputError
from semattnet.data.frames import Frame, IndexedSource, SourceInfo
from semattnet.data.transforms import Sample, Transform, color_jitter, drop_semantic, hflip
from semattnet.models.checks import SIZE_MULTIPLE

__all__ = [
    "CroppedSource",
    "FrameDataset",
    "FrameRef",
    "IndoorTrainTransform",
    "MissingSplitError",
    "check_split_in",
    "draw_samples",
    "frame_seed",
    "pad_sample",
]


def check_split_in(dataset: str, split: str, splits: Sequence[str]) -> str:
    """``split`` if ``dataset`` has it (one of ``splits``), else the one-line error naming the choices."""
    if split not in splits:
        raise InputError(f"split: {dataset} has no split {split!r}; choose one of {', '.join(splits)}")
    return split


class MissingSplitError(DataError):
    """A split's folder or list file is absent (``data check`` skips such a split)."""


def frame_seed(name: str, seed: int = 0) -> int:
    """A frame's own seed: CRC-32 of its name mixed with ``seed`` (stable across runs and machines)."""
    import zlib

    return (zlib.crc32(name.encode()) ^ (int(seed) * 0x9E3779B1)) & 0xFFFFFFFF


def draw_samples(gt: np.ndarray, count: int, rng: np.random.Generator, valid: float = 1e-4) -> np.ndarray:
    """(H, W) sparse depth: ``count`` pixels drawn without replacement among gt > ``valid`` (all of them
    when fewer), as NLSPN's ``get_sparse_depth``; the rest 0."""
    flat = np.flatnonzero(gt.reshape(-1) > valid)
    keep = rng.permutation(flat)[:count] if len(flat) > count else flat
    out = np.zeros(gt.size, np.float32)
    out[keep] = gt.reshape(-1)[keep]
    return out.reshape(gt.shape)


def padding(size: tuple[int, int], multiple: int = SIZE_MULTIPLE) -> tuple[int, int, int, int]:
    """(top, bottom, left, right) of :func:`semattnet.inference.padding.pad_to_multiple` for an (H, W) frame."""
    ph, pw = (-size[0]) % multiple, (-size[1]) % multiple
    return ph, 0, pw // 2, pw - pw // 2


def pad_sample(sample: Sample, multiple: int = SIZE_MULTIPLE) -> Sample:
    """Pad to multiples of ``multiple`` as :func:`semattnet.inference.padding.pad_to_multiple` does (rows at
    the top, columns split left/right), with 0 everywhere (gt 0: the padding carries no loss, no metric)."""
    top, _, left, right = padding(sample.size, multiple)
    if not (top or left or right):
        return sample
    widths = ((top, 0), (left, right))

    def pad(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else np.pad(a, widths + ((0, 0),) * (a.ndim - 2))

    K = None
    if sample.K is not None:
        K = sample.K.copy()
        K[0, 2] += left
        K[1, 2] += top
    return Sample(pad(sample.rgb), pad(sample.semantic), pad(sample.sparse), pad(sample.gt), K)  # type: ignore[arg-type]


@dataclass(frozen=True)
class IndoorTrainTransform:
    """Training augmentation of the indoor protocols (NLSPN's, without its scale / rotation): a fresh draw of
    ``samples`` sparse points from the ground truth (None: keep the source's sparse map), a joint horizontal
    flip (p = 0.5), colour jitter on RGB only, semantic dropout (:func:`~semattnet.data.transforms.drop_semantic`),
    then padding to the model's multiple of 32 (gt 0 there)."""

    samples: int | None = 500
    flip: bool = True
    jitter: float = 0.1
    semantic_dropout: float = 0.0

    def __call__(self, sample: Sample, rng: np.random.Generator) -> Sample:
        if self.samples is not None and sample.gt is not None:
            sample = replace(sample, sparse=draw_samples(sample.gt, self.samples, rng))
        if self.flip and rng.random() < 0.5:
            sample = hflip(sample)
        if self.jitter > 0:
            sample = replace(sample, rgb=color_jitter(sample.rgb, rng, self.jitter))
        return pad_sample(drop_semantic(sample, rng, self.semantic_dropout))


@dataclass(frozen=True)
class FrameRef:
    """What evaluation needs of a frame's files: its name (``gt`` None: predictions are named ``NAME.png``)."""

    name: str
    gt: Path | None = None


class FrameDataset(Dataset[dict[str, object]]):
    """Items like :class:`~semattnet.data.kitti.KittiDepthCompletion`'s (``rgb``, ``semantic``, ``sparse``,
    ``gt``, ``K``, ``name``, ``index``) from ``source``, padded to the model's multiple of 32 (zeros, gt 0)
    with ``pad`` = (top, bottom, left, right) (evaluation crops it back: metrics and predictions on the
    protocol's crop); a frame without a semantic map gets the ``unknown`` map. Random choices of item ``i``
    in epoch ``e``: ``numpy.random.default_rng([seed, e, i])``."""

    def __init__(self, source: IndexedSource, transform: Transform | None = None, seed: int = 0) -> None:
        self.source, self.transform, self.seed, self.epoch = source, transform, seed, 0
        self.frames = [FrameRef(n) for n in source.names]
        self.palette: str | None = source.info.palette  # None: no maps (the unknown map)

    def set_epoch(self, epoch: int) -> None:
        self.epoch = int(epoch)

    def __len__(self) -> int:
        return len(self.frames)

    def load(self, index: int) -> Sample:
        """The raw sample (numpy arrays, before any transform)."""
        return frame_sample(self.source.load(self.frames[index].name))

    def __getitem__(self, index: int) -> dict[str, object]:
        sample = self.load(index)
        if self.transform is not None:
            sample = self.transform(sample, np.random.default_rng([self.seed, self.epoch, index]))
        pad = padding(sample.size)
        item: dict[str, object] = {**pad_sample(sample).to_tensors()}
        return item | {"name": self.frames[index].name, "index": index, "pad": torch.tensor(pad)}


def frame_sample(frame: Frame) -> Sample:
    """A :class:`Frame` as a :class:`Sample` (the unknown map when it has no semantic map)."""
    from semattnet.palette import unknown_map

    sem = frame.semantic if frame.semantic is not None else unknown_map(*frame.size)
    return Sample(frame.rgb, sem, frame.sparse, frame.gt, frame.K)


class CroppedSource(IndexedSource):
    """``source``'s frames bottom-cropped to ``crop`` (H, W): the bottom rows and the centred columns, as
    :func:`semattnet.data.transforms.bottom_crop` (intrinsics moved with the crop); what a protocol scores
    (KITTI's full ``val`` at 352x1216: :meth:`~semattnet.data.datasets.DatasetSpec.eval_crop`)."""

    def __init__(self, source: IndexedSource, crop: tuple[int, int]) -> None:
        self.source, self.crop, self.names = source, crop, source.names
        self.palette: str | None = source.info.palette

    def load(self, name: str) -> Frame:
        frame = self.source.load(name)
        (h, w), (ch, cw) = frame.size, self.crop
        if h < ch or w < cw:
            raise DataError(f"{frame.paths.get('rgb', name)}: {w}x{h} is smaller than the crop {cw}x{ch}")
        top, left = h - ch, (w - cw) // 2
        win = (slice(top, top + ch), slice(left, left + cw))
        K = None if frame.K is None else frame.K.copy()
        if K is not None:
            K[0, 2] -= left
            K[1, 2] -= top
        sem, gt = (None if a is None else a[win] for a in (frame.semantic, frame.gt))
        return replace(frame, rgb=frame.rgb[win], sparse=frame.sparse[win], semantic=sem, gt=gt, K=K)

    def inputs(self) -> list[Path]:
        return self.source.inputs()

    @property
    def info(self) -> SourceInfo:
        """The source's (its frames' names, palette and predictions' names are theirs)."""
        return self.source.info
