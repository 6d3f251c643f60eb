"""Semantic palettes: the colour codes of the semantic maps SemAttNet reads (Cityscapes, the default; NYU-40).

The authors' KITTI maps are colour-coded with the Cityscapes 19-class *trainId* palette (their
segmenter was trained on Cityscapes and fine-tuned on KITTI semantics). The model sees the colour
image (3 channels, 0-255), so any map must use exactly these colours; :func:`colors_to_ids`
refuses anything else and says which colours it found.

Ids: ``trainId`` 0-18 (what segmentation networks predict), 255 = ignore / unknown; Cityscapes
``labelId`` 0-33 (what the ``*_labelIds.png`` ground truth holds) maps onto trainIds with
:func:`label_ids_to_train_ids`.

Other palettes (:data:`PALETTES`, one home): ``nyu40``, the 40 classes of Gupta et al. (CVPR 2013) that
NYU Depth v2's labelled frames map to, coloured as ScanNet's ``create_color_palette`` (the colour code
of the indoor literature); id 0 (unlabelled) is :data:`UNKNOWN_COLOR`. A model records the palette it was
trained with (:attr:`semattnet.models.SemAttNetConfig.palette`); maps of another palette are refused
(:func:`colors_to_ids` with ``palette=``, which names the palette the colours do fit).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from semattnet._errors import DataError, InputError

__all__ = [
    "IGNORE_ID",
    "LABEL_TO_TRAIN",
    "NUM_CLASSES",
    "NYU40_CLASSES",
    "PALETTE",
    "PALETTES",
    "TRAIN_CLASSES",
    "UNKNOWN_COLOR",
    "Palette",
    "PaletteMismatchError",
    "UnknownColorError",
    "check_palette",
    "colors_to_ids",
    "get_palette",
    "ids_to_colors",
    "label_ids_to_train_ids",
    "nyu894_to_nyu40",
    "one_hot",
    "palette_mapping",
    "recolor",
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
    7: 0,
    8: 1,
    11: 2,
    12: 3,
    13: 4,
    17: 5,
    19: 6,
    20: 7,
    21: 8,
    22: 9,
    23: 10,
    24: 11,
    25: 12,
    26: 13,
    27: 14,
    28: 15,
    31: 16,
    32: 17,
    33: 18,
}


#: NYU-40 classes (Gupta et al.; ids 1..40, 0 = unlabelled) with ScanNet's colours.
NYU40_CLASSES: tuple[tuple[str, tuple[int, int, int]], ...] = (
    ("wall", (174, 199, 232)),
    ("floor", (152, 223, 138)),
    ("cabinet", (31, 119, 180)),
    ("bed", (255, 187, 120)),
    ("chair", (188, 189, 34)),
    ("sofa", (140, 86, 75)),
    ("table", (255, 152, 150)),
    ("door", (214, 39, 40)),
    ("window", (197, 176, 213)),
    ("bookshelf", (148, 103, 189)),
    ("picture", (196, 156, 148)),
    ("counter", (23, 190, 207)),
    ("blinds", (178, 76, 76)),
    ("desk", (247, 182, 210)),
    ("shelves", (66, 188, 102)),
    ("curtain", (219, 219, 141)),
    ("dresser", (140, 57, 197)),
    ("pillow", (202, 185, 52)),
    ("mirror", (51, 176, 203)),
    ("floor mat", (200, 54, 131)),
    ("clothes", (92, 193, 61)),
    ("ceiling", (78, 71, 183)),
    ("books", (172, 114, 82)),
    ("refrigerator", (255, 127, 14)),
    ("television", (91, 163, 138)),
    ("paper", (153, 98, 156)),
    ("towel", (140, 153, 101)),
    ("shower curtain", (158, 218, 229)),
    ("box", (100, 125, 154)),
    ("whiteboard", (178, 127, 135)),
    ("person", (120, 185, 128)),
    ("night stand", (146, 111, 194)),
    ("toilet", (44, 160, 44)),
    ("sink", (112, 128, 144)),
    ("lamp", (96, 207, 209)),
    ("bathtub", (227, 119, 194)),
    ("bag", (213, 92, 176)),
    ("otherstructure", (94, 106, 211)),
    ("otherfurniture", (82, 84, 163)),
    ("otherprop", (100, 85, 144)),
)


class UnknownColorError(DataError):
    """A semantic map holds colours outside the palette."""


class PaletteMismatchError(UnknownColorError):
    """Semantic maps of one palette given to a model trained with another."""


@dataclass(frozen=True)
class Palette:
    """A class-to-colour code: ``classes`` in id order (id ``i`` is ``classes[i - first_id]``); ids outside
    are unknown (:data:`UNKNOWN_COLOR`)."""

    name: str
    title: str
    classes: tuple[tuple[str, tuple[int, int, int]], ...]
    first_id: int = 0

    @property
    def colors(self) -> np.ndarray:
        """(N, 3) uint8 colours in id order."""
        return np.array([c for _, c in self.classes], dtype=np.uint8).reshape(-1, 3)

    @property
    def num_classes(self) -> int:
        return len(self.classes)


#: Every palette by name; ``cityscapes`` is the default (the authors' KITTI maps).
PALETTES: dict[str, Palette] = {
    "cityscapes": Palette("cityscapes", "Cityscapes", TRAIN_CLASSES),
    "nyu40": Palette("nyu40", "NYU-40", NYU40_CLASSES, first_id=1),
}


def get_palette(name: str | Palette) -> Palette:
    """The palette called ``name`` (see :data:`PALETTES`)."""
    if isinstance(name, Palette):
        return name
    if name not in PALETTES:
        from semattnet._errors import InputError

        raise InputError(f"palette: unknown palette {name!r}; choose one of {', '.join(PALETTES)}")
    return PALETTES[name]


def check_palette(model_palette: str, maps_palette: str, where: str = "semantic maps") -> None:
    """Refuse maps of ``maps_palette`` for a model trained with ``model_palette`` (one line)."""
    if get_palette(model_palette).name != get_palette(maps_palette).name:
        raise PaletteMismatchError(
            f"{where}: {get_palette(maps_palette).title} palette, but the model was trained "
            f"with the {get_palette(model_palette).title} palette"
        )


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


def ids_to_colors(train_ids: np.ndarray, palette: str | Palette = "cityscapes") -> np.ndarray:
    """Colour-code an (H, W) id map: (H, W, 3) uint8; 255 (ignore) becomes :data:`UNKNOWN_COLOR` (for
    ``nyu40``: ids 1..40, and 0 = unlabelled too)."""
    pal = get_palette(palette)
    ids = np.asarray(train_ids).astype(np.int64)
    n, first = pal.num_classes, pal.first_id
    unknown = (ids == IGNORE_ID) | ((ids == 0) & (first == 1))
    bad = ~unknown & ((ids < first) | (ids >= first + n))
    if bad.any():
        found = sorted(set(ids[bad].tolist()))[:5]
        kind = "trainIds" if pal.name == "cityscapes" else f"{pal.title} ids"
        raise InputError(f"{kind} must be {first}..{first + n - 1} or {IGNORE_ID}, found {found}")
    table = np.concatenate([pal.colors, np.array([UNKNOWN_COLOR], dtype=np.uint8)])
    colors: np.ndarray = table[np.where(unknown, n, ids - first)]
    return colors


def _codes(rgb: np.ndarray) -> np.ndarray:
    codes: np.ndarray = (rgb[..., 0].astype(np.int32) << 16) | (rgb[..., 1].astype(np.int32) << 8) | rgb[..., 2]
    return codes


def _fits(code: np.ndarray, stray: np.ndarray, pal: Palette) -> bool:
    """Every colour is one of ``pal``'s (or unknown) and every stray one a class colour of ``pal``."""
    unknown_code = (UNKNOWN_COLOR[0] << 16) | (UNKNOWN_COLOR[1] << 8) | UNKNOWN_COLOR[2]
    classes = _codes(pal.colors)
    return bool(np.isin(code, np.append(classes, unknown_code)).all() and np.isin(code[stray], classes).all())


