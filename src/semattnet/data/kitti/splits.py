"""KITTI depth completion with the authors' semantic maps, for every split.

Frames are paired by (drive, camera, frame id), never by sorted position (the authors'
loader misaligned frames when file counts differed, their issue #4). A frame that lacks one of
its inputs is refused by default, naming the missing files; ``on_missing="skip"`` drops it and
counts it in :attr:`KittiDepthCompletion.skipped`.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from torch.utils.data import Dataset

from semattnet._errors import InputError
from semattnet.data.datasets.frames import MissingSplitError
from semattnet.data.io import DataError, read_depth, read_image, read_intrinsics
from semattnet.data.kitti import layout
from semattnet.data.transforms import Sample, Transform

__all__ = ["FrameFiles", "KittiDepthCompletion", "find_frames", "load_frame"]

OnMissing = Literal["error", "skip"]


@dataclass(frozen=True)
class FrameFiles:
    """The files of one frame. ``gt`` is None for the test split; ``intrinsics`` may be None."""

    name: str
    rgb: Path
    semantic: Path
    sparse: Path
    gt: Path | None
    intrinsics: Path | None
    intrinsics_camera: str | None = None  # set when intrinsics is a raw calib_cam_to_cam.txt


#: What a split finder returns: the frames found, and (name, missing or wrong files) per bad frame.
_Found = tuple[list[FrameFiles], list[tuple[str, Sequence[Path | str]]]]


def _first_existing(candidates: list[Path]) -> Path:
    for p in candidates:
        if p.is_file():
            return p
    return candidates[0]


def _existing_first(dirs: list[Path]) -> list[Path]:
    """Folders that exist come first, so a missing file is reported where the user keeps them."""
    return sorted(dirs, key=lambda d: not d.is_dir())


def _semantic_roots(root: Path, semantic_root: Path | None) -> list[Path]:
    if semantic_root is not None:
        return [Path(semantic_root)]
    return _existing_first([root / name for name in layout.SEMANTIC_DIR_NAMES])


def _raw_roots(root: Path, raw_root: Path | None) -> list[Path]:
    return [Path(raw_root)] if raw_root is not None else _existing_first([root / "kitti_raw", root / "raw"])


def _find_train_val(root: Path, split: str, raw_root: Path | None, semantic_root: Path | None) -> _Found:
    frames: list[FrameFiles] = []
    problems: list[tuple[str, Sequence[Path | str]]] = []
    velo = (root / "data_depth_velodyne" / split).glob("*/proj_depth/velodyne_raw/image_0[23]/*.png")
    gts = set((root / "data_depth_annotated" / split).glob("*/proj_depth/groundtruth/image_0[23]/*.png"))
    raws, sems = _raw_roots(root, raw_root), _semantic_roots(root, semantic_root)
    for sparse in sorted(velo):
        drive, camera, frame = sparse.parts[-5], sparse.parent.name[-2:], sparse.stem
        gt = layout.groundtruth_path(root, split, drive, camera, frame)
        rgb = _first_existing([layout.raw_image_path(r, drive, camera, frame) for r in raws])
        sem = _first_existing([layout.semantic_path(r, drive, camera, frame) for r in sems])
        calib = _first_existing([r / drive[:10] / "calib_cam_to_cam.txt" for r in raws])
        gts.discard(gt)
        missing = [p for p in (gt, rgb, sem) if not p.is_file()]
        if missing:
            problems.append((f"{drive}/image_{camera}/{frame}", missing))
            continue
        frames.append(
            FrameFiles(
                f"{drive}_image_{camera}_{frame}", rgb, sem, sparse, gt, calib if calib.is_file() else None, camera
            )
        )
    for gt in sorted(gts):  # ground truth without a LiDAR map
        drive, camera, frame = gt.parts[-5], gt.parent.name[-2:], gt.stem
        problems.append((f"{drive}/image_{camera}/{frame}", [layout.velodyne_path(root, split, drive, camera, frame)]))
    return frames, problems


def _find_selection(root: Path, split: str, semantic_root: Path | None) -> _Found:
    base = root / layout.SELECTION / (layout.VAL_SELECT_DIR if split == "val_select" else layout.TEST_DIR)
    sem_dirs = _existing_first([base / n for n in layout.SEMANTIC_DIR_NAMES])
    if semantic_root is not None:
        sem_dirs = [Path(semantic_root), Path(semantic_root) / base.name, *sem_dirs]
    frames: list[FrameFiles] = []
    problems: list[tuple[str, Sequence[Path | str]]] = []
    velo_files = sorted((base / "velodyne_raw").glob("*.png"))
    for sparse in velo_files:
        if split == "val_select":
            if "_velodyne_raw_" not in sparse.name:
                problems.append((sparse.name, ["a name of the form <drive>_velodyne_raw_<frame>_image_0X.png"]))
                continue
            image_name = sparse.name.replace("_velodyne_raw_", "_image_", 1)
            gt = base / "groundtruth_depth" / sparse.name.replace("_velodyne_raw_", "_groundtruth_depth_", 1)
        else:
            image_name, gt = sparse.name, None
        rgb = base / "image" / image_name
        sem = _first_existing([d / image_name for d in sem_dirs])
        intr = base / "intrinsics" / (Path(image_name).stem + ".txt")
        missing = [p for p in (rgb, sem, gt) if p is not None and not p.is_file()]
        if missing:
            problems.append((image_name, missing))
            continue
        frames.append(FrameFiles(Path(image_name).stem, rgb, sem, sparse, gt, intr if intr.is_file() else None))
    images = {p.name for p in (base / "image").glob("*.png")}
    for name in sorted(images - {f.rgb.name for f in frames} - {n for n, _ in problems}):
        expected = name.replace("_image_", "_velodyne_raw_", 1) if split == "val_select" else name
        problems.append((name, [base / "velodyne_raw" / expected]))
    return frames, problems


def find_frames(
    root: str | os.PathLike[str],
    split: str,
    raw_root: str | os.PathLike[str] | None = None,
    semantic_root: str | os.PathLike[str] | None = None,
) -> tuple[list[FrameFiles], list[tuple[str, Sequence[Path | str]]]]:
    """Index a split: the complete frames, and (frame, missing files) for the incomplete ones."""
    if split not in layout.SPLITS:
        raise InputError(f"split: unknown split {split!r}; choose one of {layout.SPLITS}")
    root = Path(root)
    sem = Path(semantic_root) if semantic_root is not None else None
    if split in ("train", "val"):
        return _find_train_val(root, split, Path(raw_root) if raw_root is not None else None, sem)
    return _find_selection(root, split, sem)


def load_frame(f: FrameFiles) -> Sample:
    """Read one frame's files and check that their sizes agree.

    Raises:
        DataError: a file is missing, unreadable or badly encoded, or the sizes disagree.
    """
    sample = Sample(
        rgb=read_image(f.rgb),
        semantic=read_image(f.semantic),
        sparse=read_depth(f.sparse),
        gt=read_depth(f.gt) if f.gt is not None else None,
        K=read_intrinsics(f.intrinsics, f.intrinsics_camera) if f.intrinsics is not None else None,
    )
    sizes = {f.rgb: sample.rgb.shape[:2], f.semantic: sample.semantic.shape[:2], f.sparse: sample.sparse.shape}
    if sample.gt is not None:
        sizes[f.gt] = sample.gt.shape  # type: ignore[index]
    if len(set(sizes.values())) > 1:
        raise DataError(
            f"{f.name}: image sizes disagree: " + ", ".join(f"{p} is {v[1]}x{v[0]}" for p, v in sizes.items())
        )
    return sample


def _describe(problems: list[tuple[str, Sequence[Path | str]]], limit: int = 5) -> str:
    shown = "; ".join(f"{name}: missing {', '.join(map(str, paths))}" for name, paths in problems[:limit])
    more = f"; ... and {len(problems) - limit} more" if len(problems) > limit else ""
    return shown + more


class KittiDepthCompletion(Dataset[dict[str, object]]):
    """KITTI depth completion samples as tensors in the model's units.

    Each item is a dict: ``rgb`` (3, H, W) 0..255, ``semantic`` (3, H, W) 0..255, ``sparse``
    (1, H, W) metres, ``gt`` (1, H, W) metres (not for ``test``), ``K`` (3, 3) intrinsics
    (adjusted for crops and flips; NaN when the split has none), ``name`` and ``index``.

    Args:
        root: the KITTI depth completion folder (holding ``data_depth_velodyne``,
            ``data_depth_annotated``, ``data_depth_selection``).
        split: ``train``, ``val`` (full), ``val_select`` or ``test``.
        raw_root: KITTI raw data (default ``root/kitti_raw`` or ``root/raw``).
        semantic_root: semantic maps (default ``root/semantic`` or ``root/semantics``; for
            val_select/test also the ``semantic``/``semantics`` folder inside the selection).
        transform: a :class:`~semattnet.data.transforms.Transform` (e.g. ``TrainTransform()``).
        on_missing: ``"error"`` (default) refuses incomplete frames, naming the files;
            ``"skip"`` drops them with a warning and keeps them in :attr:`skipped`.
        seed: base seed; every random choice of item ``i`` in epoch ``e`` comes from
            ``numpy.random.default_rng([seed, e, i])``, whatever the worker count.
    """

    def __init__(
        self,
        root: str | os.PathLike[str],
        split: str,
        raw_root: str | os.PathLike[str] | None = None,
        semantic_root: str | os.PathLike[str] | None = None,
        transform: Transform | None = None,
        on_missing: OnMissing = "error",
        seed: int = 0,
    ) -> None:
        if on_missing not in ("error", "skip"):
            raise InputError(f"on_missing must be 'error' or 'skip', got {on_missing!r}")
        self.split = split
        self.frames, self.skipped = find_frames(root, split, raw_root, semantic_root)
        if self.skipped and on_missing == "error":
            raise DataError(f"{root} ({split}): {len(self.skipped)} incomplete frame(s): {_describe(self.skipped)}")
        if self.skipped:
            warnings.warn(
                f"{root} ({split}): skipped {len(self.skipped)} incomplete frame(s): {_describe(self.skipped, 3)}",
                stacklevel=2,
            )
        if not self.frames:  # no file of the split at all (an incomplete frame was refused above)
            raise MissingSplitError(f"{root}: no {split} frames found (is this the KITTI depth completion folder?)")
        self.transform = transform
        self.seed = seed
        self.epoch = 0

    def set_epoch(self, epoch: int) -> None:
        """Select the epoch whose random augmentations ``__getitem__`` draws."""
        self.epoch = int(epoch)

    def __len__(self) -> int:
        return len(self.frames)

    def load(self, index: int) -> Sample:
        """The raw sample (numpy arrays, before any transform)."""
        return load_frame(self.frames[index])

    def __getitem__(self, index: int) -> dict[str, object]:
        sample = self.load(index)
        if self.transform is not None:
            sample = self.transform(sample, np.random.default_rng([self.seed, self.epoch, index]))
        return sample.to_tensors() | {"name": self.frames[index].name, "index": index}
