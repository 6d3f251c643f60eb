"""Pairing a user's files into frames: image, sparse depth and (optional) semantic map, by name."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from semattnet.data.io import DataError

__all__ = ["FramePaths", "pair_frames"]


@dataclass(frozen=True)
class FramePaths:
    """One frame's input files; ``name`` is the image's file stem (used for output names)."""

    name: str
    rgb: Path
    sparse: Path
    semantic: Path | None = None


def _sparse_for(image: Path, sparse_dir: Path) -> Path | None:
    """The sparse file named like ``image``, or with KITTI's ``_image_`` -> ``_velodyne_raw_`` swap."""
    for name in (image.name, image.name.replace("_image_", "_velodyne_raw_", 1)):
        if (sparse_dir / name).is_file():
            return sparse_dir / name
    return None


def pair_frames(rgb: Path, sparse: Path, semantic: Path | None = None, missing_ok: bool = False) -> list[FramePaths]:
    """Pair image files with sparse (and semantic) files by name.

    ``rgb``/``sparse``/``semantic`` are either three files (one frame) or three folders. KITTI's
    ``val_selection_cropped`` names (``..._image_...`` / ``..._velodyne_raw_...``) pair too.
    ``missing_ok``: an image without a partner is still a frame, whose missing file (named like the image)
    fails when it is read: that frame's fault, not the run's (:mod:`semattnet.inference.pipeline`).

    Raises:
        DataError: an image has no sparse (or semantic) partner (unless ``missing_ok``), or the folder has no PNG.
    """
    rgb, sparse = Path(rgb), Path(sparse)
    semantic = Path(semantic) if semantic is not None else None
    if rgb.is_file():
        return [FramePaths(rgb.stem, rgb, sparse, semantic)]
    frames, missing = [], []
    for image in sorted(rgb.glob("*.png")):
        lidar = _sparse_for(image, sparse)
        sem = None if semantic is None else semantic / image.name
        if lidar is None or (sem is not None and not sem.is_file()):
            missing.append(image.name)
            if not missing_ok:
                continue
        lidar = lidar if lidar is not None else sparse / image.name
        frames.append(FramePaths(image.stem, image, lidar, sem))
    if missing and not missing_ok:
        raise DataError(f"{rgb}: no matching sparse/semantic file for {len(missing)} image(s), e.g. {missing[:3]}")
    if not frames:
        raise DataError(f"{rgb}: no PNG images")
    return frames