def colors_to_ids(
    colors: np.ndarray, allow_unknown: bool = True, source: str = "semantic map", palette: str | Palette = "cityscapes"
) -> np.ndarray:
    """Invert :func:`ids_to_colors`: (H, W, 3) uint8 -> (H, W) uint8 ids (255 = unknown colour).

    Colours must match exactly (a resampled or JPEG-compressed map does not). Raises
    :class:`UnknownColorError` naming ``source``, the stray colours and their pixel counts, if any
    pixel is neither a colour of ``palette`` nor (when ``allow_unknown``) :data:`UNKNOWN_COLOR`; when
    the colours fit another palette of :data:`PALETTES`, :class:`PaletteMismatchError` says so.
    """
    pal = get_palette(palette)
    rgb = np.asarray(colors)
    if rgb.ndim != 3 or rgb.shape[-1] != 3 or rgb.dtype != np.uint8:
        raise DataError(f"{source}: expected an (H, W, 3) uint8 colour image, got {rgb.dtype} {rgb.shape}")
    code, keys = _codes(rgb), _codes(pal.colors)
    order = np.argsort(keys)
    pos = np.clip(np.searchsorted(keys[order], code), 0, pal.num_classes - 1)
    found = keys[order][pos] == code
    ids = np.where(found, order[pos] + pal.first_id, IGNORE_ID).astype(np.uint8)
    unknown_code = (UNKNOWN_COLOR[0] << 16) | (UNKNOWN_COLOR[1] << 8) | UNKNOWN_COLOR[2]
    stray = ~found & ((code != unknown_code) | (not allow_unknown))
    if stray.any():
        other = [p for p in PALETTES.values() if p.name != pal.name and _fits(code, stray, p)]
        if other:
            raise PaletteMismatchError(
                f"{source}: the colours are the {other[0].title} palette, but the "
                f"{pal.title} palette was expected (the model's training palette)"
            )
        values, counts = np.unique(code[stray], return_counts=True)
        top = np.argsort(-counts)[:5]
        listed = ", ".join(
            f"({v >> 16}, {(v >> 8) & 255}, {v & 255}) x{c}" for v, c in zip(values[top], counts[top], strict=True)
        )
        raise UnknownColorError(
            f"{source}: {int(stray.sum())} pixels in {len(values)} colour(s) outside the {pal.title} palette: "
            f"{listed}{' ...' if len(values) > 5 else ''}"
        )
    return ids


