"""A KITTI depth-completion split (``train``, ``val``, ``val_select``, ``test``) as frames, with ground truth."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from semattnet.data.frames import Frame, IndexedSource, SourceInfo, unique_names
from semattnet.data.kitti.splits import FrameFiles, KittiDepthCompletion, load_frame
from semattnet.data.sources.registry import register_source

__all__ = ["KittiSplitSource", "prediction_name"]


@register_source("kitti-dc", option="--data")  # the dataset's name; options: data.datasets.DatasetOptions
class KittiSplitSource(IndexedSource):
    """The frames of a split at full size, read by :func:`semattnet.data.kitti.load_frame` (paired by drive,
    camera and frame id; incomplete frames refused as :class:`KittiDepthCompletion` does).

    Args: as :class:`KittiDepthCompletion` (``root``, ``split``, ``raw_root``, ``semantic_root``);
    ``max_frames`` keeps the first frames only."""

    palette = "cityscapes"

    def __init__(
        self,
        root: str | os.PathLike[str],
        split: str = "val_select",
        raw_root: str | os.PathLike[str] | None = None,
        semantic_root: str | os.PathLike[str] | None = None,
        max_frames: int | None = None,
    ) -> None:
        ds = KittiDepthCompletion(root, split, raw_root, semantic_root)
        self.split = ds.split
        self.files: list[FrameFiles] = ds.frames[:max_frames] if max_frames else list(ds.frames)
        self.names = list(unique_names(((f.name, f.sparse) for f in self.files), root))
        self.by_name = {f.name: f for f in self.files}
        self.roots = [Path(p) for p in (root, raw_root, semantic_root) if p is not None]

    def load(self, name: str) -> Frame:
        f = self.by_name[name]
        s = load_frame(f)
        paths = {"rgb": f.rgb, "semantic": f.semantic, "sparse": f.sparse}
        paths |= {k: p for k, p in (("gt", f.gt), ("intrinsics", f.intrinsics)) if p is not None}
        return Frame(name, s.rgb, s.sparse, s.semantic, K=s.K, gt=s.gt, paths=paths)

    @property
    def info(self) -> SourceInfo:
        """Its Cityscapes maps and its predictions' names: for ``val_select`` the ground truth's own (so that
        ``semattnet metrics`` pairs by name), else ``NAME.png``."""
        names = {n: prediction_name(self.split, f) for n, f in self.by_name.items()}
        return SourceInfo(self.palette, prediction_names=names)

    def inputs(self) -> list[Path]:
        return list(self.roots)

    def check(self, names: Sequence[str] | None = None) -> None:
        for name in self.names if names is None else names:
            load_frame(self.by_name[name])


def prediction_name(split: str, frame: FrameFiles) -> str:
    """``val_select``: the ground truth's file name; other splits: ``NAME.png``."""
    return frame.gt.name if split == "val_select" and frame.gt is not None else f"{frame.name}.png"
