"""Segmenter classes -> the 40 NYU-40 classes (:data:`semattnet.palette.NYU40_CLASSES`), by name.

A model's ``id2label`` names (ignoring case, spaces, ``_``, ``-`` and a plural ``s``) are matched, in order:

1. to a NYU-40 class name (a model trained on NYU-40 matches all 40);
2. to :data:`NYU40_VARIANTS`: ADE20K names with an obvious NYU-40 counterpart that NYU's own raw names lack
   ("windowpane" -> window, "painting" -> picture, "chest of drawers" -> dresser ...);
3. to one of NYU Depth v2's 894 raw class names, through the published 894 -> 40 table
   (:mod:`semattnet.palette.nyu40_map`): ADE20K's "stove" is NYU's raw "stove", an ``otherstructure``.

Other classes (sky, road, tree ... in ADE20K) are dropped: a pixel gets the best of the classes that match.
The resulting table for ADE20K's 150 classes is in ``docs/datasets/nyuv2.md``.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from functools import cache

__all__ = ["NYU40_VARIANTS", "nyu40_class", "nyu40_indices"]

#: Normalised model label -> NYU-40 class name, for ADE20K names that neither NYU-40 nor NYU's raw names hold.
NYU40_VARIANTS: Mapping[str, str] = {
    "windowpane": "window",
    "window": "window",
    "painting": "picture",
    "poster": "picture",
    "shelf": "shelves",
    "armchair": "chair",
    "swivelchair": "chair",
    "seat": "chair",
    "cushion": "pillow",
    "chestofdrawers": "dresser",
    "bookcase": "bookshelf",
    "blind": "blinds",
    "countertop": "counter",
    "televisionreceiver": "television",
    "crtscreen": "television",
    "apparel": "clothes",
    "screendoor": "door",
    "stairway": "otherstructure",
    "bannister": "otherstructure",
    "ashcan": "otherfurniture",
    "buffet": "otherfurniture",
    "sconce": "lamp",
    "refridgerator": "refrigerator",
}


def _norm(name: str) -> str:
    return re.sub(r"[^a-z]", "", str(name).lower())


@cache
def _tables() -> tuple[dict[str, int], dict[str, int]]:
    from semattnet.palette import NYU40_CLASSES
    from semattnet.palette.nyu40_map import NYU894_TO_40, RAW_NAMES

    classes = {_norm(name): i + 1 for i, (name, _) in enumerate(NYU40_CLASSES)}
    raw: dict[str, int] = {}
    for i, name in enumerate(RAW_NAMES):
        raw.setdefault(_norm(name), NYU894_TO_40[i + 1])
    return classes, raw


def nyu40_class(label: str) -> int | None:
    """The NYU-40 id (1..40) a model class called ``label`` means, or None (module docstring)."""
    classes, raw = _tables()
    key = _norm(label)
    for k in (key, key[:-1] if key.endswith("s") else ""):
        if k in classes:
            return classes[k]
        if k in NYU40_VARIANTS:
            return classes[_norm(NYU40_VARIANTS[k])]
        if k in raw:
            return raw[k]
    return None


def nyu40_indices(id2label: Mapping[int, str] | Mapping[str, str]) -> list[list[int]]:
    """For each NYU-40 id 1..40 (list position id - 1), the model class indices whose names mean it."""
    found: list[list[int]] = [[] for _ in range(40)]
    for idx, label in sorted((int(k), v) for k, v in id2label.items()):
        c = nyu40_class(label)
        if c is not None:
            found[c - 1].append(idx)
    return found