def nyu894_to_nyu40(raw: np.ndarray) -> np.ndarray:
    """NYU Depth v2's raw label ids (0..894, the labelled subset's ``labels``; 0 = unlabelled) -> NYU-40 ids
    (uint8 0..40) by the published table (:mod:`semattnet.palette.nyu40_map`, from ankurhanda/nyuv2-meta-data)."""
    from semattnet.palette.nyu40_map import NYU894_TO_40, RAW_CLASSES

    ids = np.asarray(raw)
    if ids.size and (ids.min() < 0 or ids.max() > RAW_CLASSES):
        raise InputError(f"NYU raw label ids must lie in 0..{RAW_CLASSES}, got {ids.min()}..{ids.max()}")
    return np.asarray(NYU894_TO_40, dtype=np.uint8)[ids.astype(np.int64)]


def palette_mapping(source: str | Palette, target: str | Palette) -> dict[int, int]:
    """Ids of ``source`` -> ids of ``target`` for the classes both palettes hold under one name (ignoring case,
    spaces and ``_``): Cityscapes and NYU-40 share ``wall`` and ``person``; every other class has none."""
    src, dst = get_palette(source), get_palette(target)

    def norm(name: str) -> str:
        return "".join(c for c in name.lower() if c.isalpha())

    ids = {norm(name): i + dst.first_id for i, (name, _) in enumerate(dst.classes)}
    return {i + src.first_id: ids[norm(n)] for i, (n, _) in enumerate(src.classes) if norm(n) in ids}


def recolor(
    colors: np.ndarray, source: str | Palette, target: str | Palette, where: str = "semantic map"
) -> np.ndarray:
    """A map of ``source``'s colours in ``target``'s: classes of :func:`palette_mapping` keep their meaning,
    every other pixel becomes :data:`UNKNOWN_COLOR` (what a model reads as "no class")."""
    ids = colors_to_ids(colors, source=where, palette=source).astype(np.int64)
    lut = np.full(256, IGNORE_ID, dtype=np.int64)
    for a, b in palette_mapping(source, target).items():
        lut[a] = b
    return ids_to_colors(lut[ids], palette=target)


def one_hot(train_ids: np.ndarray, num_classes: int = NUM_CLASSES) -> np.ndarray:
    """(H, W) trainIds -> (num_classes, H, W) float32 one-hot; ignore pixels are all zero."""
    ids = np.asarray(train_ids).astype(np.int64)
    eye = np.concatenate([np.eye(num_classes, dtype=np.float32), np.zeros((1, num_classes), np.float32)])
    return np.moveaxis(eye[np.where((ids >= 0) & (ids < num_classes), ids, num_classes)], -1, 0)


def unknown_map(height: int, width: int) -> np.ndarray:
    """The no-segmenter fallback: an (H, W, 3) uint8 map of :data:`UNKNOWN_COLOR` everywhere."""
    return np.full((height, width, 3), UNKNOWN_COLOR, dtype=np.uint8)
