"""NYU Depth v2 in the sparse-to-dense HDF5 layout (Ma & Karaman, ICRA 2018; used by NLSPN, CompletionFormer).

Layout: ``ROOT/train/<scene>/<NNNNN>.h5`` (about 48k frames) and ``ROOT/val/official/<NNNNN>.h5`` (the 654
test frames of the official split). Each file holds ``rgb`` uint8 (3, 480, 640) and ``depth`` float32
(480, 640) in metres (the in-painted Kinect depth, dense); an optional ``label`` (480, 640) integer map of
NYU-40 ids (0 = unlabelled), or of the labelled subset's raw ids 1..894 (any id above 40; mapped to NYU-40 by
the published table, :mod:`semattnet.palette.nyu40_map`), becomes the frame's semantic map in the NYU-40 palette.

Protocol (NLSPN's ``src/data/nyu.py``): image and depth resized to 320x240 (bilinear, torchvision's ``Resize``
default; labels nearest), centre-cropped to 304x228,
500 depth samples drawn among gt > 1e-4 m (seeded per frame: :func:`~.frames.frame_seed` of its name, so a
test frame always gets the same points and two frames get different ones), depth range 0.1-10 m.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import h5py

from semattnet._errors import DataError
from semattnet._utils.bounds import check_image_size, regular_file
from semattnet._utils.extras import require
from semattnet.data.datasets.frames import MissingSplitError, check_split_in, draw_samples, frame_seed
from semattnet.data.datasets.hdf5 import plain_dataset, read_bounded
from semattnet.data.frames import Frame, IndexedSource, unique_names
from semattnet.data.sources.registry import register_source

__all__ = ["NYU_K", "NYU_SPLITS", "NyuV2Source", "check_root", "label_colors", "protocol_K", "read_nyu_h5"]

#: Kinect colour intrinsics at 640x480 (fx, fy, cx, cy), as NLSPN's ``nyu.py``.
NYU_K = (5.1885790117450188e02, 5.1946961112127485e02, 3.2558244941119034e02, 2.5373616633400465e02)
#: Split name -> folder below ROOT.
NYU_SPLITS = {"train": "train", "test": "val/official"}
KINECT = (480, 640)  # H, W of every frame of the layout (NYU_K's size)
RESIZED = (240, 320)  # H, W after the resize
CROP = (228, 304)  # H, W of the centre crop
SAMPLES = 500
MAX_MEDIAN_M = 100.0  # a median depth above this is millimetres, not metres
RAW_LABELS = 894  # the labelled subset's raw class ids (semattnet.palette.nyu40_map)


def _check_layout(path: Path, rgb: h5py.Dataset, depth: h5py.Dataset, label: h5py.Dataset | None) -> None:
    """Dtypes and shapes (of datasets, before they are read): rgb uint8 (3, H, W) within the image bounds,
    depth float (H, W), label integer (H, W)."""
    if rgb.dtype != np.uint8 or len(rgb.shape) != 3 or rgb.shape[0] != 3:
        raise DataError(f"{path}: 'rgb' must be uint8 (3, H, W), got {rgb.dtype} {rgb.shape}")
    check_image_size(rgb.shape[2], rgb.shape[1], f"{path}: 'rgb' (3, H, W)")
    if depth.dtype not in (np.float32, np.float64) or depth.shape != rgb.shape[1:]:
        raise DataError(f"{path}: 'depth' must be float32 {rgb.shape[1:]} metres, got {depth.dtype} {depth.shape}")
    if label is not None and (label.shape != depth.shape or not np.issubdtype(label.dtype, np.integer)):
        raise DataError(f"{path}: 'label' must be integer {depth.shape} NYU-40 ids, got {label.dtype} {label.shape}")


def _read(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The arrays of one file, read as an untrusted file (:mod:`.hdf5`): only datasets stored in it, their
    dtypes and shapes checked before any read."""
    h5py = require("h5py", f"{path}: reading NYU v2 HDF5 files")
    try:
        with h5py.File(path, "r") as f:
            found = {k: plain_dataset(f, k, path) for k in ("rgb", "depth", "label")}
            missing = [k for k in ("rgb", "depth") if found[k] is None]
            if missing:
                raise DataError(
                    f"{path}: missing HDF5 key(s) {missing}; found {sorted(f.keys())} "
                    "(expected 'rgb' and 'depth', the sparse-to-dense layout)"
                )
            _check_layout(path, found["rgb"], found["depth"], found["label"])
            rgb, depth = read_bounded(found["rgb"], "rgb", path), read_bounded(found["depth"], "depth", path)
            label = read_bounded(found["label"], "label", path) if found["label"] is not None else None
    except DataError:
        raise
    except (OSError, KeyError, TypeError, ValueError, RuntimeError) as exc:  # h5py's errors of a damaged file
        raise DataError(f"{path}: not a readable HDF5 file ({type(exc).__name__}: {exc})") from None
    return rgb, depth, label


