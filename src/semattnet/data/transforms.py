"""The paper's augmentation (spec TRAINING.md) and evaluation crops, on numpy samples.

Training: bottom crop to 352x1216 (rows from the bottom, columns centred), joint horizontal
flip (p = 0.5), colour jitter on RGB only (brightness, contrast, saturation factors each
U[0.9, 1.1], in random order), then a random vertical crop to 320 rows; optionally (not the paper's)
semantic dropout, the fallback semantic map in place of a share of the frames'. The semantic map and
depths are never jittered. Every random choice comes from the ``numpy.random.Generator`` passed
in, which the dataset seeds per (seed, epoch, index).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np
import torch

from semattnet.data.io import DataError
from semattnet.palette import unknown_map

__all__ = [
    "EvalTransform",
    "Sample",
    "TrainTransform",
    "Transform",
    "bottom_crop",
    "color_jitter",
    "drop_semantic",
    "hflip",
]


@dataclass
class Sample:
    """One frame in numpy: images (H, W, 3) uint8 or float32 0..255, depths (H, W) metres."""

    rgb: np.ndarray
    semantic: np.ndarray
    sparse: np.ndarray
    gt: np.ndarray | None = None
    K: np.ndarray | None = None

    @property
    def size(self) -> tuple[int, int]:
        return self.sparse.shape[0], self.sparse.shape[1]

    def crop(self, top: int, left: int, height: int, width: int) -> Sample:
        win = (slice(top, top + height), slice(left, left + width))
        K = None
        if self.K is not None:
            K = self.K.copy()
            K[0, 2] -= left
            K[1, 2] -= top
        return Sample(self.rgb[win], self.semantic[win], self.sparse[win], None if self.gt is None else self.gt[win], K)

    def to_tensors(self) -> dict[str, torch.Tensor]:
        def image(a: np.ndarray) -> torch.Tensor:
            return torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32)).permute(2, 0, 1).contiguous()

        def depth(a: np.ndarray) -> torch.Tensor:
            return torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32))[None]

        out = {"rgb": image(self.rgb), "semantic": image(self.semantic), "sparse": depth(self.sparse)}
        if self.gt is not None:
            out["gt"] = depth(self.gt)
        out["K"] = (
            torch.from_numpy(self.K.astype(np.float32)) if self.K is not None else torch.full((3, 3), float("nan"))
        )
        return out


class Transform(Protocol):
    def __call__(self, sample: Sample, rng: np.random.Generator) -> Sample: ...


def bottom_crop(sample: Sample, height: int, width: int) -> Sample:
    """Keep the bottom ``height`` rows and the centred ``width`` columns (KITTI's LiDAR-covered part)."""
    h, w = sample.size
    if h < height or w < width:
        raise DataError(f"sample of {h}x{w} is smaller than the crop {height}x{width}")
    return sample.crop(h - height, (w - width) // 2, height, width)


def hflip(sample: Sample) -> Sample:
    """Mirror every image of the sample left-right (and the principal point)."""
    K = None
    if sample.K is not None:
        K = sample.K.copy()
        K[0, 2] = sample.size[1] - 1 - K[0, 2]
    return Sample(
        sample.rgb[:, ::-1],
        sample.semantic[:, ::-1],
        sample.sparse[:, ::-1],
        None if sample.gt is None else sample.gt[:, ::-1],
        K,
    )


def _gray(rgb: np.ndarray) -> np.ndarray:
    return rgb[..., 0] * 0.299 + rgb[..., 1] * 0.587 + rgb[..., 2] * 0.114


def color_jitter(rgb: np.ndarray, rng: np.random.Generator, amount: float = 0.1) -> np.ndarray:
    """Brightness, contrast and saturation factors each U[1 - amount, 1 + amount], random order
    (torchvision's definitions), on float RGB 0..255; returns float32 clipped to 0..255."""
    x = np.asarray(rgb, dtype=np.float32)
    factors = rng.uniform(1.0 - amount, 1.0 + amount, size=3)
    for op in rng.permutation(3):
        f = np.float32(factors[op])
        if op == 0:  # brightness
            x = x * f
        elif op == 1:  # contrast: blend with the mean grey level
            x = (x - _gray(x).mean()) * f + _gray(x).mean()
        else:  # saturation: blend with the per-pixel grey image
            g = _gray(x)[..., None]
            x = (x - g) * f + g
        x = np.clip(x, 0.0, 255.0)
    return x.astype(np.float32)


def drop_semantic(sample: Sample, rng: np.random.Generator, share: float) -> Sample:
    """Semantic dropout: with probability ``share``, the frame's semantic map becomes the no-segmenter
    fallback (:func:`semattnet.palette.unknown_map`), so that a model learns to complete depth without one.

    Draws from ``rng`` only when ``share > 0`` (a run without dropout keeps its random stream)."""
    if share <= 0 or rng.random() >= share:
        return sample
    return replace(sample, semantic=unknown_map(*sample.size))


@dataclass(frozen=True)
class TrainTransform:
    """The paper's training augmentation. Sizes default to the paper's (352x1216 then 320 rows).

    ``semantic_dropout``: the share of frames trained with the fallback semantic map (:func:`drop_semantic`;
    not the paper's: 0 by default)."""

    crop: tuple[int, int] = (352, 1216)
    random_crop_height: int = 320
    flip: bool = True
    jitter: float = 0.1
    semantic_dropout: float = 0.0

    def __call__(self, sample: Sample, rng: np.random.Generator) -> Sample:
        sample = bottom_crop(sample, *self.crop)
        if self.flip and rng.random() < 0.5:
            sample = hflip(sample)
        if self.jitter > 0:
            sample = replace(sample, rgb=color_jitter(sample.rgb, rng, self.jitter))
        h, w = sample.size
        if self.random_crop_height < h:
            top = int(rng.integers(0, h - self.random_crop_height + 1))
            sample = sample.crop(top, 0, self.random_crop_height, w)
        return drop_semantic(sample, rng, self.semantic_dropout)


@dataclass(frozen=True)
class EvalTransform:
    """Evaluation: bottom crop to ``crop`` when the frame is larger (full val); val_select and
    test frames are already 352x1216 and pass unchanged. ``crop=None`` keeps full frames."""

    crop: tuple[int, int] | None = (352, 1216)

    def __call__(self, sample: Sample, rng: np.random.Generator) -> Sample:
        if self.crop is None or sample.size == tuple(self.crop):
            return sample
        return bottom_crop(sample, *self.crop)
