"""What the scene's surfaces are: classes (Cityscapes trainId colours) and materials as the LiDAR sees them.

:data:`MATERIALS` are the codes of ``SyntheticFrame.material``: dark paint returns few points, glossy
paint mirrors some beams (range too long), glass lets beams through or loses them. :func:`surfaces`
gives the material of every ray hit (the realistic style; building windows are glass, car cabins but
for the roof) and the posters hung on facades.
"""

from __future__ import annotations

import numpy as np

from semattnet.palette import TRAIN_CLASSES

from .layout import Box, window_corners

__all__ = [
    "CITYSCAPES_PALETTE",
    "CLASS_IDS",
    "CLASS_NAMES",
    "LABEL_COLOURS",
    "MATERIALS",
    "MATERIAL_IDS",
    "posters",
    "surfaces",
]

#: Cityscapes trainId colours of the classes the generator uses (class name -> RGB).
CITYSCAPES_PALETTE: dict[str, tuple[int, int, int]] = {
    c: dict(TRAIN_CLASSES)[c] for c in ("road", "sidewalk", "building", "pole", "vegetation", "sky", "person", "car")
}
#: The generator's classes; ``SyntheticFrame.labels`` indexes this tuple.
CLASS_NAMES: tuple[str, ...] = tuple(CITYSCAPES_PALETTE)
#: Class name -> label (index into :data:`CLASS_NAMES`).
CLASS_IDS: dict[str, int] = {c: i for i, c in enumerate(CLASS_NAMES)}
#: (len(CLASS_NAMES), 3) uint8 colour table indexed by label.
LABEL_COLOURS = np.array([CITYSCAPES_PALETTE[c] for c in CLASS_NAMES], dtype=np.uint8)

#: Surfaces as the LiDAR sees them (``SyntheticFrame.material`` indexes this).
MATERIALS: tuple[str, ...] = ("matte", "dark", "glossy", "glass")
#: Material name -> code (index into :data:`MATERIALS`).
MATERIAL_IDS: dict[str, int] = {m: i for i, m in enumerate(MATERIALS)}


def posters(points: np.ndarray, idx: np.ndarray, axis: np.ndarray, boxes: list[Box]) -> tuple[np.ndarray, np.ndarray]:
    """Per point: on a poster (N,) and the poster's colour there (N, 3)."""
    on = np.zeros(len(idx), dtype=bool)
    colour = np.zeros((len(idx), 3))
    for b, box in enumerate(boxes):
        if box.poster is None:
            continue
        ax, s0, s1, y0, y1, kind, period, *cols = box.poster
        sel = np.flatnonzero((idx == b) & (axis == ax))
        s, y = points[sel, 2 if ax == 0 else 0], points[sel, 1]
        inside = (s > s0) & (s < s1) & (y > y0) & (y < y1)
        a, c = s / period, y / period
        pattern = (np.mod(a, 1) < 0.5, (np.floor(a) + np.floor(c)) % 2 == 0, np.mod(a + c, 1) < 0.5)[int(kind)]
        on[sel[inside]] = True
        colour[sel[inside]] = np.where(pattern[inside, None], cols[:3], cols[3:])
    return on, colour


def surfaces(
    points: np.ndarray, idx: np.ndarray, axis: np.ndarray, boxes: list[Box]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per ray hit (realistic style): material code (index into MATERIALS), on a poster, poster colour."""
    on_box = idx >= 0
    safe = np.where(on_box, idx, 0)
    box_mat = np.array([MATERIAL_IDS[b.material] for b in boxes] or [0])
    is_building = np.array([b.cls == "building" for b in boxes] or [False])
    material = np.where(on_box, box_mat[safe], MATERIAL_IDS["matte"])
    material[(material == MATERIAL_IDS["glass"]) & (axis == 1)] = MATERIAL_IDS["matte"]  # a cabin's roof
    poster, colour = posters(points, idx, axis, boxes)
    facade = np.flatnonzero(on_box & is_building[safe] & (axis != 1) & ~poster)
    material[facade[window_corners(points[facade])]] = MATERIAL_IDS["glass"]
    return material, poster, colour
