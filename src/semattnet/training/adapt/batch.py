"""Training batches of ``semattnet adapt``: random crops of a source's frames, with their other views.

Every random draw (which frame, where the crop lies) comes from one :class:`torch.Generator` that the run's
state saves, so a resumed run draws what the uninterrupted one did.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch

from semattnet.data.frames import Frame

__all__ = ["AdaptBatch", "ViewBatch", "crop_size", "make_batch"]


@dataclass(frozen=True)
class ViewBatch:
    """The other views of a batch's crops: what :func:`~semattnet.training.adapt.losses.photometric_loss` warps.

    Attributes:
        images: (B, V, 3, Hv, Wv) the views' images in [0, 1] (padded with zeros to the batch's largest view).
        K: (B, 3, 3) the crops' cameras' intrinsics in full-image pixels. offset: (B, 2) the crops' ``(x0, y0)``.
        K_view: (B, V, 3, 3) the views' intrinsics. T_view_cam: (B, V, 4, 4) crop camera -> view camera, metres.
        present: (B, V) bool, False for the slots of a frame with fewer views.
    """

    images: torch.Tensor
    K: torch.Tensor
    offset: torch.Tensor
    K_view: torch.Tensor
    T_view_cam: torch.Tensor
    present: torch.Tensor

    def to(self, device: torch.device) -> ViewBatch:
        return ViewBatch(
            *(t.to(device) for t in (self.images, self.K, self.offset, self.K_view, self.T_view_cam, self.present))
        )


@dataclass(frozen=True)
class AdaptBatch:
    """Crops of frames: ``rgb`` and ``semantic`` (B, 3, h, w) 0..255, ``sparse`` (B, 1, h, w) metres (0 = none),
    ``names`` the frames, ``views`` their other views (None when no frame of the batch has one)."""

    rgb: torch.Tensor
    semantic: torch.Tensor
    sparse: torch.Tensor
    names: tuple[str, ...]
    views: ViewBatch | None


def crop_size(asked: tuple[int, int], sizes: Sequence[tuple[int, int]], multiple: int = 32) -> tuple[int, int]:
    """The crop every batch uses: ``asked`` (H, W), each side at most the smallest frame's, rounded down to a
    ``multiple`` (what the network takes)."""
    h = min([asked[0], *(s[0] for s in sizes)]) // multiple * multiple
    w = min([asked[1], *(s[1] for s in sizes)]) // multiple * multiple
    return h, w


def _chw(a: np.ndarray) -> torch.Tensor:
    return torch.from_numpy(np.array(a, dtype=np.float32)).permute(2, 0, 1)  # a copy: frames are read-only


def _views(frames: Sequence[Frame], offsets: torch.Tensor) -> ViewBatch | None:
    """The frames' views stacked (zero-padded to the largest), or None when no frame has one."""
    slots = max(len(f.views) for f in frames)
    if slots == 0:
        return None
    views = [v for f in frames for v in f.views]
    hv, wv = max(v.rgb.shape[0] for v in views), max(v.rgb.shape[1] for v in views)
    b = len(frames)
    images = torch.zeros(b, slots, 3, hv, wv)
    K_view, T = torch.eye(3).repeat(b, slots, 1, 1), torch.eye(4).repeat(b, slots, 1, 1)
    present = torch.zeros(b, slots, dtype=torch.bool)
    for i, frame in enumerate(frames):
        for j, view in enumerate(frame.views):
            h, w = view.rgb.shape[:2]
            images[i, j, :, :h, :w] = _chw(view.rgb) / 255.0
            K_view[i, j], T[i, j] = torch.as_tensor(view.K), torch.as_tensor(view.T_view_cam)
            present[i, j] = True
    K = torch.stack([torch.as_tensor(np.asarray(f.K), dtype=torch.float32) for f in frames])
    return ViewBatch(images, K, offsets, K_view, T, present)


def make_batch(frames: Sequence[Frame], crop: tuple[int, int], rng: torch.Generator) -> AdaptBatch:
    """A random ``crop`` (H, W) of each frame (its semantic map filled already), drawn with ``rng``."""
    ch, cw = crop
    offsets = torch.zeros(len(frames), 2)
    rgb, semantic, sparse = [], [], []
    for i, frame in enumerate(frames):
        h, w = frame.size
        y0 = int(torch.randint(h - ch + 1, (1,), generator=rng))
        x0 = int(torch.randint(w - cw + 1, (1,), generator=rng))
        offsets[i] = torch.tensor([x0, y0])
        window = (slice(y0, y0 + ch), slice(x0, x0 + cw))
        rgb.append(_chw(frame.rgb[window]))
        assert frame.semantic is not None  # the pool fills every frame's map
        semantic.append(_chw(frame.semantic[window]))
        sparse.append(torch.from_numpy(np.array(frame.sparse[window], dtype=np.float32))[None])
    views = _views(frames, offsets) if all(f.K is not None for f in frames) else None
    names = tuple(f.name for f in frames)
    return AdaptBatch(torch.stack(rgb), torch.stack(semantic), torch.stack(sparse), names, views)