def read_nyu_h5(path: str | os.PathLike[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(H, W, 3) uint8 rgb, (H, W) float32 depth in metres and the optional label map of one file, checked.

    The file is read as untrusted (:mod:`semattnet.data.datasets.hdf5`): links, virtual datasets and
    external storage are refused, sizes bounded before any read.

    Raises:
        DataError: unreadable file, missing keys, data outside the file, wrong dtypes or shapes, sizes above
        the bounds, depth apparently in millimetres; always naming the file.
    """
    path = regular_file(path, "NYU v2 HDF5 file")
    rgb, depth, label = _read(path)
    valid = depth[np.isfinite(depth) & (depth > 0)]
    if valid.size and float(np.median(valid)) > MAX_MEDIAN_M:
        raise DataError(
            f"{path}: 'depth' median {float(np.median(valid)):.1f} is above {MAX_MEDIAN_M:g}: "
            "millimetres? expected metres"
        )
    if label is not None and label.size and (label.min() < 0 or label.max() > RAW_LABELS):
        raise DataError(
            f"{path}: 'label' must hold NYU-40 ids 0..40 or raw NYU ids 0..{RAW_LABELS}, found "
            f"{label.min()}..{label.max()}"
        )
    depth = np.where(np.isfinite(depth), depth, 0).astype(np.float32)
    return np.ascontiguousarray(rgb.transpose(1, 2, 0)), depth, label


def _resize(a: np.ndarray, nearest: bool) -> np.ndarray:
    from PIL import Image

    h, w = RESIZED
    mode = Image.Resampling.NEAREST if nearest else Image.Resampling.BILINEAR
    if a.ndim == 3:
        return np.asarray(Image.fromarray(a).resize((w, h), mode))
    return np.asarray(Image.fromarray(a.astype(np.float32), mode="F").resize((w, h), mode), dtype=np.float32)


def _crop(a: np.ndarray) -> np.ndarray:
    top, left = (RESIZED[0] - CROP[0]) // 2, (RESIZED[1] - CROP[1]) // 2
    return a[top : top + CROP[0], left : left + CROP[1]]


def check_root(root: Path) -> None:
    """A root one level too high (``nyu/`` holding ``nyudepthv2/``) is one line naming the folder to pass."""
    folders = set(NYU_SPLITS.values())
    if not root.is_dir() or any((root / f).is_dir() for f in folders):
        return
    below = sorted(c for c in root.iterdir() if c.is_dir() and any((c / f).is_dir() for f in folders))
    if below:
        raise DataError(
            f"{root}: not a NYU v2 root (no {' or '.join(sorted(folders))} inside), but {below[0]} is "
            f"one: pass {below[0]}"
        )


def label_colors(label: np.ndarray) -> np.ndarray:
    """A file's ``label`` map as the protocol frame's NYU-40 colours: NYU-40 ids (0..40) as they are; a map with
    any id above 40 holds the labelled subset's raw ids (1..894), mapped to NYU-40 by the published table
    (:func:`semattnet.palette.nyu894_to_nyu40`)."""
    from semattnet.palette import ids_to_colors, nyu894_to_nyu40

    ids = nyu894_to_nyu40(label) if label.size and int(label.max()) > 40 else label.astype(np.uint8)
    return ids_to_colors(_crop(_resize(ids, True)), palette="nyu40")


def protocol_K() -> np.ndarray:
    """The intrinsics of the resized, cropped frame."""
    s = RESIZED[1] / 640.0
    fx, fy, cx, cy = NYU_K
    top, left = (RESIZED[0] - CROP[0]) // 2, (RESIZED[1] - CROP[1]) // 2
    return np.array([[fx * s, 0, cx * s - left], [0, fy * s, cy * s - top], [0, 0, 1]], dtype=np.float64)


@register_source("nyuv2", option="--dataset nyuv2")
class NyuV2Source(IndexedSource):
    """The frames of ``split`` (``train`` or ``test``) under ``root``, in the protocol's 304x228 crop, with
    ground truth, ``samples`` depth samples per frame (seeded per frame with ``seed``) and, from a file's
    ``label`` key or a ``semantic_root`` folder of NYU-40 colour PNGs named ``NAME.png``, semantic maps.

    Raises:
        MissingSplitError: the split's folder is absent. DataError: it holds no ``.h5`` file.
    """

    palette = "nyu40"

    def __init__(
        self,
        root: str | os.PathLike[str],
        split: str = "test",
        samples: int = SAMPLES,
        seed: int = 0,
        semantic_root: str | os.PathLike[str] | None = None,
        max_frames: int | None = None,
    ) -> None:
        self.root, self.split = Path(root), check_split_in("nyuv2", split, tuple(NYU_SPLITS))
        folder = self.root / NYU_SPLITS[self.split]
        check_root(self.root)
        if not folder.is_dir():
            raise MissingSplitError(
                f"{folder}: split folder not found (expected {folder}/"
                f"{'<scene>/' if self.split == 'train' else ''}<NNNNN>.h5)"
            )
        files = sorted(folder.glob("*/*.h5" if self.split == "train" else "*.h5"))
        if not files:
            raise DataError(f"{folder}: no .h5 files")
        files = files[:max_frames] if max_frames else files
        train = self.split == "train"
        self.files = unique_names(((f"{f.parent.name}_{f.stem}" if train else f.stem, f) for f in files), folder)
        self.names: Sequence[str] = list(self.files)
        self.samples, self.seed = samples, seed
        self.semantic_root = Path(semantic_root) if semantic_root is not None else None

    def load(self, name: str) -> Frame:
        from semattnet.data.io import read_semantic

        path = self.files[name]
        rgb, depth, label = read_nyu_h5(path)
        if rgb.shape[:2] != KINECT:  # a 1x1 image would be upsampled to the crop, under the wrong intrinsics
            raise DataError(
                f"{path}: 'rgb' is {rgb.shape[1]}x{rgb.shape[0]}; the NYU v2 protocol (NYU_K, the resize "
                f"to {RESIZED[1]}x{RESIZED[0]}) is for {KINECT[1]}x{KINECT[0]} Kinect frames"
            )
        rgb, gt = _crop(_resize(rgb, False)), _crop(_resize(depth, False))
        paths = {"rgb": path, "gt": path, "sparse": path}
        sem = None
        if label is not None:
            sem = label_colors(label)
        elif self.semantic_root is not None:
            paths["semantic"] = self.semantic_root / f"{name}.png"
            sem = read_semantic(paths["semantic"], palette="nyu40")
        sparse = draw_samples(gt, self.samples, np.random.default_rng(frame_seed(name, self.seed)))
        return Frame(
            name, np.ascontiguousarray(rgb), sparse, sem, K=protocol_K(), gt=np.ascontiguousarray(gt), paths=paths
        )

    def inputs(self) -> list[Path]:
        return [self.root, *([self.semantic_root] if self.semantic_root is not None else [])]
