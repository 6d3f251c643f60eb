"""Cityscapes semantic palette: the colour code of the semantic maps SemAttNet reads.

The authors' KITTI maps are colour-coded with the Cityscapes 19-class *trainId* palette (their
segmenter was trained on Cityscapes and fine-tuned on KITTI semantics). The model sees the colour
image (3 channels, 0-255), so any map must use exactly these colours; :func:`colors_to_ids`
refuses anything else and says which colours it found.

Ids: ``trainId`` 0-18 (what segmentation networks predict), 255 = ignore / unknown; Cityscapes
``labelId`` 0-33 (what the ``*_labelIds.png`` ground truth holds) maps onto trainIds with
:func:`label_ids_to_train_ids`.
"""

from __future__ import annotations

import numpy as np

from semattnet._errors import DataError, InputError

__all__ = [
    "IGNORE_ID",
    "LABEL_TO_TRAIN",
    "NUM_CLASSES",
    "PALETTE",
    "TRAIN_CLASSES",
    "UNKNOWN_COLOR",
    "UnknownColorError",
    "colors_to_ids",
    "ids_to_colors",
    "label_ids_to_train_ids",
    "one_hot",
    "unknown_map",
]

#: The 19 Cityscapes evaluation classes in trainId order, with their colours.
TRAIN_CLASSES: tuple[tuple[str, tuple[int, int, int]], ...] = (
    ("road", (128, 64, 128)),
    ("sidewalk", (244, 35, 232)),
    ("building", (70, 70, 70)),
    ("wall", (102, 102, 156)),
    ("fence", (190, 153, 153)),
    ("pole", (153, 153, 153)),
    ("traffic light", (250, 170, 30)),
    ("traffic sign", (220, 220, 0)),
    ("vegetation", (107, 142, 35)),
    ("terrain", (152, 251, 152)),
    ("sky", (70, 130, 180)),
    ("person", (220, 20, 60)),
    ("rider", (255, 0, 0)),
    ("car", (0, 0, 142)),
    ("truck", (0, 0, 70)),
    ("bus", (0, 60, 100)),
    ("train", (0, 80, 100)),
    ("motorcycle", (0, 0, 230)),
    ("bicycle", (119, 11, 32)),
)
NUM_CLASSES = len(TRAIN_CLASSES)
IGNORE_ID = 255
#: Colour of ignore / unknown pixels (Cityscapes' "unlabeled"); also the no-segmenter fallback.
UNKNOWN_COLOR: tuple[int, int, int] = (0, 0, 0)
#: (19, 3) uint8 colour table indexed by trainId.
PALETTE = np.array([c for _, c in TRAIN_CLASSES], dtype=np.uint8)
PALETTE.flags.writeable = False

#: Cityscapes labelId (0-33) -> trainId (255 = not evaluated), from cityscapesScripts' labels.py.
LABEL_TO_TRAIN: dict[int, int] = {
    **dict.fromkeys(range(34), IGNORE_ID),
    7: 0, 8: 1, 11: 2, 12: 3, 13: 4, 17: 5, 19: 6, 20: 7, 21: 8, 22: 9,
    23: 10, 24: 11, 25: 12, 26: 13, 27: 14, 28: 15, 31: 16, 32: 17, 33: 18,
}  # fmt: skip


class UnknownColorError(DataError):
    """A semantic map holds colours outside the palette."""


def _lut_label_to_train() -> np.ndarray:
    lut = np.full(256, IGNORE_ID, dtype=np.uint8)
    for label, train in LABEL_TO_TRAIN.items():
        lut[label] = train
    return lut


def label_ids_to_train_ids(label_ids: np.ndarray) -> np.ndarray:
    """Map a Cityscapes labelId image to trainIds (uint8, 255 where not a training class)."""
    ids = np.asarray(label_ids)
    if ids.size and (ids.min() < 0 or ids.max() > 255):
        raise InputError(f"labelIds must lie in 0..255, got {ids.min()}..{ids.max()}")
    return _lut_label_to_train()[ids.astype(np.int64)]


