"""Cityscapes palette: round trips, the labelId mapping, unknown colours."""

from __future__ import annotations

import numpy as np
import pytest

from semattnet.palette import (
    IGNORE_ID,
    LABEL_TO_TRAIN,
    NUM_CLASSES,
    PALETTE,
    TRAIN_CLASSES,
    UNKNOWN_COLOR,
    UnknownColorError,
    colors_to_ids,
    ids_to_colors,
    label_ids_to_train_ids,
    one_hot,
    unknown_map,
)


def test_palette_is_cityscapes() -> None:
    assert NUM_CLASSES == 19 and PALETTE.shape == (19, 3)
    names = [n for n, _ in TRAIN_CLASSES]
    assert names[0] == "road" and names[10] == "sky" and names[13] == "car" and names[18] == "bicycle"
    assert tuple(PALETTE[0]) == (128, 64, 128) and tuple(PALETTE[13]) == (0, 0, 142)
    assert len({tuple(c) for c in PALETTE}) == 19  # distinct colours, so decoding is exact
    assert UNKNOWN_COLOR not in {tuple(c) for c in PALETTE}
    with pytest.raises(ValueError):
        PALETTE[0, 0] = 1  # read-only


def test_ids_colors_round_trip() -> None:
    rng = np.random.default_rng(0)
    ids = rng.integers(0, NUM_CLASSES, size=(37, 53)).astype(np.uint8)
    ids[::5, ::7] = IGNORE_ID
    colors = ids_to_colors(ids)
    assert colors.shape == (37, 53, 3) and colors.dtype == np.uint8
    assert (colors[0, 0] == np.array(UNKNOWN_COLOR)).all()
    assert np.array_equal(colors_to_ids(colors), ids)


def test_synthetic_palette_agrees() -> None:
    from semattnet.synthetic.scenes import CITYSCAPES_PALETTE

    table = dict(TRAIN_CLASSES)
    for name, color in CITYSCAPES_PALETTE.items():
        assert table[name] == color


def test_unknown_colours_are_reported() -> None:
    colors = ids_to_colors(np.zeros((4, 5), dtype=np.uint8))
    colors[1, 1] = (1, 2, 3)
    colors[2, 2:4] = (129, 64, 128)  # one off from road: a resampled map
    with pytest.raises(UnknownColorError, match=r"frame\.png: 3 pixels in 2 colour\(s\).*\(129, 64, 128\) x2"):
        colors_to_ids(colors, source="frame.png")
    black = ids_to_colors(np.full((2, 2), IGNORE_ID, dtype=np.uint8))
    assert (colors_to_ids(black) == IGNORE_ID).all()
    with pytest.raises(UnknownColorError, match=r"\(0, 0, 0\) x4"):
        colors_to_ids(black, allow_unknown=False)
    with pytest.raises(ValueError, match="uint8"):
        colors_to_ids(np.zeros((2, 2, 3), dtype=np.float32))
    with pytest.raises(ValueError, match="trainIds"):
        ids_to_colors(np.array([[19]]))


def test_label_ids_to_train_ids() -> None:
    label = np.array([[7, 8, 26], [0, 33, 9]])  # road, sidewalk, car / unlabeled, bicycle, parking
    assert label_ids_to_train_ids(label).tolist() == [[0, 1, 13], [255, 18, 255]]
    assert sorted(v for v in LABEL_TO_TRAIN.values() if v != IGNORE_ID) == list(range(19))
    with pytest.raises(ValueError, match="0..255"):
        label_ids_to_train_ids(np.array([-1]))


def test_one_hot_and_fallback() -> None:
    ids = np.array([[0, 18], [IGNORE_ID, 5]], dtype=np.uint8)
    oh = one_hot(ids)
    assert oh.shape == (19, 2, 2) and oh.dtype == np.float32
    assert oh[:, 1, 0].sum() == 0 and oh[18, 0, 1] == 1 and oh.sum() == 3
    blank = unknown_map(3, 4)
    assert blank.shape == (3, 4, 3) and (colors_to_ids(blank) == IGNORE_ID).all()