def ids_to_colors(train_ids: np.ndarray) -> np.ndarray:
    """Colour-code an (H, W) trainId map: (H, W, 3) uint8; 255 (ignore) becomes :data:`UNKNOWN_COLOR`."""
    ids = np.asarray(train_ids)
    bad = (ids != IGNORE_ID) & ((ids < 0) | (ids >= NUM_CLASSES))
    if bad.any():
        found = sorted(set(ids[bad].tolist()))[:5]
        raise InputError(f"trainIds must be 0..{NUM_CLASSES - 1} or {IGNORE_ID}, found {found}")
    table = np.concatenate([PALETTE, np.array([UNKNOWN_COLOR], dtype=np.uint8)])
    return table[np.where(ids == IGNORE_ID, NUM_CLASSES, ids).astype(np.int64)]


def colors_to_ids(colors: np.ndarray, allow_unknown: bool = True, source: str = "semantic map") -> np.ndarray:
    """Invert :func:`ids_to_colors`: (H, W, 3) uint8 -> (H, W) uint8 trainIds (255 = unknown colour).

    Colours must match exactly (a resampled or JPEG-compressed map does not). Raises
    :class:`UnknownColorError` naming ``source``, the stray colours and their pixel counts, if any
    pixel is neither a palette colour nor (when ``allow_unknown``) :data:`UNKNOWN_COLOR`.
    """
    rgb = np.asarray(colors)
    if rgb.ndim != 3 or rgb.shape[-1] != 3 or rgb.dtype != np.uint8:
        raise DataError(f"{source}: expected an (H, W, 3) uint8 colour image, got {rgb.dtype} {rgb.shape}")
    code = (rgb[..., 0].astype(np.int32) << 16) | (rgb[..., 1].astype(np.int32) << 8) | rgb[..., 2]
    keys = (PALETTE[:, 0].astype(np.int32) << 16) | (PALETTE[:, 1].astype(np.int32) << 8) | PALETTE[:, 2]
    order = np.argsort(keys)
    pos = np.clip(np.searchsorted(keys[order], code), 0, NUM_CLASSES - 1)
    found = keys[order][pos] == code
    ids = np.where(found, order[pos], IGNORE_ID).astype(np.uint8)
    unknown_code = (UNKNOWN_COLOR[0] << 16) | (UNKNOWN_COLOR[1] << 8) | UNKNOWN_COLOR[2]
    stray = ~found & ((code != unknown_code) | (not allow_unknown))
    if stray.any():
        values, counts = np.unique(code[stray], return_counts=True)
        top = np.argsort(-counts)[:5]
        listed = ", ".join(
            f"({v >> 16}, {(v >> 8) & 255}, {v & 255}) x{c}" for v, c in zip(values[top], counts[top], strict=True)
        )
        raise UnknownColorError(
            f"{source}: {int(stray.sum())} pixels in {len(values)} colour(s) outside the Cityscapes palette: "
            f"{listed}{' ...' if len(values) > 5 else ''}"
        )
    return ids


def one_hot(train_ids: np.ndarray, num_classes: int = NUM_CLASSES) -> np.ndarray:
    """(H, W) trainIds -> (num_classes, H, W) float32 one-hot; ignore pixels are all zero."""
    ids = np.asarray(train_ids).astype(np.int64)
    eye = np.concatenate([np.eye(num_classes, dtype=np.float32), np.zeros((1, num_classes), np.float32)])
    return np.moveaxis(eye[np.where((ids >= 0) & (ids < num_classes), ids, num_classes)], -1, 0)


def unknown_map(height: int, width: int) -> np.ndarray:
    """The no-segmenter fallback: an (H, W, 3) uint8 map of :data:`UNKNOWN_COLOR` everywhere."""
    return np.broadcast_to(np.array(UNKNOWN_COLOR, dtype=np.uint8), (height, width, 3)).copy()
